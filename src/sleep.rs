//! Sleeping: marbles that have stopped are left out of the step until something wakes
//! them ([`StepConfig::sleep`], scene fields `sleep_speed` and `sleep_time`; off by
//! default).
//!
//! # Falling asleep
//! At the end of each step ([`fall_asleep`]) every awake marble that is slow (speed, and
//! spin times radius when it spins, below [`Sleep::speed`]), pushed by no user force and
//! touching no moving board adds the step to its [`Drowsy`] time; any other marble starts
//! again from zero. With `marble_collisions` on, the marbles are grouped (union–find) by
//! the relation that wakes them, below: two marbles are in one group when either could
//! reach the other during the next step. A group sleeps when every one of its marbles has
//! been slow for [`Sleep::time`]: each gets [`Sleeping`], its velocity and spin are set to
//! zero, and every stage skips it (as it skips [`Quarantined`] marbles). A pile therefore
//! sleeps as a whole, never a marble under a neighbour that is still settling onto it, and
//! no awake marble is within reach of a group that falls asleep. Without marble
//! collisions each marble is its own group. Nothing sleeps while gravity turns
//! ([`GravityTilt`] with an angular velocity).
//!
//! # Waking
//! At the start of each step ([`wake`]) a sleeping marble wakes when
//! - its velocity, spin or force is no longer zero, or its position is not where it fell
//!   asleep (a program moved it);
//! - a board that moves, turns, was moved, or was added, removed or reshaped since the last
//!   step comes within a radius of it (the board's bounds swept over the step);
//! - gravity changed;
//! - with `marble_collisions` on, an awake marble, or one that wakes, could reach it during
//!   the step: the marble's *reach*, its radius plus everywhere its free path can take it
//!   in one step (`|v| dt + ½|a| dt²`) plus one more radius for the knocks of collisions,
//!   meets it. Waking therefore spreads through a sleeping group.
//!
//! A woken marble starts from rest and its [`Drowsy`] time from zero. The contact solver's
//! warm start is not kept over sleep: a woken pile's impulses build up again over the first
//! substeps, as when it first settled.
//!
//! What sleeping costs in accuracy: a marble slower than the threshold is stopped. A
//! marble creeping at less than [`Sleep::speed`] for [`Sleep::time`] (a very slow roll on
//! a level board, the last settling of a pile) stops where it is; one above it never
//! sleeps. The tests in `tests/sleep.rs` check when marbles fall asleep, that a settled
//! pile asleep stays bit for bit where it is, and each way of waking.

use bevy_ecs::prelude::*;
use glam::{Vec3, Vec4};
use parry3d::bounding_volume::Aabb;

use crate::components::{
    AngularVelocity, Contacts, Force, Marble, Mass, Position, Quarantined, Radius, Velocity,
};
use crate::config::{GravityTilt, Sleep, StepConfig, SubstepCounter};
use crate::narrow::BoardCache;
use crate::pairs::Grid;

/// A marble asleep: every stage skips it until something wakes it (module docs). Remove
/// it to wake the marble by hand.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Sleeping {
    /// Where the marble fell asleep: moved elsewhere, it wakes.
    position: Vec3,
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
pub struct Drowsy(pub f32);

/// How far from its centre a marble could reach during a step of `dt` (module docs): its
/// radius, its free path's farthest point and one more radius.
#[inline]
fn reach(r: f32, v: Vec3, a: Vec3, dt: f32) -> f32 {
    2.0 * r + v.length() * dt + 0.5 * a.length() * dt * dt
}

/// The sleep stages' state (a resource): the sleeping marbles' spheres in a grid, what
/// the boards and gravity were at the last step, and reusable buffers.
#[derive(Resource, Default, Debug)]
pub struct SleepState {
    /// The sleeping marbles' spheres (centre, radius) and entities, when `fresh`.
    spheres: Vec<Vec4>,
    entities: Vec<Entity>,
    grid: Grid,
    /// Boards that reach marbles this step: swept bounds (`None`: unbounded) and margin.
    reaching: Vec<(Option<Aabb>, f32)>,
    /// Gravity as the marbles saw it at the last step.
    gravity: Option<Vec3>,
    /// The board cache's epoch and each board's pose version at the last step.
    epoch: u32,
    /// Each board's entity, pose version and swept bounds at the last step.
    poses: Vec<(Entity, u32, Option<Aabb>)>,
    /// Sleeping marbles woken this step (indices into `spheres`) and the search queue.
    woken: Vec<bool>,
    queue: Vec<u32>,
    /// The awake marbles' reach spheres (centre, reach), their union–find parents and
    /// whether each is ready to sleep, at the end of a step.
    bounds: Vec<Vec4>,
    parent: Vec<u32>,
    ready: Vec<bool>,
    group_ready: Vec<bool>,
}

/// Run condition: sleeping is on.
pub fn sleep_on(config: Res<StepConfig>) -> bool {
    config.sleep.is_some()
}

/// Run condition: the first substep of a step.
pub fn first_substep(counter: Res<SubstepCounter>) -> bool {
    counter.index == 0
}

