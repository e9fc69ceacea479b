//! Stability at the extremes (`docs/PHYSICS.md` §9): tiny and huge steps, speeds far beyond
//! `radius / dt`, restitution 0 and 1, radii and masses over many orders of magnitude,
//! scenes far from the origin, fast and jerky boards, marbles spawned inside boards, and
//! millions of steps. The longest runs are `#[ignore]`d here and run in release mode by
//! `.ci/run` (`cargo test --release --test extremes -- --ignored`).

mod common;

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use bevy_marble::study::{apexes, trajectory};
use glam::{Quat, Vec3};

const G: f32 = 9.81;
const R: f32 = 0.008;

fn drop(h: f32, r: f32, e: f32, dt: f32) -> Scene {
    drop_with(h, r, e, dt, Integrator::VelocityVerlet, true)
}

fn drop_with(h: f32, r: f32, e: f32, dt: f32, integrator: Integrator, ccd: bool) -> Scene {
    let mut s = scenes::drop_on_plane(h, r, e);
    s.dt = dt;
    s.integrator = integrator;
    s.ccd = ccd;
    s
}

/// A dropped marble (e = 0.5, from 0.2 m) at a given dt, every integrator, CCD on and
/// off: never NaN, never below the surface by more than the touching tolerance, at rest on
/// it by the end.
fn drop_comes_to_rest(dt: f32, seconds: f32) {
    for integrator in Integrator::ALL {
        for ccd in [true, false] {
            let scene = drop_with(0.2, R, 0.5, dt, integrator, ccd);
            let traj = trajectory(&scene, (seconds / dt) as usize);
            let what = format!("{integrator:?} ccd={ccd} dt={dt}");
            for (i, (x, v)) in traj.iter().enumerate() {
                assert!(x.is_finite() && v.is_finite(), "{what} step {i}: {x} {v}");
                assert!(x.y >= R - 2e-6, "{what} step {i}: sank to {}", x.y);
            }
            let (x, v) = *traj.last().unwrap();
            assert!(
                (x.y - R).abs() <= 2e-6 && v.length() <= 1e-5,
                "{what}: ended at {x} moving {v}"
            );
        }
    }
}

#[test]
fn coarse_steps_come_to_rest() {
    for dt in [0.1, 1.0 / 30.0, 1.0 / 60.0, 1e-3] {
        drop_comes_to_rest(dt, 3.0);
    }
}

#[test]
#[ignore = "millions of steps: run in release by .ci/run"]
fn tiny_steps_come_to_rest() {
    for dt in [1e-4, 1e-5, 1e-6] {
        drop_comes_to_rest(dt, 2.0);
    }
}

/// At dt = 1e-6 s a 0.1 s free fall (100,000 steps) from y = 1 m, and from y = 100 m,
/// falls `½ g t²` within 0.5%. Each step moves the marble at most 1e-6 m; near 100 m an
/// f32 resolves only 7.6e-6 m, so plain f32 accumulation would not move it at all
/// (`marble tradeoff` measures exactly that); compensated summation keeps every step.
#[test]
fn tiny_step_free_fall_is_accurate() {
    for (integrator, y0) in Integrator::ALL
        .into_iter()
        .map(|i| (i, 1.0f32))
        .chain([(Integrator::VelocityVerlet, 100.0)])
    {
        let dt = 1e-6;
        let n = 100_000;
        let scene = Scene {
            dt,
            integrator,
            marbles: vec![MarbleDesc::at([0.0, y0, 0.0])],
            ..Scene::default()
        };
        let (x, v) = *trajectory(&scene, n).last().unwrap();
        let t = n as f32 * dt;
        let fall = y0 - x.y;
        let exact = 0.5 * G * t * t;
        assert!(
            ((fall - exact) / exact).abs() <= 0.005,
            "{integrator:?}: fell {fall}, exact {exact}"
        );
        assert!(
            ((-v.y - G * t) / (G * t)).abs() <= 0.005,
            "{integrator:?}: v = {v}"
        );
    }
}

