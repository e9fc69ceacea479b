//! What a run did, for people to look at: [`Recorder`] samples a [`Simulation`] as it steps
//! (marble states at decimated frames, board poses, the strongest impacts, energy, speed,
//! penetration), and the [`Recording`] it yields writes a self-contained HTML replay page
//! ([`Recording::write_html`]) and feeds the CLI's plots and summary.
//!
//! ```
//! use bevy_marble::prelude::*;
//! use bevy_marble::replay::{Recorder, ReplayOptions};
//!
//! let scene = Scene::from_ron_str(
//!     "(boards: [(shape: Plane(()))], marbles: [(position: (0.0, 0.5, 0.0))])",
//! )?;
//! let mut sim = Simulation::from_scene(&scene)?;
//! let mut recorder = Recorder::new(&mut sim, 240, ReplayOptions::default());
//! for step in 1..=240 {
//!     sim.step();
//!     recorder.after_step(&sim, step);
//! }
//! let recording = recorder.finish("a drop");
//! assert_eq!(recording.frame_steps().last(), Some(&240));
//! let mut page = Vec::new();
//! recording.write_html(&mut page).unwrap();
//! # Ok::<(), SceneError>(())
//! ```

pub mod wireframe;

use std::io::{self, Write};

use bevy_ecs::message::Messages;
use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;

use crate::components::{Collider, Mass, Position, Radius, Rotation};
use crate::config::{GravityTilt, StepConfig};
use crate::events::{MarbleImpact, SensorEntered};
use crate::pairs::MarbleContacts;
use crate::simulation::Simulation;

/// How densely a [`Recorder`] samples a run, which bounds the page's size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayOptions {
    /// Most frames per simulated second.
    pub max_fps: f32,
    /// Most marble states recorded in all (frames × marbles shown): each costs 24 bytes,
    /// 32 characters in the page.
    pub max_marble_frames: usize,
    /// Most marbles shown; beyond this every k-th marble is recorded.
    pub max_marbles: usize,
    /// Most impacts kept per frame (the strongest) for the page's flashes.
    pub impacts_per_frame: usize,
}

impl Default for ReplayOptions {
    /// 60 frames per second, 125,000 marble states (about 4 MB of page), 20,000 marbles,
    /// 64 impacts a frame.
    fn default() -> Self {
        ReplayOptions {
            max_fps: 60.0,
            max_marble_frames: 125_000,
            max_marbles: 20_000,
            impacts_per_frame: 64,
        }
    }
}

/// A collision kept for the replay.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Impact {
    /// Time of the step it happened in, s.
    pub time: f32,
    /// The scene's index of the marble.
    pub marble: u32,
    /// Where, world frame, m.
    pub point: Vec3,
    /// Normal closing speed, m/s.
    pub speed: f32,
}

/// One board as the replay draws it.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardTrack {
    /// Its outline and edges, board frame ([`wireframe::segments`]).
    pub segments: Vec<[Vec3; 2]>,
    /// Its world pose at each frame.
    pub poses: Vec<(Vec3, Quat)>,
}

impl BoardTrack {
    /// Whether the board stands still over the whole recording.
    pub fn is_still(&self) -> bool {
        self.poses.windows(2).all(|w| w[0] == w[1])
    }
}