/// Gravity as the marbles see it (turned back by a [`GravityTilt`]).
fn seen_gravity(config: &StepConfig, tilt: Option<&GravityTilt>) -> Vec3 {
    tilt.map_or(config.gravity, |t| t.gravity(config.gravity))
}

/// True while gravity turns every step.
fn gravity_turns(tilt: Option<&GravityTilt>) -> bool {
    tilt.is_some_and(|t| t.angular_velocity != Vec3::ZERO)
}

/// A sleeping marble the program has given a velocity, spin or force, or moved.
fn changed_by_program(
    sleeping: &Sleeping,
    position: &Position,
    velocity: &Velocity,
    force: &Force,
    spin: Option<&AngularVelocity>,
) -> bool {
    position.0 != sleeping.position
        || velocity.0 != Vec3::ZERO
        || force.0 != Vec3::ZERO
        || spin.is_some_and(|w| w.0 != Vec3::ZERO)
}

/// First substep of each step, after the boards' snapshot: wakes the sleeping marbles that
/// something reaches (module docs, "Waking").
pub fn wake(
    mut commands: Commands,
    (config, tilt, cache): (Res<StepConfig>, Option<Res<GravityTilt>>, Res<BoardCache>),
    mut state: ResMut<SleepState>,
    mut sleepers: Query<
        (
            Entity,
            &Sleeping,
            &Position,
            &Velocity,
            &Force,
            &Mass,
            &Radius,
            Option<&AngularVelocity>,
            Option<&mut Drowsy>,
        ),
        (With<Marble>, Without<Quarantined>),
    >,
    awake: Query<
        (&Position, &Velocity, &Force, &Mass, &Radius),
        (With<Marble>, Without<Sleeping>, Without<Quarantined>),
    >,
    changed: Query<
        (
            &Sleeping,
            &Position,
            &Velocity,
            &Force,
            Option<&AngularVelocity>,
        ),
        (
            With<Marble>,
            Without<Quarantined>,
            Or<(
                Changed<Position>,
                Changed<Velocity>,
                Changed<Force>,
                Changed<AngularVelocity>,
            )>,
        ),
    >,
) {
    let state = state.as_mut();
    let g = seen_gravity(&config, tilt.as_deref());
    let gravity_changed = state.gravity.is_some_and(|old| old != g);
    state.gravity = Some(g);
    // Boards that move, turn, or were moved since the last step: their swept bounds, and
    // where a moved board was (`None`: unbounded, it reaches everything). A board added,
    // removed or reshaped reaches everything.
    let dt = config.dt;
    state.reaching.clear();
    if cache.epoch != state.epoch {
        state.reaching.push((None, 0.0));
    }
    for b in &cache.boards {
        let last = state.poses.iter().find(|p| p.0 == b.entity);
        let moved = last.is_some_and(|p| p.1 != b.pose_version);
        if b.is_moving() || moved {
            // The snapshot sweeps one substep; the board moves on for the rest of the step.
            let sweep = (b.velocity.length() + b.angular_velocity.length() * b.reach) * dt;
            state.reaching.push((b.swept_aabb, sweep));
        }
        if let Some(&(_, _, before)) = last.filter(|_| moved) {
            state.reaching.push((before, 0.0));
        }
    }
    state.epoch = cache.epoch;
    state.poses.clear();
    state.poses.extend(
        cache
            .boards
            .iter()
            .map(|b| (b.entity, b.pose_version, b.swept_aabb)),
    );
    let n = sleepers.iter().len();
    if n == 0 {
        return;
    }
    // The stages never write to a sleeping marble, so only one the program changed since
    // the last step can have woken by itself; with no board, no gravity and no awake
    // marble to reach the others, a still world stops here.
    let reached = gravity_changed
        || !state.reaching.is_empty()
        || (config.marble_collisions && !awake.is_empty());
    if !reached
        && !changed
            .iter()
            .any(|(s, x, v, f, w)| changed_by_program(s, x, v, f, w))
    {
        return;
    }
    // Every sleeping marble, in query order, with what wakes it by itself.
    state.spheres.clear();
    state.entities.clear();
    state.woken.clear();
    state.queue.clear();
    for (entity, sleeping, position, velocity, force, _, radius, spin, _) in &sleepers {
        let x = position.0;
        let r = radius.0;
        let k = state.spheres.len() as u32;
        state.spheres.push(x.extend(r));
        state.entities.push(entity);
        let moved = changed_by_program(sleeping, position, velocity, force, spin);
        let reached = gravity_changed
            || state.reaching.iter().any(|(aabb, sweep)| {
                aabb.is_none_or(|a| {
                    let margin = Vec3::splat(sweep + 2.0 * r);
                    let (lo, hi) = (a.mins - margin, a.maxs + margin);
                    x.cmpge(lo).all() && x.cmple(hi).all()
                })
            });
        let wakes = moved || reached;
        state.woken.push(wakes);
        if wakes {
            state.queue.push(k);
        }
    }
    if config.marble_collisions && (!awake.is_empty() || !state.queue.is_empty()) {
        // Awake marbles that could reach a sleeping one during the step, and the
        // neighbours of every marble that wakes.
        state.grid.reserve(n);
        let (grid, spheres) = (&mut state.grid, &state.spheres);
        grid.build(spheres);
        for (position, velocity, force, mass, radius) in &awake {
            let a = g + force.0 * mass.inverse();
            let probe = position.0.extend(reach(radius.0, velocity.0, a, dt));
            grid.query(spheres, probe, |k| {
                if !state.woken[k as usize] {
                    state.woken[k as usize] = true;
                    state.queue.push(k);
                }
            });
        }
        // A marble that wakes starts from rest.
        let mut head = 0;
        while head < state.queue.len() {
            let k = state.queue[head] as usize;
            head += 1;
            let Ok((.., force, mass, radius, _, _)) = sleepers.get(state.entities[k]) else {
                continue;
            };
            let a = g + force.0 * mass.inverse();
            let probe = spheres[k]
                .truncate()
                .extend(reach(radius.0, Vec3::ZERO, a, dt));
            grid.query(spheres, probe, |k| {
                if !state.woken[k as usize] {
                    state.woken[k as usize] = true;
                    state.queue.push(k);
                }
            });
        }
    }
    if state.queue.is_empty() {
        return;
    }
    for &k in &state.queue {
        let entity = state.entities[k as usize];
        commands.entity(entity).remove::<Sleeping>();
        if let Ok((.., Some(mut drowsy))) = sleepers.get_mut(entity) {
            drowsy.0 = 0.0;
        }
    }
}

