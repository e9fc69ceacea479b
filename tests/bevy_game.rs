//! A marble game in a headless Bevy app (`TimePlugin`, manual frame durations, the plugin):
//! spawning from `Transform`, teleports, collider constructors, impact, contact and sensor
//! messages and observer events, driven boards, interpolation, pausing, diagnostics and
//! reflection, each against an exact answer.
#![cfg(feature = "bevy")]

use std::time::Duration;

use bevy_app::{App, FixedUpdate, Update};
use bevy_ecs::prelude::*;
use bevy_marble::prelude::*;
use bevy_time::{Fixed, Time, TimePlugin, TimeUpdateStrategy};
use bevy_transform::components::Transform;
use glam::{Quat, Vec3};

const G: f32 = 9.81;
/// Bevy's default fixed step.
const DT: f64 = 1.0 / 64.0;

/// A headless app with the plugin whose frames each last `frame` seconds, with Verlet
/// (exact in free flight under gravity) so that every figure has an exact answer.
fn app(frame: f64) -> App {
    let mut app = App::new();
    app.add_plugins((TimePlugin, MarblePhysicsPlugin::default()));
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        frame,
    )));
    app.insert_resource(Time::<Fixed>::from_seconds(DT));
    app.world_mut().resource_mut::<StepConfig>().integrator = Integrator::VelocityVerlet;
    app.finish();
    app.cleanup();
    // The first update only starts the clock.
    app.update();
    app
}

/// Everything a reader in `Update` saw.
#[derive(Resource, Default)]
struct Seen {
    impacts: Vec<MarbleImpact>,
    started: Vec<ContactStarted>,
    ended: Vec<ContactEnded>,
    entered: Vec<(SensorEntered, u32)>,
    exited: Vec<(SensorExited, u32)>,
    /// Fixed steps run so far (counted by a `FixedUpdate` system of the game's own).
    steps: u32,
}

fn read_messages(
    mut seen: ResMut<Seen>,
    mut impacts: MessageReader<MarbleImpact>,
    mut started: MessageReader<ContactStarted>,
    mut ended: MessageReader<ContactEnded>,
    mut entered: MessageReader<SensorEntered>,
    mut exited: MessageReader<SensorExited>,
) {
    let steps = seen.steps;
    seen.impacts.extend(impacts.read().copied());
    seen.started.extend(started.read().copied());
    seen.ended.extend(ended.read().copied());
    seen.entered.extend(entered.read().map(|e| (*e, steps)));
    seen.exited.extend(exited.read().map(|e| (*e, steps)));
}

fn count_steps(mut seen: ResMut<Seen>) {
    seen.steps += 1;
}

/// An app that records every message in `Update` and counts fixed steps.
fn recording_app(frame: f64) -> App {
    let mut app = app(frame);
    app.init_resource::<Seen>();
    app.add_systems(Update, read_messages);
    app.add_systems(FixedUpdate, count_steps);
    app
}

fn floor(app: &mut App, restitution: f32) -> Entity {
    app.world_mut()
        .spawn((Board, Collider::plane(), Restitution(restitution)))
        .id()
}

#[test]
fn marbles_and_boards_start_at_their_transform_and_position_wins() {
    let mut app = app(DT);
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 0.5, 0.0)))
        .id();
    let turn = Quat::from_rotation_z(0.3);
    let board = app
        .world_mut()
        .spawn((
            Board,
            Collider::cuboid(Vec3::new(1.0, 0.1, 1.0)).unwrap(),
            Transform::from_xyz(3.0, 0.0, 0.0).with_rotation(turn),
        ))
        .id();
    let both = app
        .world_mut()
        .spawn((
            Marble,
            Position(Vec3::new(0.0, 2.0, 0.0)),
            Transform::from_xyz(0.0, 9.0, 0.0),
        ))
        .id();
    let plain = app.world_mut().spawn(Marble).id();
    let w = app.world();
    assert_eq!(
        w.get::<Position>(marble).unwrap().0,
        Vec3::new(0.0, 0.5, 0.0)
    );
    assert_eq!(
        w.get::<Position>(board).unwrap().0,
        Vec3::new(3.0, 0.0, 0.0)
    );
    assert_eq!(w.get::<Rotation>(board).unwrap().0, turn);
    assert_eq!(w.get::<Position>(both).unwrap().0, Vec3::new(0.0, 2.0, 0.0));
    assert_eq!(w.get::<Position>(plain).unwrap().0, Vec3::ZERO);
    // A step later the marble has fallen from 0.5 (Verlet: ½ g t² exactly) and its
    // Transform shows it; the one given both kept its Position.
    app.update();
    let w = app.world();
    let y = w.get::<Position>(marble).unwrap().y;
    let want = 0.5 - 0.5 * G * (DT * DT) as f32;
    assert!((y - want).abs() <= 1e-6, "y = {y}, want {want}");
    assert_eq!(w.get::<Transform>(marble).unwrap().translation.y, y);
    let y2 = w.get::<Position>(both).unwrap().y;
    assert!((y2 - (2.0 - 0.5 * G * (DT * DT) as f32)).abs() <= 1e-6);
}

#[test]
fn a_transform_set_by_the_program_teleports_and_velocity_stays() {
    let mut app = app(DT);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            Transform::from_xyz(0.0, 1.0, 0.0),
            Velocity(Vec3::new(1.0, 0.0, 0.0)),
        ))
        .id();
    for _ in 0..5 {
        app.update();
    }
    app.world_mut()
        .get_mut::<Transform>(marble)
        .unwrap()
        .translation = Vec3::new(10.0, 5.0, 0.0);
    let v = app.world().get::<Velocity>(marble).unwrap().0;
    app.update();
    let w = app.world();
    let p = w.get::<Position>(marble).unwrap().0;
    let dt = DT as f32;
    // One Verlet step from the teleport, with the velocity it had.
    let want = Vec3::new(10.0, 5.0, 0.0) + v * dt + Vec3::new(0.0, -0.5 * G * dt * dt, 0.0);
    assert!((p - want).length() <= 1e-5, "at {p}, want {want}");
    // Untouched Transforms (the engine's own writes) are not teleports.
    app.update();
    let q = app.world().get::<Position>(marble).unwrap().0;
    assert!((q.x - (p.x + v.x * dt)).abs() <= 1e-5);
}

