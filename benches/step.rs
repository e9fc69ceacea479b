//! Steps N marbles resting on a tilted, walled board (`scenes::walled_board`): the cost of
//! one marble-step of the smooth-surface model, for N = 1k, 10k, 100k.
//!
//! `cargo bench --bench step`; criterion reports time per step, and with
//! `Throughput::Elements(N)` marble-steps per second (ns per marble-step = 1e9 / that).

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

fn walled_board(c: &mut Criterion) {
    let mut group = c.benchmark_group("walled_board");
    for n in [1_000usize, 10_000, 100_000] {
        let scene = scenes::walled_board(n);
        let mut sim = Simulation::from_scene(&scene).expect("bench scene is valid");
        // Warm up: marbles settle into contact, buffers reach their size.
        for _ in 0..10 {
            sim.step();
        }
        group.throughput(Throughput::Elements(n as u64));
        if n >= 100_000 {
            group.sample_size(10);
        } else {
            group.sample_size(20);
        }
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| sim.step())
        });
    }
    group.finish();
}

criterion_group!(benches, walled_board);
criterion_main!(benches);