fn wall(speed: f32, spin: f32, dt: f32) -> Vec<(Vec3, Vec3)> {
    let mut wall = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.001, 0.5, 0.5],
    });
    wall.position = [1.0, 0.0, 0.0];
    wall.angular_velocity = [0.0, spin, 0.0];
    let mut m = MarbleDesc::at([0.0, 0.0, 0.0]);
    m.velocity = [speed, 0.0, 0.0];
    let scene = Scene {
        dt,
        gravity: [0.0; 3],
        boards: vec![wall],
        marbles: vec![m],
        ..Scene::default()
    };
    trajectory(&scene, 20)
}

/// 1,000 m/s against a 2 mm wall, still or spinning at 10 rad/s, at 60 Hz and 10 Hz: the
/// marble never gets past the wall.
#[test]
fn thousand_metres_per_second_does_not_tunnel() {
    for spin in [0.0, 10.0] {
        for dt in [1.0 / 60.0, 0.1] {
            for (i, (x, _)) in wall(1000.0, spin, dt).iter().enumerate() {
                assert!(x.x < 1.0, "spin {spin} dt {dt} step {i}: at {x}");
            }
        }
    }
}

/// e = 1 for 60 s at dt = 1/240 with Verlet and CCD: every apex at the drop height, within
/// twice the sampling bound `g dt²/8` (apexes are read at step times) and 1e-4 m of f32
/// drift over the 60 bounces; e = 0: no bounce at all.
#[test]
fn restitution_one_for_a_minute_and_zero() {
    let dt = 1.0 / 240.0;
    let a = apexes(&trajectory(&drop(1.0, R, 1.0, dt), 240 * 60), R);
    assert!(a.len() >= 60, "{} bounces", a.len());
    for (k, h) in a.iter().enumerate().take(a.len() - 1) {
        assert!(
            (h - 1.0).abs() <= 2.0 * G * dt * dt / 8.0 + 1e-4,
            "apex {k} at {h}"
        );
    }
    let traj = trajectory(&drop(1.0, R, 0.0, dt), 480);
    assert!(traj.iter().all(|(_, v)| v.y <= 0.0), "bounced with e = 0");
}

/// Radii from 0.1 mm to 10 m and masses from 1 mg to 1,000 t: the first apex of an
/// e = 0.8 drop is `e² h` (within the sampling bound plus 0.1%), and the marble comes to
/// rest on the surface.
#[test]
fn radii_and_masses_over_many_orders() {
    for (r, mass) in [
        (1e-4f32, 1e-6f32),
        (0.008, 1e-3),
        (1.0, 1.0),
        (10.0, 1e6),
        (1e-4, 1e3),
    ] {
        let dt = 1.0 / 240.0;
        let mut scene = drop(0.5, r, 0.8, dt);
        scene.marbles[0].mass = Some(mass);
        let traj = trajectory(&scene, 240 * 6);
        let first = apexes(&traj, r)[0];
        let exact = 0.5 * 0.64;
        assert!(
            (first - exact).abs() <= G * dt * dt / 8.0 + 1e-3 * exact,
            "r={r} m={mass}: first apex {first}"
        );
        let (x, v) = *traj.last().unwrap();
        assert!(
            (x.y - r).abs() <= 1e-4 * r + 1e-6 && v.length() <= 1e-4,
            "r={r} m={mass}: ended at {x} moving {v}"
        );
    }
}

/// 10 km from the origin (where an f32 resolves 1 mm) a bounce behaves as at the origin:
/// the first three apex heights of an e = 0.8 drop from 1 m within 1%.
#[test]
fn far_from_the_origin() {
    for offset in [Vec3::new(1e4, 0.0, 0.0), Vec3::new(-7e3, 7e3, 3e3)] {
        let mut scene = drop(1.0, R, 0.8, 1.0 / 240.0);
        scene.boards[0].position = offset.to_array();
        scene.marbles[0].position = (offset + Vec3::new(0.0, 1.0 + R, 0.0)).to_array();
        let traj: Vec<(Vec3, Vec3)> = trajectory(&scene, 240 * 4)
            .into_iter()
            .map(|(x, v)| (x - offset, v))
            .collect();
        let a = apexes(&traj, R);
        assert!(a.len() >= 3, "offset {offset}: {} bounces", a.len());
        for (k, h) in a.iter().enumerate().take(3) {
            let exact = 0.8f32.powi(2 * (k as i32 + 1));
            assert!(
                ((h - exact) / exact).abs() <= 0.01,
                "offset {offset}: apex {k} = {h}, exact {exact}"
            );
        }
    }
}

