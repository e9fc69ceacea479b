//! Helpers shared by the integration tests.
// Each test binary uses a different part of this module: `expect` would fail in some.
#![allow(dead_code, unused_imports)]

use bevy_marble::prelude::*;
use bevy_marble::scenes;

pub const G: f32 = 9.81;

/// A drop of a marble of radius `r` from bottom height `h` onto a plane, restitution `e`.
pub fn drop_scene(h: f32, r: f32, e: f32, dt: f32, integrator: Integrator, ccd: bool) -> Scene {
    let mut s = scenes::drop_on_plane(h, r, e);
    s.dt = dt;
    s.integrator = integrator;
    s.ccd = ccd;
    s
}

pub use bevy_marble::study::{apexes, trajectory};

/// Relative error of `got` against `want`.
pub fn rel(got: f32, want: f32) -> f32 {
    ((got - want) / want).abs()
}
