//! `marble`: run, check and print scenes from the command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use bevy_marble::output::{AtomicFile, CSV_HEADER, write_csv_rows};
use bevy_marble::prelude::*;
use bevy_marble::scenes;
use clap::{Parser, Subcommand};

/// Parses a bench scene's name for `marble scene --bench`.
fn bench_scene(name: &str) -> Result<scenes::BenchScene, String> {
    scenes::BenchScene::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = scenes::BenchScene::ALL.iter().map(|b| b.name()).collect();
        format!("unknown bench scene {name:?}; one of {}", names.join(", "))
    })
}

/// A marble-rolling physics engine: run, check and print scenes.
#[derive(Parser, Debug)]
#[command(name = "marble", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Simulate a scene file (.ron or .json).
    Run(RunArgs),
    /// Validate a scene file only.
    Check {
        /// The scene file.
        scene: PathBuf,
    },
    /// Print the built-in default scene as RON, or one of the bench scenes.
    Scene {
        /// A bench scene instead: walled_board (a), pour_box (b) or labyrinth (c).
        #[arg(long, value_name = "NAME", value_parser = bench_scene)]
        bench: Option<scenes::BenchScene>,
        /// Marbles in the bench scene.
        #[arg(long, default_value_t = 1000, requires = "bench",
              value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
        marbles: u64,
    },
    /// The speed-versus-accuracy study: every integrator × dt × substeps × CCD on the
    /// reference scenes; a table on stdout, the table and one plot per scene in DIR.
    Tradeoff {
        /// Folder for the table and plots (default: marble-out/tradeoff).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// A small grid and shorter scenes (seconds instead of a minute or two).
        #[arg(long)]
        quick: bool,
    },
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// The scene file.
    scene: PathBuf,
    /// Steps to simulate (default: duration / dt, rounded).
    #[arg(long)]
    steps: Option<u64>,
    /// Write the marbles' states as CSV to this file.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Record every K-th step in the CSV (the first and last are always recorded).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    every: u64,
    /// Write pictures of the run as SVG: a top view with each marble's trail coloured by
    /// speed, and energy and speed over time.
    #[arg(long, value_name = "FILE.svg")]
    plot: Option<PathBuf>,
    /// Write a replay page: one self-contained HTML file to open in any browser.
    #[arg(long, value_name = "FILE.html")]
    html: Option<PathBuf>,
    /// Drive boards through these poses (CSV `step,board,x,y,z,qx,qy,qz,qw`: where board
    /// `board` is at the end of step `step`), as a game does with `NextPose`; the tilts a
    /// player gave, replayed.
    #[arg(long, value_name = "FILE.csv")]
    poses: Option<PathBuf>,
    /// No progress bar or summary.
    #[arg(long)]
    quiet: bool,
    /// Threads of the compute task pool in a build with the `parallel` feature (default:
    /// the cores this process may use); every count gives the same bits. A build without
    /// `parallel` runs on one thread and accepts only 1.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: Option<u16>,
}

/// An error and the exit status it maps to: 2 for the user's input, 1 for anything else.
struct Failure {
    code: u8,
    message: String,
}

fn input_error(message: String) -> Failure {
    Failure { code: 2, message }
}

fn other_error(message: String) -> Failure {
    Failure { code: 1, message }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            // clap's first paragraph, on one line: what is wrong and what it names (a
            // missing argument's name comes on the next line).
            let text = e.to_string();
            let first: Vec<&str> = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect();
            match first.join(" ") {
                line if line.starts_with("error:") => eprintln!("{line}"),
                _ => eprintln!("error: bad arguments"),
            }
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        None => run_default(),
        Some(Command::Run(args)) => run_file(&args),
        Some(Command::Check { scene }) => load(&scene).map(|s| {
            warn(&scene, &s);
            let sensors = match s.sensors.len() {
                0 => String::new(),
                n => format!(", {n} sensors"),
            };
            println!(
                "{}: ok ({} boards, {} marbles{sensors})",
                scene.display(),
                s.boards.len(),
                s.marbles.len()
            );
        }),
        Some(Command::Scene { bench, marbles }) => {
            let scene = match bench {
                Some(kind) => kind.build(marbles as usize),
                None => scenes::default_scene(),
            };
            println!("{}", scene.to_ron_string());
            Ok(())
        }
        Some(Command::Tradeoff { out, quick }) => tradeoff(out, quick),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}

