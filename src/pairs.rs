//! Marble–marble collisions: broad phase, exact sphere–sphere narrow phase, and the pair
//! solver (`marble_collisions: true`).
//!
//! # The problem
//! Two marbles meeting is the two-body form of the seed's equation: along the line of
//! centres `n`, closing speed `u = (v₂ − v₁)·n`, impulse `J = −(1 + e) u / (1/m₁ + 1/m₂)`.
//! That is exact for an isolated impact, but marbles come in crowds: a Newton's cradle
//! passes one impact down a line of touching marbles, and a pile presses every marble
//! against its neighbours and the floor at once, so that gravity added in a step must be
//! cancelled through the whole pile. One pass of pairwise impulses does neither.
//!
//! # The method
//! Two stages per substep, both only with `marble_collisions` on.
//!
//! **Before integration** ([`PairSolver::find_touching`], [`PairSolver::solve_touching`];
//! stage `MarbleContacts`), at the substep's start, where positions are consistent:
//!
//! 1. **Broad phase: a uniform grid**, linear in the number of marbles. Each marble
//!    is bounded by the sphere around its free path over the substep (its integrator's
//!    displacement under its acceleration, along the boards it rests or slides on, plus a
//!    margin). Cells are as wide as the largest such sphere's diameter among the ordinary
//!    marbles (those at most twice the mean), so two ordinary marbles can touch only in the
//!    same or adjacent cells; marbles are counting-sorted by cell (one table entry per cell
//!    when the occupied span is compact, so that neighbouring cells are neighbours in
//!    memory; a hash of the cell otherwise), and each cell is paired with itself and its 13
//!    "forward" neighbours (every neighbouring pair of cells once). The rare large or fast
//!    marbles are paired through the cells their bound covers, or with every marble when
//!    that is fewer. The grid was chosen over sweep-and-prune (marbles on a board share one
//!    height, so sorting along an axis pairs whole rows) and over a BVH (rebuilt every
//!    substep for moving spheres, it costs `N log N` with pointer-chasing; a grid of
//!    uniform spheres is one counting sort). The pairs found stand for later substeps
//!    (a Verlet list): each bound is grown by a skin of a quarter radius, and the pairs
//!    are kept while every marble's sphere stays inside its bound after taking off the
//!    marbles' common drift (their mean displacement), so marbles sliding down a board
//!    together never rebuild; the few that leave their bounds are paired afresh on their
//!    own, and the grid is rebuilt only when many do. The spheres are gathered from the
//!    marbles before anything else ([`PairSolver::begin`], [`PairSolver::push_sphere`],
//!    [`PairSolver::cover_gathered`]): a substep in which no two marbles can meet (marbles
//!    spread over a board) stops there, without building the solver's bodies.
//! 2. **Narrow phase: exact sphere–sphere.** A pair touching at the start (within the
//!    touching tolerance) is judged, like board contacts, on its closing speed *before
//!    this step's forces*: faster than `restitution_threshold` is a collision, otherwise a
//!    contact.
//! 3. **Collisions at the start** get the two-body equation as a velocity change before the
//!    step's motion (exact for any integrator), as a cascade (below).
//! 4. **Contacts: sequential impulses with warm starting.** Every touching pair, every
//!    *speculative* pair (apart by a gap it could close during the substep, closing no
//!    faster than the threshold: a marble about to settle onto another), and the board
//!    contacts of those marbles (those recorded in the last substep, and speculative rows
//!    for the pieces of their [`crate::narrow::NearPieces`] lists they could reach during
//!    the substep), are solved together by projected Gauss–Seidel on the
//!    velocities the marbles would reach at the end of the substep: no approaching normal
//!    velocity (a speculative pair may approach at `gap / h`, closing its gap and no more),
//!    each accumulated impulse ≥ 0, starting from the previous substep's impulses (a
//!    pile's weight carries over), each update over-relaxed by 1.5 (successive
//!    over-relaxation: a pile's weight crosses its layers in about half the passes plain
//!    Gauss–Seidel needs; measured below). The pair rows are visited in colour order (no
//!    two rows of a colour share a marble, greedily coloured each substep), four rows of a
//!    colour at a time in SIMD lanes (each lane does the one-row update's operations in its
//!    order, so the result is bit for bit that of one row after another). Without the speculative rows, a marble a micrometre
//!    above its support falls freely for a substep and lands at `g h`: a settled pile
//!    would keep jittering at centimetres per second. The same holds for a board: a
//!    marble a micrometre above the floor, with no floor contact recorded, would be free
//!    for the solver, and the column it carries would fall for a substep; the floor
//!    catches only the lowest marble, and the others land on it at `g h`. The impulses are then applied as *forces
//!    over the substep* (added to each marble's acceleration), so every integrator moves
//!    the marbles consistently with them and the marble–board response handles the boards
//!    exactly as for a lone marble: a marble resting on another stays where it is.
//! 5. **Overlap** beyond a small slop (0.2% of the smaller radius) is projected out of
//!    positions, half of it per pass and at most a quarter of the radius, and at most one
//!    radius per marble in all (mass-weighted; boards do not move), without touching
//!    velocities, so no energy is added for it.
//!
//! **After the marble–board response** ([`PairSolver::find_impacts`],
//! [`PairSolver::resolve_impacts`]; stage `CollideMarbles`), with continuous collision: a
//! pair that was apart at the start and met during the
//! substep finds its time of impact along the relative path — linear, and exactly so for
//! marbles in free flight under the same gravity — by the root of
//! `|D₀ + (D₁ − D₀) τ| = r₁ + r₂`. If it would end overlapping by more than 5% of the
//! radius (or passed through), it collides there; a shallower meeting is left to the next
//! substep's contact stage, which judges it on the same closing speed (resolving it here
//! would stir a settled pile for nothing). A meeting ends no deeper than the pair's
//! relative displacement over the substep, so the stage first looks for a deep impact
//! among the pairs whose displacements differ by half that depth or more, and stops when
//! there is none (most substeps of a pile: bench scene (b)'s first second at 1,000 marbles
//! went from 5,051 M to 4,875 M instructions with this, the same bits).
//!
//! **The cascade.** Collisions get the two-body equation, earliest first; after an impact
//! inside the substep the marbles leave with their new velocity for the rest of it (their
//! positions move by `Δv (h − t*)`, which makes an isolated impact exact at any step). An
//! impulse can make a touching neighbour approach faster than the threshold, or drive a
//! marble into a board it touches: that pair (or board) then collides in turn, at the same
//! instant, and so on. A Newton's cradle therefore passes the motion to its last marble
//! instead of spreading it over the line, every impulse conserves momentum (boards aside)
//! and none adds energy. Every impact found is resolved; only what they pass on is capped.
//! Marbles a collision sends off their free paths are then checked, on the end positions,
//! in a few rounds: against the boards (the straight path since its last impact is
//! searched for its earliest board impact, so a marble knocked onto a floor it did not
//! touch rebounds there), against marbles the
//! broad phase did not pair with them, and against a marble they already met when one of
//! the two was hit again later (the floor's rebound sends it back into the marble that
//! knocked it): each such pair is traced back along the new straight paths to its meeting.
//! The search costs what the moved marbles cost, not what the pile costs: they are looked
//! up in the kept grid and paired with each other (and with the strays) through a grid of
//! their own, and whether a pair is already a row is read from its first marble's short
//! slice of rows (a counting sort). (A 100,000-marble pour moves thousands of marbles a
//! substep: its first 20 steps went from 43 to 28 µs per marble-step with this.)
//!
//! Piles need short substeps: bench scene (b) uses 8 substeps of a 1/60 s step and 15
//! (over-relaxed) solver passes; over fifteen starts of its 1,000-marble pour the last
//! marble above 5 cm/s stopped by 4.8 s. With fewer substeps the passes do not carry a
//! ten-layer pile's weight down within a substep, and the pile keeps stirring at a few
//! cm/s (overlaps 0.3–0.7% of the radius at 4 substeps, 2–3% at 2, 27–30% at 1, where
//! whole columns land within one step; see the README's measurements). Soft contacts in solver
//! substeps (Box2D v3's soft step: 30 Hz contacts, damping ratio 10, four solver
//! substeps of a 1/60 s step) were tried and measured: under a column of six 8 mm marbles
//! the lowest contact sagged by 0.45 r: a soft contact sags in proportion to its load
//! over `ω²`, a few tenths of a millimetre per marble above it at 30 Hz, and stiffer
//! contacts need shorter solver substeps. Marbles need the slop (0.2% of r), so the
//! contacts here stay rigid.
//!
//! With rolling on, touching marbles that spin also exert Coulomb friction on each other
//! (impulses at the start of each substep, capped by the contact's last normal impulse);
//! impacts inside a substep are smooth.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use bevy_ecs::prelude::*;
use glam::{IVec3, Mat4, Vec3, Vec4};

use crate::components::ContactKind;
use crate::geometry::PieceId;
use crate::narrow::{BoardSnapshot, Material, Path, TouchList};

/// Overlap left alone by the position projection, as a fraction of the smaller radius.
pub const PAIR_SLOP: f32 = 2e-3;

/// Share of an overlap the projection removes per pass.
const PROJECTION: f32 = 0.5;
/// Most a pass moves a pair apart, as a fraction of the smaller radius; and however many
/// contacts push it, a marble moves at most one radius in a substep's projection. A
/// marble that does not touch a board is more than a radius from it, so its centre never
/// crosses a board however thin (the board stage pushes it back out), while a crash's deep
/// overlaps go within a few substeps (a fiftieth of the radius per pass, as before, left
/// pairs of a one-substep pour 1.9 r inside each other for good).
const MAX_PROJECTION: f32 = 0.25;

/// Extra room around each marble's free path in the broad phase, as a fraction of its
/// radius, for the contact forces' change of path.
const BOUND_MARGIN: f32 = 0.1;

/// Impacts that would leave less overlap than this share of the radius at the end of
/// the substep are resolved by the next substep's contact stage instead.
const DISCRETE_OVERLAP: f32 = 0.05;

/// Up to this many marbles moved by collisions are looked up one by one after collisions
/// (and checked against each other directly); more, and they are paired with each other
/// (and with the strays) through a grid of their own.
const LATE_DIRECT: usize = 256;

/// When more than one marble in this many was moved by collisions, every marble is paired
/// again on the end positions instead (it costs about as much, and is simpler).
const LATE_SHARE: usize = 4;

/// How [`PairSolver::late_overlaps`] looks for pairs the collisions brought together.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LateSearch {
    /// The moved marbles against the kept grid, each other and the strays, one by one.
    Direct,
    /// The moved marbles against the kept grid, and through a grid of their own with each
    /// other and the strays.
    OwnGrid,
    /// Every marble paired again on the end positions.
    All,
}

/// Room added around each marble's bound sphere when the candidate pairs are found, as a
/// fraction of its radius: the pairs stand until a marble moves this far from where it
/// was relative to the marbles' common drift (module docs, step 1).
const SKIN: f32 = 0.25;

/// The candidate pairs are found afresh when more than this share of the marbles left
/// their skins (fewer are paired one by one).
const STRAY_SHARE: usize = 8;

/// Rounds of looking for what collided marbles run into on their new paths.
const LATE_ROUNDS: usize = 4;

/// Colours of the pair rows in the contact passes (the last takes every row that finds no
/// other free, so its rows may share marbles).
const COLOURS: usize = 32;

/// Over-relaxation of the contact passes (projected successive over-relaxation; 1 is plain
/// Gauss–Seidel, and it converges for any value below 2). Measured on the 1,000-marble
/// pour at 8 substeps over thirteen nudged starts: 15 passes at 1.5 settle it by 4.8 s, as 30
/// plain passes do (by 5.3 s), for about 20% less time; 15 plain passes leave it stirring,
/// 10 at 1.5 settle some starts only near 6 s, and 1.7 is no better. (With the impact
/// stage's later board search, 15 at 1.5 settled fourteen starts by 5.0 s.)
const RELAXATION: f32 = 1.5;

/// Most board impacts followed per marble when collisions sent it off its path.
const BOARD_IMPACTS: usize = 4;

/// Position-projection passes per substep.
const PROJECTION_PASSES: usize = 4;

/// A Gauss–Seidel pass that changes no velocity by more than this (m/s) ends the solve.
///
/// It rarely does in a pile: in bench scene (b)'s settled 1,000-marble pile the last of
/// the 15 passes still changes some pair's closing speed by about 1.2e-6 m/s (ordinary
/// contacts deep in the pile, each pass moving them by about as much as the one before),
/// and a looser tolerance only moves that level with it: at 1e-5 the change sits at
/// 1.2e-5 m/s, at 1e-4 half the substeps still run all 15 passes. The passes cannot be cut
/// by a tolerance, then (measured with the settled pile's per-pass changes printed).
const CONVERGED: f32 = 1e-6;

