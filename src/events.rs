//! What happened during a step, for programs: impacts, contacts that start and end, and
//! marbles entering and leaving sensors.
//!
//! Each is a bevy_ecs [`Message`] (read with `MessageReader<T>` in any schedule, `Update`
//! included) and, the same value, an [`EntityEvent`] triggered on the marble, for
//! observers (`commands.entity(marble).observe(|impact: On<MarbleImpact>| …)`).
//!
//! - [`MarbleImpact`]: one per *collision* (not contact) of a marble with a board or with
//!   another marble, in whichever substep it happens, with the normal closing speed before
//!   the response. A marble resting on a board produces none.
//! - [`ContactStarted`] and [`ContactEnded`]: the step a marble begins to touch a board or
//!   another marble, and the step it stops; each pair once, in that order. A pair touches
//!   during a step when it collides in any of its substeps or touches at its end, so a
//!   marble that bounces off a board gets `ContactStarted` at the impact and `ContactEnded`
//!   once it has left. A marble–marble pair is reported once, with the pair's first
//!   marble as `marble`. A sleeping marble keeps touching what it touched.
//! - [`SensorEntered`] and [`SensorExited`]: the step a marble's centre moves inside a
//!   [`Sensor`](crate::components::Sensor) volume, and the step it leaves.
//!
//! Impacts and contacts are recorded only with [`StepConfig::events`] on (the Bevy plugin
//! records them whatever it says, a `StepConfig` inserted later included;
//! [`Simulation`](crate::Simulation) leaves it off unless asked); sensors are
//! checked whenever there are any. In a [`Simulation`](crate::Simulation) the messages of a
//! step stay readable until the end of the next step.
//!
//! [`StepConfig::events`]: crate::config::StepConfig::events

use bevy_ecs::prelude::*;
use glam::{IVec3, Quat, Vec3};
use parry3d::bounding_volume::{Aabb, BoundingVolume};

use crate::geometry::{BoardGeometry, PartShape};

/// A collision of `marble` with a board or another marble.
#[derive(Message, EntityEvent, Clone, Copy, Debug, PartialEq)]
pub struct MarbleImpact {
    /// The marble (a marble–marble pair's first marble).
    #[event_target]
    pub marble: Entity,
    /// The board or the other marble.
    pub other: Entity,
    /// The contact point, world frame, m.
    pub point: Vec3,
    /// Unit normal from `other` towards `marble`.
    pub normal: Vec3,
    /// Normal closing speed before the response, m/s (> 0).
    pub speed: f32,
}

/// `marble` began to touch `other` (a board or a marble) during this step.
#[derive(Message, EntityEvent, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ContactStarted {
    /// The marble.
    #[event_target]
    pub marble: Entity,
    /// The board or the other marble.
    pub other: Entity,
}

/// `marble` stopped touching `other` during this step (or one of them was despawned).
#[derive(Message, EntityEvent, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ContactEnded {
    /// The marble.
    #[event_target]
    pub marble: Entity,
    /// The board or the other marble.
    pub other: Entity,
}

/// `marble`'s centre moved inside `sensor` during this step.
#[derive(Message, EntityEvent, Clone, Copy, Debug, PartialEq, Eq)]
pub struct SensorEntered {
    /// The sensor.
    pub sensor: Entity,
    /// The marble.
    #[event_target]
    pub marble: Entity,
}

/// `marble`'s centre left `sensor` during this step (or one of them was despawned).
#[derive(Message, EntityEvent, Clone, Copy, Debug, PartialEq, Eq)]
pub struct SensorExited {
    /// The sensor.
    pub sensor: Entity,
    /// The marble.
    #[event_target]
    pub marble: Entity,
}

