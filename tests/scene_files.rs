//! Scene files (RON and JSON, defaults, validation messages) and the `marble` command
//! line (outputs, exit codes, determinism).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use bevy_marble::prelude::*;
use bevy_marble::scenes;

const CONTRACT_RON: &str = r#"(
    dt: 0.004166667,
    boards: [(shape: Plane(()), restitution: 0.8)],
    marbles: [(position: (0.0, 1.008, 0.0), radius: 0.008, restitution: 0.8)],
)"#;

const CONTRACT_JSON: &str = r#"{"dt": 0.004166667,
 "boards": [{"shape": {"Plane": {}}, "restitution": 0.8}],
 "marbles": [{"position": [0, 1.008, 0], "radius": 0.008, "restitution": 0.8}]}"#;

#[test]
fn contract_examples_load_identically_with_defaults() {
    let ron = Scene::from_ron_str(CONTRACT_RON).unwrap();
    let json = Scene::from_json_str(CONTRACT_JSON).unwrap();
    assert_eq!(ron, json);
    assert_eq!(ron.gravity, [0.0, -9.81, 0.0]);
    assert_eq!(ron.substeps, 1);
    assert_eq!(ron.integrator, Integrator::SemiImplicitEuler);
    assert!(ron.ccd && !ron.rolling && !ron.marble_collisions);
    assert_eq!(ron.restitution_threshold, 0.05);
    assert_eq!(ron.duration, 10.0);
    let b = &ron.boards[0];
    assert_eq!(
        (
            b.position,
            b.rotation,
            b.velocity,
            b.angular_velocity,
            b.friction
        ),
        ([0.0; 3], [0.0, 0.0, 0.0, 1.0], [0.0; 3], [0.0; 3], 0.5)
    );
    let m = &ron.marbles[0];
    assert_eq!((m.velocity, m.mass, m.friction), ([0.0; 3], None, 0.5));
    // Default mass: glass, 2500 kg/m³ × 4/3 π r³.
    let sim = Simulation::from_scene(&ron).unwrap();
    let mass = sim.world().get::<Mass>(sim.marbles()[0]).unwrap().get();
    let want = 2500.0 * 4.0 / 3.0 * std::f32::consts::PI * 0.008f32.powi(3);
    assert!((mass - want).abs() <= 1e-6 * want);
}

#[test]
fn every_shape_parses_in_both_formats() {
    let ron = r#"(boards: [
        (shape: Plane(())),
        (shape: Cuboid(half_extents: (1.0, 0.1, 1.0)), position: (0.0, 1.0, 0.0)),
        (shape: TriMesh(vertices: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)], indices: [(0, 1, 2)])),
        (shape: HeightField(heights: [[0.0, 0.1], [0.2, 0.3]], scale: (1.0, 1.0, 1.0))),
        (shape: Compound([(shape: Cuboid(half_extents: (1.0, 1.0, 1.0)), position: (0.0, -1.0, 0.0))])),
    ])"#;
    let json = r#"{"boards": [
        {"shape": {"Plane": {}}},
        {"shape": {"Cuboid": {"half_extents": [1, 0.1, 1]}}, "position": [0, 1, 0]},
        {"shape": {"TriMesh": {"vertices": [[0, 0, 0], [1, 0, 0], [0, 0, 1]], "indices": [[0, 1, 2]]}}},
        {"shape": {"HeightField": {"heights": [[0, 0.1], [0.2, 0.3]], "scale": [1, 1, 1]}}},
        {"shape": {"Compound": [{"shape": {"Cuboid": {"half_extents": [1, 1, 1]}}, "position": [0, -1, 0]}]}}
    ]}"#;
    let a = Scene::from_ron_str(ron).unwrap();
    let b = Scene::from_json_str(json).unwrap();
    assert_eq!(a, b);
    Simulation::from_scene(&a).unwrap();
}

#[test]
fn default_scene_round_trips_through_ron_and_json() {
    let s = scenes::default_scene();
    assert_eq!(Scene::from_ron_str(&s.to_ron_string()).unwrap(), s);
    assert_eq!(Scene::from_json_str(&s.to_json_string()).unwrap(), s);
}

