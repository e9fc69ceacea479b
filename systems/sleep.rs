//! Sleeping's two systems ([`crate::sleep`]): waking, in the first substep's
//! `Wake` stage, and falling asleep, in the last substep's `FallAsleep` stage.

use bevy_ecs::prelude::*;
use glam::Vec3;
use parry3d::bounding_volume::Aabb;

use crate::board_contact::{BoardCache, BoardSnapshot};
use crate::components::{
    AngularVelocity, BoardContacts, Contacts, Force, Marble, Mass, Position, Quarantined, Radius,
    Velocity,
};
use crate::config::{GravityTilt, Sleep, StepConfig, Substep};
use crate::pairs::PairSolver;
use crate::sleep::{Drowsy, SleepState, Sleeping};

/// How far from its centre a marble could reach during a step of `dt` ([`crate::sleep`]): its
/// radius, one more radius, and its free path's farthest point at its speed `v` raised by
/// the fastest knock `knock` a collision could give it.
#[inline]
fn reach(r: f32, v: Vec3, a: Vec3, knock: f32, dt: f32) -> f32 {
    2.0 * r + (v.length() + knock) * dt + 0.5 * a.length() * dt * dt
}

/// The fastest knock a collision could give a marble this step: twice the fastest awake
/// marble's speed `fastest` plus the fastest board surface ([`crate::sleep`]).
fn knock(fastest: f32, boards: &[BoardSnapshot]) -> f32 {
    let board = boards
        .iter()
        .map(|b| {
            // A turning plane (unbounded) wakes every marble anyway.
            let turn = b.angular_velocity.length() * b.reach;
            b.velocity.length() + if turn.is_finite() { turn } else { 0.0 }
        })
        .fold(0.0f32, f32::max);
    2.0 * (fastest + board)
}

/// Whether one of the boards that reach marbles this step (`reaching`: swept bounds,
/// `None` for unbounded, and the distance they move on) comes within a radius of a marble
/// of radius `r` at `x`.
fn reached_by_board(reaching: &[(Option<Aabb>, f32)], x: Vec3, r: f32) -> bool {
    reaching.iter().any(|(aabb, sweep)| {
        aabb.is_none_or(|a| {
            let margin = Vec3::splat(sweep + 2.0 * r);
            let (lo, hi) = (a.mins - margin, a.maxs + margin);
            x.cmpge(lo).all() && x.cmple(hi).all()
        })
    })
}
/// Run condition: sleeping is on.
pub fn sleep_on(config: Res<StepConfig>) -> bool {
    config.sleep.is_some()
}

/// Run condition: the first substep of a step.
pub fn first_substep(substep: Res<Substep>) -> bool {
    substep.is_first()
}

/// Gravity as the marbles see it (turned back by a [`GravityTilt`]).
fn seen_gravity(config: &StepConfig, tilt: Option<&GravityTilt>) -> Vec3 {
    tilt.map_or(config.gravity, |t| t.gravity(config.gravity))
}

/// True while gravity turns every step.
fn gravity_turns(tilt: Option<&GravityTilt>) -> bool {
    tilt.is_some_and(|t| t.angular_velocity != Vec3::ZERO)
}

/// A sleeping marble the program has given a velocity, spin or force, moved or resized.
fn changed_by_program(
    sleeping: &Sleeping,
    (position, velocity, force, radius): (&Position, &Velocity, &Force, &Radius),
    spin: Option<&AngularVelocity>,
) -> bool {
    position.0 != sleeping.position
        || radius.0 != sleeping.radius
        || velocity.0 != Vec3::ZERO
        || force.0 != Vec3::ZERO
        || spin.is_some_and(|w| w.0 != Vec3::ZERO)
}

