//! The labyrinth's rules, headless: an `App` without a window, input written as a player
//! would, the level from the scene file the game loads.

use std::process::Command;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_marble::plugin::{MarblePluginSystems, PhysicsPoses};
use bevy_marble::prelude::*;
use marble_labyrinth::*;

/// One `update` is one physics step of the level's dt.
fn app(level: Scene) -> App {
    let dt = level.dt as f64;
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, LabyrinthPlugin { level }))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            dt,
        )));
    app.update(); // Startup: the level is spawned (time starts here)
    app
}

fn classic() -> Scene {
    Scene::from_ron_str(CLASSIC).unwrap()
}

fn steps(app: &App) -> u64 {
    app.world().resource::<TiltLog>().steps
}

/// Runs until `done` or `limit` physics steps, with `input(step)`; the step it ended at.
fn run_until(
    app: &mut App,
    limit: u64,
    input: impl Fn(u64) -> Vec2,
    done: impl Fn(&App) -> bool,
) -> Option<u64> {
    while steps(app) < limit {
        let next = steps(app) + 1;
        app.world_mut().resource_mut::<TiltInput>().0 = input(next);
        app.update();
        if done(app) {
            return Some(steps(app));
        }
    }
    None
}

/// The classic level after its marble was tilted into the first row's hole.
fn app_after_a_loss() -> App {
    let mut app = app(classic());
    run_until(
        &mut app,
        600,
        |_| Vec2::new(1.0, 0.0),
        |a| a.world().resource::<Score>().lost > 0,
    )
    .expect("lost");
    app
}

fn marble(app: &mut App) -> (Vec3, Vec3) {
    let mut q = app
        .world_mut()
        .query_filtered::<(&Position, &Velocity), With<PlayerMarble>>();
    let (p, v) = q.single(app.world()).unwrap();
    (p.0, v.0)
}

#[test]
fn every_update_is_one_physics_step() {
    let mut app = app(classic());
    let before = steps(&app);
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(steps(&app) - before, 10);
}

#[test]
fn tilting_towards_the_goal_brings_the_marble_home_in_the_rolling_time() {
    // An open board (the classic level's outer walls and floor without its holes or
    // inner walls) with the goal in the far corner: tilted fully towards it, the marble
    // rolls down the diagonal with a = 5/7 g sin 20° less rolling resistance, from rest,
    // and enters the goal's volume when it has come 0.43 √2 m (its centre then inside
    // the goal's 4 cm square). The tilt eases in with a time constant τ, which delays
    // the path by about τ.
    let mut level = classic();
    level.sensors.retain(|s| s.name == "goal");
    let ShapeDesc::Compound(parts) = &mut level.boards[0].shape else {
        panic!()
    };
    parts.retain(|p| p.position[1] == 0.015); // the outer walls
    let full_rows: Vec<_> = (0..10)
        .map(|j| bevy_marble::scene::PartDesc {
            shape: ShapeDesc::Cuboid {
                half_extents: [0.25, 0.005, 0.025],
            },
            position: [0.0, -0.005, -0.225 + 0.05 * j as f32],
            rotation: [0.0, 0.0, 0.0, 1.0],
        })
        .collect();
    parts.extend(full_rows);
    let mut app = app(level);
    let home = run_until(
        &mut app,
        1000,
        |_| Vec2::new(1.0, -1.0),
        |a| a.world().resource::<Score>().home > 0,
    )
    .expect("the marble gets home within 5 s");
    let t = home as f32 * 0.005;
    let (g, c) = (9.81f32, 0.002f32);
    let a = 5.0 / 7.0 * g * (MAX_TILT.sin() - c * MAX_TILT.cos());
    let d = 0.43 * std::f32::consts::SQRT_2;
    let rolling = (2.0 * d / a).sqrt();
    // No faster than at full tilt from the start; no later than that plus the whole
    // ramp to full tilt (at the rate limit), the easing's time constant and one step.
    let ramp = MAX_TILT / MAX_TILT_RATE;
    assert!(
        t >= rolling && t <= rolling + ramp + EASE_SECONDS + 0.005,
        "home after {t} s; rolling alone takes {rolling} s"
    );
    assert_eq!(app.world().resource::<Score>().lost, 0);
}

