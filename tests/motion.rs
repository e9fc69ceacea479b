//! Free flight, the smooth incline, resting without jitter, and tunnelling.

mod common;

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use common::*;
use glam::{Quat, Vec3};

const R: f32 = 0.008;

fn plane(rotation: Quat, e: f32) -> BoardDesc {
    let mut b = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    b.rotation = rotation.to_array();
    b.restitution = e;
    b
}

/// Free flight per integrator, 1 s at dt = 1/60 from `x0 = (0, 10, 0)`, `v0 = (1, 5, −2)`:
/// Verlet and RK4 are exact (`x0 + v0 t + ½ g t²`) to f32 rounding; semi-implicit Euler
/// lands exactly `½ g dt t` lower and explicit Euler `½ g dt t` higher, the closed forms
/// of their sums (`Σ g dt² k`).
#[test]
fn free_flight_per_integrator() {
    let dt = 1.0 / 60.0;
    let n = 60;
    let t = n as f32 * dt;
    let x0 = Vec3::new(0.0, 10.0, 0.0);
    let v0 = Vec3::new(1.0, 5.0, -2.0);
    let g = Vec3::new(0.0, -G, 0.0);
    for integrator in Integrator::ALL {
        let mut m = MarbleDesc::at(x0.to_array());
        m.velocity = v0.to_array();
        let scene = Scene {
            dt,
            integrator,
            marbles: vec![m],
            ..Scene::default()
        };
        let (x, v) = *trajectory(&scene, n).last().unwrap();
        let exact = x0 + v0 * t + 0.5 * g * t * t;
        let expected = match integrator {
            Integrator::VelocityVerlet | Integrator::Rk4 => exact,
            Integrator::SemiImplicitEuler => exact + 0.5 * g * dt * t,
            Integrator::ExplicitEuler => exact - 0.5 * g * dt * t,
        };
        assert!(
            (x - expected).length() <= 2e-5,
            "{integrator:?}: {x} against {expected}"
        );
        assert!(
            (v - (v0 + g * t)).length() <= 2e-5,
            "{integrator:?}: v = {v}"
        );
    }
}

/// A marble released at rest on a smooth incline of angle θ slides `s = ½ g sinθ t²` and
/// stays on the surface: exact (0.01%) with Verlet and RK4, and with semi-implicit Euler
/// off by its first-order term `½ g sinθ dt t` (0.5% of s), with CCD on and off.
#[test]
fn smooth_incline() {
    let theta = 20f32.to_radians();
    let rot = Quat::from_rotation_z(theta);
    let normal = rot * Vec3::Y;
    let down_slope = rot * -Vec3::X;
    let dt = 1.0 / 240.0;
    let n = 240;
    let t = n as f32 * dt;
    for ccd in [true, false] {
        for integrator in [
            Integrator::VelocityVerlet,
            Integrator::Rk4,
            Integrator::SemiImplicitEuler,
        ] {
            let start = normal * R;
            let scene = Scene {
                dt,
                integrator,
                ccd,
                boards: vec![plane(rot, 0.5)],
                marbles: vec![MarbleDesc::at(start.to_array())],
                ..Scene::default()
            };
            let traj = trajectory(&scene, n);
            for (x, _) in &traj {
                let height = (*x).dot(normal);
                assert!(
                    (height - R).abs() <= 1e-6,
                    "{integrator:?} ccd={ccd}: left the surface, height {height}"
                );
            }
            let s = (traj[n].0 - start).dot(down_slope);
            let a = G * theta.sin();
            let exact = 0.5 * a * t * t;
            let expected = if integrator == Integrator::SemiImplicitEuler {
                exact + 0.5 * a * dt * t
            } else {
                exact
            };
            assert!(
                rel(s, expected) <= 1e-4,
                "{integrator:?} ccd={ccd}: s = {s}, expected {expected} (exact {exact})"
            );
        }
    }
}

/// A marble at rest on a board stays at rest at dt = 1/60 with e = 0.9, with and without
/// CCD, for every integrator and every kind of floor (plane, cuboid, mesh with a seam
/// under the marble, height field): no micro-bounces (no collision recorded), no sinking,
/// no creep, over 10 s.
#[test]
fn resting_marble_does_not_jitter() {
    let floors = [
        ShapeDesc::Plane(PlaneDesc {}),
        ShapeDesc::Cuboid {
            half_extents: [1.0, 0.5, 1.0],
        },
        ShapeDesc::TriMesh {
            vertices: vec![
                [-1.0, 0.0, -1.0],
                [1.0, 0.0, -1.0],
                [1.0, 0.0, 1.0],
                [-1.0, 0.0, 1.0],
            ],
            indices: vec![[0, 2, 1], [0, 3, 2]],
        },
        ShapeDesc::HeightField {
            heights: vec![vec![0.0; 4]; 4],
            scale: [2.0, 1.0, 2.0],
        },
    ];
    for floor in floors {
        let top = if matches!(floor, ShapeDesc::Cuboid { .. }) {
            0.5
        } else {
            0.0
        };
        for ccd in [true, false] {
            for integrator in Integrator::ALL {
                let mut board = BoardDesc::new(floor.clone());
                board.restitution = 0.9;
                let mut m = MarbleDesc::at([0.0, top + R, 0.0]);
                m.restitution = 0.9;
                let scene = Scene {
                    dt: 1.0 / 60.0,
                    integrator,
                    ccd,
                    boards: vec![board],
                    marbles: vec![m],
                    ..Scene::default()
                };
                let mut sim = Simulation::from_scene(&scene).unwrap();
                let marble = sim.marbles()[0];
                for step in 0..600 {
                    sim.step();
                    let (x, v) = sim.marble_state(0);
                    let contacts = sim.contacts(marble).unwrap();
                    let what = format!("{floor:?} {integrator:?} ccd={ccd} step {step}");
                    assert!(
                        (x - Vec3::new(0.0, top + R, 0.0)).length() <= 1e-6,
                        "{what}: moved to {x}"
                    );
                    assert!(v.length() <= 1e-6, "{what}: velocity {v}");
                    assert!(!contacts.is_empty(), "{what}: lost contact");
                    assert!(!contacts.has_collision(), "{what}: micro-bounce");
                }
            }
        }
    }
}

