//! Bad values through every door (the contract's rule): a marble or board given a bad
//! value by the Rust API, later by a system, or in a Bevy app is quarantined, stays put,
//! is reported (entity, component, value), and the rest of the world steps exactly as if
//! it were not there; the newtypes' constructors refuse the same values; scene files refuse
//! positions and speeds outside the supported range.

use bevy_ecs::message::Messages;
use bevy_marble::components::{RollingResistance, SpinDamping};
use bevy_marble::prelude::*;
use bevy_marble::scenes;
use bevy_marble::validate::{MAX_BOARD_SPIN, MAX_COORDINATE, MAX_DT, MAX_GRAVITY, MAX_SPEED};
use glam::Vec3;

/// Every log line of this test binary, for the tests that check what the engine logs (each
/// looks for its own entity or message: the tests run side by side).
static LOG: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

struct Capture;

impl log::Log for Capture {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, record: &log::Record) {
        LOG.lock()
            .unwrap()
            .push(format!("{} {}", record.level(), record.args()));
    }
    fn flush(&self) {}
}

/// Installs [`Capture`] (once per process) and returns the lines logged so far.
fn logged() -> Vec<String> {
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(|| {
        log::set_logger(&Capture).expect("no other logger in this binary");
        log::set_max_level(log::LevelFilter::Trace);
    });
    LOG.lock().unwrap().clone()
}

/// A drop onto a floor and a second marble beside it, stepped once.
fn world() -> Simulation {
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.marbles[0].position = [0.0, 0.5, 0.0];
    Simulation::from_scene(&scene).unwrap()
}

/// Steps `sim` `n` times and returns every report written meanwhile (a `Simulation`
/// keeps a step's messages until the end of the next step: read them after each).
fn step(sim: &mut Simulation, n: usize) -> Vec<QuarantineReport> {
    let mut out = Vec::new();
    for _ in 0..n {
        sim.step();
        let messages = sim.world().resource::<Messages<QuarantineReport>>();
        out.extend(messages.iter_current_update_messages().cloned());
    }
    out
}

/// A second marble spawned at `at` beside [`world`]'s and spoiled by `spoil`, stepped 30
/// times: it is quarantined where it is, reported once for `component`, and the good
/// marble ends in `want` (its state stepped alone). Returns the report.
fn quarantined_where_it_is(
    component: &str,
    spoil: impl Fn(&mut bevy_ecs::world::EntityWorldMut),
    at: Vec3,
    want: (Vec3, Vec3),
) -> QuarantineReport {
    let mut sim = world();
    let bad = sim.world_mut().spawn((Marble, Position(at))).id();
    spoil(&mut sim.world_mut().entity_mut(bad));
    // Its velocity and force, bit for bit (NaN included): left as they are.
    let motion = |w: &bevy_ecs::world::World| {
        let bits = |v: Option<Vec3>| v.map(|v| v.to_array().map(f32::to_bits));
        (
            bits(w.get::<Velocity>(bad).map(|v| v.0)),
            bits(w.get::<Force>(bad).map(|f| f.0)),
        )
    };
    let before = motion(sim.world());
    let r = step(&mut sim, 30);
    let w = sim.world();
    assert!(
        w.get::<Quarantined>(bad).is_some(),
        "{component}: not quarantined"
    );
    assert_eq!(
        motion(w),
        before,
        "{component}: its velocity or force changed"
    );
    assert_eq!(
        w.get::<Position>(bad).unwrap().0,
        at,
        "{component}: it moved"
    );
    assert_eq!(r.len(), 1, "{component}: {r:?}");
    assert_eq!((r[0].entity, r[0].reason.component), (bad, component));
    assert_eq!(
        sim.marble_state(0),
        want,
        "{component}: the good marble changed"
    );
    r[0].clone()
}

