//! Runs one bench scene in both engines, bevy_marble and rapier3d, and prints where the
//! marbles are (in the first board's frame) at a few checkpoints: a check that the rapier
//! mapping simulates the same scene.
//!
//! ```text
//! cargo run --release --example compare -- [scene] [n] [steps]
//! ```
//!
//! Defaults: every bench scene, n = 1000, 240 steps (checkpoints every 60). Marble–marble
//! collisions are on, as in the benches.

use std::time::{Duration, Instant};

use bench_rapier::{Stats, board_pose_at, build, inner_half};
use bevy_marble::Simulation;
use bevy_marble::scenes::BenchScene;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kinds: Vec<BenchScene> = match args.first() {
        Some(name) => vec![BenchScene::from_name(name).expect("a bench scene name")],
        None => BenchScene::ALL.to_vec(),
    };
    let n: usize = args.get(1).map_or(1000, |s| s.parse().expect("n"));
    let steps: u64 = args.get(2).map_or(240, |s| s.parse().expect("steps"));

    println!(
        "| scene | n | step | engine | walls' inner half | min y | max abs x | max abs z \
         | max speed m/s | outside | non-finite | ms per step |"
    );
    println!("| --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for kind in kinds {
        let mut scene = kind.build(n);
        scene.marble_collisions = true;
        let half = inner_half(&scene);
        let mut sim = Simulation::from_scene(&scene).expect("a valid bench scene");
        let mut world = build(&scene);
        let (mut t_sim, mut t_rapier) = (Duration::ZERO, Duration::ZERO);
        for step in 0..=steps {
            if step > 0 {
                let start = Instant::now();
                sim.step();
                t_sim += start.elapsed();
                let start = Instant::now();
                world.step();
                t_rapier += start.elapsed();
            }
            if step % 60 == 0 || step == steps {
                let frame = board_pose_at(&scene.boards[0], step as f32 * scene.dt);
                let ours = Stats::of(
                    frame,
                    (0..sim.marbles().len()).map(|i| {
                        let (x, v) = sim.marble_world_state(i);
                        (x.to_array(), v.to_array())
                    }),
                    half,
                );
                let theirs = world.stats(half);
                for (engine, s, t) in [("bevy_marble", ours, t_sim), ("rapier", theirs, t_rapier)] {
                    println!(
                        "| {} | {} | {} | {} | {} | {:.5} | {:.5} | {:.5} | {:.4} | {} | {} | {:.3} |",
                        kind.name(),
                        n,
                        step,
                        engine,
                        half.map_or("-".into(), |h| format!("{h:.5}")),
                        s.min_y,
                        s.max_abs_x,
                        s.max_abs_z,
                        s.max_speed,
                        s.outside,
                        s.non_finite,
                        t.as_secs_f64() * 1e3 / step.max(1) as f64,
                    );
                }
            }
        }
    }
}
