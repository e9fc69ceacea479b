//! Marbles that roll (`rolling: true`): spin, Coulomb friction, rolling resistance, against
//! the exact answers of `docs/PHYSICS.md` §5 and §8.

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use glam::{Quat, Vec3};

const R: f32 = 0.008;
const G: f32 = 9.81;

fn plane(rotation: Quat, friction: f32) -> BoardDesc {
    let mut b = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    b.rotation = rotation.to_array();
    b.friction = friction;
    b
}

fn marble(position: Vec3, velocity: Vec3, spin: Vec3, friction: f32) -> MarbleDesc {
    let mut m = MarbleDesc::at(position.to_array());
    m.velocity = velocity.to_array();
    m.angular_velocity = spin.to_array();
    m.friction = friction;
    m
}

fn rolling_scene(dt: f32, boards: Vec<BoardDesc>, marbles: Vec<MarbleDesc>) -> Scene {
    Scene {
        dt,
        rolling: true,
        preset: Some(Preset::Balanced),
        boards,
        marbles,
        ..Scene::default()
    }
}

/// (position, velocity, spin) of marble 0 after each step, the initial state first.
fn run(scene: &Scene, steps: usize) -> Vec<(Vec3, Vec3, Vec3)> {
    let mut sim = Simulation::from_scene(scene).unwrap();
    let mut out = vec![(
        sim.marble_state(0).0,
        sim.marble_state(0).1,
        sim.marble_spin(0),
    )];
    for _ in 0..steps {
        sim.step();
        let (x, v) = sim.marble_state(0);
        out.push((x, v, sim.marble_spin(0)));
    }
    out
}

/// Slip of the contact point on a static board with normal `n`.
fn slip(v: Vec3, w: Vec3, n: Vec3) -> Vec3 {
    v + w.cross(-R * n)
}

/// Down a 20° incline from rest (μ = 0.5 ≥ (2/7) tan 20° = 0.10, so it rolls without
/// slipping): `s = ½ (5/7) g sinθ t²` within 1% at dt = 1/240 and 3% at 1/60 (the issue's
/// bars; measured far closer), with `ω r = v` throughout.
#[test]
fn rolls_down_an_incline() {
    let theta = 20f32.to_radians();
    let rot = Quat::from_rotation_z(theta);
    let n = rot * Vec3::Y;
    let down = rot * -Vec3::X;
    for (dt, bar) in [(1.0 / 240.0, 0.01), (1.0 / 60.0, 0.03)] {
        let start = n * R;
        let scene = rolling_scene(
            dt,
            vec![plane(rot, 0.5)],
            vec![marble(start, Vec3::ZERO, Vec3::ZERO, 0.5)],
        );
        let steps = (1.0 / dt).round() as usize;
        let traj = run(&scene, steps);
        let t = steps as f32 * dt;
        let s = (traj[steps].0 - start).dot(down);
        let exact = 0.5 * (5.0 / 7.0) * G * theta.sin() * t * t;
        let err = ((s - exact) / exact).abs();
        assert!(err <= bar, "dt={dt}: s = {s}, exact {exact}, error {err}");
        assert!(err <= 1e-3, "dt={dt}: error {err} (expected f32-level)");
        for (i, (_, v, w)) in traj.iter().enumerate() {
            assert!(
                slip(*v, *w, n).length() <= 1e-4,
                "dt={dt} step {i}: slipping"
            );
        }
    }
}

/// Launched at v0 = 2 m/s without spin on a flat board with μ = 0.2: kinetic friction
/// slows it and spins it up; rolling begins at `2 v0 / (7 μ g)` (within one step) and
/// then `v = (5/7) v0` (within 0.1%) with `ω r = v`.
#[test]
fn slip_turns_to_roll() {
    let (v0, mu) = (2.0f32, 0.2f32);
    for dt in [1.0 / 60.0, 1.0 / 240.0] {
        let scene = rolling_scene(
            dt,
            vec![plane(Quat::IDENTITY, mu)],
            vec![marble(Vec3::new(0.0, R, 0.0), Vec3::X * v0, Vec3::ZERO, mu)],
        );
        let traj = run(&scene, (1.0 / dt) as usize);
        let rolling_from = traj
            .iter()
            .position(|(_, v, w)| slip(*v, *w, Vec3::Y).length() <= 1e-4)
            .expect("starts rolling");
        let t_roll = rolling_from as f32 * dt;
        let exact = 2.0 * v0 / (7.0 * mu * G);
        assert!(
            t_roll >= exact - 1e-6 && t_roll <= exact + dt + 1e-6,
            "dt={dt}: rolling from {t_roll}, exact {exact}"
        );
        for (x, v, w) in &traj[rolling_from..] {
            assert!(
                ((v.x - 5.0 / 7.0 * v0) / v0).abs() <= 1e-3,
                "dt={dt}: v = {v}"
            );
            assert!(
                (w.z * R + v.x).abs() <= 1e-4,
                "dt={dt}: ω r = {} v = {}",
                -w.z * R,
                v.x
            );
            assert!((x.y - R).abs() <= 1e-6, "dt={dt}: left the board");
        }
    }
}