/// Each bad value, inserted by the Rust API on a second marble: quarantined before it
/// moves, reported with its component, and the good marble's state is bit for bit what it
/// is without the bad one.
#[test]
fn every_bad_marble_value_is_quarantined_where_it_is() {
    let mut alone = world();
    for _ in 0..30 {
        alone.step();
    }
    let want = alone.marble_state(0);
    let at = Vec3::new(1.0, 0.3, 0.0);
    let cases: Vec<(&str, Box<dyn Fn(&mut bevy_ecs::world::EntityWorldMut)>)> = vec![
        (
            "Radius",
            Box::new(|e| {
                e.insert(Radius(0.0));
            }),
        ),
        (
            "Radius",
            Box::new(|e| {
                e.insert(Radius(-1.0));
            }),
        ),
        (
            "Restitution",
            Box::new(|e| {
                e.insert(Restitution(2.0));
            }),
        ),
        (
            "Restitution",
            Box::new(|e| {
                e.insert(Restitution(-0.1));
            }),
        ),
        (
            "Friction",
            Box::new(|e| {
                e.insert(Friction(-0.5));
            }),
        ),
        (
            "Velocity",
            Box::new(|e| {
                e.insert(Velocity(Vec3::new(f32::INFINITY, 0.0, 0.0)));
            }),
        ),
        (
            "Velocity",
            Box::new(|e| {
                e.insert(Velocity(Vec3::new(0.0, 2.0 * MAX_SPEED, 0.0)));
            }),
        ),
        (
            "Force",
            Box::new(|e| {
                e.insert(Force(Vec3::new(0.0, f32::NAN, 0.0)));
            }),
        ),
        (
            "AngularVelocity",
            Box::new(|e| {
                e.insert(AngularVelocity(Vec3::splat(f32::NAN)));
            }),
        ),
    ];
    for (component, spoil) in cases {
        quarantined_where_it_is(component, spoil, at, want);
    }
    // A non-finite position and one beyond the supported range stay where they are too.
    for p in [Vec3::new(f32::NAN, 0.0, 0.0), Vec3::new(-1e38, 0.5, 0.0)] {
        let mut sim = world();
        let bad = sim.world_mut().spawn((Marble, Position(p))).id();
        let r = step(&mut sim, 1);
        let w = sim.world();
        assert!(w.get::<Quarantined>(bad).is_some());
        assert_eq!(
            w.get::<Position>(bad)
                .unwrap()
                .0
                .to_array()
                .map(f32::to_bits),
            p.to_array().map(f32::to_bits)
        );
        assert_eq!(r[0].reason.component, "Position");
    }
}

/// A marble whose program removed a component the stages read (`Marble` requires them
/// all) is quarantined where it is and reported as missing that component, and the good
/// marble steps bit for bit as without it; before, no stage would have moved it.
#[test]
fn a_marble_missing_a_component_is_quarantined_where_it_is() {
    let mut alone = world();
    for _ in 0..30 {
        alone.step();
    }
    let want = alone.marble_state(0);
    let at = Vec3::new(1.0, 0.3, 0.0);
    type Remove = fn(&mut bevy_ecs::world::EntityWorldMut);
    let cases: [(&str, Remove); 7] = [
        ("Velocity", |e| {
            e.remove::<Velocity>();
        }),
        ("Radius", |e| {
            e.remove::<Radius>();
        }),
        ("Restitution", |e| {
            e.remove::<Restitution>();
        }),
        ("Friction", |e| {
            e.remove::<Friction>();
        }),
        ("Acceleration", |e| {
            e.remove::<bevy_marble::components::Acceleration>();
        }),
        ("Contacts", |e| {
            e.remove::<bevy_marble::components::Contacts>();
        }),
        ("NearPieces", |e| {
            e.remove::<bevy_marble::board_contact::NearPieces>();
        }),
    ];
    for (component, remove) in cases {
        let r = quarantined_where_it_is(component, remove, at, want);
        assert_eq!(
            r.reason.to_string(),
            format!("{component} must be present on every marble, got missing")
        );
    }
}

/// A value spoiled later (a program setting a radius of −0.01 m after ten steps) is caught
/// at the next step: the marble stops where it was, and the message and a log warning say
/// what and why.
#[test]
fn a_value_changed_later_is_caught_at_the_next_step() {
    logged();
    let mut sim = world();
    assert!(step(&mut sim, 10).is_empty());
    let marble = sim.marbles()[0];
    let before = sim.world().get::<Position>(marble).unwrap().0;
    sim.world_mut().get_mut::<Radius>(marble).unwrap().0 = -0.01;
    let r = step(&mut sim, 5);
    let w = sim.world();
    assert!(w.get::<Quarantined>(marble).is_some());
    assert_eq!(w.get::<Position>(marble).unwrap().0, before);
    assert_eq!(r.len(), 1);
    assert_eq!(
        r[0].reason.to_string(),
        "Radius must be finite and > 0, got -0.01"
    );
    assert_eq!(sim.quarantined(), vec![0]);
    // And a log warning says the same.
    let line = format!("WARN bevy_marble: {marble} quarantined: {}", r[0].reason);
    assert!(logged().contains(&line), "{line}");
}

