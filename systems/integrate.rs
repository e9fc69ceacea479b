//! Free motion of every marble over the substep.

use bevy_ecs::prelude::*;

use super::Stepped;
use crate::components::{
    Acceleration, Position, PositionCarry, StepStart, Velocity, compensated_add,
};
use crate::config::{StepConfig, Substep};

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
    let h = substep.h;
    let integrator = config.integrator;
    let compensated = config.compensated;
    let each = |(mut position, mut carry, mut velocity, acceleration, mut start): (
        Mut<Position>,
        Mut<PositionCarry>,
        Mut<Velocity>,
        &Acceleration,
        Mut<StepStart>,
    )| {
        *start = StepStart {
            position: position.0,
            carry: carry.0,
            velocity: velocity.0,
        };
        let (dx, dv) = integrator.delta(velocity.0, acceleration.0, h);
        (position.0, carry.0) = compensated_add(compensated, position.0, carry.0, dx);
        velocity.0 += dv;
    };
    #[cfg(feature = "parallel")]
    if marbles.iter().len() >= super::PARALLEL_MIN {
        marbles.par_iter_mut().for_each(each);
        return;
    }
    // A `for` loop, not `Iterator::for_each`: through `for_each` the compiler leaves `each`
    // a call per marble.
    for marble in &mut marbles {
        each(marble);
    }
}
