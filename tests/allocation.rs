//! Stepping allocates nothing once warmed up (its own test binary). The counting allocator
//! counts the allocations of the thread that steps (the test's), so that the test
//! harness's own threads (its "running for over 60 seconds" notice on a loaded machine)
//! are not taken for the engine's; without the `parallel` feature every stage runs on it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use bevy_marble::prelude::*;
use bevy_marble::scenes;

/// Counts heap allocations made by this test binary.
struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Set on the thread whose allocations are counted.
    static COUNTED: Cell<bool> = const { Cell::new(false) };
}

/// Counts an allocation if it is made on the counted thread.
fn count() {
    if COUNTED.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards to the system allocator unchanged, only counting calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Once warmed up, stepping allocates nothing: 100 steps of 1,000 marbles on the walled
/// board (contacts, walls, CCD), of the tilting labyrinth scene (marbles colliding with
/// each other) and of 1,000 marbles poured into a box (the pile solver); and a pile
/// asleep. Warmed up means 10 steps, and, where marbles collide, until two first could
/// meet: the pair solver sizes its buffers for a dense pile then (marbles that never meet
/// hold none of them), which allocates once.
#[test]
fn stepping_does_not_allocate() {
    COUNTED.with(|c| c.set(true));
    for scene in [
        scenes::walled_board(1000),
        scenes::default_scene(),
        scenes::pour_box(1000),
    ] {
        let mut sim = Simulation::from_scene(&scene).unwrap();
        for _ in 0..10 {
            sim.step();
        }
        let mut warming = 0;
        while scene.marble_collisions && sim.world().resource::<MarbleContacts>().is_empty() {
            sim.step();
            warming += 1;
            assert!(
                warming < 600,
                "the {} marbles never meet",
                scene.marbles.len()
            );
        }
        let n = scene.marbles.len();
        assert_eq!(allocations_in_100_steps(&mut sim), 0, "{n} marbles");
    }
    a_sleeping_pile_does_not_allocate();
    events_do_not_allocate();
}

/// Events on (impacts, contacts started and ended, sensors entered and left) allocate
/// nothing either once warmed up: 1,000 marbles poured into a box (impacts with the floor,
/// the walls and each other, contacts coming and going) through a dozen sensors, messages
/// moved on every step.
fn events_do_not_allocate() {
    let scene = scenes::pour_box(1000);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    sim.world_mut().resource_mut::<StepConfig>().events = true;
    for i in 0..12 {
        let x = -0.12 + 0.02 * i as f32;
        sim.world_mut().spawn((
            Sensor,
            Collider::cuboid(glam::Vec3::new(0.01, 0.05, 0.2)).unwrap(),
            Position(glam::Vec3::new(x, 0.05, 0.0)),
        ));
    }
    let mut impacts = 0;
    for _ in 0..30 {
        sim.step();
        impacts += sim
            .world()
            .resource::<bevy_ecs::message::Messages<MarbleImpact>>()
            .len();
    }
    assert!(impacts > 0, "the pour has impacts");
    assert_eq!(allocations_in_100_steps(&mut sim), 0, "a pour with events");
}

/// Allocations during 100 steps of `sim`.
fn allocations_in_100_steps(sim: &mut Simulation) -> usize {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for _ in 0..100 {
        sim.step();
    }
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

/// A pile asleep allocates nothing either: bench scene (b) with sleeping on
/// (`scenes::pour_box_sleeping`, 300 marbles), stepped until every marble sleeps, then
/// 100 steps. (Called from [`stepping_does_not_allocate`]: the allocation count is
/// global, so the two must not run at once.)
fn a_sleeping_pile_does_not_allocate() {
    let scene = scenes::pour_box_sleeping(300);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let mut steps = 0;
    while sim.asleep() < scene.marbles.len() {
        sim.step();
        steps += 1;
        assert!(steps <= 360, "not all asleep after 6 s");
    }
    sim.step();
    assert_eq!(allocations_in_100_steps(&mut sim), 0, "a sleeping pile");
}