/// A run as recorded by a [`Recorder`]: frames of marble states (world frame), board poses,
/// impacts, and per-frame energy and speed.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// What was run (the page's title).
    pub title: String,
    /// The scene's step, s.
    pub dt: f32,
    /// Marbles in the scene.
    pub marbles: usize,
    /// Recorded marbles are the scene's marbles `0, k, 2k, …` for this `k`.
    pub marble_stride: usize,
    /// Radius of each recorded marble, m.
    pub radii: Vec<f32>,
    /// The step of each frame (0 first, the last step last).
    steps: Vec<u64>,
    /// Frame-major: `frames × radii.len()` positions and velocities, world frame.
    positions: Vec<Vec3>,
    velocities: Vec<Vec3>,
    /// The boards, in the scene's order.
    pub boards: Vec<BoardTrack>,
    /// The sensors (goals, holes), in the scene's order, drawn the same way.
    pub sensors: Vec<BoardTrack>,
    /// The strongest impacts of each frame's interval, in time order.
    pub impacts: Vec<Impact>,
    /// Every impact of the run, counted.
    pub impact_count: u64,
    /// The largest impact speed of the run, m/s (0 without impacts).
    pub fastest_impact: f32,
    /// Total energy of all marbles at each frame, J: kinetic (moving and spinning) and
    /// potential in the world's gravity (zero at the world's origin).
    pub energy: Vec<f64>,
    /// The kinetic part of [`Self::energy`] at each frame, J.
    pub kinetic: Vec<f64>,
    /// Fastest and mean marble speed at each frame, m/s.
    pub speed_max: Vec<f32>,
    /// Mean speed of all (finite) marbles at each frame, m/s.
    pub speed_mean: Vec<f32>,
    /// Deepest penetration of a marble into a board at any frame, m (0: none).
    pub deepest_board: f32,
    /// Deepest overlap of two marbles at any frame, m (0: none).
    pub deepest_pair: f32,
    /// The radius deepest penetrations are measured against (the largest marble's), m.
    pub radius_max: f32,
    /// Each of the simulation's sensors: its name and how many times a marble entered it.
    pub sensor_entries: Vec<(String, u64)>,
}

/// Samples a [`Simulation`] as it steps into a [`Recording`].
pub struct Recorder {
    steps: u64,
    stride: u64,
    dt: f64,
    gravity: Vec3,
    masses: Vec<f32>,
    impacts_per_frame: usize,
    pending: Vec<Impact>,
    /// The scene's index of each marble entity.
    index: std::collections::HashMap<bevy_ecs::entity::Entity, u32>,
    rec: Recording,
}

impl Recorder {
    /// Starts recording `sim`, to be stepped `steps` times, and records its state as the
    /// first frame. Turns on the simulation's impact messages ([`StepConfig::events`]),
    /// which changes no result.
    pub fn new(sim: &mut Simulation, steps: u64, options: ReplayOptions) -> Recorder {
        sim.world_mut().resource_mut::<StepConfig>().events = true;
        let config = sim.world().resource::<StepConfig>().clone();
        let dt = config.dt as f64;
        let n = sim.marbles().len();
        let marble_stride = n.div_ceil(options.max_marbles.max(1)).max(1);
        let shown = n.div_ceil(marble_stride);
        let stride = frame_stride(steps, shown, dt, &options);
        let world = sim.world();
        let (mut radii, mut masses) = (Vec::new(), Vec::new());
        for &e in sim.marbles().iter().step_by(marble_stride) {
            radii.push(world.get::<Radius>(e).map_or(0.0, |r| r.0));
            masses.push(world.get::<Mass>(e).map_or(0.0, Mass::get));
        }
        let extent = plane_extent(sim);
        let track = |e: &bevy_ecs::entity::Entity| BoardTrack {
            segments: world
                .get::<Collider>(*e)
                .map_or_else(Vec::new, |c| wireframe::segments(&c.0, extent)),
            poses: Vec::new(),
        };
        let boards = sim.boards().iter().map(track).collect();
        let sensors = sim.sensors().iter().map(track).collect();
        let mut recorder = Recorder {
            steps,
            stride,
            dt,
            gravity: config.gravity,
            masses,
            impacts_per_frame: options.impacts_per_frame,
            pending: Vec::new(),
            index: (sim.marbles().iter().enumerate())
                .map(|(i, &e)| (e, i as u32))
                .collect(),
            rec: Recording {
                title: String::new(),
                dt: config.dt,
                marbles: n,
                marble_stride,
                radius_max: radii.iter().copied().fold(0.0, f32::max),
                radii,
                steps: Vec::new(),
                positions: Vec::new(),
                velocities: Vec::new(),
                boards,
                sensors,
                impacts: Vec::new(),
                impact_count: 0,
                fastest_impact: 0.0,
                energy: Vec::new(),
                kinetic: Vec::new(),
                speed_max: Vec::new(),
                speed_mean: Vec::new(),
                deepest_board: 0.0,
                deepest_pair: 0.0,
                sensor_entries: sim
                    .sensors()
                    .iter()
                    .map(|&e| {
                        let name = world.get::<bevy_ecs::name::Name>(e);
                        (name.map_or_else(String::new, |n| n.as_str().to_owned()), 0)
                    })
                    .collect(),
            },
        };
        recorder.record(sim, 0);
        recorder
    }

