//! Reference scenes with exact answers, and the speed-versus-accuracy study behind
//! `marble tradeoff`.
//!
//! Each [`Reference`] is a small scene whose exact outcome `docs/PHYSICS.md` §8 gives in closed form;
//! [`Reference::measure`] runs it under one [`Setting`] (integrator, dt, substeps, CCD) and
//! returns the error against that answer. [`cost`] measures what the setting costs on many
//! marbles. [`run`] sweeps a grid of settings and returns the table the CLI prints and plots.
//! The same functions serve the tests, so the numbers published are the numbers tested.

use std::time::Instant;

use glam::{DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::config::{Integrator, Preset, StepConfig};
use crate::scene::{BoardDesc, MarbleDesc, PlaneDesc, Scene, ShapeDesc};
use crate::scenes;
use crate::simulation::Simulation;

/// Radius of the reference marble: 8 mm glass.
pub const R: f32 = 0.008;
const G: f32 = 9.81;

/// The speed-versus-accuracy choices a user makes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setting {
    /// Integrator.
    pub integrator: Integrator,
    /// Seconds per step.
    pub dt: f32,
    /// Substeps per step.
    pub substeps: u32,
    /// Continuous collision.
    pub ccd: bool,
    /// Compensated summation of positions ([`StepConfig::compensated`]).
    pub compensated: bool,
    /// A preset that makes the other choices (and its contact tolerance).
    pub preset: Option<Preset>,
}

impl Setting {
    /// The setting a preset makes at step `dt`.
    pub fn preset(preset: Preset, dt: f32) -> Setting {
        let c = StepConfig::with_preset(preset, dt);
        Setting {
            integrator: c.integrator,
            dt,
            substeps: c.substeps,
            ccd: c.ccd,
            compensated: c.compensated,
            preset: Some(preset),
        }
    }

    /// The scene with this setting's choices.
    pub fn apply(&self, mut scene: Scene) -> Scene {
        if let Some(preset) = self.preset {
            scene.preset = Some(preset);
            scene.dt = self.dt;
            return scene;
        }
        scene.integrator = self.integrator;
        scene.dt = self.dt;
        scene.substeps = self.substeps;
        scene.ccd = self.ccd;
        scene
    }

    /// Steps of this setting's `dt` in `seconds`, rounded.
    pub fn steps(&self, seconds: f32) -> usize {
        (seconds as f64 / self.dt as f64).round() as usize
    }
}

/// How long the reference scenes run: `Full` for the published study, `Quick` for a smoke
/// run (shorter scenes, same measures).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Length {
    /// The published study.
    Full,
    /// A fast run of the same measures.
    Quick,
}

impl Length {
    /// Marbles, steps per sample and samples of the cost measurements.
    pub fn cost_sample(self) -> (usize, usize, usize) {
        match self {
            Length::Full => (1000, 8, 5),
            Length::Quick => (200, 3, 3),
        }
    }
}

/// A reference scene with an exact answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Reference {
    /// Drop from 1 m, e = 0.8: worst relative error of the first five apex heights against
    /// `e^(2n) h`.
    Bounce,
    /// Drop from 1 m, e = 1, for 60 s (10 s quick): relative drift of the last apex from
    /// the drop height (energy is constant).
    Elastic,
    /// Slide from rest down a smooth 20° incline for 1 s: relative error of the distance
    /// against `½ g sinθ t²`.
    Incline,
    /// A marble falling onto a plane that rises and turns: relative error of its velocity
    /// and position 0.1 s after the impact against equation (1) at the exact impact.
    MovingBoard,
    /// A marble resting on a plane (e = 0.9) for 10 s (2 s quick): largest displacement, m.
    Resting,
    /// 300 m/s against a 2 mm wall: 1 if the marble ends up beyond it, else 0.
    ThinWall,
}

impl Reference {
    /// Every reference scene, in table order.
    pub const ALL: [Reference; 6] = [
        Reference::Bounce,
        Reference::Elastic,
        Reference::Incline,
        Reference::MovingBoard,
        Reference::Resting,
        Reference::ThinWall,
    ];

