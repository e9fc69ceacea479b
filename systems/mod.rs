//! The ordered ECS systems of the physics step, one file per stage.
//!
//! The order lives in one place, [`crate::schedule::MarbleSystems`]; each stage here is a
//! set of plain `pub fn` systems that can be run on a raw `World` with a `Schedule`.
//! Stages named `Board…` are marble–board work, stages named `Pair…` marble–marble work.
//!
//! | stage | file | does |
//! | --- | --- | --- |
//! | `Validate` | `validate.rs` | on the first substep: marbles and boards with a bad value (from the program, or sent out of range by the last step) are quarantined before anything moves |
//! | `PrepareBoards` | `boards.rs` | on the first substep, gives boards with a `NextPose` their velocities; snapshots every board's pose and motion for the substep |
//! | `Wake` | `sleep.rs` | on the first substep: wakes the sleeping marbles something reaches |
//! | `AccumulateForces` | `forces.rs` | acceleration = gravity + force / mass |
//! | `PairContacts` | `pairs.rs` | marble–marble pairs touching at the start: collisions, friction, contact forces, overlap (only with `marble_collisions`) |
//! | `BoardDetection` | `board_detection.rs`, `integrate.rs` | each marble's start noted; marble–board touches at the start (collision or contact), else the first impact (CCD) or the end overlap, a marble none touches or reaches moving freely with the chosen integrator; marbles resting, sliding or rolling on one piece with nothing else near are resolved here (in closed form on a still board, unless a spinning marble's friction event falls inside the substep; by the event loop on that touch otherwise) |
//! | `BoardResponse` | `board_response.rs` | the marble–board event loop for the marbles detection flagged: equation (1), contacts, continuous collision; spinning marbles' orientations turned |
//! | `PairImpacts` | `pairs.rs` | marble–marble pairs that meet inside the substep collide at their time of impact (only with `marble_collisions`) |
//! | `Events` | `events.rs` | the substep's impacts become messages, its touching pairs are noted (only with `events`) |
//! | `MoveBoards` | `boards.rs` | kinematic boards advance by their velocities; on the last substep, driven boards reach their `NextPose` |
//! | `FallAsleep` | `sleep.rs` | on the last substep, with sleeping on: put to sleep the groups that have been slow long enough |
//! | `Finish` | `forces.rs` | on the last substep: clear forces |
//! | `Report` | `events.rs` | on the last substep: contacts started and ended; sensors carried by boards placed, then sensors entered and left |

use bevy_ecs::change_detection::ContiguousMut;
use bevy_ecs::prelude::*;
use bevy_ecs::query::QueryData;

use crate::board_contact::{Material, NearPieces};
use crate::components::{
    Acceleration, AngularVelocity, Contacts, Friction, Marble, MoreContacts, Position,
    PositionCarry, Quarantined, Radius, Restitution, RollingResistance, SpinDamping, StepStart,
    Velocity,
};
use crate::sleep::Sleeping;

/// The marbles every per-marble stage steps: awake and not quarantined.
pub type Stepped = (With<Marble>, Without<Quarantined>, Without<Sleeping>);

/// The marbles that do not spin, which the marble–board stages step without any rolling
/// code.
pub type Smooth = (Stepped, Without<AngularVelocity>);

/// What the marble–board stages (detection and response) read and write of every marble.
#[derive(QueryData)]
#[query_data(mutable, contiguous(all))]
pub struct BoardStaged {
    position: &'static mut Position,
    carry: &'static mut PositionCarry,
    velocity: &'static mut Velocity,
    start: &'static mut StepStart,
    acceleration: &'static Acceleration,
    radius: &'static Radius,
    restitution: &'static Restitution,
    contacts: &'static mut Contacts,
    more: &'static mut MoreContacts,
    near: &'static mut NearPieces,
}

/// What the marble–board stages read and write besides [`BoardStaged`] of a marble that
/// carries an [`AngularVelocity`]: with rolling on it spins, with friction, rolling
/// resistance and spin damping at its contacts.
#[derive(QueryData)]
#[query_data(mutable)]
pub struct SpinStaged {
    spin: &'static mut AngularVelocity,
    friction: &'static Friction,
    rolling_resistance: Option<&'static RollingResistance>,
    spin_damping: Option<&'static SpinDamping>,
}

impl SpinStagedItem<'_, '_> {
    /// The marble's side of a contact's material, with the restitution `restitution`.
    #[inline]
    pub(crate) fn material(&self, restitution: &Restitution) -> Material {
        Material::of_marble(
            restitution,
            self.friction,
            self.rolling_resistance,
            self.spin_damping,
        )
    }
}

/// The material of a marble that does not spin: its restitution only (a smooth marble
/// feels no friction).
#[inline]
pub(crate) fn smooth_material(restitution: &Restitution) -> Material {
    Material {
        restitution: restitution.0,
        ..Material::default()
    }
}

