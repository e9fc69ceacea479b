//! A quick timing of rapier3d on bevy_marble's bench scenes, without criterion.
//!
//! For each (scene, n): build, 10 warm-up steps, then 60 timed steps; prints a markdown table
//! of nanoseconds per marble-step. Marble–marble collisions are on in every scene, as in
//! `benches/step.rs`'s `marble_collisions` group of bevy_marble.
//!
//! ```text
//! cargo run --release -- [--n 1000,10000] [--scene pour_box,labyrinth] [--check] [--substeps]
//! ```
//!
//! `--check` also runs each scene 120 steps from a fresh build and prints where the marbles
//! are (in the first board's frame) and how fast the fastest goes. `--substeps` runs the
//! scene's substeps as separate rapier steps (see `bench_rapier::build_substepped`).

use std::time::Instant;

use bench_rapier::{RapierWorld, build, build_substepped, inner_half};
use bevy_marble::Scene;
use bevy_marble::scenes::BenchScene;

const WARM_UP: usize = 10;
const TIMED: usize = 60;
const CHECK_STEPS: usize = 120;

fn main() {
    let mut sizes: Option<Vec<usize>> = None;
    let mut names: Option<Vec<String>> = None;
    let mut check = false;
    let mut substeps = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--n" => {
                let list = args.next().expect("--n needs a list, e.g. 1000,10000");
                sizes = Some(
                    list.split(',')
                        .map(|s| s.trim().parse().expect("--n takes integers"))
                        .collect(),
                );
            }
            "--scene" => {
                let list = args.next().expect("--scene needs a list of scene names");
                names = Some(list.split(',').map(|s| s.trim().to_owned()).collect());
            }
            "--check" => check = true,
            "--substeps" => substeps = true,
            "-h" | "--help" => {
                println!(
                    "bench-rapier [--n N,..] [--scene walled_board,pour_box,labyrinth] \
                     [--check] [--substeps]"
                );
                return;
            }
            other => panic!("unknown argument {other:?} (try --help)"),
        }
    }
    let make = |scene: &Scene| {
        if substeps {
            build_substepped(scene)
        } else {
            build(scene)
        }
    };

    let mut cases = Vec::new();
    for (kind, default_sizes) in [
        (BenchScene::WalledBoard, &[1_000usize, 10_000, 100_000][..]),
        (BenchScene::PourBox, &[1_000, 10_000][..]),
        (BenchScene::Labyrinth, &[1_000, 10_000, 100_000][..]),
    ] {
        if let Some(names) = &names
            && !names.iter().any(|n| n == kind.name())
        {
            continue;
        }
        for &n in sizes.as_deref().unwrap_or(default_sizes) {
            cases.push((kind, n));
        }
    }

    println!(
        "rapier3d 0.36, {} ({} warm-up steps, {} timed)\n",
        if substeps {
            "scene substeps as rapier steps"
        } else {
            "one rapier step per scene step"
        },
        WARM_UP,
        TIMED
    );
    println!("| scene | n | ns per marble-step |");
    println!("| --- | ---: | ---: |");
    for &(kind, n) in &cases {
        let scene = bench_scene(kind, n);
        let mut world = make(&scene);
        for _ in 0..WARM_UP {
            world.step();
        }
        let start = Instant::now();
        for _ in 0..TIMED {
            world.step();
        }
        let ns = start.elapsed().as_nanos() as f64 / (TIMED * scene.marbles.len()) as f64;
        println!("| {} | {} | {:.1} |", kind.name(), n, ns);
    }

    if check {
        println!(
            "\nAfter {CHECK_STEPS} steps, marble centres in the first board's frame \
             (inner half-width of the walls for reference):\n"
        );
        println!(
            "| scene | n | walls' inner half | min y | max abs x | max abs z | max speed m/s \
             | outside | non-finite | sleeping | skipped parts |"
        );
        println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
        for &(kind, n) in &cases {
            let scene = bench_scene(kind, n);
            let mut world: RapierWorld = make(&scene);
            for _ in 0..CHECK_STEPS {
                world.step();
            }
            let s = world.stats(inner_half(&scene));
            println!(
                "| {} | {} | {} | {:.5} | {:.5} | {:.5} | {:.4} | {} | {} | {} | {} |",
                kind.name(),
                n,
                inner_half(&scene).map_or("-".into(), |h| format!("{h:.5}")),
                s.min_y,
                s.max_abs_x,
                s.max_abs_z,
                s.max_speed,
                s.outside,
                s.non_finite,
                s.sleeping,
                world.skipped_parts,
            );
        }
    }
}

/// The bench scene with marble–marble collisions on (as bevy_marble's bench times it).
fn bench_scene(kind: BenchScene, n: usize) -> Scene {
    let mut scene = kind.build(n);
    scene.marble_collisions = true;
    scene
}