/// One marble as the pair stage sees it.
#[derive(Clone, Copy, Debug)]
pub struct Body {
    /// The entity.
    pub entity: Entity,
    /// Centre at the end of the substep (after the board response).
    pub x: Vec3,
    /// Centre at the substep's start.
    pub x0: Vec3,
    /// Velocity at the end of the substep.
    pub v: Vec3,
    /// Velocity at the substep's start (before this step's forces).
    pub v0: Vec3,
    /// Inverse mass, 1/kg.
    pub w: f32,
    /// Radius, m.
    pub r: f32,
    /// Restitution.
    pub e: f32,
    /// Acceleration over the substep (before contact forces); the contact stage adds the
    /// contact forces to it.
    pub a: Vec3,
    /// Free displacement over the substep under `a`, as the integrator will move it.
    pub d: Vec3,
    /// Angular velocity, rad/s (contact stage, marbles that spin).
    pub omega: Vec3,
    /// The marble spins (rolling on and it carries an angular velocity): marble–marble
    /// friction acts on it.
    pub spins: bool,
    /// Friction coefficient.
    pub mu: f32,
}

/// A contact between two marbles during the last substep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarbleContact {
    /// The first marble.
    pub a: Entity,
    /// The second marble.
    pub b: Entity,
    /// Unit normal from `a` towards `b`.
    pub normal: Vec3,
    /// Overlap at the end of the substep, m (≤ 0: a gap within the touching tolerance).
    pub depth: f32,
    /// Closing speed `(v_b − v_a)·n` when classified, m/s (negative: approaching).
    pub closing_speed: f32,
    /// Collision (restitution applied) or contact.
    pub kind: ContactKind,
    /// When in the substep it was found, s from the substep's start.
    pub time: f32,
}

/// The marble–marble contacts of the last substep, in a deterministic order (a resource;
/// empty unless `marble_collisions` is on). Sleeping marbles ([`crate::sleep`]) are not
/// stepped, so their contacts are not listed.
#[derive(Resource, Default, Debug)]
pub struct MarbleContacts {
    pub(crate) list: Vec<MarbleContact>,
}

impl MarbleContacts {
    /// The contacts.
    pub fn as_slice(&self) -> &[MarbleContact] {
        &self.list
    }

    /// Number of contacts.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }
}

/// A pair of marbles that may interact in this substep.
#[derive(Clone, Copy, Debug)]
struct Row {
    i: u32,
    j: u32,
    /// Unit normal from `i` to `j` (at the impact for impacts).
    n: Vec3,
    /// Closing speed the collision rule judges (before the step's forces, or at the
    /// impact), before any impulse of this stage.
    u: f32,
    /// When the pair meets, s from the substep's start.
    t: f32,
    /// Pair restitution.
    e: f32,
    /// `1 / (w_i + w_j)`.
    k: f32,
    /// The row collides when closing faster than this, m/s.
    limit: f32,
    /// How the pair was found.
    kind: Found,
    /// Collided in this substep.
    collided: bool,
    /// Gap between the marbles at the substep's start, m ([`Found::Near`] rows; zero for
    /// the others).
    gap: f32,
}

/// How a pair was found by the narrow phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Found {
    /// Touching at the substep's start.
    Start,
    /// Apart at the start, meeting during the substep.
    Impact,
    /// Apart at the start, within the touching tolerance at the end.
    End,
    /// Apart at the start by a gap they could close during the substep: a speculative
    /// contact of the contact stage, which lets them close the gap but not overlap.
    Near,
}

/// A contact row of the velocity solver: a pair or a marble on a board.
#[derive(Clone, Copy, Debug)]
struct Constraint {
    i: u32,
    /// The other marble, or `u32::MAX` for a board.
    j: u32,
    n: Vec3,
    /// Board: velocity of the board's surface point. Pair: unused.
    vb: Vec3,
    /// Board: the contact point at the end of the substep. Pair: unused.
    p: Vec3,
    /// Effective mass `1 / (w_i + w_j)` (`1 / w_i` for a board).
    k: f32,
    /// Accumulated impulse, N·s.
    lambda: f32,
    /// Overlap allowed before projection, m.
    slop: f32,
    /// Least closing speed the row allows at the end of the substep, m/s: zero, or for a
    /// speculative row, the speed that closes its gap over the substep.
    target: f32,
    /// Warm-start key.
    key: (u64, u64),
}

/// One projected Gauss–Seidel update of a contact row with closing speed `u` and effective
/// mass `k`: the accumulated impulse `lambda` moves to stop the approach (over-relaxed by
/// [`RELAXATION`]), never below zero; returns the change to apply, if any.
#[inline]
fn accumulate(lambda: &mut f32, u: f32, k: f32) -> Option<f32> {
    let next = (*lambda - u * k * RELAXATION).max(0.0);
    let d = next - *lambda;
    (d != 0.0).then(|| {
        *lambda = next;
        d
    })
}

/// The larger of `a` and `x`, `a` when `x` is NaN: `f32::max` for a running maximum
/// `a` that is never NaN, in one instruction instead of five.
#[inline(always)]
fn larger(a: f32, x: f32) -> f32 {
    if x > a { x } else { a }
}

/// A pair row of the contact passes (compact copy of a [`Constraint`]).
#[derive(Clone, Copy, Debug)]
struct PairGs {
    i: u32,
    j: u32,
    n: Vec3,
    k: f32,
    lambda: f32,
    target: f32,
}

impl PairGs {
    /// Applies impulse `d` along the row's normal to its two marbles' [`Vel`]s.
    #[inline]
    fn apply(&self, vel: &mut [Vel], d: f32) {
        let (i, j) = (self.i as usize, self.j as usize);
        let (a, b) = (vel[i], vel[j]);
        (vel[i], vel[j]) = self.applied(a, b, d);
    }

    /// Marbles `a`, `b` ([`Vel`]s) after impulse `d` along the normal (the same
    /// operations, lane by lane, as on `Vec3`s).
    #[inline(always)]
    fn applied(&self, a: Vel, b: Vel, d: f32) -> (Vel, Vel) {
        let n = self.n.extend(0.0);
        (a - (d * a.w) * n, b + (d * b.w) * n)
    }

    /// One projected, over-relaxed update of the row (module docs, step 4), branch-free: a
    /// row that does not change applies zero. Returns the running maximum `largest` of the
    /// velocity changes.
    #[inline(always)]
    fn pass(&mut self, vel: &mut [Vel], largest: f32) -> f32 {
        let (i, j) = (self.i as usize, self.j as usize);
        let (a, b) = (vel[i], vel[j]);
        let u = self.closing(a, b);
        let next = (self.lambda - u * self.k * RELAXATION).max(0.0);
        let d = next - self.lambda;
        self.lambda = next;
        (vel[i], vel[j]) = self.applied(a, b, d);
        larger(largest, d.abs() / self.k)
    }

    /// The closing speed of `a` and `b` along the normal less the row's target, `Vec3::dot`'s
    /// sum order, so the same bits as on `Vec3`s.
    #[inline(always)]
    fn closing(&self, a: Vel, b: Vel) -> f32 {
        let d = b - a;
        d.x * self.n.x + d.y * self.n.y + d.z * self.n.z - self.target
    }
}

/// A marble in the contact passes: its velocity (`x`, `y`, `z`) and inverse mass (`w`) in
/// one 16-byte lane set, so that a row reads and writes each of its marbles with one load
/// and one store.
type Vel = Vec4;

/// Four pair rows of one colour side by side, a row to a lane. No two of them share a
/// marble, so updating them together is updating them one after another, and each lane
/// does [`PairGs::pass`]'s operations in its order: the same bits, four rows at a time.
#[derive(Clone, Copy, Debug)]
struct RowBlock {
    i: [u32; 4],
    j: [u32; 4],
    /// The normals' `x`, `y` and `z`.
    n: [Vec4; 3],
    k: Vec4,
    lambda: Vec4,
    target: Vec4,
}

impl RowBlock {
    /// The block of four rows.
    fn new(r: &[PairGs; 4]) -> RowBlock {
        let lanes = |f: fn(&PairGs) -> f32| Vec4::new(f(&r[0]), f(&r[1]), f(&r[2]), f(&r[3]));
        RowBlock {
            i: r.each_ref().map(|r| r.i),
            j: r.each_ref().map(|r| r.j),
            n: [lanes(|r| r.n.x), lanes(|r| r.n.y), lanes(|r| r.n.z)],
            k: lanes(|r| r.k),
            lambda: lanes(|r| r.lambda),
            target: lanes(|r| r.target),
        }
    }

    /// [`PairGs::pass`] on the four rows; `wide` is the running maximum by lane.
    #[inline(always)]
    fn pass(&mut self, vel: &mut [Vel], wide: Vec4) -> Vec4 {
        let [i0, i1, i2, i3] = self.i.map(|i| i as usize);
        let [j0, j1, j2, j3] = self.j.map(|j| j as usize);
        // By lane: x_axis holds the four marbles' x, and so on (w: inverse masses).
        let a = Mat4::from_cols(vel[i0], vel[i1], vel[i2], vel[i3]).transpose();
        let b = Mat4::from_cols(vel[j0], vel[j1], vel[j2], vel[j3]).transpose();
        let [nx, ny, nz] = self.n;
        let u =
            (b.x_axis - a.x_axis) * nx + (b.y_axis - a.y_axis) * ny + (b.z_axis - a.z_axis) * nz
                - self.target;
        let next = (self.lambda - u * self.k * RELAXATION).max(Vec4::ZERO);
        let d = next - self.lambda;
        self.lambda = next;
        let (sa, sb) = (d * a.w_axis, d * b.w_axis);
        let a = Mat4::from_cols(
            a.x_axis - sa * nx,
            a.y_axis - sa * ny,
            a.z_axis - sa * nz,
            a.w_axis,
        )
        .transpose();
        let b = Mat4::from_cols(
            b.x_axis + sb * nx,
            b.y_axis + sb * ny,
            b.z_axis + sb * nz,
            b.w_axis,
        )
        .transpose();
        (vel[i0], vel[i1], vel[i2], vel[i3]) = (a.x_axis, a.y_axis, a.z_axis, a.w_axis);
        (vel[j0], vel[j1], vel[j2], vel[j3]) = (b.x_axis, b.y_axis, b.z_axis, b.w_axis);
        // `larger` lane by lane.
        (d.abs() / self.k).max(wide)
    }
}

/// The rows of one colour in the passes: `blocks` of four, then the rest one by one
/// (`tail`, slots of [`PairSolver::pair_pass`]).
#[derive(Clone, Copy, Debug, Default)]
struct ColourSpan {
    blocks: (u32, u32),
    tail: (u32, u32),
}

/// A board row of the contact passes (compact copy of a [`Constraint`]).
#[derive(Clone, Copy, Debug)]
struct BoardGs {
    i: u32,
    n: Vec3,
    vb: Vec3,
    k: f32,
    lambda: f32,
    target: f32,
}

impl BoardGs {
    #[inline]
    fn apply(&self, vel: &mut [Vel], d: f32) {
        let i = self.i as usize;
        let a = vel[i];
        vel[i] = a + (d * a.w) * self.n.extend(0.0);
    }
}

/// A board contact of one marble, copied from its [`crate::components::Contacts`].
#[derive(Clone, Copy, Debug)]
pub struct BoardTouch {
    /// Index of the marble in the bodies.
    pub body: u32,
    /// Unit normal out of the board.
    pub normal: Vec3,
    /// Contact point on the board at the end of the substep.
    pub point: Vec3,
    /// Velocity of the board's surface at the point.
    pub velocity: Vec3,
    /// Which piece.
    pub piece: PieceId,
    /// Restitution of the marble and board pair.
    pub restitution: f32,
    /// Gap at the substep's start, m: 0 for a recorded contact; positive for a
    /// speculative row (a piece the marble does not touch but could reach during the
    /// substep), which lets the marble close the gap and no more, and which the collision
    /// cascade leaves alone.
    pub gap: f32,
}

/// A fast hasher for warm-start keys (entity bits are already well spread).
#[derive(Default, Clone, Copy)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Contact impulses by warm-start key: a pair's two marbles' entity bits (smaller first),
/// or a marble's entity bits and a board piece's id with its bits flipped.
pub(crate) type KeyMap = HashMap<(u64, u64), f32, BuildHasherDefault<KeyHasher>>;

/// The hashed uniform grid of the broad phase (buffers reused between substeps).
#[derive(Default, Debug)]
pub(crate) struct Grid {
    cell: f32,
    mask: u32,
    /// Dense mode: the lowest cell (less one in every axis) and the cell counts, when the
    /// marbles' cells span few enough cells for one table entry per cell: neighbouring
    /// cells are then neighbours in memory, and no two cells share a bucket. Otherwise
    /// (`None`) cells are hashed.
    dense: Option<(IVec3, IVec3)>,
    /// Bucket of each body.
    bucket: Vec<u32>,
    /// Start of each bucket in `order` (`mask + 2` entries).
    start: Vec<u32>,
    /// Ordinary bodies sorted by bucket.
    order: Vec<u32>,
    /// Cell of each entry of `order`.
    cells: Vec<IVec3>,
    /// Bound sphere (centre, radius) of each entry of `order`.
    bounds: Vec<Vec4>,
    /// Bodies too large or fast for the cell size.
    large: Vec<u32>,
}

