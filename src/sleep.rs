//! Sleeping: marbles that have stopped are left out of the step until something wakes
//! them ([`StepConfig::sleep`], scene fields `sleep_speed` and `sleep_time`; off by
//! default).
//!
//! # Falling asleep
//! At the end of each step, before the forces are cleared ([`fall_asleep`]), every awake
//! marble that is slow (speed, and spin times radius when it spins, below
//! [`Sleep::speed`]), pushed by no program force, touching no moving board and out of
//! reach of every moving board (below) adds the step to its [`Drowsy`] time; any other
//! marble starts again from zero. Nothing is slow while gravity turns ([`GravityTilt`]
//! with an angular velocity). With `marble_collisions` on, the marbles are grouped
//! (union–find) by the relation that wakes them, below: two marbles are in one group when
//! either could reach the other during the next step. A group sleeps when every one of its
//! marbles has been slow for [`Sleep::time`] (within half a step: the sum of f32 steps may
//! fall short by a rounding): each gets [`Sleeping`], its velocity and spin are set to
//! zero, and every stage skips it (as it skips [`Quarantined`] marbles). A pile therefore
//! sleeps as a whole, never a marble under a neighbour still settling onto it, and no
//! awake marble is within reach of a group that falls asleep. Without marble collisions
//! each marble is its own group.
//!
//! # Waking
//! At the start of each step ([`wake`]) a sleeping marble wakes when
//! - the program gave it a velocity, spin or force, moved it or changed its radius (or
//!   removed its [`Sleeping`]);
//! - a board that moves or turns, or was moved, added, removed or reshaped since the last
//!   step, comes within a radius of it (the board's bounds swept over the substep, grown by
//!   how far it moves in the rest of the step; for a moved board also where it was);
//! - gravity changed, or turns;
//! - with `marble_collisions` on, an awake marble, or one that wakes, could reach it during
//!   the step. A marble's *reach* is its radius, plus one more radius, plus everywhere its
//!   free path can take it in one step at its speed raised by the fastest *knock* a
//!   collision could give it this step: twice the fastest awake or waking marble's speed
//!   plus the fastest board surface's (a marble struck by a heavier one leaves at up to
//!   `(1 + e)` times the striker's speed). Waking therefore spreads through a group.
//! - sleeping is turned off: every sleeping marble wakes.
//!
//! A woken marble keeps the velocity the program gave it (zero otherwise) and starts its
//! [`Drowsy`] time from zero; when a board moved, came or went, its board contacts from
//! before are dropped. The contact impulses its group carried when it fell asleep are kept
//! and warm start its first substep awake, so a settled pile woken as it lies holds its
//! weight at once instead of sagging while the impulses build up again.
//!
//! A step whose [`wake`] finds a still world (every marble asleep, none woken, no board
//! moving, gravity not turning: [`SleepState::is_idle`]) runs only its first substep
//! ([`crate::schedule::run_step`]): the others would find nothing to do. The stages that
//! end a step run in it all the same, so sensors added, moved or removed around sleeping
//! marbles are reported at once.
//!
//! What sleeping costs in accuracy: a marble slower than the threshold for [`Sleep::time`]
//! (a very slow roll on a level board, the last settling of a pile) stops where it is; one
//! above it never sleeps. A knock larger than the bound above (a chain of ever lighter
//! marbles, each struck by a heavier one) could still carry a marble into a sleeping one
//! within a step; it is then woken at the next step, overlapping, and the contact stage
//! pushes the two apart. The tests in `tests/sleep.rs` check when marbles fall asleep,
//! that a settled pile asleep stays bit for bit where it is, and each way of waking.
use bevy_ecs::prelude::*;
#[cfg(feature = "bevy")]
use bevy_ecs::reflect::ReflectComponent;
use glam::{Vec3, Vec4};
use parry3d::bounding_volume::Aabb;

#[cfg(doc)]
use crate::components::Quarantined;
#[cfg(doc)]
use crate::config::{GravityTilt, Sleep, StepConfig};
use crate::pairs::{Grid, StowedImpulses};
#[cfg(doc)]
use crate::systems::sleep::{fall_asleep, wake};

