//! Sleeping (`sleep_speed`, `sleep_time`; `bevy_marble::sleep`): when marbles fall asleep,
//! that a sleeping marble stays exactly where it is, and every way of waking one, each
//! against the exact answer of the same motion awake.

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use bevy_marble::scenes;
use glam::{Quat, Vec3};

const R: f32 = 0.008;
/// A step that is exact in binary, so that `sleep_time` is a whole number of steps.
const DT: f32 = 1.0 / 64.0;

fn asleep(sim: &Simulation, i: usize) -> bool {
    sim.is_asleep(i)
}

/// One marble resting on a level floor (a box whose top face is at y = 0), sleeping on.
fn resting_on_floor() -> Scene {
    let floor = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.5, 0.05, 0.5],
    });
    let mut floor = floor;
    floor.position = [0.0, -0.05, 0.0];
    Scene {
        dt: DT,
        sleep_speed: 0.01,
        sleep_time: 0.5,
        boards: vec![floor],
        marbles: vec![MarbleDesc::at([0.0, R, 0.0])],
        ..Scene::default()
    }
}

/// A marble at rest on a floor is slow from the first step, so it falls asleep at the end
/// of step `sleep_time / dt` = 32 and not before; asleep, its position and velocity stay
/// bit for bit what they were for 200 more steps.
#[test]
fn a_resting_marble_sleeps_after_sleep_time_and_stays_put() {
    let mut sim = Simulation::from_scene(&resting_on_floor()).unwrap();
    for step in 1..=31 {
        sim.step();
        assert!(!asleep(&sim, 0), "asleep after step {step}");
    }
    sim.step();
    assert!(asleep(&sim, 0), "awake after step 32");
    let (x, v) = sim.marble_state(0);
    assert_eq!(v, Vec3::ZERO);
    for _ in 0..200 {
        sim.step();
    }
    let (x2, v2) = sim.marble_state(0);
    assert_eq!((x2.to_array(), v2), (x.to_array(), Vec3::ZERO));
    assert!(asleep(&sim, 0));
}

/// The substep a step ended on (`Substep::index`).
fn last_substep(sim: &Simulation) -> u32 {
    sim.world().resource::<bevy_marble::config::Substep>().index
}

/// A still world (every marble asleep, no board moving) runs one substep per step instead
/// of `substeps`, and stays bit for bit where it is; a velocity given to the sleeping
/// marble wakes it, and that step runs every substep and moves it exactly `v t` (the floor
/// is smooth and level, so it slides at constant velocity). A board that moves, however
/// far from the marble, keeps every substep running.
#[test]
fn a_still_world_runs_one_substep_per_step() {
    let mut scene = resting_on_floor();
    scene.substeps = 4;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..32 {
        sim.step();
        assert_eq!(last_substep(&sim), 3, "awake steps run every substep");
    }
    assert!(asleep(&sim, 0));
    let (x, _) = sim.marble_state(0);
    for _ in 0..10 {
        sim.step();
        assert_eq!(last_substep(&sim), 0, "a still world runs one substep");
    }
    assert_eq!(sim.marble_state(0), (x, Vec3::ZERO));
    let marble = sim.marbles()[0];
    let v = Vec3::new(0.1, 0.0, 0.0);
    sim.world_mut().get_mut::<Velocity>(marble).unwrap().0 = v;
    sim.step();
    assert!(!asleep(&sim, 0));
    assert_eq!(last_substep(&sim), 3, "a woken marble steps every substep");
    let (x1, v1) = sim.marble_state(0);
    assert!(
        (x1 - (x + v * DT)).length() < 1e-6,
        "{x1} vs {}",
        x + v * DT
    );
    assert!((v1 - v).length() < 1e-6, "{v1}");

    // A board sliding far away: the marble sleeps, but the board moves every substep.
    let mut far = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.05, 0.05, 0.05],
    });
    far.position = [10.0, 0.0, 0.0];
    far.velocity = [0.0, 0.0, 0.1];
    scene.boards.push(far);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    assert_eq!(last_substep(&sim), 3);
    let board = sim.boards()[1];
    let z = sim.world().get::<Position>(board).unwrap().0.z;
    assert!((z - 40.0 * DT * 0.1).abs() < 1e-5, "board at z = {z}");
}

