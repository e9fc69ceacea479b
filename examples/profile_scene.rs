//! Steps a bench scene for profiling: `cargo run --release --example profile_scene --
//! SCENE N STEPS [collisions|off|rolling|noboards|events|sensors|each|save FILE]`, e.g.
//! `walled_board 10000 60 collisions` (`each`: the scene's own settings, every step timed
//! and printed on its own; `rolling`: spin and friction on, marble collisions off;
//! `events`: the scene's own settings with impacts and contacts recorded as messages;
//! `sensors`: the scene's own settings and 48 sensors, 10 cm boxes, spread over the
//! marbles; `save FILE`: the scene as built written to a scene file, nothing stepped).
//! SCENE `labyrinth_steady` is the labyrinth from where it is after 5 s (building it steps
//! the labyrinth for 5 s); SCENE `pile_asleep` is bench scene (b) with sleeping on, stepped
//! for 6 s before the timed steps (the whole pile is asleep by then; the `settled_pile`
//! bench's `asleep`). SCENE may also be a scene file (`.ron` or `.json`; N is then
//! ignored), such as one written by `profile_scene labyrinth_steady N 0 save FILE`, which
//! profiles a scene's timed steps without its set-up.
use bevy_marble::prelude::*;
use bevy_marble::scenes::BenchScene;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("walled_board", |s| s);
    let n: usize = args.get(2).map_or(10_000, |s| s.parse().expect("N"));
    let steps: usize = args.get(3).map_or(60, |s| s.parse().expect("STEPS"));
    let (label, mut scene) = if name.ends_with(".ron") || name.ends_with(".json") {
        (name, Scene::from_path(name).expect("a valid scene file"))
    } else if name == "labyrinth_steady" {
        (name, bevy_marble::scenes::labyrinth_steady(n))
    } else if name == "pile_asleep" {
        (name, bevy_marble::scenes::pour_box_sleeping(n))
    } else {
        let kind = BenchScene::from_name(name).expect("scene");
        (kind.name(), kind.build(n))
    };
    let events = args.get(4).is_some_and(|c| c == "events");
    let sensors = args.get(4).is_some_and(|c| c == "sensors");
    let each = args.get(4).is_some_and(|c| c == "each");
    let save = args.get(4).is_some_and(|c| c == "save");
    if let Some(c) = args
        .get(4)
        .filter(|_| !events && !sensors && !each && !save)
    {
        scene.marble_collisions = c == "collisions";
        scene.rolling |= c == "rolling";
        if c == "noboards" {
            scene.boards.clear();
        }
    }
    if save {
        let file = args.get(5).expect("save FILE");
        std::fs::write(file, scene.to_ron_string()).expect("the scene file is written");
        return;
    }
    let n = if name.ends_with(".ron") || name.ends_with(".json") {
        scene.marbles.len()
    } else {
        n
    };
    let mut sim = Simulation::from_scene(&scene).expect("valid scene");
    sim.world_mut().resource_mut::<StepConfig>().events = events;
    if sensors {
        let (mut lo, mut hi) = (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY);
        for m in &scene.marbles {
            let p = glam::Vec3::from_array(m.position);
            (lo, hi) = (lo.min(p), hi.max(p));
        }
        for i in 0..8 {
            for k in 0..6 {
                let at = glam::Vec3::new(
                    lo.x + (hi.x - lo.x) * (i as f32 + 0.5) / 8.0,
                    0.5 * (lo.y + hi.y),
                    lo.z + (hi.z - lo.z) * (k as f32 + 0.5) / 6.0,
                );
                sim.world_mut().spawn((
                    Sensor,
                    Collider::cuboid(glam::Vec3::splat(0.05)).expect("a valid box"),
                    Position(at),
                ));
            }
        }
    }
    if name == "pile_asleep" {
        for _ in 0..bevy_marble::scenes::SETTLE_STEPS {
            sim.step();
        }
        assert_eq!(sim.asleep(), n, "the pile is asleep after 6 s");
    }
    let start = std::time::Instant::now();
    for s in 0..steps {
        let at = std::time::Instant::now();
        sim.step();
        if each {
            let ns = at.elapsed().as_nanos() as f64 / n as f64;
            println!("step {}: {ns:.0} ns per marble", s + 1);
        }
    }
    let ns = start.elapsed().as_nanos() as f64 / (steps * n) as f64;
    println!("{label} x {n}, {steps} steps: {ns:.0} ns per marble-step");
}