/// The 13 neighbours of a cell that come after it: with the cell itself they visit every
/// pair of neighbouring cells once.
const FORWARD: [IVec3; 13] = [
    IVec3::new(1, -1, -1),
    IVec3::new(1, -1, 0),
    IVec3::new(1, -1, 1),
    IVec3::new(1, 0, -1),
    IVec3::new(1, 0, 0),
    IVec3::new(1, 0, 1),
    IVec3::new(1, 1, -1),
    IVec3::new(1, 1, 0),
    IVec3::new(1, 1, 1),
    IVec3::new(0, 1, -1),
    IVec3::new(0, 1, 0),
    IVec3::new(0, 1, 1),
    IVec3::new(0, 0, 1),
];

/// The cell of point `p` for cells of size `1 / inv`: `floor(p · inv)` per axis, without
/// a call to libm's `floorf` (baseline x86-64 has no rounding instruction).
#[inline]
fn cell_of(p: Vec3, inv: f32) -> IVec3 {
    let q = p * inv;
    let t = q.as_ivec3();
    t - IVec3::from(t.as_vec3().cmpgt(q))
}

#[inline]
fn hash_cell(c: IVec3) -> u32 {
    (c.x as u32).wrapping_mul(0x8da6_b343)
        ^ (c.y as u32).wrapping_mul(0xd816_3841)
        ^ (c.z as u32).wrapping_mul(0xcb1a_b31f)
}

impl Grid {
    /// Sizes the buffers for `n` bodies.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.bucket.reserve(n);
        self.start.reserve(8 * n + 66);
        self.order.reserve(n);
        self.cells.reserve(n);
        self.bounds.reserve(n);
        self.large.reserve(n);
    }

    /// Sorts the bodies into cells from their bound spheres `b` (centre, radius).
    pub(crate) fn build(&mut self, b: &[Vec4]) {
        let n = b.len();
        self.large.clear();
        self.order.clear();
        self.cells.clear();
        self.bounds.clear();
        self.bucket.clear();
        if n == 0 {
            return;
        }
        let mean = b.iter().map(|s| s.w as f64).sum::<f64>() / n as f64;
        let limit = 2.0 * mean as f32;
        let largest = b
            .iter()
            .map(|s| s.w)
            .filter(|&w| w <= limit)
            .fold(0.0f32, f32::max);
        self.cell = (2.0 * largest).max(f32::MIN_POSITIVE);
        let inv = 1.0 / self.cell;
        // The span of the ordinary marbles' cells, padded by one cell on every side so
        // that every neighbour of an occupied cell has a table entry.
        let (mut lo, mut hi) = (IVec3::MAX, IVec3::MIN);
        for s in b.iter().filter(|s| s.w <= limit) {
            let c = cell_of(s.truncate(), inv);
            lo = lo.min(c);
            hi = hi.max(c);
        }
        let dims = (hi - lo).as_i64vec3() + glam::I64Vec3::splat(3);
        let cells = dims.x.saturating_mul(dims.y).saturating_mul(dims.z);
        let table = if cells <= 8 * n as i64 + 64 {
            self.dense = Some((lo - IVec3::ONE, dims.as_ivec3()));
            cells as usize
        } else {
            self.dense = None;
            (2 * n).next_power_of_two().max(16)
        };
        self.mask = (table - 1) as u32;
        self.start.clear();
        self.start.resize(table + 1, 0);
        for (k, s) in b.iter().enumerate() {
            if s.w > limit {
                self.large.push(k as u32);
                self.bucket.push(u32::MAX);
                continue;
            }
            let h = self.bucket_of(cell_of(s.truncate(), inv));
            self.bucket.push(h as u32);
            self.start[h + 1] += 1;
        }
        for h in 0..table {
            self.start[h + 1] += self.start[h];
        }
        let ordinary = n - self.large.len();
        self.order.resize(ordinary, 0);
        self.cells.resize(ordinary, IVec3::ZERO);
        self.bounds.resize(ordinary, Vec4::ZERO);
        // Scatter with a running cursor per bucket (the bucket starts, shifted back after).
        for (k, s) in b.iter().enumerate() {
            let h = self.bucket[k];
            if h == u32::MAX {
                continue;
            }
            let slot = self.start[h as usize] as usize;
            self.start[h as usize] += 1;
            self.order[slot] = k as u32;
            self.cells[slot] = cell_of(s.truncate(), inv);
            self.bounds[slot] = *s;
        }
        for h in (1..=table).rev() {
            self.start[h] = self.start[h - 1];
        }
        self.start[0] = 0;
    }

    /// The bucket of cell `c`: its index in the dense table, or its hash. In dense mode
    /// a cell outside the padded span (only large marbles ask for those) has no marbles:
    /// it maps to the padding cell `0`, which is always empty.
    #[inline]
    fn bucket_of(&self, c: IVec3) -> usize {
        match self.dense {
            Some((lo, dims)) => {
                let d = c - lo;
                if d.cmplt(IVec3::ZERO).any() || d.cmpge(dims).any() {
                    0
                } else {
                    ((d.x as usize * dims.y as usize) + d.y as usize) * dims.z as usize
                        + d.z as usize
                }
            }
            None => (hash_cell(c) & self.mask) as usize,
        }
    }

    /// Entries of `order` in the bucket of cell `c`.
    #[inline]
    fn bucket_range(&self, c: IVec3) -> std::ops::Range<usize> {
        let h = self.bucket_of(c);
        self.start[h] as usize..self.start[h + 1] as usize
    }

    /// Calls `f(j)` for every body whose bound sphere overlaps sphere `s` (centre, radius).
    pub(crate) fn query(&self, b: &[Vec4], s: Vec4, mut f: impl FnMut(u32)) {
        let near = |q: Vec4| {
            let r = s.w + q.w;
            (s.truncate() - q.truncate()).length_squared() <= r * r
        };
        let half = 0.5 * self.cell;
        let inv = 1.0 / self.cell;
        let lo = cell_of(s.truncate() - Vec3::splat(s.w + half), inv);
        let hi = cell_of(s.truncate() + Vec3::splat(s.w + half), inv);
        let span = (hi - lo + IVec3::ONE).as_vec3();
        if (span.x * span.y * span.z) as f64 > self.order.len() as f64 {
            for q in 0..self.order.len() {
                if near(self.bounds[q]) {
                    f(self.order[q]);
                }
            }
        } else {
            for x in lo.x..=hi.x {
                for y in lo.y..=hi.y {
                    for z in lo.z..=hi.z {
                        let c = IVec3::new(x, y, z);
                        for q in self.bucket_range(c) {
                            if self.cells[q] == c && near(self.bounds[q]) {
                                f(self.order[q]);
                            }
                        }
                    }
                }
            }
        }
        for &l in &self.large {
            if near(b[l as usize]) {
                f(l);
            }
        }
    }

    /// Calls `f(i, j)` once for every pair of bodies whose bound spheres overlap.
    pub(crate) fn pairs(&self, b: &[Vec4], mut f: impl FnMut(u32, u32)) {
        let near = |p: Vec4, q: Vec4| {
            let r = p.w + q.w;
            (p.truncate() - q.truncate()).length_squared() <= r * r
        };
        for p in 0..self.order.len() {
            let c = self.cells[p];
            let bp = self.bounds[p];
            let range = self.bucket_range(c);
            for q in p + 1..range.end {
                if self.cells[q] == c && near(bp, self.bounds[q]) {
                    f(self.order[p], self.order[q]);
                }
            }
            for d in FORWARD {
                let cd = c + d;
                for q in self.bucket_range(cd) {
                    if self.cells[q] == cd && near(bp, self.bounds[q]) {
                        f(self.order[p], self.order[q]);
                    }
                }
            }
        }
        // Large bodies: against every ordinary body through the cells their bound covers
        // (or all of them, when that is fewer), then against each other.
        let half = 0.5 * self.cell;
        let inv = 1.0 / self.cell;
        for (a, &l) in self.large.iter().enumerate() {
            let s = b[l as usize];
            let lo = ((s.truncate() - Vec3::splat(s.w + half)) * inv).floor();
            let hi = ((s.truncate() + Vec3::splat(s.w + half)) * inv).floor();
            let span = hi - lo + Vec3::ONE;
            if (span.x * span.y * span.z) as f64 > self.order.len() as f64 {
                for q in 0..self.order.len() {
                    if near(s, self.bounds[q]) {
                        f(l, self.order[q]);
                    }
                }
            } else {
                let (lo, hi) = (lo.as_ivec3(), hi.as_ivec3());
                for x in lo.x..=hi.x {
                    for y in lo.y..=hi.y {
                        for z in lo.z..=hi.z {
                            let c = IVec3::new(x, y, z);
                            for q in self.bucket_range(c) {
                                if self.cells[q] == c && near(s, self.bounds[q]) {
                                    f(l, self.order[q]);
                                }
                            }
                        }
                    }
                }
            }
            for &m in &self.large[a + 1..] {
                if near(s, b[m as usize]) {
                    f(l, m);
                }
            }
        }
    }
}

/// The settings the pair stage needs, copied out of [`crate::config::StepConfig`].
#[derive(Clone, Copy, Debug)]
pub struct PairParams {
    /// Substep length, s.
    pub h: f32,
    /// Continuous collision.
    pub ccd: bool,
    /// Collision-versus-contact threshold, m/s.
    pub threshold: f32,
    /// Touching tolerance relative to the radius.
    pub tolerance: f32,
    /// Gauss–Seidel passes.
    pub iterations: u32,
}

/// The pair stage's state: reusable buffers and the warm-start impulses (a resource).
#[derive(Resource, Default, Debug)]
pub struct PairSolver {
    /// The marbles of the current substep (filled by the system).
    pub bodies: Vec<Body>,
    /// Their board contacts (filled by the system), grouped by body in body order.
    pub board_touches: Vec<BoardTouch>,
    /// Start of each body's board contacts in `board_touches` (one more entry than
    /// bodies; filled by the system).
    pub touch_start: Vec<u32>,
    /// The bound spheres the candidate pairs were found on (each marble's sphere when
    /// they were found, grown by the skin), and the grid over them.
    bound: Vec<Vec4>,
    grid: Grid,
    /// The candidates stand for these bodies (cleared when the bodies change).
    skin_valid: bool,
    /// This substep's spheres (scratch of [`PairSolver::cover`]).
    spheres: Vec<Vec4>,
    /// With the spheres: each body's radius and entity.
    radii: Vec<f32>,
    gathered: Vec<Entity>,
    /// The contact stage's free displacements, kept from the sphere gather for the bodies.
    pub(crate) paths: Vec<Vec3>,
    /// Per body: outside its bound at the last cover, and the list of those.
    stray: Vec<bool>,
    strays: Vec<u32>,
    /// Candidate pairs of strays found at the last cover.
    extra: Vec<(u32, u32)>,
    /// The marbles' common drift since the candidates were found, at the last cover.
    drift: Vec3,
    /// A second grid (strays against each other; every marble after collisions).
    scratch_bound: Vec<Vec4>,
    scratch_grid: Grid,
    rows: Vec<Row>,
    /// Collision stage: velocity change and time of the last impact per body.
    dv: Vec<Vec3>,
    event: Vec<f32>,
    /// The rows' pairs by their first body (`i < j`): the `j`s of body `i` are
    /// `known[known_start[i]..known_start[i + 1]]` (a handful in a pile), so that asking
    /// whether a pair is known is a short scan of one body's slice, not a search of all.
    known_start: Vec<u32>,
    known: Vec<u32>,
    /// Bodies a collision moved off their free paths.
    moved: Vec<u32>,
    /// Those and the strays the collisions did not move, paired through a grid of their
    /// own when there are many.
    late_bodies: Vec<u32>,
    candidates: Vec<(u32, u32)>,
    /// The bodies' entities when the candidates were found.
    entities: Vec<Entity>,
    late: Vec<Row>,
    adjacency_start: Vec<u32>,
    adjacency: Vec<u32>,
    queue: Vec<u32>,
    first: Vec<u32>,
    /// Contact stage.
    constraints: Vec<Constraint>,
    pub(crate) in_contact: Vec<bool>,
    warm: KeyMap,
    warm_next: KeyMap,
    /// Velocities and inverse masses in the passes.
    vel: Vec<Vel>,
    /// Projection each marble may still move this substep.
    push_left: Vec<f32>,
    pair_gs: Vec<PairGs>,
    /// The pair rows in the order the passes visit them (by colour: no two rows of a
    /// colour share a marble), and each row's slot there.
    pair_pass: Vec<PairGs>,
    pair_slot: Vec<u32>,
    /// The colours' rows by four ([`RowBlock`]), the first slot of each block, and where
    /// each colour's blocks and single rows are.
    blocks: Vec<RowBlock>,
    block_first: Vec<u32>,
    spans: Vec<ColourSpan>,
    /// Colours used by each marble's rows so far (a bit per colour).
    colours: Vec<u32>,
    board_gs: Vec<BoardGs>,
    /// Bodies whose state the stage changed.
    pub changed: Vec<bool>,
    /// Marble count the buffers were sized for.
    reserved_for: usize,
    /// Test only: check every late-pair search against re-pairing every marble, and count
    /// the checks by search.
    #[cfg(test)]
    cross_check_late: bool,
    #[cfg(test)]
    cross_checked: [usize; 3],
}