/// Sleeping off (the default), nothing sleeps; and a marble sliding down a smooth 5°
/// slope is never slow, so it never sleeps, and slides as the exact answer says:
/// `s = ½ g sin θ t²` after 1 s (within 0.5%).
#[test]
fn moving_marbles_and_scenes_without_sleep_never_sleep() {
    let mut off = resting_on_floor();
    off.sleep_speed = 0.0;
    let mut sim = Simulation::from_scene(&off).unwrap();
    for _ in 0..100 {
        sim.step();
    }
    assert!(!asleep(&sim, 0));

    let theta = 5f32.to_radians();
    let rot = Quat::from_rotation_z(theta);
    let mut plane = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    plane.rotation = rot.to_array();
    let start = rot * Vec3::new(0.0, R, 0.0);
    let scene = Scene {
        dt: DT,
        integrator: Integrator::VelocityVerlet,
        sleep_speed: 0.01,
        sleep_time: 0.5,
        boards: vec![plane],
        marbles: vec![MarbleDesc::at(start.to_array())],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..64 {
        sim.step();
        assert!(!asleep(&sim, 0));
    }
    let s = (sim.marble_state(0).0 - start).length();
    let want = 0.5 * 9.81 * theta.sin();
    assert!((s - want).abs() < 5e-3 * want, "slid {s} m, want {want}");
}

/// A scene without gravity or boards, marble collisions and sleeping on.
fn space() -> Scene {
    Scene {
        gravity: [0.0; 3],
        dt: DT,
        marble_collisions: true,
        sleep_speed: 0.01,
        sleep_time: 0.5,
        ..Scene::default()
    }
}

/// A marble shot at a sleeping one, head-on, equal masses, e = 0.5: the sleeping marble
/// falls asleep at step 32 (the shot is far away then), is woken before the shot reaches
/// it, and the impact gives the two-body answer of `docs/PHYSICS.md` §6, `v₁' = (1 − e) u / 2`,
/// `v₂' = (1 + e) u / 2`, within 0.5%.
#[test]
fn a_sleeping_marble_is_woken_before_a_marble_hits_it() {
    let mut scene = space();
    let u = 1.0;
    let mut shot = MarbleDesc::at([0.0, 0.0, 0.0]);
    shot.velocity = [u, 0.0, 0.0];
    shot.restitution = 0.5;
    let mut target = MarbleDesc::at([1.0, 0.0, 0.0]);
    target.restitution = 0.5;
    scene.marbles = vec![shot, target];
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 1) && !asleep(&sim, 0));
    for _ in 0..40 {
        sim.step();
    }
    let (v1, v2) = (sim.marble_state(0).1.x, sim.marble_state(1).1.x);
    let (want1, want2) = (0.25 * u, 0.75 * u);
    assert!(
        (v1 - want1).abs() < 5e-3 * u && (v2 - want2).abs() < 5e-3 * u,
        "after the impact {v1}, {v2}; want {want1}, {want2}"
    );
}

