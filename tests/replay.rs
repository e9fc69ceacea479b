//! The replay page and the run's records: the page is self-contained, holds every recorded
//! frame, and its numbers are the CSV's; energy, impacts and penetration against exact
//! answers.

mod common;

use std::collections::HashMap;
use std::process::Command;

use bevy_marble::prelude::*;
use bevy_marble::replay::{Recorder, Recording, ReplayOptions, frame_stride};
use bevy_marble::scenes;
use glam::Vec3;

/// The JSON the page carries.
fn page_data(page: &str) -> serde_json::Value {
    let open = r#"<script id="replay-data" type="application/json">"#;
    let start = page.find(open).expect("the data element") + open.len();
    let end = start + page[start..].find("</script>").expect("its end");
    serde_json::from_str(&page[start..end]).expect("the data is JSON")
}

/// Standard base64, decoded independently of the engine's encoder.
fn unbase64(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let mut out = Vec::new();
    for chunk in text.as_bytes().chunks(4) {
        let pad = chunk.iter().filter(|&&c| c == b'=').count();
        let mut n = 0u32;
        for &c in chunk {
            n = n << 6 | if c == b'=' { 0 } else { value(c) as u32 };
        }
        out.extend_from_slice(&n.to_be_bytes()[1..4 - pad]);
    }
    out
}

