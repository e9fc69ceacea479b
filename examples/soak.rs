//! A long run of the labyrinth with colliding marbles, checked as it goes:
//! `cargo run --release --example soak -- [MARBLES] [STEPS]` (default 1,000 marbles and a
//! million steps of 1/240 s, 69 simulated minutes).
//!
//! The board of `scenes::labyrinth` tilts back and forth (±0.15 rad about X, a period of
//! 30 s) instead of turning on for ever. Checked:
//! - every 1,000 steps: no marble quarantined or non-finite, every marble inside the walled
//!   floor (in the board's frame, within its half-width and between the floor and 0.2 m
//!   above it), and the fastest marble's speed;
//! - every step: the energy in the board's frame never exceeds its start plus the work the
//!   board's motion has done (below);
//! - the resident memory at 10% of the run and at its end (`/proc/self/statm`), which must
//!   not grow, and the heap allocations made by the steps after the first 10%, which must
//!   be none.
//!
//! Exit status 1 on the first failure, with what failed.
//!
//! **The energy bound.** In the frame of a board turning at `Ω` about its origin `c`, with
//! `r = x − c` and `u = v − Ω × r`, the energy `E = Σ ½m|u|² − m g·r − ½m|Ω × r|²` changes
//! only by the contacts' work, which a static surface and an impact with e ≤ 1 make ≤ 0
//! (marble–marble contacts included, whose frame terms cancel at their common point), and
//! by the board's: while `Ω` is constant, `dE/dt = Σ m (Ω × g)·r` (gravity turning in the
//! board's frame), and when the program changes `Ω` between steps, `E` jumps by its new
//! value less its old. With W the sum of both (f64, trapezoids over each step),
//! `E(t₂) − E(t₁) ≤ W(t₂) − W(t₁)` for every `t₁ < t₂`: `E − W` never rises. The discrete
//! step is not exactly dissipative (the integrator's own energy error, the pushing apart of
//! overlapping marbles), so the check allows a rise of 0.1 mJ per kilogram of marbles (the
//! energy of a 0.01 mm climb) above its lowest value so far, and prints the largest rise.
use std::alloc::{GlobalAlloc, Layout, System};
use std::f32::consts::TAU;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use glam::{Quat, Vec3};

/// Counts heap allocations while `COUNTING` is set.
struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator unchanged, only counting calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The board-frame energy of the marbles (module docs) for the board's angular velocity
/// `omega` about `c`, and its rate `Σ m (Ω × g)·r` at constant `omega`: f64 sums of f32
/// states.
fn frame_energy(
    states: &[(Vec3, Vec3)],
    masses: &[f64],
    c: Vec3,
    omega: Vec3,
    g: Vec3,
) -> (f64, f64) {
    let d = |v: Vec3| v.as_dvec3();
    let (c, omega, g) = (d(c), d(omega), d(g));
    let turn = omega.cross(g);
    let (mut energy, mut rate) = (0.0, 0.0);
    for (&(x, v), &m) in states.iter().zip(masses) {
        let r = d(x) - c;
        let sweep = omega.cross(r);
        let u = d(v) - sweep;
        energy += m * (0.5 * u.length_squared() - g.dot(r) - 0.5 * sweep.length_squared());
        rate += m * turn.dot(r);
    }
    (energy, rate)
}

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
    let g = Vec3::from_array(scene.gravity);
    // θ(t) = θ0 + A sin(2π t / T): the board turns at θ'(t) about X, set before each step.
    let omega = |step: u64| {
        let t = step as f32 * dt;
        Vec3::new(
            amplitude * TAU / period * (TAU * t / period).cos(),
            0.0,
            0.0,
        )
    };
    let masses: Vec<f64> = sim
        .marbles()
        .iter()
        .map(|&e| f64::from(sim.world().get::<Mass>(e).expect("a marble").get()))
        .collect();
    let kilograms: f64 = masses.iter().sum();
    let allowed = 1e-4 * kilograms;
    let c = sim.world().get::<Position>(board).unwrap().0;
    let mut states: Vec<(Vec3, Vec3)> = (0..n).map(|i| sim.marble_state(i)).collect();
    let start_omega = sim.world().get::<AngularVelocity>(board).unwrap().0;
    let (mut energy_before, _) = frame_energy(&states, &masses, c, start_omega, g);
    let mut rate_before;
    // The energy less the board's work, D = E − W, never rises: its lowest value so far.
    let (mut work, mut lowest, mut excess) = (0.0f64, energy_before, 0.0f64);
    let started = std::time::Instant::now();
    let (mut fastest, mut early_kib) = (0.0f32, 0);
    for step in 0..steps {
        // The program's change of Ω is the board's work on the frame energy.
        let w = omega(step);
        let (energy_set, rate_set) = frame_energy(&states, &masses, c, w, g);
        work += energy_set - energy_before;
        rate_before = rate_set;
        sim.world_mut().get_mut::<AngularVelocity>(board).unwrap().0 = w;
        // Only the steps are counted, every one after the first 10%; the checks around
        // them (reading /proc, printing) may allocate.
        COUNTING.store(step >= steps / 10, Ordering::Relaxed);
        sim.step();
        COUNTING.store(false, Ordering::Relaxed);
        for (i, state) in states.iter_mut().enumerate() {
            *state = sim.marble_state(i);
        }
        let (energy, rate) = frame_energy(&states, &masses, c, w, g);
        work += 0.5 * f64::from(dt) * (rate_before + rate);
        energy_before = energy;
        let over = energy - work - lowest;
        lowest = lowest.min(energy - work);
        excess = excess.max(over);
        if over > allowed {
            eprintln!(
                "step {step}: the frame energy gained {over:.3e} J more than the board's work since it was lowest (allowed {allowed:.3e})"
            );
            std::process::exit(1);
        }
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
                "{:>8} steps ({:>6.0} s simulated, {:>5.0} s wall): fastest {:.3} m/s, largest rise of E − W {:.2e} J, resident {} KiB",
                step + 1,
                (step + 1) as f32 * dt,
                started.elapsed().as_secs_f32(),
                fastest,
                excess,
                resident_kib()
            );
        }
    }
    let end_kib = resident_kib();
    let allocations = ALLOCATIONS.load(Ordering::Relaxed);
    println!(
        "{steps} steps of {n} marbles: every check held; fastest {fastest:.3} m/s; frame energy E − W rose at most {excess:.2e} J (allowed {allowed:.2e}; the board's work W = {work:.4} J); resident {early_kib} KiB at 10%, {end_kib} KiB at the end; {allocations} allocations after the first 10%"
    );
    if allocations > 0 {
        eprintln!("the steps after the first 10% allocated {allocations} times");
        std::process::exit(1);
    }
    if early_kib > 0 && end_kib > early_kib + early_kib / 20 {
        eprintln!("resident memory grew by more than 5% after the first 10%");
        std::process::exit(1);
    }
}
