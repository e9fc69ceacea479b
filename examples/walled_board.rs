//! Steps the bench scene (a) headless and prints the time per marble-step:
//! `cargo run --release --example walled_board -- 10000 600`.

use std::time::Instant;

use bevy_marble::prelude::*;
use bevy_marble::scenes;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let steps: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(600);
    let mut sim = Simulation::from_scene(&scenes::walled_board(n)).expect("valid scene");
    let start = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let ns = start.elapsed().as_secs_f64() * 1e9 / (n * steps) as f64;
    let (x, v) = sim.marble_state(0);
    println!("{n} marbles, {steps} steps: {ns:.1} ns per marble-step; marble 0 at {x} moving {v}");
}