/// A program that gives a sleeping marble a velocity or a force, or moves it, wakes it,
/// and it then moves exactly as an awake marble would: at the velocity, `x = x₀ + v t`;
/// under the force (Verlet, no gravity), `x = x₀ + ½ (F/m) t²` over the step. Sleeping
/// turned off wakes every sleeping marble.
#[test]
fn a_program_that_changes_a_sleeping_marble_wakes_it() {
    let mut scene = space();
    scene.integrator = Integrator::VelocityVerlet;
    scene.marbles = vec![MarbleDesc::at([0.0, 0.0, 0.0])];
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let m = sim.marbles()[0];

    // A velocity.
    let v = Vec3::new(0.3, -0.1, 0.2);
    sim.world_mut().get_mut::<Velocity>(m).unwrap().0 = v;
    for _ in 0..10 {
        sim.step();
    }
    assert!(!asleep(&sim, 0));
    let want = v * (10.0 * DT);
    let got = sim.marble_state(0).0;
    assert!((got - want).length() < 1e-6, "{got} against {want}");

    // Stopped, it sleeps again; then a force for one step.
    sim.world_mut().get_mut::<Velocity>(m).unwrap().0 = Vec3::ZERO;
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let x0 = sim.marble_state(0).0;
    let mass = 1.0 / sim.world().get::<Mass>(m).unwrap().inverse();
    let f = Vec3::new(0.0, 0.0, 1e-3);
    sim.world_mut().get_mut::<Force>(m).unwrap().0 = f;
    sim.step();
    assert!(!asleep(&sim, 0));
    let moved = sim.marble_state(0).0 - x0;
    let want = f / mass * (0.5 * DT * DT);
    assert!(
        (moved - want).length() < 1e-3 * want.length(),
        "{moved} against {want}"
    );

    // Moved by hand, it wakes where it was put.
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    sim.world_mut().get_mut::<Velocity>(m).unwrap().0 = Vec3::ZERO;
    sim.world_mut().get_mut::<Position>(m).unwrap().0 = Vec3::new(0.5, 0.0, 0.0);
    sim.step();
    assert!(!asleep(&sim, 0));
    // (Within the rounding that compensated summation still carries from the earlier
    // motion.)
    let got = sim.marble_state(0).0;
    assert!((got - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6, "{got}");

    // Sleeping turned off.
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    sim.world_mut().resource_mut::<StepConfig>().sleep = None;
    for _ in 0..40 {
        sim.step();
        assert!(!asleep(&sim, 0));
    }
}

/// A cue marble asleep 10 cm from a sleeping target, given 5 m/s towards it by the
/// program: the target wakes before the cue reaches it (the cue's reach counts the speed
/// it was given), and the impact gives the two-body answer (equal masses, e = 0.5:
/// `1.25` and `3.75` m/s) within 0.5%.
#[test]
fn a_marble_woken_with_a_velocity_wakes_what_it_will_reach() {
    let mut scene = space();
    let mut cue = MarbleDesc::at([0.0, 0.0, 0.0]);
    cue.restitution = 0.5;
    let mut target = MarbleDesc::at([0.1, 0.0, 0.0]);
    target.restitution = 0.5;
    scene.marbles = vec![cue, target];
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0) && asleep(&sim, 1));
    let m = sim.marbles()[0];
    sim.world_mut().get_mut::<Velocity>(m).unwrap().0 = Vec3::new(5.0, 0.0, 0.0);
    for _ in 0..4 {
        sim.step();
    }
    let (v1, v2) = (sim.marble_state(0).1.x, sim.marble_state(1).1.x);
    assert!(
        (v1 - 1.25).abs() < 0.025 && (v2 - 3.75).abs() < 0.025,
        "after the impact {v1}, {v2}; want 1.25, 3.75"
    );
}

/// A knock carries a marble farther than its own speed would: a heavy marble (1,000
/// times the mass) at 1 m/s hits a light one resting 2 r from a sleeping third, which
/// the light one, leaving at about 2 m/s (`(1 + e)` times, e = 1), reaches within the
/// step. The sleeping marble is woken in time (its reach counts the fastest knock of the
/// step): the light marbles never overlap by more than 5% of r, and the third leaves at
/// the light one's speed after the first impact, `2M/(M + m)` = 2000/1001 m/s (the light
/// one, hit again by the heavy one, never catches it up), to 1e-3 m/s.
#[test]
fn a_marble_knocked_by_a_collision_does_not_pass_through_a_sleeping_one() {
    let mut scene = space();
    let ball = |x: f32, mass: f32| {
        let mut m = MarbleDesc::at([x, 0.0, 0.0]);
        m.restitution = 1.0;
        m.mass = Some(mass);
        m
    };
    let light = 5e-3;
    // The third marble first, alone, so that it falls asleep.
    scene.marbles = vec![ball(0.0, light)];
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let spawn = |sim: &mut Simulation, x: f32, v: f32, mass: f32| {
        sim.world_mut()
            .spawn((
                Marble,
                Position(Vec3::new(x, 0.0, 0.0)),
                Velocity(Vec3::new(v, 0.0, 0.0)),
                Mass::new(mass),
                Restitution(1.0),
            ))
            .id()
    };
    // The light marble 2 r short of the sleeping one (centres 4 r apart), the heavy one
    // just short of the light one, closing at 1 m/s.
    let second = spawn(&mut sim, -4.0 * R, 0.0, light);
    spawn(&mut sim, -6.0 * R - 1e-3, 1.0, 1000.0 * light);
    for step in 0..6 {
        sim.step();
        let a = sim.world().get::<Position>(second).unwrap().0;
        let b = sim.marble_state(0).0;
        let overlap = (2.0 * R - (b - a).length()) / R;
        assert!(overlap < 0.05, "step {step}: overlap {overlap} r");
    }
    assert!(!asleep(&sim, 0));
    let v = sim.marble_state(0).1.x;
    assert!(
        (v - 2000.0 / 1001.0).abs() <= 1e-3,
        "the third marble left at {v} m/s, want 2000/1001"
    );
}

