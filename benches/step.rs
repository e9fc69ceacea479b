//! Steps N marbles on a 1°-tilted walled board (`scenes::walled_board`, bench scene (a)):
//! the cost of one marble-step of the smooth-surface model, for N = 1k, 10k, 100k.
//!
//! The `rolling` group steps 10,000 of them with rolling off and on; the
//! `marble_collisions` group steps the three bench scenes (a), (b), (c) with marble–marble
//! collisions on.
//!
//! `cargo bench --bench step`; criterion reports the time per step and, with
//! `Throughput::Elements(N)`, marble-steps per second (ns per marble-step = 1e9 / that).
//!
//! On a smooth tilted board the marbles slide downhill for ever and would end up pressed
//! against the low wall (through each other: marble–marble contact is off). To measure
//! the scene as defined, the simulation is rebuilt, outside the timed region, every
//! 60 steps (1 s): the marbles slide at most 8.5 cm, so a few rows reach the low wall.

use std::time::{Duration, Instant};

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

const STEPS_PER_BUILD: u64 = 60;

/// Benchmarks one step of `scene` under `id`, rebuilding the simulation outside the timing
/// every [`STEPS_PER_BUILD`] steps.
fn bench_scene(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    id: BenchmarkId,
    scene: &Scene,
) {
    let fresh = || Simulation::from_scene(scene).expect("bench scene is valid");
    let mut sim = fresh();
    group.throughput(Throughput::Elements(scene.marbles.len() as u64));
    group.bench_function(id, |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                if sim.steps() >= STEPS_PER_BUILD {
                    sim = fresh();
                }
                let start = Instant::now();
                sim.step();
                total += start.elapsed();
            }
            total
        })
    });
}

fn walled_board(c: &mut Criterion) {
    let mut group = c.benchmark_group("walled_board");
    for n in [1_000usize, 10_000, 100_000] {
        group.sample_size(if n >= 100_000 { 10 } else { 20 });
        bench_scene(
            &mut group,
            BenchmarkId::from_parameter(n),
            &scenes::walled_board(n),
        );
    }
    group.finish();
}

/// The same 10,000-marble walled board with rolling off (the smooth model: no spin stored,
/// no rolling system run) and on (spin, friction and rolling, `rolling: true`).
fn rolling(c: &mut Criterion) {
    let mut group = c.benchmark_group("rolling");
    group.sample_size(20);
    for on in [false, true] {
        let mut scene = scenes::walled_board(10_000);
        scene.rolling = on;
        let name = if on { "on" } else { "off" };
        bench_scene(&mut group, BenchmarkId::from_parameter(name), &scene);
    }
    group.finish();
}

/// The three bench scenes with marble–marble collisions on ([`scenes::BenchScene`]): (a)
/// the walled board (marbles never touch each other, so this is the broad phase's cost),
/// (b) marbles poured into a box (dense contact; the scene runs 8 substeps per 1/60 s
/// step) and (c) the labyrinth scaled to N. Throughput is marble-steps.
fn marble_collisions(c: &mut Criterion) {
    let mut group = c.benchmark_group("marble_collisions");
    for (kind, sizes) in [
        (
            scenes::BenchScene::WalledBoard,
            &[1_000usize, 10_000, 100_000][..],
        ),
        (scenes::BenchScene::PourBox, &[1_000, 10_000][..]),
        (scenes::BenchScene::Labyrinth, &[1_000, 10_000, 100_000][..]),
    ] {
        for &n in sizes {
            let mut scene = kind.build(n);
            scene.marble_collisions = true;
            group.sample_size(10);
            bench_scene(&mut group, BenchmarkId::new(kind.name(), n), &scene);
        }
    }
    group.finish();
}

criterion_group!(benches, walled_board, rolling, marble_collisions);
criterion_main!(benches);