/// One table's columns of what the marble–board stages read and write ([`BoardStaged`]),
/// as slices of equal length: what a stage walks in order, or hands to the task pool in
/// chunks ([`run_rows`]).
pub(crate) struct BoardRows<'a> {
    pub position: &'a mut [Position],
    pub carry: &'a mut [PositionCarry],
    pub velocity: &'a mut [Velocity],
    pub start: &'a mut [StepStart],
    pub acceleration: &'a [Acceleration],
    pub radius: &'a [Radius],
    pub restitution: &'a [Restitution],
    pub contacts: &'a mut [Contacts],
    pub more: &'a mut [MoreContacts],
    pub near: &'a mut [NearPieces],
}

impl<'a> BoardRows<'a> {
    /// One table's rows of a [`BoardStaged`] query. The positions', carries' and
    /// velocities' change ticks are set for the whole table in one pass (detection writes
    /// those of the marbles it resolves, the response those of the others); the contacts'
    /// only with `contacts_changed` (the response's rewrite), the other lists' never (they
    /// are the stages' own records).
    pub(crate) fn of_table(t: BoardStagedContiguousItem<'a, '_>, contacts_changed: bool) -> Self {
        let contacts = if contacts_changed {
            ContiguousMut::split(t.contacts).0
        } else {
            ContiguousMut::bypass_change_detection_split(t.contacts).0
        };
        BoardRows {
            position: ContiguousMut::split(t.position).0,
            carry: ContiguousMut::split(t.carry).0,
            velocity: ContiguousMut::split(t.velocity).0,
            start: ContiguousMut::bypass_change_detection_split(t.start).0,
            acceleration: t.acceleration,
            radius: t.radius,
            restitution: t.restitution,
            contacts,
            more: ContiguousMut::bypass_change_detection_split(t.more).0,
            near: ContiguousMut::bypass_change_detection_split(t.near).0,
        }
    }
}

/// Slices of one table's columns that split into chunks of rows.
#[cfg_attr(
    not(feature = "parallel"),
    expect(dead_code, reason = "only the task pool splits rows")
)]
pub(crate) trait Rows: Sized + Send {
    /// The fewest rows [`run_rows`] hands the task pool as one chunk.
    const MIN_CHUNK: usize = 256;
    /// How many rows.
    fn len(&self) -> usize;
    /// The first `mid` rows and the rest.
    fn split_at(self, mid: usize) -> (Self, Self);
}

impl<T: Sync> Rows for &[T] {
    fn len(&self) -> usize {
        <[T]>::len(self)
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        <[T]>::split_at(self, mid)
    }
}

impl<T: Send> Rows for &mut [T] {
    fn len(&self) -> usize {
        <[T]>::len(self)
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        <[T]>::split_at_mut(self, mid)
    }
}

/// Rows given by their indices alone.
impl Rows for std::ops::Range<usize> {
    fn len(&self) -> usize {
        ExactSizeIterator::len(self)
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        let at = self.start + mid;
        (self.start..at, at..self.end)
    }
}

/// Columns side by side (a tuple of slices, or of other [`Rows`]) split together; the
/// first says how many rows there are.
macro_rules! tuple_rows {
    ($(($R:ident, $r:ident)),+) => {
        impl<$($R: Rows),+> Rows for ($($R,)+) {
            fn len(&self) -> usize {
                self.0.len()
            }

            fn split_at(self, mid: usize) -> (Self, Self) {
                let ($($r,)+) = self;
                $(let $r = $r.split_at(mid);)+
                (($($r.0,)+), ($($r.1,)+))
            }
        }
    };
}
tuple_rows!((A, a), (B, b));
tuple_rows!((A, a), (B, b), (C, c));
tuple_rows!((A, a), (B, b), (C, c), (D, d));
tuple_rows!((A, a), (B, b), (C, c), (D, d), (E, e));
tuple_rows!((A, a), (B, b), (C, c), (D, d), (E, e), (F, f));
tuple_rows!((A, a), (B, b), (C, c), (D, d), (E, e), (F, f), (G, g));

impl Rows for BoardRows<'_> {
    fn len(&self) -> usize {
        self.position.len()
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        let (p0, p1) = self.position.split_at_mut(mid);
        let (c0, c1) = self.carry.split_at_mut(mid);
        let (v0, v1) = self.velocity.split_at_mut(mid);
        let (s0, s1) = self.start.split_at_mut(mid);
        let (a0, a1) = self.acceleration.split_at(mid);
        let (r0, r1) = self.radius.split_at(mid);
        let (e0, e1) = self.restitution.split_at(mid);
        let (k0, k1) = self.contacts.split_at_mut(mid);
        let (m0, m1) = self.more.split_at_mut(mid);
        let (n0, n1) = self.near.split_at_mut(mid);
        let head = BoardRows {
            position: p0,
            carry: c0,
            velocity: v0,
            start: s0,
            acceleration: a0,
            radius: r0,
            restitution: e0,
            contacts: k0,
            more: m0,
            near: n0,
        };
        let tail = BoardRows {
            position: p1,
            carry: c1,
            velocity: v1,
            start: s1,
            acceleration: a1,
            radius: r1,
            restitution: e1,
            contacts: k1,
            more: m1,
            near: n1,
        };
        (head, tail)
    }
}