    /// Short name (table column, plot file name).
    pub fn name(self) -> &'static str {
        match self {
            Reference::Bounce => "bounce",
            Reference::Elastic => "elastic",
            Reference::Incline => "incline",
            Reference::MovingBoard => "moving_board",
            Reference::Resting => "resting",
            Reference::ThinWall => "thin_wall",
        }
    }

    /// What the error measures.
    pub fn description(self) -> &'static str {
        match self {
            Reference::Bounce => "worst relative error of apexes 1–5, e = 0.8, h = 1 m",
            Reference::Elastic => "relative apex drift of an e = 1 bounce after 60 s",
            Reference::Incline => "relative error of the distance slid down 20° in 1 s",
            Reference::MovingBoard => {
                "relative error 0.1 s after landing on a rising, turning board (eq. 1)"
            }
            Reference::Resting => "largest displacement of a resting marble over 10 s, m",
            Reference::ThinWall => "1 if a 300 m/s marble passes a 2 mm wall, else 0",
        }
    }

    /// Runs the scene under `setting` and returns its error.
    pub fn measure(self, setting: &Setting, length: Length) -> f32 {
        let quick = length == Length::Quick;
        match self {
            Reference::Bounce => bounce_error(setting),
            Reference::Elastic => elastic_drift(setting, if quick { 10.0 } else { 60.0 }),
            Reference::Incline => incline_error(setting),
            Reference::MovingBoard => moving_board_error(setting),
            Reference::Resting => resting_drift(setting, if quick { 2.0 } else { 10.0 }),
            Reference::ThinWall => thin_wall(setting),
        }
    }
}

/// Steps `scene` and returns the first marble's (position, velocity) before the first step
/// and after each.
pub fn trajectory(scene: &Scene, steps: usize) -> Vec<(Vec3, Vec3)> {
    trajectory_with(scene, true, steps)
}

/// [`trajectory`] with compensated summation on or off.
pub fn trajectory_with(scene: &Scene, compensated: bool, steps: usize) -> Vec<(Vec3, Vec3)> {
    let mut sim = Simulation::from_scene(scene).expect("reference scenes are valid");
    sim.world_mut().resource_mut::<StepConfig>().compensated = compensated;
    let mut out = Vec::with_capacity(steps + 1);
    out.push(sim.marble_state(0));
    for _ in 0..steps {
        sim.step();
        out.push(sim.marble_state(0));
    }
    out
}

/// Apex heights of the marble's bottom (`y − r`) in each flight after a bounce: the sampled
/// maximum of y between an upward velocity reversal and the next one. Sampling at step
/// times reads an apex at most `g dt² / 8` low.
pub fn apexes(traj: &[(Vec3, Vec3)], r: f32) -> Vec<f32> {
    let mut out = Vec::new();
    let mut best: Option<f32> = None;
    for w in traj.windows(2) {
        if w[0].1.y <= 0.0 && w[1].1.y > 0.0 {
            out.extend(best.take());
            best = Some(w[1].0.y - r);
        } else if let Some(b) = best.as_mut() {
            *b = b.max(w[1].0.y - r);
        }
    }
    out.extend(best);
    out
}

fn bounce_error(s: &Setting) -> f32 {
    let e = 0.8f32;
    let traj = trajectory_with(
        &s.apply(scenes::drop_on_plane(1.0, R, e)),
        s.compensated,
        s.steps(6.0),
    );
    let a = apexes(&traj, R);
    (0..5)
        .map(|k| {
            let exact = e.powi(2 * (k as i32 + 1));
            a.get(k).map_or(1.0, |h| ((h - exact) / exact).abs())
        })
        .fold(0.0, f32::max)
}

fn elastic_drift(s: &Setting, seconds: f32) -> f32 {
    let traj = trajectory_with(
        &s.apply(scenes::drop_on_plane(1.0, R, 1.0)),
        s.compensated,
        s.steps(seconds),
    );
    let a = apexes(&traj, R);
    // The last complete flight (the final one may be cut short by the end of the run).
    match a.len() {
        0 | 1 => 1.0,
        n => (a[n - 2] - 1.0).abs(),
    }
}

fn incline_error(s: &Setting) -> f32 {
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
    let n = s.steps(1.0);
    let traj = trajectory_with(&s.apply(scene), s.compensated, n);
    let slid = (traj[n].0 - start).dot(rot * -Vec3::X);
    let t = n as f32 * s.dt;
    let exact = 0.5 * G * theta.sin() * t * t;
    ((slid - exact) / exact).abs()
}

/// The moving-board reference: a plane through `c(t) = (0, 0.3 t, 0)` turning about Z at
/// −0.5 rad/s, a marble thrown down onto it 0.5 m from the axis.
struct MovingBoard {
    lift: f64,
    spin: f64,
    x0: DVec3,
    v0: DVec3,
    e: f64,
}