/// Every marble's position and velocity bits.
fn state_bits(sim: &Simulation) -> Vec<u32> {
    (0..sim.marbles().len())
        .flat_map(|i| {
            let (x, v) = sim.marble_state(i);
            x.to_array().into_iter().chain(v.to_array())
        })
        .map(f32::to_bits)
        .collect()
}

/// A program that gives the step settings a bad value, through the Rust API, gets the step
/// refused: nothing moves (bit for bit), the step is not counted, a `StepRefused` message
/// names the field and value; once mended, the next step runs. Each limit is tested at its
/// edge: the edge accepted, the next f32 past it refused.
#[test]
fn a_bad_step_setting_refuses_the_step_and_leaves_the_world_as_it_was() {
    type Set = fn(&mut StepConfig);
    let cases: &[(Set, &str)] = &[
        (
            |c| c.dt = f32::NAN,
            "StepConfig.dt must be > 0 and at most 1 s, got NaN",
        ),
        (
            |c| c.dt = 0.0,
            "StepConfig.dt must be > 0 and at most 1 s, got 0.0",
        ),
        (
            |c| c.dt = f32::from_bits(MAX_DT.to_bits() + 1),
            "StepConfig.dt must be > 0 and at most 1 s, got 1.0000001",
        ),
        (
            |c| c.gravity.y = f32::NEG_INFINITY,
            "StepConfig.gravity must be finite, each coordinate within 1e4 m/s², got Vec3(0.0, -inf, 0.0)",
        ),
        (
            |c| c.gravity.x = f32::from_bits(MAX_GRAVITY.to_bits() + 1),
            "StepConfig.gravity must be finite, each coordinate within 1e4 m/s², got Vec3(10000.001, -9.81, 0.0)",
        ),
        (
            |c| c.substeps = 0,
            "StepConfig.substeps must be >= 1, got 0",
        ),
        (
            |c| c.restitution_threshold = -1e-9,
            "StepConfig.restitution_threshold must be finite and >= 0, got -1e-9",
        ),
        (
            |c| c.contact_tolerance = f32::NAN,
            "StepConfig.contact_tolerance must be finite and >= 0, got NaN",
        ),
        (
            |c| {
                c.sleep = Some(Sleep {
                    speed: 0.0,
                    time: 0.5,
                })
            },
            "StepConfig.sleep.speed must be finite and > 0, got 0.0",
        ),
    ];
    for &(set, message) in cases {
        let mut sim = world();
        step(&mut sim, 3);
        let good = sim.world().resource::<StepConfig>().clone();
        let (before, steps) = (state_bits(&sim), sim.steps());
        set(&mut sim.world_mut().resource_mut::<StepConfig>());
        for _ in 0..2 {
            sim.step();
            assert_eq!(state_bits(&sim), before, "{message}: the world moved");
            assert_eq!(sim.steps(), steps, "{message}: a refused step was counted");
            let refused: Vec<_> = sim
                .world()
                .resource::<Messages<StepRefused>>()
                .iter_current_update_messages()
                .map(|m| m.reason.to_string())
                .collect();
            assert_eq!(refused, [message]);
        }
        *sim.world_mut().resource_mut::<StepConfig>() = good;
        sim.step();
        assert_ne!(
            state_bits(&sim),
            before,
            "{message}: the mended step did not run"
        );
        assert_eq!(sim.steps(), steps + 1);
        let messages = sim.world().resource::<Messages<StepRefused>>();
        assert_eq!(messages.iter_current_update_messages().count(), 0);
    }
    // The edges themselves step.
    let mut sim = world();
    {
        let mut c = sim.world_mut().resource_mut::<StepConfig>();
        c.dt = MAX_DT;
        c.gravity = Vec3::new(MAX_GRAVITY, -MAX_GRAVITY, 0.0);
        c.restitution_threshold = 0.0;
        c.contact_tolerance = 0.0;
    }
    sim.step();
    assert_eq!(sim.steps(), 1);
    assert!(sim.world().resource::<Messages<StepRefused>>().is_empty());
}

