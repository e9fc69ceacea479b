//! rapier3d on bevy_marble's three bench scenes ([`BenchScene`]), timed the way
//! bevy_marble's `benches/step.rs` times its `marble_collisions` group: one step per
//! iteration, the world rebuilt outside the timed region every 60 steps (1 s at 1/60 s),
//! marble–marble collisions on, `Throughput::Elements(n)` so that criterion reports
//! marble-steps per second (ns per marble-step = 1e9 / that).
//!
//! `cargo bench --bench rapier` (from this folder).

use std::time::{Duration, Instant};

use bench_rapier::{build, inner_half};
use bevy_marble::Scene;
use bevy_marble::scenes::{BenchScene, SETTLE_STEPS};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use rapier3d::prelude::RigidBodyActivation;

const STEPS_PER_BUILD: u64 = 60;

/// Benchmarks one step of `scene` under `id`, rebuilding the world outside the timing every
/// [`STEPS_PER_BUILD`] steps.
fn bench_scene(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    id: BenchmarkId,
    scene: &Scene,
) {
    let mut world = build(scene);
    group.throughput(Throughput::Elements(scene.marbles.len() as u64));
    group.bench_function(id, |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                if world.steps() >= STEPS_PER_BUILD {
                    world = build(scene);
                }
                let start = Instant::now();
                world.step();
                total += start.elapsed();
            }
            total
        })
    });
}

fn rapier(c: &mut Criterion) {
    let mut group = c.benchmark_group("rapier");
    group.sample_size(10);
    for (kind, sizes) in [
        (BenchScene::WalledBoard, &[1_000usize, 10_000, 100_000][..]),
        (BenchScene::PourBox, &[1_000, 10_000][..]),
        (BenchScene::Labyrinth, &[1_000, 10_000, 100_000][..]),
    ] {
        for &n in sizes {
            let mut scene = kind.build(n);
            scene.marble_collisions = true;
            bench_scene(&mut group, BenchmarkId::new(kind.name(), n), &scene);
        }
    }
    group.finish();
}

/// Bench scene (c) in its steady state, as bevy_marble's `labyrinth_steady` group times
/// it: the marbles where bevy_marble's labyrinth put them after 5 s
/// ([`bevy_marble::scenes::labyrinth_steady`]), the same configuration for both engines,
/// each starting without cached contacts; rebuilt every 60 steps.
fn labyrinth_steady(c: &mut Criterion) {
    let mut group = c.benchmark_group("rapier_labyrinth_steady");
    group.sample_size(10);
    for n in [1_000usize, 10_000] {
        let scene = bevy_marble::scenes::labyrinth_steady(n);
        bench_scene(&mut group, BenchmarkId::from_parameter(n), &scene);
    }
    group.finish();
}

/// Bench scene (b)'s pile once settled, as bevy_marble's `settled_pile` group times it,
/// step after step: `awake`, every marble kept awake
/// (`RigidBodyActivation::cannot_sleep`), stepped for [`SETTLE_STEPS`] (6 s) outside the
/// timing; and `asleep`, rapier's sleeping on as by default (after 2 s below its
/// thresholds), stepped for 6 s and on until rapier has put every marble to sleep (at most
/// 60 s more; on this machine it took until 38 s, the pile stirring at up to a few cm/s
/// until then). When the pile fell asleep is printed.
fn settled_pile(c: &mut Criterion) {
    let mut group = c.benchmark_group("rapier_settled_pile");
    group.sample_size(10);
    // 1,000 marbles only, as bevy_marble's group.
    let n = 1_000usize;
    let scene = BenchScene::PourBox.build(n);
    for asleep in [false, true] {
        let mut world = build(&scene);
        if !asleep {
            for &h in &world.marbles.clone() {
                *world.bodies[h].activation_mut() = RigidBodyActivation::cannot_sleep();
            }
        }
        for _ in 0..SETTLE_STEPS {
            world.step();
        }
        while asleep && world.stats(None).sleeping < n && world.steps() < SETTLE_STEPS + 3600 {
            world.step();
        }
        let stats = world.stats(inner_half(&scene));
        eprintln!(
            "rapier, pour box of {n} after {:.2} s: {} asleep, fastest {:.4} m/s, {} outside",
            world.steps() as f32 * scene.dt,
            stats.sleeping,
            stats.max_speed,
            stats.outside
        );
        let name = if asleep { "asleep" } else { "awake" };
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::new(name, n), |b| b.iter(|| world.step()));
    }
    group.finish();
}

criterion_group!(benches, rapier, labyrinth_steady, settled_pile);
criterion_main!(benches);
