//! Helpers shared by the integration tests.
#![allow(dead_code)]

use bevy_marble::prelude::*;
use bevy_marble::scenes;
use glam::Vec3;

pub const G: f32 = 9.81;

/// A drop of a marble of radius `r` from bottom height `h` onto a plane, restitution `e`.
pub fn drop_scene(h: f32, r: f32, e: f32, dt: f32, integrator: Integrator, ccd: bool) -> Scene {
    let mut s = scenes::drop_on_plane(h, r, e);
    s.dt = dt;
    s.integrator = integrator;
    s.ccd = ccd;
    s
}

/// Runs a one-marble scene for `steps` steps, returning (position, velocity) after each
/// step (the initial state first).
pub fn trajectory(scene: &Scene, steps: usize) -> Vec<(Vec3, Vec3)> {
    let mut sim = Simulation::from_scene(scene).expect("valid scene");
    let mut out = Vec::with_capacity(steps + 1);
    out.push(sim.marble_state(0));
    for _ in 0..steps {
        sim.step();
        out.push(sim.marble_state(0));
    }
    out
}

/// Apex heights of the marble's bottom (`y − r`) in each flight after a bounce: the
/// sampled maximum of y between an upward velocity reversal and the next downward one.
pub fn apexes(traj: &[(Vec3, Vec3)], r: f32) -> Vec<f32> {
    let mut out = Vec::new();
    let mut best: Option<f32> = None;
    for w in traj.windows(2) {
        let (prev, cur) = (w[0], w[1]);
        if prev.1.y <= 0.0 && cur.1.y > 0.0 {
            // A bounce happened in this step: a new flight starts.
            if let Some(b) = best.take() {
                out.push(b);
            }
            best = Some(cur.0.y - r);
        } else if let Some(b) = best.as_mut() {
            *b = b.max(cur.0.y - r);
        }
    }
    if let Some(b) = best {
        out.push(b);
    }
    out
}

/// Relative error of `got` against `want`.
pub fn rel(got: f32, want: f32) -> f32 {
    ((got - want) / want).abs()
}