/// A board spinning at 10 rad/s about its normal under a resting marble (smooth: the
/// marble stays put), and one tilting at 10 rad/s into a marble: no NaN, no tunnelling,
/// and the resting marble neither moves nor sinks.
#[test]
fn boards_rotating_at_ten_radians_per_second() {
    let mut turntable = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [1.0, 0.05, 1.0],
    });
    turntable.position = [0.0, -0.05, 0.0];
    turntable.angular_velocity = [0.0, 10.0, 0.0];
    let scene = Scene {
        dt: 1.0 / 60.0,
        boards: vec![turntable],
        marbles: vec![MarbleDesc::at([0.3, R, 0.2])],
        ..Scene::default()
    };
    for (i, (x, v)) in trajectory(&scene, 600).iter().enumerate() {
        assert!(
            (*x - Vec3::new(0.3, R, 0.2)).length() <= 1e-5 && v.length() <= 1e-4,
            "turntable step {i}: {x} {v}"
        );
    }
    // A paddle 1 m long turning at 10 rad/s about Z sweeps through a hanging marble.
    let mut paddle = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.5, 0.002, 0.2],
    });
    paddle.position = [0.0, 0.0, 0.0];
    paddle.rotation = Quat::from_rotation_z(-0.5).to_array();
    paddle.angular_velocity = [0.0, 0.0, 10.0];
    let scene = Scene {
        dt: 1.0 / 60.0,
        gravity: [0.0; 3],
        boards: vec![paddle],
        marbles: vec![MarbleDesc::at([0.3, 0.05, 0.0])],
        ..Scene::default()
    };
    // Equation (1) at the paddle's first touch: its upper face (2 mm above its centre
    // plane) turning into the marble, whose velocity after is `(1 + e)(v_b(p)·n) n`.
    let (t_hit, want) = common::face_impact(
        Vec3::new(0.3, 0.05, 0.0),
        Vec3::ZERO,
        Vec3::ZERO,
        Vec3::ZERO,
        Vec3::ZERO,
        Vec3::new(0.0, 0.0, 10.0),
        Quat::from_rotation_z(-0.5) * Vec3::Y,
        0.002,
        R,
        0.5,
    );
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let m = sim.marbles()[0];
    let mut hit = None;
    let mut traj = vec![sim.marble_state(0)];
    for step in 0..30 {
        sim.step();
        traj.push(sim.marble_state(0));
        if let Some(c) = sim
            .contacts(m)
            .unwrap()
            .iter()
            .find(|c| c.kind == ContactKind::Collision)
        {
            hit.get_or_insert(step as f32 / 60.0 + c.time);
        }
    }
    let hit = hit.expect("the paddle hits the marble");
    assert!(
        (hit as f64 - t_hit).abs() <= 1e-5,
        "impact at {hit} s, exact {t_hit}"
    );
    let (_, v) = traj[30];
    assert!(
        (v - want).length() <= 1e-4 * want.length(),
        "v = {v}, equation (1) gives {want}"
    );
    for (i, (x, v)) in traj.iter().enumerate() {
        assert!(x.is_finite() && v.is_finite(), "step {i}");
        // Hit from below while the paddle turns upward: the marble stays on the upper side
        // of the paddle's plane at every step.
        let angle = -0.5 + 10.0 * i as f32 / 60.0;
        let n = Quat::from_rotation_z(angle) * Vec3::Y;
        if angle < 1.0 {
            assert!(x.dot(n) >= R - 1e-4 || x.length() > 0.55, "step {i}: {x}");
        }
    }
}

