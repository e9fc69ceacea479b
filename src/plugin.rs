//! `MarblePhysicsPlugin`: the same pipeline inside a Bevy app, at its fixed timestep.

use bevy_app::{App, FixedPostUpdate, Plugin};
use bevy_ecs::intern::Interned;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;
use bevy_time::{Fixed, Time};
use bevy_transform::components::Transform;

use crate::components::{Board, Marble, Position, Rotation};
use crate::config::StepConfig;
use crate::schedule::{MarbleSubstep, init_resources, run_step, substep_schedule};

/// Runs the marble physics in a Bevy app.
///
/// Each run of `schedule` (default `FixedPostUpdate`, i.e. once per fixed timestep)
/// advances the physics by the app's fixed timestep (`Time<Fixed>`), split into
/// [`StepConfig::substeps`], then writes every marble's and board's pose into its
/// `Transform` (entities without a `Transform` are left alone).
///
/// ```
/// use bevy_app::App;
/// use bevy_marble::prelude::*;
///
/// let mut app = App::new();
/// app.add_plugins(MarblePhysicsPlugin::default());
/// ```
pub struct MarblePhysicsPlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl Default for MarblePhysicsPlugin {
    fn default() -> Self {
        MarblePhysicsPlugin::new(FixedPostUpdate)
    }
}

impl MarblePhysicsPlugin {
    /// Runs the physics in `schedule` instead of `FixedPostUpdate`. The step length is
    /// still read from `Time<Fixed>`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        MarblePhysicsPlugin {
            schedule: schedule.intern(),
        }
    }
}

/// The plugin's systems.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MarblePluginSystems {
    /// Runs one physics step (all substeps).
    Step,
    /// Copies poses into `Transform`s.
    SyncTransforms,
}

impl Plugin for MarblePhysicsPlugin {
    fn build(&self, app: &mut App) {
        init_resources(app.world_mut());
        app.init_resource::<Time<Fixed>>();
        app.add_schedule(substep_schedule());
        app.configure_sets(
            self.schedule,
            (
                MarblePluginSystems::Step,
                MarblePluginSystems::SyncTransforms,
            )
                .chain(),
        );
        app.add_systems(
            self.schedule,
            (
                physics_step.in_set(MarblePluginSystems::Step),
                sync_transforms.in_set(MarblePluginSystems::SyncTransforms),
            ),
        );
    }
}

/// Advances the physics by the fixed timestep.
pub fn physics_step(world: &mut World) {
    let dt = world.resource::<Time<Fixed>>().timestep().as_secs_f32();
    if dt <= 0.0 {
        return;
    }
    world.resource_mut::<StepConfig>().dt = dt;
    run_step(world, |world| world.run_schedule(MarbleSubstep));
}

/// Writes marble positions (and orientations, for marbles that roll) and board poses into
/// their `Transform`s.
pub fn sync_transforms(
    mut marbles: Query<
        (&Position, Option<&Rotation>, &mut Transform),
        (With<Marble>, Without<Board>),
    >,
    mut boards: Query<(&Position, &Rotation, &mut Transform), (With<Board>, Without<Marble>)>,
) {
    for (position, rotation, mut transform) in &mut marbles {
        transform.translation = position.0;
        if let Some(rotation) = rotation {
            transform.rotation = rotation.0;
        }
    }
    for (position, rotation, mut transform) in &mut boards {
        transform.translation = position.0;
        transform.rotation = rotation.0;
    }
}