    /// Steps between frames.
    pub fn stride(&self) -> u64 {
        self.stride
    }

    /// Call after each [`Simulation::step`], with the number of steps taken so far: counts
    /// the step's impacts and records a frame every [`Self::stride`] steps and at the last.
    pub fn after_step(&mut self, sim: &Simulation, step: u64) {
        let time = (step as f64 * self.dt) as f32;
        if let Some(messages) = sim.world().get_resource::<Messages<MarbleImpact>>() {
            for m in messages.iter_current_update_messages() {
                self.rec.impact_count += 1;
                self.rec.fastest_impact = self.rec.fastest_impact.max(m.speed);
                if let Some(&i) = self.index.get(&m.marble) {
                    self.pending.push(Impact {
                        time,
                        marble: i,
                        point: m.point,
                        speed: m.speed,
                    });
                }
            }
            let k = self.impacts_per_frame;
            if self.pending.len() > 4 * k.max(64) {
                self.keep_strongest();
            }
        }
        if let Some(messages) = sim.world().get_resource::<Messages<SensorEntered>>() {
            for m in messages.iter_current_update_messages() {
                if let Some(i) = sim.sensors().iter().position(|&e| e == m.sensor) {
                    self.rec.sensor_entries[i].1 += 1;
                }
            }
        }
        if step.is_multiple_of(self.stride) || step == self.steps {
            self.keep_strongest();
            self.pending.sort_by(|a, b| a.time.total_cmp(&b.time));
            self.rec.impacts.append(&mut self.pending);
            self.record(sim, step);
        }
    }

    /// The recording, titled `title`.
    pub fn finish(mut self, title: &str) -> Recording {
        self.rec.title = title.to_owned();
        self.rec.impacts.append(&mut self.pending);
        self.rec
    }

    fn keep_strongest(&mut self) {
        let k = self.impacts_per_frame;
        if self.pending.len() > k {
            self.pending
                .select_nth_unstable_by(k, |a, b| b.speed.total_cmp(&a.speed));
            self.pending.truncate(k);
        }
    }

    fn record(&mut self, sim: &Simulation, step: u64) {
        let world = sim.world();
        let tilt = world.get_resource::<GravityTilt>().copied();
        let rec = &mut self.rec;
        rec.steps.push(step);
        let (mut kinetic, mut potential) = (0.0f64, 0.0f64);
        let (mut fastest, mut sum, mut count) = (0.0f32, 0.0f64, 0usize);
        let stride = rec.marble_stride;
        for (k, i) in (0..sim.marbles().len()).step_by(stride).enumerate() {
            // A marble the program despawned is recorded as nowhere (not drawn, not
            // counted), as a quarantined one is.
            let (x, v) = sim
                .try_marble_world_state(i)
                .unwrap_or((Vec3::NAN, Vec3::NAN));
            rec.positions.push(x);
            rec.velocities.push(v);
            let w = match tilt {
                Some(t) => t.spin_to_world(sim.marble_spin(i)),
                None => sim.marble_spin(i),
            };
            if !(x.is_finite() && v.is_finite() && w.is_finite()) {
                continue;
            }
            let (m, r) = (self.masses[k] as f64, rec.radii[k] as f64);
            // A solid sphere: I = 2/5 m r².
            kinetic += 0.5 * m * v.as_dvec3().length_squared()
                + 0.2 * m * r * r * w.as_dvec3().length_squared();
            potential -= m * self.gravity.as_dvec3().dot(x.as_dvec3());
            let s = v.length();
            fastest = fastest.max(s);
            sum += s as f64;
            count += 1;
        }
        rec.energy.push(kinetic + potential);
        rec.kinetic.push(kinetic);
        rec.speed_max.push(fastest);
        rec.speed_mean.push(if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        });
        let tracks = (rec.boards.iter_mut().zip(sim.boards()))
            .chain(rec.sensors.iter_mut().zip(sim.sensors()));
        for (track, &e) in tracks {
            // One the program despawned is recorded as nowhere from then on (not drawn).
            let Some(p) = world.get::<Position>(e).map(|p| p.0) else {
                track
                    .poses
                    .push((Vec3::NAN, Quat::from_xyzw(f32::NAN, 0.0, 0.0, 0.0)));
                continue;
            };
            let q = world.get::<Rotation>(e).map_or(Quat::IDENTITY, |r| r.0);
            track.poses.push(match tilt {
                Some(t) => (t.pivot + t.rotation * (p - t.pivot), t.rotation * q),
                None => (p, q),
            });
        }
        rec.deepest_board = rec.deepest_board.max(deepest_board(sim));
        if let Some(contacts) = world.get_resource::<MarbleContacts>() {
            for c in contacts.as_slice() {
                rec.deepest_pair = rec.deepest_pair.max(c.depth);
            }
        }
    }
}