const MOVING_BOARD: MovingBoard = MovingBoard {
    lift: 0.3,
    spin: -0.5,
    x0: DVec3::new(0.5, 0.4, 0.0),
    v0: DVec3::new(0.3, -1.0, 0.2),
    e: 0.6,
};

impl MovingBoard {
    fn scene(&self) -> Scene {
        let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
        board.velocity = [0.0, self.lift as f32, 0.0];
        board.angular_velocity = [0.0, 0.0, self.spin as f32];
        board.restitution = self.e as f32;
        let mut m = MarbleDesc::at(self.x0.as_vec3().to_array());
        m.velocity = self.v0.as_vec3().to_array();
        m.restitution = self.e as f32;
        Scene {
            boards: vec![board],
            marbles: vec![m],
            ..Scene::default()
        }
    }

    fn gap(&self, t: f64) -> f64 {
        let g = DVec3::new(0.0, -G as f64, 0.0);
        let x = self.x0 + self.v0 * t + 0.5 * g * t * t;
        let n = DVec3::new(-(self.spin * t).sin(), (self.spin * t).cos(), 0.0);
        n.dot(x - DVec3::new(0.0, self.lift * t, 0.0)) - R as f64
    }

    /// Exact impact time, then the exact state at `t`, in f64.
    fn exact(&self, t: f64) -> (f64, DVec3, DVec3) {
        let g = DVec3::new(0.0, -G as f64, 0.0);
        // Bracket the first root on a fine grid, then bisect.
        let (mut lo, mut hi) = (0.0, 0.0);
        while self.gap(hi) > 0.0 {
            lo = hi;
            hi += 1e-3;
        }
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.gap(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let ts = 0.5 * (lo + hi);
        let x = self.x0 + self.v0 * ts + 0.5 * g * ts * ts;
        let v = self.v0 + g * ts;
        let n = DVec3::new(-(self.spin * ts).sin(), (self.spin * ts).cos(), 0.0);
        let p = x - R as f64 * n;
        let c = DVec3::new(0.0, self.lift * ts, 0.0);
        let vb = DVec3::new(0.0, self.lift, 0.0) + DVec3::new(0.0, 0.0, self.spin).cross(p - c);
        // Equation (1).
        let v1 = v - (1.0 + self.e) * (v - vb).dot(n) * n;
        let dt = t - ts;
        (ts, x + v1 * dt + 0.5 * g * dt * dt, v1 + g * dt)
    }
}

fn moving_board_error(s: &Setting) -> f32 {
    let mb = &MOVING_BOARD;
    let (impact, _, _) = mb.exact(0.0);
    let steps = ((impact + 0.1) / s.dt as f64).ceil() as usize;
    let t = steps as f64 * s.dt as f64;
    let (_, x, v) = mb.exact(t);
    let (xs, vs) = *trajectory_with(&s.apply(mb.scene()), s.compensated, steps)
        .last()
        .expect("steps");
    let (_, _, v_after) = mb.exact(impact);
    let speed = v_after.length();
    let dv = (vs.as_dvec3() - v).length() / speed;
    let dx = (xs.as_dvec3() - x).length() / (speed * (t - impact));
    dv.max(dx) as f32
}

fn resting_drift(s: &Setting, seconds: f32) -> f32 {
    let mut scene = scenes::drop_on_plane(0.0, R, 0.9);
    scene.marbles[0].position[1] = R;
    let start = Vec3::new(0.0, R, 0.0);
    trajectory_with(&s.apply(scene), s.compensated, s.steps(seconds))
        .iter()
        .map(|(x, _)| (*x - start).length())
        .fold(0.0, f32::max)
}

fn thin_wall(s: &Setting) -> f32 {
    let mut wall = BoardDesc::new(ShapeDesc::Cuboid {
        half_extents: [0.001, 0.5, 0.5],
    });
    wall.position = [1.0, 0.0, 0.0];
    let mut m = MarbleDesc::at([0.0, 0.0, 0.0]);
    m.velocity = [300.0, 0.0, 0.0];
    let scene = Scene {
        gravity: [0.0; 3],
        boards: vec![wall],
        marbles: vec![m],
        ..Scene::default()
    };
    let passed = trajectory_with(&s.apply(scene), s.compensated, s.steps(0.05).max(2))
        .iter()
        .any(|(x, _)| x.x > 1.0);
    if passed { 1.0 } else { 0.0 }
}

/// Cost of a setting: median over `repeats` runs of the time per marble-step (one `dt`,
/// all substeps) of `marbles` marbles on the walled board (bench scene (a)), in ns.
pub fn cost(setting: &Setting, marbles: usize, steps: usize, repeats: usize) -> f64 {
    scene_cost(
        &setting.apply(scenes::walled_board(marbles)),
        setting.compensated,
        steps,
        repeats,
    )
}

/// Median over `repeats` runs of `steps` steps of the time per marble-step of `scene`, ns,
/// after three steps of warm-up.
pub fn scene_cost(scene: &Scene, compensated: bool, steps: usize, repeats: usize) -> f64 {
    let mut sim = Simulation::from_scene(scene).expect("bench scene is valid");
    sim.world_mut().resource_mut::<StepConfig>().compensated = compensated;
    for _ in 0..3 {
        sim.step();
    }
    let marbles = sim.marbles().len().max(1);
    let mut samples: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let start = Instant::now();
            for _ in 0..steps {
                sim.step();
            }
            start.elapsed().as_secs_f64() * 1e9 / (marbles * steps) as f64
        })
        .collect();
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