/// The event stages' state (a resource): the pairs touching and the marbles inside sensors
/// at the last step and during this one, and the sensors' grid. Its buffers are reused, so
/// a warmed-up step allocates nothing.
#[derive(Resource, Default, Debug)]
pub struct EventState {
    /// `(marble, other)` pairs touching during this step, unsorted and repeated.
    pub(crate) touching: Vec<(Entity, Entity)>,
    /// The same at the last step, sorted and unique.
    pub(crate) touched: Vec<(Entity, Entity)>,
    /// The last step's `touching` as it was recorded, before the sleeping marbles' pairs
    /// were added and it was sorted.
    pub(crate) touched_raw: Vec<(Entity, Entity)>,
    /// How many marbles slept when `touched` was made, and [`SleepState`]'s count of steps
    /// that put marbles to sleep then: the pairs it keeps for sleepers stand while neither
    /// changes (none fell asleep, so as many means none woke or went).
    ///
    /// [`SleepState`]: crate::sleep::SleepState
    pub(crate) sleepers: (usize, u32),
    /// `(sensor, marble)` pairs inside, at this step and the last (sorted, unique).
    pub(crate) inside: Vec<(Entity, Entity)>,
    pub(crate) was_inside: Vec<(Entity, Entity)>,
    /// The bounded sensors' world bounds, the grid over them, and for each its entity,
    /// pose and shape; the unbounded ones (half-spaces) apart.
    pub(crate) sensor_bounds: Vec<Aabb>,
    pub(crate) sensor_grid: SensorGrid,
    pub(crate) bounded: Vec<SensorVolume>,
    pub(crate) unbounded: Vec<SensorVolume>,
    /// `(sensor, marble)` pairs crossed within this step (entered and left at once).
    pub(crate) crossed: Vec<(Entity, Entity)>,
    /// Where the marbles were before this substep's impact and contact observers could run
    /// (noted only while there are sensors and such observers): one moved since was sent
    /// there by an observer.
    pub(crate) noted: Vec<(Entity, Vec3)>,
    /// Which event types have observers, by [`Observed`] bit: only those are triggered
    /// (a pour's thousands of impacts per substep cost a message each, not an observer
    /// dispatch each).
    pub(crate) observed: u8,
}

/// The bits of [`EventState::observed`].
pub(crate) struct Observed;

impl Observed {
    pub(crate) const IMPACT: u8 = 1;
    pub(crate) const STARTED: u8 = 2;
    pub(crate) const ENDED: u8 = 4;
    pub(crate) const ENTERED: u8 = 8;
    pub(crate) const EXITED: u8 = 16;
}

/// Where a marble's centre was at the start of the step (added to marbles while there are
/// sensors): a marble that crosses a thin sensor within one step enters and leaves it.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct SensorTrack(pub Vec3);

/// A sensor as one step sees it.
#[derive(Clone, Debug)]
pub(crate) struct SensorVolume {
    pub(crate) entity: Entity,
    pub(crate) position: Vec3,
    /// The inverse of its rotation (world → local).
    pub(crate) inverse: Quat,
    pub(crate) geometry: std::sync::Arc<BoardGeometry>,
}

impl SensorVolume {
    /// Whether the segment from `a` to `b` (world frame), neither end inside, passes
    /// through the volume: a marble that crossed a thin sensor within one step.
    pub(crate) fn crossed(&self, a: Vec3, b: Vec3) -> bool {
        let (la, lb) = (
            self.inverse * (a - self.position),
            self.inverse * (b - self.position),
        );
        self.geometry.parts().iter().any(|part| {
            let inv = part.rotation.conjugate();
            let (qa, qb) = (inv * (la - part.translation), inv * (lb - part.translation));
            part_crossed(&part.shape, qa, qb)
        })
    }

    /// Whether the world point `p` is inside the volume.
    pub(crate) fn contains(&self, p: Vec3) -> bool {
        let local = self.inverse * (p - self.position);
        self.geometry.parts().iter().any(|part| {
            let q = part.rotation.conjugate() * (local - part.translation);
            part_contains(&part.shape, q)
        })
    }
}

/// Whether the point `q` (in the part's frame) is inside the part's shape (see
/// [`Sensor`](crate::components::Sensor)).
fn part_contains(shape: &PartShape, q: Vec3) -> bool {
    match shape {
        PartShape::HalfSpace(_) => q.y <= 0.0,
        PartShape::Cuboid(c) => q.abs().cmple(c.half_extents).all(),
        PartShape::Bowl(r) => q.y <= 0.0 && q.length_squared() <= r * r,
        PartShape::HeightField(field) => below_height_field(field, q),
        PartShape::TriMesh(mesh) => inside_closed_mesh(mesh, q),
    }
}

/// Whether the segment from `a` to `b` (the part's frame) passes through the part's shape.
fn part_crossed(shape: &PartShape, a: Vec3, b: Vec3) -> bool {
    use parry3d::query::{Ray, RayCast};
    let ray = Ray::new(a, b - a);
    match shape {
        PartShape::HalfSpace(h) => h.cast_local_ray(&ray, 1.0, true).is_some(),
        PartShape::Cuboid(c) => c.cast_local_ray(&ray, 1.0, true).is_some(),
        PartShape::TriMesh(m) => m.cast_local_ray(&ray, 1.0, true).is_some(),
        PartShape::HeightField(f) => f.cast_local_ray(&ray, 1.0, true).is_some(),
        PartShape::Bowl(r) => {
            // Points along the segment at most a quarter of the radius apart.
            let n = ((b - a).length() / (0.25 * r)).ceil().clamp(1.0, 1024.0) as u32;
            (1..n).any(|k| part_contains(shape, a.lerp(b, k as f32 / n as f32)))
        }
    }
}

