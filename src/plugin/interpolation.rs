//! Smooth rendering: `Transform` eased between the last two physics poses.

use bevy_app::{App, Plugin, RunFixedMainLoop, RunFixedMainLoopSystems};
use bevy_ecs::intern::Interned;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;
use bevy_reflect::Reflect;
use bevy_time::{Fixed, Time};
use bevy_transform::components::Transform;
use glam::{Quat, Vec3};

use super::{MarblePluginSystems, stepped};
use crate::components::{Marble, Position, Rotation};

/// Marks a marble or board whose `Transform` is eased, every frame, between its last two
/// physics poses by `Time<Fixed>::overstep_fraction()`, after the fixed-step loop of that
/// frame (so `Update` systems and rendering see it). Without it, `Transform` shows the
/// last physics pose, which moves once per fixed step: with a 64 Hz step on a 144 Hz
/// display, a stutter. Correct whether a frame runs no fixed step, one or several (the
/// poses are the last two steps'); a teleport by the program (its `Transform` or
/// `Position` set) jumps there with no streak; a paused physics holds still.
#[derive(Component, Reflect, Clone, Copy, Debug, Default)]
#[reflect(Component)]
#[require(PhysicsPoses)]
pub struct TransformInterpolation;

/// The last two physics poses of an interpolated entity (translation and rotation): the
/// one before the last step and the one after it.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct PhysicsPoses {
    /// The pose before the last step.
    pub previous: (Vec3, Quat),
    /// The pose after the last step.
    pub current: (Vec3, Quat),
    /// Set once the poses hold the entity's pose.
    initialised: bool,
    /// The `Transform` the easing wrote or the step took last: one that differs was set
    /// by the program.
    pub(super) written: Option<(Vec3, Quat)>,
    /// A marble's position where the step's own stages left it (noted in its last
    /// substep, before the engine's events reach observers): a position that differs
    /// after the step was set by an observer.
    pub(super) stepped_to: Option<Vec3>,
}

impl PhysicsPoses {
    /// Both poses at this one (a teleport: nothing to ease from).
    pub fn reset(&mut self, position: Vec3, rotation: Quat) {
        self.previous = (position, rotation);
        self.current = (position, rotation);
        self.initialised = true;
    }

    /// `transform` is taken (the pose it gave was read, or it is where the entity
    /// starts): only a `Transform` the program sets after this counts as set by it.
    pub(super) fn saw(&mut self, transform: &Transform) {
        self.written = Some((transform.translation, transform.rotation));
    }

    /// Whether `transform` differs from what the easing last wrote: the program set it.
    /// `turned`: whether its rotation counts (not for a marble without a `Rotation`, whose
    /// `Transform` rotation the easing leaves to the game: a spinning mesh).
    pub(super) fn set_by_program(&self, transform: &Transform, turned: bool) -> bool {
        self.written.is_some_and(|(translation, rotation)| {
            translation != transform.translation || (turned && rotation != transform.rotation)
        })
    }

    /// The pose a fraction `t` of the way from the previous to the current one.
    pub fn at(&self, t: f32) -> (Vec3, Quat) {
        (
            self.previous.0.lerp(self.current.0, t),
            self.previous.1.slerp(self.current.1, t),
        )
    }
}

/// [`TransformInterpolation`] for the entities that carry it.
pub struct MarbleInterpolationPlugin {
    pub(super) schedule: Interned<dyn ScheduleLabel>,
}

impl Plugin for MarbleInterpolationPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<TransformInterpolation>();
        app.add_systems(
            self.schedule,
            (
                catch_teleports.in_set(MarblePluginSystems::ReadTransforms),
                (
                    record_poses.run_if(stepped),
                    hold_poses.run_if(not(stepped)),
                )
                    .in_set(MarblePluginSystems::Record),
            ),
        );
        app.add_systems(
            RunFixedMainLoop,
            ease_transforms.in_set(RunFixedMainLoopSystems::AfterFixedMainLoop),
        );
        app.add_systems(
            crate::schedule::MarbleSubstep,
            note_stepped_poses
                .run_if(crate::systems::forces::step_ends)
                .in_set(crate::schedule::MarbleSystems::Events)
                .after(crate::systems::events::find_observers)
                .before(crate::systems::events::record_touches),
        );
    }
}

/// The pose of an entity: its position, and its rotation when it has one.
fn pose(position: &Position, rotation: Option<&Rotation>) -> (Vec3, Quat) {
    (position.0, rotation.map_or(Quat::IDENTITY, |r| r.0))
}

/// Before the step: an interpolated entity whose `Position` is not where the last step
/// left it was moved by the program: it jumps (no easing from the old place).
pub fn catch_teleports(
    mut entities: Query<
        (
            &Position,
            Option<&Rotation>,
            &mut PhysicsPoses,
            Option<&Transform>,
        ),
        With<TransformInterpolation>,
    >,
) {
    for (position, rotation, mut poses, transform) in &mut entities {
        let now = pose(position, rotation);
        if !poses.initialised
            && let Some(transform) = transform
        {
            poses.saw(transform);
        }
        if !poses.initialised || now != poses.current {
            poses.reset(now.0, now.1);
        }
    }
}

/// In the step's last substep, before the engine's events are sent: where the step's
/// stages left each interpolated marble (what an observer of those events may change).
pub fn note_stepped_poses(
    mut marbles: Query<
        (&Position, &mut PhysicsPoses),
        (With<TransformInterpolation>, With<Marble>),
    >,
) {
    for (position, mut poses) in &mut marbles {
        poses.stepped_to = Some(position.0);
    }
}

/// After a step: the poses move on by one; a marble an observer moved during the step
/// jumps there (no easing from where it was).
pub fn record_poses(
    mut entities: Query<
        (&Position, Option<&Rotation>, &mut PhysicsPoses),
        With<TransformInterpolation>,
    >,
) {
    for (position, rotation, mut poses) in &mut entities {
        let now = pose(position, rotation);
        match poses.stepped_to.take() {
            Some(stepped) if stepped != position.0 => poses.reset(now.0, now.1),
            _ => {
                poses.previous = poses.current;
                poses.current = now;
            }
        }
    }
}

/// A run of the physics schedule that did not step (paused): hold still where it is.
pub fn hold_poses(mut entities: Query<&mut PhysicsPoses, With<TransformInterpolation>>) {
    for mut poses in &mut entities {
        poses.previous = poses.current;
    }
}

/// Every frame, after the fixed-step loop: `Transform` at the overstep fraction between the
/// last two physics poses. A `Transform` the program set since the last easing is left
/// alone, for the next physics step to take as a teleport.
pub fn ease_transforms(
    fixed: Res<Time<Fixed>>,
    mut entities: Query<
        (
            &mut PhysicsPoses,
            Option<&Rotation>,
            Has<Marble>,
            &mut Transform,
        ),
        With<TransformInterpolation>,
    >,
) {
    let t = fixed.overstep_fraction();
    for (mut poses, rotation, marble, mut transform) in &mut entities {
        let turned = !marble || rotation.is_some();
        if !poses.initialised || poses.set_by_program(&transform, turned) {
            continue;
        }
        let (translation, r) = poses.at(t);
        transform.translation = translation;
        if rotation.is_some() {
            transform.rotation = r;
        }
        poses.written = Some((transform.translation, transform.rotation));
    }
}