/// One row of the study: a setting, its cost and its error on every reference scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The setting.
    pub setting: Setting,
    /// ns per marble-step (one `dt`).
    pub ns_per_step: f64,
    /// Errors, in [`Reference::ALL`] order.
    pub errors: [f32; 6],
}

impl Row {
    /// Cost of simulating one marble for one second: `ns_per_step / dt`, in µs. This is the
    /// cost that compares settings of different `dt`.
    pub fn us_per_second(&self) -> f64 {
        self.ns_per_step / self.setting.dt as f64 * 1e-3
    }

    /// Error on one reference scene.
    pub fn error(&self, reference: Reference) -> f32 {
        self.errors[Reference::ALL
            .iter()
            .position(|r| *r == reference)
            .expect("every reference has a column")]
    }
}

/// The grid of settings: every integrator × `dts` × `substeps` × CCD on and off.
pub fn grid(dts: &[f32], substeps: &[u32]) -> Vec<Setting> {
    let mut out = Vec::new();
    for integrator in Integrator::ALL {
        for &dt in dts {
            for &n in substeps {
                for ccd in [true, false] {
                    out.push(Setting {
                        integrator,
                        dt,
                        substeps: n,
                        ccd,
                        compensated: true,
                        preset: None,
                    });
                }
            }
        }
    }
    out
}

/// The published grid: dt from 1/30 to 1/4000 s, 1–8 substeps.
pub fn full_grid() -> Vec<Setting> {
    grid(
        &[
            1.0 / 30.0,
            1.0 / 60.0,
            1.0 / 120.0,
            1.0 / 240.0,
            1.0 / 480.0,
            1.0 / 1000.0,
            1.0 / 2000.0,
            1.0 / 4000.0,
        ],
        &[1, 2, 4, 8],
    )
}

/// A small grid for a smoke run.
pub fn quick_grid() -> Vec<Setting> {
    grid(&[1.0 / 60.0, 1.0 / 240.0], &[1, 2])
}

/// Runs every setting of `settings` on every reference scene and measures its cost;
/// `progress` is called after each setting.
pub fn run(settings: &[Setting], length: Length, mut progress: impl FnMut(usize)) -> Vec<Row> {
    let (marbles, steps, repeats) = length.cost_sample();
    settings
        .iter()
        .enumerate()
        .map(|(i, setting)| {
            let errors = Reference::ALL.map(|r| r.measure(setting, length));
            let ns_per_step = cost(setting, marbles, steps, repeats);
            progress(i + 1);
            Row {
                setting: *setting,
                ns_per_step,
                errors,
            }
        })
        .collect()
}

/// Indices of the rows on the Pareto front of `(us_per_second, error)` for `reference`:
/// no other row is at least as cheap and as accurate and better in one. Sorted by cost.
pub fn pareto_front(rows: &[Row], reference: Reference) -> Vec<usize> {
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by(|&a, &b| {
        rows[a]
            .us_per_second()
            .total_cmp(&rows[b].us_per_second())
            .then(
                rows[a]
                    .error(reference)
                    .total_cmp(&rows[b].error(reference)),
            )
    });
    let mut front = Vec::new();
    let mut best = f32::INFINITY;
    for i in order {
        let e = rows[i].error(reference);
        if e < best {
            front.push(i);
            best = e;
        }
    }
    front
}

/// Formats an error for the tables.
pub fn format_error(reference: Reference, e: f32) -> String {
    match reference {
        Reference::ThinWall => if e > 0.0 { "passes" } else { "holds" }.into(),
        Reference::Resting => format!("{e:.1e}"),
        _ if e == 0.0 => "0".into(),
        _ => format!("{:.3}%", 100.0 * e),
    }
}

