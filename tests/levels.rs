//! Level files: sensors in scene files (fixed, or carried by a board), and board poses
//! driven from a file (`marble run --poses`), the way a game's tilts are replayed.

use std::process::Command;

use bevy_marble::output::{POSES_HEADER, PoseRow, parse_poses, write_pose_row};
use bevy_marble::prelude::*;
use bevy_marble::scene::SensorDesc;
use glam::{Quat, Vec3};

fn temp(name: &str) -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("bevy_marble_levels_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A board turning about Y at `omega` through the origin, carrying a 2 cm sensor cube 0.3 m
/// out along +x; a marble held still in the air (no gravity) on the sensor's circle, a
/// quarter turn ahead.
fn sweeping(omega: f32) -> Scene {
    let mut board = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.5, 0.01, 0.5],
    });
    board.position = [0.0, -0.5, 0.0];
    board.angular_velocity = [0.0, omega, 0.0];
    let mut scene = Scene {
        gravity: [0.0; 3],
        dt: 1.0 / 240.0,
        boards: vec![board],
        ..Scene::default()
    };
    // A quarter turn about +Y takes +x to −z.
    scene.marbles.push(MarbleDesc::at([0.0, 0.0, -0.3]));
    scene.sensors.push(SensorDesc {
        name: "gate".into(),
        shape: ShapeDesc::Cuboid {
            half_extents: [0.01, 0.01, 0.01],
        },
        board: Some(0),
        position: [0.3, 0.5, 0.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
    });
    scene
}

#[test]
fn a_sensor_carried_by_a_turning_board_sweeps_over_a_marble_at_its_time() {
    let omega = 1.0f32;
    let scene = sweeping(omega);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let (sensor, marble) = (sim.sensors()[0], sim.marbles()[0]);
    assert_eq!(
        sim.world()
            .get::<bevy_ecs::name::Name>(sensor)
            .unwrap()
            .as_str(),
        "gate"
    );
    // The marble's centre enters the cube when the cube's near face (0.01 m ahead of its
    // centre, at 0.3 m out: half-angle atan(0.01 / 0.3)) reaches it: at
    // (π/2 − atan(0.01/0.3)) / ω, and leaves at (π/2 + atan(0.01/0.3)) / ω (the cube's
    // corners aside, which the marble at its centre line never meets).
    let half = (0.01f32 / 0.3).atan();
    let enter = (std::f32::consts::FRAC_PI_2 - half) / omega;
    let exit = (std::f32::consts::FRAC_PI_2 + half) / omega;
    let (mut entered, mut exited) = (None, None);
    for step in 1..=600u32 {
        sim.step();
        let world = sim.world();
        let t = step as f32 * scene.dt;
        for m in world
            .resource::<bevy_ecs::message::Messages<SensorEntered>>()
            .iter_current_update_messages()
        {
            assert_eq!((m.sensor, m.marble), (sensor, marble));
            entered.get_or_insert(t);
        }
        for m in world
            .resource::<bevy_ecs::message::Messages<SensorExited>>()
            .iter_current_update_messages()
        {
            assert_eq!((m.sensor, m.marble), (sensor, marble));
            exited.get_or_insert(t);
        }
        // Where it is: the board's pose composed with its own.
        let (p, q) = (
            world.get::<Position>(sim.boards()[0]).unwrap().0,
            world.get::<Rotation>(sim.boards()[0]).unwrap().0,
        );
        let at = world.get::<Position>(sensor).unwrap().0;
        assert!((at - (p + q * Vec3::new(0.3, 0.5, 0.0))).length() < 1e-6);
    }
    // Sensors are checked at step ends: each event is in the step that holds its time.
    let (entered, exited) = (entered.expect("entered"), exited.expect("left"));
    assert!(
        entered >= enter && entered < enter + scene.dt + 1e-5,
        "entered at {entered} s, want {enter}"
    );
    assert!(
        exited >= exit && exited < exit + scene.dt + 1e-5,
        "left at {exited} s, want {exit}"
    );
}