/// Rolling at 1 m/s on a level board with rolling resistance c = 0.02 (marble and board):
/// it decelerates at `(5/7) c g` (within 1%), keeps rolling (`ω r = v`), and stops.
#[test]
fn rolling_resistance_decelerates_at_five_sevenths_c_g() {
    let c = 0.02f32;
    let dt = 1.0 / 120.0;
    let mut board = plane(Quat::IDENTITY, 0.5);
    board.rolling_resistance = c;
    let mut m = marble(
        Vec3::new(0.0, R, 0.0),
        Vec3::X,
        Vec3::new(0.0, 0.0, -1.0 / R),
        0.5,
    );
    m.rolling_resistance = c;
    let traj = run(&rolling_scene(dt, vec![board], vec![m]), 960);
    let decel = 5.0 / 7.0 * c * G;
    for (i, (_, v, w)) in traj.iter().enumerate().take(60) {
        let t = i as f32 * dt;
        let want = 1.0 - decel * t;
        assert!(
            (v.x - want).abs() <= 0.01 * decel * t + 1e-5,
            "step {i}: v = {}, want {want}",
            v.x
        );
        assert!(slip(*v, *w, Vec3::Y).length() <= 1e-4, "step {i}: slipping");
    }
    // Stops after v0 / decel = 7.3 s and stays stopped.
    let (_, v, w) = traj[960];
    assert!(v.length() <= 1e-5 && w.length() <= 1e-3, "v = {v}, ω = {w}");
}

/// An oblique impact with friction puts spin on the marble: hitting the floor at
/// (2, −3) m/s with e = 0.5 and μ = 0.5, the tangential impulse that stops the slip,
/// −(2/7)·2 m/s, is within Coulomb's μ·(1 + e)·3 m/s, so the marble leaves rolling:
/// `v_x = (5/7)·2`, `ω_z r = −v_x`, `v_y = e·3`.
#[test]
fn oblique_impact_spins_the_marble() {
    let mut board = plane(Quat::IDENTITY, 0.5);
    board.restitution = 0.5;
    let mut m = marble(
        Vec3::new(0.0, 0.1, 0.0),
        Vec3::new(2.0, -3.0, 0.0),
        Vec3::ZERO,
        0.5,
    );
    m.restitution = 0.5;
    let mut scene = rolling_scene(1.0 / 240.0, vec![board], vec![m]);
    scene.gravity = [0.0; 3];
    let (_, v, w) = *run(&scene, 60).last().unwrap();
    assert!((v.x - 10.0 / 7.0).abs() <= 1e-4, "v = {v}");
    assert!((v.y - 1.5).abs() <= 1e-4, "v = {v}");
    assert!((w.z * R + v.x).abs() <= 1e-4, "ω = {w}");
}

