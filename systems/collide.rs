//! Marble–marble collisions and contacts ([`crate::pairs`]).

use bevy_ecs::prelude::*;

use crate::components::{
    Contacts, Marble, Mass, Position, PositionCarry, Quarantined, Radius, Restitution, StepStart,
    Velocity, compensated_add,
};
use crate::config::StepConfig;
use crate::narrow::BoardCache;
use crate::pairs::{BoardTouch, Body, MarbleContacts, PairParams, PairSolver};

/// Runs the pair stage of [`crate::pairs`] over every marble: gathers the marbles' end
/// state and board contacts, solves, and writes back the marbles it changed. Runs only
/// with `marble_collisions` on.
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
        (With<Marble>, Without<Quarantined>),
    >,
) {
    let h = cache.h;
    let solver = solver.as_mut();
    solver.bodies.clear();
    solver.board_touches.clear();
    solver.touch_start.clear();
    for (entity, (position, _, velocity), (start, radius, mass, restitution, contacts)) in &marbles
    {
        let body = solver.bodies.len() as u32;
        solver.touch_start.push(solver.board_touches.len() as u32);
        solver.bodies.push(Body {
            entity,
            x: position.0,
            x0: start.position,
            v: velocity.0,
            v0: start.velocity,
            w: mass.inverse(),
            r: radius.0,
            e: restitution.0,
        });
        for c in contacts.iter() {
            let Some(board) = cache.boards.get(c.piece.board()) else {
                continue;
            };
            let point = c.point + board.point_velocity(c.time, c.point) * (h - c.time);
            solver.board_touches.push(BoardTouch {
                body,
                normal: c.normal,
                point,
                velocity: board.point_velocity(h, point),
                piece: c.piece,
                restitution: 0.5 * (restitution.0 + board.restitution),
            });
        }
    }
    // Displacement per unit of velocity change and second, for a velocity changed evenly
    // over the substep by a constant force: dx / (a h²).
    solver.touch_start.push(solver.board_touches.len() as u32);
    let share = config
        .integrator
        .delta(glam::Vec3::ZERO, glam::Vec3::X, h)
        .0
        .x
        / (h * h).max(f32::MIN_POSITIVE);
    let params = PairParams {
        h,
        ccd: config.ccd,
        threshold: config.restitution_threshold,
        tolerance: config.contact_tolerance,
        iterations: config.solver_iterations,
        position_share: share,
    };
    solver.solve(&params, &mut recorded);
    for (k, (_, (mut position, mut carry, mut velocity), _)) in marbles.iter_mut().enumerate() {
        if !solver.changed[k] {
            continue;
        }
        let body = &solver.bodies[k];
        let moved = body.x - position.0;
        (position.0, carry.0) = compensated_add(config.compensated, position.0, carry.0, moved);
        velocity.0 = body.v;
    }
}
