//! Debug drawing with bevy's gizmos (feature `debug_draw`): board shapes, sensor volumes,
//! each marble's contacts with their normals, and impacts as they happen.
//!
//! Add [`MarbleDebugDrawPlugin`] to an app that renders gizmos (bevy's `bevy_gizmos` and
//! `bevy_gizmos_render`, in `DefaultPlugins`), and switch it at run time through the
//! [`MarbleDebugDraw`] resource:
//!
//! ```ignore
//! fn toggle(keys: Res<ButtonInput<KeyCode>>, mut draw: ResMut<MarbleDebugDraw>) {
//!     if keys.just_pressed(KeyCode::F1) {
//!         draw.enabled = !draw.enabled;
//!     }
//! }
//! ```

use std::sync::Arc;

use bevy_app::{App, Plugin, PostUpdate};
use bevy_color::Color;
use bevy_ecs::prelude::*;
use bevy_gizmos::prelude::Gizmos;
use bevy_math::Isometry3d;
use bevy_time::Time;
use bevy_transform::components::GlobalTransform;
use glam::{Quat, Vec3};

use crate::components::{Board, BoardContacts, Collider, ContactKind, Position, Rotation, Sensor};
use crate::events::MarbleImpact;

/// Draws the physics with gizmos; see the [module](self).
pub struct MarbleDebugDrawPlugin;

impl Plugin for MarbleDebugDrawPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<MarbleDebugDraw>()
            .init_resource::<RecentImpacts>()
            .add_systems(
                PostUpdate,
                (
                    outline_new_shapes,
                    note_impacts,
                    (draw_shapes, draw_contacts, draw_impacts)
                        .run_if(|draw: Res<MarbleDebugDraw>| draw.enabled),
                )
                    .chain()
                    .after(bevy_transform::TransformSystems::Propagate),
            );
    }
}

/// What the debug drawing shows (a resource; change it at run time).
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct MarbleDebugDraw {
    /// Draw anything at all.
    pub enabled: bool,
    /// Board outlines.
    pub boards: bool,
    /// Sensor volumes.
    pub sensors: bool,
    /// Contact points and their normals (collisions red, contacts cyan).
    pub contacts: bool,
    /// A ring at each impact, fading over [`Self::impact_seconds`], wider for harder hits.
    pub impacts: bool,
    /// How long an impact's ring stays, s.
    pub impact_seconds: f32,
    /// Length of a contact normal's arrow, m.
    pub normal_length: f32,
    /// Board colour.
    pub board_colour: Color,
    /// Sensor colour.
    pub sensor_colour: Color,
}

impl Default for MarbleDebugDraw {
    /// On, everything shown; impacts for 0.4 s; normals 2 cm.
    fn default() -> Self {
        MarbleDebugDraw {
            enabled: true,
            boards: true,
            sensors: true,
            contacts: true,
            impacts: true,
            impact_seconds: 0.4,
            normal_length: 0.02,
            board_colour: Color::srgb(0.55, 0.62, 0.72),
            sensor_colour: Color::srgb(0.95, 0.8, 0.2),
        }
    }
}

/// The outline of a board's or a sensor's shape in its own frame, computed once when its
/// [`Collider`] is added or changed ([`crate::replay::wireframe::segments`]).
#[derive(Component, Clone, Debug)]
pub struct Outline(pub Arc<Vec<[Vec3; 2]>>);

/// Impacts of the last [`MarbleDebugDraw::impact_seconds`]: `(point, normal, speed, time)`.
#[derive(Resource, Default, Debug)]
struct RecentImpacts(Vec<(Vec3, Vec3, f32, f32)>);

/// Half-size of the grid that draws an unbounded board (a plane), m.
const PLANE_EXTENT: f32 = 1.0;

fn outline_new_shapes(
    mut commands: Commands,
    shapes: Query<(Entity, &Collider), (Or<(With<Board>, With<Sensor>)>, Changed<Collider>)>,
) {
    for (entity, collider) in &shapes {
        let segments = crate::replay::wireframe::segments(&collider.0, PLANE_EXTENT);
        commands.entity(entity).insert(Outline(Arc::new(segments)));
    }
}

/// The pose to draw at: the rendered one where there is a `GlobalTransform`, else the
/// physics pose.
fn pose(
    global: Option<&GlobalTransform>,
    position: &Position,
    rotation: &Rotation,
) -> (Vec3, Quat) {
    match global {
        Some(g) => {
            let (_, q, p) = g.to_scale_rotation_translation();
            (p, q)
        }
        None => (position.0, rotation.0),
    }
}

fn draw_shapes(
    draw: Res<MarbleDebugDraw>,
    mut gizmos: Gizmos,
    shapes: Query<(
        &Outline,
        &Position,
        &Rotation,
        Option<&GlobalTransform>,
        Has<Sensor>,
    )>,
) {
    for (outline, position, rotation, global, sensor) in &shapes {
        if (sensor && !draw.sensors) || (!sensor && !draw.boards) {
            continue;
        }
        let colour = if sensor {
            draw.sensor_colour
        } else {
            draw.board_colour
        };
        let (p, q) = pose(global, position, rotation);
        for [a, b] in outline.0.iter() {
            gizmos.line(p + q * *a, p + q * *b, colour);
        }
    }
}

fn draw_contacts(draw: Res<MarbleDebugDraw>, mut gizmos: Gizmos, marbles: Query<BoardContacts>) {
    if !draw.contacts {
        return;
    }
    for contacts in &marbles {
        for c in contacts.iter() {
            let colour = match c.kind {
                ContactKind::Collision => Color::srgb(1.0, 0.3, 0.25),
                ContactKind::Contact => Color::srgb(0.3, 0.9, 1.0),
            };
            gizmos.arrow(c.point, c.point + c.normal * draw.normal_length, colour);
        }
    }
}

fn note_impacts(
    draw: Res<MarbleDebugDraw>,
    time: Res<Time>,
    mut impacts: MessageReader<MarbleImpact>,
    mut recent: ResMut<RecentImpacts>,
) {
    let now = time.elapsed_secs();
    recent.0.retain(|i| now - i.3 < draw.impact_seconds);
    for i in impacts.read() {
        recent.0.push((i.point, i.normal, i.speed, now));
    }
}

fn draw_impacts(
    draw: Res<MarbleDebugDraw>,
    time: Res<Time>,
    recent: Res<RecentImpacts>,
    mut gizmos: Gizmos,
) {
    if !draw.impacts {
        return;
    }
    let now = time.elapsed_secs();
    for &(point, normal, speed, at) in &recent.0 {
        let age = ((now - at) / draw.impact_seconds).clamp(0.0, 1.0);
        // 5 mm plus 1 cm per m/s of closing speed, growing by half as it fades.
        let radius = (0.005 + 0.01 * speed.min(5.0)) * (1.0 + 0.5 * age);
        let rotation = Quat::from_rotation_arc(Vec3::Z, normal.normalize_or(Vec3::Y));
        gizmos.circle(
            Isometry3d::new(point, rotation),
            radius,
            Color::srgba(1.0, 0.95, 0.8, 1.0 - age),
        );
    }
}