impl PairSolver {
    /// Each stage starts with the broad phase on one sphere per marble, gathered before
    /// the bodies are: [`PairSolver::begin`], then [`PairSolver::push_sphere`] for every
    /// marble in the order its body will have, then [`PairSolver::cover_gathered`]. A
    /// substep in which no two marbles can meet (marbles spread over a board) ends there,
    /// without building the bodies. `n` is the number of marbles; `out` (the stage's
    /// records) is only sized.
    pub fn begin(&mut self, n: usize, out: &mut MarbleContacts) {
        if n > self.reserved_for {
            self.reserve(n, out);
        }
        self.spheres.clear();
        self.radii.clear();
        self.gathered.clear();
        self.paths.clear();
    }

    /// A marble's broad-phase sphere (centre, radius), its radius and entity.
    #[inline]
    pub fn push_sphere(&mut self, entity: Entity, sphere: Vec4, r: f32) {
        self.spheres.push(sphere);
        self.radii.push(r);
        self.gathered.push(entity);
    }

    /// The broad phase on the gathered spheres (module docs, step 1); whether any two
    /// marbles can meet.
    pub fn cover_gathered(&mut self) -> bool {
        self.cover_spheres();
        !(self.candidates.is_empty() && self.extra.is_empty())
    }

    /// Drops the contact impulses kept for warm starting (no marble touches another).
    pub fn forget_contacts(&mut self) {
        self.warm.clear();
    }

    /// Copies into `store` the contact impulses kept for warm starting of the marbles whose
    /// entity bits are in `sorted` (ascending), which fall asleep ([`crate::sleep`]): a
    /// pair's key starts with its smaller entity, and a marble falls asleep with every
    /// marble it touches.
    pub(crate) fn stow_impulses(&self, sorted: &[u64], store: &mut KeyMap) {
        for (key, &lambda) in &self.warm {
            if sorted.binary_search(&key.0).is_ok() {
                store.insert(*key, lambda);
            }
        }
    }

    /// Moves back from `store` the impulses of the marbles in `sorted` (ascending), which
    /// wake, so that their first substep is warm started as if they had not slept.
    pub(crate) fn restore_impulses(&mut self, sorted: &[u64], store: &mut KeyMap) {
        let warm = &mut self.warm;
        store.retain(|key, lambda| {
            let woken = sorted.binary_search(&key.0).is_ok();
            if woken {
                warm.insert(*key, *lambda);
            }
            !woken
        });
    }

    /// The contact stage's sphere: around the marble's free path over the substep (its
    /// displacement `d` from `x`, along the boards it rests on), with a margin for the
    /// contact forces' change of path and the touching tolerance.
    #[inline]
    pub fn contact_sphere(p: &PairParams, x: Vec3, d: Vec3, r: f32) -> Vec4 {
        let tol = crate::narrow::touch_tolerance(p.tolerance, r, x);
        (x + 0.5 * d).extend(r * (1.0 + BOUND_MARGIN) + 0.5 * d.length() + tol)
    }

    /// The impact stage's sphere: around the straight path from `x0` to `x` and the
    /// touching tolerance.
    #[inline]
    pub fn impact_sphere(p: &PairParams, x0: Vec3, x: Vec3, r: f32) -> Vec4 {
        let tol = crate::narrow::touch_tolerance(p.tolerance, r, x);
        (0.5 * (x0 + x)).extend(r + 0.5 * (x - x0).length() + tol)
    }

    /// The contact stage, before integration (module docs, steps 1–2), after the broad
    /// phase on [`PairSolver::contact_sphere`]s, on [`PairSolver::bodies`] at the
    /// substep's start (`x`, `v`, `a`, `d` set; `x0 = x`, `v0 = v`): finds the touching
    /// pairs, keeps the candidate pairs for [`PairSolver::find_impacts`], and returns
    /// whether any pair touches; then [`PairSolver::solve_touching`] needs the board
    /// contacts.
    pub fn find_touching(&mut self, p: &PairParams) -> bool {
        let n = self.bodies.len();
        debug_assert_eq!(n, self.spheres.len(), "the broad phase ran on these bodies");
        self.changed.clear();
        self.changed.resize(n, false);
        // 2. The touching pairs, and the pairs that could close their gap this substep.
        self.rows.clear();
        for (i, j) in candidate_pairs(&self.candidates, &self.extra, &self.stray, &self.strays) {
            if let Some(row) = narrow(&self.bodies, i, j, p) {
                if row.kind == Found::Start {
                    self.rows.push(row);
                }
            } else if let Some(row) = near_row(&self.bodies, i, j, p) {
                self.rows.push(row);
            }
        }
        if self.rows.is_empty() {
            self.warm.clear();
            return false;
        }
        // The marbles in the rows: those whose board contacts, and speculative board rows,
        // the passes need.
        self.in_contact.clear();
        self.in_contact.resize(n, false);
        for row in &self.rows {
            self.in_contact[row.i as usize] = true;
            self.in_contact[row.j as usize] = true;
        }
        true
    }

    /// The rest of the contact stage (module docs, steps 3–5), after
    /// [`PairSolver::find_touching`] found touching pairs, with
    /// [`PairSolver::board_touches`] (the previous substep's board contacts): collisions
    /// of touching pairs become velocity changes at the start, contacts become forces added
    /// to `a`, overlaps are projected out of `x`. Records the touching pairs in `out`.
    pub fn solve_touching(&mut self, p: &PairParams, out: &mut MarbleContacts) {
        // 3. Collisions of touching pairs: velocity changes at the start.
        self.collide(p, false);
        // Friction between touching marbles that spin.
        self.friction();
        // 4. Contacts: forces over the substep.
        self.solve_contacts(p);
        // 5. Overlap.
        self.project();
        for row in &self.rows {
            if row.kind == Found::Start {
                out.list.push(self.contact(row));
            }
        }
    }

    /// The impact stage, after the marble–board response (module docs), on
    /// [`PairSolver::bodies`] with `x0`, `v0` at the substep's start and `x`, `v` at its
    /// end: finds the pairs that met during the substep deeply enough to collide now, and
    /// returns whether there are any; then [`PairSolver::resolve_impacts`] needs the board
    /// contacts.
    pub fn find_impacts(&mut self, p: &PairParams) -> bool {
        let n = self.bodies.len();
        debug_assert_eq!(n, self.spheres.len(), "the broad phase ran on these bodies");
        self.changed.clear();
        self.changed.resize(n, false);
        self.rows.clear();
        // The rows are needed only when some pair collides deeply: look for one first,
        // with the narrow phase only for the pairs that moved far enough apart from each
        // other to leave a deep overlap ([`may_impact_deeply`]); most substeps of a pile
        // or of marbles rolling together have none and stop here.
        let bodies = &self.bodies;
        let slack = rounding_slack(bodies);
        let deep = candidate_pairs(&self.candidates, &self.extra, &self.stray, &self.strays)
            .filter(|&(i, j)| may_impact_deeply(bodies, i, j, slack))
            .any(|(i, j)| narrow(bodies, i, j, p).is_some_and(|row| deep_impact(bodies, &row)));
        if !deep {
            return false;
        }
        let mut any = false;
        for (i, j) in candidate_pairs(&self.candidates, &self.extra, &self.stray, &self.strays) {
            if let Some(mut row) = narrow(&self.bodies, i, j, p) {
                if row.kind == Found::Impact {
                    if shallow(&self.bodies, &row) {
                        // An impact that leaves the pair overlapping by less than a small
                        // share of the radius is left to the next substep's contact stage,
                        // which judges it on the same closing speed; resolving it here
                        // would move a settled pile for nothing.
                        row.limit = f32::INFINITY;
                    } else {
                        any |= row.u < 0.0;
                    }
                }
                if row.kind != Found::End {
                    self.rows.push(row);
                }
            }
        }
        debug_assert!(any, "the search above found a deep impact");
        any
    }

    /// The rest of the impact stage, after [`PairSolver::find_impacts`] found impacts,
    /// with [`PairSolver::board_touches`] (this substep's board contacts): the pairs
    /// collide at their time of impact, exactly, and pass the impact on. Records the
    /// impacts in `out`.
    pub fn resolve_impacts(
        &mut self,
        p: &PairParams,
        boards: &[BoardSnapshot],
        out: &mut MarbleContacts,
    ) {
        if self.collide(p, true) {
            // Collisions moved marbles off their free paths; what they run into there,
            // boards and marbles, is found and resolved in a few rounds.
            let mut settled = false;
            for _ in 0..LATE_ROUNDS {
                self.onto_boards(p, boards);
                if !self.late_overlaps(p) {
                    settled = true;
                    break;
                }
            }
            if !settled {
                // The last round's collisions may have sent marbles into boards.
                self.onto_boards(p, boards);
            }
        }
        for row in &self.rows {
            if row.collided && row.kind != Found::Start {
                out.list.push(self.contact(row));
            }
        }
    }

    /// The record of a row: its pair, the end overlap, the closing speed judged and when.
    fn contact(&self, row: &Row) -> MarbleContact {
        let (a, b) = (&self.bodies[row.i as usize], &self.bodies[row.j as usize]);
        MarbleContact {
            a: a.entity,
            b: b.entity,
            normal: row.n,
            depth: a.r + b.r - (b.x - a.x).length(),
            closing_speed: row.u,
            kind: if row.collided {
                ContactKind::Collision
            } else {
                ContactKind::Contact
            },
            time: row.t,
        }
    }

    /// Makes the candidate pairs ([`candidate_pairs`]) hold every pair of bodies whose
    /// spheres `sphere(body)` (centre, radius) overlap (module docs, step 1).
    ///
    /// The candidates found on the bound spheres (each body's sphere when they were found,
    /// grown by [`SKIN`]) stand while every body's sphere stays inside its bound, measured
    /// after taking off the bodies' common drift since then (their mean displacement: two
    /// bodies' distance changes only by their displacements relative to any common one, so
    /// marbles sliding down a board together keep their pairs). Bodies that left their
    /// bound (strays) are paired afresh: with the others through the grid of bounds, with
    /// each other through a grid of their own. When the bodies changed, or more than one
    /// in [`STRAY_SHARE`] strayed, the candidates are found afresh.
    #[cfg(test)]
    fn cover(&mut self, sphere: impl Fn(&Body) -> Vec4) {
        self.spheres.clear();
        self.radii.clear();
        self.gathered.clear();
        for b in &self.bodies {
            self.spheres.push(sphere(b));
            self.radii.push(b.r);
            self.gathered.push(b.entity);
        }
        self.cover_spheres();
    }

    /// [`PairSolver::cover`] on the gathered spheres.
    fn cover_spheres(&mut self) {
        let n = self.spheres.len();
        self.extra.clear();
        self.strays.clear();
        self.stray.clear();
        self.stray.resize(n, false);
        let same =
            self.skin_valid && n > 0 && self.bound.len() == n && self.entities == self.gathered;
        if same {
            let sum = self
                .spheres
                .iter()
                .zip(&self.bound)
                .fold(Vec3::ZERO, |acc, (s, b)| {
                    acc + (s.truncate() - b.truncate())
                });
            let drift = sum / n as f32;
            for (k, (s, b)) in self.spheres.iter().zip(&self.bound).enumerate() {
                if (s.truncate() - drift - b.truncate()).length() + s.w > b.w {
                    self.stray[k] = true;
                    self.strays.push(k as u32);
                }
            }
            if self.strays.len() * STRAY_SHARE <= n {
                self.drift = drift;
                self.pair_strays();
                return;
            }
            self.strays.clear();
            self.stray.fill(false);
        }
        self.bound.clear();
        self.bound.extend(
            self.spheres
                .iter()
                .zip(&self.radii)
                .map(|(s, r)| s.truncate().extend(s.w + SKIN * r)),
        );
        self.grid.build(&self.bound);
        self.candidates.clear();
        let (candidates, grid, bound) = (&mut self.candidates, &self.grid, &self.bound);
        grid.pairs(bound, |i, j| candidates.push((i.min(j), i.max(j))));
        self.entities.clear();
        self.entities.extend_from_slice(&self.gathered);
        self.drift = Vec3::ZERO;
        self.skin_valid = true;
    }

