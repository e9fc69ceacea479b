//! Marble–marble pairs ([`crate::pairs`]): the `PairContacts` stage before integration
//! (touching pairs: collisions at the start, contact forces, overlap) and the
//! `PairImpacts` stage after the marble–board response (pairs that meet during the
//! substep). Both drive the [`PairSolver`] through its phases.

use bevy_ecs::prelude::*;
use bevy_ecs::query::QueryData;
use glam::Vec3;

use super::Stepped;
use crate::board_contact::{BoardCache, NearPieces, touch_tolerance};
use crate::components::{
    Acceleration, AngularVelocity, Contacts, Friction, Mass, MoreContacts, Position, PositionCarry,
    Radius, Restitution, StepStart, Velocity, compensated_add, contact_iter, contact_slices,
};
use crate::config::{StepConfig, Substep};
use crate::pairs::{BoardTouch, Body, Gathered, MarbleContacts, PairParams, PairSolver};

fn params(config: &StepConfig, h: f32) -> PairParams {
    PairParams {
        h,
        ccd: config.ccd,
        threshold: config.restitution_threshold,
        tolerance: config.contact_tolerance,
        iterations: config.solver_iterations,
    }
}

/// Copies a marble's board contacts (recorded during a substep of length `h`) into the
/// solver, the contact point carried with the board to the end of that substep, and the
/// board's velocity there taken at time `at` of the current substep. With `start` (the
/// contact stage: the marble's centre, radius, touching tolerance, free displacement and
/// acceleration over the substep), a contact the marble has since left (it bounced off
/// during the last substep) becomes a speculative row with the gap it now has, if its free
/// path can close that gap this substep (as for [`speculative_touches`]), and no row
/// otherwise: held as if it still touched, it would make the pair impulses those of a
/// marble pinned to a board it does not reach.
#[expect(
    clippy::too_many_arguments,
    reason = "a marble's contacts and state, handed over"
)]
fn board_touches(
    solver: &mut PairSolver,
    cache: &BoardCache,
    body: u32,
    (contacts, more): (&Contacts, &MoreContacts),
    restitution: f32,
    h: f32,
    at: f32,
    start: Option<(Vec3, f32, f32, Vec3, Vec3)>,
) {
    solver.next_body_touches();
    for c in contact_iter(contacts, more) {
        let Some(board) = cache.boards.get(c.piece.board()) else {
            continue;
        };
        let point = c.point + board.point_velocity(c.time, c.point) * (h - c.time);
        let velocity = board.point_velocity(at, point);
        let mut gap = 0.0;
        if let Some((x, r, tol, d, a)) = start {
            let left = (x - point).dot(c.normal) - r;
            if left > tol {
                let closing = (-(d - velocity * h).dot(c.normal)).max(0.0) + a.length() * h * h;
                if left > closing {
                    continue;
                }
                gap = left;
            }
        }
        solver.push_board_touch(BoardTouch {
            body,
            normal: c.normal,
            point,
            velocity,
            piece: c.piece,
            restitution: 0.5 * (restitution + board.restitution),
            gap,
        });
    }
}

/// Adds to the solver the speculative board rows of a marble in the pair rows (`body`, at
/// `x` with velocity `v`, acceleration `a` and free path `d` over the substep): the pieces
/// it does not touch according to its recorded contacts but could reach during the
/// substep (its free path's approach plus what its acceleration alone could close, as for
/// a pair's speculative row, with the board's own motion; found through its
/// [`NearPieces`] list). Without them a marble a micrometre above the floor is free for
/// the solver, and a column resting on it falls for a substep and lands at `g h`. A piece
/// it touches that its recorded contacts lack (the first substep, or after a sleeping
/// marble's contacts were dropped) becomes an ordinary contact row (gap 0).
#[expect(clippy::too_many_arguments, reason = "a marble's state, handed over")]
fn speculative_touches(
    solver: &mut PairSolver,
    cache: &BoardCache,
    body: u32,
    (x, v, a, d): (Vec3, Vec3, Vec3, Vec3),
    r: f32,
    (contacts, more): (&Contacts, &MoreContacts),
    near: &NearPieces,
    restitution: f32,
    h: f32,
) {
    let reach = d.length() + a.length() * h * h;
    let touched = |piece| contact_iter(contacts, more).any(|c| c.piece == piece);
    near.within(
        cache,
        x,
        v,
        r,
        reach,
        h,
        touched,
        |piece, point, normal, gap| {
            let Some(board) = cache.boards.get(piece.board()) else {
                return;
            };
            let velocity = board.point_velocity(0.0, point);
            let closing = (-(d - velocity * h).dot(normal)).max(0.0) + a.length() * h * h;
            if gap <= closing {
                solver.push_board_touch(BoardTouch {
                    body,
                    normal,
                    point,
                    velocity,
                    piece,
                    restitution: 0.5 * (restitution + board.restitution),
                    gap: gap.max(0.0),
                });
            }
        },
    );
}

