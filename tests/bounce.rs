//! The bounce sequence `h_n = e^(2n) h_0` (PHYSICS.md) for several e, every integrator,
//! continuous collision on and off; e = 0 stops on the surface; e = 1 keeps its energy.

mod common;

use bevy_marble::prelude::*;
use common::*;

const R: f32 = 0.008;
const H: f32 = 1.0;

/// Absolute errors of the first `n` sampled apex heights against `e^(2k) h`.
fn apex_errors(e: f32, dt: f32, integrator: Integrator, ccd: bool, n: usize) -> Vec<f32> {
    let scene = drop_scene(H, R, e, dt, integrator, ccd);
    let steps = (5.0 / dt) as usize;
    let a = apexes(&trajectory(&scene, steps), R);
    assert!(
        a.len() >= n,
        "{integrator:?} ccd={ccd} e={e} dt={dt}: only {} bounces",
        a.len()
    );
    (0..n)
        .map(|k| (a[k] - H * e.powi(2 * (k as i32 + 1))).abs())
        .collect()
}

/// The apex of a flight is sampled at step times, so the sampled maximum lies at most
/// `g dt² / 8` below the true apex (the parabola's drop over half a step).
fn sampling_bound(dt: f32) -> f32 {
    G * dt * dt / 8.0
}

/// With continuous collision, Verlet and RK4 (exact paths for constant gravity) reproduce
/// the first five apex heights to within 0.2% at dt = 1/240 (the bar), and at
/// 1/60 to within the sampling bound plus 0.02%.
#[test]
fn ccd_second_order_integrators_match_the_bounce_sequence() {
    for integrator in [Integrator::VelocityVerlet, Integrator::Rk4] {
        for e in [0.8f32, 0.9] {
            for (k, err) in apex_errors(e, 1.0 / 240.0, integrator, true, 5)
                .iter()
                .enumerate()
            {
                let exact = H * e.powi(2 * (k as i32 + 1));
                assert!(
                    err / exact <= 0.002,
                    "{integrator:?} e={e} apex {k}: relative error {}",
                    err / exact
                );
            }
            for (k, err) in apex_errors(e, 1.0 / 60.0, integrator, true, 5)
                .iter()
                .enumerate()
            {
                let exact = H * e.powi(2 * (k as i32 + 1));
                assert!(
                    *err <= sampling_bound(1.0 / 60.0) + 2e-4 * exact,
                    "{integrator:?} e={e} dt=1/60 apex {k}: error {err} m"
                );
            }
        }
        // e = 0.5: three bounces (the fourth is 0.4 mm high, sampled by few steps).
        for (k, err) in apex_errors(0.5, 1.0 / 240.0, integrator, true, 3)
            .iter()
            .enumerate()
        {
            let exact = H * 0.5f32.powi(2 * (k as i32 + 1));
            assert!(
                *err <= sampling_bound(1.0 / 240.0) + 2e-4 * exact,
                "{integrator:?} e=0.5 apex {k}: error {err} m"
            );
        }
    }
}

/// First-order integrators, and every integrator without continuous collision, are wrong
/// by O(dt) at each bounce; the test pins that their error shrinks at least 2.5× when dt
/// shrinks 4× (first order would give 4×), and is below 10% of the fifth apex (0.107 m) at 1/960 s.
#[test]
fn first_order_settings_converge() {
    let cases = [
        (Integrator::SemiImplicitEuler, true),
        (Integrator::ExplicitEuler, true),
        (Integrator::SemiImplicitEuler, false),
        (Integrator::VelocityVerlet, false),
        (Integrator::Rk4, false),
        (Integrator::ExplicitEuler, false),
    ];
    let e = 0.8f32;
    let fifth = H * e.powi(10);
    for (integrator, ccd) in cases {
        let worst = |dt: f32| {
            apex_errors(e, dt, integrator, ccd, 5)
                .into_iter()
                .fold(0.0, f32::max)
        };
        let coarse = worst(1.0 / 240.0);
        let fine = worst(1.0 / 960.0);
        assert!(
            fine * 2.5 <= coarse,
            "{integrator:?} ccd={ccd}: error {coarse} m at 1/240, {fine} m at 1/960"
        );
        assert!(
            fine <= 0.1 * fifth,
            "{integrator:?} ccd={ccd}: error {fine} m at 1/960"
        );
    }
}

/// e = 0: the marble stops on the surface at its first impact and never leaves it.
#[test]
fn zero_restitution_stops_on_the_surface() {
    for ccd in [true, false] {
        for integrator in Integrator::ALL {
            let scene = drop_scene(0.5, R, 0.0, 1.0 / 60.0, integrator, ccd);
            let traj = trajectory(&scene, 120);
            let landed = traj
                .iter()
                .position(|(x, _)| x.y <= R + 1e-6)
                .expect("it lands");
            for (x, v) in &traj[landed..] {
                assert!(
                    (x.y - R).abs() <= 1e-6 && v.length() <= 1e-6,
                    "{integrator:?} ccd={ccd}: at y={} v={v} after landing",
                    x.y
                );
            }
        }
    }
}

/// e = 1 with continuous collision and Verlet: the energy `½v² + g y` (per unit mass) is
/// constant to 0.01% at every step for 20 s (about 22 bounces), at 1/60 and 1/240.
#[test]
fn elastic_bounce_keeps_its_energy() {
    for dt in [1.0 / 60.0, 1.0 / 240.0] {
        let scene = drop_scene(H, R, 1.0, dt, Integrator::VelocityVerlet, true);
        let traj = trajectory(&scene, (20.0 / dt) as usize);
        let e0 = G * H;
        for (i, (x, v)) in traj.iter().enumerate() {
            let e = 0.5 * v.length_squared() + G * (x.y - R);
            assert!(
                rel(e, e0) <= 1e-4,
                "dt={dt} step {i}: energy {e} against {e0}"
            );
        }
        let a = apexes(&traj, R);
        assert!(a.len() >= 20, "{} bounces", a.len());
        for (k, h) in a.iter().enumerate() {
            assert!(
                (h - H).abs() <= sampling_bound(dt) + 1e-4,
                "dt={dt}: apex {k} at {h}"
            );
        }
    }
}

/// The first impact happens at `√(2h/g)` (within one step's resolution: the contact is
/// recorded with its time inside the step).
#[test]
fn first_impact_time() {
    let dt = 1.0 / 60.0;
    let scene = drop_scene(H, R, 0.8, dt, Integrator::VelocityVerlet, true);
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let marble = sim.marbles()[0];
    for step in 0..60 {
        sim.step();
        let contacts = sim.world().get::<Contacts>(marble).unwrap();
        if let Some(c) = contacts.iter().find(|c| c.kind == ContactKind::Collision) {
            let t = step as f32 * dt + c.time;
            let exact = (2.0 * H / G).sqrt();
            assert!((t - exact).abs() <= 1e-5, "impact at {t}, exact {exact}");
            assert!((c.normal - glam::Vec3::Y).length() < 1e-6);
            return;
        }
    }
    panic!("no collision recorded");
}