/// Below the surface of a height field, within its span.
fn below_height_field(field: &parry3d::shape::HeightField, q: Vec3) -> bool {
    let Some((i, j)) = field.cell_at_point(q) else {
        return false;
    };
    let (a, b) = field.triangles_at(i, j);
    [a, b].into_iter().flatten().any(|t| {
        // The triangle under `q` in the XZ plane, and its height there.
        let (p0, p1, p2) = (t.a, t.b, t.c);
        let d1 = glam::Vec2::new(p1.x - p0.x, p1.z - p0.z);
        let d2 = glam::Vec2::new(p2.x - p0.x, p2.z - p0.z);
        let dq = glam::Vec2::new(q.x - p0.x, q.z - p0.z);
        let det = d1.perp_dot(d2);
        if det == 0.0 {
            return false;
        }
        let u = dq.perp_dot(d2) / det;
        let v = d1.perp_dot(dq) / det;
        let tol = -1e-6;
        u >= tol
            && v >= tol
            && u + v <= 1.0 - tol
            && q.y <= p0.y + u * (p1.y - p0.y) + v * (p2.y - p0.y)
    })
}

/// Inside a closed triangle mesh: a ray from `q` crosses its surface an odd number of
/// times (the ray's direction is skewed so that it meets no edge of an axis-aligned mesh).
fn inside_closed_mesh(mesh: &parry3d::shape::TriMesh, q: Vec3) -> bool {
    if !mesh.local_aabb().contains_local_point(q) {
        return false;
    }
    let dir = Vec3::new(0.5773, 0.5779, 0.5767).normalize();
    let mut crossings = 0u32;
    for t in mesh.triangles() {
        // Möller–Trumbore.
        let (e1, e2) = (t.b - t.a, t.c - t.a);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            continue;
        }
        let s = q - t.a;
        let u = s.dot(p) / det;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let qv = s.cross(e1);
        let v = dir.dot(qv) / det;
        if v < 0.0 || u + v > 1.0 {
            continue;
        }
        if e2.dot(qv) / det > 0.0 {
            crossings += 1;
        }
    }
    crossings % 2 == 1
}

/// Writes `event` as a message and, when `observed`, triggers it on its marble.
#[inline]
pub(crate) fn emit<E>(commands: &mut Commands, messages: &mut Messages<E>, event: E, observed: bool)
where
    E: Message + for<'t> EntityEvent<Trigger<'t>: Default> + Copy,
{
    messages.write(event);
    if observed {
        commands.trigger(event);
    }
}

/// Moves every message of the engine on by one step (double buffering): what the last
/// step wrote stays readable, what the step before it wrote is dropped. A Bevy app does
/// this itself; [`Simulation::step`](crate::Simulation::step) calls it.
pub fn update_messages(world: &mut World) {
    fn update<E: Message>(world: &mut World) {
        if let Some(mut m) = world.get_resource_mut::<Messages<E>>() {
            m.update();
        }
    }
    update::<MarbleImpact>(world);
    update::<ContactStarted>(world);
    update::<ContactEnded>(world);
    update::<SensorEntered>(world);
    update::<SensorExited>(world);
    update::<crate::validate::QuarantineReport>(world);
    update::<crate::validate::StepRefused>(world);
}

/// A dense grid over the sensors' bounds, for point and short-segment queries: each cell
/// lists the sensors whose bounds overlap it, so a marble's query reads one or two cells,
/// and a marble outside every sensor's bounds stops at one box test. Cells are about as
/// wide as a typical sensor (the median of their largest sides), doubled until the grid
/// has at most [`SensorGrid::MAX_CELLS`] cells; a sensor that would cover more than
/// [`SensorGrid::MAX_SPAN`] cells is checked for every query instead.
#[derive(Debug, Default)]
pub(crate) struct SensorGrid {
    /// The union of the bounds, and the cell counts along each axis.
    bounds: Option<Aabb>,
    inv_cell: f32,
    dims: IVec3,
    /// Start of each cell's sensors in `items` (one more entry than cells).
    start: Vec<u32>,
    items: Vec<u32>,
    /// The sensors too large for cells.
    large: Vec<u32>,
    /// Scratch: each sensor's largest side, and each cell's count.
    sides: Vec<f32>,
}