fn f32s(value: &serde_json::Value) -> Vec<f32> {
    unbase64(value.as_str().expect("a base64 string"))
        .chunks(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// A small scene for the CLI: five marbles on a walled board with one baffle, rolling and
/// colliding, 0.6 s.
fn small_scene() -> Scene {
    let mut scene = scenes::labyrinth(5);
    scene.duration = 0.6;
    scene
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("bevy_marble_replay_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `marble run` on [`small_scene`], written into `dir`, with `args` after the scene.
fn run_small(dir: &std::path::Path, args: &[&std::ffi::OsStr]) -> std::process::Output {
    let scene_path = dir.join("small.ron");
    std::fs::write(&scene_path, small_scene().to_ron_string()).unwrap();
    Command::new(env!("CARGO_BIN_EXE_marble"))
        .arg("run")
        .arg(&scene_path)
        .args(args)
        .output()
        .unwrap()
}

/// `step → marble → [x, y, z, vx, vy, vz]` from the contract's CSV.
fn csv_states(csv: &str) -> HashMap<u64, Vec<[f32; 6]>> {
    let mut out: HashMap<u64, Vec<[f32; 6]>> = HashMap::new();
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let step: u64 = f[0].parse().unwrap();
        let marble: usize = f[2].parse().unwrap();
        let row = out.entry(step).or_default();
        assert_eq!(row.len(), marble, "marbles in order");
        row.push(std::array::from_fn(|k| f[3 + k].parse::<f32>().unwrap()));
    }
    out
}

#[test]
fn the_page_is_self_contained_and_holds_every_frame_with_the_csv_values() {
    let dir = temp_dir("cli");
    let (html, csv, svg) = (
        dir.join("run.html"),
        dir.join("run.csv"),
        dir.join("run.svg"),
    );
    let out = run_small(
        &dir,
        &[
            "--every".as_ref(),
            "1".as_ref(),
            "--quiet".as_ref(),
            "--csv".as_ref(),
            csv.as_os_str(),
            "--html".as_ref(),
            html.as_os_str(),
            "--plot".as_ref(),
            svg.as_os_str(),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.is_empty(), "--quiet prints nothing");
    let page = std::fs::read_to_string(&html).unwrap();

    // Self-contained: nothing fetched from anywhere.
    for outside in ["http://", "https://", "<link", "src=", "@import", "url("] {
        assert!(
            !page.contains(outside),
            "the page refers outside: {outside}"
        );
    }

    let data = page_data(&page);
    let states = csv_states(&std::fs::read_to_string(&csv).unwrap());
    let steps: Vec<u64> = data["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_u64().unwrap())
        .collect();
    let scene = small_scene();
    let total = scene.default_steps();
    let n = scene.marbles.len();
    // Every recorded frame: the first, every stride-th, the last.
    let stride = frame_stride(total, n, scene.dt as f64, &ReplayOptions::default());
    let mut want: Vec<u64> = (0..=total).step_by(stride as usize).collect();
    if *want.last().unwrap() != total {
        want.push(total);
    }
    assert_eq!(steps, want);
    let (pos, vel) = (f32s(&data["positions"]), f32s(&data["velocities"]));
    assert_eq!(pos.len(), steps.len() * n * 3);
    assert_eq!(vel.len(), pos.len());
    // The page's numbers are the CSV's, to the bit.
    for (f, step) in steps.iter().enumerate() {
        for (i, row) in states[step].iter().enumerate() {
            let k = 3 * (f * n + i);
            let page_row = [
                pos[k],
                pos[k + 1],
                pos[k + 2],
                vel[k],
                vel[k + 1],
                vel[k + 2],
            ];
            assert_eq!(
                page_row.map(f32::to_bits),
                row.map(f32::to_bits),
                "frame {f} (step {step}) marble {i}"
            );
        }
    }
    let times = data["times"].as_array().unwrap();
    for (t, step) in times.iter().zip(&steps) {
        assert_eq!(
            t.as_f64().unwrap() as f32,
            (*step as f64 * scene.dt as f64) as f32
        );
    }
    // One board, drawn by its edges; it tilts, so it has a pose at every frame.
    let boards = data["boards"].as_array().unwrap();
    assert_eq!(boards.len(), 1);
    assert_eq!(f32s(&boards[0]["poses"]).len(), 7 * steps.len());
    assert_eq!(f32s(&boards[0]["segments"]).len() % 6, 0);

    // The plot is an SVG with its three panels.
    let svg = std::fs::read_to_string(&svg).unwrap();
    assert!(svg.starts_with("<svg") || svg.starts_with("<?xml"));
    for caption in ["top view", "energy of the marbles", "speed of the marbles"] {
        assert!(svg.contains(caption), "{caption}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_summary_names_what_happened_and_the_files_written() {
    let dir = temp_dir("summary");
    let html = dir.join("run.html");
    let out = run_small(&dir, &["--html".as_ref(), html.as_os_str()]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    for row in [
        "simulated",
        "wall time",
        "per marble-step",
        "impacts",
        "deepest",
        "energy",
        "quarantined",
        "asleep",
        "written",
    ] {
        assert!(text.contains(row), "no {row} in\n{text}");
    }
    assert!(text.contains(&html.display().to_string()));
    // Not a terminal: no progress bar on stderr.
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_bad_output_path_fails_with_status_1_and_leaves_nothing() {
    let dir = temp_dir("bad");
    let html = dir.join("missing-folder").join("run.html");
    let out = run_small(&dir, &["--html".as_ref(), html.as_os_str()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.starts_with("error: ") && err.contains("run.html"),
        "{err}"
    );
    assert!(!html.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

fn record(scene: &Scene, steps: u64, options: ReplayOptions) -> (Simulation, Recording) {
    let mut sim = Simulation::from_scene(scene).unwrap();
    let mut recorder = Recorder::new(&mut sim, steps, options);
    for step in 1..=steps {
        sim.step();
        recorder.after_step(&sim, step);
    }
    (sim, recorder.finish("test"))
}

#[test]
fn frames_stay_within_the_budget_and_keep_the_first_and_last_step() {
    let options = ReplayOptions::default();
    for (steps, marbles, dt) in [
        (2400u64, 1000usize, 1.0 / 240.0),
        (2400, 48, 1.0 / 240.0),
        (600, 1, 1.0 / 60.0),
        (7, 3, 1.0 / 60.0),
        (100_000, 20_000, 1.0 / 240.0),
    ] {
        let stride = frame_stride(steps, marbles, dt, &options);
        let frames = 1 + steps / stride + u64::from(steps % stride != 0);
        assert!(
            frames as usize * marbles <= options.max_marble_frames,
            "{steps} steps, {marbles} marbles: {frames} frames"
        );
        // No more than 60 a second (beyond the first).
        assert!((frames - 1) as f64 <= (steps as f64 * dt * 60.0).ceil() + 1.0);
        // And no sparser than needed: one step less would break a limit.
        if stride > 1 {
            let denser = stride - 1;
            let frames = 1 + steps / denser + u64::from(steps % denser != 0);
            // (The budget counts the last frame as one more, so one stride denser may still
            // fit by a frame or two.)
            assert!(
                (frames as usize + 2) * marbles > options.max_marble_frames
                    || (denser as f64) < 1.0 / (60.0 * dt) - 1e-9,
                "stride {stride} is sparser than needed for {steps} steps of {marbles}"
            );
        }
    }
    // A recorded run: the first and the last step, whatever the stride.
    let scene = common::drop_scene(
        0.5,
        0.01,
        0.5,
        1.0 / 240.0,
        Integrator::VelocityVerlet,
        true,
    );
    let (_, rec) = record(&scene, 101, options);
    assert_eq!(rec.frame_steps().first(), Some(&0));
    assert_eq!(rec.frame_steps().last(), Some(&101));
    assert_eq!(rec.frame_steps()[1], 4, "60 frames a second at dt = 1/240");
}

#[test]
fn energy_is_the_exact_sum_in_free_fall() {
    // One spinning marble in free fall from (0, 2, 0) with v0 = (1, 0, 0), no boards:
    // velocity Verlet is exact under constant gravity, so the kinetic energy is
    // ½ m (1 + g²t²) + ½ (2/5 m r²) ω² at every frame and the total stays at its start.
    let mut scene = Scene {
        integrator: Integrator::VelocityVerlet,
        rolling: true,
        ..Scene::default()
    };
    let mut m = MarbleDesc::at([0.0, 2.0, 0.0]);
    m.velocity = [1.0, 0.0, 0.0];
    m.angular_velocity = [0.0, 0.0, 30.0];
    m.radius = 0.01;
    scene.marbles.push(m);
    let (_, rec) = record(&scene, 120, ReplayOptions::default());
    let mass = Mass::glass_mass(0.01) as f64;
    let g = 9.81f64;
    for f in 0..rec.frames() {
        let t = rec.time(f) as f64;
        let (x, v) = (rec.positions(f)[0], rec.velocities(f)[0]);
        // Velocity-Verlet is exact here: v = v0 + g t, y = 2 − g t²/2.
        assert!((v.y as f64 + g * t).abs() < 1e-4, "frame {f}: vy {}", v.y);
        assert!(
            (x.y as f64 - (2.0 - 0.5 * g * t * t)).abs() < 1e-4,
            "frame {f}: y {}",
            x.y
        );
        let spin = 0.2 * mass * 0.01f64.powi(2) * 900.0;
        let kinetic = 0.5 * mass * (1.0 + g * g * t * t) + spin;
        let total = 0.5 * mass * 1.0 + spin + mass * g * 2.0;
        assert!(
            (rec.kinetic[f] - kinetic).abs() < 1e-6 * total,
            "frame {f}: kinetic {} J, want {kinetic} J",
            rec.kinetic[f]
        );
        // Energy is conserved in free fall.
        assert!(
            (rec.energy[f] - total).abs() < 1e-5 * total,
            "frame {f}: {} J, want {total} J",
            rec.energy[f]
        );
        assert_eq!(rec.speed_max[f], v.length());
    }
    assert_eq!(rec.impact_count, 0);
}

#[test]
fn the_first_impact_is_recorded_at_its_time_and_speed() {
    // A drop from 0.5 m (bottom height) onto a plane: the impact speed is √(2 g h) and it
    // happens in the step that contains t = √(2h/g) (continuous collision).
    let (h, r) = (0.5f32, 0.01f32);
    let dt = 1.0 / 240.0;
    let scene = common::drop_scene(h, r, 0.5, dt, Integrator::VelocityVerlet, true);
    let (_, rec) = record(&scene, 240, ReplayOptions::default());
    let speed = (2.0 * common::G * h).sqrt();
    let first = rec.impacts.first().expect("an impact");
    assert!(
        common::rel(first.speed, speed) < 1e-4,
        "{} m/s, want {speed}",
        first.speed
    );
    let t = (2.0 * h / common::G).sqrt();
    assert!(
        first.time >= t && first.time < t + dt,
        "at {} s, want the step ending after {t} s",
        first.time
    );
    assert_eq!(first.marble, 0);
    assert!(
        (first.point - Vec3::ZERO).length() < 1e-4,
        "at {}",
        first.point
    );
    assert_eq!(rec.fastest_impact, first.speed);
    // Later bounces are slower (e = 0.5), and every one is counted.
    assert!(rec.impact_count >= 2);
    assert!(rec.impacts[1..].iter().all(|i| i.speed < first.speed));
}

#[test]
fn penetration_is_measured_from_the_geometry() {
    // A marble (r = 1 cm) placed 1 mm into a still plane and another 2.5 mm into a box's
    // top face, nothing moving (no gravity): the deepest is 2.5 mm at the first frame.
    let mut scene = Scene {
        gravity: [0.0; 3],
        ..Scene::default()
    };
    scene
        .boards
        .push(BoardDesc::new(ShapeDesc::Plane(Default::default())));
    let mut cube = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.1, 0.1, 0.1],
    });
    cube.position = [1.0, 0.5, 0.0];
    scene.boards.push(cube);
    let mut a = MarbleDesc::at([0.0, 0.009, 0.0]);
    a.radius = 0.01;
    let mut b = MarbleDesc::at([1.0, 0.6075, 0.0]);
    b.radius = 0.01;
    scene.marbles = vec![a, b];
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let rec = Recorder::new(&mut sim, 10, ReplayOptions::default()).finish("resting");
    assert!(
        (rec.deepest_board - 0.0025).abs() < 1e-6,
        "{} m, want 2.5 mm",
        rec.deepest_board
    );
    assert_eq!(rec.deepest_pair, 0.0);
}

#[test]
fn a_tilted_gravity_scene_is_recorded_in_the_world_frame() {
    // With `tilt_as_gravity` the engine keeps the board still and turns gravity; the
    // recording maps marbles and the board back to the world, as the CSV does.
    let mut scene = scenes::labyrinth(6);
    scene.tilt_as_gravity = true;
    let steps = 120;
    let (sim, rec) = record(&scene, steps, ReplayOptions::default());
    let last = rec.frames() - 1;
    for i in 0..6 {
        assert_eq!(rec.positions(last)[i], sim.marble_world_state(i).0);
    }
    let (_, q) = rec.boards[0].poses[last];
    let turned = 0.02 * steps as f32 * scene.dt;
    let tilt0 = -0.1f32;
    let angle = 2.0 * q.x.atan2(q.w);
    assert!(
        (angle - (tilt0 + turned)).abs() < 1e-4,
        "board at {angle} rad, want {}",
        tilt0 + turned
    );
}

#[test]
fn many_marbles_are_shown_every_kth_within_the_budget() {
    let mut scene = Scene {
        gravity: [0.0; 3],
        ..Scene::default()
    };
    for i in 0..50 {
        scene
            .marbles
            .push(MarbleDesc::at([i as f32 * 0.1, 0.0, 0.0]));
    }
    let options = ReplayOptions {
        max_marbles: 20,
        max_marble_frames: 200,
        ..ReplayOptions::default()
    };
    let (_, rec) = record(&scene, 100, options);
    assert_eq!(rec.marble_stride, 3);
    assert_eq!(rec.radii.len(), 17);
    assert!(rec.frames() * rec.radii.len() <= 200);
    assert_eq!(rec.positions(0)[5].x, 15.0 * 0.1);
    let mut page = Vec::new();
    rec.write_html(&mut page).unwrap();
    let data = page_data(std::str::from_utf8(&page).unwrap());
    assert_eq!(data["marbleStride"], 3);
    assert_eq!(f32s(&data["positions"]).len(), rec.frames() * 17 * 3);
}

#[test]
fn sensors_are_recorded_where_their_board_carries_them() {
    // The tilting labyrinth with a goal carried by its board: the page holds the goal's
    // outline and its pose at every frame, the board's pose composed with its own.
    let mut scene = scenes::labyrinth(5);
    scene.sensors.push(bevy_marble::scene::SensorDesc {
        name: "goal".into(),
        shape: ShapeDesc::Cuboid {
            half_extents: [0.02, 0.02, 0.02],
        },
        board: Some(0),
        position: [0.1, 0.02, 0.1],
        rotation: [0.0, 0.0, 0.0, 1.0],
    });
    let (_, rec) = record(&scene, 60, ReplayOptions::default());
    let (board, goal) = (&rec.boards[0], &rec.sensors[0]);
    assert_eq!(goal.segments.len(), 12, "a box's edges");
    assert_eq!(goal.poses.len(), rec.frames());
    assert!(!goal.is_still(), "it tilts with the board");
    for ((bp, bq), (gp, gq)) in board.poses.iter().zip(&goal.poses) {
        assert!((*gp - (*bp + *bq * Vec3::new(0.1, 0.02, 0.1))).length() < 1e-6);
        assert!((*gq - *bq).length() < 1e-6, "{gq} against {bq}");
    }
    let mut page = Vec::new();
    rec.write_html(&mut page).unwrap();
    let data = page_data(std::str::from_utf8(&page).unwrap());
    assert_eq!(f32s(&data["sensors"][0]["poses"]).len(), 7 * rec.frames());
    assert_eq!(f32s(&data["sensors"][0]["segments"]).len(), 12 * 6);
}

/// A recording goes on when the program despawns one of the scene's marbles (one that fell
/// into a hole): from then on it is recorded as nowhere (not drawn), and the page is
/// written; the other marble's frames are its free fall, exactly (velocity Verlet).
#[test]
fn a_despawned_marble_is_recorded_as_nowhere() {
    let scene = Scene {
        integrator: Integrator::VelocityVerlet,
        dt: 1.0 / 60.0,
        marbles: vec![
            MarbleDesc::at([0.0, 2.0, 0.0]),
            MarbleDesc::at([1.0, 2.0, 0.0]),
        ],
        ..Scene::default()
    };
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut recorder = Recorder::new(&mut sim, 30, ReplayOptions::default());
    for step in 1..=30u64 {
        if step == 10 {
            let gone = sim.marbles()[0];
            sim.world_mut().despawn(gone);
        }
        sim.step();
        recorder.after_step(&sim, step);
    }
    let mut csv = Vec::new();
    bevy_marble::output::write_csv_rows(&mut csv, &sim, 30, scene.dt).unwrap();
    let csv = String::from_utf8(csv).unwrap();
    assert!(
        csv.starts_with("30,0.5,0,NaN,NaN,NaN,NaN,NaN,NaN,"),
        "{csv}"
    );
    let rec = recorder.finish("despawned");
    let last = rec.frames() - 1;
    assert!(rec.positions(0)[0].is_finite());
    assert!(rec.positions(last)[0].is_nan());
    let t = rec.time(last);
    let want = 2.0 - 0.5 * 9.81 * t * t;
    assert!((rec.positions(last)[1].y - want).abs() <= 1e-4);
    let mut page = Vec::new();
    rec.write_html(&mut page).unwrap();
}

/// A board the program despawns during a recording is recorded as nowhere from then on
/// (not drawn), not left at the origin; the other board keeps its pose.
#[test]
fn a_despawned_board_is_recorded_as_nowhere() {
    let mut scene = Scene::from_ron_str(
        "(boards: [(shape: Plane(())), (shape: Cuboid(half_extents: (0.1, 0.1, 0.1)), position: (2.0, 0.5, 0.0))])",
    )
    .unwrap();
    scene.dt = 1.0 / 60.0;
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut recorder = Recorder::new(&mut sim, 20, ReplayOptions::default());
    for step in 1..=20u64 {
        if step == 10 {
            let gone = sim.boards()[1];
            sim.world_mut().despawn(gone);
        }
        sim.step();
        recorder.after_step(&sim, step);
    }
    let rec = recorder.finish("despawned board");
    let (first, last) = (&rec.boards[1].poses[0], rec.boards[1].poses.last().unwrap());
    assert_eq!(first.0, Vec3::new(2.0, 0.5, 0.0));
    assert!(last.0.is_nan() && last.1.is_nan(), "{last:?}");
    assert_eq!(rec.boards[0].poses.last().unwrap().0, Vec3::ZERO);
    let mut page = Vec::new();
    rec.write_html(&mut page).unwrap();
}