/// `dt` as `1/N` where it is one.
pub fn format_dt(dt: f32) -> String {
    let inv = 1.0 / dt as f64;
    if (inv - inv.round()).abs() < 1e-3 {
        format!("1/{}", inv.round())
    } else {
        format!("{dt}")
    }
}

/// A markdown table header: the given columns, then one per reference scene.
fn table_header(columns: &[&str]) -> String {
    let names: Vec<&str> = columns
        .iter()
        .copied()
        .chain(Reference::ALL.iter().map(|r| r.name()))
        .collect();
    format!(
        "| {} |\n|{}\n",
        names.join(" | "),
        " --- |".repeat(names.len())
    )
}

/// The integrator, dt, substeps and CCD cells of a setting's table row.
fn setting_cells(s: &Setting) -> String {
    format!(
        "{:?} | {} | {} | {}",
        s.integrator,
        format_dt(s.dt),
        s.substeps,
        if s.ccd { "on" } else { "off" }
    )
}

/// Ends a table row with the row's error on every reference scene.
fn push_errors(out: &mut String, row: &Row) {
    for r in Reference::ALL {
        out.push_str(&format!(" {} |", format_error(r, row.error(r))));
    }
    out.push('\n');
}

/// The study as a markdown table, one row per setting.
pub fn markdown(rows: &[Row]) -> String {
    let mut out = table_header(&[
        "integrator",
        "dt",
        "substeps",
        "CCD",
        "ns/marble-step",
        "µs/marble/s",
    ]);
    for row in rows {
        out.push_str(&format!(
            "| {} | {:.0} | {:.1} |",
            setting_cells(&row.setting),
            row.ns_per_step,
            row.us_per_second()
        ));
        push_errors(&mut out, row);
    }
    out
}

/// The Pareto front of every reference scene as markdown: for each, the settings no other
/// setting beats on both cost (per simulated second) and error.
pub fn front_markdown(rows: &[Row]) -> String {
    let mut out = String::new();
    for reference in Reference::ALL {
        out.push_str(&format!(
            "### Pareto front: {} ({})\n\n| integrator | dt | substeps | CCD | µs/marble/s | error |\n| --- | --- | --- | --- | --- | --- |\n",
            reference.name(),
            reference.description()
        ));
        for i in pareto_front(rows, reference) {
            let r = &rows[i];
            out.push_str(&format!(
                "| {} | {:.1} | {} |\n",
                setting_cells(&r.setting),
                r.us_per_second(),
                format_error(reference, r.error(reference))
            ));
        }
        out.push('\n');
    }
    out
}

/// The presets measured like the grid, at dt = 1/30 and 1/60, as markdown.
pub fn presets_markdown(length: Length) -> String {
    let mut settings = Vec::new();
    for dt in [1.0 / 30.0, 1.0 / 60.0] {
        for p in Preset::ALL {
            settings.push(Setting::preset(p, dt));
        }
    }
    let rows = run(&settings, length, |_| {});
    let mut out = table_header(&["preset", "dt", "substeps", "ns/marble-step", "µs/marble/s"]);
    for row in &rows {
        out.push_str(&format!(
            "| {:?} | {} | {} | {:.0} | {:.1} |",
            row.setting.preset.expect("preset rows"),
            format_dt(row.setting.dt),
            row.setting.substeps,
            row.ns_per_step,
            row.us_per_second()
        ));
        push_errors(&mut out, row);
    }
    out
}