#[test]
fn sensors_are_checked_and_named_in_the_cli() {
    let dir = temp("cli");
    let mut scene = sweeping(1.0);
    let path = dir.join("ok.ron");
    std::fs::write(&path, scene.to_ron_string()).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_marble"))
            .args(args)
            .output()
            .unwrap()
    };
    let out = run(&["check", path.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("1 sensors"));
    let out = run(&["run", path.to_str().unwrap(), "--steps", "480"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("sensors entered  gate (1) 1"), "{text}");
    // A sensor on a board that is not there.
    scene.sensors[0].board = Some(3);
    let path = dir.join("bad.ron");
    std::fs::write(&path, scene.to_ron_string()).unwrap();
    let out = run(&["check", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("sensors[0].board") && err.contains("got 3"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A marble resting on a level board that the poses tilt about X by up to 0.2 rad.
fn tilting() -> (Scene, Vec<PoseRow>) {
    let mut scene = Scene {
        dt: 0.005,
        integrator: Integrator::VelocityVerlet,
        rolling: true,
        ..Scene::default()
    };
    scene.boards.push(BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.5, 0.01, 0.5],
    }));
    scene.marbles.push(MarbleDesc::at([0.05, 0.018, 0.0]));
    let rows = (1..=200u64)
        .map(|step| PoseRow {
            step,
            board: 0,
            position: Vec3::ZERO,
            rotation: Quat::from_rotation_x(0.2 * (step as f32 / 200.0)),
        })
        .collect();
    (scene, rows)
}

#[test]
fn poses_from_a_file_drive_the_board_as_next_pose_does_bit_for_bit() {
    let (scene, rows) = tilting();
    // In-process: NextPose before each step.
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut path = Vec::new();
    for row in &rows {
        let board = sim.boards()[0];
        sim.world_mut().entity_mut(board).insert(NextPose {
            position: row.position,
            rotation: row.rotation,
        });
        sim.step();
        // The board is at the pose at the step's end (its rotation normalized).
        let q = sim.world().get::<Rotation>(board).unwrap().0;
        assert!(
            q.angle_between(row.rotation) < 1e-5,
            "{q} against {}",
            row.rotation
        );
        path.push(sim.marble_world_state(0).0);
    }
    assert!((path[199] - path[0]).length() > 0.01, "the marble rolled");
    // Through the CLI.
    let dir = temp("poses");
    let (level, poses, csv) = (
        dir.join("tilt.ron"),
        dir.join("poses.csv"),
        dir.join("run.csv"),
    );
    std::fs::write(&level, scene.to_ron_string()).unwrap();
    let mut text = format!("{POSES_HEADER}\n").into_bytes();
    for row in &rows {
        write_pose_row(&mut text, row).unwrap();
    }
    std::fs::write(&poses, &text).unwrap();
    assert_eq!(
        parse_poses(std::str::from_utf8(&text).unwrap(), 1).unwrap(),
        rows
    );
    let out = Command::new(env!("CARGO_BIN_EXE_marble"))
        .arg("run")
        .arg(&level)
        .args(["--quiet", "--steps", "200", "--poses"])
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
    for line in std::fs::read_to_string(&csv).unwrap().lines().skip(2) {
        let f: Vec<f32> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let p = Vec3::new(f[3], f[4], f[5]);
        assert_eq!(p, path[f[0] as usize - 1], "step {}", f[0]);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_bad_poses_file_is_refused_with_its_line_and_field() {
    let ok = format!("{POSES_HEADER}\n1,0,0,0,0,0,0,0,1\n");
    assert_eq!(parse_poses(&ok, 1).unwrap().len(), 1);
    for (text, want) in [
        ("step,board\n".to_owned(), "line 1: the header must be"),
        (
            format!("{POSES_HEADER}\n0,0,0,0,0,0,0,0,1\n"),
            "line 2: step must be a whole number >= 1",
        ),
        (
            format!("{POSES_HEADER}\n1,1,0,0,0,0,0,0,1\n"),
            "line 2: board must be the index of one of the 1 boards",
        ),
        (
            format!("{POSES_HEADER}\n1,0,NaN,0,0,0,0,0,1\n"),
            "line 2: x must be a finite number",
        ),
        (
            format!("{POSES_HEADER}\n1,0,0,0,2e6,0,0,0,1\n"),
            "line 2: z must be within",
        ),
        (
            format!("{POSES_HEADER}\n1,0,0,0,0,0,0,0,1.01\n"),
            "must be a unit quaternion",
        ),
        (
            format!("{POSES_HEADER}\n1,0,0,0,0,0,0,0\n"),
            "line 2: 9 fields",
        ),
        (
            format!("{POSES_HEADER}\n2,0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0,0,1\n"),
            "line 3: rows must be in order",
        ),
    ] {
        let err = parse_poses(&text, 1).unwrap_err();
        assert!(
            err.starts_with(want) || err.contains(want),
            "{err:?}, want {want:?}"
        );
    }
    // At the CLI: status 2, one error line naming the file, nothing written.
    let dir = temp("badposes");
    let (level, poses, csv) = (
        dir.join("tilt.ron"),
        dir.join("poses.csv"),
        dir.join("run.csv"),
    );
    std::fs::write(&level, tilting().0.to_ron_string()).unwrap();
    std::fs::write(&poses, format!("{POSES_HEADER}\n1,0,0,0,0,0,0,0,2\n")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_marble"))
        .arg("run")
        .arg(&level)
        .arg("--poses")
        .arg(&poses)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.starts_with("error: ") && err.contains("poses.csv: line 2"),
        "{err}"
    );
    assert!(!csv.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