/// The displacement over the substep of a marble's free path along the boards it rests or
/// slides on, as the marble–board response will move it (what the broad phase bounds).
#[inline]
fn free_path(
    config: &StepConfig,
    h: f32,
    v: Vec3,
    a: Vec3,
    (contacts, more): (&Contacts, &MoreContacts),
) -> Vec3 {
    let (mut v, mut a) = (v, a);
    let (first, rest) = contact_slices(contacts, more);
    // The two slices one after the other, in the order recorded (the same operations as
    // over one list).
    for list in [first, rest] {
        for c in list {
            v -= v.dot(c.normal).min(0.0) * c.normal;
            a -= a.dot(c.normal).min(0.0) * c.normal;
        }
    }
    config.integrator.delta(v, a, h).0
}

/// Writes a body's position (by compensated summation of its move) and velocity back to
/// its marble.
fn write_back(
    compensated: bool,
    body: &Body,
    position: &mut Position,
    carry: &mut PositionCarry,
    velocity: &mut Velocity,
) {
    let moved = body.x - position.0;
    if moved != Vec3::ZERO {
        (position.0, carry.0) = compensated_add(compensated, position.0, carry.0, moved);
    }
    velocity.0 = body.v;
}

impl super::Rows for Gathered<'_> {
    fn len(&self) -> usize {
        Gathered::len(self)
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        Gathered::split_at(self, mid)
    }
}

/// What the contact stage (`PairContacts`) reads and writes of a marble.
#[derive(QueryData)]
#[query_data(mutable, contiguous(immutable))]
pub struct PairContactStaged {
    entity: Entity,
    position: &'static mut Position,
    carry: &'static mut PositionCarry,
    velocity: &'static mut Velocity,
    acceleration: &'static mut Acceleration,
    radius: &'static Radius,
    mass: &'static Mass,
    restitution: &'static Restitution,
    contacts: &'static Contacts,
    more: &'static MoreContacts,
    near: &'static NearPieces,
    spin: Option<&'static mut AngularVelocity>,
    friction: Option<&'static Friction>,
}

/// What the impact stage (`PairImpacts`) reads and writes of a marble.
#[derive(QueryData)]
#[query_data(mutable, contiguous(immutable))]
pub struct PairImpactStaged {
    entity: Entity,
    position: &'static mut Position,
    carry: &'static mut PositionCarry,
    velocity: &'static mut Velocity,
    start: &'static StepStart,
    radius: &'static Radius,
    mass: &'static Mass,
    restitution: &'static Restitution,
    contacts: &'static Contacts,
    more: &'static MoreContacts,
    acceleration: &'static Acceleration,
    near: &'static NearPieces,
}

/// First in the contact stage, when the board list has changed since its last substep (a
/// board added, removed or given another shape): the marbles' board contacts of the last
/// substep name their pieces by place in the old list, so they are dropped (detection
/// records this substep's afresh), and so are the impulses kept for warm starting
/// ([`PairSolver::boards_unchanged`]). The contact stage then finds the pieces each marble
/// touches through its speculative board rows, as in a first substep.
pub fn forget_stale_contacts(
    cache: Res<BoardCache>,
    mut solver: ResMut<PairSolver>,
    mut marbles: Query<&mut Contacts, Stepped>,
) {
    if solver.boards_unchanged(cache.epoch) {
        return;
    }
    for mut contacts in &mut marbles {
        contacts.clear();
    }
}

/// With `marble_collisions` off: no pair touches, so the touching pairs recorded while it
/// was on are dropped (events, diagnostics and replays read them), and the contact stage
/// starts afresh once it is on again ([`PairSolver::pause`]).
pub fn forget_pairs(mut recorded: ResMut<MarbleContacts>, mut solver: ResMut<PairSolver>) {
    if !recorded.list.is_empty() {
        recorded.list.clear();
    }
    solver.pause();
}

