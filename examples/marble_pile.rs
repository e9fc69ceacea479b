//! Pours marbles into a walled box (bench scene (b)) and reports how the pile settles:
//! every half second, the fastest marble, how many move faster than 5 cm/s, how many are
//! out of the box (centre beyond a wall's inner face or under the floor), the deepest
//! marble–marble overlap and how many marbles touch each other; then the last time any
//! marble moved at 5 cm/s or more (checked every step) and the wall time.
//!
//! `cargo run --release --example marble_pile -- [MARBLES] [SUBSTEPS] [SOLVER_PASSES]
//! [SEED] [SECONDS] [SLEEP_MM_S]` (defaults: 1000, the scene's 8 substeps and 15 passes,
//! the scene's own start, 6 s, no sleeping). A SEED nudges every marble by up to 5 µm:
//! another start of the same pour. Try fewer substeps to see why the scene uses 8
//! (`docs/pair-solver.md`, "What piles need"). With SLEEP_MM_S, marbles slower than that many mm/s for
//! half a second fall asleep (`sleep_speed`), and the table counts the sleeping ones and
//! the wall time of each half second.

use bevy_marble::prelude::*;
use bevy_marble::scenes;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize| {
        args.get(i)
            .map(|s| s.parse::<u64>().expect("a whole number"))
    };
    let n = arg(1).unwrap_or(1000) as usize;
    let mut scene = scenes::pour_box(n);
    if let Some(substeps) = arg(2) {
        scene.substeps = substeps as u32;
    }
    if let Some(passes) = arg(3) {
        scene.solver_iterations = passes as u32;
    }
    if let Some(sleep) = arg(6) {
        scene.sleep_speed = sleep as f32 * 1e-3;
    }
    if let Some(seed) = arg(4) {
        // Nudge every marble by up to 5 µm: another start of the same pour.
        let mut state = seed as u32;
        for m in &mut scene.marbles {
            for c in &mut m.position {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *c += 1e-5 * ((state >> 8) as f32 / (1u32 << 24) as f32 - 0.5);
            }
        }
    }
    let mut sim = Simulation::from_scene(&scene).expect("the bench scene is valid");
    let r = scene.marbles[0].radius;
    // The walls' inner faces (the first wall of `scenes::walled_floor`) and the floor's top
    // at y = 0.
    let inner = match &scene.boards[0].shape {
        bevy_marble::scene::ShapeDesc::Compound(parts) => match parts[1].shape {
            bevy_marble::scene::ShapeDesc::Cuboid { half_extents } => {
                parts[1].position[0] - half_extents[0]
            }
            _ => unreachable!("the pour box's walls are cuboids"),
        },
        _ => unreachable!("the pour box is a compound"),
    };
    println!(
        "{n} marbles, dt {:.4} s in {} substeps, {} solver passes",
        scene.dt, scene.substeps, scene.solver_iterations
    );
    println!(
        "  time | fastest m/s | > 5 cm/s | out | deepest overlap / r | touching pairs | asleep | ns per marble-step"
    );
    let steps = (arg(5).unwrap_or(6) as f32 / scene.dt).round() as u64;
    let every = (0.5 / scene.dt).round() as u64;
    let start = std::time::Instant::now();
    // The last time any marble moved at 5 cm/s or more, checked every step.
    let mut last_moving = 0.0;
    // Time spent stepping, all and in the current half second.
    let (mut stepping, mut window) = (std::time::Duration::ZERO, std::time::Duration::ZERO);
    for step in 1..=steps {
        let t = std::time::Instant::now();
        sim.step();
        let took = t.elapsed();
        stepping += took;
        window += took;
        let fastest_now = (0..n)
            .map(|i| sim.marble_state(i).1.length())
            .fold(0.0, f32::max);
        if fastest_now >= 0.05 {
            last_moving = step as f32 * scene.dt;
        }
        if step % every == 0 {
            let speeds: Vec<f32> = (0..n).map(|i| sim.marble_state(i).1.length()).collect();
            let fastest = speeds.iter().copied().fold(0.0, f32::max);
            let moving = speeds.iter().filter(|&&v| v >= 0.05).count();
            let out = (0..n)
                .filter(|&i| {
                    let x = sim.marble_state(i).0;
                    x.x.abs() > inner || x.z.abs() > inner || x.y < 0.0 || !x.is_finite()
                })
                .count();
            let contacts = sim.world().resource::<MarbleContacts>();
            let deepest = contacts
                .as_slice()
                .iter()
                .map(|c| c.depth)
                .fold(0.0, f32::max);
            let asleep = sim.asleep();
            println!(
                "{:5.1} s | {fastest:11.4} | {moving:8} | {out:3} | {:19.4} | {:14} | {asleep:6} | {:.0}",
                step as f32 * scene.dt,
                deepest / r,
                contacts.len(),
                window.as_nanos() as f64 / (every as f64 * n as f64)
            );
            window = std::time::Duration::ZERO;
        }
    }
    let elapsed = start.elapsed();
    println!("last marble at 5 cm/s or more: {last_moving:.2} s");
    println!(
        "{:.2} s wall, {:.0} ns per marble-step stepping",
        elapsed.as_secs_f64(),
        stepping.as_nanos() as f64 / (steps as f64 * n as f64)
    );
}
