//! Free motion of every marble over the substep.

use bevy_ecs::prelude::*;

use super::Stepped;
use crate::components::{
    Acceleration, Position, PositionCarry, StepStart, Velocity, compensated_add,
};
use crate::config::{Integrator, StepConfig, Substep};

/// Advances every marble by one substep of free motion with the configured integrator
/// (position by compensated summation, see [`PositionCarry`]), remembering where it
/// started ([`StepStart`]) for detection and response.
pub fn integrate(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    mut marbles: Query<
        (
            &mut Position,
            &mut PositionCarry,
            &mut Velocity,
            &Acceleration,
            &mut StepStart,
        ),
        Stepped,
    >,
) {
    let step = (config.integrator, config.compensated, substep.h);
    #[cfg(feature = "parallel")]
    if marbles.iter().len() >= super::PARALLEL_MIN {
        marbles
            .par_iter_mut()
            .for_each(|(mut x, mut carry, mut v, a, mut start)| {
                advance(step, (&mut x, &mut carry, &mut v, a, &mut start));
            });
        return;
    }
    // Table by table, over the columns as slices: one loop over plain arrays, each
    // column's change ticks set in one pass, rather than a fetch and five tick writes per
    // marble.
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for (mut position, mut carry, mut velocity, acceleration, mut start) in tables {
        let rows = position
            .iter_mut()
            .zip(carry.iter_mut())
            .zip(velocity.iter_mut())
            .zip(acceleration)
            .zip(start.iter_mut());
        for ((((x, carry), v), a), start) in rows {
            advance(step, (x, carry, v, a, start));
        }
    }
}

/// One marble's substep of free motion (`step`: the integrator, compensated summation, h).
#[inline(always)]
fn advance(
    (integrator, compensated, h): (Integrator, bool, f32),
    (position, carry, velocity, acceleration, start): (
        &mut Position,
        &mut PositionCarry,
        &mut Velocity,
        &Acceleration,
        &mut StepStart,
    ),
) {
    *start = StepStart {
        position: position.0,
        carry: carry.0,
        velocity: velocity.0,
    };
    let (dx, dv) = integrator.delta(velocity.0, acceleration.0, h);
    (position.0, carry.0) = compensated_add(compensated, position.0, carry.0, dx);
    velocity.0 += dv;
}