/// Before integration: the touching pairs of [`crate::pairs`] (collisions at the start,
/// contact forces added to the marbles' acceleration, overlap projected out). Runs only
/// with `marble_collisions` on.
pub fn pair_contacts(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    mut solver: ResMut<PairSolver>,
    mut recorded: ResMut<MarbleContacts>,
    mut marbles: Query<PairContactStaged, Stepped>,
) {
    let h = substep.h;
    let params = params(&config, h);
    let config = &*config;
    let solver = solver.as_mut();
    let n = marbles.iter().len();
    let parallel = super::on_pool(n);
    // 1. The broad phase first: marbles spread apart stop there.
    recorded.list.clear();
    solver.begin(n, &mut recorded);
    // Table by table, over the columns as slices (the order of the query's items); with
    // `parallel`, in chunks on the task pool.
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    for t in tables {
        let out = solver.gather_table(t.entity.len());
        let rows = (
            t.entity,
            (t.position, t.velocity, t.acceleration),
            (t.contacts, t.more, t.radius),
            out,
        );
        super::run_rows(
            rows,
            parallel,
            |(entities, (x, v, a), (contacts, more, r), out)| {
                let rows = x.iter().zip(v).zip(a).zip(contacts).zip(more).zip(r).map(
                    |(((((x, v), a), contacts), more), r)| {
                        let d = free_path(config, h, v.0, a.0, (contacts, more));
                        (PairSolver::contact_sphere(&params, x.0, d, r.0), r.0, d)
                    },
                );
                out.write_with_paths(entities, rows);
            },
        );
    }
    if !solver.cover_gathered(parallel) {
        solver.forget_contacts();
        return;
    }
    // 2. The bodies at the substep's start, each on the free path gathered with its
    // sphere: the marbles of the candidate pairs when they are few, else every marble (in
    // the same table order).
    solver.select_bodies();
    solver.clear_bodies();
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    if solver.selected().is_some() {
        let at = |t: &PairContactStagedReadOnlyContiguousItem<'_, '_>, i: usize| {
            let row = (
                &t.entity[i],
                &t.position[i],
                &t.velocity[i],
                &t.mass[i],
                &t.radius[i],
                &t.restitution[i],
                &t.acceleration[i],
            );
            let spin = t.spin.map(|w| w[i].0);
            let mu = t.friction.map_or(0.0, |f| f[i].0);
            contact_body(row, spin, mu, config.rolling)
        };
        push_selected(
            solver,
            tables,
            |t| t.entity.len(),
            at,
            PairSolver::push_body_on_free_path,
        );
    } else {
        // Every marble: the columns zipped, with no index checked per column.
        for t in tables {
            let rows = t
                .entity
                .iter()
                .zip(t.position)
                .zip(t.velocity)
                .zip(t.mass)
                .zip(t.radius)
                .zip(t.restitution)
                .zip(t.acceleration);
            for (i, ((((((entity, x), v), mass), r), e), a)) in rows.enumerate() {
                let spin = t.spin.map(|w| w[i].0);
                let mu = t.friction.map_or(0.0, |f| f[i].0);
                let row = (entity, x, v, mass, r, e, a);
                solver.push_body_on_free_path(contact_body(row, spin, mu, config.rolling));
            }
        }
    }
    if !solver.find_touching(&params) {
        return;
    }
    // 3. The board contacts of the bodies in the rows: the contact stage reads no other
    // marble's boards (its cascade and passes run on the rows' marbles).
    solver.begin_board_touches();
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    let mut rows = TableRows::new(tables, |t| t.entity.len());
    for body in 0..solver.chosen() {
        if !solver.in_rows(body) {
            solver.next_body_touches();
            continue;
        }
        let (t, i) = rows.seek(solver.marble_of(body));
        // The contacts were recorded during the last substep; its boards have since
        // moved on to this substep's start.
        let (e, r) = (t.restitution[i].0, t.radius[i].0);
        let b = solver.body(body);
        let x = b.x;
        let tol = touch_tolerance(config.contact_tolerance, r, x);
        let start = Some((x, r, tol, b.d, b.a));
        let contacts = (&t.contacts[i], &t.more[i]);
        board_touches(solver, &cache, body as u32, contacts, e, h, 0.0, start);
        let b = solver.body(body);
        let state = (b.x, b.v, b.a, b.d);
        let near = &t.near[i];
        speculative_touches(solver, &cache, body as u32, state, r, contacts, near, e, h);
    }
    solver.end_board_touches();
    // 4. Solve, and write back what changed: a selection's bodies found by entity, every
    // marble's in order.
    solver.solve_touching(&params, &mut recorded);
    let write = |body: &Body, m: &mut PairContactStagedItem<'_, '_>| {
        write_back(
            config.compensated,
            body,
            &mut m.position,
            &mut m.carry,
            &mut m.velocity,
        );
        m.acceleration.0 = body.a;
        if body.spins
            && let Some(spin) = m.spin.as_mut()
        {
            spin.0 = body.omega;
        }
    };
    if solver.selected().is_some() {
        for k in 0..solver.chosen() {
            if let Some(body) = solver.changed_body(k) {
                let mut m = marbles
                    .get_mut(body.entity)
                    .expect("a body's marble is stepped");
                write(body, &mut m);
            }
        }
    } else {
        for (k, mut m) in (0usize..).zip(&mut marbles) {
            if let Some(body) = solver.changed_body(k) {
                write(body, &mut m);
            }
        }
    }
}