    /// The candidate pairs of the strays of a [`PairSolver::cover`]: each stray against
    /// the bounds (its sphere moved back by the common drift), and strays against each
    /// other on their spheres.
    fn pair_strays(&mut self) {
        if self.strays.is_empty() {
            return;
        }
        let (grid, bound, stray, extra) = (&self.grid, &self.bound, &self.stray, &mut self.extra);
        for &i in &self.strays {
            let s = self.spheres[i as usize];
            grid.query(bound, (s.truncate() - self.drift).extend(s.w), |j| {
                if !stray[j as usize] {
                    extra.push((i.min(j), i.max(j)));
                }
            });
        }
        self.scratch_bound.clear();
        self.scratch_bound
            .extend(self.strays.iter().map(|&i| self.spheres[i as usize]));
        self.scratch_grid.build(&self.scratch_bound);
        let strays = &self.strays;
        self.scratch_grid.pairs(&self.scratch_bound, |a, b| {
            let (i, j) = (strays[a as usize], strays[b as usize]);
            extra.push((i.min(j), i.max(j)));
        });
    }

    /// Sizes every buffer for `n` marbles in a dense pile (a marble touches at most 12
    /// others; rows count each pair once), so that stepping allocates nothing once the
    /// number of marbles stops growing.
    fn reserve(&mut self, n: usize, out: &mut MarbleContacts) {
        // A settled pile has about 3 touching pairs and 6 candidate pairs per marble (a
        // marble touches at most 12 others, each pair counted once); marbles touch a
        // board or two at most, mostly none. Buffers that outgrow this grow once and stay.
        let pairs = 4 * n + 64;
        let touches = 2 * n;
        self.rows.reserve(pairs);
        self.known.reserve(pairs);
        self.known_start.reserve(n + 2);
        self.bodies.reserve(n);
        self.changed.reserve(n);
        self.moved.reserve(n);
        self.late_bodies.reserve(n);
        self.candidates.reserve(2 * pairs);
        self.entities.reserve(n);
        self.late.reserve(n);
        self.first.reserve(n);
        self.adjacency.reserve(2 * pairs);
        self.queue.reserve(pairs);
        self.constraints.reserve(pairs + touches);
        self.pair_gs.reserve(pairs);
        self.pair_pass.reserve(pairs);
        self.pair_slot.reserve(pairs);
        self.blocks.reserve(pairs / 4);
        self.block_first.reserve(pairs / 4);
        self.spans.reserve(COLOURS);
        self.colours.reserve(n);
        self.board_gs.reserve(touches);
        self.vel.reserve(n);
        self.push_left.reserve(n);
        self.warm.reserve(pairs + touches);
        self.warm_next.reserve(pairs + touches);
        out.list.reserve(pairs);
        self.board_touches.reserve(touches);
        self.touch_start.reserve(n + 1);
        self.adjacency_start.reserve(n + 1);
        self.dv.reserve(n);
        self.event.reserve(n);
        self.in_contact.reserve(n);
        self.bound.reserve(n);
        self.spheres.reserve(n);
        self.stray.reserve(n);
        self.radii.reserve(n);
        self.gathered.reserve(n);
        self.paths.reserve(n);
        self.strays.reserve(n);
        self.extra.reserve(pairs);
        self.scratch_bound.reserve(n);
        self.grid.reserve(n);
        self.scratch_grid.reserve(n);
        self.reserved_for = n;
    }

    /// Step 3 of the module docs: the cascade of exact two-body impacts. A marble the
    /// cascade drives into a board it touches bounces off that board in turn (the board's
    /// restitution, the board not moving); boards it did not touch are the impact stage's
    /// [`PairSolver::onto_boards`].
    /// Returns whether any marble collided.
    fn collide(&mut self, p: &PairParams, shift: bool) -> bool {
        let n = self.bodies.len();
        self.first.clear();
        for (k, row) in self.rows.iter().enumerate() {
            if row.u < -row.limit {
                self.first.push(k as u32);
            }
        }
        if self.first.is_empty() {
            return false;
        }
        let rows = &mut self.rows;
        self.first.sort_unstable_by(|&a, &b| {
            rows[a as usize]
                .t
                .total_cmp(&rows[b as usize].t)
                .then(a.cmp(&b))
        });
        // Which rows each body is in (compressed adjacency).
        self.adjacency_start.clear();
        self.adjacency_start.resize(n + 1, 0);
        for row in rows.iter() {
            self.adjacency_start[row.i as usize + 1] += 1;
            self.adjacency_start[row.j as usize + 1] += 1;
        }
        for k in 0..n {
            self.adjacency_start[k + 1] += self.adjacency_start[k];
        }
        self.adjacency.clear();
        self.adjacency.resize(2 * rows.len(), 0);
        self.queue.clear();
        self.queue.extend_from_slice(&self.adjacency_start[..n]);
        for (k, row) in rows.iter().enumerate() {
            for b in [row.i, row.j] {
                let slot = &mut self.queue[b as usize];
                self.adjacency[*slot as usize] = k as u32;
                *slot += 1;
            }
        }
        self.queue.clear();
        self.dv.clear();
        self.dv.resize(n, Vec3::ZERO);
        self.event.clear();
        self.event.resize(n, 0.0);
        // A cap on the cascade: with e = 1 a jammed cluster could pass impulses round for
        // ever; what is left then goes to the contact solver (inelastic).
        let mut budget = 8 * (rows.len() + self.board_touches.len()) + 64;
        let mut c = Cascade {
            p,
            shift,
            rows,
            bodies: &mut self.bodies,
            touches: &self.board_touches,
            touch_start: &self.touch_start,
            dv: &mut self.dv,
            event: &mut self.event,
            changed: &mut self.changed,
            queue: &mut self.queue,
        };
        for f in 0..self.first.len() {
            // Every impact found is resolved; only what they pass on is capped.
            c.pair(self.first[f] as usize);
            budget = budget.saturating_sub(1);
            // Whatever this impact set moving collides next, at once.
            let mut head = 0;
            while head < c.queue.len() && budget > 0 {
                let b = c.queue[head] as usize;
                head += 1;
                budget =
                    budget.saturating_sub(1 + (c.touch_start[b + 1] - c.touch_start[b]) as usize);
                c.boards(b);
                for a in self.adjacency_start[b]..self.adjacency_start[b + 1] {
                    if budget == 0 {
                        break;
                    }
                    budget -= 1;
                    c.pair(self.adjacency[a as usize] as usize);
                }
            }
            c.queue.clear();
        }
        let (bodies, dv) = (&mut self.bodies, &self.dv);
        for (b, d) in bodies.iter_mut().zip(dv.iter()) {
            b.v += *d;
        }
        true
    }

    /// The search of [`PairSolver::late_overlaps`] for pairs that overlap at the end and
    /// are not among the rows, into `late` (rows not yet collided), by `search`.
    fn find_late(&mut self, p: &PairParams, search: LateSearch) {
        self.late.clear();
        let n = self.bodies.len();
        let few = search == LateSearch::Direct;
        let all = search == LateSearch::All;
        let end_sphere = |b: &Body| {
            b.x.extend(b.r + crate::narrow::touch_tolerance(p.tolerance, b.r, b.x))
        };
        self.late_bodies.clear();
        if all {
            self.late_bodies.extend(0..n as u32);
        } else if !few {
            self.late_bodies.extend_from_slice(&self.moved);
            self.late_bodies.extend(
                self.strays
                    .iter()
                    .copied()
                    .filter(|&j| !self.changed[j as usize]),
            );
        }
        if !few {
            self.scratch_bound.clear();
            self.scratch_bound.extend(
                self.late_bodies
                    .iter()
                    .map(|&i| end_sphere(&self.bodies[i as usize])),
            );
            self.scratch_grid.build(&self.scratch_bound);
        }
        {
            let (bodies, known_start, known, late, event, changed, stray, late_bodies) = (
                &self.bodies,
                &self.known_start,
                &self.known,
                &mut self.late,
                &self.event,
                &self.changed,
                &self.stray,
                &self.late_bodies,
            );
            let mut check = |i: u32, j: u32| {
                let (i, j) = (i.min(j), i.max(j));
                if i == j {
                    return;
                }
                // Most candidates do not overlap, and in a pile most that do are rows
                // already: the distance test, then the row lookup, then the tracing back.
                if late_touch(bodies, i, j, p)
                    && !known
                        [known_start[i as usize] as usize..known_start[i as usize + 1] as usize]
                        .contains(&j)
                    && let Some(row) = late_row(bodies, event, i, j, p)
                {
                    late.push(row);
                }
            };
            if !all {
                for (m, &i) in self.moved.iter().enumerate() {
                    let b = &bodies[i as usize];
                    let tol = crate::narrow::touch_tolerance(p.tolerance, b.r, b.x);
                    let s = (b.x - self.drift).extend(b.r + tol);
                    self.grid.query(&self.bound, s, |j| {
                        // Pairs of moved marbles, and strays (outside their bounds), are
                        // checked below, once.
                        if !changed[j as usize] && !stray[j as usize] {
                            check(i, j);
                        }
                    });
                    if few {
                        for &j in &self.moved[m + 1..] {
                            check(i, j);
                        }
                        for &j in &self.strays {
                            if !changed[j as usize] {
                                check(i, j);
                            }
                        }
                    }
                }
            }
            if all {
                self.scratch_grid.pairs(&self.scratch_bound, &mut check);
            } else if !few {
                // Moved marbles with each other and with the strays they did not move.
                self.scratch_grid.pairs(&self.scratch_bound, |a, b| {
                    let (i, j) = (late_bodies[a as usize], late_bodies[b as usize]);
                    if changed[i as usize] || changed[j as usize] {
                        check(i, j);
                    }
                });
            }
        }
    }

    /// Test only: the late pairs `search` found involving a moved marble are exactly
    /// those re-pairing every marble finds (which also sees pairs of unmoved marbles).
    #[cfg(test)]
    fn cross_check(&mut self, p: &PairParams, search: LateSearch) {
        let pairs = |late: &[Row], changed: &[bool]| {
            let mut v: Vec<(u32, u32)> = late
                .iter()
                .filter(|r| changed[r.i as usize] || changed[r.j as usize])
                .map(|r| (r.i, r.j))
                .collect();
            v.sort_unstable();
            v
        };
        let found = pairs(&self.late, &self.changed);
        self.find_late(p, LateSearch::All);
        let every = pairs(&self.late, &self.changed);
        assert_eq!(found, every, "{search:?} missed or added late pairs");
        self.cross_checked[search as usize] += 1;
        self.find_late(p, search);
    }

    /// After collisions moved marbles off their free paths, pairs that overlap at the end
    /// of the substep are found on the end positions: pairs that were not among the rows
    /// (the broad phase saw the free paths), and rows whose marbles were hit again after
    /// the row's time (they can meet again). Each is traced back along the marbles' new
    /// straight paths to where they met ([`late_row`]); a pair approaching faster than the
    /// threshold collides there, and every one is then a contact.
    /// Returns whether any marble collided.
    fn late_overlaps(&mut self, p: &PairParams) -> bool {
        // The rows' pairs by first body, a counting sort.
        let n = self.bodies.len();
        self.known_start.clear();
        self.known_start.resize(n + 2, 0);
        for row in &self.rows {
            self.known_start[row.i.min(row.j) as usize + 2] += 1;
        }
        for k in 2..n + 2 {
            self.known_start[k] += self.known_start[k - 1];
        }
        self.known.clear();
        self.known.resize(self.rows.len(), 0);
        for row in &self.rows {
            let slot = &mut self.known_start[row.i.min(row.j) as usize + 1];
            self.known[*slot as usize] = row.i.max(row.j);
            *slot += 1;
        }
        self.moved.clear();
        self.moved
            .extend((0..self.bodies.len() as u32).filter(|&i| self.changed[i as usize]));
        // The grid still bounds every marble's path over the substep, and a marble the
        // cascade did not touch ends inside its bound: the moved marbles are looked up
        // against it, and against each other and the strays (outside their bounds)
        // directly when few, else through a grid of their own on the end positions (the
        // cost stays linear in the marbles moved). When a large share moved, every marble
        // is paired again on the end positions.
        let search = if self.moved.len() <= LATE_DIRECT {
            LateSearch::Direct
        } else if self.moved.len() * LATE_SHARE > n {
            LateSearch::All
        } else {
            LateSearch::OwnGrid
        };
        self.find_late(p, search);
        #[cfg(test)]
        if self.cross_check_late && search != LateSearch::All {
            self.cross_check(p, search);
        }
        // A pair already among the rows can meet (again) when one of them is hit later in
        // the substep (a marble knocked onto the floor rebounds into the one that knocked
        // it): such a pair found approaching and overlapping at the end is traced back to
        // its new meeting.
        // A shallow impact left to the next substep (its limit infinite) is taken up only
        // if the later hits drove it deep.
        let first_again = self.late.len();
        for row in &self.rows {
            let (i, j) = (row.i as usize, row.j as usize);
            if !(self.changed[i] || self.changed[j]) || self.event[i].max(self.event[j]) <= row.t {
                continue;
            }
            let (a, b) = (&self.bodies[i], &self.bodies[j]);
            let d = b.x - a.x;
            let deferred = row.limit == f32::INFINITY
                && a.r + b.r - d.length() < DISCRETE_OVERLAP * a.r.min(b.r);
            if !deferred
                && (b.v - a.v).dot(d) < -p.threshold * d.length()
                && let Some(again) = late_row(&self.bodies, &self.event, row.i, row.j, p)
            {
                self.late.push(again);
            }
        }
        // A pair with several rows is traced once.
        self.late[first_again..].sort_unstable_by_key(|r| (r.i, r.j));
        let mut kept = first_again;
        for k in first_again..self.late.len() {
            let pair = (self.late[k].i, self.late[k].j);
            if kept == first_again || pair != (self.late[kept - 1].i, self.late[kept - 1].j) {
                self.late[kept] = self.late[k];
                kept += 1;
            }
        }
        self.late.truncate(kept);
        let mut any = false;
        for row in self.late.iter_mut() {
            let (i, j) = (row.i as usize, row.j as usize);
            let u = (self.bodies[j].v - self.bodies[i].v).dot(row.n);
            if u < -p.threshold {
                let impulse = -(1.0 + row.e) * u * row.k;
                let (wi, wj) = (self.bodies[i].w, self.bodies[j].w);
                let rest = p.h - row.t;
                self.bodies[i].v -= (impulse * wi) * row.n;
                self.bodies[j].v += (impulse * wj) * row.n;
                self.bodies[i].x -= (impulse * wi * rest) * row.n;
                self.bodies[j].x += (impulse * wj * rest) * row.n;
                self.event[i] = row.t;
                self.event[j] = row.t;
                self.changed[i] = true;
                self.changed[j] = true;
                row.collided = true;
                any = true;
            }
        }
        self.rows.extend_from_slice(&self.late);
        any
    }

