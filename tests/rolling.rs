//! Marbles that roll (`rolling: true`): spin, Coulomb friction, rolling resistance, against
//! the exact answers of `docs/PHYSICS.md` §5 and §8.

mod common;

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use common::{G, turning_board_exact, turning_board_scene};
use glam::{Quat, Vec3};

const R: f32 = 0.008;

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

/// A rolling scene with `integrator` and continuous collision, one step per `dt`.
fn rolling_scene(
    dt: f32,
    integrator: Integrator,
    boards: Vec<BoardDesc>,
    marbles: Vec<MarbleDesc>,
) -> Scene {
    Scene {
        dt,
        integrator,
        ccd: true,
        rolling: true,
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

/// A marble released at rest on an incline of angle `theta` (μ = 0.5 on both, rolling
/// resistance `c` on both) for `seconds`, for every integrator at dt = 1/240 and 1/60:
/// it must roll without slipping (slip ≤ 1e-6 m/s in what every step reports) at
/// `a = (5/7) g (sin θ − c cos θ)`, each integrator's closed form `s = ½ a t² + λ a t`,
/// where `λ` is how far its path leads its reported velocity (`Integrator::velocity_lead`:
/// 0 for Verlet and RK4, ±dt/2 for the Euler schemes), to 1e-4 relative (f32 summation
/// over at most 480 steps).
fn assert_rolls_down(theta: f32, c: f32, seconds: f32) {
    let rot = Quat::from_rotation_z(theta);
    let n = rot * Vec3::Y;
    let down = rot * -Vec3::X;
    let a = 5.0 / 7.0 * G * (theta.sin() - c * theta.cos());
    for integrator in Integrator::ALL {
        for dt in [1.0f32 / 240.0, 1.0 / 60.0] {
            let mut board = plane(rot, 0.5);
            board.rolling_resistance = c;
            let start = n * R;
            let mut m = marble(start, Vec3::ZERO, Vec3::ZERO, 0.5);
            m.rolling_resistance = c;
            let steps = (seconds / dt).round() as usize;
            let traj = run(&rolling_scene(dt, integrator, vec![board], vec![m]), steps);
            let t = steps as f32 * dt;
            let s = (traj[steps].0 - start).dot(down);
            let want = 0.5 * a * t * t + integrator.velocity_lead(dt) * a * t;
            let err = ((s - want) / want).abs();
            println!("{integrator:?} dt={dt} c={c}: incline error {err:e}");
            assert!(
                err <= 1e-4,
                "{integrator:?} dt={dt} c={c}: s = {s}, want {want}, error {err}"
            );
            for (i, (_, v, w)) in traj.iter().enumerate() {
                assert!(
                    slip(*v, *w, n).length() <= 1e-6,
                    "{integrator:?} dt={dt} c={c} step {i}: slipping at {}",
                    slip(*v, *w, n).length()
                );
            }
        }
    }
}

/// Down a 20° incline from rest for 1 s without rolling resistance (μ = 0.5 ≥
/// (2/7) tan 20° = 0.10, so it rolls without slipping) at `a = (5/7) g sinθ`
/// ([`assert_rolls_down`]).
#[test]
fn rolls_down_an_incline() {
    assert_rolls_down(20f32.to_radians(), 0.0, 1.0);
}

/// Launched at v0 = 2 m/s without spin on a flat board with μ = 0.2 and e = 0: kinetic
/// friction slows it and spins it up; rolling begins at `2 v0 / (7 μ g)` (in the reported
/// velocities `λ` earlier, `Integrator::velocity_lead`; within one step) and from then on `v = (5/7) v0` and `ω r = v`, for every integrator at dt = 1/60
/// and 1/240, to 2e-5 m/s (1e-5 of v0: f32 rounding of the event time and of the
/// velocities).
#[test]
fn slip_turns_to_roll() {
    let (v0, mu) = (2.0f32, 0.2f32);
    for integrator in Integrator::ALL {
        for dt in [1.0 / 60.0, 1.0 / 240.0] {
            let mut board = plane(Quat::IDENTITY, mu);
            board.restitution = 0.0;
            let mut m = marble(Vec3::new(0.0, R, 0.0), Vec3::X * v0, Vec3::ZERO, mu);
            m.restitution = 0.0;
            let scene = rolling_scene(dt, integrator, vec![board], vec![m]);
            let traj = run(&scene, (1.0 / dt) as usize);
            let rolling_from = traj
                .iter()
                .position(|(_, v, w)| slip(*v, *w, Vec3::Y).length() <= 2e-5)
                .expect("starts rolling");
            let t_roll = rolling_from as f32 * dt;
            // The path leads the reported velocities by λ, so the reported state rolls
            // from the first step at or after `t_roll − λ`.
            let exact = 2.0 * v0 / (7.0 * mu * G) - integrator.velocity_lead(dt);
            assert!(
                t_roll >= exact - 1e-6 && t_roll <= exact + dt + 1e-6,
                "{integrator:?} dt={dt}: rolling from {t_roll}, exact {exact}"
            );
            let mut worst = 0.0f32;
            for (i, (x, v, w)) in traj.iter().enumerate().skip(rolling_from) {
                let what = format!("{integrator:?} dt={dt} step {i}");
                worst = worst.max((v.x - 5.0 / 7.0 * v0).abs());
                assert!((v.x - 5.0 / 7.0 * v0).abs() <= 2e-5, "{what}: v = {v}");
                assert!(
                    (w.z * R + v.x).abs() <= 2e-5,
                    "{what}: ω r = {} v = {}",
                    -w.z * R,
                    v.x
                );
                assert!((x.y - R).abs() <= 1e-6, "{what}: left the board");
            }
            println!("{integrator:?} dt={dt}: rolling speed error {worst:e}");
        }
    }
}

/// Rolling at 1 m/s on a level board with rolling resistance c = 0.02 (marble and board):
/// it decelerates at `(5/7) c g`, so `v = 1 − (5/7) c g t` at every step for every
/// integrator (each updates velocity by `a dt` exactly; 1e-5 m/s: f32 rounding over
/// 60 steps), keeps rolling (`ω r = v`), and stops after 7.3 s and stays stopped.
#[test]
fn rolling_resistance_decelerates_at_five_sevenths_c_g() {
    let c = 0.02f32;
    let dt = 1.0 / 120.0;
    let decel = 5.0 / 7.0 * c * G;
    for integrator in Integrator::ALL {
        let mut board = plane(Quat::IDENTITY, 0.5);
        board.rolling_resistance = c;
        let mut m = marble(
            Vec3::new(0.0, R, 0.0),
            Vec3::X,
            Vec3::new(0.0, 0.0, -1.0 / R),
            0.5,
        );
        m.rolling_resistance = c;
        let traj = run(&rolling_scene(dt, integrator, vec![board], vec![m]), 960);
        for (i, (_, v, w)) in traj.iter().enumerate().take(60) {
            let want = 1.0 - decel * i as f32 * dt;
            assert!(
                (v.x - want).abs() <= 1e-5,
                "{integrator:?} step {i}: v = {}, want {want}",
                v.x
            );
            assert!(
                slip(*v, *w, Vec3::Y).length() <= 1e-5,
                "{integrator:?} step {i}: slipping"
            );
        }
        let (_, v, w) = traj[960];
        assert!(
            v.length() <= 1e-6 && w.length() <= 1e-4,
            "{integrator:?}: v = {v}, ω = {w}"
        );
    }
}

/// On an incline of slope `tan θ = c / 2` with rolling resistance `c = 0.05` (marble and
/// board) a marble left at rest stays at rest: holding it needs a friction `g sin θ` up
/// the slope, whose torque `g sin θ · r` the resistance cancels up to `c g cos θ · r`
/// (it holds for `tan θ ≤ c`). For every integrator at dt = 1/240 and 1/60, over 2 s:
/// it moves less than 1e-6 m and never faster than 1e-6 m/s (f32 rounding of the
/// cancelled acceleration, a few ulps of g over at most 480 steps).
#[test]
fn rolling_resistance_holds_a_marble_on_a_shallow_incline() {
    let c = 0.05f32;
    let theta = (0.5 * c).atan();
    let rot = Quat::from_rotation_z(theta);
    let n = rot * Vec3::Y;
    for integrator in Integrator::ALL {
        for dt in [1.0f32 / 240.0, 1.0 / 60.0] {
            let mut board = plane(rot, 0.5);
            board.rolling_resistance = c;
            let start = n * R;
            let mut m = marble(start, Vec3::ZERO, Vec3::ZERO, 0.5);
            m.rolling_resistance = c;
            let steps = (2.0f32 / dt).round() as usize;
            let traj = run(&rolling_scene(dt, integrator, vec![board], vec![m]), steps);
            let moved = (traj[steps].0 - start).length();
            let fastest = traj.iter().map(|(_, v, _)| v.length()).fold(0.0, f32::max);
            println!("{integrator:?} dt={dt}: moved {moved:e} m, fastest {fastest:e} m/s");
            assert!(
                moved <= 1e-6 && fastest <= 1e-6,
                "{integrator:?} dt={dt}: moved {moved} m, fastest {fastest} m/s"
            );
        }
    }
}

/// Down an incline of slope `tan θ = 2c` with rolling resistance `c = 0.05`, from rest,
/// for 2 s: the resistance's torque `c N r` stands against the roll from the first
/// instant, so the marble rolls at `a = (5/7) g (sin θ − c cos θ)` ([`assert_rolls_down`]).
#[test]
fn rolls_down_an_incline_against_rolling_resistance() {
    let c = 0.05f32;
    assert_rolls_down((2.0 * c).atan(), c, 2.0);
}

/// An oblique impact with friction puts spin on the marble: hitting the floor at
/// (2, −3) m/s with e = 0.5 and μ = 0.5, the tangential impulse that stops the slip,
/// −(2/7)·2 m/s, is within Coulomb's μ·(1 + e)·3 m/s, so the marble leaves rolling:
/// `v_x = (5/7)·2`, `ω_z r = −v_x`, `v_y = e·3`, for every integrator (no gravity: their
/// paths are the same straight line), to 2e-6 m/s (f32 rounding of a few operations on
/// numbers near 2).
#[test]
fn oblique_impact_spins_the_marble() {
    for integrator in Integrator::ALL {
        let mut board = plane(Quat::IDENTITY, 0.5);
        board.restitution = 0.5;
        let mut m = marble(
            Vec3::new(0.0, 0.1, 0.0),
            Vec3::new(2.0, -3.0, 0.0),
            Vec3::ZERO,
            0.5,
        );
        m.restitution = 0.5;
        let mut scene = rolling_scene(1.0 / 240.0, integrator, vec![board], vec![m]);
        scene.gravity = [0.0; 3];
        let (_, v, w) = *run(&scene, 60).last().unwrap();
        assert!((v.x - 10.0 / 7.0).abs() <= 2e-6, "{integrator:?}: v = {v}");
        assert!((v.y - 1.5).abs() <= 2e-6, "{integrator:?}: v = {v}");
        assert!((w.z * R + v.x).abs() <= 2e-6, "{integrator:?}: ω = {w}");
    }
}

/// A marble resting on a board that moves sideways at 0.5 m/s is carried along: friction
/// spins it up until it rolls on the board; with rolling resistance (c = 0.05) the rolling
/// then dies out and the marble ends at the board's speed, rolling relative to nothing,
/// for every integrator. Energy in the board's frame never grows.
#[test]
fn a_moving_board_carries_the_marble() {
    for integrator in Integrator::ALL {
        let mut board = BoardDesc::new(ShapeDesc::Cuboid {
            half_extents: [100.0, 0.05, 1.0],
        });
        board.position = [0.0, -0.05, 0.0];
        board.velocity = [0.5, 0.0, 0.0];
        board.rolling_resistance = 0.05;
        let mut m = marble(Vec3::new(0.0, R, 0.0), Vec3::ZERO, Vec3::ZERO, 0.5);
        m.rolling_resistance = 0.05;
        let traj = run(
            &rolling_scene(1.0 / 60.0, integrator, vec![board], vec![m]),
            180,
        );
        let (_, v, w) = *traj.last().unwrap();
        assert!(
            (v - Vec3::new(0.5, 0.0, 0.0)).length() <= 1e-6,
            "{integrator:?}: v = {v}"
        );
        assert!(w.length() <= 1e-4, "{integrator:?}: ω = {w}");
        let energy = |v: Vec3, w: Vec3| {
            let u = v - Vec3::new(0.5, 0.0, 0.0);
            0.5 * u.length_squared() + 0.5 * 0.4 * R * R * w.length_squared()
        };
        for pair in traj.windows(2) {
            assert!(
                energy(pair[1].1, pair[1].2) <= energy(pair[0].1, pair[0].2) + 1e-7,
                "{integrator:?}: energy grew"
            );
        }
    }
}

/// Worst distance from the exact path and worst spin error (relative to the spin gained)
/// over 2 s of `common::turning_board_scene` at 0.2 rad/s about Z from 0.1 m, with a
/// contact every step and never a collision.
fn turning_board_errors(integrator: Integrator, rolling: bool, dt: f32) -> (f32, f32) {
    let (omega, q0) = (0.2f32, 0.1f32);
    let scene = turning_board_scene(integrator, rolling, Vec3::Z, omega, q0, dt);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let m = sim.marbles()[0];
    let steps = (2.0 / dt).round() as usize;
    let (mut path, mut spin) = (0.0f32, 0.0f32);
    for i in 1..=steps {
        sim.step();
        let (x, _, w) = turning_board_exact(rolling, Vec3::Z, omega, q0, i as f32 * dt);
        path = path.max((sim.marble_state(0).0 - x).length());
        if rolling {
            let got = sim.marble_spin(0).z;
            spin = spin.max((got - w).abs() / (w - omega).abs().max(1.0));
        }
        let contacts = sim.contacts(m).unwrap();
        assert!(
            !contacts.is_empty() && !contacts.has_collision(),
            "{integrator:?} rolling={rolling} dt={dt} step {i}: {contacts:?}"
        );
    }
    (path, spin)
}

/// The labyrinth case: a marble on a board that turns at 0.2 rad/s about Z (its +X side
/// going up), starting 0.1 m from the axis at rest relative to the board, for 2 s (1.76 m
/// rolled, 2.51 m smooth), against the closed form of `common::turning_board_exact`, for
/// every integrator, rolling and smooth, at dt = 1/240 and 1/960. Verlet and RK4 are
/// second order: within 0.1 mm of the exact path (f32 rounding of positions near 1 m over
/// up to 1,920 steps) and 0.1% of the exact spin. Semi-implicit Euler, the leapfrog scheme,
/// has Verlet's positions (within the same 0.1 mm: measured 0.013–0.019 mm) and reports a
/// spin `|λ| = dt/2` behind the path's, first order: shrinking at least 3.5× when dt does
/// 4× (first order gives 4×). Explicit Euler is first order in both: its path at most twice
/// `|λ|` times the 2.8 m/s gained (11.7 mm at 1/240), and both errors shrink at least 3.5×
/// (a scheme gaining energy ends metres off and does not converge).
#[test]
fn rolls_on_a_turning_board() {
    for integrator in Integrator::ALL {
        for rolling in [true, false] {
            let coarse = turning_board_errors(integrator, rolling, 1.0 / 240.0);
            let fine = turning_board_errors(integrator, rolling, 1.0 / 960.0);
            println!("{integrator:?} rolling={rolling}: {coarse:?} at 1/240, {fine:?} at 1/960");
            let what =
                format!("{integrator:?} rolling={rolling}: {coarse:?} at 1/240, {fine:?} at 1/960");
            let lead = integrator.velocity_lead(1.0 / 240.0).abs();
            match integrator {
                Integrator::ExplicitEuler => {
                    assert!(coarse.0 <= 2.0 * lead * 2.8, "{what}");
                    assert!(coarse.0 >= 3.5 * fine.0, "{what}");
                    assert!(coarse.1 >= 3.5 * fine.1, "{what}");
                }
                Integrator::SemiImplicitEuler => {
                    assert!(coarse.0 <= 1e-4 && fine.0 <= 1e-4, "{what}");
                    assert!(coarse.1 >= 3.5 * fine.1, "{what}");
                }
                _ => {
                    assert!(coarse.0 <= 1e-4 && fine.0 <= 1e-4, "{what}");
                    assert!(coarse.1 <= 1e-3 && fine.1 <= 1e-3, "{what}");
                }
            }
        }
    }
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
/// bottom, 8 s at 1/240 s, every integrator: the pendulum `θ'' = −κ (g / (R − r)) sin θ`
/// (κ = 5/7 rolling, 1 smooth) of period `2π √((R − r) / (κ g)) (1 + θ₀²/16)` to the
/// amplitude's second order (the θ₀⁴ term is 1e-7 here), within 1e-4 (measured 1e-5; the
/// explicit Euler scheme's swing has grown, lengthening its period by 6e-5). It stays on
/// the bowl, and its swing does not grow (0.1%) except with explicit Euler, which gains
/// energy by construction: at most as the textbook scheme, `exp(½ ω² h t)` (measured
/// `exp(¼ ω² h t)`, 1.17, the growth of a scheme that holds the start's force over a step
/// and reports the end's: semi-implicit Euler reports the start's, `src/response.rs`).
#[test]
fn bowl_oscillation_period() {
    let big_r = 0.5f32;
    let rho = big_r - R;
    let theta0 = 0.05f32;
    let start = Vec3::new(rho * theta0.sin(), -rho * theta0.cos(), 0.0);
    let (dt, seconds) = (1.0 / 240.0, 8.0);
    for integrator in Integrator::ALL {
        for rolling in [true, false] {
            let mut scene = rolling_scene(
                dt,
                integrator,
                vec![BoardDesc::new(ShapeDesc::Bowl { radius: big_r })],
                vec![marble(start, Vec3::ZERO, Vec3::ZERO, 0.5)],
            );
            scene.rolling = rolling;
            let what = format!("{integrator:?} rolling={rolling}");
            let traj = run(&scene, (seconds / dt) as usize);
            let p = periods(&traj, dt);
            assert!(p.len() >= 3, "{what}: {} periods", p.len());
            let mean = p.iter().sum::<f32>() / p.len() as f32;
            let kappa = if rolling { 5.0 / 7.0 } else { 1.0 };
            let omega_sq = kappa * G / rho;
            let exact =
                2.0 * std::f32::consts::PI / omega_sq.sqrt() * (1.0 + theta0 * theta0 / 16.0);
            println!("{what}: period {mean}, exact {exact}");
            assert!(
                ((mean - exact) / exact).abs() <= 1e-4,
                "{what}: period {mean}, exact {exact} ({p:?})"
            );
            let growth = if integrator == Integrator::ExplicitEuler {
                (0.5 * omega_sq * dt * seconds).exp()
            } else {
                1.001
            };
            for (i, (x, _, _)) in traj.iter().enumerate() {
                assert!(
                    (x.length() - rho).abs() <= 2e-5,
                    "{what} step {i}: off the bowl at {x}"
                );
                assert!(
                    x.x.abs() <= rho * theta0.sin() * growth,
                    "{what} step {i}: the swing grew to {} from {}",
                    x.x,
                    rho * theta0.sin()
                );
            }
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
            Integrator::VelocityVerlet,
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

/// `tilt_as_gravity` models every board in the turning board's frame: a board that does
/// not turn beside one that does (a world floor below a tilting labyrinth) is refused,
/// naming it, instead of turning with the frame.
#[test]
fn tilting_gravity_refuses_a_still_board_beside_a_turning_one() {
    let err = Scene::from_ron_str(
        "(tilt_as_gravity: true, boards: [(shape: Plane(()), angular_velocity: (0.0, 0.0, 0.1)), (shape: Plane(()), position: (0.0, -1.0, 0.0))])",
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("boards[1].angular_velocity must be"),
        "{err}"
    );
    // Without a turning board, still boards are all there is: accepted.
    Scene::from_ron_str(
        "(tilt_as_gravity: true, boards: [(shape: Plane(())), (shape: Plane(()), position: (0.0, -1.0, 0.0))])",
    )
    .unwrap();
}

/// With `tilt_as_gravity`, the CSV's spin is in the world frame like its position and
/// velocity: a marble at rest on the turning board turns with it, at the board's angular
/// velocity exactly; a marble whose spin is not modelled (rolling off) reports none.
#[test]
fn tilting_gravity_reports_the_spin_in_the_world() {
    for (rolling, want) in [(true, 0.1f32), (false, 0.0)] {
        let scene = Scene::from_ron_str(&format!(
            "(tilt_as_gravity: true, rolling: {rolling}, boards: [(shape: Cuboid(half_extents: (1.0, 0.05, 1.0)), angular_velocity: (0.1, 0.0, 0.0))], marbles: [(position: (0.0, 0.058, 0.5))])"
        ))
        .unwrap();
        let sim = Simulation::from_scene(&scene).unwrap();
        let mut csv = Vec::new();
        bevy_marble::output::write_csv_rows(&mut csv, &sim, 0, scene.dt).unwrap();
        let row = String::from_utf8(csv).unwrap();
        let w: Vec<f32> = row
            .trim()
            .split(',')
            .skip(9)
            .map(|c| c.parse().unwrap())
            .collect();
        assert_eq!(w, [want, 0.0, 0.0], "rolling {rolling}: {row}");
    }
}