/// Phase 2 for the marbles [`PairSolver::selected`], in order: `push` the body
/// `body(table, row)` of each, its table and row found among `tables` (`len_of`: a
/// table's number of rows).
fn push_selected<T>(
    solver: &mut PairSolver,
    tables: impl Iterator<Item = T>,
    len_of: impl Fn(&T) -> usize,
    body: impl Fn(&T, usize) -> Body,
    push: fn(&mut PairSolver, Body),
) {
    let mut rows = TableRows::new(tables, len_of);
    for k in 0..solver.chosen() {
        let (t, i) = rows.seek(solver.marble_of(k));
        push(solver, body(t, i));
    }
}

/// The tables of a query's contiguous iteration, walked to the rows of ascending marble
/// indices (counted over the tables in order).
struct TableRows<T, I, L> {
    tables: I,
    table: Option<T>,
    /// Index of the current table's first marble, and its length.
    first: usize,
    len: usize,
    len_of: L,
}

impl<T, I: Iterator<Item = T>, L: Fn(&T) -> usize> TableRows<T, I, L> {
    fn new(tables: I, len_of: L) -> Self {
        TableRows {
            tables,
            table: None,
            first: 0,
            len: 0,
            len_of,
        }
    }

    /// The table and row of marble `m` (not before the last one sought).
    #[inline]
    fn seek(&mut self, m: usize) -> (&T, usize) {
        while m >= self.first + self.len || self.table.is_none() {
            self.first += self.len;
            let table = self.tables.next().expect("marble index within the tables");
            self.len = (self.len_of)(&table);
            self.table = Some(table);
        }
        let table = self.table.as_ref().expect("a table");
        (table, m - self.first)
    }
}

/// After the marble–board response: pairs of [`crate::pairs`] that meet during the
/// substep collide at their time of impact. Runs only with `marble_collisions` on.
pub fn pair_impacts(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    mut solver: ResMut<PairSolver>,
    mut recorded: ResMut<MarbleContacts>,
    mut marbles: Query<PairImpactStaged, Stepped>,
) {
    let h = substep.h;
    let params = params(&config, h);
    let solver = solver.as_mut();
    // 1. The broad phase first, on the paths the marbles took: marbles spread apart stop
    // there. Table by table; with `parallel`, in chunks on the task pool.
    let n = marbles.iter().len();
    let parallel = super::on_pool(n);
    solver.begin(n, &mut recorded);
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    for t in tables {
        let out = solver.gather_table(t.entity.len());
        let rows = (t.entity, t.start, t.position, t.radius, out);
        super::run_rows(rows, parallel, |(entities, start, x, r, out)| {
            let rows = start.iter().zip(x).zip(r).map(|((s, x), r)| {
                let sphere = PairSolver::impact_sphere(&params, s.position, x.0, r.0);
                (sphere, r.0)
            });
            out.write(entities, rows);
        });
    }
    if !solver.cover_gathered(parallel) {
        return;
    }
    // 2. The bodies: where each marble started the substep and where it ended. The
    // marbles of the candidate pairs first, when they are few, to look for a deep
    // impact; once one is found every marble, since what follows may reach any.
    solver.select_bodies();
    solver.clear_bodies();
    if solver.selected().is_some() {
        let tables = marbles
            .contiguous_iter()
            .expect("a marble's components are stored in tables");
        let at = |t: &PairImpactStagedReadOnlyContiguousItem<'_, '_>, i: usize| {
            impact_body((
                &t.entity[i],
                &t.position[i],
                &t.start[i],
                &t.velocity[i],
                &t.mass[i],
                &t.radius[i],
                &t.restitution[i],
            ))
        };
        push_selected(
            solver,
            tables,
            |t| t.entity.len(),
            at,
            PairSolver::push_body,
        );
    } else {
        push_every_body(solver, &marbles);
    }
    if !solver.any_deep_impact(&params) {
        return;
    }
    if solver.select_every_marble_for_impacts() {
        solver.clear_bodies();
        push_every_body(solver, &marbles);
    }
    solver.find_impacts(&params);
    // 3. Every marble's board contacts of this substep; where it would have got without
    // its boards, and when one first changed its path (a touch found after the substep's
    // start).
    solver.begin_board_touches();
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    let mut body = 0u32;
    for t in tables {
        let rows = t
            .start
            .iter()
            .zip(t.acceleration)
            .zip(t.contacts)
            .zip(t.more)
            .zip(t.restitution);
        for ((((start, a), contacts), more), e) in rows {
            let after = contact_iter(contacts, more)
                .map(|c| c.time)
                .filter(|&t| t > 0.0)
                .fold(f32::INFINITY, f32::min);
            let (dx, dv) = config.integrator.delta(start.velocity, a.0, h);
            solver.push_free_end(after, start.position + dx, start.velocity + dv);
            board_touches(solver, &cache, body, (contacts, more), e.0, h, h, None);
            body += 1;
        }
    }
    solver.end_board_touches();
    // 4. Collide, and write back what changed.
    // (Detection left every marble's list fresh for this substep, or empty.)
    let near = |entity| marbles.get(entity).ok().map(|m| m.near);
    solver.resolve_impacts(&params, &cache.boards, &near, &mut recorded);
    for (k, mut m) in (0usize..).zip(&mut marbles) {
        let Some(body) = solver.changed_body(k) else {
            continue;
        };
        write_back(
            config.compensated,
            body,
            &mut m.position,
            &mut m.carry,
            &mut m.velocity,
        );
    }
}