/// The longest step under the strongest gravity from the edge of the supported range
/// leaves finite values, which the next step's validation quarantines as out of range
/// (at dt = 1e20 s, which scene files refuse, one step overflowed to infinity): a marble
/// at 1e6 m moving away at 1e5 m/s under 1e4 m/s² back is, after 1 s, where the default
/// integrator puts it, then quarantined where it is.
#[test]
fn the_longest_step_from_the_edge_of_the_range_stays_finite() {
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.dt = MAX_DT;
    scene.gravity = [-MAX_GRAVITY, 0.0, 0.0];
    scene.marbles[0].position = [MAX_COORDINATE, 0.5, 0.0];
    scene.marbles[0].velocity = [MAX_SPEED, 0.0, 0.0];
    assert!(scene.validate().is_ok());
    let mut sim = Simulation::from_scene(&scene).unwrap();
    assert!(step(&mut sim, 1).is_empty());
    let (x, v) = sim.marble_state(0);
    // Semi-implicit Euler takes the whole step's gravity into the velocity first, so x
    // gains (v − g dt) dt: 1.09e6 m (the exact path is at 1.095e6); f32 resolves 0.125 m
    // there.
    let expected = MAX_COORDINATE as f64 + (MAX_SPEED - MAX_GRAVITY) as f64;
    assert!(((x.x as f64) - expected).abs() <= 0.125, "x = {x}");
    assert_eq!(v.x, MAX_SPEED - MAX_GRAVITY);
    let r = step(&mut sim, 1);
    assert_eq!(r.len(), 1);
    assert_eq!(r[0].reason.component, "Position");
    assert_eq!(sim.marble_state(0).0, x);
    // Scene files refuse anything longer, naming the field.
    scene.dt = f32::from_bits(MAX_DT.to_bits() + 1);
    assert_eq!(
        scene.validate().unwrap_err().to_string(),
        "dt must be at most 1 s, got 1.0000001"
    );
}

/// A board given a non-finite pose is quarantined and out of the step: the marble above
/// it falls freely through where it was, as if it were not there.
#[test]
fn a_bad_board_is_quarantined_and_out_of_the_step() {
    let mut sim = world();
    let floor = {
        let mut q = sim
            .world_mut()
            .query_filtered::<bevy_ecs::entity::Entity, bevy_ecs::query::With<Board>>();
        q.iter(sim.world()).next().unwrap()
    };
    sim.world_mut().get_mut::<Velocity>(floor).unwrap().0 = Vec3::new(f32::NAN, 0.0, 0.0);
    let dt = sim.world().resource::<StepConfig>().dt;
    let steps = 120;
    let r = step(&mut sim, steps);
    assert!(sim.world().get::<Quarantined>(floor).is_some());
    assert_eq!(r[0].reason.component, "Velocity");
    // Semi-implicit Euler's free fall: y = y0 − g dt² n(n+1)/2.
    let n = steps as f32;
    let want = 0.5 - 9.81 * dt * dt * n * (n + 1.0) / 2.0;
    let (x, _) = sim.marble_state(0);
    assert!((x.y - want).abs() <= 1e-4, "y = {}, want {want}", x.y);
}

