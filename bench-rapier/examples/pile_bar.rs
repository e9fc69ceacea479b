//! Bench scene (b) in rapier against the pile bar of bevy_marble's `examples/marble_pile.rs`:
//! after the pour (6 s by default), the fastest marble, how many move faster than 5 cm/s,
//! how many are out of the box (centre beyond a wall's inner face or under the floor), the
//! deepest marble–marble overlap as a share of the radius, and the time spent stepping.
//!
//! ```text
//! cargo run --release --example pile_bar -- [MARBLES] [SOLVER_ITERATIONS] [SECONDS]
//! ```
//!
//! Defaults: 1,000 marbles, rapier's default `num_solver_iterations` (its soft-constraint
//! substeps, 4), 6 s. One rapier step per 1/60 s scene step, sleeping at rapier's default.

use std::time::{Duration, Instant};

use bench_rapier::{build, inner_half};
use bevy_marble::scenes;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize| {
        args.get(i)
            .map(|s| s.parse::<u64>().expect("a whole number"))
    };
    let n = arg(0).unwrap_or(1000) as usize;
    let scene = scenes::pour_box(n);
    let mut world = build(&scene);
    if let Some(iterations) = arg(1) {
        world.params.num_solver_iterations = iterations as usize;
    }
    let seconds = arg(2).unwrap_or(6) as f32;
    let steps = (seconds / scene.dt).round() as u64;
    let r = scene.marbles[0].radius;
    let mut stepping = Duration::ZERO;
    for _ in 0..steps {
        let t = Instant::now();
        world.step();
        stepping += t.elapsed();
    }
    let stats = world.stats(inner_half(&scene));
    let states: Vec<([f32; 3], f32)> = world
        .marbles
        .iter()
        .map(|&h| {
            let b = &world.bodies[h];
            (b.translation().to_array(), b.linvel().length())
        })
        .collect();
    let moving = states.iter().filter(|s| s.1 >= 0.05).count();
    // The deepest overlap: every pair, sorted by x so that only neighbours within a
    // diameter along x are compared.
    let mut by_x: Vec<[f32; 3]> = states.iter().map(|s| s.0).collect();
    by_x.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut deepest = 0.0f32;
    for (k, a) in by_x.iter().enumerate() {
        for b in &by_x[k + 1..] {
            if b[0] - a[0] > 2.0 * r {
                break;
            }
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            deepest = deepest.max(2.0 * r - d);
        }
    }
    println!(
        "rapier3d, {n} marbles, {} solver iterations, after {seconds} s: fastest {:.4} m/s, \
         {moving} above 5 cm/s, {} out, {} asleep, deepest overlap {:.4} r; {:.2} s stepping, \
         {:.0} ns per marble-step",
        world.params.num_solver_iterations,
        stats.max_speed,
        stats.outside,
        stats.sleeping,
        deepest / r,
        stepping.as_secs_f64(),
        stepping.as_nanos() as f64 / (steps as f64 * n as f64)
    );
}
