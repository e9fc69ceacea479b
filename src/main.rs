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
    /// Write an SVG plot of the marbles' heights against time.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// No progress bar or summary.
    #[arg(long)]
    quiet: bool,
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
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("error: bad arguments");
            eprintln!("{first}");
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        None => run_default(),
        Some(Command::Run(args)) => run_file(&args),
        Some(Command::Check { scene }) => load(&scene).map(|s| {
            println!(
                "{}: ok ({} boards, {} marbles)",
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
    let scene =
        Scene::from_path(path).map_err(|e| input_error(format!("{}: {e}", path.display())))?;
    for w in scene.warnings() {
        eprintln!("warning: {}: {w}", path.display());
    }
    Ok(scene)
}

fn run_file(args: &RunArgs) -> Result<(), Failure> {
    let scene = load(&args.scene)?;
    let steps = args.steps.unwrap_or_else(|| scene.default_steps());
    simulate(
        &scene,
        &args.scene.display().to_string(),
        steps,
        args.csv.as_deref(),
        args.every,
        args.plot.as_deref(),
        args.quiet,
    )
}

fn run_default() -> Result<(), Failure> {
    let scene = scenes::default_scene();
    let dir = Path::new("marble-out");
    std::fs::create_dir_all(dir)
        .map_err(|e| other_error(format!("{}: cannot create: {e}", dir.display())))?;
    let scene_path = dir.join("default.ron");
    std::fs::write(&scene_path, scene.to_ron_string())
        .map_err(|e| other_error(format!("{}: {e}", scene_path.display())))?;
    let csv = dir.join("default.csv");
    let plot = dir.join("default.svg");
    simulate(
        &scene,
        "built-in default scene",
        scene.default_steps(),
        Some(&csv),
        12,
        Some(&plot),
        false,
    )?;
    println!(
        "outputs: {}, {}, {}",
        scene_path.display(),
        csv.display(),
        plot.display()
    );
    Ok(())
}

fn simulate(
    scene: &Scene,
    name: &str,
    steps: u64,
    csv: Option<&Path>,
    every: u64,
    plot: Option<&Path>,
    quiet: bool,
) -> Result<(), Failure> {
    let mut sim = Simulation::from_scene(scene).map_err(|e| input_error(format!("{name}: {e}")))?;
    let io = |p: &Path, e: std::io::Error| other_error(format!("{}: {e}", p.display()));
    let mut csv_file = match csv {
        Some(p) => {
            let mut f = AtomicFile::create(p).map_err(|e| io(p, e))?;
            use std::io::Write;
            writeln!(f.writer(), "{CSV_HEADER}").map_err(|e| io(p, e))?;
            write_csv_rows(f.writer(), &sim, 0, scene.dt).map_err(|e| io(p, e))?;
            Some((p, f))
        }
        None => None,
    };
    let mut heights = bevy_marble::output::HeightTrace::new(plot.is_some(), sim.marbles().len());
    heights.record(&sim, 0.0);
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(steps)
    };
    let started = Instant::now();
    for step in 1..=steps {
        sim.step();
        if step % every == 0 || step == steps {
            if let Some((p, f)) = csv_file.as_mut() {
                write_csv_rows(f.writer(), &sim, step, scene.dt).map_err(|e| io(p, e))?;
            }
            heights.record(&sim, (step as f64 * scene.dt as f64) as f32);
        }
        if step % 64 == 0 {
            bar.set_position(step);
        }
    }
    bar.finish_and_clear();
    let elapsed = started.elapsed();
    if let Some((p, f)) = csv_file {
        f.commit().map_err(|e| io(p, e))?;
    }
    if let Some(p) = plot {
        heights
            .write_svg(p, name)
            .map_err(|e| other_error(format!("{}: {e}", p.display())))?;
    }
    if !quiet {
        let n = sim.marbles().len().max(1) as f64;
        let per = elapsed.as_secs_f64() * 1e9 / (n * steps.max(1) as f64);
        let quarantined = sim.quarantined();
        println!(
            "{name}: {steps} steps of {} s ({} s simulated), {} marbles, {} boards, {:.3} s wall, {:.0} ns per marble-step{}",
            scene.dt,
            (steps as f64 * scene.dt as f64) as f32,
            sim.marbles().len(),
            sim.boards().len(),
            elapsed.as_secs_f64(),
            per,
            if quarantined.is_empty() {
                String::new()
            } else {
                format!(", quarantined (non-finite) marbles: {quarantined:?}")
            }
        );
    }
    Ok(())
}