    /// Marbles the cascade moved off their paths, checked against the boards along them. A
    /// collision can send a marble in flight into a board it did not touch during the
    /// substep (the cascade only knows the boards each marble touched). Since its last
    /// event the marble has moved on a straight line; that path, from where the marble was
    /// then, is searched for its earliest impact with a board it did not touch there
    /// ([`crate::narrow::earliest_impact`]: exact for planes, meshes, thin boxes and moving
    /// boards alike). There, faster than the threshold it rebounds (equation (1) with the
    /// pair's restitution), slower it stops approaching, and it moves on for the rest of the
    /// substep (a few impacts at most). Boards it already touched at its last event that
    /// it now presses into put it back on their surface and stop its approach.
    fn onto_boards(&mut self, p: &PairParams, boards: &[BoardSnapshot]) {
        let (mut touching, mut touches) = (TouchList::default(), TouchList::default());
        for (k, b) in self.bodies.iter_mut().enumerate() {
            if !self.changed[k] {
                continue;
            }
            let tol = crate::narrow::touch_tolerance(p.tolerance, b.r, b.x);
            let material = Material {
                restitution: b.e,
                ..Material::default()
            };
            let r = b.r;
            // The boards within touching distance of centre `x` moving at `v`, at time `t`.
            let gather = |t: f32, x: Vec3, v: Vec3, out: &mut TouchList| {
                crate::narrow::gather(boards, None, t, x, r, tol, &material, -v, out);
            };
            let mut t0 = self.event[k].min(p.h);
            let mut start = b.x - b.v * (p.h - t0);
            gather(t0, start, b.v, &mut touching);
            for _ in 0..BOARD_IMPACTS {
                let path = Path {
                    t0,
                    x: start,
                    v: b.v,
                    a: Vec3::ZERO,
                };
                let Some((tau, piece)) = crate::narrow::earliest_impact(
                    boards,
                    None,
                    &path,
                    p.h - t0,
                    b.r,
                    tol,
                    &touching,
                ) else {
                    break;
                };
                let at = path.position(tau);
                gather(t0 + tau, at, b.v, &mut touches);
                let Some(t) = touches.as_slice().iter().find(|t| t.piece == piece) else {
                    break;
                };
                let u = (b.v - t.board_velocity).dot(t.normal);
                if u < -p.threshold {
                    b.v -= (1.0 + t.material.restitution) * u * t.normal;
                } else if u < 0.0 {
                    b.v -= u * t.normal;
                }
                t0 += tau;
                start = at;
                b.x = at + b.v * (p.h - t0);
                self.event[k] = t0;
                touching = touches;
            }
            // The boards it touched when it was last set moving: pressed into, it stays on
            // them.
            for t in touching.as_slice() {
                let depth = b.r - (b.x - t.point).dot(t.normal);
                let u = (b.v - t.board_velocity).dot(t.normal);
                if depth > 0.0 && u < 0.0 {
                    b.v -= u * t.normal;
                    b.x += depth * t.normal;
                }
            }
        }
    }

    /// Coulomb friction between touching marbles that both spin (rolling on), as impulses
    /// at the substep's start: the contact point's slip
    /// `s = (v₂ + ω₂ × (−r₂ n)) − (v₁ + ω₁ × (r₁ n))`, tangential part, is stopped by the
    /// impulse `−s / ((7/2)(1/m₁ + 1/m₂))` (a solid sphere's contact point has effective
    /// mass `2/7 m` against a tangential push), capped by `μ λ_n`, where `λ_n` is the normal
    /// impulse the pair's contact carried over the last substep (warm start) and `μ` the
    /// pair's mean friction. Piecewise-constant Coulomb friction, exact substep by substep;
    /// it never adds energy and conserves momentum. Impacts inside a substep are smooth.
    fn friction(&mut self) {
        if !self.bodies.iter().any(|b| b.spins) {
            return;
        }
        for row in &self.rows {
            let (i, j) = (row.i as usize, row.j as usize);
            let (a, b) = (&self.bodies[i], &self.bodies[j]);
            if !(a.spins && b.spins) || row.kind != Found::Start {
                continue;
            }
            let (ka, kb) = (a.entity.to_bits(), b.entity.to_bits());
            let Some(&normal) = self.warm.get(&(ka.min(kb), ka.max(kb))) else {
                continue;
            };
            let n = row.n;
            let vc = (b.v + b.omega.cross(-b.r * n)) - (a.v + a.omega.cross(a.r * n));
            let slip = vc - vc.dot(n) * n;
            let mut j_t = slip * (-1.0 / (3.5 * (a.w + b.w)));
            let cap = 0.5 * (a.mu + b.mu) * normal;
            let len = j_t.length();
            if len > cap {
                j_t *= cap / len;
            }
            if j_t == Vec3::ZERO {
                continue;
            }
            let spin = n.cross(j_t);
            let (wa, wb, ra, rb) = (a.w, b.w, a.r, b.r);
            let a = &mut self.bodies[i];
            a.v -= wa * j_t;
            a.omega -= (2.5 * wa / ra) * spin;
            let b = &mut self.bodies[j];
            b.v += wb * j_t;
            b.omega -= (2.5 * wb / rb) * spin;
            self.changed[i] = true;
            self.changed[j] = true;
        }
    }