/// One marble's columns that make its body in the contact stage: entity, position,
/// velocity, mass, radius, restitution, acceleration.
type ContactBodyRow<'a> = (
    &'a Entity,
    &'a Position,
    &'a Velocity,
    &'a Mass,
    &'a Radius,
    &'a Restitution,
    &'a Acceleration,
);

/// A marble's body in the contact stage, from its row's columns, and its spin and
/// friction when it has them (`rolling`: spin and friction are on).
#[inline(always)]
fn contact_body(
    (&entity, x, v, mass, r, e, a): ContactBodyRow<'_>,
    spin: Option<Vec3>,
    mu: f32,
    rolling: bool,
) -> Body {
    Body {
        entity,
        x: x.0,
        x0: x.0,
        v: v.0,
        v0: v.0,
        w: mass.inverse(),
        r: r.0,
        e: e.0,
        a: a.0,
        d: Vec3::ZERO,
        omega: spin.unwrap_or(Vec3::ZERO),
        spins: rolling && spin.is_some(),
        mu,
    }
}

/// One marble's columns that make its body in the impact stage: entity, position, the
/// substep's start, velocity, mass, radius, restitution.
type ImpactBodyRow<'a> = (
    &'a Entity,
    &'a Position,
    &'a StepStart,
    &'a Velocity,
    &'a Mass,
    &'a Radius,
    &'a Restitution,
);

/// A marble's body in the impact stage: where it started the substep and where it ended.
#[inline(always)]
fn impact_body((&entity, x, start, v, mass, r, e): ImpactBodyRow<'_>) -> Body {
    Body {
        entity,
        x: x.0,
        x0: start.position,
        v: v.0,
        v0: start.velocity,
        w: mass.inverse(),
        r: r.0,
        e: e.0,
        a: Vec3::ZERO,
        d: Vec3::ZERO,
        omega: Vec3::ZERO,
        spins: false,
        mu: 0.0,
    }
}

/// Phase 2 of the impact stage for every marble, in order, table by table: the columns
/// zipped, with no index checked per column.
fn push_every_body(solver: &mut PairSolver, marbles: &Query<PairImpactStaged, Stepped>) {
    let tables = marbles
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    for t in tables {
        let rows = t
            .entity
            .iter()
            .zip(t.position)
            .zip(t.start)
            .zip(t.velocity)
            .zip(t.mass)
            .zip(t.radius)
            .zip(t.restitution);
        for ((((((entity, x), start), v), mass), r), e) in rows {
            solver.push_body(impact_body((entity, x, start, v, mass, r, e)));
        }
    }
}
