//! Kinematic boards: the per-substep snapshot and their motion.

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;

use crate::board_contact::{BoardCache, BoardSnapshot};
use crate::components::{
    AngularVelocity, Board, Collider, Friction, NextPose, Position, PositionCarry, Quarantined,
    Restitution, RollingResistance, Rotation, Sensor, SpinDamping, Velocity, compensated_add,
};
use crate::config::{StepConfig, Substep};
use crate::geometry::transform_aabb;

/// Snapshots every board (pose, motion, bounds swept over the substep) into
/// [`BoardCache`], reusing its storage. A board that is also a [`Sensor`] is a volume
/// marbles pass through: it is left out.
pub fn prepare_boards(
    substep: Res<Substep>,
    mut cache: ResMut<BoardCache>,
    boards: Query<
        (
            Entity,
            &Collider,
            &Position,
            &Rotation,
            &Velocity,
            &AngularVelocity,
            &Restitution,
            &Friction,
            Option<&RollingResistance>,
            Option<&SpinDamping>,
        ),
        (With<Board>, Without<Sensor>, Without<Quarantined>),
    >,
) {
    let h = substep.h;
    let cache = cache.as_mut();
    cache.boards.clear();
    for (
        entity,
        collider,
        position,
        rotation,
        velocity,
        angular,
        restitution,
        friction,
        rolling_resistance,
        spin_damping,
    ) in &boards
    {
        let local = collider.0.local_aabb();
        let reach = local.map_or(f32::INFINITY, |a| a.mins.abs().max(a.maxs.abs()).length());
        let swept_aabb = local.map(|a| {
            let start = transform_aabb(&a, position.0, rotation.0);
            let end_pos = position.0 + velocity.0 * h;
            if angular.0 == Vec3::ZERO {
                let end = transform_aabb(&a, end_pos, rotation.0);
                Aabb::new(start.mins.min(end.mins), start.maxs.max(end.maxs))
            } else {
                // Turning: everything within `reach` of the origin's path.
                let r = Vec3::splat(reach);
                Aabb::new(position.0.min(end_pos) - r, position.0.max(end_pos) + r)
            }
        });
        cache.boards.push(
            BoardSnapshot {
                entity,
                geometry: collider.0.clone(),
                position: position.0,
                rotation: rotation.0,
                velocity: velocity.0,
                angular_velocity: angular.0,
                restitution: restitution.0,
                friction: friction.0,
                rolling_resistance: rolling_resistance.map_or(0.0, |c| c.0),
                spin_damping: spin_damping.map_or(0.0, |c| c.0),
                swept_aabb,
                reach,
                pose_version: 0,
                poses: None,
            }
            .with_poses(h),
        );
    }
    // By entity, not the query's order: a board that gains or loses a component (a
    // `NextPose` each step) moves to another table, which would reorder the list, and the
    // marbles' recorded contacts and near-piece lists name pieces by their board's place
    // in it.
    cache.boards.sort_unstable_by_key(|b| b.entity);
    cache.update_epoch();
}

/// Advances every board by its linear and angular velocity over the substep (its position
/// by compensated summation, as a marble's: a board moving for minutes stays on its path
/// to f32's resolution).
pub fn move_boards(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    mut boards: Query<
        (
            &mut Position,
            Option<&mut PositionCarry>,
            &mut Rotation,
            &Velocity,
            &AngularVelocity,
        ),
        (With<Board>, Without<Quarantined>),
    >,
) {
    let h = substep.h;
    for (mut position, carry, mut rotation, velocity, angular) in &mut boards {
        if velocity.0 != Vec3::ZERO {
            let moved = velocity.0 * h;
            match carry {
                Some(mut carry) => {
                    (position.0, carry.0) =
                        compensated_add(config.compensated, position.0, carry.0, moved);
                }
                None => position.0 += moved,
            }
        }
        if angular.0 != Vec3::ZERO {
            rotation.0 = (Quat::from_scaled_axis(angular.0 * h) * rotation.0).normalize();
        }
    }
}

/// Advances the [`GravityTilt`](crate::config::GravityTilt) of a scene that models its
/// turning board by turning gravity (runs only when there is one).
pub fn advance_tilt(substep: Res<Substep>, mut tilt: ResMut<crate::config::GravityTilt>) {
    let h = substep.h;
    let tilt = tilt.as_mut();
    tilt.rotation = (Quat::from_scaled_axis(tilt.angular_velocity * h) * tilt.rotation).normalize();
}

/// First substep, before the snapshot: a board with a [`NextPose`] gets the constant
/// linear and angular velocity (about its position) that bring it to that pose at the
/// step's end.
pub fn drive_boards(
    config: Res<StepConfig>,
    mut boards: Query<
        (
            &Position,
            &Rotation,
            &NextPose,
            &mut Velocity,
            &mut AngularVelocity,
        ),
        (With<Board>, Without<Quarantined>),
    >,
) {
    let dt = config.dt;
    for (position, rotation, next, mut velocity, mut angular) in &mut boards {
        (velocity.0, angular.0) = next.motion(position.0, rotation.0, dt);
    }
}

/// Last substep, after the boards moved: a driven board is placed exactly at its
/// [`NextPose`] and holds still there (velocities zero, the component removed).
pub fn finish_driven_boards(
    mut commands: Commands,
    mut boards: Query<
        (
            Entity,
            &NextPose,
            &mut Position,
            &mut Rotation,
            &mut Velocity,
            &mut AngularVelocity,
        ),
        (With<Board>, Without<Quarantined>),
    >,
) {
    for (entity, next, mut position, mut rotation, mut velocity, mut angular) in &mut boards {
        position.0 = next.position;
        rotation.0 = next.rotation.normalize();
        velocity.0 = Vec3::ZERO;
        angular.0 = Vec3::ZERO;
        commands.entity(entity).remove::<NextPose>();
    }
}