fn tradeoff(out: Option<PathBuf>, quick: bool) -> Result<(), Failure> {
    use bevy_marble::study::{self, Length, Reference};
    let dir = out.unwrap_or_else(|| PathBuf::from("marble-out/tradeoff"));
    std::fs::create_dir_all(&dir)
        .map_err(|e| other_error(format!("{}: cannot create: {e}", dir.display())))?;
    let (settings, length) = if quick {
        (study::quick_grid(), Length::Quick)
    } else {
        (study::full_grid(), Length::Full)
    };
    let bar = indicatif::ProgressBar::new(settings.len() as u64);
    let started = Instant::now();
    let rows = study::run(&settings, length, |done| bar.set_position(done as u64));
    bar.finish_and_clear();
    let report = format!(
        "## Every setting\n\n{}\n## Presets\n\n{}\n## Compensated summation\n\n{}\n## Tilting board: moving board or tilted gravity\n\n{}\n{}",
        study::markdown(&rows),
        study::presets_markdown(length),
        study::compensation_markdown(length),
        study::tilt_markdown(length),
        study::front_markdown(&rows),
    );
    print!("{report}");
    let io = |p: &Path, e: std::io::Error| other_error(format!("{}: {e}", p.display()));
    let md = dir.join("tradeoff.md");
    std::fs::write(&md, &report).map_err(|e| io(&md, e))?;
    for reference in Reference::ALL {
        let svg = dir.join(format!("{}.svg", reference.name()));
        bevy_marble::output::write_tradeoff_svg(&rows, reference, &svg).map_err(|e| io(&svg, e))?;
    }
    eprintln!(
        "{} settings in {:.1} s; table and plots in {}",
        rows.len(),
        started.elapsed().as_secs_f64(),
        dir.display()
    );
    Ok(())
}

fn load(path: &Path) -> Result<Scene, Failure> {
    Scene::from_path(path).map_err(|e| input_error(format!("{}: {e}", path.display())))
}

/// Prints the scene's warnings, once all of the input is accepted (input at fault gets
/// one line on stderr, its error).
fn warn(path: &Path, scene: &Scene) {
    for w in scene.warnings() {
        eprintln!("warning: {}: {w}", path.display());
    }
}

/// Refuses output paths that name the same file, or a file the run reads (`inputs`): the
/// run would write one output over another, or over its own scene.
fn check_outputs(
    outputs: &[(&str, Option<&Path>)],
    inputs: &[(&str, Option<&Path>)],
) -> Result<(), Failure> {
    for (k, &(flag, path)) in outputs.iter().enumerate() {
        let Some(path) = path else { continue };
        let earlier = outputs[..k]
            .iter()
            .map(|&(f, p)| (f, p, "the same file as"));
        let read = inputs.iter().map(|&(f, p)| (f, p, "the file read as"));
        for (other, p, what) in earlier.chain(read) {
            if p.is_some_and(|p| same_file(p, path)) {
                return Err(input_error(format!(
                    "{flag} {}: {what} {other}",
                    path.display()
                )));
            }
        }
    }
    Ok(())
}

/// Whether two paths name one file: compared resolved (the file itself where it exists,
/// else its resolved directory and name).
fn same_file(a: &Path, b: &Path) -> bool {
    fn resolved(p: &Path) -> PathBuf {
        if let Ok(c) = p.canonicalize() {
            return c;
        }
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        match (dir.canonicalize(), p.file_name()) {
            (Ok(d), Some(name)) => d.join(name),
            _ => p.to_path_buf(),
        }
    }
    a == b || resolved(a) == resolved(b)
}

fn run_file(args: &RunArgs) -> Result<(), Failure> {
    if let Some(n) = args.threads {
        task_pool(n)?;
    }
    let scene = load(&args.scene)?;
    let steps = args.steps.unwrap_or_else(|| scene.default_steps());
    let poses = match &args.poses {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| input_error(format!("{}: {e}", p.display())))?;
            bevy_marble::output::parse_poses(&text, scene.boards.len())
                .map_err(|e| input_error(format!("{}: {e}", p.display())))?
        }
        None => Vec::new(),
    };
    check_outputs(
        &[
            ("--csv", args.csv.as_deref()),
            ("--plot", args.plot.as_deref()),
            ("--html", args.html.as_deref()),
        ],
        &[
            ("SCENE", Some(&args.scene)),
            ("--poses", args.poses.as_deref()),
        ],
    )?;
    warn(&args.scene, &scene);
    let outputs = Outputs {
        poses,
        csv: args.csv.clone(),
        every: args.every,
        plot: args.plot.clone(),
        html: args.html.clone(),
        quiet: args.quiet,
    };
    simulate(&scene, &args.scene.display().to_string(), steps, &outputs)
}