/// A marble under a weak, steady program force (0.004 m/s², below what `sleep_speed` /
/// `sleep_time` would notice) never sleeps and moves as the exact answer says: `½ a t²`
/// after 2 s (Verlet), within 0.5%.
#[test]
fn a_marble_under_a_steady_force_never_sleeps() {
    let mut scene = resting_on_floor();
    scene.integrator = Integrator::VelocityVerlet;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let m = sim.marbles()[0];
    let mass = 1.0 / sim.world().get::<Mass>(m).unwrap().inverse();
    let a = 0.004;
    let x0 = sim.marble_state(0).0;
    for _ in 0..128 {
        sim.world_mut().get_mut::<Force>(m).unwrap().0 = Vec3::new(mass * a, 0.0, 0.0);
        sim.step();
        assert!(!asleep(&sim, 0));
    }
    let moved = sim.marble_state(0).0.x - x0.x;
    let want = 0.5 * a * 2.0 * 2.0;
    assert!(
        (moved - want).abs() < 5e-3 * want,
        "moved {moved} m, want {want}"
    );
}

/// A marble resting on a still floor 5 mm from a paddle (a second board) that slides away
/// at 1 mm/s: within a radius of the paddle's bounds, the paddle would wake it every
/// step, so it never falls asleep (no sleeping and waking over and over); once the paddle
/// is more than a radius away (after 3 s), it sleeps.
#[test]
fn a_marble_beside_a_moving_board_stays_awake() {
    let mut scene = resting_on_floor();
    let mut paddle = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.005, 0.02, 0.05],
    });
    paddle.position = [R + 0.005 + 0.005, 0.02, 0.0];
    paddle.velocity = [0.001, 0.0, 0.0];
    scene.boards.push(paddle);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    // Within a radius of the paddle's bounds for the first 3 s: 150 steps (2.3 s).
    for step in 0..150 {
        sim.step();
        assert!(!asleep(&sim, 0), "asleep after step {step}");
    }
    for _ in 0..150 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
}

