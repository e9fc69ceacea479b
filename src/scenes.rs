//! Scenes defined once and shared by the CLI, tests, benches and examples.

use crate::scene::{BoardDesc, MarbleDesc, PartDesc, PlaneDesc, Scene, ShapeDesc};

fn cuboid(half_extents: [f32; 3], position: [f32; 3]) -> PartDesc {
    PartDesc {
        shape: ShapeDesc::Cuboid { half_extents },
        position,
        rotation: [0.0, 0.0, 0.0, 1.0],
    }
}

/// A walled square board, `half` metres from centre to wall, as compound parts: a floor
/// whose top face is at local y = 0 and four walls `wall_height` high.
pub fn walled_floor(half: f32, wall_height: f32) -> Vec<PartDesc> {
    let t = 0.01; // wall and floor half thickness
    let h = wall_height * 0.5;
    vec![
        cuboid([half + 2.0 * t, t, half + 2.0 * t], [0.0, -t, 0.0]),
        cuboid([t, h, half + 2.0 * t], [half + t, h, 0.0]),
        cuboid([t, h, half + 2.0 * t], [-half - t, h, 0.0]),
        cuboid([half, h, t], [0.0, h, half + t]),
        cuboid([half, h, t], [0.0, h, -half - t]),
    ]
}

/// The built-in scene of `marble` and `marble scene`: a 40 cm labyrinth board with walls
/// and inner baffles, tilting slowly through level (−0.1 rad about X to +0.1 rad over
/// 10 s), and 48 glass marbles dropped onto it.
pub fn default_scene() -> Scene {
    let half = 0.2;
    let mut parts = walled_floor(half, 0.03);
    // Inner baffles of the labyrinth.
    for (i, z) in [-0.1f32, 0.0, 0.1].iter().enumerate() {
        let x = if i % 2 == 0 { -0.05 } else { 0.05 };
        parts.push(cuboid([0.15, 0.015, 0.005], [x, 0.015, *z]));
    }
    let tilt = -0.1f32;
    let mut board = BoardDesc::new(ShapeDesc::Compound(parts));
    board.rotation = [(tilt / 2.0).sin(), 0.0, 0.0, (tilt / 2.0).cos()];
    board.angular_velocity = [0.02, 0.0, 0.0];
    board.restitution = 0.6;
    let mut marbles = Vec::new();
    for i in 0..8 {
        for j in 0..6 {
            let x = -0.17 + 0.048 * i as f32;
            let z = -0.17 + 0.065 * j as f32 + 0.01;
            let mut m = MarbleDesc::at([x, 0.06 + 0.004 * ((i + j) % 3) as f32, z]);
            m.restitution = 0.7;
            marbles.push(m);
        }
    }
    Scene {
        dt: 1.0 / 240.0,
        duration: 10.0,
        boards: vec![board],
        marbles,
        ..Scene::default()
    }
}

/// Bench scene (a): `n` marbles resting in a square grid on a walled board tilted by
/// 1°, spaced four radii apart so that they never touch each other while the bench runs.
pub fn walled_board(n: usize) -> Scene {
    let r = crate::components::DEFAULT_RADIUS;
    let spacing = 4.0 * r;
    let side = (n as f64).sqrt().ceil() as usize;
    let half = spacing * side as f32 * 0.5 + spacing;
    let tilt = 1.0f32.to_radians();
    let mut board = BoardDesc::new(ShapeDesc::Compound(walled_floor(half, 0.03)));
    board.rotation = [0.0, 0.0, (tilt / 2.0).sin(), (tilt / 2.0).cos()];
    let (s, c) = tilt.sin_cos();
    let marbles = (0..n)
        .map(|k| {
            let (i, j) = (k % side, k / side);
            let u = -half + spacing * (i as f32 + 1.5);
            let w = -half + spacing * (j as f32 + 1.5);
            // On the tilted floor: local (u, r, w) rotated about Z.
            MarbleDesc::at([u * c - r * s, u * s + r * c, w])
        })
        .collect();
    Scene {
        dt: 1.0 / 60.0,
        boards: vec![board],
        marbles,
        ..Scene::default()
    }
}

/// A marble of radius `r` dropped from `height` (bottom above the surface) onto a plane,
/// both with restitution `e`.
pub fn drop_on_plane(height: f32, r: f32, e: f32) -> Scene {
    let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    board.restitution = e;
    let mut m = MarbleDesc::at([0.0, height + r, 0.0]);
    m.radius = r;
    m.restitution = e;
    Scene {
        boards: vec![board],
        marbles: vec![m],
        ..Scene::default()
    }
}