/// A board driven to a bad pose (`NextPose` with a NaN, or one it could reach only
/// faster than the supported speed or spin) is quarantined before it moves, where it is,
/// reported as `NextPose`: the marble above falls freely through where it was.
#[test]
fn a_board_driven_to_a_bad_pose_is_quarantined_where_it_is() {
    use glam::Quat;
    let dt = world().world().resource::<StepConfig>().dt;
    // A quarter turn in a step: a spin of π/(2 dt), past the supported range at dt = 1e-4 s.
    let short = 1e-4;
    for (next, dt) in [
        (
            NextPose {
                position: Vec3::new(f32::NAN, 0.0, 0.0),
                rotation: Quat::IDENTITY,
            },
            dt,
        ),
        (
            NextPose {
                position: Vec3::ZERO,
                rotation: Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            },
            dt,
        ),
        (
            NextPose {
                position: Vec3::new(2.0 * MAX_SPEED * dt, 0.0, 0.0),
                rotation: Quat::IDENTITY,
            },
            dt,
        ),
        (
            NextPose {
                position: Vec3::ZERO,
                rotation: Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            },
            short,
        ),
    ] {
        assert!(std::f32::consts::FRAC_PI_2 / short > MAX_BOARD_SPIN);
        let mut sim = world();
        sim.world_mut().resource_mut::<StepConfig>().dt = dt;
        let floor = sim.boards()[0];
        let before = *sim.world().get::<Position>(floor).unwrap();
        sim.world_mut().entity_mut(floor).insert(next);
        let steps = 60;
        let r = step(&mut sim, steps);
        assert!(sim.world().get::<Quarantined>(floor).is_some(), "{next:?}");
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!(r[0].reason.component, "NextPose");
        assert_eq!(*sim.world().get::<Position>(floor).unwrap(), before);
        let v = *sim.world().get::<Velocity>(floor).unwrap();
        assert_eq!(v.0, Vec3::ZERO);
        // Semi-implicit Euler's free fall: y = y0 − g dt² n(n+1)/2.
        let n = steps as f32;
        let want = 0.5 - 9.81 * dt * dt * n * (n + 1.0) / 2.0;
        let (x, _) = sim.marble_state(0);
        assert!((x.y - want).abs() <= 1e-4, "y = {}, want {want}", x.y);
    }
}

/// The newtypes' constructors refuse what the step would quarantine, at the edges.
#[test]
fn constructors_refuse_bad_values_at_their_edges() {
    assert!(Radius::new(0.008).is_ok());
    assert!(Radius::new(0.0).is_err() && Radius::new(-1.0).is_err());
    assert!(Radius::new(f32::NAN).is_err() && Radius::new(f32::INFINITY).is_err());
    assert!(Restitution::new(0.0).is_ok() && Restitution::new(1.0).is_ok());
    let above_one = f32::from_bits(1.0f32.to_bits() + 1);
    assert_eq!(
        Restitution::new(above_one).unwrap_err().to_string(),
        format!("Restitution must be in [0, 1], got {above_one:?}")
    );
    assert!(Restitution::new(-0.0).is_ok() && Restitution::new(-1e-9).is_err());
    assert!(Friction::new(0.0).is_ok() && Friction::new(-1e-9).is_err());
    assert!(Mass::try_new(0.005).is_ok() && Mass::try_new(0.0).is_err());
    assert!(Mass::try_new(1e-39).is_err(), "an infinite inverse");
    assert!(Position::new(Vec3::splat(MAX_COORDINATE)).is_ok());
    assert!(Position::new(Vec3::new(0.0, -1e38, 0.0)).is_err());
    assert!(Velocity::new(Vec3::splat(MAX_SPEED)).is_ok());
    assert!(Velocity::new(Vec3::new(0.0, f32::NAN, 0.0)).is_err());
    assert!(Force::new(Vec3::INFINITY).is_err());
    assert!(Rotation::new(glam::Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)).is_err());
    assert!(RollingResistance::new(-1.0).is_err() && SpinDamping::new(0.1).is_ok());
}

/// Scene files refuse positions and speeds outside the supported range, naming the field.
#[test]
fn scene_files_refuse_coordinates_out_of_range() {
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.marbles[0].position = [-1e38, 0.5, 0.0];
    let err = scene.validate().unwrap_err().to_string();
    assert!(
        err.starts_with(
            "marbles[0].position must be within 1e6 m of the origin in each coordinate, got [-1e38"
        ),
        "{err}"
    );
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.marbles[0].velocity = [0.0, 0.0, 1e6];
    let err = scene.validate().unwrap_err().to_string();
    assert!(
        err.starts_with("marbles[0].velocity must be within 1e5 m/s in each coordinate, got [0.0, 0.0, 1000000.0]"),
        "{err}"
    );
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.boards[0].position = [0.0, 2e6, 0.0];
    assert!(
        scene
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("boards[0].position")
    );
}

