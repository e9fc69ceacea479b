//! Force accumulation and the end-of-step housekeeping.

use std::sync::atomic::{AtomicBool, Ordering};

use bevy_ecs::change_detection::ContiguousMut;
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
    let parallel = super::on_pool(marbles.iter().len());
    // Table by table, over the columns as slices: the accelerations' change ticks are set
    // in one pass, not one write per marble; with `parallel`, in chunks on the task pool.
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for (force, mass, acceleration) in tables {
        let rows = (force, mass, ContiguousMut::split(acceleration).0);
        super::run_rows(rows, parallel, |(force, mass, acceleration)| {
            for ((f, m), a) in force.iter().zip(mass).zip(acceleration) {
                a.0 = g + f.0 * m.inverse();
            }
        });
    }
}

/// Run condition: true during the last substep of a step.
pub fn last_substep(substep: Res<Substep>) -> bool {
    substep.is_last()
}

/// Run condition: true during the substep that ends the step: the last, or the only one a
/// still world runs ([`SleepState::is_idle`](crate::sleep::SleepState::is_idle)).
pub fn step_ends(substep: Res<Substep>, sleep: Res<crate::sleep::SleepState>) -> bool {
    substep.is_last() || sleep.is_idle()
}

/// Clears every stepped marble's [`Force`] once the whole step has integrated it (a
/// quarantined marble's is left as it is, with the rest of its state).
pub fn clear_forces(
    mut forces: Query<&mut Force, (With<Marble>, Without<Quarantined>, Without<Sleeping>)>,
) {
    // Most scenes apply no force: the columns are read as slices first (the bits of each
    // component, less its sign, or-ed: zero only when every force is ±0), and only a marble
    // whose force is not zero is written (its change tick set).
    let parallel = super::on_pool(forces.iter().len());
    let any = AtomicBool::new(false);
    let tables = forces
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    for f in tables {
        super::run_rows(f, parallel, |f| {
            let bits = f.iter().fold(0u32, |bits, f| {
                bits | f.0.x.to_bits() | f.0.y.to_bits() | f.0.z.to_bits()
            });
            if bits << 1 != 0 {
                any.store(true, Ordering::Relaxed);
            }
        });
    }
    if !any.into_inner() {
        return;
    }
    for mut force in &mut forces {
        if force.0 != glam::Vec3::ZERO {
            force.0 = glam::Vec3::ZERO;
        }
    }
}
