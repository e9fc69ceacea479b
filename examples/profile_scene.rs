//! Steps a bench scene for profiling: `cargo run --release --example profile_scene --
//! SCENE N STEPS [collisions|off|rolling|noboards]`, e.g. `walled_board 10000 60 collisions`
//! (`rolling`: spin and friction on, marble collisions off). SCENE `labyrinth_steady` is
//! the labyrinth from where it is after 5 s (building it steps the labyrinth for 5 s);
//! SCENE `pile_asleep` is bench scene (b) with sleeping on, stepped for 6 s before the
//! timed steps (the whole pile is asleep by then; the `settled_pile` bench's `asleep`).
use bevy_marble::prelude::*;
use bevy_marble::scenes::BenchScene;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("walled_board", |s| s);
    let n: usize = args.get(2).map_or(10_000, |s| s.parse().expect("N"));
    let steps: usize = args.get(3).map_or(60, |s| s.parse().expect("STEPS"));
    let (label, mut scene) = if name == "labyrinth_steady" {
        (name, bevy_marble::scenes::labyrinth_steady(n))
    } else if name == "pile_asleep" {
        (name, bevy_marble::scenes::pour_box_sleeping(n))
    } else {
        let kind = BenchScene::from_name(name).expect("scene");
        (kind.name(), kind.build(n))
    };
    if let Some(c) = args.get(4) {
        scene.marble_collisions = c == "collisions";
        scene.rolling |= c == "rolling";
        if c == "noboards" {
            scene.boards.clear();
        }
    }
    let mut sim = Simulation::from_scene(&scene).expect("valid scene");
    if name == "pile_asleep" {
        for _ in 0..bevy_marble::scenes::SETTLE_STEPS {
            sim.step();
        }
        assert_eq!(sim.asleep(), n, "the pile is asleep after 6 s");
    }
    let start = std::time::Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let ns = start.elapsed().as_nanos() as f64 / (steps * n) as f64;
    println!("{label} x {n}, {steps} steps: {ns:.0} ns per marble-step");
}