    /// Orders the pair rows for the passes by colour (greedy: each row takes the first
    /// colour neither of its marbles has yet; beyond 31 they share the last): consecutive
    /// rows then rarely share a marble, so that one row's update does not wait on the one
    /// before it.
    fn colour_rows(&mut self) {
        const LAST: u32 = COLOURS as u32 - 1;
        self.colours.clear();
        self.colours.resize(self.bodies.len(), 0);
        let mut count = [0u32; LAST as usize + 2];
        self.pair_slot.clear();
        for r in &self.pair_gs {
            let used = self.colours[r.i as usize] | self.colours[r.j as usize];
            let c = (!used).trailing_zeros().min(LAST);
            self.colours[r.i as usize] |= 1 << c;
            self.colours[r.j as usize] |= 1 << c;
            count[c as usize + 1] += 1;
            self.pair_slot.push(c);
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let starts = count;
        // Scatter by colour (stable), remembering each row's index.
        self.pair_pass.clear();
        self.pair_pass.resize(
            self.pair_gs.len(),
            PairGs {
                i: 0,
                j: 0,
                n: Vec3::ZERO,
                k: 0.0,
                lambda: 0.0,
                target: 0.0,
            },
        );
        for (k, r) in self.pair_gs.iter().enumerate() {
            let c = self.pair_slot[k] as usize;
            let slot = count[c] as usize;
            count[c] += 1;
            self.pair_pass[slot] = *r;
            self.pair_slot[k] = slot as u32;
        }
        // Each colour's rows by four, the rest one by one; the last colour's rows may
        // share marbles, so they all go one by one.
        self.spans.clear();
        self.blocks.clear();
        self.block_first.clear();
        for c in 0..COLOURS {
            let (start, end) = (starts[c], starts[c + 1]);
            if start == end {
                continue;
            }
            let wide_end = if c < LAST as usize {
                start + (end - start) / 4 * 4
            } else {
                start
            };
            let first_block = self.blocks.len() as u32;
            for first in (start..wide_end).step_by(4) {
                let f = first as usize;
                let rows: &[PairGs; 4] = self.pair_pass[f..f + 4].try_into().expect("four rows");
                self.blocks.push(RowBlock::new(rows));
                self.block_first.push(first);
            }
            self.spans.push(ColourSpan {
                blocks: (first_block, self.blocks.len() as u32),
                tail: (wide_end, end),
            });
        }
    }

    /// Step 4 of the module docs: sequential impulses over every touching pair and the
    /// board contacts of their marbles, warm started, on the velocities the marbles would
    /// reach at the end of the substep; the impulses become forces over the substep
    /// (added to `a`), so every integrator moves the marbles consistently with them.
    fn solve_contacts(&mut self, p: &PairParams) {
        self.constraints.clear();
        // (`in_contact` marks the marbles in the rows: [`PairSolver::find_touching`].)
        for row in &self.rows {
            let (a, b) = (&self.bodies[row.i as usize], &self.bodies[row.j as usize]);
            let (ka, kb) = (a.entity.to_bits(), b.entity.to_bits());
            self.constraints.push(Constraint {
                i: row.i,
                j: row.j,
                n: row.n,
                vb: Vec3::ZERO,
                p: Vec3::ZERO,
                k: row.k,
                lambda: 0.0,
                slop: PAIR_SLOP * a.r.min(b.r),
                target: -row.gap / p.h,
                key: (ka.min(kb), ka.max(kb)),
            });
        }
        for t in &self.board_touches {
            if !self.in_contact[t.body as usize] {
                continue;
            }
            let b = &self.bodies[t.body as usize];
            self.constraints.push(Constraint {
                i: t.body,
                j: u32::MAX,
                n: t.normal,
                vb: t.velocity,
                p: t.point,
                k: 1.0 / b.w,
                lambda: 0.0,
                slop: PAIR_SLOP * b.r,
                // A speculative row may close its gap within the substep.
                target: if t.gap > 0.0 { -t.gap / p.h } else { 0.0 },
                // Board keys: the marble and the piece, the piece's bits flipped so that
                // they never equal a pair's key.
                key: (b.entity.to_bits(), !t.piece.0),
            });
        }
        let h = p.h;
        // From here on `v` is the velocity each marble would reach at the end of the
        // substep without contact forces, `v0` its velocity at the start.
        for b in self.bodies.iter_mut() {
            b.v0 = b.v;
            b.v += b.a * h;
        }
        // The passes run on compact copies: velocities and inverse masses by body, and the
        // pair and board rows apart (the same order as `constraints`: pairs, then boards),
        // so that the inner loops are short and branch-free.
        self.vel.clear();
        self.vel.extend(self.bodies.iter().map(|b| b.v.extend(b.w)));
        self.pair_gs.clear();
        self.board_gs.clear();
        for c in &self.constraints {
            let lambda = self.warm.get(&c.key).copied().unwrap_or(0.0);
            if c.j == u32::MAX {
                self.board_gs.push(BoardGs {
                    i: c.i,
                    n: c.n,
                    vb: c.vb,
                    k: c.k,
                    lambda,
                    target: c.target,
                });
            } else {
                self.pair_gs.push(PairGs {
                    i: c.i,
                    j: c.j,
                    n: c.n,
                    k: c.k,
                    lambda,
                    target: c.target,
                });
            }
        }
        self.colour_rows();
        let vel = self.vel.as_mut_slice();
        // Warm start.
        for r in &self.pair_pass {
            if r.lambda != 0.0 {
                r.apply(vel, r.lambda);
            }
        }
        for r in &self.board_gs {
            if r.lambda != 0.0 {
                r.apply(vel, r.lambda);
            }
        }
        let (blocks, pass) = (&mut self.blocks, &mut self.pair_pass);
        for _ in 0..p.iterations {
            // Colour by colour, its blocks of four and then its single rows.
            let mut wide = Vec4::ZERO;
            let mut largest = 0.0f32;
            for span in &self.spans {
                for b in &mut blocks[span.blocks.0 as usize..span.blocks.1 as usize] {
                    wide = b.pass(vel, wide);
                }
                for r in &mut pass[span.tail.0 as usize..span.tail.1 as usize] {
                    largest = r.pass(vel, largest);
                }
            }
            largest = larger(largest, wide.max_element());
            for r in self.board_gs.iter_mut() {
                let u = (vel[r.i as usize].truncate() - r.vb).dot(r.n) - r.target;
                if let Some(d) = accumulate(&mut r.lambda, u, r.k) {
                    r.apply(vel, d);
                    largest = larger(largest, d.abs() / r.k);
                }
            }
            if largest < CONVERGED {
                break;
            }
        }
        for (b, &first) in self.blocks.iter().zip(&self.block_first) {
            let rows = &mut self.pair_pass[first as usize..first as usize + 4];
            for (r, lambda) in rows.iter_mut().zip(b.lambda.to_array()) {
                r.lambda = lambda;
            }
        }
        for (r, &slot) in self.pair_gs.iter_mut().zip(&self.pair_slot) {
            r.lambda = self.pair_pass[slot as usize].lambda;
        }
        let lambdas = self
            .pair_gs
            .iter()
            .map(|r| r.lambda)
            .chain(self.board_gs.iter().map(|r| r.lambda));
        for (c, lambda) in self.constraints.iter_mut().zip(lambdas) {
            c.lambda = lambda;
        }
        let bodies = &mut self.bodies;
        for (b, v) in bodies.iter_mut().zip(vel.iter()) {
            b.v = v.truncate();
        }
        self.warm_next.clear();
        for c in &self.constraints {
            if c.lambda > 0.0 {
                self.warm_next.insert(c.key, c.lambda);
            }
        }
        std::mem::swap(&mut self.warm, &mut self.warm_next);
        // The impulses are forces over the substep.
        for (k, b) in bodies.iter_mut().enumerate() {
            let free = b.v0 + b.a * h;
            let dv = b.v - free;
            if dv != Vec3::ZERO {
                b.a += dv / h;
                self.changed[k] = true;
            }
            b.v = b.v0;
        }
    }

    /// Step 5 of the module docs: overlap beyond the slop out of positions.
    fn project(&mut self) {
        let (bodies, left) = (&mut self.bodies, &mut self.push_left);
        // Each marble moves at most one radius in all (see [`MAX_PROJECTION`]).
        left.clear();
        left.extend(bodies.iter().map(|b| b.r));
        for _ in 0..PROJECTION_PASSES {
            let mut moved = false;
            for c in &self.constraints {
                let i = c.i as usize;
                if c.j == u32::MAX {
                    let gap = (bodies[i].x - c.p).dot(c.n) - bodies[i].r;
                    if gap < -c.slop && left[i] > 0.0 {
                        let most = (MAX_PROJECTION * bodies[i].r).min(left[i]);
                        let push = (PROJECTION * (-c.slop - gap)).min(most);
                        bodies[i].x += push * c.n;
                        left[i] -= push;
                        self.changed[i] = true;
                        moved = true;
                    }
                    continue;
                }
                let j = c.j as usize;
                let d = bodies[j].x - bodies[i].x;
                let dist = d.length();
                let gap = dist - bodies[i].r - bodies[j].r;
                if gap < -c.slop {
                    let n = if dist > 0.0 { d / dist } else { c.n };
                    let push = (PROJECTION * (-c.slop - gap))
                        .min(MAX_PROJECTION * bodies[i].r.min(bodies[j].r))
                        * c.k;
                    let pi = (push * bodies[i].w).min(left[i]);
                    let pj = (push * bodies[j].w).min(left[j]);
                    if pi <= 0.0 && pj <= 0.0 {
                        continue;
                    }
                    bodies[i].x -= pi * n;
                    bodies[j].x += pj * n;
                    left[i] -= pi;
                    left[j] -= pj;
                    self.changed[i] = true;
                    self.changed[j] = true;
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
    }
}

/// The state of the collision cascade (module docs, step 3).
struct Cascade<'a> {
    p: &'a PairParams,
    /// Move marbles for the time left after each impact (impacts inside the substep,
    /// after integration); off for impacts at the substep's start, before integration.
    shift: bool,
    rows: &'a mut [Row],
    bodies: &'a mut [Body],
    touches: &'a [BoardTouch],
    touch_start: &'a [u32],
    /// Velocity change per body.
    dv: &'a mut [Vec3],
    /// Time of each body's last impact.
    event: &'a mut [f32],
    changed: &'a mut [bool],
    /// Bodies whose velocity changed, to look at next.
    queue: &'a mut Vec<u32>,
}

impl Cascade<'_> {
    /// Row `k`: the two-body equation if its marbles approach faster than the threshold.
    fn pair(&mut self, k: usize) {
        let row = &mut self.rows[k];
        let (i, j) = (row.i as usize, row.j as usize);
        let u = row.u + (self.dv[j] - self.dv[i]).dot(row.n);
        if u >= -row.limit {
            return;
        }
        let t = row.t.max(self.event[i]).max(self.event[j]);
        let impulse = -(1.0 + row.e) * u * row.k;
        let (wi, wj) = (self.bodies[i].w, self.bodies[j].w);
        self.dv[i] -= impulse * wi * row.n;
        self.dv[j] += impulse * wj * row.n;
        if self.shift {
            // The marbles leave the impact with their new velocities.
            let rest = self.p.h - t;
            self.bodies[i].x -= (impulse * wi * rest) * row.n;
            self.bodies[j].x += (impulse * wj * rest) * row.n;
        }
        self.event[i] = t;
        self.event[j] = t;
        // The impact happened at `t` (later than found when a neighbour's impact passed it
        // on): a later hit of either marble is what can make the pair meet again.
        row.t = t;
        row.collided = true;
        self.changed[i] = true;
        self.changed[j] = true;
        self.queue.push(i as u32);
        self.queue.push(j as u32);
    }

    /// The boards body `b` touches: equation (1) against each one the cascade drives it
    /// into (judged on its end velocity, which the board response already made leave or
    /// rest on the board).
    fn boards(&mut self, b: usize) {
        let mut hit = false;
        let range = self.touch_start[b] as usize..self.touch_start[b + 1] as usize;
        for t in &self.touches[range] {
            if t.gap > 0.0 {
                // A speculative row: the marble does not touch this piece.
                continue;
            }
            let u = (self.bodies[b].v + self.dv[b] - t.velocity).dot(t.normal);
            if u < -self.p.threshold {
                let change = -(1.0 + t.restitution) * u * t.normal;
                self.dv[b] += change;
                if self.shift {
                    self.bodies[b].x += change * (self.p.h - self.event[b]);
                }
                hit = true;
            }
        }
        if hit {
            self.queue.push(b as u32);
        }
    }
}

/// Whether impact `row` ends with the pair overlapping by less than [`DISCRETE_OVERLAP`]
/// of the smaller radius, measured along the impact normal (a pair that passed through
/// each other is deep, however far apart it ends).
#[inline]
fn shallow(bodies: &[Body], row: &Row) -> bool {
    let (a, b) = (&bodies[row.i as usize], &bodies[row.j as usize]);
    let overlap = a.r + b.r - (b.x - a.x).dot(row.n);
    overlap < DISCRETE_OVERLAP * a.r.min(b.r)
}

/// Whether `row` is an impact the impact stage resolves now: a deep one (not
/// [`shallow`]) whose marbles close.
#[inline]
fn deep_impact(bodies: &[Body], row: &Row) -> bool {
    row.kind == Found::Impact && !shallow(bodies, row) && row.u < 0.0
}

/// A necessary condition for marbles `i` and `j` to meet during the substep and end it
/// overlapping deeply (not [`shallow`]): their displacements over the substep differ by
/// at least half the depth that counts, less `slack` ([`rounding_slack`]).
///
/// Why: on the relative path `d(τ) = d₀ + m τ` (`m` the difference of the
/// displacements) the pair meets at `τ*` with `|d(τ*)| = r₁ + r₂` and normal
/// `n = d(τ*) / |d(τ*)|`, so the end overlap along `n` is
/// `r₁ + r₂ − d(1)·n = −(1 − τ*) m·n ≤ |m|`. The factor of one half, and the slack far
/// from the origin, cover the rounding of the narrow phase's root and normal, so that the
/// test never drops a pair the narrow phase would call deep. (Impacts are found only
/// with continuous collision on, but the test does not need to know.)
#[inline]
fn may_impact_deeply(bodies: &[Body], i: u32, j: u32, slack: f32) -> bool {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let m = (b.x - b.x0) - (a.x - a.x0);
    let least = 0.5 * DISCRETE_OVERLAP * a.r.min(b.r) - slack;
    least <= 0.0 || m.length_squared() >= least * least
}

/// Sixteen f32 ulps of the largest coordinate and diameter among `bodies` (at the start
/// and end of the substep): more than the narrow phase's rounding of an impact's depth.
fn rounding_slack(bodies: &[Body]) -> f32 {
    let far = bodies.iter().fold(0.0f32, |far, b| {
        far.max(b.x.abs().max(b.x0.abs()).max_element() + 2.0 * b.r)
    });
    16.0 * f32::EPSILON * far
}

/// The candidate pairs of the last [`PairSolver::cover`]: the standing candidates of
/// marbles that stayed inside their bounds, and the strays' pairs.
fn candidate_pairs<'a>(
    candidates: &'a [(u32, u32)],
    extra: &'a [(u32, u32)],
    stray: &'a [bool],
    strays: &[u32],
) -> impl Iterator<Item = (u32, u32)> + 'a {
    let any = !strays.is_empty();
    candidates
        .iter()
        .filter(move |&&(i, j)| !(any && (stray[i as usize] || stray[j as usize])))
        .chain(extra)
        .copied()
}

