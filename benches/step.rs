//! Steps N marbles on a 1°-tilted walled board (`scenes::walled_board`, bench scene (a)):
//! the cost of one marble-step of the smooth-surface model, for N = 1k, 10k, 100k.
//!
//! The `rolling` group steps 10,000 of them with rolling off and on; the
//! `marble_collisions` group steps the three bench scenes (a), (b), (c) with marble–marble
//! collisions on; the `labyrinth_steady` group steps (c) from where it is after 5 s; the
//! `settled_pile` group steps scene (b)'s pile once it has settled, awake and asleep; the
//! `events` group steps scene (b) at 10,000 marbles with events off and on.
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
    bench_with(group, id, scene, |_| {});
}

/// [`bench_scene`] with `setup` applied to every fresh simulation.
fn bench_with(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    id: BenchmarkId,
    scene: &Scene,
    setup: impl Fn(&mut Simulation),
) {
    let fresh = || {
        let mut sim = Simulation::from_scene(scene).expect("bench scene is valid");
        setup(&mut sim);
        sim
    };
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
    for n in [1_000usize, 10_000, 100_000, 1_000_000] {
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
/// the walled board (spread marbles, mostly the broad phase's cost; only the rows that
/// reach its lower wall meet, late in each 60-step run),
/// (b) marbles poured into a box (dense contact; the scene runs 8 substeps per 1/60 s
/// step) and (c) the labyrinth scaled to N; and (b) at the fewest substeps that meet the
/// pile bar ([`scenes::POUR_BOX_BAR_SUBSTEPS`], id `pour_box_bar`). Throughput is
/// marble-steps.
fn marble_collisions(c: &mut Criterion) {
    let mut group = c.benchmark_group("marble_collisions");
    for (kind, sizes) in [
        (
            scenes::BenchScene::WalledBoard,
            &[1_000usize, 10_000, 100_000][..],
        ),
        (scenes::BenchScene::PourBox, &[1_000, 10_000, 100_000][..]),
        (scenes::BenchScene::Labyrinth, &[1_000, 10_000, 100_000][..]),
    ] {
        for &n in sizes {
            let mut scene = kind.build(n);
            scene.marble_collisions = true;
            group.sample_size(10);
            bench_scene(&mut group, BenchmarkId::new(kind.name(), n), &scene);
        }
    }
    for n in [1_000, 10_000] {
        let scene = Scene {
            substeps: scenes::POUR_BOX_BAR_SUBSTEPS,
            ..scenes::pour_box(n)
        };
        bench_scene(&mut group, BenchmarkId::new("pour_box_bar", n), &scene);
    }
    group.finish();
}

/// The practical limit for bench scene (a): a hand-written fused loop over plain f32
/// arrays (structure of arrays) doing the same smooth-surface physics in one pass per
/// step — semi-implicit Euler under gravity, then each of the board's five planes (the
/// floor and four walls of the tilted walled board, as half-spaces in world space): push
/// out of any overlap and apply the seed's equation (restitution above the threshold,
/// approach removed below it). No ECS, no continuous collision, no narrow phase.
struct Fused {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    vx: Vec<f32>,
    vy: Vec<f32>,
    vz: Vec<f32>,
    /// (normal, offset): a marble centre c is inside when n·c < offset + r.
    planes: Vec<([f32; 3], f32)>,
}

impl Fused {
    fn new(scene: &Scene) -> Fused {
        let n = scene.marbles.len();
        let mut f = Fused {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            vx: vec![0.0; n],
            vy: vec![0.0; n],
            vz: vec![0.0; n],
            planes: Vec::new(),
        };
        for m in &scene.marbles {
            f.x.push(m.position[0]);
            f.y.push(m.position[1]);
            f.z.push(m.position[2]);
        }
        // The walled board's floor top and inner wall faces, rotated with the board.
        let board = &scene.boards[0];
        let q = glam::Quat::from_array(board.rotation);
        let half = match &board.shape {
            bevy_marble::scene::ShapeDesc::Compound(parts) => parts[1].position[0] - 0.01,
            _ => unreachable!("the walled board is a compound"),
        };
        for (n, d) in [
            (glam::Vec3::Y, 0.0),
            (glam::Vec3::X, -half),
            (-glam::Vec3::X, -half),
            (glam::Vec3::Z, -half),
            (-glam::Vec3::Z, -half),
        ] {
            f.planes.push(((q * n).to_array(), d));
        }
        f
    }

    fn step(&mut self, dt: f32, g: [f32; 3], r: f32, e: f32, threshold: f32) {
        for i in 0..self.x.len() {
            let (mut vx, mut vy, mut vz) = (
                self.vx[i] + g[0] * dt,
                self.vy[i] + g[1] * dt,
                self.vz[i] + g[2] * dt,
            );
            let (mut x, mut y, mut z) = (
                self.x[i] + vx * dt,
                self.y[i] + vy * dt,
                self.z[i] + vz * dt,
            );
            for &([nx, ny, nz], d) in &self.planes {
                let gap = nx * x + ny * y + nz * z - d - r;
                if gap < 0.0 {
                    x -= gap * nx;
                    y -= gap * ny;
                    z -= gap * nz;
                    let u = vx * nx + vy * ny + vz * nz;
                    if u < 0.0 {
                        let k = if u < -threshold { 1.0 + e } else { 1.0 };
                        vx -= k * u * nx;
                        vy -= k * u * ny;
                        vz -= k * u * nz;
                    }
                }
            }
            (self.x[i], self.y[i], self.z[i]) = (x, y, z);
            (self.vx[i], self.vy[i], self.vz[i]) = (vx, vy, vz);
        }
    }
}

/// Bench scene (c) in its steady state ([`scenes::labyrinth_steady`]: the labyrinth after
/// 5 s, marbles sliding on the turning floor and piled against the baffles), rebuilt from
/// that state every 60 steps (a quarter second at the labyrinth's 1/240 s), as the other
/// scenes are from their start. 1,000 and 10,000 marbles (building the state steps the
/// whole labyrinth for 5 s).
fn labyrinth_steady(c: &mut Criterion) {
    let mut group = c.benchmark_group("labyrinth_steady");
    group.sample_size(10);
    for n in [1_000usize, 10_000] {
        bench_scene(
            &mut group,
            BenchmarkId::from_parameter(n),
            &scenes::labyrinth_steady(n),
        );
    }
    group.finish();
}

/// Bench scene (a) stepped by the fused loop, N = 1k … 1M, rebuilt every 60 steps like
/// the engine's.
fn fused_loop(c: &mut Criterion) {
    let mut group = c.benchmark_group("fused_loop");
    for n in [1_000usize, 10_000, 100_000, 1_000_000] {
        let scene = scenes::walled_board(n);
        let m = &scene.marbles[0];
        let (dt, g, r, e, threshold) = (
            scene.dt,
            scene.gravity,
            m.radius,
            0.5 * (m.restitution + scene.boards[0].restitution),
            scene.restitution_threshold,
        );
        let mut fused = Fused::new(&scene);
        let mut steps = 0u64;
        group.sample_size(10);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if steps >= STEPS_PER_BUILD {
                        fused = Fused::new(&scene);
                        steps = 0;
                    }
                    let start = Instant::now();
                    fused.step(dt, g, r, e, threshold);
                    total += start.elapsed();
                    steps += 1;
                }
                std::hint::black_box(&fused.y);
                total
            })
        });
    }
    group.finish();
}