/// A dropped marble with e = 0.9 bounces, settles, and then rests on the plane exactly.
#[test]
fn dropped_marble_comes_to_rest() {
    for ccd in [true, false] {
        let scene = drop_scene(0.05, R, 0.9, 1.0 / 60.0, Integrator::SemiImplicitEuler, ccd);
        let traj = trajectory(&scene, 600);
        for (x, v) in &traj[300..] {
            assert!((x.y - R).abs() <= 1e-6, "ccd={ccd}: y = {}", x.y);
            assert!(v.length() <= 1e-6, "ccd={ccd}: v = {v}");
        }
    }
}

fn wall_scene(speed: f32, ccd: bool, wall_velocity: [f32; 3], spin: [f32; 3]) -> Scene {
    // A 2 mm thick wall at x = 1 m; the marble starts at the origin heading for it.
    let mut wall = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.001, 0.5, 0.5],
    });
    wall.position = [1.0, 0.0, 0.0];
    wall.velocity = wall_velocity;
    wall.angular_velocity = spin;
    wall.restitution = 0.5;
    let mut m = MarbleDesc::at([0.0, 0.0, 0.0]);
    m.velocity = [speed, 0.0, 0.0];
    m.restitution = 0.5;
    Scene {
        dt: 1.0 / 60.0,
        ccd,
        gravity: [0.0; 3],
        boards: vec![wall],
        marbles: vec![m],
        ..Scene::default()
    }
}

/// A marble at 300 m/s against a 2 mm wall at 60 Hz (5 m per step, 625 radii) bounces
/// back with CCD and never reaches the far side: off the still wall at `e·300`, off the
/// wall coming at it at 20 m/s at `−e (300 + 20) − 20`, off the wall spinning at 3 rad/s
/// about Y by equation (1) with the face turned at the impact time and its surface
/// velocity there (`face_impact`); each to 2e-3 m/s (f32 rounding at 300 m/s is 3e-5
/// m/s per operation).
#[test]
fn no_tunnelling_with_ccd() {
    for (wall_velocity, spin) in [
        ([0.0; 3], [0.0; 3]),
        ([-20.0, 0.0, 0.0], [0.0; 3]),
        ([0.0; 3], [0.0, 3.0, 0.0]),
    ] {
        let traj = trajectory(&wall_scene(300.0, true, wall_velocity, spin), 30);
        for (x, _) in &traj {
            assert!(
                x.x <= 1.0 + 0.001 * 30.0 * 20.0,
                "wall {wall_velocity:?} spin {spin:?}: passed through to {x}"
            );
        }
        let (_, want) = face_impact(
            Vec3::ZERO,
            Vec3::new(300.0, 0.0, 0.0),
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::from_array(wall_velocity),
            Vec3::from_array(spin),
            -Vec3::X,
            0.001,
            R,
            0.5,
        );
        let (_, v) = traj[30];
        assert!(
            (v - want).length() <= 2e-3,
            "wall {wall_velocity:?} spin {spin:?}: v = {v}, equation (1) gives {want}"
        );
    }
    // The closed forms of the first two.
    let face = |vb: Vec3| {
        face_impact(
            Vec3::ZERO,
            Vec3::X * 300.0,
            Vec3::ZERO,
            Vec3::X,
            vb,
            Vec3::ZERO,
            -Vec3::X,
            0.001,
            R,
            0.5,
        )
        .1
    };
    let (still, moving) = (face(Vec3::ZERO), face(Vec3::X * -20.0));
    assert!((still.x + 150.0).abs() <= 1e-4 && (moving.x + 180.0).abs() <= 1e-4);
}

/// Without CCD the same marble passes through: the trade continuous collision buys.
#[test]
fn discrete_detection_tunnels_at_300_m_per_s() {
    let (x, _) = *trajectory(&wall_scene(300.0, false, [0.0; 3], [0.0; 3]), 10)
        .last()
        .unwrap();
    assert!(x.x > 1.0, "x = {x}");
}