/// Sets up the compute task pool with `n` threads before the engine's default (the
/// available cores) would.
#[cfg(feature = "parallel")]
fn task_pool(n: u16) -> Result<(), Failure> {
    let n = usize::from(n);
    let pool = bevy_tasks::ComputeTaskPool::get_or_init(|| {
        bevy_tasks::TaskPoolBuilder::new().num_threads(n).build()
    });
    if pool.thread_num() == n {
        Ok(())
    } else {
        Err(other_error(format!(
            "--threads {n}: the task pool already has {} threads",
            pool.thread_num()
        )))
    }
}

#[cfg(not(feature = "parallel"))]
fn task_pool(n: u16) -> Result<(), Failure> {
    if n == 1 {
        Ok(())
    } else {
        Err(input_error(format!(
            "--threads {n}: this marble was built without the `parallel` feature and runs on one thread"
        )))
    }
}

fn run_default() -> Result<(), Failure> {
    let scene = scenes::default_scene();
    let dir = Path::new("marble-out");
    std::fs::create_dir_all(dir)
        .map_err(|e| other_error(format!("{}: cannot create: {e}", dir.display())))?;
    let scene_path = dir.join("default.ron");
    std::fs::write(&scene_path, scene.to_ron_string())
        .map_err(|e| other_error(format!("{}: {e}", scene_path.display())))?;
    let outputs = Outputs {
        poses: Vec::new(),
        csv: Some(dir.join("default.csv")),
        every: 12,
        plot: Some(dir.join("default.svg")),
        html: Some(dir.join("default.html")),
        quiet: false,
    };
    simulate(
        &scene,
        "built-in default scene",
        scene.default_steps(),
        &outputs,
    )?;
    println!("  scene            {}", scene_path.display());
    Ok(())
}

/// What a run reads besides the scene, and what it writes.
struct Outputs {
    poses: Vec<bevy_marble::output::PoseRow>,
    csv: Option<PathBuf>,
    every: u64,
    plot: Option<PathBuf>,
    html: Option<PathBuf>,
    quiet: bool,
}

fn simulate(scene: &Scene, name: &str, steps: u64, out: &Outputs) -> Result<(), Failure> {
    use bevy_marble::replay::{Recorder, ReplayOptions};
    use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
    let mut sim = Simulation::from_scene(scene).map_err(|e| input_error(format!("{name}: {e}")))?;
    let io = |p: &Path, e: std::io::Error| other_error(format!("{}: {e}", p.display()));
    let mut csv_file = match out.csv.as_deref() {
        Some(p) => {
            let mut f = AtomicFile::create(p).map_err(|e| io(p, e))?;
            use std::io::Write;
            writeln!(f.writer(), "{CSV_HEADER}").map_err(|e| io(p, e))?;
            write_csv_rows(f.writer(), &sim, 0, scene.dt).map_err(|e| io(p, e))?;
            Some((p, f))
        }
        None => None,
    };
    // Every output file is opened before the run, so that a bad path fails at once.
    let open = |p: &Option<PathBuf>| -> Result<Option<(PathBuf, AtomicFile)>, Failure> {
        p.as_ref()
            .map(|p| Ok((p.clone(), AtomicFile::create(p).map_err(|e| io(p, e))?)))
            .transpose()
    };
    let (plot_file, html_file) = (open(&out.plot)?, open(&out.html)?);
    // The pictures, the page and the summary come from one recording of the run.
    let recording = out.plot.is_some() || out.html.is_some() || !out.quiet;
    let mut recorder = recording.then(|| Recorder::new(&mut sim, steps, ReplayOptions::default()));
    // The bar appears once a run has taken a second, on stderr, and only on a terminal.
    let bar = ProgressBar::with_draw_target(Some(steps), ProgressDrawTarget::hidden());
    bar.set_style(
        ProgressStyle::with_template("{bar:40.cyan/blue} {percent:>3}%  {msg}  eta {eta}")
            .expect("a valid template"),
    );
    let (started, mut stepping) = (Instant::now(), std::time::Duration::ZERO);
    let mut shown = out.quiet;
    let mut poses = out.poses.iter().peekable();
    for step in 1..=steps {
        while let Some(row) = poses.next_if(|r| r.step == step) {
            let board = sim.boards()[row.board];
            sim.world_mut().entity_mut(board).insert(NextPose {
                position: row.position,
                rotation: row.rotation,
            });
        }
        let t = Instant::now();
        sim.step();
        stepping += t.elapsed();
        if (step.is_multiple_of(out.every) || step == steps)
            && let Some((p, f)) = csv_file.as_mut()
        {
            write_csv_rows(f.writer(), &sim, step, scene.dt).map_err(|e| io(p, e))?;
        }
        if let Some(r) = recorder.as_mut() {
            r.after_step(&sim, step);
        }
        if step % 64 == 0 {
            if !shown && started.elapsed().as_secs_f32() > 1.0 {
                bar.set_draw_target(ProgressDrawTarget::stderr());
                shown = true;
            }
            bar.set_message(format!("{:.2} s simulated", step as f64 * scene.dt as f64));
            bar.set_position(step);
        }
    }
    bar.finish_and_clear();
    let mut written = Vec::new();
    if let Some((p, f)) = csv_file {
        f.commit().map_err(|e| io(p, e))?;
        written.push(p.to_path_buf());
    }
    let Some(recorder) = recorder else {
        return Ok(());
    };
    let rec = recorder.finish(name);
    if let Some((p, mut f)) = plot_file {
        use std::io::Write;
        let svg = bevy_marble::output::plot_svg(&rec).map_err(|e| io(&p, e))?;
        f.writer()
            .write_all(svg.as_bytes())
            .map_err(|e| io(&p, e))?;
        f.commit().map_err(|e| io(&p, e))?;
        written.push(p);
    }
    if let Some((p, mut f)) = html_file {
        rec.write_html(f.writer()).map_err(|e| io(&p, e))?;
        f.commit().map_err(|e| io(&p, e))?;
        written.push(p);
    }
    if !out.quiet {
        print_summary(
            scene,
            &sim,
            &rec,
            steps,
            started.elapsed(),
            stepping,
            &written,
        );
    }
    Ok(())
}