/// Steps between frames for a run of `steps` steps of `dt` seconds showing `marbles`
/// marbles: no more than `max_fps` frames a second, and no more than `max_marble_frames`
/// marble states in all, counting the first and last step, which are always recorded
/// (a run of more marbles than that records those two frames alone).
pub fn frame_stride(steps: u64, marbles: usize, dt: f64, options: &ReplayOptions) -> u64 {
    // (A hair under the rate, so that 1/240 s in f32 still gives 4 steps a frame at 60.)
    let by_rate = (1.0 / (options.max_fps as f64 * dt) - 1e-6).ceil().max(1.0) as u64;
    // Frames after the first, with room for the last one off the stride.
    let frames = (options.max_marble_frames / marbles.max(1))
        .saturating_sub(2)
        .max(1) as u64;
    by_rate.max(steps.div_ceil(frames)).max(1)
}

/// Half-size of the grid that draws a plane: the farthest marble or bounded board corner
/// from the origin, with a margin (at least 0.25 m).
fn plane_extent(sim: &Simulation) -> f32 {
    let world = sim.world();
    let mut far = 0.0f32;
    for i in 0..sim.marbles().len() {
        let Some((x, _)) = sim.try_marble_state(i) else {
            continue;
        };
        if x.is_finite() {
            far = far.max(x.x.abs()).max(x.z.abs());
        }
    }
    for &b in sim.boards() {
        let p = world.get::<Position>(b).map_or(Vec3::ZERO, |p| p.0);
        if let Some(aabb) = world.get::<Collider>(b).and_then(|c| c.0.local_aabb()) {
            let r = (aabb.maxs - aabb.mins).length() * 0.5;
            far = far.max(p.x.abs() + r).max(p.z.abs() + r);
        }
    }
    (far * 1.2).max(0.25)
}

/// The deepest any marble reaches into any board now, m (0: none touches).
fn deepest_board(sim: &Simulation) -> f32 {
    let world = sim.world();
    let boards: Vec<_> = sim
        .boards()
        .iter()
        .filter_map(|&b| {
            let c = world.get::<Collider>(b)?;
            let p = world.get::<Position>(b).map_or(Vec3::ZERO, |p| p.0);
            let q = world.get::<Rotation>(b).map_or(Quat::IDENTITY, |r| r.0);
            Some((c.0.clone(), p, q.conjugate()))
        })
        .collect();
    let mut deepest = 0.0f32;
    for (i, &e) in sim.marbles().iter().enumerate() {
        let Some((x, _)) = sim.try_marble_state(i) else {
            continue;
        };
        let r = world.get::<Radius>(e).map_or(0.0, |r| r.0);
        if !x.is_finite() {
            continue;
        }
        for (geometry, p, inv) in &boards {
            let q = *inv * (x - *p);
            let query = Aabb::new(q - Vec3::splat(r), q + Vec3::splat(r));
            geometry.for_each_piece(&query, |part, _, piece| {
                let d = geometry.proximity(part, piece, q, Vec3::Y).distance;
                deepest = deepest.max(r - d);
            });
        }
    }
    deepest
}

