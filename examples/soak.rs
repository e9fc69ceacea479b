//! A long run of the labyrinth with colliding marbles, checked as it goes:
//! `cargo run --release --example soak -- [MARBLES] [STEPS]` (default 1,000 marbles and a
//! million steps of 1/240 s, 69 simulated minutes).
//!
//! The board of `scenes::labyrinth` tilts back and forth (±0.15 rad about X, a period of
//! 30 s) instead of turning on for ever. Every 1,000 steps: no marble quarantined or
//! non-finite, every marble inside the walled floor (in the board's frame, within its
//! half-width and between the floor and 0.2 m above it), and the fastest marble's speed;
//! the resident memory at 10% of the run and at its end (`/proc/self/statm`), which must
//! not grow. Exit status 1 on the first failure, with what failed.
use std::f32::consts::TAU;

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use glam::{Quat, Vec3};

fn resident_kib() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|p| p.parse().ok())
        .unwrap_or(0);
    pages * 4
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map_or(1_000, |s| s.parse().expect("MARBLES"));
    let steps: u64 = args.get(2).map_or(1_000_000, |s| s.parse().expect("STEPS"));
    let scene = scenes::labyrinth(n);
    let half = match &scene.boards[0].shape {
        ShapeDesc::Compound(parts) => parts
            .iter()
            .map(|p| p.position[0].abs().max(p.position[2].abs()))
            .fold(0.0f32, f32::max),
        _ => unreachable!("the labyrinth is a compound"),
    };
    let mut sim = Simulation::from_scene(&scene).expect("valid scene");
    let board = sim.boards()[0];
    let (amplitude, period) = (0.15f32, 30.0f32);
    let dt = scene.dt;
    let started = std::time::Instant::now();
    let (mut fastest, mut early_kib) = (0.0f32, 0);
    for step in 0..steps {
        // θ(t) = θ0 + A sin(2π t / T): the board turns at θ'(t) about X.
        let t = step as f32 * dt;
        let rate = amplitude * TAU / period * (TAU * t / period).cos();
        sim.world_mut().get_mut::<AngularVelocity>(board).unwrap().0 = Vec3::new(rate, 0.0, 0.0);
        sim.step();
        if step % 1000 != 999 {
            continue;
        }
        if !sim.quarantined().is_empty() {
            eprintln!("step {step}: quarantined {:?}", sim.quarantined());
            std::process::exit(1);
        }
        let c = sim.world().get::<Position>(board).unwrap().0;
        let q: Quat = sim.world().get::<Rotation>(board).unwrap().0;
        for i in 0..n {
            let (x, v) = sim.marble_state(i);
            let local = q.conjugate() * (x - c);
            let inside =
                local.x.abs() <= half && local.z.abs() <= half && (-0.001..0.2).contains(&local.y);
            if !(x.is_finite() && v.is_finite() && inside) {
                eprintln!("step {step}: marble {i} at {local} in the board's frame, v = {v}");
                std::process::exit(1);
            }
            fastest = fastest.max(v.length());
        }
        if step + 1 == steps / 10 {
            early_kib = resident_kib();
        }
        if (step + 1) % (steps / 20).max(1000) == 0 {
            println!(
                "{:>8} steps ({:>6.0} s simulated, {:>5.0} s wall): fastest {:.3} m/s, resident {} KiB",
                step + 1,
                (step + 1) as f32 * dt,
                started.elapsed().as_secs_f32(),
                fastest,
                resident_kib()
            );
        }
    }
    let end_kib = resident_kib();
    println!(
        "{steps} steps of {n} marbles: every check held; fastest {fastest:.3} m/s; resident {early_kib} KiB at 10%, {end_kib} KiB at the end"
    );
    if early_kib > 0 && end_kib > early_kib + early_kib / 20 {
        eprintln!("resident memory grew by more than 5% after the first 10%");
        std::process::exit(1);
    }
}