#[test]
fn collider_constructors_check_their_input() {
    assert!(Collider::cuboid(Vec3::ONE).is_ok());
    let err = Collider::cuboid(Vec3::new(-1.0, 1.0, 1.0)).unwrap_err();
    assert_eq!(
        err.to_string(),
        "collider.Cuboid.half_extents.x must be > 0, got -1"
    );
    let tri = [Vec3::ZERO, Vec3::X, Vec3::Z];
    assert!(Collider::trimesh(&tri, &[[0, 1, 2]]).is_ok());
    let err = Collider::trimesh(&tri, &[[0, 1, 3]]).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("collider.TriMesh.indices[0][2] must be < 3"),
        "{err}"
    );
    assert!(Collider::heightfield(vec![vec![0.0; 3]; 3], Vec3::ONE).is_ok());
    let err = Collider::heightfield(vec![vec![0.0; 3]], Vec3::ONE).unwrap_err();
    assert!(err.to_string().contains("HeightField.heights"), "{err}");
    assert!(Collider::bowl(0.5).is_ok());
    assert!(Collider::bowl(0.0).is_err());
    assert!(Collider::compound(vec![]).is_err());
    let parts = vec![(
        Vec3::Y,
        Quat::IDENTITY,
        ShapeDesc::Cuboid {
            half_extents: [1.0, 0.1, 1.0],
        },
    )];
    assert!(Collider::compound(parts).is_ok());
    let _ = Collider::plane();
}

/// A marble dropped from h onto a floor: the first impact speed is √(2gh), each next one
/// e times the last (Verlet's free flight is exact; continuous collision finds each impact
/// within the touching tolerance, a micrometre, so the speeds are good to about 1e-5); a
/// `MarbleImpact` for each, read in `Update` and seen by an observer on the marble, the
/// contact starting at the first impact; none once it rests.
#[test]
fn impacts_come_at_the_free_fall_speed_and_shrink_by_e() {
    let mut app = recording_app(DT);
    let (h, r, e) = (0.5f32, 0.008f32, 0.5f32);
    let floor = floor(&mut app, e);
    let marble = app
        .world_mut()
        .spawn((Marble, Restitution(e), Transform::from_xyz(0.0, h + r, 0.0)))
        .id();
    #[derive(Resource, Default)]
    struct Observed(Vec<f32>);
    app.init_resource::<Observed>();
    app.world_mut().entity_mut(marble).observe(
        |impact: On<MarbleImpact>, mut seen: ResMut<Observed>| {
            seen.0.push(impact.speed);
        },
    );
    for _ in 0..(3.0 / DT) as usize {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert!(seen.impacts.len() >= 4, "{} impacts", seen.impacts.len());
    let v0 = (2.0 * G * h).sqrt();
    for (n, impact) in seen.impacts.iter().take(4).enumerate() {
        let want = v0 * e.powi(n as i32);
        assert!(
            ((impact.speed - want) / want).abs() <= 1e-4,
            "impact {n}: {} m/s, want {want}",
            impact.speed
        );
        assert_eq!((impact.marble, impact.other), (marble, floor));
        assert!((impact.normal - Vec3::Y).length() <= 1e-6);
        assert!(impact.point.y.abs() <= 1e-5, "point {}", impact.point);
    }
    let observed = &app.world().resource::<Observed>().0;
    let read: Vec<f32> = seen.impacts.iter().map(|i| i.speed).collect();
    assert_eq!(observed, &read, "observers see what readers read");
    assert_eq!(
        seen.started.first(),
        Some(&ContactStarted {
            marble,
            other: floor
        })
    );
    // It rests now: a second more brings no impact.
    let n = seen.impacts.len();
    for _ in 0..64 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert_eq!(seen.impacts.len(), n, "a resting marble makes no impacts");
    assert!(app.world().get::<Position>(marble).unwrap().y - r <= 1e-4);
}

/// A recording app with no gravity and marble collisions on, and two elastic marbles
/// 10 cm apart on the x axis closing head-on, each at `u`.
fn head_on_pair(u: f32) -> (App, Entity, Entity) {
    let mut app = recording_app(DT);
    {
        let mut config = app.world_mut().resource_mut::<StepConfig>();
        config.gravity = Vec3::ZERO;
        config.marble_collisions = true;
    }
    let mut spawn = |x: f32, v: f32| {
        app.world_mut()
            .spawn((
                Marble,
                Restitution(1.0),
                Position(Vec3::X * x),
                Velocity(Vec3::X * v),
            ))
            .id()
    };
    let (a, b) = (spawn(-0.05, u), spawn(0.05, -u));
    (app, a, b)
}

/// Two marbles meeting head-on (no gravity, marble collisions on): one `MarbleImpact` for
/// the pair at the closing speed 2u, its normal from the other marble towards the first,
/// its point midway; the contact starts at the impact and ends once they have parted.
#[test]
fn a_marble_pair_impact_is_reported_once_at_its_closing_speed() {
    let u = 0.5;
    let (mut app, a, b) = head_on_pair(u);
    for _ in 0..16 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert_eq!(seen.impacts.len(), 1, "{:?}", seen.impacts);
    let hit = seen.impacts[0];
    let (marble, other) = (hit.marble, hit.other);
    assert!((marble, other) == (a, b) || (marble, other) == (b, a));
    assert!(
        ((hit.speed - 2.0 * u) / (2.0 * u)).abs() <= 1e-4,
        "speed {}",
        hit.speed
    );
    let towards_marble = if marble == a { -Vec3::X } else { Vec3::X };
    assert!(
        (hit.normal - towards_marble).length() <= 1e-4,
        "normal {}",
        hit.normal
    );
    assert!(hit.point.length() <= 1e-3, "point {}", hit.point);
    assert_eq!(seen.started, vec![ContactStarted { marble, other }]);
    assert_eq!(seen.ended, vec![ContactEnded { marble, other }]);
    // Elastic and equal: they swapped velocities.
    let va = app.world().get::<Velocity>(a).unwrap().0;
    assert!((va.x + u).abs() <= 1e-4, "{va}");
}

/// A bounce off the floor and away: ContactStarted at the impact, ContactEnded once the
/// marble has left, each once and in that order.
#[test]
fn a_bounce_starts_and_ends_one_contact() {
    let mut app = recording_app(DT);
    let floor = floor(&mut app, 1.0);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            Restitution(1.0),
            Transform::from_xyz(0.0, 0.1, 0.0),
            Velocity(Vec3::new(0.0, -1.0, 0.0)),
        ))
        .id();
    for _ in 0..16 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert_eq!(seen.impacts.len(), 1);
    assert_eq!(
        seen.started,
        vec![ContactStarted {
            marble,
            other: floor
        }]
    );
    assert_eq!(
        seen.ended,
        vec![ContactEnded {
            marble,
            other: floor
        }]
    );
}