/// A board that starts to move, or is moved, wakes the marbles on it, and gravity that
/// changes wakes every marble: a floor rising at 0.2 m/s lifts its marble with it (after
/// 0.5 s, 0.1 m higher, resting on the floor within 1% of the rise); a floor moved 1 m
/// down lets its marble fall freely (`½ g t²` after 0.25 s, within 1%); gravity turned
/// upwards lifts a marble off its floor the same way.
#[test]
fn boards_that_move_and_gravity_that_changes_wake_marbles() {
    let g = 9.81;
    // A rising floor.
    let mut sim = Simulation::from_scene(&resting_on_floor()).unwrap();
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let floor = sim.boards()[0];
    let y0 = sim.marble_state(0).0.y;
    sim.world_mut().get_mut::<Velocity>(floor).unwrap().0 = Vec3::new(0.0, 0.2, 0.0);
    for _ in 0..32 {
        sim.step();
        assert!(!asleep(&sim, 0));
    }
    let rise = sim.marble_state(0).0.y - y0;
    assert!((rise - 0.1).abs() < 1e-3, "rose {rise} m");

    // A floor moved away.
    let mut sim = Simulation::from_scene(&resting_on_floor()).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().integrator = Integrator::VelocityVerlet;
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let floor = sim.boards()[0];
    sim.world_mut().get_mut::<Position>(floor).unwrap().0.y -= 1.0;
    for _ in 0..16 {
        sim.step();
    }
    let fall = y0 - sim.marble_state(0).0.y;
    let want = 0.5 * g * 0.25 * 0.25;
    assert!(
        (fall - want).abs() < 1e-2 * want,
        "fell {fall} m, want {want}"
    );

    // Gravity turned upwards.
    let mut sim = Simulation::from_scene(&resting_on_floor()).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().integrator = Integrator::VelocityVerlet;
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    sim.world_mut().resource_mut::<StepConfig>().gravity = Vec3::new(0.0, g, 0.0);
    for _ in 0..16 {
        sim.step();
    }
    let lift = sim.marble_state(0).0.y - y0;
    assert!(
        (lift - want).abs() < 1e-2 * want,
        "rose {lift} m, want {want}"
    );
}

/// Marbles poured into a box (bench scene (b), 300 marbles) with sleeping on (5 mm/s for
/// 0.5 s) settle and fall asleep as one pile within 6 s, with overlaps under 5% of the
/// radius and none out of the box; asleep, the pile stays bit for bit where it is, and
/// woken by the program it stays put and falls asleep again. A marble then dropped onto it at 1 m/s wakes it before it lands: the pile takes it
/// (no marble passes through another: overlaps stay under 5% of the radius, and the
/// dropped marble ends on the pile, above its lowest layer), and everything is asleep
/// again within 4 s.
#[test]
fn a_settled_pile_sleeps_whole_and_wakes_when_hit() {
    let mut scene = scenes::pour_box(300);
    scene.sleep_speed = 0.005;
    scene.sleep_time = 0.5;
    let half = 0.5 * 2.2 * R * 6.0;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let n = sim.marbles().len();
    let all_asleep = |sim: &Simulation| sim.asleep() == sim.marbles().len();
    let mut steps = 0;
    while !all_asleep(&sim) {
        sim.step();
        steps += 1;
        assert!(steps <= 360, "not all asleep after 6 s");
    }
    let positions = |sim: &Simulation| -> Vec<[f32; 3]> {
        (0..sim.marbles().len())
            .map(|i| sim.marble_state(i).0.to_array())
            .collect()
    };
    let deepest = |sim: &Simulation| -> f32 {
        let x: Vec<Vec3> = (0..sim.marbles().len())
            .map(|i| sim.marble_state(i).0)
            .collect();
        let mut deepest = 0.0f32;
        for i in 0..x.len() {
            for j in i + 1..x.len() {
                deepest = deepest.max(2.0 * R - (x[j] - x[i]).length());
            }
        }
        deepest / R
    };
    let outside = |sim: &Simulation| {
        (0..sim.marbles().len())
            .filter(|&i| {
                let x = sim.marble_state(i).0;
                x.x.abs() > half || x.z.abs() > half || x.y < 0.0
            })
            .count()
    };
    assert!(deepest(&sim) < 0.05 && outside(&sim) == 0);
    let settled = positions(&sim);
    for _ in 0..60 {
        sim.step();
    }
    assert_eq!(positions(&sim), settled, "a sleeping pile moved");

    // Woken by the program, the settled pile stays where it is (the contact impulses kept
    // over sleep warm start its first substep): no marble moves by 1% of r before the
    // whole pile is asleep again, 0.5 s later.
    let marbles = sim.marbles().to_vec();
    for &m in &marbles {
        sim.world_mut().entity_mut(m).remove::<Sleeping>();
    }
    let mut steps = 0;
    loop {
        sim.step();
        steps += 1;
        let moved = positions(&sim)
            .iter()
            .zip(&settled)
            .map(|(a, b)| (Vec3::from(*a) - Vec3::from(*b)).length())
            .fold(0.0f32, f32::max);
        assert!(
            moved < 0.01 * R,
            "step {steps} after waking: moved {moved} m"
        );
        if all_asleep(&sim) {
            break;
        }
        assert!(steps <= 40, "not asleep again 40 steps after waking");
    }
    let settled = positions(&sim);

    // Drop a marble onto the middle of the pile.
    let top = settled.iter().map(|x| x[1]).fold(0.0, f32::max);
    let drop = sim
        .world_mut()
        .spawn((
            Marble,
            Position(Vec3::new(0.0, top + 3.0 * R, 0.0)),
            Velocity(Vec3::new(0.0, -1.0, 0.0)),
        ))
        .id();
    let mut woke = 0;
    for step in 0..240 {
        sim.step();
        if step < 30 {
            woke = woke.max((0..n).filter(|&i| !asleep(&sim, i)).count());
        }
        let pile = deepest(&sim);
        let dropped = deepest_with(&sim, drop);
        assert!(
            pile < 0.05 && dropped < 0.05,
            "overlap at step {step}: {pile} r in the pile, {dropped} r with the dropped marble"
        );
    }
    assert!(woke > 0, "the drop woke nothing");
    let y = sim.world().get::<Position>(drop).unwrap().y;
    assert!(y > 3.0 * R, "the dropped marble sank to {y} m");
    assert!(all_asleep(&sim), "not asleep again 4 s after the drop");
    assert!(sim.world().get::<Sleeping>(drop).is_some());
    assert_eq!(outside(&sim), 0);
}