/// Bench scene (b)'s pile once settled: stepped for [`scenes::SETTLE_STEPS`] (6 s)
/// outside the timing, then timed as it lies, step after step: awake (the scene as
/// defined, sleeping off) and asleep ([`scenes::pour_box_sleeping`]: the whole pile is
/// asleep by then). Throughput is marble-steps.
fn settled_pile(c: &mut Criterion) {
    let mut group = c.benchmark_group("settled_pile");
    group.sample_size(10);
    // 1,000 marbles only: the 10,000-marble pour still has marbles stirring at 5–9 cm/s
    // after 8 s (`docs/pair-solver.md`, "What piles need"), so its one touching group never sleeps.
    for n in [1_000usize] {
        for (name, scene) in [
            ("awake", scenes::pour_box(n)),
            ("asleep", scenes::pour_box_sleeping(n)),
        ] {
            let mut sim = Simulation::from_scene(&scene).expect("bench scene is valid");
            for _ in 0..scenes::SETTLE_STEPS {
                sim.step();
            }
            let asleep = sim.asleep();
            eprintln!("pour box of {n} after 6 s, {name}: {asleep} asleep");
            // The two benches time what they say: an awake pile, and one wholly asleep.
            assert_eq!(asleep, if name == "asleep" { n } else { 0 });
            group.throughput(Throughput::Elements(n as u64));
            group.bench_function(BenchmarkId::new(name, n), |b| b.iter(|| sim.step()));
        }
    }
    group.finish();
}

/// Bench scene (b) with 10,000 marbles, events off and on (impacts, contacts started and
/// ended recorded as messages every substep: [`StepConfig::events`]).
fn events(c: &mut Criterion) {
    let mut group = c.benchmark_group("events");
    group.sample_size(10);
    let scene = scenes::pour_box(10_000);
    for on in [false, true] {
        let name = if on { "on" } else { "off" };
        bench_with(
            &mut group,
            BenchmarkId::from_parameter(name),
            &scene,
            |sim| {
                sim.world_mut().resource_mut::<StepConfig>().events = on;
            },
        );
    }
    group.finish();
}

criterion_group!(
    benches,
    events,
    walled_board,
    rolling,
    labyrinth_steady,
    marble_collisions,
    settled_pile,
    fused_loop
);
criterion_main!(benches);
