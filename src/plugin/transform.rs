//! `Transform` in and out: where entities start, teleports by the program, and the poses
//! each step writes back.

use bevy_app::{App, Plugin};
use bevy_ecs::change_detection::Tick;
use bevy_ecs::hierarchy::ChildOf;
use bevy_ecs::intern::Interned;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;
use bevy_ecs::system::SystemChangeTick;
use bevy_transform::components::Transform;
use glam::{Quat, Vec3};

use super::MarblePluginSystems;
use super::interpolation::{PhysicsPoses, TransformInterpolation};
use crate::components::{Board, Marble, Position, Rotation, Sensor};

/// `Transform` in and out.
///
/// - An entity spawned with `Marble`, `Board` or `Sensor` and a `Transform` but no
///   `Position` starts at the `Transform`'s translation (a board or sensor also at its
///   rotation); given both, `Position` and `Rotation` win. (This is the components' own
///   spawn hook, so it holds in a plain `World` too.)
/// - An entity spawned without a pose whose `Transform` is given or changed by a later
///   command or system, before the next step, starts there too (a pose given by then
///   wins).
/// - A `Transform` the program changes after spawning moves its entity there before the
///   next physics step: a **teleport**. The marble keeps its velocity and spin (set them
///   too for a fresh start); its contacts are found afresh at the new place in the next
///   substep, a sleeping marble wakes, and an interpolated entity jumps there without a
///   streak. A teleported board keeps its velocity; marbles it now overlaps are pushed
///   out. To move a board smoothly, give it a [`NextPose`](crate::components::NextPose).
/// - After every step, each marble's, board's and sensor's pose is written into its
///   `Transform` (a marble's rotation only when it has a `Rotation`); entities with
///   [`TransformInterpolation`] are eased every frame instead.
pub struct MarbleTransformPlugin {
    pub(super) schedule: Interned<dyn ScheduleLabel>,
}

impl Plugin for MarbleTransformPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<TransformWrites>();
        app.init_resource::<Spawned>();
        app.add_systems(
            self.schedule,
            (
                (warn_children, read_transforms)
                    .chain()
                    .in_set(MarblePluginSystems::ReadTransforms),
                sync_transforms.in_set(MarblePluginSystems::SyncTransforms),
            ),
        );
    }
}

/// The tick of the engine's last write to `Transform`s (a resource): a `Transform` changed
/// after it was changed by the program.
#[derive(Resource, Default, Debug)]
pub struct TransformWrites {
    pub(super) tick: Tick,
}

/// Logs a warning for each marble, board or sensor that became another entity's child
/// since the last step: the engine reads and writes its `Transform` as its world pose, so
/// a child is stepped where its local `Transform` puts it and shown offset by its parent
/// (docs/bevy.md, "Spawning and teleports").
#[allow(clippy::type_complexity)]
pub fn warn_children(
    children: Query<
        Entity,
        (
            Or<(With<Marble>, With<Board>, With<Sensor>)>,
            Or<(Changed<ChildOf>, Added<Marble>, Added<Board>, Added<Sensor>)>,
            With<ChildOf>,
        ),
    >,
) {
    for entity in &children {
        log::warn!(
            "bevy_marble: {entity} is a child entity: its Transform is taken as its world \
             pose (make it a root entity; a sensor that moves with a board is CarriedBy it)"
        );
    }
}

/// Marbles, boards and sensors spawned without a pose since the last step (a resource):
/// each with whether its position and its rotation were unset, and the `Transform` pose
/// the spawn hook took them from (`None`: it had none, they took the origin), so that a
/// `Transform` inserted or changed by a later command or system, before the next step,
/// places the entity as if it had been spawned with it.
#[derive(Resource, Default, Debug)]
pub struct Spawned(Vec<SpawnedPose>);

/// One entry of [`Spawned`].
#[derive(Clone, Copy, Debug)]
struct SpawnedPose {
    entity: Entity,
    position_unset: bool,
    rotation_unset: bool,
    read: Option<(Vec3, Quat)>,
}

/// Notes an entity whose pose the spawn hook set (`unset`: whether its position and its
/// rotation were not given) from the `Transform` pose `read` (or the origin), in an app
/// with [`MarbleTransformPlugin`] (elsewhere nothing would take it up).
pub(crate) fn note_spawned(
    world: &mut bevy_ecs::world::DeferredWorld,
    entity: Entity,
    (position_unset, rotation_unset): (bool, bool),
    read: Option<(Vec3, Quat)>,
) {
    if let Some(mut spawned) = world.get_resource_mut::<Spawned>() {
        spawned.0.push(SpawnedPose {
            entity,
            position_unset,
            rotation_unset,
            read,
        });
    }
}

