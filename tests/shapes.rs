//! Every board shape of the contract: plane, cuboid, triangle mesh, height field, compound.

mod common;

use bevy_marble::prelude::*;
use bevy_marble::scene::{PartDesc, PlaneDesc};
use common::*;
use glam::{Quat, Vec3};

const R: f32 = 0.008;

/// A flat square mesh of `n × n` cells (2·n² triangles) over [−1, 1]², at y = 0.
fn grid_mesh(n: usize) -> ShapeDesc {
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let x = -1.0 + 2.0 * j as f32 / n as f32;
            let z = -1.0 + 2.0 * i as f32 / n as f32;
            vertices.push([x, 0.0, z]);
        }
    }
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    for i in 0..n {
        for j in 0..n {
            indices.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            indices.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    ShapeDesc::TriMesh { vertices, indices }
}

/// Each shape, with the height of its top surface under (0, 0).
fn shapes() -> Vec<(&'static str, ShapeDesc, f32)> {
    vec![
        ("plane", ShapeDesc::Plane(PlaneDesc {}), 0.0),
        (
            "cuboid",
            ShapeDesc::Cuboid {
                half_extents: [1.0, 0.25, 1.0],
            },
            0.25,
        ),
        ("trimesh", grid_mesh(8), 0.0),
        (
            "heightfield",
            ShapeDesc::HeightField {
                heights: vec![vec![0.1; 6]; 5],
                scale: [2.0, 1.0, 2.0],
            },
            0.1,
        ),
        (
            "compound",
            ShapeDesc::Compound(vec![
                PartDesc {
                    shape: ShapeDesc::Cuboid {
                        half_extents: [0.5, 0.1, 1.0],
                    },
                    position: [-0.5, 0.2, 0.0],
                    rotation: [0.0, 0.0, 0.0, 1.0],
                },
                PartDesc {
                    shape: ShapeDesc::Cuboid {
                        half_extents: [0.5, 0.1, 1.0],
                    },
                    position: [0.5, 0.2, 0.0],
                    rotation: [0.0, 0.0, 0.0, 1.0],
                },
            ]),
            0.3,
        ),
    ]
}

/// A marble dropped 0.5 m onto each shape (onto the seam of the compound's two parts and
/// onto a mesh vertex) bounces to `e² h` within the sampling bound, then rests on the
/// surface.
#[test]
fn every_shape_bounces_and_holds() {
    for (name, shape, top) in shapes() {
        let mut board = BoardDesc::new(shape);
        board.restitution = 0.8;
        let mut m = MarbleDesc::at([0.0, top + 0.5 + R, 0.0]);
        m.restitution = 0.8;
        let dt = 1.0 / 240.0;
        let scene = Scene {
            dt,
            integrator: Integrator::VelocityVerlet,
            boards: vec![board],
            marbles: vec![m],
            ..Scene::default()
        };
        let traj = trajectory(&scene, 240 * 8);
        let first = apexes(&traj, R)[0] - top;
        let exact = 0.5 * 0.64;
        assert!(
            (first - exact).abs() <= G * dt * dt / 8.0 + 1e-4 * exact,
            "{name}: first apex {first}, exact {exact}"
        );
        let (x, v) = *traj.last().unwrap();
        assert!(
            (x - Vec3::new(0.0, top + R, 0.0)).length() <= 1e-5 && v.length() <= 1e-5,
            "{name}: ended at {x}, v = {v}"
        );
    }
}

/// A marble sliding on a flat mesh of 2·20² triangles crosses dozens of internal edges
/// at 2 m/s without a "ghost bump": it never leaves the surface, its speed never changes
/// and no collision is ever recorded.
#[test]
fn no_ghost_bumps_on_internal_edges() {
    let mut m = MarbleDesc::at([-0.9, R, -0.7]);
    m.velocity = [1.6, 0.0, 1.2];
    let scene = Scene {
        dt: 1.0 / 60.0,
        boards: vec![BoardDesc::new(grid_mesh(20))],
        marbles: vec![m],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let marble = sim.marbles()[0];
    for step in 0..50 {
        sim.step();
        let (x, v) = sim.marble_state(0);
        assert!((x.y - R).abs() <= 2e-6, "step {step}: y = {}", x.y);
        assert!(
            (v - Vec3::new(1.6, 0.0, 1.2)).length() <= 1e-5,
            "step {step}: v = {v}"
        );
        assert!(!sim.contacts(marble).unwrap().has_collision());
    }
}

/// Both faces of a mesh collide: with gravity up, a marble hits the mesh from below and
/// bounces down with `v' = −e v`.
#[test]
fn mesh_collides_from_below() {
    let mut board = BoardDesc::new(grid_mesh(3));
    board.restitution = 0.5;
    let mut m = MarbleDesc::at([0.1, -0.2, 0.1]);
    m.velocity = [0.0, 2.0, 0.0];
    m.restitution = 0.5;
    let scene = Scene {
        dt: 1.0 / 60.0,
        gravity: [0.0; 3],
        boards: vec![board],
        marbles: vec![m],
        ..Scene::default()
    };
    let traj = trajectory(&scene, 30);
    let (x, v) = *traj.last().unwrap();
    assert!((v - Vec3::new(0.0, -1.0, 0.0)).length() <= 1e-5, "v = {v}");
    assert!(traj.iter().all(|(x, _)| x.y <= -R + 1e-5), "crossed: {x}");
}

/// A smooth slope built as a height field (rising 0.2 m per metre along X, 11.3°) gives
/// the incline's `s = ½ g sinθ t²` (Verlet, 0.05%).
#[test]
fn heightfield_slope_is_an_incline() {
    let heights: Vec<Vec<f32>> = (0..5)
        .map(|_| (0..9).map(|j| 0.2 * (-2.0 + 0.5 * j as f32)).collect())
        .collect();
    let theta = 0.2f32.atan();
    let n = Quat::from_rotation_z(theta) * Vec3::Y;
    let start = Vec3::new(1.0, 0.2, 0.0) + n * R;
    let scene = Scene {
        dt: 1.0 / 240.0,
        integrator: Integrator::VelocityVerlet,
        boards: vec![BoardDesc::new(ShapeDesc::HeightField {
            heights,
            scale: [4.0, 1.0, 2.0],
        })],
        marbles: vec![MarbleDesc::at(start.to_array())],
        ..Scene::default()
    };
    let traj = trajectory(&scene, 120);
    let s = (traj[120].0 - start).length();
    let exact = 0.5 * G * theta.sin() * 0.25;
    assert!(rel(s, exact) <= 5e-4, "s = {s}, exact {exact}");
}

/// A marble sliding slowly (below the restitution threshold) into the corner of a walled
/// compound board comes to rest touching floor and both walls, three contacts recorded.
#[test]
fn resting_in_a_corner_touches_three_boards() {
    let parts = bevy_marble::scenes::walled_floor(0.1, 0.05);
    let mut m = MarbleDesc::at([0.05, R, 0.07]);
    m.velocity = [0.04, 0.0, 0.03];
    let scene = Scene {
        dt: 1.0 / 120.0,
        boards: vec![BoardDesc::new(ShapeDesc::Compound(parts))],
        marbles: vec![m],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..600 {
        sim.step();
    }
    let (x, v) = sim.marble_state(0);
    assert!(
        (x - Vec3::new(0.1 - R, R, 0.1 - R)).length() <= 1e-5 && v.length() <= 1e-5,
        "x = {x}, v = {v}"
    );
    let contacts = sim.contacts(sim.marbles()[0]).unwrap();
    assert_eq!(contacts.len(), 3, "{contacts:?}");
}
