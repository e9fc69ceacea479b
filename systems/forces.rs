//! Force accumulation and the end-of-step housekeeping.

use bevy_ecs::prelude::*;

use crate::components::{Acceleration, Force, Marble, Mass, Quarantined};
use crate::config::{GravityTilt, StepConfig, Substep};
use crate::sleep::Sleeping;

/// Acceleration of every marble for this substep: `gravity + Force / mass` (gravity turned
/// back by the tilt when a [`GravityTilt`] stands in for a turning board).
pub fn accumulate_forces(
    config: Res<StepConfig>,
    tilt: Option<Res<GravityTilt>>,
    mut marbles: Query<
        (&Force, &Mass, &mut Acceleration),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
) {
    let g = tilt.map_or(config.gravity, |t| t.gravity(config.gravity));
    // Table by table, over the columns as slices: the accelerations' change ticks are set
    // in one pass, not one write per marble.
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for (force, mass, mut acceleration) in tables {
        for ((f, m), a) in force.iter().zip(mass).zip(acceleration.iter_mut()) {
            a.0 = g + f.0 * m.inverse();
        }
    }
}

/// Run condition: true during the last substep of a step.
pub fn last_substep(substep: Res<Substep>) -> bool {
    substep.is_last()
}

/// Clears every marble's [`Force`] once the whole step has integrated it.
pub fn clear_forces(mut forces: Query<&mut Force, (With<Marble>, Without<Sleeping>)>) {
    // Most scenes apply no force: the columns are read as slices first (the bits of each
    // component, less its sign, or-ed: zero only when every force is ±0), and only a marble
    // whose force is not zero is written (its change tick set).
    let any = forces
        .contiguous_iter()
        .expect("a marble's components are stored in tables")
        .any(|f| {
            let bits = f.iter().fold(0u32, |bits, f| {
                bits | f.0.x.to_bits() | f.0.y.to_bits() | f.0.z.to_bits()
            });
            bits << 1 != 0
        });
    if !any {
        return;
    }
    for mut force in &mut forces {
        if force.0 != glam::Vec3::ZERO {
            force.0 = glam::Vec3::ZERO;
        }
    }
}
