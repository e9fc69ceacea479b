//! rapier3d on bevy_marble's three bench scenes ([`BenchScene`]), timed the way
//! bevy_marble's `benches/step.rs` times its `marble_collisions` group: one step per
//! iteration, the world rebuilt outside the timed region every 60 steps (1 s at 1/60 s),
//! marble–marble collisions on, `Throughput::Elements(n)` so that criterion reports
//! marble-steps per second (ns per marble-step = 1e9 / that).
//!
//! `cargo bench --bench rapier` (from this folder).

use std::time::{Duration, Instant};

use bench_rapier::build;
use bevy_marble::Scene;
use bevy_marble::scenes::BenchScene;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

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

criterion_group!(benches, rapier);
criterion_main!(benches);