/// A sensor between heights 0.4 and 0.6 m and a marble dropped from rest at 1 m: entered
/// at the first step that ends with the centre below 0.6 m (t = √(2·0.4/g)) and left at the
/// first that ends below 0.4 m (t = √(2·0.6/g)), Verlet's positions being exact.
#[test]
fn a_sensor_is_entered_and_left_at_the_free_fall_times() {
    let mut app = recording_app(DT);
    let sensor = app
        .world_mut()
        .spawn((
            Sensor,
            Collider::cuboid(Vec3::new(0.5, 0.1, 0.5)).unwrap(),
            Transform::from_xyz(0.0, 0.5, 0.0),
        ))
        .id();
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 1.0, 0.0)))
        .id();
    for _ in 0..40 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    let step_of = |fall: f32| ((2.0 * fall / G).sqrt() as f64 / DT).ceil() as u32;
    assert_eq!(
        seen.entered,
        vec![(SensorEntered { sensor, marble }, step_of(0.4))]
    );
    assert_eq!(
        seen.exited,
        vec![(SensorExited { sensor, marble }, step_of(0.6))]
    );
    // The marble passed through untouched.
    assert!(seen.impacts.is_empty());
    let y = app.world().get::<Position>(marble).unwrap().y;
    let t = 40.0 * DT as f32;
    assert!((y - (1.0 - 0.5 * G * t * t)).abs() <= 1e-4);
}

/// A dozen sensors (a labyrinth's holes) and 200 marbles falling through them: each
/// marble enters and leaves exactly the sensors its column passes.
#[test]
fn many_sensors_report_each_marble_once() {
    let mut app = recording_app(DT);
    let mut sensors = Vec::new();
    for i in 0..12 {
        let x = i as f32;
        sensors.push(
            app.world_mut()
                .spawn((
                    Sensor,
                    Collider::cuboid(Vec3::new(0.3, 0.05, 0.3)).unwrap(),
                    Position(Vec3::new(x, 0.0, 0.0)),
                ))
                .id(),
        );
    }
    for k in 0..200 {
        let x = (k % 24) as f32 * 0.5;
        app.world_mut()
            .spawn((Marble, Position(Vec3::new(x, 0.5 + 0.01 * k as f32, 0.0))));
    }
    for _ in 0..64 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    // Marbles at x = 0, 1, …, 11 (every other column) pass through one sensor each.
    let through = (0..200).filter(|k| k % 2 == 0).count();
    assert_eq!(seen.entered.len(), through);
    assert_eq!(seen.exited.len(), through);
}

/// `NextPose` lifts and turns a board to its pose exactly in one step and leaves it still;
/// a marble resting on it (e = 0) is carried up with the board's velocity.
#[test]
fn next_pose_reaches_its_pose_in_one_step_and_carries_a_marble() {
    let mut app = recording_app(DT);
    let board = app
        .world_mut()
        .spawn((
            Board,
            Collider::cuboid(Vec3::new(1.0, 0.05, 1.0)).unwrap(),
            Restitution(0.0),
            Position(Vec3::new(0.0, -0.05, 0.0)),
        ))
        .id();
    let r = 0.008;
    let marble = app
        .world_mut()
        .spawn((Marble, Restitution(0.0), Position(Vec3::new(0.0, r, 0.0))))
        .id();
    for _ in 0..8 {
        app.update();
    }
    let lift = 0.01;
    let target = Vec3::new(0.0, -0.05 + lift, 0.0);
    let turn = Quat::from_rotation_y(0.2);
    app.world_mut().entity_mut(board).insert(NextPose {
        position: target,
        rotation: turn,
    });
    app.update();
    let w = app.world();
    assert_eq!(w.get::<Position>(board).unwrap().0, target);
    assert!(w.get::<Rotation>(board).unwrap().0.angle_between(turn) <= 1e-6);
    assert_eq!(w.get::<Velocity>(board).unwrap().0, Vec3::ZERO);
    assert_eq!(w.get::<AngularVelocity>(board).unwrap().0, Vec3::ZERO);
    assert!(w.get::<NextPose>(board).is_none());
    let (p, v) = (
        w.get::<Position>(marble).unwrap().0,
        w.get::<Velocity>(marble).unwrap().0,
    );
    let board_speed = lift / DT as f32;
    assert!((p.y - (lift + r)).abs() <= 2e-4, "marble at {p}");
    assert!(
        (v.y - board_speed).abs() <= 0.01 * board_speed,
        "marble moving at {v}"
    );
    // Turning about the vertical through the marble moves it nowhere sideways.
    assert!(p.x.abs() <= 1e-5 && p.z.abs() <= 1e-5);
    // The board holds still afterwards.
    app.update();
    assert_eq!(app.world().get::<Position>(board).unwrap().0, target);
}

/// With `TransformInterpolation`, a frame's `Transform` lies on the line between the
/// positions after the last two physics steps, at the overstep fraction: at 144 frames a
/// second (0 or 1 step a frame) and at 4 steps a frame; a teleport jumps with no streak.
#[test]
fn interpolated_transforms_lie_between_the_last_two_poses() {
    for frame in [1.0 / 144.0, 4.0 * DT] {
        let mut app = app(frame);
        #[derive(Resource, Default)]
        struct Poses(Vec<Vec3>);
        app.init_resource::<Poses>();
        let marble = app
            .world_mut()
            .spawn((
                Marble,
                TransformInterpolation,
                Transform::from_xyz(0.0, 10.0, 0.0),
                Velocity(Vec3::new(1.0, 0.0, 0.0)),
            ))
            .id();
        app.add_systems(
            bevy_app::FixedLast,
            move |q: Query<&Position>, mut poses: ResMut<Poses>| {
                poses.0.push(q.get(marble).unwrap().0);
            },
        );
        for _ in 0..40 {
            app.update();
            let w = app.world();
            let poses = &w.resource::<Poses>().0;
            if poses.len() < 2 {
                continue;
            }
            let (a, b) = (poses[poses.len() - 2], poses[poses.len() - 1]);
            let f = w.resource::<Time<Fixed>>().overstep_fraction();
            let shown = w.get::<Transform>(marble).unwrap().translation;
            let want = a.lerp(b, f);
            assert!((shown - want).length() <= 1e-5, "{shown} against {want}");
        }
        // A teleport: the frames after it show the new place and the path from it, never a
        // point between the old place and the new (a streak).
        let to = Vec3::new(-50.0, 20.0, 0.0);
        let from = app.world().get::<Position>(marble).unwrap().0;
        app.world_mut()
            .get_mut::<Transform>(marble)
            .unwrap()
            .translation = to;
        for _ in 0..3 {
            app.update();
            let shown = app.world().get::<Transform>(marble).unwrap().translation;
            let t = app.world().resource::<Time>().elapsed_secs();
            assert!(
                (shown - to).length() < 0.1 * (shown - from).length(),
                "shown at {shown} after a teleport from {from} to {to} ({t} s)"
            );
        }
    }
}