/// Each invalid scene is refused with the field path and value in the message.
#[test]
fn invalid_scenes_name_field_and_value() {
    let cases: &[(&str, &str)] = &[
        ("(dt: 0.0)", "dt must be > 0, got 0"),
        ("(dt: -0.1)", "dt must be > 0, got -0.1"),
        ("(dt: NaN)", "dt must be > 0, got NaN"),
        ("(dt: 1.5)", "dt must be at most 1 s, got 1.5"),
        ("(substeps: 0)", "substeps must be >= 1, got 0"),
        (
            "(gravity: (0.0, inf, 0.0))",
            "gravity must be finite, got [0.0, inf, 0.0]",
        ),
        (
            "(restitution_threshold: -1.0)",
            "restitution_threshold must be >= 0, got -1",
        ),
        ("(duration: -1.0)", "duration must be >= 0, got -1"),
        (
            "(sleep_speed: -0.01)",
            "sleep_speed must be >= 0, got -0.01",
        ),
        ("(sleep_time: 0.0)", "sleep_time must be > 0, got 0"),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0), radius: -0.01)])",
            "marbles[3].radius must be > 0, got -0.01",
        ),
        (
            "(marbles: [(position: (0.0, NaN, 0.0))])",
            "marbles[0].position must be finite, got [0.0, NaN, 0.0]",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), radius: 0.0)])",
            "marbles[0].radius must be > 0, got 0",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), mass: 0.0)])",
            "marbles[0].mass must be > 0, got 0",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), mass: -2.0)])",
            "marbles[0].mass must be > 0, got -2",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), restitution: 1.5)])",
            "marbles[0].restitution must be in [0, 1], got 1.5",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), restitution: -0.1)])",
            "marbles[0].restitution must be in [0, 1], got -0.1",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), friction: -1.0)])",
            "marbles[0].friction must be >= 0, got -1",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), velocity: (inf, 0.0, 0.0))])",
            "marbles[0].velocity must be finite, got [inf, 0.0, 0.0]",
        ),
        (
            "(boards: [(shape: Plane(()), restitution: 2.0)])",
            "boards[0].restitution must be in [0, 1], got 2",
        ),
        (
            "(boards: [(shape: Plane(()), rotation: (0.0, 0.0, 0.0, 0.0))])",
            "boards[0].rotation must be a non-zero quaternion, got [0.0, 0.0, 0.0, 0.0]",
        ),
        (
            "(boards: [(shape: Plane(()), position: (NaN, 0.0, 0.0))])",
            "boards[0].position must be finite, got [NaN, 0.0, 0.0]",
        ),
        (
            "(boards: [(shape: Cuboid(half_extents: (1.0, 0.0, 1.0)))])",
            "boards[0].shape.Cuboid.half_extents.y must be > 0, got 0",
        ),
        (
            "(boards: [(shape: TriMesh(vertices: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)], indices: [(0, 1, 3)]))])",
            "boards[0].shape.TriMesh.indices[0][2] must be < 3 (the number of vertices), got 3",
        ),
        (
            "(boards: [(shape: TriMesh(vertices: [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0)], indices: [(0, 1, 2)]))])",
            "boards[0].shape.TriMesh.indices[0] must be a triangle of non-zero area, got [0, 1, 2]",
        ),
        (
            // Past the supported range: its cross product would overflow to NaN.
            "(boards: [(shape: TriMesh(vertices: [(-3e38, 0.0, 0.0), (3e38, 0.0, 0.0), (0.0, 0.0, 0.0)], indices: [(0, 1, 2)]))])",
            "boards[0].shape.TriMesh.vertices[0] must be within 1e6 m of the origin in each coordinate, got [-3e38, 0.0, 0.0]",
        ),
        (
            "(boards: [(shape: Compound([(shape: Plane(()), position: (0.0, 2e6, 0.0))]))])",
            "boards[0].shape.Compound[0].position must be within 1e6 m of the origin in each coordinate, got [0.0, 2000000.0, 0.0]",
        ),
        (
            "(boards: [(shape: TriMesh(vertices: [], indices: []))])",
            "boards[0].shape.TriMesh.indices must be non-empty, got []",
        ),
        (
            "(boards: [(shape: HeightField(heights: [[0.0, 0.0], [0.0]], scale: (1.0, 1.0, 1.0)))])",
            "boards[0].shape.HeightField.heights[1] must be 2 long like row 0, got 1",
        ),
        (
            "(boards: [(shape: HeightField(heights: [[0.0, 0.0]], scale: (1.0, 1.0, 1.0)))])",
            "boards[0].shape.HeightField.heights must be at least 2 rows, got 1",
        ),
        (
            "(boards: [(shape: HeightField(heights: [[0.0, 0.0], [0.0, 0.0]], scale: (1.0, -1.0, 1.0)))])",
            "boards[0].shape.HeightField.scale.y must be > 0, got -1",
        ),
        (
            "(boards: [(shape: Compound([(shape: Compound([(shape: Plane(()))]))]))])",
            "boards[0].shape.Compound[0].shape must be not a Compound (parts are not compounds), got Compound",
        ),
        (
            "(marbles: [(position: (0.0, 0.0, 0.0), rolling_resistance: -0.1)])",
            "marbles[0].rolling_resistance must be >= 0, got -0.1",
        ),
        (
            "(boards: [(shape: Plane(()), spin_damping: -1.0)])",
            "boards[0].spin_damping must be >= 0, got -1",
        ),
        (
            "(marble_collisions: true, solver_iterations: 0)",
            "solver_iterations must be >= 1, got 0",
        ),
    ];
    for (text, message) in cases {
        let err = Scene::from_ron_str(text).expect_err(text);
        assert_eq!(&err.to_string(), message, "for {text}");
    }
}