/// Deepest overlap (/ r) of marble `m` with any pile marble.
fn deepest_with(sim: &Simulation, m: bevy_ecs::entity::Entity) -> f32 {
    let x = sim.world().get::<Position>(m).unwrap().0;
    (0..sim.marbles().len())
        .map(|i| 2.0 * R - (sim.marble_state(i).0 - x).length())
        .fold(0.0, f32::max)
        / R
}

/// Two marbles stacked on a floor (marble collisions on, contact events as `events`),
/// stepped until both sleep.
fn sleeping_column(events: bool) -> Simulation {
    let mut scene = resting_on_floor();
    scene.marble_collisions = true;
    scene.marbles.push(MarbleDesc::at([0.0, 3.0 * R, 0.0]));
    let mut sim = Simulation::from_scene(&scene).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().events = events;
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0) && asleep(&sim, 1), "the column sleeps");
    sim
}

/// A sleeping column of two marbles on a floor: the program despawns the lower one, or
/// spoils its velocity (quarantined, it is out of every stage). The upper one wakes and
/// falls the 2r onto the floor, as it would awake; asleep on a marble that is gone, it
/// would hang in the air.
#[test]
fn a_sleeping_marble_wakes_when_the_one_under_it_goes() {
    for despawn in [true, false] {
        let mut sim = sleeping_column(true);
        let (lower, upper) = (sim.marbles()[0], sim.marbles()[1]);
        if despawn {
            sim.world_mut().despawn(lower);
        } else {
            sim.world_mut()
                .entity_mut(lower)
                .insert(Velocity(Vec3::splat(f32::NAN)));
        }
        let mut ended = Vec::new();
        for _ in 0..30 {
            sim.step();
            let messages = sim
                .world()
                .resource::<bevy_ecs::message::Messages<ContactEnded>>();
            ended.extend(messages.iter_current_update_messages().copied());
        }
        let y = sim.world().get::<Position>(upper).unwrap().y;
        assert!((y - R).abs() <= 0.01 * R, "despawn {despawn}: at {y}");
        // The pair's contact ended too (the quarantined marble is as if not there).
        let pair = ContactEnded {
            marble: lower.min(upper),
            other: lower.max(upper),
        };
        assert!(ended.contains(&pair), "despawn {despawn}: {ended:?}");
    }
}