/// Messages written during the several fixed steps of one frame all reach the `Update`
/// reader: the same bounces read at one step a frame and at four steps a frame.
#[test]
fn messages_of_several_fixed_steps_in_a_frame_all_arrive() {
    let mut counts = Vec::new();
    for frame in [DT, 4.0 * DT] {
        let mut app = recording_app(frame);
        floor(&mut app, 0.9);
        for k in 0..8 {
            app.world_mut().spawn((
                Marble,
                Restitution(0.9),
                Transform::from_xyz(k as f32, 0.05 + 0.02 * k as f32, 0.0),
            ));
        }
        for _ in 0..(128.0 * DT / frame) as usize {
            app.update();
        }
        let seen = app.world().resource::<Seen>();
        assert_eq!(seen.steps, 128);
        counts.push((seen.impacts.len(), seen.started.len(), seen.ended.len()));
    }
    assert!(counts[0].0 > 16, "{counts:?}");
    assert_eq!(counts[0], counts[1]);
}

/// Paused, the physics does not step while the game's own fixed-step systems go on;
/// at speed 2 a step covers twice the time.
#[test]
fn the_physics_pauses_and_scales_apart_from_the_game() {
    let mut app = recording_app(DT);
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 10.0, 0.0)))
        .id();
    app.world_mut().resource_mut::<PhysicsClock>().paused = true;
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(app.world().resource::<Seen>().steps, 10);
    assert_eq!(app.world().get::<Position>(marble).unwrap().y, 10.0);
    *app.world_mut().resource_mut::<PhysicsClock>() = PhysicsClock {
        paused: false,
        speed: 2.0,
    };
    for _ in 0..10 {
        app.update();
    }
    let y = app.world().get::<Position>(marble).unwrap().y;
    let t = 20.0 * DT as f32;
    assert!((y - (10.0 - 0.5 * G * t * t)).abs() <= 1e-4, "y = {y}");
}

/// Diagnostics report the marbles stepped and the step time; the components are
/// registered for reflection.
#[test]
fn diagnostics_and_reflection() {
    let mut app = app(DT);
    for k in 0..5 {
        app.world_mut()
            .spawn((Marble, Position(Vec3::new(k as f32, 1.0, 0.0))));
    }
    app.update();
    app.update();
    let store = app.world().resource::<bevy_diagnostic::DiagnosticsStore>();
    let awake = store.get(&MarbleDiagnostics::AWAKE).unwrap();
    assert_eq!(awake.value(), Some(5.0));
    assert!(
        store
            .get(&MarbleDiagnostics::STEP_TIME)
            .unwrap()
            .value()
            .is_some()
    );
    let registry = app.world().resource::<AppTypeRegistry>().read();
    assert!(registry.get(std::any::TypeId::of::<Position>()).is_some());
    assert!(registry.get(std::any::TypeId::of::<StepConfig>()).is_some());
}

/// The group leaves parts out: without the events plugin no impact is recorded.
#[test]
fn the_plugin_group_leaves_parts_out() {
    use bevy_app::PluginGroup;
    use bevy_marble::plugin::MarbleEventsPlugin;
    let mut app = App::new();
    app.add_plugins((
        TimePlugin,
        MarblePhysicsPlugins::default()
            .build()
            .disable::<MarbleEventsPlugin>(),
    ));
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        DT,
    )));
    app.finish();
    assert!(!app.world().resource::<StepConfig>().events);
}

/// Marble collisions turned off right after two marbles met: the impact is not reported
/// again, and their contact ends at the next step (the pair stages no longer run, so no
/// pair is touching).
#[test]
fn turning_marble_collisions_off_ends_their_pairs() {
    let (mut app, a, b) = head_on_pair(0.5);
    let mut steps = 0;
    while app.world().resource::<Seen>().impacts.is_empty() {
        app.update();
        steps += 1;
        assert!(steps < 16, "the marbles never met");
    }
    app.world_mut()
        .resource_mut::<StepConfig>()
        .marble_collisions = false;
    for _ in 0..8 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert_eq!(seen.impacts.len(), 1, "{:?}", seen.impacts);
    let (marble, other) = (seen.impacts[0].marble, seen.impacts[0].other);
    assert!((marble, other) == (a, b) || (marble, other) == (b, a));
    assert_eq!(seen.ended, vec![ContactEnded { marble, other }]);
}

/// Two marbles resting against each other (no gravity): their contact starts once and
/// holds while the game adds a component to one of them (which moves it to another table
/// and so changes the order the engine steps them in).
#[test]
fn a_resting_pair_keeps_its_contact_when_a_marble_changes_table() {
    #[derive(Component)]
    struct Picked;
    let mut app = recording_app(DT);
    {
        let mut config = app.world_mut().resource_mut::<StepConfig>();
        config.gravity = Vec3::ZERO;
        config.marble_collisions = true;
    }
    let r = 0.008;
    let a = app.world_mut().spawn((Marble, Position(Vec3::ZERO))).id();
    let b = app
        .world_mut()
        .spawn((Marble, Position(Vec3::X * 2.0 * r)))
        .id();
    for _ in 0..4 {
        app.update();
    }
    app.world_mut().entity_mut(a).insert(Picked);
    for _ in 0..4 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    // A pair is reported in `Entity`'s order.
    let (marble, other) = (a.min(b), a.max(b));
    assert_eq!(seen.started, vec![ContactStarted { marble, other }]);
    assert!(seen.ended.is_empty(), "{:?}", seen.ended);
}

