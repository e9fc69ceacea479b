//! Memory per marble: the heap a simulation holds, counted by a counting allocator (its
//! own test binary: the allocator sees every thread of the process).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicIsize, Ordering};

use bevy_marble::prelude::*;
use bevy_marble::scenes::BenchScene;

/// Tracks the bytes allocated and not yet freed by this test binary.
struct Counting;

static LIVE: AtomicIsize = AtomicIsize::new(0);

// SAFETY: forwards to the system allocator unchanged, only counting bytes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_add(
            new_size as isize - layout.size() as isize,
            Ordering::Relaxed,
        );
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Heap bytes per marble held by a warmed-up simulation of each bench scene at 20,000
/// marbles (ECS storage, contact buffers, the pair solver's grid, rows and warm-start
/// impulses): printed for the README (`cargo test --release --test memory -- --nocapture`),
/// and bounded so that a regression shows.
#[test]
fn memory_per_marble() {
    let n = 20_000;
    for (kind, collisions, bound) in [
        (BenchScene::WalledBoard, false, 750),
        // Marbles that never meet hold none of the pair solver's pile buffers: at most
        // 1 KiB a marble.
        (BenchScene::WalledBoard, true, 1_024),
        (BenchScene::PourBox, true, 4_000),
        (BenchScene::Labyrinth, true, 4_000),
    ] {
        let mut scene = kind.build(n);
        scene.marble_collisions = collisions;
        let before = LIVE.load(Ordering::Relaxed);
        let mut sim = Simulation::from_scene(&scene).unwrap();
        for _ in 0..3 {
            sim.step();
        }
        let per_marble = (LIVE.load(Ordering::Relaxed) - before) / n as isize;
        eprintln!(
            "{} (collisions {collisions}): {per_marble} bytes per marble",
            kind.name()
        );
        assert!(
            per_marble > 0 && per_marble < bound,
            "{}: {per_marble} bytes per marble",
            kind.name()
        );
        drop(sim);
    }
}