/// Runs `each` over a table's `rows`: with the `parallel` feature and `parallel` set, in
/// chunks on bevy's compute task pool (four a thread, the calling thread taking its share
/// while it waits), in order otherwise. Each row's work depends on that row alone, so
/// both give the same bits; a chunk is walked by the same loop as a whole table.
#[cfg_attr(
    not(feature = "parallel"),
    expect(unused_variables, reason = "one thread")
)]
#[inline(always)]
pub(crate) fn run_rows<R: Rows>(rows: R, parallel: bool, each: impl Fn(R) + Sync) {
    #[cfg(feature = "parallel")]
    if parallel {
        let pool = bevy_tasks::ComputeTaskPool::get();
        let chunk = chunk_len(rows.len(), R::MIN_CHUNK);
        let each = &each;
        pool.scope(|scope| {
            let mut rows = rows;
            while rows.len() > chunk {
                let (head, tail) = rows.split_at(chunk);
                scope.spawn(async move { each(head) });
                rows = tail;
            }
            scope.spawn(async move { each(rows) });
        });
        return;
    }
    each(rows);
}

/// The rows of each chunk [`run_rows`] hands the task pool, for `len` rows and chunks of
/// at least `min_chunk`: four chunks a pool thread.
#[cfg(feature = "parallel")]
#[inline]
fn chunk_len(len: usize, min_chunk: usize) -> usize {
    let threads = bevy_tasks::ComputeTaskPool::get().thread_num().max(1);
    len.div_ceil(4 * threads).max(min_chunk)
}

/// How many chunks [`run_rows`] cuts `len` rows of `R` into with `parallel`: one when it
/// runs them in order.
#[cfg_attr(
    not(feature = "parallel"),
    expect(unused_variables, reason = "one thread")
)]
#[inline]
pub(crate) fn pool_chunks<R: Rows>(len: usize, parallel: bool) -> usize {
    #[cfg(feature = "parallel")]
    if parallel {
        return len.div_ceil(chunk_len(len, R::MIN_CHUNK)).max(1);
    }
    1
}

/// Whether a stage of `n` marbles runs on the task pool (the `parallel` feature and at
/// least [`PARALLEL_MIN`] marbles).
#[inline]
pub(crate) fn on_pool(n: usize) -> bool {
    #[cfg(feature = "parallel")]
    return n >= PARALLEL_MIN;
    #[cfg(not(feature = "parallel"))]
    {
        let _ = n;
        false
    }
}

/// With the `parallel` feature, queries of fewer marbles than this run in order: handing
/// a few marbles to the task pool costs more than their work (a study of thousands of
/// one-marble scenes ran ten times slower).
#[cfg(feature = "parallel")]
pub(crate) const PARALLEL_MIN: usize = 1024;

thread_local! {
    /// Each thread's scratch [`ContactList`](crate::components::ContactList), in which the
    /// marble–board detection of a marble that spins builds its contacts before storing
    /// them (rather than a fresh list per marble).
    pub(crate) static CONTACT_LIST: std::cell::RefCell<crate::components::ContactList> =
        std::cell::RefCell::new(crate::components::ContactList::default());
}

#[cfg(feature = "parallel")]
thread_local! {
    /// Each task-pool thread's scratch [`TouchList`](crate::board_contact::TouchList) for
    /// [`for_each_marble`]. (`for_each_init` would hand its scratch value from item to item
    /// by value: a copy of the whole list in and out per marble, which took a fifth of the
    /// parallel walled board's time.)
    pub(crate) static SCRATCH: std::cell::RefCell<crate::board_contact::TouchList> =
        std::cell::RefCell::new(crate::board_contact::TouchList::default());
}

/// Runs `each(&mut touches, item)` for every item of the marble query `query`, with a
/// scratch [`TouchList`](crate::board_contact::TouchList): on bevy's compute task pool with the
/// `parallel` feature (each thread's own scratch list, [`SCRATCH`]) when there are at least
/// [`PARALLEL_MIN`] marbles, in order otherwise. Each marble's work depends on that marble
/// alone, so both give the same bits.
macro_rules! for_each_marble {
    ($query:expr, $each:expr) => {{
        #[cfg(feature = "parallel")]
        let parallel = $query.iter().len() >= crate::systems::PARALLEL_MIN;
        #[cfg(not(feature = "parallel"))]
        let parallel = false;
        if parallel {
            #[cfg(feature = "parallel")]
            {
                let each = $each;
                $query.par_iter_mut().for_each(|item| {
                    crate::systems::SCRATCH.with_borrow_mut(|touches| each(touches, item))
                });
            }
        } else {
            let mut touches = crate::board_contact::TouchList::default();
            for item in &mut $query {
                ($each)(&mut touches, item);
            }
        }
    }};
}
pub(crate) use for_each_marble;

pub mod board_detection;
pub mod board_response;
pub mod boards;
pub mod events;
pub mod forces;
pub(crate) mod integrate;
pub mod pairs;
pub mod sleep;
pub mod validate;