/// A marble inside the only sensor leaves it at the next step when the sensor is despawned,
/// and another when its sensor loses the `Sensor` component.
#[test]
fn a_removed_sensor_is_left() {
    for despawn in [true, false] {
        let mut app = recording_app(DT);
        app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
        let sensor = app
            .world_mut()
            .spawn((
                Sensor,
                Collider::cuboid(Vec3::splat(0.1)).unwrap(),
                Transform::default(),
            ))
            .id();
        let marble = app.world_mut().spawn((Marble, Transform::default())).id();
        for _ in 0..3 {
            app.update();
        }
        let seen = app.world().resource::<Seen>();
        assert_eq!(seen.entered.len(), 1);
        let steps = seen.steps;
        if despawn {
            app.world_mut().despawn(sensor);
        } else {
            app.world_mut().entity_mut(sensor).remove::<Sensor>();
        }
        app.update();
        let seen = app.world().resource::<Seen>();
        assert_eq!(
            seen.exited,
            vec![(SensorExited { sensor, marble }, steps + 1)]
        );
    }
}

/// A `Transform` (or `Position`) given by a later command than the one that spawned the
/// marble or board: the entity starts there, as if spawned with it. A `Position` given
/// still wins.
#[test]
fn a_transform_inserted_after_the_spawn_places_the_entity() {
    let mut app = app(DT);
    let world = app.world_mut();
    let marble = world.spawn(Marble).id();
    world
        .entity_mut(marble)
        .insert(Transform::from_xyz(0.0, 0.5, 0.0));
    let turn = Quat::from_rotation_z(0.3);
    let board = world
        .spawn((Board, Collider::cuboid(Vec3::new(1.0, 0.1, 1.0)).unwrap()))
        .id();
    world
        .entity_mut(board)
        .insert(Transform::from_xyz(3.0, 0.0, 0.0).with_rotation(turn));
    let given = world.spawn(Marble).id();
    world
        .entity_mut(given)
        .insert(Position(Vec3::new(0.0, 2.0, 0.0)));
    world
        .entity_mut(given)
        .insert(Transform::from_xyz(0.0, 9.0, 0.0));
    // Through commands, as a game's systems spawn.
    let mut commands = world.commands();
    let id = commands.spawn(Marble).id();
    commands
        .entity(id)
        .insert((Transform::from_xyz(1.0, 0.5, 0.0), Radius(0.02)));
    world.flush();
    app.update();
    let fall = 0.5 * G * (DT * DT) as f32;
    let w = app.world_mut();
    let y = w.get::<Position>(marble).unwrap().0;
    assert!(
        (y - Vec3::new(0.0, 0.5 - fall, 0.0)).length() <= 1e-6,
        "{y}"
    );
    assert_eq!(
        w.get::<Position>(board).unwrap().0,
        Vec3::new(3.0, 0.0, 0.0)
    );
    assert_eq!(w.get::<Rotation>(board).unwrap().0, turn);
    let y2 = w.get::<Position>(given).unwrap().0;
    assert!(
        (y2 - Vec3::new(0.0, 2.0 - fall, 0.0)).length() <= 1e-6,
        "{y2}"
    );
    let p = w.get::<Position>(id).unwrap().0;
    assert!(
        (p - Vec3::new(1.0, 0.5 - fall, 0.0)).length() <= 1e-6,
        "{p}"
    );
}

/// A board given `Sensor` stops holding marbles: the marble resting on it falls through
/// from the next step on, its contact ending, and enters it as a sensor.
#[test]
fn a_board_made_a_sensor_lets_marbles_through() {
    let mut app = recording_app(DT);
    let slab = app
        .world_mut()
        .spawn((
            Board,
            Collider::cuboid(Vec3::new(1.0, 0.1, 1.0)).unwrap(),
            Transform::from_xyz(0.0, -0.1, 0.0),
        ))
        .id();
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 0.1, 0.0)))
        .id();
    for _ in 0..64 {
        app.update();
    }
    let r = app.world().get::<Radius>(marble).unwrap().0;
    let y = app.world().get::<Position>(marble).unwrap().y;
    assert!((y - r).abs() <= 1e-4, "resting at {y}");
    let seen = app.world().resource::<Seen>();
    let (steps, started, ended) = (seen.steps, seen.started.len(), seen.ended.len());
    assert_eq!(started, ended + 1, "resting on it");
    app.world_mut().entity_mut(slab).insert(Sensor);
    app.update();
    // Free fall from rest at y = r: after one step, ½ g dt² lower; its centre passes the
    // slab's top, y = 0, after √(2r/g).
    let y = app.world().get::<Position>(marble).unwrap().y;
    let want = r - 0.5 * G * (DT * DT) as f32;
    assert!((y - want).abs() <= 1e-6, "y = {y}, want {want}");
    for _ in 0..4 {
        app.update();
    }
    let inside = ((2.0 * r / G).sqrt() as f64 / DT).ceil() as u32;
    let seen = app.world().resource::<Seen>();
    assert_eq!(
        seen.entered,
        vec![(
            SensorEntered {
                sensor: slab,
                marble
            },
            steps + inside
        )]
    );
    assert_eq!(seen.started.len(), started);
    assert_eq!(
        seen.ended[ended..],
        [ContactEnded {
            marble,
            other: slab
        }]
    );
}

/// Two teleports by the game's own fixed-step system within one frame of several fixed
/// steps, on an interpolated marble: both are taken, the marble ends where the second
/// put it.
#[test]
fn an_interpolated_marble_takes_every_teleport_of_a_frame() {
    let mut app = app(4.0 * DT);
    app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            TransformInterpolation,
            Transform::from_xyz(0.0, 1.0, 0.0),
        ))
        .id();
    #[derive(Resource, Default)]
    struct Count(u32);
    app.init_resource::<Count>();
    app.add_systems(
        FixedUpdate,
        move |mut count: ResMut<Count>, mut q: Query<&mut Transform>| {
            count.0 += 1;
            let to = match count.0 {
                9 => Vec3::new(5.0, 1.0, 0.0),
                11 => Vec3::new(-7.0, 2.0, 0.0),
                _ => return,
            };
            q.get_mut(marble).unwrap().translation = to;
        },
    );
    for _ in 0..4 {
        app.update();
    }
    assert_eq!(app.world().resource::<Count>().0, 16);
    let w = app.world();
    assert_eq!(
        w.get::<Position>(marble).unwrap().0,
        Vec3::new(-7.0, 2.0, 0.0)
    );
    assert_eq!(
        w.get::<Transform>(marble).unwrap().translation,
        Vec3::new(-7.0, 2.0, 0.0)
    );
}