/// Places every entity of [`Spawned`] whose `Transform` came or changed since the spawn
/// hook read it, where its pose is still the one the hook gave it; then moves every
/// marble, board and sensor whose `Transform` the program changed since the engine last
/// wrote it to that `Transform` (see [`MarbleTransformPlugin`]).
#[allow(clippy::type_complexity)]
pub fn read_transforms(
    writes: Res<TransformWrites>,
    ticks: SystemChangeTick,
    mut spawned: ResMut<Spawned>,
    mut entities: Query<
        (
            Ref<Transform>,
            &mut Position,
            Option<&mut Rotation>,
            Has<Marble>,
            Option<&mut PhysicsPoses>,
        ),
        (
            Or<(With<Marble>, With<Board>, With<Sensor>)>,
            Changed<Transform>,
        ),
    >,
) {
    for s in spawned.0.drain(..) {
        // Changed: its `Transform` came or was written since the last step.
        let Ok((transform, mut position, rotation, _, poses)) = entities.get_mut(s.entity) else {
            continue;
        };
        let now = (transform.translation, transform.rotation);
        if s.read == Some(now) {
            continue;
        }
        let (translation, turn) = s.read.unwrap_or((Vec3::ZERO, Quat::IDENTITY));
        let take = (s.position_unset && position.0 == translation, |r: Quat| {
            s.rotation_unset && r == turn
        });
        take_pose(&transform, &mut position, rotation, poses, take);
    }
    for (transform, mut position, rotation, marble, poses) in &mut entities {
        // Spawned with it (the spawn hook read it), or written by the engine: by the
        // easing for an interpolated entity, else by the last step's write-back.
        let by_program = match &poses {
            // (A marble without a `Rotation`: only its translation counts.)
            Some(poses) => poses.set_by_program(&transform, !marble || rotation.is_some()),
            None => transform
                .last_changed()
                .is_newer_than(writes.tick, ticks.this_run()),
        };
        if transform.is_added() || !by_program {
            continue;
        }
        // A marble's orientation is only its spin's bookkeeping (written only when it
        // differs); a board's and a sensor's is their pose.
        let take = (true, |r: Quat| !marble || r != transform.rotation);
        take_pose(&transform, &mut position, rotation, poses, take);
    }
}

/// Moves an entity to its `Transform`: its position where `take.0`, its rotation where
/// `take.1` holds of its rotation; an interpolated one starts its poses there afresh, the
/// `Transform` taken.
fn take_pose(
    transform: &Ref<Transform>,
    position: &mut Mut<Position>,
    rotation: Option<Mut<Rotation>>,
    poses: Option<Mut<PhysicsPoses>>,
    take: (bool, impl Fn(Quat) -> bool),
) {
    if take.0 {
        position.0 = transform.translation;
    }
    let mut r = None;
    if let Some(mut rotation) = rotation {
        if take.1(rotation.0) {
            rotation.0 = transform.rotation;
        }
        r = Some(rotation.0);
    }
    if let Some(mut poses) = poses {
        poses.reset(position.0, r.unwrap_or(transform.rotation));
        poses.saw(transform);
    }
}

/// Writes marble positions (and orientations, for marbles that carry a `Rotation`), board
/// poses and the poses of sensors that moved (carried by a board) into their
/// `Transform`s; entities with [`TransformInterpolation`] are left to the interpolation.
#[allow(clippy::type_complexity)]
pub fn sync_transforms(
    mut writes: ResMut<TransformWrites>,
    ticks: SystemChangeTick,
    mut marbles: Query<
        (&Position, Option<&Rotation>, &mut Transform),
        (
            With<Marble>,
            Without<Board>,
            Without<TransformInterpolation>,
        ),
    >,
    mut boards: Query<
        (&Position, &Rotation, &mut Transform),
        (
            With<Board>,
            Without<Marble>,
            Without<TransformInterpolation>,
        ),
    >,
    mut sensors: Query<
        (&Position, &Rotation, &mut Transform),
        (
            With<Sensor>,
            Without<Board>,
            Without<Marble>,
            Without<TransformInterpolation>,
        ),
    >,
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
    // A sensor moves only when carried or moved by the program: its `Transform` is written
    // (and marked changed) only then.
    for (position, rotation, mut transform) in &mut sensors {
        if (transform.translation, transform.rotation) != (position.0, rotation.0) {
            transform.translation = position.0;
            transform.rotation = rotation.0;
        }
    }
    writes.tick = ticks.this_run();
}