/// A board spinning faster than the supported 1e4 rad/s, or a gravity past 1e4 m/s²: refused
/// in a scene file, naming
/// the field (exactly 1e4 accepted), and quarantined when a program sets it later, with a
/// report naming it. Continuous collision against a board turning at 1e7
/// rad/s made 30 steps of one marble take minutes (a fuzzing finding, kept in the corpus).
#[test]
fn a_board_spin_or_gravity_past_the_supported_range_is_refused() {
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.boards[0].angular_velocity = [MAX_BOARD_SPIN, 0.0, -MAX_BOARD_SPIN];
    assert!(scene.validate().is_ok());
    scene.boards[0].angular_velocity = [1e7, 0.0, 0.0];
    let err = scene.validate().unwrap_err().to_string();
    assert!(
        err.starts_with(
            "boards[0].angular_velocity must be within 1e4 rad/s in each coordinate, got [10000000.0"
        ),
        "{err}"
    );
    // Gravity likewise (a marble under 1e7 m/s² leaves the supported speeds within a step,
    // whose response took minutes: another fuzzing finding).
    let mut scene = scenes::drop_on_plane(0.5, 0.008, 0.5);
    scene.gravity = [0.0, -MAX_GRAVITY, MAX_GRAVITY];
    assert!(scene.validate().is_ok());
    scene.gravity = [0.0, 1e7, 0.0];
    let err = scene.validate().unwrap_err().to_string();
    assert!(
        err.starts_with("gravity must be within 1e4 m/s² in each coordinate, got [0.0, 10000000.0"),
        "{err}"
    );
    let mut sim = world();
    let floor = sim.boards()[0];
    let above = f32::from_bits(MAX_BOARD_SPIN.to_bits() + 1);
    sim.world_mut().get_mut::<AngularVelocity>(floor).unwrap().0 = Vec3::new(0.0, above, 0.0);
    let r = step(&mut sim, 1);
    assert!(sim.world().get::<Quarantined>(floor).is_some());
    assert_eq!(r[0].entity, floor);
    assert_eq!(r[0].reason.component, "AngularVelocity");
}

/// A Bevy app with the physics at a fixed step of 1/64 s, advanced 1/64 s per update,
/// and one marble 1 m up.
#[cfg(feature = "bevy")]
fn fixed_step_app() -> (bevy_app::App, bevy_ecs::entity::Entity) {
    use bevy_time::{Fixed, Time, TimePlugin, TimeUpdateStrategy};
    use std::time::Duration;
    let mut app = bevy_app::App::new();
    app.add_plugins((TimePlugin, MarblePhysicsPlugin::default()));
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 64.0,
    )));
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 64.0));
    let marble = app
        .world_mut()
        .spawn((Marble, Position(Vec3::new(0.0, 1.0, 0.0))))
        .id();
    (app, marble)
}

/// In a Bevy app: a system of the game sets a restitution of 2 in `Update`; the marble is
/// quarantined at the next fixed step, stays put, and a reader in `Update` gets the report.
#[cfg(feature = "bevy")]
#[test]
fn a_bevy_system_setting_a_bad_value_is_reported_to_the_app() {
    use bevy_app::Update;
    use bevy_ecs::prelude::*;
    #[derive(Resource, Default)]
    struct Seen(Vec<QuarantineReport>);
    let (mut app, marble) = fixed_step_app();
    app.init_resource::<Seen>();
    app.add_systems(
        Update,
        move |mut q: Query<&mut Restitution>,
              mut reader: MessageReader<QuarantineReport>,
              mut seen: ResMut<Seen>| {
            q.get_mut(marble).unwrap().0 = 2.0;
            seen.0.extend(reader.read().cloned());
        },
    );
    for _ in 0..6 {
        app.update();
    }
    let w = app.world();
    assert!(w.get::<Quarantined>(marble).is_some());
    let seen = &w.resource::<Seen>().0;
    assert_eq!(seen.len(), 1);
    assert_eq!(seen[0].entity, marble);
    assert_eq!(
        seen[0].reason.to_string(),
        "Restitution must be in [0, 1], got 2.0"
    );
    // It fell for the fixed steps before the change reached the physics, then stopped.
    let y = w.get::<Position>(marble).unwrap().y;
    app.update();
    assert_eq!(app.world().get::<Position>(marble).unwrap().y, y);
}

