//! The engine inside a Bevy app: [`MarblePhysicsPlugin`] (one line adds everything) and
//! the [`MarblePhysicsPlugins`] group it is made of, for a game that leaves parts out.
//!
//! | plugin | does |
//! | --- | --- |
//! | [`MarbleStepPlugin`] | the physics step at `Time<Fixed>` (in `FixedPostUpdate` unless told otherwise), paused or scaled by [`PhysicsClock`]; types registered for reflection |
//! | [`MarbleTransformPlugin`] | entities spawned with a `Transform` start there; a `Transform` the program changes moves the entity (a teleport); each step writes poses back into `Transform` |
//! | [`MarbleEventsPlugin`] | impacts, contacts started and ended, sensors entered and left, as messages and observer events ([`crate::events`]) |
//! | [`MarbleInterpolationPlugin`] | [`TransformInterpolation`]: `Transform` eased between the last two physics poses every frame |
//! | [`MarbleDiagnosticsPlugin`] | step time, marbles awake and asleep, contacts, through `bevy_diagnostic` |
//!
//! Not in the group: `debug_draw::MarbleDebugDrawPlugin` (feature `debug_draw`), gizmos of
//! the boards, sensors, contacts and impacts for a game that renders.

use bevy_app::{App, FixedPostUpdate, Plugin, PluginGroup, PluginGroupBuilder};
use bevy_ecs::intern::Interned;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;
use bevy_reflect::Reflect;
use bevy_time::{Fixed, Time};
use glam::Vec3;

use crate::components::{Force, Marble, Quarantined};
use crate::config::StepConfig;
use crate::schedule::{MarbleSubstep, init_resources, run_step, substep_schedule};

#[cfg(feature = "debug_draw")]
pub mod debug_draw;
mod diagnostics;
mod interpolation;
mod transform;

pub use diagnostics::{MarbleDiagnostics, MarbleDiagnosticsPlugin};
pub use interpolation::{MarbleInterpolationPlugin, PhysicsPoses, TransformInterpolation};
pub use transform::MarbleTransformPlugin;
pub(crate) use transform::note_spawned;

/// Runs the marble physics in a Bevy app: every plugin of [`MarblePhysicsPlugins`].
///
/// Each run of `schedule` (default `FixedPostUpdate`, i.e. once per fixed timestep)
/// advances the physics by the app's fixed timestep (`Time<Fixed>`, times
/// [`PhysicsClock::speed`], not at all while [`PhysicsClock::paused`]), split into
/// [`StepConfig::substeps`], then writes every marble's and board's pose into its
/// `Transform`.
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

impl Plugin for MarblePhysicsPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(MarblePhysicsPlugins {
            schedule: self.schedule,
        });
    }
}

/// The plugins [`MarblePhysicsPlugin`] adds, as a group: a game can leave parts out,
/// `MarblePhysicsPlugins::default().build().disable::<MarbleDiagnosticsPlugin>()`.
pub struct MarblePhysicsPlugins {
    schedule: Interned<dyn ScheduleLabel>,
}

impl Default for MarblePhysicsPlugins {
    fn default() -> Self {
        MarblePhysicsPlugins::new(FixedPostUpdate)
    }
}

impl MarblePhysicsPlugins {
    /// The group, stepping in `schedule` instead of `FixedPostUpdate`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        MarblePhysicsPlugins {
            schedule: schedule.intern(),
        }
    }
}

impl PluginGroup for MarblePhysicsPlugins {
    fn build(self) -> PluginGroupBuilder {
        PluginGroupBuilder::start::<Self>()
            .add(MarbleStepPlugin {
                schedule: self.schedule,
            })
            .add(MarbleTransformPlugin {
                schedule: self.schedule,
            })
            .add(MarbleEventsPlugin)
            .add(MarbleInterpolationPlugin {
                schedule: self.schedule,
            })
            .add(MarbleDiagnosticsPlugin {
                schedule: self.schedule,
            })
    }
}

/// The plugin systems' sets, in this order in the physics schedule.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MarblePluginSystems {
    /// `Transform`s the program changed move their entities.
    ReadTransforms,
    /// Runs one physics step (all substeps).
    Step,
    /// Records what the step did: interpolation poses, diagnostics.
    Record,
    /// Copies poses into `Transform`s.
    SyncTransforms,
}