/// A rotation is normalized on load however far from unit length it is given: components
/// whose squares overflow or underflow f32 included.
#[test]
fn rotations_far_from_unit_length_load_normalized() {
    for (q, want) in [
        (
            [1e20, 0.0, 0.0, 1.0],
            glam::Quat::from_xyzw(1.0, 0.0, 0.0, 0.0),
        ),
        ([0.0, 0.0, 0.0, 1e-25], glam::Quat::IDENTITY),
        (
            [3e38, 0.0, 0.0, 3e38],
            glam::Quat::from_xyzw(1.0, 0.0, 0.0, 1.0).normalize(),
        ),
    ] {
        let text = format!(
            "(boards: [(shape: Plane(()), rotation: ({:e}, {:e}, {:e}, {:e}))])",
            q[0], q[1], q[2], q[3]
        );
        let scene = Scene::from_ron_str(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
        let got = bevy_marble::scene::quat(scene.boards[0].rotation);
        assert!(got.abs_diff_eq(want, 1e-6), "{q:?}: {got}");
    }
}

#[test]
fn syntax_errors_and_unknown_fields_are_refused() {
    let e = Scene::from_ron_str("(dt: 0.1, wobble: 3)").unwrap_err();
    assert!(e.to_string().contains("wobble"), "{e}");
    let e =
        Scene::from_json_str(r#"{"marbles": [{"position": [0, 0, 0], "colour": 1}]}"#).unwrap_err();
    assert!(e.to_string().contains("colour"), "{e}");
    let e = Scene::from_ron_str("(dt: 0.1,").unwrap_err();
    assert!(matches!(e, SceneError::Parse(_)), "{e}");
    let e = Scene::from_json_str(r#"{"marbles": [{}]}"#).unwrap_err();
    assert!(e.to_string().contains("position"), "{e}");
    let e = Scene::from_path("/nonexistent/scene.ron").unwrap_err();
    assert!(matches!(e, SceneError::Io(_)), "{e}");
    let e = Scene::from_path("scene.yaml").unwrap_err();
    assert!(matches!(e, SceneError::Format(_)), "{e}");
}

// ---------------------------------------------------------------- the command line

fn marble(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_marble"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("marble runs")
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bevy_marble_cli_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn cli_run_writes_the_contract_csv_deterministically() {
    let dir = temp_dir("run");
    std::fs::write(dir.join("drop.ron"), CONTRACT_RON).unwrap();
    let args = [
        "run", "drop.ron", "--steps", "25", "--every", "10", "--csv", "a.csv", "--quiet",
    ];
    let o = marble(&args, &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("a.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "step,time,marble,x,y,z,vx,vy,vz,wx,wy,wz");
    assert_eq!(lines[1], "0,0,0,0,1.008,0,0,0,0,0,0,0");
    let steps: Vec<&str> = lines[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(steps, ["0", "10", "20", "25"]);
    // Time is step × dt and every number parses back to f32.
    for l in &lines[1..] {
        let f: Vec<f32> = l.split(',').map(|x| x.parse().unwrap()).collect();
        assert!((f[1] - f[0] * 0.004166667).abs() <= 1e-6);
    }
    let o = marble(
        &[
            "run", "drop.ron", "--steps", "25", "--every", "10", "--csv", "b.csv", "--quiet",
        ],
        &dir,
    );
    assert!(o.status.success());
    assert_eq!(csv, std::fs::read_to_string(dir.join("b.csv")).unwrap());
    // One thread asked for is what every build runs.
    let o = marble(
        &[
            "run",
            "drop.ron",
            "--steps",
            "25",
            "--every",
            "10",
            "--csv",
            "t.csv",
            "--quiet",
            "--threads",
            "1",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(csv, std::fs::read_to_string(dir.join("t.csv")).unwrap());
    // JSON gives the same bytes.
    std::fs::write(dir.join("drop.json"), CONTRACT_JSON).unwrap();
    let o = marble(
        &[
            "run",
            "drop.json",
            "--steps",
            "25",
            "--every",
            "10",
            "--csv",
            "c.csv",
            "--quiet",
        ],
        &dir,
    );
    assert!(o.status.success());
    assert_eq!(csv, std::fs::read_to_string(dir.join("c.csv")).unwrap());
    // A plot.
    let o = marble(
        &[
            "run", "drop.ron", "--steps", "25", "--plot", "p.svg", "--quiet",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read_to_string(dir.join("p.svg"))
            .unwrap()
            .starts_with("<svg")
    );
}

#[test]
fn cli_bad_input_exits_2_with_one_line_and_no_output() {
    let dir = temp_dir("bad");
    std::fs::write(
        dir.join("scene.ron"),
        "(marbles: [(position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0), radius: -0.01)])",
    )
    .unwrap();
    std::fs::write(dir.join("syntax.json"), "{\"dt\": ").unwrap();
    std::fs::write(dir.join("big.ron"), "(substeps: 4294967296)").unwrap();
    std::fs::write(dir.join("big.json"), r#"{"substeps": 4e9}"#).unwrap();
    std::fs::write(
        dir.join("types.ron"),
        r#"(marbles: [(position: (0.0, 0.0, 0.0)), (position: (0.0, 0.0, 0.0), radius: "big")])"#,
    )
    .unwrap();
    // Accepted with a warning (ccd off), which is not printed when other input is at fault.
    let warned = "(ccd: false, marbles: [(position: (0.0, 1.0, 0.0))])";
    std::fs::write(dir.join("warned.ron"), warned).unwrap();
    std::fs::write(dir.join("poses.csv"), "junk\n").unwrap();
    std::fs::write(dir.join("header.csv"), "step,board,x,y,z,qx,qy,qz,qw\n").unwrap();
    let cases: &[(&[&str], &str)] = &[
        (
            &["check", "big.ron"],
            "error: big.ron: substeps: Integer is out of bounds, got 4294967296",
        ),
        (
            &["check", "big.json"],
            "error: big.json: substeps: invalid type: floating point `4000000000.0`",
        ),
        (
            &["check", "types.ron"],
            r#"error: types.ron: marbles[1].radius: Expected float, got "big""#,
        ),
        (
            &["run"],
            "error: the following required arguments were not provided: <SCENE>",
        ),
        (
            &[
                "run",
                "warned.ron",
                "--poses",
                "poses.csv",
                "--csv",
                "out.csv",
            ],
            "error: poses.csv: line 1",
        ),
        (
            &[
                "run",
                "warned.ron",
                "--csv",
                "out.same",
                "--plot",
                "out.same",
            ],
            "error: --plot out.same: the same file as --csv",
        ),
        (
            &["run", "warned.ron", "--csv", "./warned.ron"],
            "error: --csv ./warned.ron: the file read as SCENE",
        ),
        (
            &[
                "run",
                "warned.ron",
                "--html",
                "header.csv",
                "--poses",
                "header.csv",
            ],
            "error: --html header.csv: the file read as --poses",
        ),
        (
            &["run", "scene.ron", "--csv", "out.csv"],
            "error: scene.ron: marbles[3].radius must be > 0, got -0.01",
        ),
        (
            &["check", "scene.ron"],
            "error: scene.ron: marbles[3].radius must be > 0, got -0.01",
        ),
        (&["check", "syntax.json"], "error: syntax.json: "),
        (
            &["check", "missing.ron"],
            "error: missing.ron: cannot read the file",
        ),
        (&["run", "scene.ron", "--every", "0"], "error: "),
        (&["run", "--wobble"], "error: "),
        (&["run", "scene.ron", "--threads", "0"], "error: "),
    ];
    // A build without `parallel` runs on one thread and says so.
    let serial: &[(&[&str], &str)] = &[(
        &["run", "scene.ron", "--threads", "4", "--csv", "out.csv"],
        "error: --threads 4: this marble was built without the `parallel` feature",
    )];
    let serial = if cfg!(feature = "parallel") {
        &[]
    } else {
        serial
    };
    for (args, start) in cases.iter().chain(serial) {
        let o = marble(args, &dir);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with(start), "{args:?}: {err}");
    }
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.contains("out"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    assert_eq!(
        std::fs::read_to_string(dir.join("warned.ron")).unwrap(),
        warned
    );
}

#[test]
fn cli_check_scene_and_default_run() {
    let dir = temp_dir("default");
    let o = marble(&["scene"], &dir);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(Scene::from_ron_str(&text).unwrap(), scenes::default_scene());
    std::fs::write(dir.join("default.ron"), &text).unwrap();
    let o = marble(&["check", "default.ron"], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = marble(&[], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("marble-out/default.csv")).unwrap();
    assert!(csv.starts_with("step,time,marble,"));
    assert!(dir.join("marble-out/default.svg").exists());
}

/// `marble scene --bench NAME --marbles N` prints the shared bench scenes (the same the
/// benches and the rapier comparison use); a bad name or a missing `--bench` is exit 2.
#[test]
fn cli_prints_the_bench_scenes() {
    let dir = temp_dir("bench_scenes");
    for kind in scenes::BenchScene::ALL {
        let o = marble(&["scene", "--bench", kind.name(), "--marbles", "60"], &dir);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = String::from_utf8(o.stdout).unwrap();
        assert_eq!(
            Scene::from_ron_str(&text).unwrap(),
            kind.build(60),
            "{}",
            kind.name()
        );
    }
    let o = marble(&["scene", "--bench", "nope"], &dir);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("unknown bench scene"), "{}", stderr(&o));
    let o = marble(&["scene", "--marbles", "5"], &dir);
    assert_eq!(o.status.code(), Some(2));
}

/// A preset in a scene file sets the integrator, CCD and the substeps its dt needs.
#[test]
fn presets_load_from_scene_files() {
    // (preset, dt, substeps): substeps reach the preset's longest substep.
    for (preset, dt, substeps) in [
        ("Fast", "0.016666668", 1),
        ("Balanced", "0.016666668", 1),
        ("Precise", "0.016666668", 4),
        ("Fast", "0.1", 3),
        ("Balanced", "0.033333335", 2),
        ("Precise", "0.004166667", 1),
    ] {
        let scene = Scene::from_ron_str(&format!("(preset: {preset}, dt: {dt})")).unwrap();
        let c = scene.step_config();
        assert_eq!(c, StepConfig::with_preset(scene.preset.unwrap(), scene.dt));
        assert_eq!(
            (c.integrator, c.ccd, c.substeps),
            (Integrator::VelocityVerlet, true, substeps),
            "{preset} at {dt}"
        );
    }
    let json = Scene::from_json_str(r#"{"preset": "Precise", "dt": 0.01}"#).unwrap();
    let c = json.step_config();
    assert_eq!((c.substeps, c.contact_tolerance), (3, 1e-5));
}

/// `marble tradeoff --quick` runs the whole study on a small grid: the table on stdout,
/// the report and one plot per reference scene in DIR, and the measured facts the README
/// relies on hold (CCD holds the thin wall, compensation keeps the 100 m fall).
#[test]
fn cli_tradeoff_quick() {
    let dir = temp_dir("tradeoff");
    let o = marble(&["tradeoff", "--quick", "--out", "study"], &dir);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8(o.stdout).unwrap();
    assert!(
        out.contains("| integrator | dt | substeps | CCD |"),
        "{out}"
    );
    assert!(out.contains("## Presets") && out.contains("Pareto front: bounce"));
    let grid_rows = out.lines().filter(|l| l.matches('|').count() == 13);
    for line in grid_rows.filter(|l| l.contains("| on |") && l.starts_with("| Velocity")) {
        assert!(line.ends_with("holds |"), "{line}");
    }
    let report = std::fs::read_to_string(dir.join("study/tradeoff.md")).unwrap();
    assert_eq!(report, out);
    for name in [
        "bounce",
        "elastic",
        "incline",
        "moving_board",
        "resting",
        "thin_wall",
    ] {
        let svg = std::fs::read_to_string(dir.join(format!("study/{name}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("Pareto"), "{name}");
    }
}

/// An interrupted run (SIGTERM, or SIGINT as Ctrl-C sends, in the middle of stepping)
/// leaves no CSV or plot under the asked-for names: they are written under temporary
/// names and renamed into place only once complete.
#[cfg(unix)]
#[test]
fn an_interrupted_run_leaves_no_output_that_looks_complete() {
    for signal in ["-TERM", "-INT"] {
        let dir = temp_dir(&format!("interrupted{signal}"));
        let scene = dir.join("pour.ron");
        let mut s = scenes::pour_box(2000);
        s.duration = 600.0;
        std::fs::write(&scene, ron::to_string(&s).unwrap()).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_marble"))
            .args([
                "run", "pour.ron", "--csv", "out.csv", "--plot", "out.svg", "--quiet",
            ])
            .current_dir(&dir)
            .spawn()
            .expect("marble runs");
        std::thread::sleep(std::time::Duration::from_millis(1500));
        assert!(
            child.try_wait().unwrap().is_none(),
            "still running when interrupted"
        );
        let killed = Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let status = child.wait().unwrap();
        assert!(!status.success(), "{signal}: {status:?}");
        assert!(
            !dir.join("out.csv").exists(),
            "{signal}: out.csv left behind"
        );
        assert!(
            !dir.join("out.svg").exists(),
            "{signal}: out.svg left behind"
        );
    }
}

/// A restitution of exactly 0 and exactly 1 is accepted, the next f32 above 1 and the
/// next below 0 refused, for marbles and boards alike.
#[test]
fn restitution_bounds_are_exact_for_marbles_and_boards() {
    let above = f32::from_bits(1.0f32.to_bits() + 1);
    let below = -f32::from_bits(1);
    for e in [0.0f32, 1.0] {
        let mut s = scenes::drop_on_plane(0.5, 0.008, e);
        s.boards[0].restitution = e;
        assert!(s.validate().is_ok(), "e = {e}");
    }
    for e in [above, below] {
        let mut s = scenes::drop_on_plane(0.5, 0.008, 0.5);
        s.marbles[0].restitution = e;
        let err = s.validate().unwrap_err().to_string();
        assert_eq!(
            err,
            format!("marbles[0].restitution must be in [0, 1], got {e}")
        );
        let mut s = scenes::drop_on_plane(0.5, 0.008, 0.5);
        s.boards[0].restitution = e;
        let err = s.validate().unwrap_err().to_string();
        assert_eq!(
            err,
            format!("boards[0].restitution must be in [0, 1], got {e}")
        );
    }
}

/// An output path that is a directory fails at once (exit status 1, one line), before the
/// run, and leaves nothing behind.
#[test]
fn cli_output_onto_a_directory_fails_at_once() {
    let dir = temp_dir("dir_out");
    std::fs::write(
        dir.join("scene.ron"),
        "(marbles: [(position: (0.0, 0.5, 0.0))])",
    )
    .unwrap();
    std::fs::create_dir(dir.join("out")).unwrap();
    for flag in ["--csv", "--plot", "--html"] {
        let o = marble(&["run", "scene.ron", flag, "out", "--quiet"], &dir);
        assert_eq!(o.status.code(), Some(1), "{flag}: {}", stderr(&o));
        let err = stderr(&o);
        assert_eq!(err.lines().count(), 1, "{flag}: {err}");
        assert!(
            err.starts_with("error: out: is a directory"),
            "{flag}: {err}"
        );
    }
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["out", "scene.ron"]);
}