/// In a Bevy app: a `PhysicsClock` speed that makes the fixed step longer than 1 s gets
/// every such step refused (the marble stays where it is, an `Update` reader gets a
/// `StepRefused` per fixed step naming `StepConfig.dt` and its value), and the steps run
/// again once the speed is mended.
#[cfg(feature = "bevy")]
#[test]
fn a_bevy_app_stepping_too_long_gets_its_steps_refused() {
    use bevy_app::Update;
    use bevy_ecs::prelude::*;
    use bevy_marble::plugin::PhysicsClock;
    #[derive(Resource, Default)]
    struct Seen(Vec<String>);
    logged();
    let (mut app, marble) = fixed_step_app();
    app.insert_resource(PhysicsClock {
        paused: false,
        speed: 128.0,
    });
    app.init_resource::<Seen>();
    app.add_systems(
        Update,
        |mut reader: MessageReader<StepRefused>, mut seen: ResMut<Seen>| {
            seen.0.extend(reader.read().map(|m| m.reason.to_string()));
        },
    );
    for _ in 0..6 {
        app.update();
    }
    let w = app.world();
    assert_eq!(
        w.get::<Position>(marble).unwrap().0,
        Vec3::new(0.0, 1.0, 0.0)
    );
    let seen = &w.resource::<Seen>().0;
    assert!(seen.len() >= 4, "{seen:?}");
    assert!(
        seen.iter()
            .all(|s| s == "StepConfig.dt must be > 0 and at most 1 s, got 2.0"),
        "{seen:?}"
    );
    // One log error for the reason, not one per refused step (other tests of this binary
    // may log the same line: at least one, and no more than the tests that refuse dt = 2).
    let line =
        "ERROR bevy_marble: step refused: StepConfig.dt must be > 0 and at most 1 s, got 2.0";
    let count = logged().iter().filter(|l| *l == line).count();
    assert!((1..seen.len()).contains(&count), "{count} × {line}");
    app.world_mut().resource_mut::<PhysicsClock>().speed = 1.0;
    for _ in 0..3 {
        app.update();
    }
    assert!(app.world().get::<Position>(marble).unwrap().y < 1.0);
}

/// In a Bevy app: a marble spawned with a radius of −1 and a board spawned with a
/// restitution of 1.5 (a floor right under a falling marble) are quarantined at the next
/// fixed step, where they were spawned; an `Update` reader gets a report naming each entity,
/// component and value, the log has a warning saying the same, and the good marble falls
/// through where the board is, bit for bit as in the same app without the two.
#[cfg(feature = "bevy")]
#[test]
fn a_bevy_app_quarantines_what_it_spawns_with_bad_values_and_logs_it() {
    use bevy_app::Update;
    use bevy_ecs::prelude::*;
    #[derive(Resource, Default)]
    struct Seen(Vec<QuarantineReport>);
    logged();
    let (mut app, marble) = fixed_step_app();
    let (mut alone, alone_marble) = fixed_step_app();
    app.init_resource::<Seen>();
    app.add_systems(
        Update,
        |mut reader: MessageReader<QuarantineReport>, mut seen: ResMut<Seen>| {
            seen.0.extend(reader.read().cloned());
        },
    );
    for _ in 0..2 {
        app.update();
        alone.update();
    }
    let bad_marble = app
        .world_mut()
        .spawn((Marble, Position(Vec3::new(1.0, 1.0, 0.0)), Radius(-1.0)))
        .id();
    let bad_board = app
        .world_mut()
        .spawn((
            Board,
            Collider::plane(),
            Position(Vec3::new(0.0, 0.9, 0.0)),
            Restitution(1.5),
        ))
        .id();
    for _ in 0..30 {
        app.update();
        alone.update();
    }
    let w = app.world();
    assert!(w.get::<Quarantined>(bad_marble).is_some());
    assert!(w.get::<Quarantined>(bad_board).is_some());
    assert_eq!(
        w.get::<Position>(bad_marble).unwrap().0,
        Vec3::new(1.0, 1.0, 0.0)
    );
    let y = w.get::<Position>(marble).unwrap().0;
    assert!(y.y < 0.9, "the marble stopped on the bad board: {y}");
    assert_eq!(
        y.to_array().map(f32::to_bits),
        alone
            .world()
            .get::<Position>(alone_marble)
            .unwrap()
            .0
            .to_array()
            .map(f32::to_bits)
    );
    let mut seen: Vec<(Entity, String)> = w
        .resource::<Seen>()
        .0
        .iter()
        .map(|r| (r.entity, r.reason.to_string()))
        .collect();
    seen.sort();
    let mut want = vec![
        (
            bad_marble,
            "Radius must be finite and > 0, got -1.0".to_string(),
        ),
        (
            bad_board,
            "Restitution must be in [0, 1], got 1.5".to_string(),
        ),
    ];
    want.sort();
    assert_eq!(seen, want);
    let log = logged();
    for (entity, reason) in &want {
        let line = format!("WARN bevy_marble: {entity} quarantined: {reason}");
        assert_eq!(
            log.iter().filter(|l| **l == line).count(),
            1,
            "{line} in {log:?}"
        );
    }
}