/// Whether marbles `i` and `j` touch or overlap at the end of the substep (the test
/// [`late_row`] starts with).
#[inline]
fn late_touch(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> bool {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let tol = crate::narrow::touch_tolerance(p.tolerance, a.r.min(b.r), a.x.abs().max(b.x.abs()));
    (b.x - a.x).length() - (a.r + b.r) <= tol
}

/// A pair of marbles `i < j` that a collision sent into each other off their free paths,
/// found overlapping (or touching) at the end of the substep: back along their new straight
/// paths to the later of their last impacts, then forward to where they meet.
fn late_row(bodies: &[Body], event: &[f32], i: u32, j: u32, p: &PairParams) -> Option<Row> {
    if !late_touch(bodies, i, j, p) {
        return None;
    }
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let d = b.x - a.x;
    let te = event[i as usize].max(event[j as usize]);
    let rest = p.h - te;
    let de = d - (b.v - a.v) * rest;
    let reach = a.r + b.r;
    let le = de.length();
    let m = d - de;
    let (t, n) = if le > reach && m.length_squared() > 0.0 {
        let half_b = de.dot(m);
        let c = (le - reach) * (le + reach);
        let disc = (half_b * half_b - m.length_squared() * c).max(0.0);
        let tau = (c / (-half_b + disc.sqrt())).clamp(0.0, 1.0);
        (te + tau * rest, (de + m * tau).normalize_or(Vec3::Y))
    } else {
        (te, d.normalize_or(Vec3::Y))
    };
    Some(Row {
        i,
        j,
        n,
        u: (b.v - a.v).dot(n),
        t,
        e: 0.5 * (a.e + b.e),
        k: 1.0 / (a.w + b.w),
        limit: p.threshold,
        kind: Found::Impact,
        collided: false,
        gap: 0.0,
    })
}

/// A speculative contact for bodies `i < j`, apart at the substep's start (contact stage):
/// a row if they close no faster than the restitution threshold (faster is an impact) and
/// their gap is within what they could close during the substep, their free paths'
/// approach plus what their accelerations alone could close (a marble held by a board or
/// another marble does not follow its free path). The row lets the pair close its gap
/// and no more (module docs, step 4).
#[inline]
fn near_row(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> Option<Row> {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let d = b.x - a.x;
    let l = d.length();
    let gap = l - (a.r + b.r);
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    let n = d / l;
    let u = (b.v0 - a.v0).dot(n);
    let closing = (-(b.d - a.d).dot(n)).max(0.0) + (a.a.length() + b.a.length()) * p.h * p.h;
    // A pair closing faster than the threshold is an impact to come, for the impact stage
    // (with its restitution), not a contact.
    (gap <= closing && u >= -p.threshold).then_some(Row {
        i,
        j,
        n,
        u,
        t: 0.0,
        e: 0.0,
        k: 1.0 / (a.w + b.w),
        // Never a collision of the start's cascade.
        limit: f32::INFINITY,
        kind: Found::Near,
        collided: false,
        gap,
    })
}

/// Step 2 of the module docs for bodies `i < j`: the pair's row, if they touch at the
/// start, meet during the substep, or touch at its end.
#[inline]
fn narrow(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> Option<Row> {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let reach = a.r + b.r;
    let tol = crate::narrow::touch_tolerance(p.tolerance, a.r.min(b.r), a.x.abs().max(b.x.abs()));
    let d0 = b.x0 - a.x0;
    let d1 = b.x - a.x;
    let l0 = d0.length();
    let e = 0.5 * (a.e + b.e);
    let k = 1.0 / (a.w + b.w);
    let unit = |d: Vec3, fallback: Vec3| {
        let l = d.length();
        if l > 0.0 { d / l } else { fallback }
    };
    let row = |n: Vec3, u: f32, t: f32, kind: Found| {
        // A pair meeting slower than the threshold is a contact: its approach is removed
        // at the impact (restitution 0), as on boards.
        let slow = kind == Found::Impact && u >= -p.threshold;
        Row {
            i,
            j,
            n,
            u,
            t,
            e: if slow { 0.0 } else { e },
            k,
            limit: if slow { 0.0 } else { p.threshold },
            kind,
            collided: false,
            gap: 0.0,
        }
    };
    if l0 - reach <= tol {
        // Touching at the start: judged before this step's forces.
        let n = unit(d0, unit(d1, Vec3::Y));
        return Some(row(n, (b.v0 - a.v0).dot(n), 0.0, Found::Start));
    }
    let l1 = d1.length();
    if p.ccd {
        // |d0 + m τ| = reach on τ ∈ [0, 1].
        let m = d1 - d0;
        let half_b = d0.dot(m);
        if half_b < 0.0 {
            let aa = m.length_squared();
            let c = (l0 - reach) * (l0 + reach);
            let disc = half_b * half_b - aa * c;
            if disc >= 0.0 {
                let tau = c / (-half_b + disc.sqrt());
                if tau <= 1.0 {
                    let n = unit(d0 + m * tau, d0 / l0);
                    // The closing speed at the impact: exact on the linear relative path
                    // (marbles under the same gravity), unless a marble's velocity jumped
                    // during the substep (a board stopped it): then the pair closes at
                    // least as fast as at the end, and judging it slower would leave it
                    // still closing, and sinking into each other, after the impulse.
                    let v_rel = (b.v0 - a.v0).lerp(b.v - a.v, tau);
                    let u = v_rel.dot(n).min((b.v - a.v).dot(n));
                    return Some(row(n, u, tau * p.h, Found::Impact));
                }
            }
        }
    }
    if l1 - reach <= tol {
        let n = unit(d1, d0 / l0);
        return Some(row(n, (b.v0 - a.v0).dot(n), p.h, Found::End));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid reports exactly the pairs whose bound spheres overlap, each once, for
    /// mixed sizes (some large) and random positions.
    /// The late-pair searches that look only at the marbles the collisions moved (one by
    /// one, or through a grid of their own) find exactly the pairs that re-pairing every
    /// marble finds, checked at every substep of a pour in which tens to hundreds of
    /// marbles are moved per substep.
    #[test]
    fn late_pair_searches_match_re_pairing_every_marble() {
        let scene = crate::scenes::pour_box(1200);
        let mut sim = crate::simulation::Simulation::from_scene(&scene).unwrap();
        sim.step();
        sim.world_mut()
            .resource_mut::<PairSolver>()
            .cross_check_late = true;
        for _ in 0..20 {
            sim.step();
        }
        let checked = sim.world().resource::<PairSolver>().cross_checked;
        eprintln!("late-pair searches checked (direct, own grid): {checked:?}");
        assert!(
            checked[LateSearch::Direct as usize] > 0 && checked[LateSearch::OwnGrid as usize] > 0,
            "both searches ran: {checked:?}"
        );
    }

    /// A fixed pseudo-random sequence in [0, 1) from `seed` (a 32-bit LCG).
    fn uniform(mut seed: u32) -> impl FnMut() -> f32 {
        move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        }
    }

    /// The impact stage's screen ([`may_impact_deeply`]) never drops a pair the narrow
    /// phase calls a deep impact: random pairs (radii from 0.1 mm to 10 cm, in ratios to
    /// 100; near the origin and a kilometre out) apart at the start, moved towards each
    /// other by their gap and a few times the depth that counts, or by up to four radii.
    #[test]
    fn the_impact_screen_keeps_every_deep_impact() {
        let mut uniform = uniform(0x2f6b_51c3);
        let p = PairParams {
            h: 1.0 / 240.0,
            ccd: true,
            threshold: 0.0,
            tolerance: 1e-4,
            iterations: 1,
        };
        let (mut deep, mut near_limit, mut screened_out) = (0, 0, 0);
        for case in 0..200_000 {
            let mut unit = || {
                Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5).normalize_or(Vec3::X)
            };
            let (u1, u2, u3) = (unit(), unit(), unit());
            let ra = 1e-4 * 1e3f32.powf(uniform());
            let rb = ra * 10f32.powf(2.0 * uniform() - 1.0);
            let origin = if case % 4 == 0 { 1e3 * u1 } else { 0.1 * u1 };
            // Apart at the start by up to the depth that counts or up to a diameter, then
            // moved towards each other (roughly along the line of centres) by the gap
            // and from minus one to two times the depth that counts more, or by up to
            // four radii.
            let limit = DISCRETE_OVERLAP * ra.min(rb);
            let gap = 2e-4 * (ra + rb)
                + if case % 3 == 0 {
                    (ra + rb) * uniform()
                } else {
                    limit * uniform()
                };
            let (x0a, x0b) = (origin, origin + (ra + rb + gap) * u2);
            let travel = if case % 2 == 0 {
                (gap + limit * (3.0 * uniform() - 1.0)).max(0.0)
            } else {
                gap + 4.0 * ra.max(rb) * uniform()
            };
            let towards = (-(u2 + 0.3 * u3)).normalize();
            let body = |x0: Vec3, x: Vec3, r: f32| Body {
                entity: Entity::from_raw_u32(1).unwrap(),
                x,
                x0,
                v: (x - x0) / p.h,
                v0: (x - x0) / p.h,
                w: 1.0,
                r,
                e: 0.5,
                a: Vec3::ZERO,
                d: Vec3::ZERO,
                omega: Vec3::ZERO,
                spins: false,
                mu: 0.0,
            };
            let bodies = [body(x0a, x0a, ra), body(x0b, x0b + travel * towards, rb)];
            let kept = may_impact_deeply(&bodies, 0, 1, rounding_slack(&bodies));
            screened_out += usize::from(!kept);
            if let Some(row) = narrow(&bodies, 0, 1, &p)
                && deep_impact(&bodies, &row)
            {
                deep += 1;
                near_limit += usize::from(travel - gap < 2.0 * limit);
                assert!(kept, "case {case}: a deep impact screened out: {row:?}");
            }
        }
        assert!(
            deep > 10_000 && near_limit > 1_000 && screened_out > 10_000,
            "all kinds of pair exercised: {deep} deep ({near_limit} near the limit), \
             {screened_out} screened out"
        );
    }

    /// Four rows of a colour updated together in SIMD lanes give bit for bit what the
    /// rows give one after another: velocities, impulses and the running maximum, over
    /// random rows, masses, impulses (zero ones among them) and velocities.
    #[test]
    fn row_blocks_are_four_single_rows() {
        let mut uniform = uniform(0x9e37_79b9);
        let mut rnd = move || uniform() * 2.0 - 1.0;
        for _ in 0..2000 {
            let vel: Vec<Vel> = (0..8)
                .map(|_| Vec4::new(rnd(), rnd(), rnd(), 1.0 + 100.0 * rnd().abs()))
                .collect();
            // Marbles 0..4 against 4..8 in a shuffled order: no two rows share a marble.
            let rows: [PairGs; 4] = std::array::from_fn(|k| {
                let n = Vec3::new(rnd(), rnd(), rnd()).normalize();
                let (i, j) = (k as u32, 4 + ((k as u32 + 1) % 4));
                PairGs {
                    i,
                    j,
                    n,
                    k: 1.0 / (vel[i as usize].w + vel[j as usize].w),
                    lambda: if rnd() > 0.0 { 0.0 } else { rnd().abs() },
                    target: 0.1 * rnd(),
                }
            });
            let (mut one, mut rows_one, mut largest) = (vel.clone(), rows, 0.0f32);
            for r in &mut rows_one {
                largest = r.pass(&mut one, largest);
            }
            let (mut four, mut block) = (vel.clone(), RowBlock::new(&rows));
            let wide = block.pass(&mut four, Vec4::ZERO);
            let bits = |v: &[Vel]| {
                v.iter()
                    .map(|v| v.to_array().map(f32::to_bits))
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&one), bits(&four));
            let lambdas = rows_one.map(|r| r.lambda.to_bits());
            assert_eq!(lambdas, block.lambda.to_array().map(f32::to_bits));
            assert_eq!(largest.to_bits(), wide.max_element().to_bits());
        }
    }

    #[test]
    fn grid_pairs_match_brute_force() {
        let mut dense = 0;
        let mut rnd = uniform(12345);
        // Spread wide (hashed cells) and packed (the dense table).
        for case in 0..40 {
            let spread = if case % 2 == 0 { 1.0 } else { 0.15 };
            let n = 50 + 30 * (case / 2);
            let b: Vec<Vec4> = (0..n)
                .map(|k| {
                    let r = if k % 37 == 0 {
                        0.2
                    } else {
                        0.01 + 0.01 * rnd()
                    };
                    let p = spread * (Vec3::new(rnd(), 0.3 * rnd(), rnd()) - 0.5);
                    p.extend(r)
                })
                .collect();
            let mut grid = Grid::default();
            grid.build(&b);
            dense += grid.dense.is_some() as usize;
            let mut found = Vec::new();
            grid.pairs(&b, |i, j| found.push((i.min(j), i.max(j))));
            let len = found.len();
            found.sort_unstable();
            found.dedup();
            assert_eq!(found.len(), len, "case {case}: a pair reported twice");
            let mut want = Vec::new();
            for i in 0..n {
                for j in i + 1..n {
                    let (p, q) = (b[i], b[j]);
                    let r = p.w + q.w;
                    if (p.truncate() - q.truncate()).length_squared() <= r * r {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(found, want, "case {case}");
        }
        assert!(
            dense > 0 && dense < 40,
            "both modes exercised: {dense} dense"
        );
    }

    /// Over many substeps of marbles drifting together, jittering, a few jumping far and
    /// one leaving, the candidate pairs of [`PairSolver::cover`] hold every pair whose
    /// spheres overlap, each once, while the skin is kept (strays paired on their own)
    /// and rebuilt.
    #[test]
    fn kept_candidates_cover_every_overlapping_pair() {
        let mut uniform = uniform(99);
        let mut rnd = move || uniform() - 0.5;
        let r = 0.008;
        let mut solver = PairSolver::default();
        let n = 600;
        solver.bodies = (0..n)
            .map(|k| {
                let x = Vec3::new(rnd(), 0.3 * rnd(), rnd()) * 0.5;
                Body {
                    entity: Entity::from_raw_u32(k as u32 + 1).unwrap(),
                    x,
                    x0: x,
                    v: Vec3::ZERO,
                    v0: Vec3::ZERO,
                    w: 1.0,
                    r: if k % 50 == 0 { 4.0 * r } else { r },
                    e: 0.5,
                    a: Vec3::ZERO,
                    d: Vec3::ZERO,
                    omega: Vec3::ZERO,
                    spins: false,
                    mu: 0.5,
                }
            })
            .collect();
        let (mut kept, mut with_strays) = (0, 0);
        for step in 0..200 {
            let drift = Vec3::new(0.004, -0.001, 0.002);
            for (k, b) in solver.bodies.iter_mut().enumerate() {
                let jitter = Vec3::new(rnd(), rnd(), rnd()) * 0.0008;
                b.x += drift + jitter;
                if (k + step) % 97 == 0 {
                    b.x += Vec3::new(rnd(), rnd(), rnd()) * 0.05;
                }
            }
            if step == 150 {
                solver.bodies.pop();
            }
            let was_valid = solver.skin_valid && solver.bound.len() == solver.bodies.len();
            solver.cover(|b| b.x.extend(1.1 * b.r));
            kept += usize::from(was_valid && solver.drift != Vec3::ZERO);
            with_strays += usize::from(!solver.strays.is_empty());
            let mut found: Vec<(u32, u32)> = candidate_pairs(
                &solver.candidates,
                &solver.extra,
                &solver.stray,
                &solver.strays,
            )
            .collect();
            let mut overlapping = Vec::new();
            let b = &solver.bodies;
            for i in 0..b.len() {
                for j in i + 1..b.len() {
                    let reach = 1.1 * (b[i].r + b[j].r);
                    if (b[i].x - b[j].x).length() <= reach {
                        overlapping.push((i as u32, j as u32));
                    }
                }
            }
            let len = found.len();
            found.sort_unstable();
            found.dedup();
            assert_eq!(found.len(), len, "step {step}: a pair reported twice");
            for pair in overlapping {
                assert!(
                    found.binary_search(&pair).is_ok(),
                    "step {step}: {pair:?} missed"
                );
            }
        }
        assert!(
            kept > 100 && with_strays > 50,
            "kept {kept}, with strays {with_strays}"
        );
    }
}
