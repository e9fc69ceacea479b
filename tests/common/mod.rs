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

/// A marble on the top face of a board turning at a constant `omega` (rad/s) about `axis`
/// (`Vec3::X` or `Vec3::Z`) through its centre (a 20 × 0.1 × 20 m cuboid centred at
/// y = −0.05), starting `q0` from the axis at rest relative to the board (velocity
/// `ω × r`, spin `ω` when rolling), friction 0.5, `steps` steps of `dt` with `integrator`
/// and continuous collision.
pub fn turning_board_scene(
    integrator: Integrator,
    rolling: bool,
    axis: glam::Vec3,
    omega: f32,
    q0: f32,
    dt: f32,
) -> Scene {
    use glam::Vec3;
    let r = 0.008;
    let mut board = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [10.0, 0.05, 10.0],
    });
    board.position = [0.0, -0.05, 0.0];
    board.angular_velocity = (axis * omega).to_array();
    board.friction = 0.5;
    let along = Vec3::Y.cross(axis);
    let p = along * q0 + Vec3::Y * r;
    let mut m = MarbleDesc::at(p.to_array());
    m.velocity = (axis * omega)
        .cross(p - Vec3::new(0.0, -0.05, 0.0))
        .to_array();
    m.friction = 0.5;
    if rolling {
        m.angular_velocity = (axis * omega).to_array();
    }
    Scene {
        dt,
        integrator,
        ccd: true,
        rolling,
        boards: vec![board],
        marbles: vec![m],
        ..Scene::default()
    }
}

/// The exact motion of [`turning_board_scene`]'s marble at time `t`: world position and
/// velocity, and the spin about `axis` when it rolls. In the board's frame the coordinate
/// `q` along the board, away from the axis (`ŷ × axis`), obeys
/// `q'' = κ (ω² q + g·e(ωt))` with `e` that direction turned with the board, `κ = 5/7`
/// rolling and 1 smooth (`docs/PHYSICS.md` §8): with `g·e = −σ g sin ωt`,
/// `q = q0 cosh kt − (σ A ω / k) sinh kt + σ A sin ωt`, `k = √κ ω`,
/// `A = κ g / (ω² (1 + κ))`. Rolling, the spin is `ω − q'/r` about the axis.
pub fn turning_board_exact(
    rolling: bool,
    axis: glam::Vec3,
    omega: f32,
    q0: f32,
    t: f32,
) -> (glam::Vec3, glam::Vec3, f32) {
    use glam::{Quat, Vec3};
    let r = 0.008f64;
    let (w, q0, t) = (omega as f64, q0 as f64, t as f64);
    let kappa: f64 = if rolling { 5.0 / 7.0 } else { 1.0 };
    let along = Vec3::Y.cross(axis);
    // e(θ)·ŷ = σ sin θ.
    let sigma = (Quat::from_axis_angle(axis, 0.5) * along).y.signum() as f64;
    let g = G as f64;
    let k = kappa.sqrt() * w;
    let a = kappa * g / (w * w * (1.0 + kappa));
    let q = q0 * (k * t).cosh() - sigma * a * w / k * (k * t).sinh() + sigma * a * (w * t).sin();
    let dq =
        q0 * k * (k * t).sinh() - sigma * a * w * (k * t).cosh() + sigma * a * w * (w * t).cos();
    let turn = Quat::from_axis_angle(axis, (w * t) as f32);
    let centre = Vec3::new(0.0, -0.05, 0.0);
    let rel = turn * (along * q as f32 + Vec3::Y * (0.05 + r as f32));
    let x = centre + rel;
    let v = turn * along * dq as f32 + (axis * omega).cross(rel);
    (x, v, (w - dq / r) as f32)
}

/// Equation (1) at the first touch of a marble moving from `x0` on the parabola
/// `x0 + v t + ½ a t²` with a flat face of a board: the face is the plane at `offset` from
/// the board's centre (`c0 + vb t`) along its normal, which turns as `spin` turns the board
/// from `n0`, for a marble of radius `r`. Returns the impact time (bisection in f64 on the
/// centre-to-face gap) and the velocity just after, equation (1) on `v + a t` with
/// `v_b(p) = vb + spin × (p − c)` at the contact point.
#[allow(clippy::too_many_arguments)]
pub fn face_impact(
    x0: glam::Vec3,
    v: glam::Vec3,
    a: glam::Vec3,
    c0: glam::Vec3,
    vb: glam::Vec3,
    spin: glam::Vec3,
    n0: glam::Vec3,
    offset: f32,
    r: f32,
    e: f32,
) -> (f64, glam::Vec3) {
    use glam::Vec3;
    let (x0, v, a, c0, vb, spin, n0) = (
        x0.as_dvec3(),
        v.as_dvec3(),
        a.as_dvec3(),
        c0.as_dvec3(),
        vb.as_dvec3(),
        spin.as_dvec3(),
        n0.as_dvec3(),
    );
    let normal = |t: f64| {
        if spin == glam::DVec3::ZERO {
            n0
        } else {
            glam::DQuat::from_scaled_axis(spin * t) * n0
        }
    };
    let path = |t: f64| x0 + v * t + 0.5 * a * t * t;
    let gap = |t: f64| (path(t) - (c0 + vb * t)).dot(normal(t)) - offset as f64 - r as f64;
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    while gap(hi) > 0.0 {
        lo = hi;
        hi += 1e-4;
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if gap(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    let t = hi;
    let n = normal(t);
    let p = path(t) - r as f64 * n;
    let v_b = vb + spin.cross(p - (c0 + vb * t));
    let u = v + a * t;
    let after = u - (1.0 + e as f64) * (u - v_b).dot(n) * n;
    (t, after.as_vec3())
}

/// Steps `sim` up to `steps` times until marble 0 records a collision: the step's index
/// and the collision.
pub fn first_collision(
    sim: &mut bevy_marble::prelude::Simulation,
    steps: usize,
) -> Option<(usize, bevy_marble::prelude::Contact)> {
    use bevy_marble::prelude::*;
    let marble = sim.marbles()[0];
    (0..steps).find_map(|step| {
        sim.step();
        let contacts = sim.contacts(marble).unwrap();
        contacts
            .iter()
            .find(|c| c.kind == ContactKind::Collision)
            .map(|c| (step, *c))
    })
}