/// The `on_remove` hook of [`Sleeping`]: the marble woke (by [`wake`] or by hand) or was
/// despawned asleep. Noted for the next step's [`wake`] (its slow time starts again, its
/// kept contact impulses go back to the solver) whenever that runs: a hook, unlike bevy's
/// removal buffers, keeps it however many frames pass without a physics step.
fn note_woken(
    mut world: bevy_ecs::world::DeferredWorld,
    context: bevy_ecs::lifecycle::HookContext,
) {
    if let Some(mut state) = world.get_resource_mut::<SleepState>() {
        state.woke.push(context.entity);
    }
}

/// The `on_remove` hook of [`Marble`](crate::components::Marble): a sleeping marble
/// despawned, or made no longer a marble, is noted where it slept, so that the marbles
/// resting on it wake at the next step.
pub(crate) fn note_removed_sleeper(
    mut world: bevy_ecs::world::DeferredWorld,
    context: bevy_ecs::lifecycle::HookContext,
) {
    let Some(&Sleeping { position, radius }) = world.get::<Sleeping>(context.entity) else {
        return;
    };
    if let Some(mut state) = world.get_resource_mut::<SleepState>() {
        state.removed.push(position.extend(radius));
    }
}

/// A marble asleep: every stage skips it until something wakes it (module docs). Remove
/// it to wake the marble by hand.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
#[component(on_remove = note_woken)]
pub struct Sleeping {
    /// Where the marble fell asleep: moved elsewhere, it wakes.
    pub(crate) position: Vec3,
    /// Its radius then: given another, it wakes.
    pub(crate) radius: f32,
}

impl Sleeping {
    /// Where the marble fell asleep.
    pub fn position(&self) -> Vec3 {
        self.position
    }
}

/// How long a marble has been slow, s (module docs). Added to a marble by the first step
/// that looks at it with sleeping on.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Drowsy(pub f32);
/// The sleep stages' state (a resource): the sleeping marbles' spheres in a grid, what
/// the boards and gravity were at the last step, and reusable buffers.
#[derive(Resource, Default, Debug)]
pub struct SleepState {
    /// The sleeping marbles' spheres (centre, radius) and entities.
    pub(crate) spheres: Vec<Vec4>,
    pub(crate) entities: Vec<Entity>,
    pub(crate) grid: Grid,
    /// Boards that reach marbles this step: swept bounds (`None`: unbounded) and the
    /// distance they move on over the rest of the step; and of those, the boards that move.
    pub(crate) reaching: Vec<(Option<Aabb>, f32)>,
    pub(crate) moving: Vec<(Option<Aabb>, f32)>,
    /// Gravity as the marbles saw it at the last step, and whether marble collisions and
    /// rolling were on.
    pub(crate) gravity: Option<Vec3>,
    pub(crate) switches: Option<(bool, bool)>,
    /// The board cache's epoch at the last step.
    pub(crate) epoch: u32,
    /// Each board's entity, pose version and swept bounds at the last step.
    pub(crate) poses: Vec<(Entity, u32, Option<Aabb>)>,
    /// Sleeping marbles woken this step (indices into `spheres`) and the search queue.
    pub(crate) woken: Vec<bool>,
    pub(crate) queue: Vec<u32>,
    /// The awake marbles' reach spheres (centre, reach), their union–find parents and
    /// whether each is ready to sleep, at the end of a step.
    pub(crate) bounds: Vec<Vec4>,
    pub(crate) parent: Vec<u32>,
    pub(crate) ready: Vec<bool>,
    pub(crate) group_ready: Vec<bool>,
    /// The sleeping marbles' contact impulses, kept for when they wake, and the entity
    /// bits of the marbles falling asleep or waking (sorted).
    pub(crate) impulses: StowedImpulses,
    pub(crate) keys: Vec<u64>,
    /// Sleeping marbles despawned (or no longer marbles) since the last step, where they
    /// slept (centre, radius): the marbles resting on them wake.
    pub(crate) removed: Vec<Vec4>,
    /// Set by [`wake`]: every marble sleeps, nothing woke, no board moves and gravity
    /// holds still, so the rest of the step's substeps would do nothing ([`run_step`]
    /// skips them).
    ///
    /// [`run_step`]: crate::schedule::run_step
    pub(crate) idle: bool,
    /// How many times a step has put marbles to sleep (wrapping).
    pub(crate) naps: u32,
    /// Marbles whose `Sleeping` went since the last step ([`note_woken`]).
    pub(crate) woke: Vec<Entity>,
}

impl SleepState {
    /// True when this step's [`wake`] found a still world: every marble asleep, none woken,
    /// no board moving and gravity not turning.
    pub fn is_idle(&self) -> bool {
        self.idle
    }
}