impl SensorGrid {
    const MAX_CELLS: i64 = 1 << 16;
    const MAX_SPAN: i64 = 64;

    /// Rebuilds the grid over `bounds` (one per sensor, in sensor order).
    pub(crate) fn build(&mut self, bounds: &[Aabb]) {
        self.large.clear();
        self.items.clear();
        self.start.clear();
        let Some(union) = bounds.iter().copied().reduce(|a, b| a.merged(&b)) else {
            self.bounds = None;
            return;
        };
        if !(union.mins.is_finite() && union.maxs.is_finite()) {
            // Bounds that reach past f32's range (a huge sensor turned) have no grid: every
            // sensor is checked for every query.
            self.bounds = None;
            self.large.extend(0..bounds.len() as u32);
            return;
        }
        self.sides.clear();
        self.sides
            .extend(bounds.iter().map(|b| b.extents().max_element().max(1e-6)));
        self.sides.sort_unstable_by(f32::total_cmp);
        let mut cell = self.sides[self.sides.len() / 2];
        let size = union.extents();
        let dims = loop {
            // Each side clamped to the most cells a grid may have, so the product cannot
            // overflow.
            let d = (size / cell)
                .ceil()
                .clamp(Vec3::ONE, Vec3::splat(Self::MAX_CELLS as f32))
                .as_ivec3();
            if (d.x as i64) * (d.y as i64) * (d.z as i64) <= Self::MAX_CELLS {
                break d;
            }
            cell *= 2.0;
        };
        self.bounds = Some(union);
        self.inv_cell = 1.0 / cell;
        self.dims = dims;
        let cells = (dims.x * dims.y * dims.z) as usize;
        self.start.resize(cells + 1, 0);
        // Count, then place (a counting sort of the (cell, sensor) entries).
        for pass in 0..2 {
            for (k, b) in bounds.iter().enumerate() {
                let (lo, hi) = self.range(b);
                let span = (hi - lo + IVec3::ONE).as_i64vec3();
                if span.x * span.y * span.z > Self::MAX_SPAN {
                    if pass == 0 {
                        self.large.push(k as u32);
                    }
                    continue;
                }
                for x in lo.x..=hi.x {
                    for y in lo.y..=hi.y {
                        for z in lo.z..=hi.z {
                            let c = self.index(IVec3::new(x, y, z));
                            if pass == 0 {
                                self.start[c + 1] += 1;
                            } else {
                                self.items[self.start[c] as usize] = k as u32;
                                self.start[c] += 1;
                            }
                        }
                    }
                }
            }
            if pass == 0 {
                for c in 0..cells {
                    self.start[c + 1] += self.start[c];
                }
                self.items.resize(self.start[cells] as usize, 0);
            } else {
                // Placing moved each start to the next cell's; move them back.
                for c in (1..=cells).rev() {
                    self.start[c] = self.start[c - 1];
                }
                self.start[0] = 0;
            }
        }
    }

    /// The cells (clamped to the grid) that box `b` overlaps.
    fn range(&self, b: &Aabb) -> (IVec3, IVec3) {
        let lo = self.bounds.map_or(Vec3::ZERO, |u| u.mins);
        let cell = |p: Vec3| {
            ((p - lo) * self.inv_cell)
                .floor()
                .as_ivec3()
                .clamp(IVec3::ZERO, self.dims - IVec3::ONE)
        };
        (cell(b.mins), cell(b.maxs))
    }

    #[inline]
    fn index(&self, c: IVec3) -> usize {
        ((c.x * self.dims.y + c.y) * self.dims.z + c.z) as usize
    }

    /// Calls `f(sensor)` for every sensor whose bounds may overlap box `b` (some more than
    /// once when `b` spans several cells).
    #[inline]
    pub(crate) fn query(&self, b: &Aabb, mut f: impl FnMut(u32)) {
        for &k in &self.large {
            f(k);
        }
        let Some(union) = self.bounds else {
            return;
        };
        if b.mins.cmpgt(union.maxs).any() || b.maxs.cmplt(union.mins).any() {
            return;
        }
        let (lo, hi) = self.range(b);
        for x in lo.x..=hi.x {
            for y in lo.y..=hi.y {
                for z in lo.z..=hi.z {
                    let c = self.index(IVec3::new(x, y, z));
                    for &k in &self.items[self.start[c] as usize..self.start[c + 1] as usize] {
                        f(k);
                    }
                }
            }
        }
    }
}
