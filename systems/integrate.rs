//! Free motion of every marble over the substep.

use bevy_ecs::change_detection::ContiguousMut;
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
    let parallel = super::on_pool(marbles.iter().len());
    // Table by table, over the columns as slices: one loop over plain arrays, each
    // column's change ticks set in one pass, rather than a fetch and five tick writes per
    // marble; with `parallel`, in chunks on the task pool.
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for (position, carry, velocity, acceleration, start) in tables {
        let rows = FreeRows {
            position: ContiguousMut::split(position).0,
            carry: ContiguousMut::split(carry).0,
            velocity: ContiguousMut::split(velocity).0,
            acceleration,
            start: ContiguousMut::split(start).0,
        };
        super::run_rows(rows, parallel, |t| {
            let rows = t
                .position
                .iter_mut()
                .zip(t.carry.iter_mut())
                .zip(t.velocity.iter_mut())
                .zip(t.acceleration)
                .zip(t.start.iter_mut());
            for ((((x, carry), v), a), start) in rows {
                advance(step, (x, carry, v, a, start));
            }
        });
    }
}

/// One table's columns that integration reads and writes, as slices.
struct FreeRows<'a> {
    position: &'a mut [Position],
    carry: &'a mut [PositionCarry],
    velocity: &'a mut [Velocity],
    acceleration: &'a [Acceleration],
    start: &'a mut [StepStart],
}

impl super::Rows for FreeRows<'_> {
    fn len(&self) -> usize {
        self.position.len()
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        let (p0, p1) = self.position.split_at_mut(mid);
        let (c0, c1) = self.carry.split_at_mut(mid);
        let (v0, v1) = self.velocity.split_at_mut(mid);
        let (a0, a1) = self.acceleration.split_at(mid);
        let (s0, s1) = self.start.split_at_mut(mid);
        let head = FreeRows {
            position: p0,
            carry: c0,
            velocity: v0,
            acceleration: a0,
            start: s0,
        };
        let tail = FreeRows {
            position: p1,
            carry: c1,
            velocity: v1,
            acceleration: a1,
            start: s1,
        };
        (head, tail)
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
