//! Free motion of every marble over the substep.

use bevy_ecs::prelude::*;

use crate::components::{Acceleration, Marble, Position, Quarantined, StepStart, Velocity};
use crate::config::StepConfig;
use crate::narrow::BoardCache;

/// Advances every marble by one substep of free motion with the configured integrator,
/// remembering where it started ([`StepStart`]) for detection and response.
pub fn integrate(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut marbles: Query<
        (&mut Position, &mut Velocity, &Acceleration, &mut StepStart),
        (With<Marble>, Without<Quarantined>),
    >,
) {
    let h = cache.h;
    let integrator = config.integrator;
    for (mut position, mut velocity, acceleration, mut start) in &mut marbles {
        *start = StepStart {
            position: position.0,
            velocity: velocity.0,
        };
        let (x, v) = integrator.advance(position.0, velocity.0, acceleration.0, h);
        position.0 = x;
        velocity.0 = v;
    }
}
