//! Free motion over the substep with the chosen integrator, as the marble–board
//! detection stage applies it: each marble's start is noted (`start_substep`), and a
//! marble that no board touches or reaches moves freely (`move_freely`). Detection
//! resolves the others from that start (the closed forms), or the response does, so
//! with continuous collision their free motion is never computed (without it, a marble
//! touching nothing at the start moves freely first: its end is what detection checks
//! for overlap). One pass over the columns does both.

use crate::components::{
    Acceleration, Position, PositionCarry, StepStart, Velocity, compensated_add,
};
use crate::config::Integrator;

/// What a substep of free motion needs besides the marble: the integrator, whether
/// positions are summed compensated ([`PositionCarry`]), and the substep's length.
pub(crate) type FreeStep = (Integrator, bool, f32);

/// Notes where a marble starts the substep ([`StepStart`]), which detection, the response
/// and the impact stage read.
#[inline(always)]
pub(crate) fn start_substep(
    position: &Position,
    carry: &PositionCarry,
    velocity: &Velocity,
    start: &mut StepStart,
) {
    // Field by field: a whole `StepStart` built on the stack and copied in 16-byte moves
    // stalls on store forwarding (a tenth of the walled board's detection time).
    start.position = position.0;
    start.carry = carry.0;
    start.velocity = velocity.0;
}

/// One substep of free motion from the marble's `start` under its acceleration, its
/// position by compensated summation ([`PositionCarry`]).
#[inline(always)]
pub(crate) fn move_freely(
    (integrator, compensated, h): FreeStep,
    start: &StepStart,
    acceleration: &Acceleration,
    (position, carry, velocity): (&mut Position, &mut PositionCarry, &mut Velocity),
) {
    let (dx, dv) = integrator.delta(start.velocity, acceleration.0, h);
    (position.0, carry.0) = compensated_add(compensated, start.position, start.carry, dx);
    velocity.0 = start.velocity + dv;
}