#[test]
fn a_marble_tilted_into_a_hole_is_lost_and_starts_again() {
    // Tilted to the right, the marble rolls along the first row into the hole at its
    // seventh cell.
    let mut app = app(classic());
    let m = app
        .world_mut()
        .query_filtered::<Entity, With<PlayerMarble>>()
        .single(app.world())
        .unwrap();
    app.world_mut().entity_mut(m).insert(TransformInterpolation);
    let lost = run_until(
        &mut app,
        600,
        |_| Vec2::new(1.0, 0.0),
        |a| a.world().resource::<Score>().lost > 0,
    )
    .expect("lost within 3 s");
    let level = app.world().resource::<Level>().clone();
    let board = app.world().get::<Rotation>(level.board).unwrap().0;
    let board_p = app.world().get::<Position>(level.board).unwrap().0;
    let (p, v) = marble(&mut app);
    // Back at the start, at rest, in the board's frame as it is.
    assert!(
        (p - (board_p + board * level.start)).length() < 1e-6,
        "at {p}"
    );
    assert_eq!(v, Vec3::ZERO);
    let score = *app.world().resource::<Score>();
    assert_eq!((score.home, score.lost), (0, 1));
    assert_eq!(score.time, 0.0, "the clock starts again");
    // It went in at the hole: rolling 0.275 m at full tilt from rest to the hole's near
    // edge takes √(2 · 0.275 / a) = 0.48 s, then its centre drops 2.8 cm into the
    // sensor (0.08 s free fall); the ramp to full tilt (0.17 s at most) and the bounce
    // off the hole's far edge come on top.
    let t = lost as f32 * 0.005;
    assert!((0.55..1.0).contains(&t), "lost after {t} s");
    // Rendered, it jumps to the start: the next step eases from the start, not from the
    // hole (no streak across the board).
    let start = p;
    run_until(&mut app, lost + 1, |_| Vec2::ZERO, |_| false);
    let poses = *app.world().get::<PhysicsPoses>(m).unwrap();
    assert_eq!(poses.previous.0, start, "eased from {}", poses.previous.0);
    assert!((poses.current.0 - start).length() < 1e-3);
    // Once: the next steps count nothing more while it sits at the start, level.
    run_until(&mut app, lost + 100, |_| Vec2::ZERO, |_| false);
    assert_eq!(app.world().resource::<Score>().lost, 1);
}

#[test]
fn the_tilt_eases_exactly_and_never_exceeds_its_clamp() {
    let mut app = app(classic());
    // A constant small input from level (a fifth of the way: slower than the rate limit
    // from the start): |tilt| after n steps is 0.2 MAX (1 − e^(−n h / τ)).
    let h = 0.005f32;
    for n in 1..=40u64 {
        app.world_mut().resource_mut::<TiltInput>().0 = Vec2::new(0.0, 0.2);
        app.update();
        let tilt = app.world().resource::<Tilt>().0.length();
        let want = 0.2 * MAX_TILT * (1.0 - (-(n as f32) * h / EASE_SECONDS).exp());
        assert!(
            (tilt - want).abs() < 1e-5,
            "step {n}: {tilt} rad, want {want}"
        );
    }
    // A full swing from one side to the other is limited in rate: it takes 2 MAX / rate.
    let mut last = app.world().resource::<Tilt>().0;
    let mut swing = 0;
    for _ in 0..200 {
        app.world_mut().resource_mut::<TiltInput>().0 = Vec2::new(0.0, -1.0);
        app.update();
        let tilt = app.world().resource::<Tilt>().0;
        assert!(
            (tilt - last).length() <= MAX_TILT_RATE * h * (1.0 + 1e-5),
            "{} rad in a step",
            (tilt - last).length()
        );
        if (tilt - last).length() >= MAX_TILT_RATE * h * (1.0 - 1e-5) {
            swing += 1;
        }
        last = tilt;
    }
    // From +0.2 MAX (near enough) to −MAX at the full rate, then the easing's tail.
    let full_rate = ((1.2 * MAX_TILT) / (MAX_TILT_RATE * h)) as i32;
    assert!(
        (swing - full_rate).abs() <= 12,
        "{swing} steps at the full rate, about {full_rate} expected"
    );
    assert!((last.y + MAX_TILT).abs() < 1e-4, "ends at {last}");
    // Any input, however wild: the board's normal stays within 20° of the vertical.
    let inputs = [
        Vec2::new(5.0, -7.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(-1.0, 1.0),
        Vec2::new(f32::NAN, 0.3),
        Vec2::new(f32::INFINITY, 0.0),
        Vec2::new(-0.7, -0.7),
    ];
    let board = app.world().resource::<Level>().board;
    for k in 0..600usize {
        app.world_mut().resource_mut::<TiltInput>().0 = inputs[(k / 50) % inputs.len()];
        app.update();
        let tilt = app.world().resource::<Tilt>().0;
        assert!(
            tilt.is_finite() && tilt.length() <= MAX_TILT * (1.0 + 1e-6),
            "{tilt}"
        );
        let q = app.world().get::<Rotation>(board).unwrap().0;
        let normal = q * Vec3::Y;
        let angle = normal.dot(Vec3::Y).clamp(-1.0, 1.0).acos();
        assert!(
            angle <= MAX_TILT + 1e-4,
            "step {k}: the board at {} degrees",
            angle.to_degrees()
        );
    }
}

/// The `marble` binary of the engine (`MARBLE_BIN`, or built here).
fn marble_bin() -> std::path::PathBuf {
    if let Some(p) = std::env::var_os("MARBLE_BIN") {
        return p.into();
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "--bin", "marble", "--manifest-path"])
        .arg(root.join("Cargo.toml"))
        .status()
        .unwrap();
    assert!(status.success(), "building marble");
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or(root.join("target"), Into::into);
    target.join("debug/marble")
}