/// A board whose velocity reverses every step (±2 m/s along its normal) under a marble:
/// nothing explodes; the marble never sinks below the board and its energy stays within
/// what the board's motion can give.
#[test]
fn board_reversing_every_step() {
    let mut board = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [1.0, 0.05, 1.0],
    });
    board.position = [0.0, -0.05, 0.0];
    let scene = Scene {
        dt: 1.0 / 60.0,
        boards: vec![board],
        marbles: vec![MarbleDesc::at([0.0, R, 0.0])],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let b = sim.boards()[0];
    for step in 0..600 {
        let vy = if step % 2 == 0 { 2.0 } else { -2.0 };
        sim.world_mut().get_mut::<Velocity>(b).unwrap().0 = Vec3::new(0.0, vy, 0.0);
        sim.step();
        let (x, v) = sim.marble_state(0);
        let top = sim.world().get::<Position>(b).unwrap().y + 0.05;
        assert!(x.is_finite() && v.is_finite(), "step {step}");
        assert!(
            x.y >= top + R - 1e-5,
            "step {step}: marble {} under board top {top}",
            x.y
        );
        // Each impact can give at most (1 + e)·4 m/s relative; the marble stays bounded.
        assert!(v.length() <= 10.0, "step {step}: v = {v}");
    }
}

/// Marbles spawned inside a board (just in, half in, centre inside) are pushed out to its
/// surface without gaining speed.
#[test]
fn spawned_inside_is_pushed_out_without_speed() {
    for depth in [0.001f32, 0.004, 0.012] {
        let mut board = BoardDesc::new(ShapeDesc::Cuboid {
            half_extents: [1.0, 0.05, 1.0],
        });
        board.position = [0.0, -0.05, 0.0];
        let scene = Scene {
            dt: 1.0 / 60.0,
            boards: vec![board],
            marbles: vec![MarbleDesc::at([0.0, R - depth, 0.0])],
            ..Scene::default()
        };
        let traj = trajectory(&scene, 60);
        for (i, (x, v)) in traj.iter().enumerate().skip(1) {
            assert!(v.length() <= 1e-5, "depth {depth} step {i}: v = {v}");
            assert!(
                (x.y - R).abs() <= 1e-5,
                "depth {depth} step {i}: y = {}",
                x.y
            );
        }
    }
}

/// A million steps (69 min of simulated time at 1/240, about 6,500 bounces) of an e = 1
/// bounce from 0.5 m, for every integrator with CCD: the k-th sampled apex stays within
/// `g dt²/4 + k·ulp(0.5)` of the drop height (the sampling, up to `g dt²/8` low, and the
/// Euler schemes' velocity offset, up to `g dt²/8` high: `tests/bounce.rs`; and f32
/// rounding of the height, at most an ulp a bounce; measured at most 1.5e-4 m after
/// 6,500 bounces against a bar of 4.3e-4). A resting marble beside it does not drift by a
/// micrometre.
#[test]
#[ignore = "a million steps: run in release by .ci/run"]
fn a_million_steps() {
    let (dt, h) = (1.0 / 240.0, 0.5f32);
    let ulp = h.next_up() - h;
    let sampling = G * dt * dt / 8.0;
    for integrator in Integrator::ALL {
        let mut scene = drop_with(h, R, 1.0, dt, integrator, true);
        let mut resting = scene.marbles[0].clone();
        resting.position = [1.0, R, 0.0];
        scene.marbles.push(resting);
        let mut sim = Simulation::from_scene(&scene).unwrap();
        let (mut best, mut prev_vy, mut bounces) = (0.0f32, 0.0f32, 0u32);
        for step in 0..1_000_000 {
            sim.step();
            let (x, v) = sim.marble_state(0);
            if prev_vy > 0.0 && v.y <= 0.0 {
                bounces += 1;
                let bar = 2.0 * sampling + bounces as f32 * ulp;
                assert!(
                    (best - h).abs() <= bar,
                    "{integrator:?}: apex {bounces} at {best} (bar {bar} off {h})"
                );
                best = 0.0;
            }
            best = best.max(x.y - R);
            prev_vy = v.y;
            if step % 1000 == 0 {
                let (xr, vr) = sim.marble_state(1);
                assert!(
                    (xr - Vec3::new(1.0, R, 0.0)).length() <= 1e-6 && vr.length() <= 1e-6,
                    "{integrator:?} step {step}: resting marble at {xr} moving {vr}"
                );
            }
        }
        assert!(bounces > 6000, "{integrator:?}: {bounces} bounces");
    }
}
