//! Equation (1) against boards that translate along and across their normal, tilted boards
//! and rotating boards: `v' = v_m − (1 + e)((v_m − v_b(p))·n)n` with `v_b(p) = v + ω × (p − c)`.

mod common;

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use common::{turning_board_exact, turning_board_scene};
use glam::{Quat, Vec3};

const R: f32 = 0.008;
const E: f32 = 0.6;

fn equation_1(vm: Vec3, vb: Vec3, n: Vec3, e: f32) -> Vec3 {
    vm - (1.0 + e) * (vm - vb).dot(n) * n
}

/// A weightless marble launched at `vm` towards a plane board with the given pose and
/// motion; returns the simulation after `steps` steps of 1/120 s and the first collision.
fn shoot(
    board_rotation: Quat,
    board_velocity: Vec3,
    board_spin: Vec3,
    start: Vec3,
    vm: Vec3,
    ccd: bool,
    steps: usize,
) -> (Simulation, Option<(Contact, f32)>) {
    let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    board.rotation = board_rotation.to_array();
    board.velocity = board_velocity.to_array();
    board.angular_velocity = board_spin.to_array();
    board.restitution = E;
    let mut m = MarbleDesc::at(start.to_array());
    m.velocity = vm.to_array();
    m.restitution = E;
    let dt = 1.0 / 120.0;
    let scene = Scene {
        dt,
        ccd,
        gravity: [0.0; 3],
        boards: vec![board],
        marbles: vec![m],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let marble = sim.marbles()[0];
    let mut first = None;
    for step in 0..steps {
        sim.step();
        if first.is_none()
            && let Some(c) = sim
                .contacts(marble)
                .unwrap()
                .iter()
                .find(|c| c.kind == ContactKind::Collision)
        {
            first = Some((*c, step as f32 * dt + c.time));
        }
    }
    (sim, first)
}

/// Boards translating along and across their normal, tilted and not, CCD on and off:
/// the velocity after the impact is equation (1) to f32 precision (1e-5 relative).
#[test]
fn translating_and_tilted_boards() {
    let vm = Vec3::new(0.5, -3.0, 0.2);
    let tilt = Quat::from_rotation_z(30f32.to_radians()) * Quat::from_rotation_x(0.2);
    let cases = [
        ("static", Quat::IDENTITY, Vec3::ZERO),
        ("along the normal", Quat::IDENTITY, Vec3::new(0.0, 2.0, 0.0)),
        (
            "across the normal",
            Quat::IDENTITY,
            Vec3::new(3.0, 0.0, -1.0),
        ),
        ("tilted", tilt, Vec3::ZERO),
        ("tilted, moving", tilt, Vec3::new(1.0, 0.5, 0.0)),
    ];
    for ccd in [true, false] {
        for (name, rotation, vb) in cases {
            let n = rotation * Vec3::Y;
            let start = n * (0.5 + R);
            let (sim, first) = shoot(rotation, vb, Vec3::ZERO, start, vm, ccd, 60);
            assert!(first.is_some(), "{name} ccd={ccd}: no collision");
            let want = equation_1(vm, vb, n, E);
            let (_, got) = sim.marble_state(0);
            assert!(
                (got - want).length() <= 1e-5 * want.length(),
                "{name} ccd={ccd}: {got} against {want}"
            );
        }
    }
}

/// The same impacts under gravity, for every integrator, with CCD: each moves on the exact
/// parabola of its path velocity `v + λ g` (`Integrator::velocity_lead`: λ = 0 for Verlet
/// and RK4, ±dt/2 for the Euler schemes), so the impact's time and the velocity after are
/// equation (1) where that parabola first touches the moving, turning plane
/// (`common::face_impact`, bisection in f64), and at the end of the step that holds it the
/// marble reports the path's velocity there less `λ g`. Boards still, rising, sliding
/// across their normal, tilted and moving, and turning at 1 rad/s about an axis 0.5 m
/// from the impact: the time within 1e-5 s and the velocity within 1e-5 relative (1e-4 on
/// the turning board, whose pose over a step is f32 quaternion arithmetic).
#[test]
fn impacts_under_gravity_for_every_integrator() {
    let g = Vec3::new(0.0, -common::G, 0.0);
    let tilt = Quat::from_rotation_z(30f32.to_radians()) * Quat::from_rotation_x(0.2);
    let vm = Vec3::new(0.5, -3.0, 0.2);
    let above = |q: Quat| q * Vec3::Y * (0.5 + R);
    let cases = [
        (
            "still",
            Quat::IDENTITY,
            Vec3::ZERO,
            Vec3::ZERO,
            above(Quat::IDENTITY),
            vm,
            1e-5,
        ),
        (
            "rising",
            Quat::IDENTITY,
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::ZERO,
            above(Quat::IDENTITY),
            vm,
            1e-5,
        ),
        (
            "sliding",
            Quat::IDENTITY,
            Vec3::new(3.0, 0.0, -1.0),
            Vec3::ZERO,
            above(Quat::IDENTITY),
            vm,
            1e-5,
        ),
        (
            "tilted, moving",
            tilt,
            Vec3::new(1.0, 0.5, 0.0),
            Vec3::ZERO,
            above(tilt),
            vm,
            1e-5,
        ),
        (
            "turning",
            Quat::IDENTITY,
            Vec3::ZERO,
            Vec3::Z,
            Vec3::new(0.5, 0.3, 0.0),
            Vec3::new(0.0, -2.0, 0.0),
            1e-4,
        ),
    ];
    let dt = 1.0 / 120.0;
    for integrator in Integrator::ALL {
        for (name, rotation, vb, spin, start, v0, tolerance) in cases {
            let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
            board.rotation = rotation.to_array();
            board.velocity = vb.to_array();
            board.angular_velocity = spin.to_array();
            board.restitution = E;
            let mut m = MarbleDesc::at(start.to_array());
            m.velocity = v0.to_array();
            m.restitution = E;
            let scene = Scene {
                dt,
                integrator,
                boards: vec![board],
                marbles: vec![m],
                ..Scene::default()
            };
            let lead = integrator.velocity_lead(dt);
            let (t_exact, after) = common::face_impact(
                start,
                v0 + lead * g,
                g,
                Vec3::ZERO,
                vb,
                spin,
                rotation * Vec3::Y,
                0.0,
                R,
                E,
            );
            let mut sim = Simulation::from_scene(&scene).unwrap();
            let what = format!("{integrator:?}, {name}");
            let (step, c) = common::first_collision(&mut sim, 60)
                .unwrap_or_else(|| panic!("{what}: no collision"));
            let t = step as f32 * dt + c.time;
            assert!(
                (f64::from(t) - t_exact).abs() <= 1e-5,
                "{what}: impact at {t}, exact {t_exact}"
            );
            let t_end = (step + 1) as f32 * dt;
            let want = after + g * (t_end - t_exact as f32) - lead * g;
            let got = sim.marble_state(0).1;
            assert!(
                (got - want).length() <= tolerance * want.length(),
                "{what}: {got} after the impact, exact {want}"
            );
        }
    }
}

/// With CCD, the impact on a translating board happens when the marble first touches the
/// moving surface: the recorded time matches the closed form `t = d / (v_b − v_m)·n`.
#[test]
fn impact_time_on_a_moving_board() {
    let vm = Vec3::new(0.0, -3.0, 0.0);
    let vb = Vec3::new(0.0, 2.0, 0.0);
    let (_, first) = shoot(
        Quat::IDENTITY,
        vb,
        Vec3::ZERO,
        Vec3::new(0.0, 0.5 + R, 0.0),
        vm,
        true,
        30,
    );
    let (c, t) = first.expect("collision");
    assert!((t - 0.5 / 5.0).abs() <= 1e-5, "impact at {t}");
    assert!(
        (c.point.y - 2.0 * t).abs() <= 1e-5,
        "contact point {}",
        c.point
    );
}

/// A rotating board (a plane turning about Z through the origin at 1 rad/s) hit 0.5 m
/// from the axis: at the recorded impact time the normal is the board's turned normal,
/// the contact point lies on the turned plane, and the velocity after is equation (1)
/// with the surface velocity `ω × (p − c)` at that point.
#[test]
fn rotating_board() {
    let spin = Vec3::new(0.0, 0.0, 1.0);
    let vm = Vec3::new(0.0, -2.0, 0.0);
    let start = Vec3::new(0.5, 0.3, 0.0);
    let (sim, first) = shoot(Quat::IDENTITY, Vec3::ZERO, spin, start, vm, true, 40);
    let (c, t) = first.expect("collision");
    let n = Quat::from_rotation_z(t) * Vec3::Y;
    assert!(
        (c.normal - n).length() <= 1e-5,
        "normal {} against {n}",
        c.normal
    );
    assert!(
        c.point.dot(n).abs() <= 1e-5,
        "point {} off the plane",
        c.point
    );
    let vb = spin.cross(c.point);
    let want = equation_1(vm, vb, n, E);
    let (_, got) = sim.marble_state(0);
    assert!(
        (got - want).length() <= 1e-4 * want.length(),
        "{got} against {want}"
    );
}

/// A marble resting on a board that rises at 1 m/s (and moving with it from the start: a
/// board that jumps to 1 m/s under a marble at rest is an impact) is carried up with it,
/// for every integrator: a contact, not a collision, every step; its height is the
/// board's plus r and its velocity the board's, to f32 rounding (1e-5 m near 2 m).
#[test]
fn rising_board_carries_a_resting_marble() {
    for integrator in Integrator::ALL {
        let mut board = BoardDesc::new(ShapeDesc::Cuboid {
            half_extents: [1.0, 0.1, 1.0],
        });
        board.velocity = [0.0, 1.0, 0.0];
        board.restitution = 0.9;
        let scene = Scene {
            dt: 1.0 / 60.0,
            integrator,
            boards: vec![board],
            marbles: vec![MarbleDesc {
                velocity: [0.0, 1.0, 0.0],
                ..MarbleDesc::at([0.0, 0.1 + R, 0.0])
            }],
            ..Scene::default()
        };
        let mut sim = Simulation::from_scene(&scene).unwrap();
        let marble = sim.marbles()[0];
        for step in 1..=120 {
            sim.step();
            let t = step as f32 / 60.0;
            let (x, v) = sim.marble_state(0);
            let what = format!("{integrator:?} step {step}");
            assert!((x.y - (0.1 + R + t)).abs() <= 1e-5, "{what}: y = {}", x.y);
            assert!((v - Vec3::Y).length() <= 1e-5, "{what}: v = {v}");
            assert!(!sim.contacts(marble).unwrap().has_collision());
        }
    }
}

/// A marble resting on a tilting labyrinth board (0.2 rad/s about X, the marble 0.3 m
/// from the axis, at rest relative to the board) slides off the rising side for 1 s at
/// dt = 1/60 along the closed form of `common::turning_board_exact` (smooth), for every
/// integrator, with a contact every step and never a collision: Verlet, RK4 and
/// semi-implicit Euler (the leapfrog scheme, Verlet's positions) within 0.2 mm (second
/// order at this step: measured 0.09 mm), the first-order explicit Euler within twice its
/// lead `dt/2` times the 1 m/s it gains (measured 8 mm). (At 1 m/s the held path's
/// drift over a substep is about the touching tolerance: `docs/PHYSICS.md` §9.)
#[test]
fn tilting_board_keeps_a_resting_marble_in_contact() {
    let (omega, q0, dt) = (0.2f32, 0.3f32, 1.0 / 60.0);
    for integrator in Integrator::ALL {
        let scene = turning_board_scene(integrator, false, Vec3::X, omega, q0, dt);
        let mut sim = Simulation::from_scene(&scene).unwrap();
        let marble = sim.marbles()[0];
        let lead = integrator.velocity_lead(dt).abs();
        let bar = if integrator == Integrator::ExplicitEuler {
            2.0 * lead * 1.0
        } else {
            2e-4
        };
        let mut worst = 0.0f32;
        for step in 1..=60 {
            sim.step();
            let (x, _, _) = turning_board_exact(false, Vec3::X, omega, q0, step as f32 * dt);
            worst = worst.max((sim.marble_state(0).0 - x).length());
            let contacts = sim.contacts(marble).unwrap();
            assert!(
                !contacts.is_empty() && !contacts.has_collision(),
                "{integrator:?} step {step}: {contacts:?}"
            );
        }
        println!("{integrator:?}: {worst:e} m off the exact path");
        assert!(worst <= bar, "{integrator:?}: {worst} m off the exact path");
    }
}

/// A marble sliding or rolling on a board that turns (0.1 rad/s about Z, the marble
/// starting 0.3 m from the axis at rest relative to it) stays on it for 3 s at dt = 1/60,
/// for every integrator: a contact every step, never a collision (staying on a turning
/// surface takes its Coriolis term `2 (v − v_b)·(ω × n)`; with half of it the marble
/// drifted off by micrometres each step and hopped back as an impact). And it follows the
/// closed form of `common::turning_board_exact` to 4.5 m/s and 3.2 m/s (rolling, up to
/// 400 rad/s of spin). Verlet and RK4 within 0.3 mm at every step and 5e-5 m/s at the end
/// (second order: measured 0.14 mm and 1.4e-5 m/s). Semi-implicit Euler is the leapfrog
/// scheme, Verlet's positions: within the same 0.3 mm (measured 0.14 mm), its reported
/// velocity `|λ| = dt/2` behind the path, within 1.5 `|λ|` times the acceleration (measured
/// 1.0). Explicit Euler is first order: within twice `|λ|` times the speed, and at the end
/// three times `|λ|` times the acceleration (the path `λ` behind the closed form and the
/// reported velocity `λ` ahead of the path: measured 0.8–3.6 cm and 0.004–0.007 m/s,
/// against bars of 5.3–7.4 cm and 0.07 m/s). Rolling at 2.5 m/s, the held path's slip drift (1e-5 m/s) passes
/// the rolling threshold: taken for a slip, it gives a kick of `½ h μ N` every other step,
/// 1 mm and 0.03 m/s off by the end (`Hold::rolled` in `src/response.rs`).
#[test]
fn riding_a_turning_board_never_hops() {
    let (omega, q0, dt) = (0.1f32, -0.3f32, 1.0 / 60.0);
    for rolling in [false, true] {
        for integrator in Integrator::ALL {
            let scene = turning_board_scene(integrator, rolling, Vec3::Z, omega, q0, dt);
            let mut sim = Simulation::from_scene(&scene).unwrap();
            let marble = sim.marbles()[0];
            let lead = integrator.velocity_lead(dt).abs();
            let explicit = integrator == Integrator::ExplicitEuler;
            let what = format!("{integrator:?} rolling={rolling}");
            let mut worst = 0.0f32;
            for step in 1..=180 {
                sim.step();
                let contacts = sim.contacts(marble).unwrap();
                assert!(
                    !contacts.is_empty() && !contacts.has_collision(),
                    "{what} step {step}: {contacts:?}"
                );
                let t = step as f32 * dt;
                let (x, v, _) = turning_board_exact(rolling, Vec3::Z, omega, q0, t);
                let off = (sim.marble_state(0).0 - x).length();
                let bar = if explicit {
                    2.0 * lead * v.length()
                } else {
                    3e-4
                };
                worst = worst.max(off / bar);
                assert!(off <= bar, "{what} step {step}: {off} m off the exact path");
            }
            let (_, v) = sim.marble_state(0);
            let (_, want, _) = turning_board_exact(rolling, Vec3::Z, omega, q0, 3.0);
            let (_, before, _) = turning_board_exact(rolling, Vec3::Z, omega, q0, 3.0 - 0.01);
            let accel = (want - before).length() / 0.01;
            let bar = match integrator {
                Integrator::ExplicitEuler => 3.0 * lead * accel,
                Integrator::SemiImplicitEuler => 1.5 * lead * accel,
                _ => 5e-5,
            };
            let off = (v - want).length();
            println!(
                "{what}: at worst {worst:.2} of the bar off the path, {off:e} m/s off at the end"
            );
            assert!(off <= bar, "{what}: {v} at the end, exact {want}");
        }
    }
}

/// A marble on a slab 2 cm thick (thinner than its 16 mm diameter plus the slab's half),
/// pressed into it far harder than gravity (as the marbles of a pile press the lowest
/// ones into a floor), while its velocity leaves the surface slowly, never goes under the
/// slab's top face, for every integrator, and stays on it at rest (`y = r` to the
/// touching tolerance), every step for 12 steps. Three cases: 0.5 mm into the face (where a pile's
/// overlap projection leaves it) moving off it at 0.2 mm/s under 300 m/s² at 1/120 s (a
/// hop that could never rise past the touching tolerance: the touch holds); on the face
/// moving off it at 6 cm/s under 400 m/s² at 1/120 s (it leaves, and is back within
/// 0.3 ms); and 0.9 mm into the face moving off it at 7.6 cm/s, faster than the
/// restitution threshold, under 255.6 m/s² at 1/60 s (its path `gap + u τ − ½ |a| τ²`
/// never gets out of the slab, `u² < 2 |a| depth`, so the face holds it at once, however
/// fast it starts). Judged to have left the face without being watched on the way back,
/// the marble ended the step past the slab's middle and was pushed out of its underside
/// (the second case), or went through the slab within the step (the third: 7 cm down in
/// one step, as a marble at the bottom of bench scene (b) did at one substep).
#[test]
fn a_marble_pressed_into_a_thin_slab_stays_on_top() {
    for (gap, up, pull, dt) in [
        (-5e-4f32, 2e-4f32, 300.0f32, 1.0 / 120.0),
        (0.0, 0.06, 400.0, 1.0 / 120.0),
        (-9e-4, 0.076, 255.6, 1.0 / 60.0),
    ] {
        for integrator in Integrator::ALL {
            let mut board = BoardDesc::new(ShapeDesc::Cuboid {
                half_extents: [0.5, 0.01, 0.5],
            });
            board.position = [0.0, -0.01, 0.0];
            let scene = Scene {
                dt,
                integrator,
                gravity: [0.0, -pull, 0.0],
                boards: vec![board],
                marbles: vec![MarbleDesc {
                    velocity: [0.0, up, 0.0],
                    ..MarbleDesc::at([0.0, R + gap, 0.0])
                }],
                ..Scene::default()
            };
            let mut sim = Simulation::from_scene(&scene).unwrap();
            for step in 1..=12 {
                sim.step();
                let (x, v) = sim.marble_state(0);
                let what = format!("{integrator:?}, {up} m/s under {pull} m/s², step {step}");
                assert!(x.y >= R - 1e-6, "{what}: under the top face, y = {}", x.y);
                // Explicit Euler's path runs on the step's start velocity (it lifts off
                // by 0.5 mm and comes back at 3.3 m/s): only the first claim for it.
                if integrator != Integrator::ExplicitEuler || up < 0.01 {
                    assert!((x.y - R).abs() <= 1e-6, "{what}: y = {}", x.y);
                    assert!(v.length() <= 1e-6, "{what}: v = {v}");
                }
            }
        }
    }
}

/// A board moving at a constant velocity follows its path to f32's resolution: after 2 s at
/// 1/437 s (874 substeps) it is within two ulps of `start + v t` in every coordinate
/// (compensated summation, as for marbles: half an ulp measured); added plainly, the
/// substeps' rounding drifts it by about 50 ulps (1e-5 m), which a marble in free flight
/// above it sees as energy gained in the board's frame (`contacts_never_add_energy` in
/// `tests/properties.rs` found it, 1.06e-5 of the energy over 350 steps).
#[test]
fn a_moving_board_follows_its_path() {
    for compensated in [true, false] {
        let velocity = [0.639_311_2, -0.952_972_5, 0.0];
        let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
        board.velocity = velocity;
        let scene = Scene {
            dt: 1.0 / 436.697_6,
            boards: vec![board],
            ..Scene::default()
        };
        let mut sim = Simulation::from_scene(&scene).unwrap();
        sim.world_mut().resource_mut::<StepConfig>().compensated = compensated;
        let steps = 874;
        for _ in 0..steps {
            sim.step();
        }
        let at = sim.world().get::<Position>(sim.boards()[0]).unwrap().0;
        let t = steps as f64 * scene.dt as f64;
        let worst = (0..3)
            .map(|i| {
                let exact = velocity[i] as f64 * t;
                let ulp = (exact.abs() as f32).max(f32::MIN_POSITIVE) * f32::EPSILON;
                (at[i] as f64 - exact).abs() / ulp as f64
            })
            .fold(0.0, f64::max);
        if compensated {
            assert!(worst <= 2.0, "{worst} ulps off its path");
        } else {
            assert!(worst > 20.0, "plain addition drifts: {worst} ulps");
        }
    }
}

/// A board driven by `NextPose` at every step (a game's tilt) gains and loses the component
/// each step, which moves it between tables; the board list keeps its order all the same,
/// so its epoch stands (the marbles' near-piece lists and recorded contacts name pieces
/// by their board's place in it: a new epoch rebuilds the lists and drops the contact
/// solver's warm start).
#[test]
fn a_driven_board_keeps_its_place_in_the_board_list() {
    let mut wall = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.01, 0.05, 0.2],
    });
    wall.position = [0.3, 0.05, 0.0];
    let scene = Scene {
        dt: 1.0 / 60.0,
        marble_collisions: true,
        boards: vec![BoardDesc::new(ShapeDesc::Plane(PlaneDesc {})), wall],
        marbles: vec![
            MarbleDesc::at([0.0, R, 0.0]),
            MarbleDesc::at([2.0 * R, R, 0.0]),
        ],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    sim.step();
    let epoch = |sim: &Simulation| {
        sim.world()
            .resource::<bevy_marble::board_contact::BoardCache>()
            .epoch
    };
    let before = epoch(&sim);
    let floor = sim.boards()[0];
    for k in 0..10 {
        let rotation = Quat::from_rotation_x(0.001 * k as f32);
        sim.world_mut().entity_mut(floor).insert(NextPose {
            position: Vec3::ZERO,
            rotation,
        });
        sim.step();
        assert_eq!(epoch(&sim), before, "step {k}");
    }
}