#[test]
fn the_level_through_marble_run_follows_the_game_bit_for_bit() {
    // The game, recording the board's poses and the marble's position after each step,
    // until the marble is lost (it then starts again, which `marble run` does not do).
    let mut app = app(classic());
    app.world_mut().resource_mut::<TiltLog>().enabled = true;
    #[derive(Resource, Default)]
    struct Path(Vec<Vec3>);
    app.init_resource::<Path>();
    app.add_systems(
        FixedPostUpdate,
        (|marbles: Query<&Position, With<PlayerMarble>>, mut path: ResMut<Path>| {
            path.0.push(marbles.single().unwrap().0);
        })
        .after(MarblePluginSystems::Step)
        .before(LabyrinthSystems::Judge),
    );
    // Right along the first row, then down into the second and back left: rolling,
    // walls and a turn.
    let input = |s: u64| match s {
        0..=60 => Vec2::new(0.8, 0.0),
        61..=140 => Vec2::new(-0.2, -0.6),
        _ => Vec2::new(-0.9, 0.1),
    };
    let end = run_until(&mut app, 500, input, |a| {
        a.world().resource::<Score>().lost > 0
    })
    .unwrap_or(500);
    let log = app.world().resource::<TiltLog>().clone();
    let path = app.world().resource::<Path>().0.clone();
    assert_eq!(log.rows.len() as u64, end);
    assert_eq!(path.len() as u64, end);

    let dir = std::env::temp_dir().join(format!("labyrinth_replay_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (level, poses, csv) = (
        dir.join("classic.ron"),
        dir.join("poses.csv"),
        dir.join("run.csv"),
    );
    std::fs::write(&level, CLASSIC).unwrap();
    let mut text = Vec::new();
    use std::io::Write;
    writeln!(text, "{}", bevy_marble::output::POSES_HEADER).unwrap();
    for row in &log.rows {
        bevy_marble::output::write_pose_row(&mut text, row).unwrap();
    }
    std::fs::write(&poses, text).unwrap();
    let out = Command::new(marble_bin())
        .arg("run")
        .arg(&level)
        .args(["--quiet", "--steps", &end.to_string(), "--poses"])
        .arg(&poses)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(&csv).unwrap();
    let mut compared = 0;
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let step: usize = f[0].parse().unwrap();
        if step == 0 {
            continue;
        }
        let p = Vec3::new(
            f[3].parse().unwrap(),
            f[4].parse().unwrap(),
            f[5].parse().unwrap(),
        );
        let game = path[step - 1];
        assert_eq!(
            p.to_array().map(f32::to_bits),
            game.to_array().map(f32::to_bits),
            "step {step}: marble run {p}, the game {game}"
        );
        compared += 1;
    }
    assert_eq!(compared, end);
    // The path went somewhere: not a marble sitting still.
    assert!((path[path.len() - 1] - path[0]).length() > 0.1);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_many_marbles_mode_places_them_on_free_floor_and_keeps_them_on_the_board() {
    // 300 marbles in one layer: none in a hole or a wall at the start, and after 2 s on a
    // level board (no input) none has been lost: they were placed at rest on floor.
    let level = classic();
    let r = level.marbles[0].radius;
    let spots = free_floor(&level, r);
    assert!(spots.len() >= MANY, "{} places", spots.len());
    for (i, a) in spots.iter().enumerate() {
        for b in &spots[i + 1..] {
            assert!((*a - *b).length() >= 2.0 * r, "{a} and {b} overlap");
        }
    }
    let mut app = app(level);
    app.world_mut().write_message(SetMarbles(MANY));
    run_until(&mut app, 400, |_| Vec2::ZERO, |_| false);
    let count = app
        .world_mut()
        .query_filtered::<(), With<PlayerMarble>>()
        .iter(app.world())
        .count();
    assert_eq!(count, MANY);
    assert!(app.world().resource::<StepConfig>().marble_collisions);
    let score = *app.world().resource::<Score>();
    assert_eq!((score.home, score.lost), (0, 0), "none lost, none home");
}

#[test]
fn a_restart_brings_the_marble_back_and_clears_the_score() {
    // A restart with one marble, after a loss and while it rolls again: it is back at the
    // start (within a step's roll), and the score is clear.
    let mut app_one = app_after_a_loss();
    let now = steps(&app_one);
    run_until(&mut app_one, now + 40, |_| Vec2::new(1.0, 0.0), |_| false);
    let level = app_one.world().resource::<Level>().clone();
    let (away, _) = marble(&mut app_one);
    let board_p = app_one.world().get::<Position>(level.board).unwrap().0;
    let board_q = app_one.world().get::<Rotation>(level.board).unwrap().0;
    assert!(
        (away - (board_p + board_q * level.start)).length() > 0.02,
        "it rolled off"
    );
    app_one.world_mut().write_message(SetMarbles(1));
    app_one.update();
    let board_p = app_one.world().get::<Position>(level.board).unwrap().0;
    let board_q = app_one.world().get::<Rotation>(level.board).unwrap().0;
    let (p, _) = marble(&mut app_one);
    assert!(
        (p - (board_p + board_q * level.start)).length() < 0.01,
        "at {p}"
    );
    assert_eq!(app_one.world().resource::<Score>().lost, 0);
}
