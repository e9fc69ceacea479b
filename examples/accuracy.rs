//! Prints the README's accuracy table: every integrator, CCD on and off, dt = 1/60 and
//! 1/240, against the exact answers of PHYSICS.md.
//!
//! `cargo run --release --example accuracy`
//!
//! Columns: the worst relative error of the first five apex heights of an e = 0.8 drop
//! from 1 m (`e^(2n) h`); how far the apex of an elastic (e = 1) bounce from 1 m has drifted
//! after 60 s;
//! the relative error of the distance slid down a smooth 20° incline in 1 s
//! (`½ g sinθ t²`); the largest drift of a marble resting for 10 s (e = 0.9).

use bevy_marble::prelude::*;
use bevy_marble::scene::PlaneDesc;
use bevy_marble::scenes;
use glam::{Quat, Vec3};

const R: f32 = 0.008;
const G: f32 = 9.81;

fn run(scene: &Scene, steps: usize) -> Vec<(Vec3, Vec3)> {
    let mut sim = Simulation::from_scene(scene).unwrap();
    let mut out = vec![sim.marble_state(0)];
    for _ in 0..steps {
        sim.step();
        out.push(sim.marble_state(0));
    }
    out
}

fn configure(mut s: Scene, dt: f32, integrator: Integrator, ccd: bool) -> Scene {
    s.dt = dt;
    s.integrator = integrator;
    s.ccd = ccd;
    s
}

fn bounce_error(dt: f32, integrator: Integrator, ccd: bool) -> f32 {
    let e = 0.8f32;
    let traj = run(
        &configure(scenes::drop_on_plane(1.0, R, e), dt, integrator, ccd),
        (6.0 / dt) as usize,
    );
    let apexes = apexes(&traj);
    (0..5)
        .map(|k| match apexes.get(k) {
            Some(a) => ((a - e.powi(2 * (k as i32 + 1))) / e.powi(2 * (k as i32 + 1))).abs(),
            None => 1.0,
        })
        .fold(0.0, f32::max)
}

fn apexes(traj: &[(Vec3, Vec3)]) -> Vec<f32> {
    let mut apexes = Vec::new();
    let mut best: Option<f32> = None;
    for w in traj.windows(2) {
        if w[0].1.y <= 0.0 && w[1].1.y > 0.0 {
            apexes.extend(best.take());
            best = Some(w[1].0.y - R);
        } else if let Some(b) = best.as_mut() {
            *b = b.max(w[1].0.y - R);
        }
    }
    apexes.extend(best);
    apexes
}

fn elastic_drift(dt: f32, integrator: Integrator, ccd: bool) -> f32 {
    let traj = run(
        &configure(scenes::drop_on_plane(1.0, R, 1.0), dt, integrator, ccd),
        (60.0 / dt) as usize,
    );
    // The last complete flight's apex (the final one may be cut short).
    let a = apexes(&traj);
    match a.len() {
        0 | 1 => 1.0,
        n => (a[n - 2] - 1.0).abs(),
    }
}

fn incline_error(dt: f32, integrator: Integrator, ccd: bool) -> f32 {
    let theta = 20f32.to_radians();
    let rot = Quat::from_rotation_z(theta);
    let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    board.rotation = rot.to_array();
    let start = rot * Vec3::Y * R;
    let scene = Scene {
        boards: vec![board],
        marbles: vec![MarbleDesc::at(start.to_array())],
        ..Scene::default()
    };
    let n = (1.0 / dt).round() as usize;
    let traj = run(&configure(scene, dt, integrator, ccd), n);
    let s = (traj[n].0 - start).dot(rot * -Vec3::X);
    let t = n as f32 * dt;
    let exact = 0.5 * G * theta.sin() * t * t;
    ((s - exact) / exact).abs()
}

fn resting_drift(dt: f32, integrator: Integrator, ccd: bool) -> f32 {
    let mut s = scenes::drop_on_plane(0.0, R, 0.9);
    s.marbles[0].position[1] = R;
    let traj = run(&configure(s, dt, integrator, ccd), (10.0 / dt) as usize);
    traj.iter()
        .map(|(x, _)| (x.y - R).abs())
        .fold(0.0, f32::max)
}

fn pct(x: f32) -> String {
    if x < 1e-5 {
        "< 0.001%".into()
    } else {
        format!("{:.3}%", 100.0 * x)
    }
}

fn main() {
    println!(
        "| integrator | CCD | dt | bounce apexes 1–5 (e = 0.8) | e = 1: apex drift after 60 s (h = 1 m) | incline 1 s | resting drift 10 s |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for integrator in Integrator::ALL {
        for ccd in [true, false] {
            for (name, dt) in [("1/60", 1.0 / 60.0), ("1/240", 1.0 / 240.0)] {
                println!(
                    "| {integrator:?} | {} | {name} | {} | {:.4} m | {} | {:.1e} m |",
                    if ccd { "on" } else { "off" },
                    pct(bounce_error(dt, integrator, ccd)),
                    elastic_drift(dt, integrator, ccd),
                    pct(incline_error(dt, integrator, ccd)),
                    resting_drift(dt, integrator, ccd),
                );
            }
        }
    }
}
