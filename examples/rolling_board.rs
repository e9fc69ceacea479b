//! Steps the bench scene (a) with rolling on and prints the time per marble-step:
//! `cargo run --release --example rolling_board -- 10000 60`.

use std::time::Instant;

use bevy_marble::prelude::*;
use bevy_marble::scenes;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let steps: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(60);
    let mut scene = scenes::walled_board(n);
    scene.rolling = true;
    let mut sim = Simulation::from_scene(&scene).expect("valid scene");
    let start = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let ns = start.elapsed().as_secs_f64() * 1e9 / (n * steps) as f64;
    println!("{n} rolling marbles, {steps} steps: {ns:.1} ns per marble-step");
}