/// Last substep of each step, after the quarantine: adds the step to each slow marble's
/// [`Drowsy`] time and puts to sleep every touching group whose marbles have all been slow
/// for [`Sleep::time`] (module docs, "Falling asleep").
pub fn fall_asleep(
    mut commands: Commands,
    config: Res<StepConfig>,
    tilt: Option<Res<GravityTilt>>,
    cache: Res<BoardCache>,
    mut state: ResMut<SleepState>,
    mut marbles: Query<
        (
            Entity,
            &Position,
            &mut Velocity,
            &Force,
            &Mass,
            &Radius,
            &Contacts,
            Option<&mut AngularVelocity>,
            Option<&mut Drowsy>,
        ),
        (With<Marble>, Without<Sleeping>, Without<Quarantined>),
    >,
) {
    let Some(Sleep { speed, time }) = config.sleep else {
        return;
    };
    if gravity_turns(tilt.as_deref()) {
        return;
    }
    let state = state.as_mut();
    let dt = config.dt;
    let g = seen_gravity(&config, tilt.as_deref());
    let mut any = false;
    state.ready.clear();
    state.bounds.clear();
    for (entity, position, velocity, force, mass, radius, contacts, spin, drowsy) in &mut marbles {
        let a = g + force.0 * mass.inverse();
        state
            .bounds
            .push(position.0.extend(reach(radius.0, velocity.0, a, dt)));
        let spin_speed = spin.as_ref().map_or(0.0, |w| w.0.length() * radius.0);
        let on_moving_board = contacts.iter().any(|c| {
            cache
                .boards
                .get(c.piece.board())
                .is_some_and(|b| b.is_moving())
        });
        let slow = velocity.0.length() < speed
            && spin_speed < speed
            && force.0 == Vec3::ZERO
            && !on_moving_board;
        let t = match drowsy {
            Some(mut d) => {
                d.0 = if slow { d.0 + dt } else { 0.0 };
                d.0
            }
            None => {
                let t = if slow { dt } else { 0.0 };
                commands.entity(entity).insert(Drowsy(t));
                t
            }
        };
        let ready = t >= time;
        any |= ready;
        state.ready.push(ready);
    }
    if !any {
        return;
    }
    // Groups: union–find over the pairs within each other's reach.
    let n = state.bounds.len();
    state.parent.clear();
    state.parent.extend(0..n as u32);
    fn root(parent: &mut [u32], mut k: u32) -> u32 {
        while parent[k as usize] != k {
            let up = parent[parent[k as usize] as usize];
            parent[k as usize] = up;
            k = up;
        }
        k
    }
    if config.marble_collisions {
        state.grid.reserve(n);
        state.grid.build(&state.bounds);
        let (grid, parent) = (&state.grid, &mut state.parent);
        grid.pairs(&state.bounds, |a, b| {
            let (ra, rb) = (root(parent, a), root(parent, b));
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        });
    }
    // A group is ready when every one of its marbles is: clear the roots of groups with
    // a marble that is not.
    state.group_ready.clear();
    state.group_ready.resize(n, true);
    for k in 0..n {
        if !state.ready[k] {
            let r = root(&mut state.parent, k as u32);
            state.group_ready[r as usize] = false;
        }
    }
    for (k, (entity, position, mut velocity, .., spin, _)) in marbles.iter_mut().enumerate() {
        let r = root(&mut state.parent, k as u32);
        if !(state.ready[k] && state.group_ready[r as usize]) {
            continue;
        }
        velocity.0 = Vec3::ZERO;
        if let Some(mut spin) = spin {
            spin.0 = Vec3::ZERO;
        }
        commands.entity(entity).insert(Sleeping {
            position: position.0,
        });
    }
}