/// The engine's messages are dropped two updates after they were written, as every Bevy
/// message is: marbles that bounced and came to rest leave none behind (kept, every impact
/// since the start would stay in memory, and a reader added later would read them all).
#[test]
fn messages_are_dropped_after_two_updates() {
    let mut app = recording_app(DT);
    floor(&mut app, 0.5);
    for k in 0..4 {
        app.world_mut()
            .spawn((Marble, Transform::from_xyz(k as f32, 0.1, 0.0)));
    }
    for _ in 0..256 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert!(seen.impacts.len() >= 4, "{} impacts", seen.impacts.len());
    let last = seen.impacts.len();
    for _ in 0..3 {
        app.update();
    }
    assert_eq!(
        app.world().resource::<Seen>().impacts.len(),
        last,
        "at rest"
    );
    let world = app.world();
    assert_eq!(
        world
            .resource::<bevy_ecs::message::Messages<MarbleImpact>>()
            .len(),
        0
    );
    assert_eq!(
        world
            .resource::<bevy_ecs::message::Messages<ContactStarted>>()
            .len(),
        0
    );
}

/// A marble sent back to the start (a labyrinth's reset: an observer of `SensorEntered`
/// on the hole sets its `Position`, or the game sets it between steps) does not cross the
/// sensors between where it was and where it is put: the goal on that line reports
/// nothing, while the hole it falls into reports each entry.
#[test]
fn a_marble_sent_back_crosses_no_sensor_on_the_way() {
    let mut app = recording_app(DT);
    app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
    let cube = || Collider::cuboid(Vec3::splat(0.05)).unwrap();
    let hole = app
        .world_mut()
        .spawn((Sensor, cube(), Transform::from_xyz(1.0, 0.0, 0.0)))
        .id();
    let goal = app
        .world_mut()
        .spawn((Sensor, cube(), Transform::from_xyz(0.5, 0.0, 0.0)))
        .id();
    let start = Vec3::new(0.8, 0.0, 0.0);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            Transform::from_translation(start),
            Velocity(Vec3::new(1.0, 0.0, 0.0)),
        ))
        .id();
    app.world_mut().entity_mut(marble).observe(
        move |_: On<SensorEntered>, mut q: Query<&mut Position>| {
            q.get_mut(marble).unwrap().0 = Vec3::new(0.0, 0.0, 0.0);
        },
    );
    // From 0.8 at 1 m/s: into the hole (x > 0.95) within 10 steps, then from 0 it would
    // reach the goal (x > 0.45) after 29 more.
    for _ in 0..20 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    let entered: Vec<_> = seen.entered.iter().map(|(e, _)| e.sensor).collect();
    assert_eq!(entered, [hole], "{:?}", seen.entered);
    // Between steps, by the program: back to the start, over the goal.
    app.world_mut().get_mut::<Position>(marble).unwrap().0 = start;
    for _ in 0..12 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    let entered: Vec<_> = seen.entered.iter().map(|(e, _)| e.sensor).collect();
    assert_eq!(entered, [hole, hole], "{:?}", seen.entered);
    assert!(
        seen.exited
            .iter()
            .all(|(e, _)| e.sensor == hole && e.marble == marble)
    );
    let _ = goal;
}

/// A game system that places what was just spawned (`Query<&mut Transform, Added<Marble>>`
/// in `PreUpdate`, before the frame's fixed step): the marble starts where that system put
/// it, not where it was spawned.
#[test]
fn a_transform_changed_after_the_spawn_places_the_entity() {
    let mut app = app(DT);
    app.add_systems(
        bevy_app::PreUpdate,
        |mut q: Query<&mut Transform, Added<Marble>>| {
            for mut t in &mut q {
                t.translation.x = 5.0;
            }
        },
    );
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 1.0, 0.0)))
        .id();
    app.update();
    let p = app.world().get::<Position>(marble).unwrap().0;
    let want = Vec3::new(5.0, 1.0 - 0.5 * G * (DT * DT) as f32, 0.0);
    assert!((p - want).length() <= 1e-6, "{p}");
    assert_eq!(app.world().get::<Transform>(marble).unwrap().translation, p);
}

/// A sensor carried by a turning board (a labyrinth's hole, drawn with a mesh) has its
/// pose written back into its `Transform` each step, as a board's is: the board's pose
/// composed with the sensor's in the board's frame.
#[test]
fn a_carried_sensor_shows_where_its_board_carries_it() {
    let mut app = app(DT);
    let board = app
        .world_mut()
        .spawn((
            Board,
            Collider::cuboid(Vec3::new(1.0, 0.05, 1.0)).unwrap(),
            Transform::default(),
            AngularVelocity(Vec3::new(0.5, 0.0, 0.0)),
        ))
        .id();
    let local = Vec3::new(0.3, 0.05, 0.4);
    let hole = app
        .world_mut()
        .spawn((
            Sensor,
            Collider::cuboid(Vec3::splat(0.02)).unwrap(),
            Transform::from_translation(local),
            CarriedBy {
                board,
                position: local,
                rotation: Quat::IDENTITY,
            },
        ))
        .id();
    for _ in 0..16 {
        app.update();
    }
    let w = app.world();
    let turn = w.get::<Rotation>(board).unwrap().0;
    assert!(turn.angle_between(Quat::IDENTITY) > 0.1, "{turn}");
    let want = turn * local;
    let t = w.get::<Transform>(hole).unwrap();
    assert!(
        (t.translation - want).length() <= 1e-6,
        "{} vs {want}",
        t.translation
    );
    assert!(t.rotation.angle_between(turn) <= 1e-6);
    assert_eq!(t.translation, w.get::<Position>(hole).unwrap().0);
}