/// How the physics keeps time in an app (a resource): paused, it does not step (the game's
/// own fixed-step systems still run); `speed` scales each step's length (0.5 is slow
/// motion, 2 runs twice as fast; a longer step is a coarser one).
#[derive(Resource, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Resource)]
pub struct PhysicsClock {
    /// No physics steps while true.
    pub paused: bool,
    /// Simulated seconds per second of `Time<Fixed>`, > 0. Default 1.
    pub speed: f32,
}

impl Default for PhysicsClock {
    fn default() -> Self {
        PhysicsClock {
            paused: false,
            speed: 1.0,
        }
    }
}

/// The physics step in an app: the substep schedule run at the fixed timestep.
pub struct MarbleStepPlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl Plugin for MarbleStepPlugin {
    fn build(&self, app: &mut App) {
        // The messages first: registered, the app's message update drops each after two
        // updates (`add_message` registers only a message whose buffer is not there yet,
        // and `init_resources` would put it there).
        app.add_message::<crate::events::MarbleImpact>();
        app.add_message::<crate::events::ContactStarted>();
        app.add_message::<crate::events::ContactEnded>();
        app.add_message::<crate::events::SensorEntered>();
        app.add_message::<crate::events::SensorExited>();
        app.add_message::<crate::validate::QuarantineReport>();
        app.add_message::<crate::validate::StepRefused>();
        init_resources(app.world_mut());
        app.init_resource::<Time<Fixed>>();
        app.init_resource::<PhysicsClock>();
        app.init_resource::<LastStep>();
        app.add_schedule(substep_schedule());
        app.configure_sets(
            self.schedule,
            (
                MarblePluginSystems::ReadTransforms,
                MarblePluginSystems::Step,
                MarblePluginSystems::Record,
                MarblePluginSystems::SyncTransforms,
            )
                .chain(),
        );
        app.add_systems(
            self.schedule,
            physics_step.in_set(MarblePluginSystems::Step),
        );
        crate::components::register_types(app);
    }
}

/// Advances the physics by the fixed timestep times [`PhysicsClock::speed`], unless
/// [`PhysicsClock::paused`]. A fixed step the physics does not take clears the marbles'
/// [`Force`] as a step would: what the game's systems add while it is paused is not
/// saved up for the first step after.
pub fn physics_step(world: &mut World) {
    let clock = world
        .get_resource::<PhysicsClock>()
        .copied()
        .unwrap_or_default();
    let dt = world.resource::<Time<Fixed>>().timestep().as_secs_f32() * clock.speed;
    if clock.paused || !(clock.speed > 0.0 && clock.speed.is_finite()) || dt <= 0.0 {
        drop_forces(world);
        return;
    }
    world.resource_mut::<StepConfig>().dt = dt;
    let start = std::time::Instant::now();
    run_step(world, |world| world.run_schedule(MarbleSubstep));
    let seconds = start.elapsed().as_secs_f64();
    if let Some(mut last) = world.get_resource_mut::<LastStep>() {
        last.seconds = seconds;
    }
}

/// Clears every marble's [`Force`], but a quarantined one's (as
/// [`clear_forces`](crate::systems::forces::clear_forces) does after a step), writing
/// only those not zero.
fn drop_forces(world: &mut World) {
    let mut forces = world.query_filtered::<&mut Force, (With<Marble>, Without<Quarantined>)>();
    for mut force in forces.iter_mut(world) {
        if force.0 != Vec3::ZERO {
            force.0 = Vec3::ZERO;
        }
    }
}

/// How long the last physics step took to compute, s (a resource, for diagnostics).
#[derive(Resource, Default, Clone, Copy, Debug)]
pub struct LastStep {
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Whether the physics stepped in this run of its schedule (a resource the step plugin
/// keeps for the plugins that record what a step did).
pub fn stepped(clock: Option<Res<PhysicsClock>>) -> bool {
    clock.is_none_or(|c| !c.paused && c.speed > 0.0 && c.speed.is_finite())
}

/// Impacts and contacts as messages and observer events ([`crate::events`]): turns
/// [`StepConfig::events`] on, and records them whatever it says from then on (a
/// `StepConfig` inserted later, `..default()` included, keeps them; leave this plugin out
/// of the group to record none). (The step plugin registers every message, kept until
/// `Update` has read it however many fixed steps a frame runs, and sensors report without
/// this plugin.)
pub struct MarbleEventsPlugin;

impl Plugin for MarbleEventsPlugin {
    fn build(&self, app: &mut App) {
        init_resources(app.world_mut());
        app.world_mut().resource_mut::<StepConfig>().events = true;
        app.init_resource::<crate::systems::events::RecordEvents>();
    }
}