impl Recording {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.steps.len()
    }

    /// The step of each frame.
    pub fn frame_steps(&self) -> &[u64] {
        &self.steps
    }

    /// Time of frame `f`, s.
    pub fn time(&self, f: usize) -> f32 {
        (self.steps[f] as f64 * self.dt as f64) as f32
    }

    /// The recorded marbles' positions at frame `f` (world frame, m).
    pub fn positions(&self, f: usize) -> &[Vec3] {
        let n = self.radii.len();
        &self.positions[f * n..(f + 1) * n]
    }

    /// The recorded marbles' velocities at frame `f` (world frame, m/s).
    pub fn velocities(&self, f: usize) -> &[Vec3] {
        let n = self.radii.len();
        &self.velocities[f * n..(f + 1) * n]
    }

    /// Writes the replay page: one HTML file with its script, styles and data inline, no
    /// network access. Marble states are stored as little-endian f32 in base64, so the
    /// page reads back exactly the recorded values.
    pub fn write_html(&self, w: &mut impl Write) -> io::Result<()> {
        let data = self.page_data();
        // Inside <script type="application/json"> only "</" could end the element early.
        let data = data.replace("</", "<\\/");
        let page = PAGE.replacen(DATA_SLOT, &data, 1);
        w.write_all(page.as_bytes())
    }

    fn page_data(&self) -> String {
        let f32s = |values: &mut dyn Iterator<Item = f32>| {
            let bytes: Vec<u8> = values.flat_map(f32::to_le_bytes).collect();
            base64(&bytes)
        };
        let vec3s = |v: &[Vec3]| f32s(&mut v.iter().flat_map(|p| p.to_array()));
        let tracks = |tracks: &[BoardTrack]| -> Vec<serde_json::Value> {
            tracks.iter().map(|b| {
                let poses = if b.is_still() {
                    &b.poses[..1.min(b.poses.len())]
                } else {
                    &b.poses[..]
                };
                serde_json::json!({
                    "segments": f32s(&mut b.segments.iter().flatten().flat_map(|p| p.to_array())),
                    "poses": f32s(&mut poses.iter().flat_map(|(p, q)| {
                        [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
                    })),
                })
            })
            .collect()
        };
        let times: Vec<f32> = (0..self.frames()).map(|f| self.time(f)).collect();
        serde_json::json!({
            "title": self.title,
            "dt": self.dt,
            "marbles": self.marbles,
            "marbleStride": self.marble_stride,
            "radii": f32s(&mut self.radii.iter().copied()),
            "steps": self.steps,
            "times": times,
            "positions": vec3s(&self.positions),
            "velocities": vec3s(&self.velocities),
            "boards": tracks(&self.boards),
            "sensors": tracks(&self.sensors),
            "impacts": {
                "time": f32s(&mut self.impacts.iter().map(|i| i.time)),
                "marble": base64(&self.impacts.iter().flat_map(|i| i.marble.to_le_bytes()).collect::<Vec<u8>>()),
                "point": f32s(&mut self.impacts.iter().flat_map(|i| i.point.to_array())),
                "speed": f32s(&mut self.impacts.iter().map(|i| i.speed)),
                "count": self.impact_count,
            },
            "energy": self.energy,
            "kinetic": self.kinetic,
            "speedMax": self.speed_max,
            "speedMean": self.speed_mean,
        })
        .to_string()
    }
}

/// The page, with [`DATA_SLOT`] where the recording's JSON goes.
const PAGE: &str = include_str!("page.html");
const DATA_SLOT: &str = "\"__REPLAY_DATA__\"";

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::base64;

    #[test]
    fn base64_matches_the_standard_alphabet_and_padding() {
        // RFC 4648, section 10.
        for (input, want) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), want);
        }
        assert_eq!(base64(&[0xfb, 0xff]), "+/8=");
    }
}