/// A marble resting on a board that moves sideways at 0.5 m/s is carried along: friction
/// spins it up until it rolls on the board; with rolling resistance (c = 0.05) the rolling
/// then dies out and the marble ends at the board's speed, rolling relative to nothing.
#[test]
fn a_moving_board_carries_the_marble() {
    let mut board = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [100.0, 0.05, 1.0],
    });
    board.position = [0.0, -0.05, 0.0];
    board.velocity = [0.5, 0.0, 0.0];
    board.rolling_resistance = 0.05;
    let mut m = marble(Vec3::new(0.0, R, 0.0), Vec3::ZERO, Vec3::ZERO, 0.5);
    m.rolling_resistance = 0.05;
    let traj = run(&rolling_scene(1.0 / 60.0, vec![board], vec![m]), 180);
    let (_, v, w) = *traj.last().unwrap();
    assert!((v - Vec3::new(0.5, 0.0, 0.0)).length() <= 1e-4, "v = {v}");
    assert!(w.length() <= 1e-2, "ω = {w}");
    // Energy in the board's frame never grows.
    let energy = |v: Vec3, w: Vec3| {
        let u = v - Vec3::new(0.5, 0.0, 0.0);
        0.5 * u.length_squared() + 0.5 * 0.4 * R * R * w.length_squared()
    };
    for pair in traj.windows(2) {
        assert!(energy(pair[1].1, pair[1].2) <= energy(pair[0].1, pair[0].2) + 1e-7);
    }
}

/// A labyrinth board tilting at 0.2 rad/s about Z (its +X side going up): a marble resting
/// on it near the axis rolls towards −X, stays in contact, and rolls without slipping.
#[test]
fn tilting_board_rolls_the_marble_downhill() {
    let mut board = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [1.0, 0.05, 1.0],
    });
    board.position = [0.0, -0.05, 0.0];
    board.angular_velocity = [0.0, 0.0, 0.2];
    let scene = rolling_scene(
        1.0 / 60.0,
        vec![board],
        vec![marble(Vec3::new(0.0, R, 0.0), Vec3::ZERO, Vec3::ZERO, 0.5)],
    );
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let m = sim.marbles()[0];
    for _ in 0..60 {
        sim.step();
        assert!(
            !sim.world().get::<Contacts>(m).unwrap().is_empty(),
            "lost contact"
        );
    }
    let (x, v) = sim.marble_state(0);
    let w = sim.marble_spin(0);
    assert!(v.x < -0.1 && x.x < 0.0, "x = {x}, v = {v}");
    // Rolling: ω about +Z for motion towards −X.
    assert!(
        w.z > 0.0 && (w.z * R + v.x).abs() <= 0.05 * v.x.abs(),
        "ω = {w}, v = {v}"
    );
}

/// Rolling off costs no spin: with `rolling: false` marbles carry no angular velocity and
/// slide down the incline at the smooth rate.
#[test]
fn rolling_off_stores_no_spin() {
    let scene = Scene {
        boards: vec![plane(Quat::IDENTITY, 0.5)],
        marbles: vec![MarbleDesc::at([0.0, R, 0.0])],
        ..Scene::default()
    };
    let sim = Simulation::from_scene(&scene).unwrap();
    assert!(
        sim.world()
            .get::<AngularVelocity>(sim.marbles()[0])
            .is_none()
    );
}

/// With the default semi-implicit Euler the marble rolls too (its stored velocity and spin
/// both lag the path by half a step, so `ω r = v` holds in what it reports), and slides the
/// incline by the scheme's closed form `½ a t² + ½ a dt t` with `a = (5/7) g sinθ`.
#[test]
fn rolls_with_semi_implicit_euler() {
    let theta = 20f32.to_radians();
    let rot = Quat::from_rotation_z(theta);
    let n = rot * Vec3::Y;
    let dt = 1.0 / 60.0;
    let start = n * R;
    let mut scene = rolling_scene(
        dt,
        vec![plane(rot, 0.5)],
        vec![marble(start, Vec3::ZERO, Vec3::ZERO, 0.5)],
    );
    scene.preset = None;
    let traj = run(&scene, 60);
    let a = 5.0 / 7.0 * G * theta.sin();
    let t = 60.0 * dt;
    let s = (traj[60].0 - start).dot(rot * -Vec3::X);
    let want = 0.5 * a * t * t + 0.5 * a * dt * t;
    assert!(((s - want) / want).abs() <= 1e-3, "s = {s}, want {want}");
    for (i, (_, v, w)) in traj.iter().enumerate() {
        assert!(slip(*v, *w, n).length() <= 1e-4, "step {i}: slipping");
    }
}

/// Times between successive upward zero crossings of x (linearly interpolated).
fn periods(traj: &[(Vec3, Vec3, Vec3)], dt: f32) -> Vec<f32> {
    let mut crossings = Vec::new();
    for (i, w) in traj.windows(2).enumerate() {
        let (a, b) = (w[0].0.x, w[1].0.x);
        if a < 0.0 && b >= 0.0 {
            crossings.push((i as f32 + a / (a - b)) * dt);
        }
    }
    crossings.windows(2).map(|c| c[1] - c[0]).collect()
}