/// A sleeping marble that the program spoils is quarantined at the next step, as an awake
/// one is: one missing a component (here `Force`, or `Velocity`), or given a negative
/// rolling resistance or a non-finite spin damping.
#[test]
fn a_sleeping_marble_spoiled_is_quarantined() {
    type Spoil = fn(&mut bevy_ecs::world::EntityWorldMut);
    let cases: [(&str, Spoil); 4] = [
        ("Force", |e| {
            e.remove::<Force>();
        }),
        ("Velocity", |e| {
            e.remove::<Velocity>();
        }),
        ("RollingResistance", |e| {
            e.insert(RollingResistance(-1.0));
        }),
        ("SpinDamping", |e| {
            e.insert(SpinDamping(f32::INFINITY));
        }),
    ];
    for (component, spoil) in cases {
        let mut scene = scenes::drop_on_plane(0.0, 0.008, 0.5);
        scene.rolling = true;
        scene.sleep_speed = 0.01;
        scene.sleep_time = 0.25;
        let mut sim = Simulation::from_scene(&scene).unwrap();
        step(&mut sim, 60);
        assert!(sim.is_asleep(0), "{component}: asleep first");
        let m = sim.marbles()[0];
        spoil(&mut sim.world_mut().entity_mut(m));
        let r = step(&mut sim, 1);
        assert!(
            sim.world().get::<Quarantined>(m).is_some(),
            "{component}: not quarantined"
        );
        assert_eq!(r.len(), 1, "{component}: {r:?}");
        assert_eq!((r[0].entity, r[0].reason.component), (m, component));
    }
}

/// A marble, board or sensor made the child of another entity gets a logged warning that
/// names it: the engine takes its `Transform` as its world pose (docs/bevy.md), so a
/// child is stepped and shown elsewhere than a game may mean. A root entity gets none.
#[cfg(feature = "bevy")]
#[test]
fn a_child_marble_board_or_sensor_is_warned_of() {
    use bevy_ecs::hierarchy::ChildOf;
    logged();
    let (mut app, root_marble) = fixed_step_app();
    let parent = app.world_mut().spawn_empty().id();
    let child_marble = app
        .world_mut()
        .spawn((Marble, Position(Vec3::new(2.0, 1.0, 0.0)), ChildOf(parent)))
        .id();
    let child_sensor = app
        .world_mut()
        .spawn((Sensor, Collider::plane(), ChildOf(parent)))
        .id();
    // Made a child later: warned too.
    let board = app.world_mut().spawn((Board, Collider::plane())).id();
    app.update();
    app.world_mut().entity_mut(board).insert(ChildOf(parent));
    app.update();
    let lines = logged();
    let warned = |e: bevy_ecs::entity::Entity| {
        lines
            .iter()
            .filter(|l| l.starts_with("WARN") && l.contains(&format!("{e} is a child")))
            .count()
    };
    assert_eq!(warned(child_marble), 1, "{lines:?}");
    assert_eq!(warned(child_sensor), 1, "{lines:?}");
    assert_eq!(warned(board), 1, "{lines:?}");
    assert_eq!(warned(root_marble), 0, "{lines:?}");
}