/// A sleeping column of two marbles: turning marble collisions off wakes it (the upper
/// marble falls through the lower onto the floor, as it would awake), as turning off
/// rolling with a spin left on a resting marble lets it fall asleep (the frozen spin no
/// longer counts, and is kept), and turning rolling on again wakes it.
#[test]
fn sleep_follows_the_config_switches() {
    let mut sim = sleeping_column(false);
    sim.world_mut()
        .resource_mut::<StepConfig>()
        .marble_collisions = false;
    for _ in 0..30 {
        sim.step();
    }
    let y = sim.marble_state(1).0.y;
    assert!((y - R).abs() <= 0.01 * R, "at {y}");

    let mut scene = resting_on_floor();
    scene.rolling = true;
    scene.marbles[0].angular_velocity = [0.0, 50.0, 0.0]; // spinning in place
    let mut sim = Simulation::from_scene(&scene).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().rolling = false;
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0), "a frozen spin keeps it awake");
    // Asleep, it keeps its spin, inert while rolling is off; rolling on again wakes it.
    let m = sim.marbles()[0];
    let spin = |sim: &Simulation| sim.world().get::<AngularVelocity>(m).unwrap().0;
    assert_eq!(spin(&sim), Vec3::new(0.0, 50.0, 0.0));
    sim.world_mut().resource_mut::<StepConfig>().rolling = true;
    sim.step();
    assert!(!asleep(&sim, 0), "rolling on again: still asleep");
}

/// Two marbles asleep side by side on a floor, with contact events on: despawning one ends
/// its contacts (with the other marble and with the floor) at the next step (the other
/// wakes, so the pair is not carried on as a sleeping marble's).
#[test]
fn a_despawned_sleeping_marble_ends_its_contacts() {
    use bevy_ecs::message::Messages;
    let mut scene = resting_on_floor();
    scene.marble_collisions = true;
    scene.marbles.push(MarbleDesc::at([2.0 * R, R, 0.0]));
    let mut sim = Simulation::from_scene(&scene).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().events = true;
    for _ in 0..40 {
        sim.step();
    }
    assert!(asleep(&sim, 0) && asleep(&sim, 1), "both asleep");
    let (a, b) = (sim.marbles()[0], sim.marbles()[1]);
    let floor = sim.boards()[0];
    sim.world_mut().despawn(b);
    sim.step();
    let ended: Vec<ContactEnded> = sim
        .world()
        .resource::<Messages<ContactEnded>>()
        .iter_current_update_messages()
        .copied()
        .collect();
    let pair = ContactEnded {
        marble: a.min(b),
        other: a.max(b),
    };
    let on_floor = ContactEnded {
        marble: b,
        other: floor,
    };
    assert!(
        ended.contains(&pair) && ended.contains(&on_floor) && ended.len() == 2,
        "{ended:?}"
    );
}

/// A still world (every marble asleep) still reports its sensors each step, however many
/// substeps a step has: a sensor spawned around a sleeping marble is entered at the next
/// step, and left at the step after it is despawned, the marble asleep all along.
#[test]
fn a_sleeping_marble_enters_and_leaves_sensors() {
    use bevy_ecs::message::Messages;
    let mut scene = resting_on_floor();
    scene.substeps = 4;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    for _ in 0..33 {
        sim.step();
    }
    assert!(asleep(&sim, 0));
    let marble = sim.marbles()[0];
    let sensor = sim
        .world_mut()
        .spawn((
            Sensor,
            Collider::cuboid(Vec3::splat(0.05)).unwrap(),
            Position(Vec3::ZERO),
        ))
        .id();
    sim.step();
    assert_eq!(last_substep(&sim), 0, "still a still world");
    let entered: Vec<SensorEntered> = sim
        .world()
        .resource::<Messages<SensorEntered>>()
        .iter_current_update_messages()
        .copied()
        .collect();
    assert_eq!(entered, [SensorEntered { sensor, marble }]);
    sim.world_mut().despawn(sensor);
    sim.step();
    let exited: Vec<SensorExited> = sim
        .world()
        .resource::<Messages<SensorExited>>()
        .iter_current_update_messages()
        .copied()
        .collect();
    assert_eq!(exited, [SensorExited { sensor, marble }]);
    assert!(asleep(&sim, 0));
}