/// An interpolated marble sent back to the start by an observer of the engine's events
/// (inside the step, as docs/bevy.md advises: by its `Position`) jumps there: no frame
/// shows it between the hole and the start.
#[test]
fn an_interpolated_marble_moved_by_an_observer_jumps() {
    let mut app = app(0.5 * DT);
    app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
    app.world_mut().spawn((
        Sensor,
        Collider::cuboid(Vec3::splat(0.05)).unwrap(),
        Transform::from_xyz(1.0, 0.0, 0.0),
    ));
    let start = Vec3::new(-5.0, 0.0, 0.0);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            TransformInterpolation,
            Transform::from_xyz(0.8, 0.0, 0.0),
            Velocity(Vec3::new(1.0, 0.0, 0.0)),
        ))
        .id();
    app.world_mut().entity_mut(marble).observe(
        move |_: On<SensorEntered>, mut q: Query<&mut Position>| {
            q.get_mut(marble).unwrap().0 = start;
        },
    );
    let mut sent_back = false;
    for _ in 0..60 {
        app.update();
        let shown = app.world().get::<Transform>(marble).unwrap().translation;
        let x = app.world().get::<Position>(marble).unwrap().0.x;
        if x < 0.0 {
            sent_back = true;
            // Within a step's motion (1 m/s) of where it was put, never on the way.
            assert!(shown.x < start.x + 0.5, "shown at {shown}, put at {start}");
        } else {
            assert!(shown.x > 0.7, "shown at {shown}");
        }
    }
    assert!(sent_back);
}

/// An interpolated marble without a `Transform` (a headless game's) still has its last two
/// physics poses kept, and a teleport by its `Position` between steps starts them afresh.
#[test]
fn an_interpolated_marble_without_a_transform_keeps_its_poses() {
    let mut app = app(DT);
    app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            TransformInterpolation,
            Position(Vec3::ZERO),
            Velocity(Vec3::new(1.0, 0.0, 0.0)),
        ))
        .id();
    for _ in 0..3 {
        app.update();
    }
    let to = Vec3::new(-5.0, 0.0, 0.0);
    app.world_mut().get_mut::<Position>(marble).unwrap().0 = to;
    app.update();
    let poses = *app
        .world()
        .get::<bevy_marble::plugin::PhysicsPoses>(marble)
        .unwrap();
    assert_eq!(poses.previous.0, to);
    let dx = (poses.current.0 - to - Vec3::new(DT as f32, 0.0, 0.0)).length();
    assert!(dx <= 1e-6, "{:?}", poses.current);
}

/// A `StepConfig` the game inserts after adding the plugin, built from its default (which
/// records no events), keeps impacts and contacts recorded: the first impact of a drop
/// comes at the free-fall speed `√(2gh)` and starts the contact with the floor.
#[test]
fn a_step_config_inserted_later_keeps_the_events() {
    let mut app = recording_app(DT);
    app.insert_resource(StepConfig {
        integrator: Integrator::VelocityVerlet,
        ..StepConfig::default()
    });
    let (h, r) = (0.2f32, 0.008f32);
    let floor = floor(&mut app, 0.5);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            Restitution(0.5),
            Transform::from_xyz(0.0, h + r, 0.0),
        ))
        .id();
    for _ in 0..64 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    let first = seen.impacts.first().expect("the drop's impact is reported");
    let want = (2.0 * G * h).sqrt();
    assert!(
        ((first.speed - want) / want).abs() <= 1e-4,
        "{} m/s, want {want}",
        first.speed
    );
    assert_eq!((first.marble, first.other), (marble, floor));
    assert_eq!(
        seen.started.first(),
        Some(&ContactStarted {
            marble,
            other: floor
        })
    );
}

/// A force the game adds every fixed step (a wind) is not saved up while the physics is
/// paused: the first step after 32 paused ones gives the velocity of one step's force,
/// `F/m · dt` (no gravity), not of 33.
#[test]
fn a_force_added_while_paused_is_not_saved_up() {
    let mut app = app(DT);
    app.world_mut().resource_mut::<StepConfig>().gravity = Vec3::ZERO;
    let (f, m) = (0.01f32, 0.02f32);
    let marble = app.world_mut().spawn((Marble, Mass::new(m))).id();
    app.add_systems(FixedUpdate, move |mut forces: Query<&mut Force>| {
        for mut force in &mut forces {
            force.0 += Vec3::X * f;
        }
    });
    app.world_mut().resource_mut::<PhysicsClock>().paused = true;
    for _ in 0..32 {
        app.update();
    }
    assert_eq!(app.world().get::<Velocity>(marble).unwrap().0, Vec3::ZERO);
    app.world_mut().resource_mut::<PhysicsClock>().paused = false;
    app.update();
    let v = app.world().get::<Velocity>(marble).unwrap().0;
    let want = f / m * DT as f32;
    assert!(((v.x - want) / want).abs() <= 1e-6, "v = {v}, want {want}");
}

/// A board that an observer of its first impact despawns (breaking glass) starts no
/// contact: the impact is reported, then no `ContactStarted` or `ContactEnded` names the
/// gone board, and the marble falls on.
#[test]
fn a_board_despawned_by_an_impact_observer_starts_no_contact() {
    let mut app = recording_app(DT);
    let glass = floor(&mut app, 0.5);
    app.world_mut().spawn((
        Board,
        Collider::plane(),
        Position(Vec3::new(0.0, -1.0, 0.0)),
    ));
    let marble = app
        .world_mut()
        .spawn((Marble, Transform::from_xyz(0.0, 0.1, 0.0)))
        .id();
    app.add_observer(move |impact: On<MarbleImpact>, mut commands: Commands| {
        if impact.other == glass {
            commands.entity(glass).despawn();
        }
    });
    for _ in 0..32 {
        app.update();
    }
    let seen = app.world().resource::<Seen>();
    assert_eq!(seen.impacts.first().map(|i| i.other), Some(glass));
    assert!(
        seen.started.iter().all(|c| c.other != glass),
        "{:?}",
        seen.started
    );
    assert!(
        seen.ended.iter().all(|c| c.other != glass),
        "{:?}",
        seen.ended
    );
    assert!(app.world().get_entity(glass).is_err());
    assert!(app.world().get::<Position>(marble).unwrap().y < 0.0);
}