/// Effect and cost of compensated summation ([`StepConfig::compensated`]): a 0.1 s free
/// fall at dt = 1e-6 s from 1 m and from 100 m (where one step's motion is below half an
/// f32 ulp of the height) and a bounce 10 km from the origin, each with it on and off, and
/// the cost on the walled board.
pub fn compensation_markdown(length: Length) -> String {
    let mut out = String::from(
        "| compensated | 0.1 s free fall at dt = 1e-6 s from y = 1 m | the same from y = 100 m | bounce 10 km out (worst of apexes 1–3) | ns/marble-step |\n| --- | --- | --- | --- | --- |\n",
    );
    let (marbles, steps, repeats) = length.cost_sample();
    for compensated in [true, false] {
        let fall_error = |y0: f32| {
            let fall = Scene {
                dt: 1e-6,
                integrator: Integrator::VelocityVerlet,
                marbles: vec![MarbleDesc::at([0.0, y0, 0.0])],
                ..Scene::default()
            };
            let n = 100_000;
            let (x, _) = *trajectory_with(&fall, compensated, n)
                .last()
                .expect("steps");
            let t = n as f32 * 1e-6;
            let exact = 0.5 * G * t * t;
            ((y0 - x.y - exact) / exact).abs()
        };
        let (fall_1, fall_100) = (fall_error(1.0), fall_error(100.0));

        let offset = Vec3::new(-7e3, 7e3, 3e3);
        let mut far = scenes::drop_on_plane(1.0, R, 0.8);
        far.integrator = Integrator::VelocityVerlet;
        far.boards[0].position = offset.to_array();
        far.marbles[0].position = (offset + Vec3::new(0.0, 1.0 + R, 0.0)).to_array();
        let traj: Vec<(Vec3, Vec3)> = trajectory_with(&far, compensated, 240 * 4)
            .into_iter()
            .map(|(x, v)| (x - offset, v))
            .collect();
        let a = apexes(&traj, R);
        let far_error = (0..3)
            .map(|k| {
                let exact = 0.8f32.powi(2 * (k as i32 + 1));
                a.get(k).map_or(1.0, |h| ((h - exact) / exact).abs())
            })
            .fold(0.0, f32::max);
        let setting = Setting {
            integrator: Integrator::VelocityVerlet,
            dt: 1.0 / 60.0,
            substeps: 1,
            ccd: true,
            compensated,
            preset: None,
        };
        out.push_str(&format!(
            "| {} | {:.3}% | {:.3}% | {:.3}% | {:.0} |\n",
            if compensated { "on (default)" } else { "off" },
            100.0 * fall_1,
            100.0 * fall_100,
            100.0 * far_error,
            cost(&setting, marbles, steps, repeats)
        ));
    }
    out
}

/// Neverball's cheap model against the true one. Drift: a marble resting 0.3 m from the
/// axis of a large board that starts level and turns about Z at each rate until it has
/// tilted 0.1 rad, rolling on (Balanced preset, dt = 1/120); how far apart the two models'
/// marbles end, relative to the distance the true one rolled. Cost: 1,000 marbles on a
/// walled board turning at 0.1 rad/s (it turns 0.07 rad while measured), each model.
pub fn tilt_markdown(length: Length) -> String {
    let (marbles, steps, repeats) = length.cost_sample();
    let mut out = String::from(
        "| tilt rate (rad/s) | time to tilt 0.1 rad | drift of the gravity-tilt model |\n| --- | --- | --- |\n",
    );
    for rate in [0.03f32, 0.1, 0.3, 1.0, 3.0] {
        let duration = 0.1 / rate;
        let run = |cheap: bool| {
            let mut board = BoardDesc::new(ShapeDesc::Cuboid {
                half_extents: [10.0, 0.05, 10.0],
            });
            board.position = [0.0, -0.05, 0.0];
            board.angular_velocity = [0.0, 0.0, rate];
            let scene = Scene {
                dt: 1.0 / 120.0,
                preset: Some(Preset::Balanced),
                rolling: true,
                tilt_as_gravity: cheap,
                boards: vec![board],
                marbles: vec![MarbleDesc::at([0.3, R, 0.0])],
                ..Scene::default()
            };
            let mut sim = Simulation::from_scene(&scene).expect("valid tilt scene");
            let n = (duration * 120.0).round() as usize;
            for _ in 0..n {
                sim.step();
            }
            sim.marble_world_state(0).0
        };
        let truth = run(false);
        let cheap = run(true);
        let start = Vec3::new(0.3, R, 0.0);
        let drift = (cheap - truth).length() / (truth - start).length().max(1e-9);
        out.push_str(&format!(
            "| {rate} | {duration:.2} s | {:.2}% |\n",
            100.0 * drift
        ));
    }
    let cost_of = |cheap: bool| {
        let mut scene = scenes::walled_board(marbles);
        scene.rolling = true;
        scene.preset = Some(Preset::Balanced);
        scene.dt = 1.0 / 60.0;
        scene.boards[0].angular_velocity = [0.0, 0.0, 0.1];
        scene.tilt_as_gravity = cheap;
        scene_cost(&scene, true, steps, repeats)
    };
    out.push_str(&format!(
        "\nCost at 0.1 rad/s, rolling on: moving board {:.0} ns/marble-step, gravity tilt {:.0}.\n",
        cost_of(false),
        cost_of(true)
    ));
    out
}
