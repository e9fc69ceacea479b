//! Marble–marble contacts and impacts ([`crate::pairs`]): one system before integration
//! (touching pairs: collisions at the start, contact forces, overlap) and one after the
//! marble–board response (pairs that meet during the substep).

use bevy_ecs::prelude::*;
use glam::Vec3;

use crate::components::{
    Acceleration, AngularVelocity, Contacts, Friction, Marble, Mass, Position, PositionCarry,
    Quarantined, Radius, Restitution, StepStart, Velocity, compensated_add,
};
use crate::config::StepConfig;
use crate::narrow::{BoardCache, NearPieces};
use crate::pairs::{BoardTouch, Body, MarbleContacts, PairParams, PairSolver};
use crate::sleep::Sleeping;

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
/// board's velocity there taken at time `at` of the current substep.
fn board_touches(
    solver: &mut PairSolver,
    cache: &BoardCache,
    body: u32,
    contacts: &Contacts,
    restitution: f32,
    h: f32,
    at: f32,
) {
    solver.touch_start.push(solver.board_touches.len() as u32);
    for c in contacts.iter() {
        let Some(board) = cache.boards.get(c.piece.board()) else {
            continue;
        };
        let point = c.point + board.point_velocity(c.time, c.point) * (h - c.time);
        solver.board_touches.push(BoardTouch {
            body,
            normal: c.normal,
            point,
            velocity: board.point_velocity(at, point),
            piece: c.piece,
            restitution: 0.5 * (restitution + board.restitution),
            gap: 0.0,
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
    contacts: &Contacts,
    near: &NearPieces,
    restitution: f32,
    h: f32,
) {
    let reach = d.length() + a.length() * h * h;
    let touched = |piece| contacts.iter().any(|c| c.piece == piece);
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
                solver.board_touches.push(BoardTouch {
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
fn free_path(config: &StepConfig, h: f32, v: Vec3, a: Vec3, contacts: &Contacts) -> Vec3 {
    let (mut v, mut a) = (v, a);
    for c in contacts.iter() {
        v -= v.dot(c.normal).min(0.0) * c.normal;
        a -= a.dot(c.normal).min(0.0) * c.normal;
    }
    config.integrator.delta(v, a, h).0
}

/// Writes a body's position (by compensated summation of its move) and velocity back.
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

/// Before integration: the touching pairs of [`crate::pairs`] (collisions at the start,
/// contact forces added to the marbles' acceleration, overlap projected out). Runs only
/// with `marble_collisions` on.
pub fn marble_contacts(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut solver: ResMut<PairSolver>,
    mut recorded: ResMut<MarbleContacts>,
    mut marbles: Query<
        (
            Entity,
            (
                &mut Position,
                &mut PositionCarry,
                &mut Velocity,
                &mut Acceleration,
            ),
            (&Radius, &Mass, &Restitution, &Contacts, &NearPieces),
            (Option<&mut AngularVelocity>, Option<&Friction>),
        ),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
) {
    let h = cache.h;
    let params = params(&config, h);
    let solver = solver.as_mut();
    // The broad phase first: marbles spread apart stop there.
    recorded.list.clear();
    solver.begin(marbles.iter().len(), &mut recorded);
    for (entity, (position, _, velocity, acceleration), (radius, _, _, contacts, _), _) in &marbles
    {
        let d = free_path(&config, h, velocity.0, acceleration.0, contacts);
        let sphere = PairSolver::contact_sphere(&params, position.0, d, radius.0);
        solver.push_sphere(entity, sphere, radius.0);
        solver.paths.push(d);
    }
    if !solver.cover_gathered() {
        solver.forget_contacts();
        return;
    }
    solver.bodies.clear();
    // (Plain loops with a counter: through `enumerate` the compiler leaves the query's
    // `next` a call per marble.)
    for (
        entity,
        (position, _, velocity, acceleration),
        (radius, mass, restitution, _, _),
        (spin, friction),
    ) in &marbles
    {
        let d = solver.paths[solver.bodies.len()];
        solver.bodies.push(Body {
            entity,
            x: position.0,
            x0: position.0,
            v: velocity.0,
            v0: velocity.0,
            w: mass.inverse(),
            r: radius.0,
            e: restitution.0,
            a: acceleration.0,
            d,
            omega: spin.as_ref().map_or(Vec3::ZERO, |w| w.0),
            spins: config.rolling && spin.is_some(),
            mu: friction.map_or(0.0, |f| f.0),
        });
    }
    if !solver.find_touching(&params) {
        return;
    }
    solver.board_touches.clear();
    solver.touch_start.clear();
    for (body, (_, _, (radius, _, restitution, contacts, near), _)) in (0usize..).zip(&marbles) {
        // Only the marbles in the rows: the contact stage reads no other marble's boards
        // (its cascade and passes run on the rows' marbles).
        if !solver.in_contact[body] {
            solver.touch_start.push(solver.board_touches.len() as u32);
            continue;
        }
        // The contacts were recorded during the last substep; its boards have since
        // moved on to this substep's start.
        board_touches(solver, &cache, body as u32, contacts, restitution.0, h, 0.0);
        let b = &solver.bodies[body];
        let state = (b.x, b.v, b.a, b.d);
        speculative_touches(
            solver,
            &cache,
            body as u32,
            state,
            radius.0,
            contacts,
            near,
            restitution.0,
            h,
        );
    }
    solver.touch_start.push(solver.board_touches.len() as u32);
    solver.solve_touching(&params, &mut recorded);
    for (k, (_, (mut position, mut carry, mut velocity, mut acceleration), _, (spin, _))) in
        (0usize..).zip(&mut marbles)
    {
        if !solver.changed[k] {
            continue;
        }
        let body = &solver.bodies[k];
        write_back(
            config.compensated,
            body,
            &mut position,
            &mut carry,
            &mut velocity,
        );
        acceleration.0 = body.a;
        if body.spins
            && let Some(mut spin) = spin
        {
            spin.0 = body.omega;
        }
    }
}

/// After the marble–board response: pairs of [`crate::pairs`] that meet during the
/// substep collide at their time of impact. Runs only with `marble_collisions` on.
pub fn collide_marbles(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut solver: ResMut<PairSolver>,
    mut recorded: ResMut<MarbleContacts>,
    mut marbles: Query<
        (
            Entity,
            (&mut Position, &mut PositionCarry, &mut Velocity),
            (&StepStart, &Radius, &Mass, &Restitution, &Contacts),
        ),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
) {
    let h = cache.h;
    let params = params(&config, h);
    let solver = solver.as_mut();
    // The broad phase first, on the paths the marbles took: marbles spread apart stop
    // there.
    solver.begin(marbles.iter().len(), &mut recorded);
    for (entity, (position, _, _), (start, radius, _, _, _)) in &marbles {
        let sphere = PairSolver::impact_sphere(&params, start.position, position.0, radius.0);
        solver.push_sphere(entity, sphere, radius.0);
    }
    if !solver.cover_gathered() {
        return;
    }
    solver.bodies.clear();
    for (entity, (position, _, velocity), (start, radius, mass, restitution, _)) in &marbles {
        solver.bodies.push(Body {
            entity,
            x: position.0,
            x0: start.position,
            v: velocity.0,
            v0: start.velocity,
            w: mass.inverse(),
            r: radius.0,
            e: restitution.0,
            a: Vec3::ZERO,
            d: Vec3::ZERO,
            omega: Vec3::ZERO,
            spins: false,
            mu: 0.0,
        });
    }
    if !solver.find_impacts(&params) {
        return;
    }
    solver.board_touches.clear();
    solver.touch_start.clear();
    for (body, (_, _, (_, _, _, restitution, contacts))) in (0usize..).zip(&marbles) {
        board_touches(solver, &cache, body as u32, contacts, restitution.0, h, h);
    }
    solver.touch_start.push(solver.board_touches.len() as u32);
    solver.resolve_impacts(&params, &cache.boards, &mut recorded);
    for (k, (_, (mut position, mut carry, mut velocity), _)) in (0usize..).zip(&mut marbles) {
        if !solver.changed[k] {
            continue;
        }
        write_back(
            config.compensated,
            &solver.bodies[k],
            &mut position,
            &mut carry,
            &mut velocity,
        );
    }
}