/// A marble rolling in a spherical bowl of radius R = 0.5 m, released 0.05 rad from the
/// bottom: small oscillations of period `2π √(7 (R − r) / (5 g))` (within 1%), and without
/// rolling (smooth) `2π √((R − r) / g)`.
#[test]
fn bowl_oscillation_period() {
    let big_r = 0.5f32;
    let rho = big_r - R;
    let theta0 = 0.05f32;
    let start = Vec3::new(rho * theta0.sin(), -rho * theta0.cos(), 0.0);
    let dt = 1.0 / 240.0;
    for rolling in [true, false] {
        let mut scene = rolling_scene(
            dt,
            vec![BoardDesc::new(ShapeDesc::Bowl { radius: big_r })],
            vec![marble(start, Vec3::ZERO, Vec3::ZERO, 0.5)],
        );
        scene.rolling = rolling;
        let traj = run(&scene, 240 * 8);
        let p = periods(&traj, dt);
        assert!(p.len() >= 3, "rolling={rolling}: {} periods", p.len());
        let mean = p.iter().sum::<f32>() / p.len() as f32;
        let factor = if rolling { 7.0 / 5.0 } else { 1.0 };
        let exact = 2.0 * std::f32::consts::PI * (factor * rho / G).sqrt();
        println!("rolling={rolling}: period {mean}, exact {exact}");
        assert!(
            ((mean - exact) / exact).abs() <= 0.01,
            "rolling={rolling}: period {mean}, exact {exact} ({p:?})"
        );
        // It stays on the bowl and its amplitude does not grow.
        for (i, (x, _, _)) in traj.iter().enumerate() {
            assert!(
                (x.length() - rho).abs() <= 2e-5,
                "step {i}: off the bowl at {x}"
            );
            assert!(
                x.x.abs() <= rho * theta0.sin() * 1.001,
                "step {i}: amplitude grew to {} from {}",
                x.x,
                rho * theta0.sin()
            );
        }
    }
}

/// Neverball's model (`tilt_as_gravity: true`): the board stays still and gravity tilts
/// back. For a slow tilt (0.03 rad/s to 0.1 rad) the marble ends within 3% of where the
/// true moving board rolls it (relative to the distance rolled); the board itself never
/// moves; results map back to the world.
#[test]
fn tilting_gravity_approximates_a_slowly_tilting_board() {
    let run = |cheap: bool| {
        let mut board = BoardDesc::new(ShapeDesc::Cuboid {
            half_extents: [10.0, 0.05, 10.0],
        });
        board.position = [0.0, -0.05, 0.0];
        board.angular_velocity = [0.0, 0.0, 0.03];
        let mut scene = rolling_scene(
            1.0 / 120.0,
            vec![board],
            vec![marble(Vec3::new(0.3, R, 0.0), Vec3::ZERO, Vec3::ZERO, 0.5)],
        );
        scene.tilt_as_gravity = cheap;
        let mut sim = Simulation::from_scene(&scene).unwrap();
        for _ in 0..400 {
            sim.step();
        }
        let b = sim.boards()[0];
        let board_turned = sim.world().get::<Rotation>(b).unwrap().0 != Quat::IDENTITY;
        (sim.marble_world_state(0).0, board_turned)
    };
    let (truth, turned) = run(false);
    let (cheap, still) = run(true);
    assert!(turned && !still);
    let rolled = (truth - Vec3::new(0.3, R, 0.0)).length();
    assert!(rolled > 0.5, "rolled {rolled}");
    assert!(
        (cheap - truth).length() <= 0.03 * rolled,
        "{cheap} against {truth}"
    );
}

/// `tilt_as_gravity` needs one shared turn: two boards turning differently are refused.
#[test]
fn tilting_gravity_refuses_two_different_turns() {
    let err = Scene::from_ron_str(
        "(tilt_as_gravity: true, boards: [(shape: Plane(()), angular_velocity: (0.0, 0.0, 0.1)), (shape: Plane(()), angular_velocity: (0.1, 0.0, 0.0))])",
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("boards[1].angular_velocity must be"),
        "{err}"
    );
}