/// The table at the end of a run.
fn print_summary(
    scene: &Scene,
    sim: &Simulation,
    rec: &bevy_marble::replay::Recording,
    steps: u64,
    wall: std::time::Duration,
    stepping: std::time::Duration,
    written: &[PathBuf],
) {
    let n = sim.marbles().len();
    let per = stepping.as_secs_f64() * 1e9 / (n.max(1) as f64 * steps.max(1) as f64);
    let r = rec.radius_max.max(f32::MIN_POSITIVE);
    let depth = |d: f32| format!("{:.3} mm ({:.1}% of r)", d * 1e3, 100.0 * d / r);
    let quarantined = sim.quarantined();
    let last = rec.frames() - 1;
    println!("{}", rec.title);
    let row = |k: &str, v: String| println!("  {k:<16} {v}");
    row(
        "simulated",
        format!(
            "{:.3} s: {steps} steps of {} s, {}",
            steps as f64 * scene.dt as f64,
            scene.dt,
            match sim.world().resource::<StepConfig>().substeps {
                1 => "one substep each".to_owned(),
                k => format!("{k} substeps each"),
            }
        ),
    );
    row("marbles, boards", format!("{n}, {}", sim.boards().len()));
    row(
        "wall time",
        format!(
            "{:.3} s ({:.3} s stepping)",
            wall.as_secs_f64(),
            stepping.as_secs_f64()
        ),
    );
    row("per marble-step", format!("{per:.0} ns"));
    row(
        "impacts",
        format!(
            "{} (hardest {:.3} m/s)",
            rec.impact_count, rec.fastest_impact
        ),
    );
    let pair = if scene.marble_collisions {
        format!(", marble into marble {}", depth(rec.deepest_pair))
    } else {
        String::new()
    };
    row(
        "deepest",
        format!(
            "marble into board {}{pair}, over {} frames",
            depth(rec.deepest_board),
            rec.frames()
        ),
    );
    row(
        "energy",
        format!(
            "{:.6} J at the start, {:.6} J at the end",
            rec.energy[0], rec.energy[last]
        ),
    );
    row(
        "fastest at end",
        format!(
            "{:.4} m/s (mean {:.4} m/s)",
            rec.speed_max[last], rec.speed_mean[last]
        ),
    );
    row(
        "quarantined",
        if quarantined.is_empty() {
            "none".to_owned()
        } else {
            format!("{} (marbles {quarantined:?})", quarantined.len())
        },
    );
    row("asleep", format!("{}", sim.asleep()));
    if !rec.sensor_entries.is_empty() {
        // Entries summed by sensor name, in the order the names first appear.
        let mut by_name: Vec<(&str, u64, usize)> = Vec::new();
        for (name, n) in &rec.sensor_entries {
            match by_name.iter_mut().find(|(m, _, _)| m == name) {
                Some(entry) => {
                    entry.1 += n;
                    entry.2 += 1;
                }
                None => by_name.push((name, *n, 1)),
            }
        }
        let text: Vec<String> = by_name
            .iter()
            .map(|(name, n, count)| {
                let name = if name.is_empty() { "unnamed" } else { name };
                format!("{name} ({count}) {n}")
            })
            .collect();
        row("sensors entered", text.join(", "));
    }
    for (k, p) in written.iter().enumerate() {
        row(if k == 0 { "written" } else { "" }, p.display().to_string());
    }
}