/// A game that spins an interpolated marble's mesh (its `Transform`'s rotation, every
/// frame; the marble carries no `Rotation`) moves nothing: the marble flies its free path
/// (Verlet: exact), and its `Transform` stays eased between its last two physics poses.
#[test]
fn spinning_an_interpolated_marbles_mesh_moves_nothing() {
    let mut app = app(1.0 / 144.0);
    let v = Vec3::new(1.0, 2.0, 0.0);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            TransformInterpolation,
            Transform::from_xyz(0.0, 10.0, 0.0),
            Velocity(v),
        ))
        .id();
    app.add_systems(Update, |mut q: Query<&mut Transform, With<Marble>>| {
        for mut transform in &mut q {
            transform.rotate_y(0.1);
        }
    });
    for _ in 0..100 {
        app.update();
    }
    let steps = app.world().resource::<Time<Fixed>>().elapsed_secs_f64() / DT;
    let t = (steps.round() * DT) as f32;
    let want = Vec3::new(0.0, 10.0, 0.0) + v * t - 0.5 * G * t * t * Vec3::Y;
    let at = app.world().get::<Position>(marble).unwrap().0;
    assert!((at - want).length() <= 1e-4, "at {at}, want {want}");
    // Eased: within the last step's move behind the physics pose.
    let shown = app.world().get::<Transform>(marble).unwrap().translation;
    let speed = app.world().get::<Velocity>(marble).unwrap().0.length() + G * DT as f32;
    assert!(
        (shown - at).length() <= speed * DT as f32,
        "shown at {shown}, at {at}"
    );
}

/// With sleeping on, a marble asleep on the floor that the game lifts into the air ends
/// its contact with the floor, and starts it again when it lands (inelastic: once).
#[test]
fn a_sleeping_marble_lifted_off_the_floor_ends_and_restarts_its_contact() {
    let mut app = recording_app(DT);
    app.world_mut().resource_mut::<StepConfig>().sleep = Some(Sleep {
        speed: 0.01,
        time: 0.2,
    });
    let floor = floor(&mut app, 0.0);
    let r = 0.008;
    let marble = app
        .world_mut()
        .spawn((Marble, Restitution(0.0), Transform::from_xyz(0.0, r, 0.0)))
        .id();
    for _ in 0..64 {
        app.update();
    }
    assert!(app.world().get::<Sleeping>(marble).is_some(), "asleep");
    let contact = ContactStarted {
        marble,
        other: floor,
    };
    assert_eq!(app.world().resource::<Seen>().started, vec![contact]);
    app.world_mut().get_mut::<Position>(marble).unwrap().0 = Vec3::new(0.0, 0.5, 0.0);
    for _ in 0..4 {
        app.update();
    }
    let ended = ContactEnded {
        marble,
        other: floor,
    };
    assert_eq!(app.world().resource::<Seen>().ended, vec![ended], "lifted");
    for _ in 0..64 {
        app.update();
    }
    assert_eq!(
        app.world().resource::<Seen>().started,
        vec![contact, contact],
        "landed"
    );
}

/// A marble woken by hand (its `Sleeping` removed by the game) stays awake for the sleep
/// time before it can fall asleep again, also when the frames after the removal run no
/// fixed step (four frames a step: removals older than two frames are gone from bevy's
/// removal buffers by the next step).
#[test]
fn a_marble_woken_by_hand_stays_awake_for_the_sleep_time() {
    let mut app = app(DT / 4.0);
    let time = 0.25;
    app.world_mut().resource_mut::<StepConfig>().sleep = Some(Sleep { speed: 0.01, time });
    floor(&mut app, 0.0);
    let marble = app
        .world_mut()
        .spawn((
            Marble,
            Restitution(0.0),
            Transform::from_xyz(0.0, 0.008, 0.0),
        ))
        .id();
    for _ in 0..256 {
        app.update();
    }
    assert!(app.world().get::<Sleeping>(marble).is_some(), "asleep");
    // Woken right after a fixed step, so that the next one comes three frames later.
    let steps = |app: &App| app.world().resource::<Time<Fixed>>().elapsed_secs_f64();
    let before = steps(&app);
    while steps(&app) == before {
        app.update();
    }
    app.world_mut().entity_mut(marble).remove::<Sleeping>();
    let woken = steps(&app);
    while app.world().get::<Sleeping>(marble).is_none() {
        app.update();
    }
    let awake = steps(&app) - woken;
    assert!(awake >= time as f64, "asleep again after {awake} s");
}

/// A marble sent back by an observer of its impact (lava), during the step, crosses no
/// sensor on the way back, in the last substep or an earlier one: the goal between the
/// lava and the start reports nothing.
#[test]
fn a_marble_sent_back_by_an_impact_observer_crosses_no_sensor() {
    for substeps in [1, 3] {
        let mut app = recording_app(DT);
        {
            let mut config = app.world_mut().resource_mut::<StepConfig>();
            config.gravity = Vec3::ZERO;
            config.substeps = substeps;
        }
        let lava = app
            .world_mut()
            .spawn((
                Board,
                Collider::cuboid(Vec3::new(0.05, 1.0, 1.0)).unwrap(),
                Transform::from_xyz(1.0, 0.0, 0.0),
            ))
            .id();
        app.world_mut().spawn((
            Sensor,
            Collider::cuboid(Vec3::splat(0.05)).unwrap(),
            Transform::from_xyz(0.5, 0.0, 0.0),
        ));
        let marble = app
            .world_mut()
            .spawn((
                Marble,
                Transform::from_xyz(0.8, 0.0, 0.0),
                Velocity(Vec3::new(2.0, 0.0, 0.0)),
            ))
            .id();
        app.add_observer(
            move |hit: On<MarbleImpact>, mut q: Query<(&mut Position, &mut Velocity)>| {
                if hit.other == lava {
                    let (mut x, mut v) = q.get_mut(hit.marble).unwrap();
                    (x.0, v.0) = (Vec3::ZERO, Vec3::ZERO);
                }
            },
        );
        for _ in 0..16 {
            app.update();
        }
        let seen = app.world().resource::<Seen>();
        assert!(
            !seen.impacts.is_empty(),
            "{substeps} substeps: the lava is hit"
        );
        // (At the start, to the ulp of its old position that its carry may hold.)
        let at = app.world().get::<Position>(marble).unwrap().0;
        assert!(at.length() <= 1e-6, "{substeps} substeps: at {at}");
        assert!(
            seen.entered.is_empty() && seen.exited.is_empty(),
            "{substeps} substeps: {:?} {:?}",
            seen.entered,
            seen.exited
        );
    }
}