/// First substep of each step, after the boards' snapshot: wakes the sleeping marbles that
/// something reaches ([`crate::sleep`], "Waking"); with sleeping off, wakes every sleeping
/// marble. Runs with sleeping off too, so that marbles asleep when it was turned off
/// wake; it stops at once when none sleeps.
pub fn wake(
    mut commands: Commands,
    (config, tilt, cache): (Res<StepConfig>, Option<Res<GravityTilt>>, Res<BoardCache>),
    (mut state, mut solver): (ResMut<SleepState>, ResMut<PairSolver>),
    quarantined: Query<&Sleeping, (With<Marble>, Added<Quarantined>)>,
    mut sleepers: Query<
        (
            Entity,
            &Sleeping,
            (&Position, &Velocity, &Force, &Radius),
            &Mass,
            &mut Contacts,
            Option<&AngularVelocity>,
            Option<&mut Drowsy>,
        ),
        (With<Marble>, Without<Quarantined>),
    >,
    mut awake: Query<
        (
            &Position,
            &Velocity,
            &Force,
            &Mass,
            &Radius,
            Option<&mut Drowsy>,
        ),
        (With<Marble>, Without<Sleeping>, Without<Quarantined>),
    >,
    changed: Query<
        (
            &Sleeping,
            (&Position, &Velocity, &Force, &Radius),
            Option<&AngularVelocity>,
        ),
        (
            With<Marble>,
            Without<Quarantined>,
            Or<(
                Changed<Position>,
                Changed<Velocity>,
                Changed<Force>,
                Changed<Radius>,
                Changed<AngularVelocity>,
            )>,
        ),
    >,
) {
    // A marble whose `Sleeping` went (woken here last step, or by the program) starts its
    // slow time again, and one the program woke gets its contact impulses back.
    let state = state.as_mut();
    state.idle = false;
    state.keys.clear();
    for entity in state.woke.drain(..) {
        if let Ok((.., Some(mut drowsy))) = awake.get_mut(entity) {
            drowsy.0 = 0.0;
        }
        state.keys.push(entity.to_bits());
    }
    if !state.keys.is_empty() && !state.impulses.is_empty() {
        state.keys.sort_unstable();
        solver.restore_impulses(&state.keys, &mut state.impulses);
    }
    if config.sleep.is_none() {
        state.removed.clear();
        state.gravity = None;
        state.switches = None;
        state.poses.clear();
        state.keys.clear();
        for (entity, .., drowsy) in &mut sleepers {
            commands.entity(entity).remove::<Sleeping>();
            state.keys.push(entity.to_bits());
            if let Some(mut drowsy) = drowsy {
                drowsy.0 = 0.0;
            }
        }
        state.keys.sort_unstable();
        solver.restore_impulses(&state.keys, &mut state.impulses);
        return;
    }
    let g = seen_gravity(&config, tilt.as_deref());
    // Gravity changed, or marble collisions or rolling turned on or off (a sleeping pile
    // then falls through itself, marbles asleep inside each other are pushed apart, a
    // spin kept while rolling was off turns): every sleeping marble wakes.
    let switches = (config.marble_collisions, config.rolling);
    let wake_all = state.gravity.is_some_and(|old| old != g)
        || gravity_turns(tilt.as_deref())
        || state.switches.is_some_and(|old| old != switches);
    state.gravity = Some(g);
    state.switches = Some(switches);
    // A spin counts only while rolling is on (off, it is kept as it was, inert).
    let rolling = config.rolling;
    // Boards that move, turn, or were moved since the last step: their swept bounds, and
    // where a moved board was (`None`: unbounded, it reaches everything). A board added,
    // removed or reshaped reaches everything.
    let dt = config.dt;
    state.reaching.clear();
    state.moving.clear();
    let mut rearranged = cache.epoch != state.epoch;
    if rearranged {
        state.reaching.push((None, 0.0));
    }
    // Sleeping marbles gone since the last step (despawned, or quarantined: out of every
    // stage, as if not there) reach the marbles that rested on them.
    let gone = quarantined
        .iter()
        .map(|s| s.position.extend(s.radius))
        .chain(state.removed.drain(..));
    for sphere in gone {
        let (c, r) = (sphere.truncate(), Vec3::splat(sphere.w));
        state.reaching.push((Some(Aabb::new(c - r, c + r)), 0.0));
    }
    for b in &cache.boards {
        let last = state.poses.iter().find(|p| p.0 == b.entity);
        let moved = last.is_some_and(|p| p.1 != b.pose_version);
        if b.is_moving() || moved {
            // The snapshot sweeps one substep; the board moves on for the rest of the step.
            let sweep = (b.velocity.length() + b.angular_velocity.length() * b.reach) * dt;
            state.reaching.push((b.swept_aabb, sweep));
            if b.is_moving() {
                state.moving.push((b.swept_aabb, sweep));
            }
        }
        if let Some(&(_, _, before)) = last.filter(|_| moved) {
            state.reaching.push((before, 0.0));
            rearranged = true;
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
    let reached =
        wake_all || !state.reaching.is_empty() || (config.marble_collisions && !awake.is_empty());
    if !reached
        && !changed.iter().any(|(sleeping, state, spin)| {
            changed_by_program(sleeping, state, spin.filter(|_| rolling))
        })
    {
        // Nothing reached a sleeper (so no board moves and gravity holds); with no marble
        // awake either, the step has nothing left to do.
        state.idle = awake.is_empty();
        return;
    }
    // Every sleeping marble, in query order, with what wakes it by itself.
    state.spheres.clear();
    state.entities.clear();
    state.woken.clear();
    state.queue.clear();
    let mut fastest = 0.0f32;
    for (entity, sleeping, marble, _, _, spin, _) in &sleepers {
        let (position, velocity, _, radius) = marble;
        let k = state.spheres.len() as u32;
        state.spheres.push(position.0.extend(radius.0));
        state.entities.push(entity);
        let wakes = wake_all
            || changed_by_program(sleeping, marble, spin.filter(|_| rolling))
            || reached_by_board(&state.reaching, position.0, radius.0);
        state.woken.push(wakes);
        if wakes {
            state.queue.push(k);
            fastest = fastest.max(velocity.0.length());
        }
    }
    if config.marble_collisions && (!awake.is_empty() || !state.queue.is_empty()) {
        // Awake marbles that could reach a sleeping one during the step, and the marbles
        // within reach of every marble that wakes.
        for (_, velocity, ..) in &awake {
            fastest = fastest.max(velocity.0.length());
        }
        let knock = knock(fastest, &cache.boards);
        state.grid.reserve(n);
        let (grid, spheres) = (&mut state.grid, &state.spheres);
        grid.build(spheres);
        for (position, velocity, force, mass, radius, _) in &awake {
            let a = g + force.0 * mass.inverse();
            let probe = position.0.extend(reach(radius.0, velocity.0, a, knock, dt));
            grid.query(spheres, probe, |k| {
                if !state.woken[k as usize] {
                    state.woken[k as usize] = true;
                    state.queue.push(k);
                }
            });
        }
        let mut head = 0;
        while head < state.queue.len() {
            let k = state.queue[head] as usize;
            head += 1;
            let Ok((_, _, (_, velocity, force, radius), mass, ..)) =
                sleepers.get(state.entities[k])
            else {
                continue;
            };
            let a = g + force.0 * mass.inverse();
            let probe = spheres[k]
                .truncate()
                .extend(reach(radius.0, velocity.0, a, knock, dt));
            grid.query(spheres, probe, |k| {
                if !state.woken[k as usize] {
                    state.woken[k as usize] = true;
                    state.queue.push(k);
                }
            });
        }
    }
    state.keys.clear();
    for &k in &state.queue {
        let entity = state.entities[k as usize];
        commands.entity(entity).remove::<Sleeping>();
        state.keys.push(entity.to_bits());
        if let Ok((.., mut contacts, _, drowsy)) = sleepers.get_mut(entity) {
            if let Some(mut drowsy) = drowsy {
                drowsy.0 = 0.0;
            }
            // Contacts kept from before a board moved, came or went may be gone.
            if rearranged {
                contacts.clear();
            }
        }
    }
    state.keys.sort_unstable();
    solver.restore_impulses(&state.keys, &mut state.impulses);
}

/// Last substep of each step, before the forces are cleared: adds the step to each slow
/// marble's [`Drowsy`] time and puts to sleep every group whose marbles have all been slow
/// for [`Sleep::time`] ([`crate::sleep`], "Falling asleep").
pub fn fall_asleep(
    mut commands: Commands,
    (config, tilt, cache): (Res<StepConfig>, Option<Res<GravityTilt>>, Res<BoardCache>),
    (mut state, solver): (ResMut<SleepState>, Res<PairSolver>),
    mut marbles: Query<
        (
            Entity,
            (&Position, &mut Velocity, &Force, &Mass, &Radius),
            BoardContacts,
            Option<&mut AngularVelocity>,
            Option<&mut Drowsy>,
        ),
        (With<Marble>, Without<Sleeping>, Without<Quarantined>),
    >,
) {
    let Some(Sleep { speed, time }) = config.sleep else {
        return;
    };
    let state = state.as_mut();
    let dt = config.dt;
    let g = seen_gravity(&config, tilt.as_deref());
    // Nothing is slow while gravity turns.
    let turning = gravity_turns(tilt.as_deref());
    let mut any = false;
    let mut fastest = 0.0f32;
    state.ready.clear();
    for (entity, (position, velocity, force, _, radius), contacts, spin, drowsy) in &mut marbles {
        fastest = fastest.max(velocity.0.length());
        // A spin counts only while rolling is on (off, it is frozen as it was).
        let spin_speed = spin
            .as_ref()
            .filter(|_| config.rolling)
            .map_or(0.0, |w| w.0.length() * radius.0);
        let on_moving_board = contacts.iter().any(|c| {
            cache
                .boards
                .get(c.piece.board())
                .is_some_and(|b| b.is_moving())
        });
        let slow = !turning
            && velocity.0.length() < speed
            && spin_speed < speed
            && force.0 == Vec3::ZERO
            && !on_moving_board
            // A moving board that would wake it next step.
            && !reached_by_board(&state.moving, position.0, radius.0);
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
        // Within half a step of `time`: the sum of f32 steps may fall short of it by a
        // rounding.
        let ready = t >= time - 0.5 * dt;
        any |= ready;
        state.ready.push(ready);
    }
    if !any {
        return;
    }
    // Groups: union–find over the pairs within each other's reach.
    let knock = knock(fastest, &cache.boards);
    state.bounds.clear();
    for (_, (position, velocity, force, mass, radius), ..) in &marbles {
        let a = g + force.0 * mass.inverse();
        state
            .bounds
            .push(position.0.extend(reach(radius.0, velocity.0, a, knock, dt)));
    }
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
    state.keys.clear();
    for (k, (entity, (position, mut velocity, _, _, radius), _, spin, _)) in
        (0usize..).zip(&mut marbles)
    {
        let r = root(&mut state.parent, k as u32);
        if !(state.ready[k] && state.group_ready[r as usize]) {
            continue;
        }
        state.keys.push(entity.to_bits());
        velocity.0 = Vec3::ZERO;
        if let Some(mut spin) = spin.filter(|_| config.rolling) {
            spin.0 = Vec3::ZERO;
        }
        commands.entity(entity).insert(Sleeping {
            position: position.0,
            radius: radius.0,
        });
    }
    if !state.keys.is_empty() {
        state.naps = state.naps.wrapping_add(1);
    }
    // Their contact impulses, for warm starting them when they wake.
    state.keys.sort_unstable();
    solver.stow_impulses(&state.keys, &mut state.impulses);
}
