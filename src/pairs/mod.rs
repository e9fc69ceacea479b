//! Marble–marble collisions (`marble_collisions: true`): broad phase, exact
//! sphere–sphere narrow phase, the collision cascade and the contact solver. The method,
//! its reasoning and its figures are in `docs/pair-solver.md`; the physics in
//! `docs/PHYSICS.md` §6.
//!
//! Two marbles meeting is the two-body form of equation (1): along the line of centres
//! `n`, closing speed `u = (v₂ − v₁)·n`, impulse `J = −(1 + e) u / (1/m₁ + 1/m₂)`. That is
//! exact for an isolated impact, but marbles come in crowds: a Newton's cradle passes one
//! impact down a line of touching marbles, and a pile presses every marble against its
//! neighbours and the floor at once. Two stages per substep handle them, each driving a
//! [`PairSolver`] through the phases its docs list:
//!
//! **Before integration** (stage `PairContacts`), at the substep's start:
//! 1. **Broad phase** (`grid.rs`, `candidates.rs`): a uniform grid over each marble's sphere
//!    around its free path, counting-sorted by cell; the pairs found stand for later
//!    substeps (a Verlet list with a skin of a quarter radius, or up to a radius for a lone
//!    marble moving relative to the others, measured after taking off the marbles' common
//!    drift), and the few marbles that leave their skins are paired afresh.
//! 2. **Narrow phase** (`narrow.rs`): exact sphere–sphere. A pair touching at the start is
//!    judged on its closing speed *before this step's forces*: faster than
//!    `restitution_threshold` is a collision, otherwise a contact.
//! 3. **Collisions at the start** (`impacts.rs`) get the two-body equation as a velocity
//!    change before the step's motion, as a cascade: an impulse that makes a touching
//!    neighbour (or a board) approach faster than the threshold makes it collide in turn,
//!    at the same instant. Friction between touching marbles that spin (`friction.rs`).
//! 4. **Contacts** (`colour.rs`, `rows.rs`, `solve.rs`, `warm.rs`): every touching pair, every
//!    speculative pair (apart by a gap it could close during the substep), and those
//!    marbles' board contacts (recorded, and speculative rows for the pieces they could
//!    reach) are solved together by projected Gauss–Seidel with warm starting and
//!    over-relaxation, on the velocities the marbles would reach at the substep's end. The
//!    pair rows are visited by colour, four at a time in SIMD lanes with the bits of one
//!    row after another. The impulses become forces over the substep, so every integrator
//!    moves the marbles consistently with them.
//! 5. **Overlap** beyond a slop of 0.2% of the smaller radius is projected out of
//!    positions (`project.rs`), without touching velocities.
//!
//! **After the marble–board response** (stage `PairImpacts`), with continuous collision: a
//! pair that met during the substep finds its time of impact along the relative path, the
//! root of `|D₀ + (D₁ − D₀) τ| = r₁ + r₂`. If it would end overlapping by more than 5% of
//! the radius it collides there, through the same cascade; a shallower meeting is left to
//! the next substep's contact stage, which judges it on the same closing speed. Marbles a
//! collision sends off their free paths are then checked against the boards and the
//! marbles they may now meet, in a few rounds (`late.rs`).
//!
//! With rolling on, touching marbles that spin also exert Coulomb friction on each other
//! (impulses at the start of each substep, capped by the contact's last normal impulse).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicBool, Ordering};

use bevy_ecs::prelude::*;
use glam::{IVec3, Mat4, Vec3, Vec4};

use crate::board_contact::{BoardSnapshot, Material, NearPieces, Path, TouchList};
use crate::components::ContactKind;
use crate::geometry::PieceId;

mod candidates;
mod colour;
mod friction;
mod grid;
mod impacts;
mod late;
mod narrow;
mod project;
mod rows;
mod solve;
mod warm;

use candidates::{any_body_pair, scan_body_pairs};
pub(crate) use grid::{Grid, KeyMap};
use narrow::{
    deep_impact, late_row, late_touch, may_impact_deeply, narrow, near_row, rounding_slack, shallow,
};
use rows::{BoardGs, ColourSpan, PairGs, RowBlock, Vel, accumulate, larger};
use solve::BoardPush;
pub(crate) use warm::StowedImpulses;
use warm::{Warm, scale as warm_scale};

/// A marble's [`NearPieces`] list by its entity, where it has one: how the searches of
/// the boards after collisions reach the lists the marbles keep as components.
pub type NearOf<'a> = dyn Fn(Entity) -> Option<&'a NearPieces> + Sync + 'a;

/// Overlap left alone by the position projection, as a fraction of the smaller radius.
pub const PAIR_SLOP: f32 = 2e-3;

/// Extra room around each marble's free path in the broad phase, as a fraction of its
/// radius, for the contact forces' change of path.
const BOUND_MARGIN: f32 = 0.1;

/// Impacts that would leave less overlap than this share of the radius at the end of
/// the substep are resolved by the next substep's contact stage instead.
const DISCRETE_OVERLAP: f32 = 0.05;

/// Rounds of looking for what collided marbles run into on their new paths.
const LATE_ROUNDS: usize = 4;

/// Colours of the pair rows in the contact passes (the last takes every row that finds no
/// other free, so its rows may share marbles).
const COLOURS: usize = 32;

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
    /// The first marble: the pair's lower entity in `Entity`'s order (each pair is
    /// listed in one order whatever the marbles' storage order).
    pub a: Entity,
    /// The second marble, the higher entity.
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
    /// In the contact stage ([`PairSolver::find_touching`]), the pair's place in the
    /// standing candidates followed by the strays' pairs (the standing pairs of strays,
    /// which are left out, counted too): its warm start is found by walking the last
    /// substep's rows in that order ([`warm`]). `u32::MAX` elsewhere.
    at: u32,
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

/// A marble's free path in the impact stage ([`PairSolver::push_free_end`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct FreeEnd {
    /// Time of the first board event after the substep's start, s (`INFINITY`: none, or the
    /// marble was put back on its free path already).
    pub(crate) after: f32,
    /// End of the free path.
    pub(crate) x: Vec3,
    /// Velocity at the end of the free path.
    pub(crate) v: Vec3,
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

/// The pair stages' state: reusable buffers and the warm-start impulses (a resource).
///
/// Both stages drive it in the same four phases, each a call or a loop of calls, and stop
/// after the first phase that finds nothing to do:
///
/// | phase | contact stage (`PairContacts`) | impact stage (`PairImpacts`) |
/// | --- | --- | --- |
/// | 1. broad phase | [`begin`](Self::begin); per table of marbles [`gather_table`](Self::gather_table), its rows' [`contact_sphere`](Self::contact_sphere)s written with [`Gathered::write_with_paths`]; [`cover_gathered`](Self::cover_gathered) (false: [`forget_contacts`](Self::forget_contacts), stop) | [`begin`](Self::begin); per table [`gather_table`](Self::gather_table), its rows' [`impact_sphere`](Self::impact_sphere)s written with [`Gathered::write`]; [`cover_gathered`](Self::cover_gathered) (false: stop) |
/// | 2. bodies | [`select_bodies`](Self::select_bodies), [`clear_bodies`](Self::clear_bodies), per marble [`selected`](Self::selected) [`push_body_on_free_path`](Self::push_body_on_free_path) (at the substep's start), [`find_touching`](Self::find_touching) (false: stop) | [`select_bodies`](Self::select_bodies), [`clear_bodies`](Self::clear_bodies), per marble selected [`push_body`](Self::push_body) (start and end of the substep), [`any_deep_impact`](Self::any_deep_impact) (false: stop); [`select_every_marble_for_impacts`](Self::select_every_marble_for_impacts) (true: the bodies again, every marble's), [`find_impacts`](Self::find_impacts) |
/// | 3. board contacts | [`begin_board_touches`](Self::begin_board_touches); per body [`next_body_touches`](Self::next_body_touches) then, if [`in_rows`](Self::in_rows), its [`push_board_touch`](Self::push_board_touch)es; [`end_board_touches`](Self::end_board_touches) | the same, every marble |
/// | 4. solve | [`solve_touching`](Self::solve_touching) | [`resolve_impacts`](Self::resolve_impacts) |
///
/// Then [`changed_body`](Self::changed_body) gives each body whose state the stage
/// changed. Bodies are pushed in the marbles' order in every phase: every marble, or the
/// marbles [`selected`](Self::selected).
#[derive(Resource, Default, Debug)]
pub struct PairSolver {
    /// The marbles of the current substep: every marble, or with `compact` those in
    /// `selected` ([`PairSolver::select_bodies`]).
    bodies: Vec<Body>,
    /// The marbles chosen as bodies (ascending), and each marble's body index among them
    /// (`NOT_A_BODY` for the others), when `compact`.
    selected: Vec<u32>,
    local: Vec<u32>,
    compact: bool,
    /// Their board contacts, grouped by body in body order.
    board_touches: Vec<BoardTouch>,
    /// Start of each body's board contacts in `board_touches` (one more entry than
    /// bodies).
    touch_start: Vec<u32>,
    /// The bound spheres the candidate pairs were found on (each marble's sphere when
    /// they were found, grown by the skin), and the grid over them.
    bound: Vec<Vec4>,
    grid: Grid,
    /// The grid's pairs found by each chunk on the task pool ([`Grid::pairs_into`]).
    pair_chunks: Vec<Vec<(u32, u32)>>,
    /// Whether the narrow phases over the candidate pairs run on the task pool (set by
    /// [`PairSolver::cover_gathered`]), and the rows each chunk found there
    /// ([`scan_body_pairs`]).
    on_pool: bool,
    row_chunks: Vec<Vec<Row>>,
    /// The candidates stand for these bodies (cleared when the bodies change).
    skin_valid: bool,
    /// Covers since the bounds were made.
    covers: u32,
    /// This substep's spheres (scratch of [`PairSolver::cover`]), kept at the number of
    /// marbles: each table's rows write theirs in place ([`PairSolver::gather_table`]).
    spheres: Vec<Vec4>,
    /// With the spheres: each body's radius.
    radii: Vec<f32>,
    /// The contact stage's free displacements, kept from the sphere gather for the bodies.
    paths: Vec<Vec3>,
    /// Where the next table's rows go in the gathered columns.
    gather_at: usize,
    /// Set by the gather when a body's entity differs from the one in `entities`.
    entities_changed: AtomicBool,
    /// The board list's epoch at the last contact stage ([`PairSolver::boards_unchanged`]).
    board_epoch: Option<u32>,
    /// Per body: outside its bound at the last cover, and the list of those.
    stray: Vec<bool>,
    strays: Vec<u32>,
    /// Candidate pairs of strays found at the last cover.
    extra: Vec<(u32, u32)>,
    /// The marbles' common drift since the candidates were found, at the last cover, and
    /// the sums of its blocks of bodies ([`candidates::DRIFT_BLOCK`]).
    drift: Vec3,
    drift_sums: Vec<Vec3>,
    /// A second grid (strays against each other; every marble after collisions).
    scratch_bound: Vec<Vec4>,
    scratch_grid: Grid,
    rows: Vec<Row>,
    /// Collision stage: velocity change and time of the last impact per body.
    dv: Vec<Vec3>,
    event: Vec<f32>,
    /// Impact stage: per body, its free path's end and when a board first changed its
    /// path this substep ([`PairSolver::push_free_end`]).
    free_ends: Vec<FreeEnd>,
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
    /// The bodies' entities when the candidates were found; the gather overwrites those
    /// that changed.
    entities: Vec<Entity>,
    late: Vec<Row>,
    adjacency_start: Vec<u32>,
    adjacency: Vec<u32>,
    queue: Vec<u32>,
    first: Vec<u32>,
    /// Contact stage: the rows' warm-start keys (beside `pair_gs` and `board_gs`), and
    /// the board rows of the projection.
    pair_keys: Vec<(u64, u64)>,
    board_keys: Vec<(u64, u64)>,
    /// Each board row's marble (its place for the warm start: [`warm`]).
    board_places: Vec<u32>,
    board_push: Vec<BoardPush>,
    in_contact: Vec<bool>,
    /// The contact impulses kept for warm starting.
    warm: Warm,
    /// Velocities and inverse masses in the passes.
    vel: Vec<Vel>,
    /// The projection's centres (and what each marble may still move), radii and
    /// inverse masses.
    centres: Vec<project::Centre>,
    sizes: Vec<project::Size>,
    /// The projection's order of the pair rows ([`PairSolver::order_pushes`]): one more
    /// than each marble's latest level, each row's level, where each level ends in
    /// `push_order`, the rows by level (indices of `pair_gs`), and each level's rows by
    /// four.
    push_last: Vec<u32>,
    push_level: Vec<u32>,
    push_end: Vec<u32>,
    push_order: Vec<u32>,
    push_blocks: Vec<project::PushBlock>,
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
    changed: Vec<bool>,
    /// Marble count the broad phase's buffers were sized for, and the rest (the bodies,
    /// rows and warm-start impulses, sized the first time two marbles may meet).
    reserved_for: usize,
    pile_reserved_for: usize,
    /// Test only: check every late-pair search against re-pairing every marble, and count
    /// the checks by search.
    #[cfg(test)]
    cross_check_late: bool,
    #[cfg(test)]
    cross_checked: [usize; 3],
    /// Test only: never select bodies ([`PairSolver::select_bodies`]), and count the
    /// substeps that did.
    #[cfg(test)]
    never_select: bool,
    #[cfg(test)]
    selections: usize,
    /// Test only: impact stages that found a deep impact among selected bodies.
    #[cfg(test)]
    widened: usize,
}

/// One table's rows of the broad phase's gathered columns ([`PairSolver::gather_table`]).
pub struct Gathered<'a> {
    spheres: &'a mut [Vec4],
    radii: &'a mut [f32],
    paths: &'a mut [Vec3],
    entities: &'a mut [Entity],
    changed: &'a AtomicBool,
}

impl Gathered<'_> {
    /// How many rows.
    #[inline]
    pub fn len(&self) -> usize {
        self.spheres.len()
    }

    /// True when there are none.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.spheres.is_empty()
    }

    /// The first `mid` rows and the rest.
    #[inline]
    pub fn split_at(self, mid: usize) -> (Self, Self) {
        let (s0, s1) = self.spheres.split_at_mut(mid);
        let (r0, r1) = self.radii.split_at_mut(mid);
        let (p0, p1) = self.paths.split_at_mut(mid);
        let (e0, e1) = self.entities.split_at_mut(mid);
        let head = Gathered {
            spheres: s0,
            radii: r0,
            paths: p0,
            entities: e0,
            changed: self.changed,
        };
        let tail = Gathered {
            spheres: s1,
            radii: r1,
            paths: p1,
            entities: e1,
            changed: self.changed,
        };
        (head, tail)
    }

    /// Writes the rows of the impact stage: their entities, and each row's sphere
    /// (centre, radius) and radius. An entity that differs from the one the candidates
    /// were found for is noted, and the candidates are then found afresh.
    #[inline]
    pub fn write(mut self, entities: &[Entity], rows: impl Iterator<Item = (Vec4, f32)>) {
        self.note_entities(entities);
        for ((s, r), (sphere, radius)) in
            self.spheres.iter_mut().zip(self.radii.iter_mut()).zip(rows)
        {
            (*s, *r) = (sphere, radius);
        }
    }

    /// [`Gathered::write`] for the contact stage, with each row's free displacement over
    /// the substep, kept for its body.
    #[inline]
    pub fn write_with_paths(
        mut self,
        entities: &[Entity],
        rows: impl Iterator<Item = (Vec4, f32, Vec3)>,
    ) {
        self.note_entities(entities);
        let out = self
            .spheres
            .iter_mut()
            .zip(self.radii.iter_mut())
            .zip(self.paths.iter_mut());
        for (((s, r), d), (sphere, radius, path)) in out.zip(rows) {
            (*s, *r, *d) = (sphere, radius, path);
        }
    }

    #[inline]
    fn note_entities(&mut self, entities: &[Entity]) {
        debug_assert_eq!(entities.len(), self.entities.len());
        if self.entities != entities {
            self.entities.copy_from_slice(entities);
            self.changed.store(true, Ordering::Relaxed);
        }
    }
}

impl PairSolver {
    /// Each stage starts with the broad phase on one sphere per marble, gathered before
    /// the bodies are: [`PairSolver::begin`], then [`PairSolver::gather_table`] for every
    /// table of marbles, in the order their bodies will have, each table's rows writing
    /// their spheres there, then [`PairSolver::cover_gathered`]. A substep in which no
    /// two marbles can meet (marbles spread over a board) ends there, without building
    /// the bodies. `n` is the number of marbles; `out` (the stage's records) is only
    /// sized.
    pub fn begin(&mut self, n: usize, out: &mut MarbleContacts) {
        if n > self.reserved_for {
            self.reserve(n);
        }
        // The records are the pile's too (see `reserve_pile`), sized once it is.
        if self.pile_reserved_for >= n && out.list.capacity() < 4 * n + 64 {
            out.list.reserve(4 * n + 64 - out.list.len());
        }
        // The gathered columns keep their length while the number of marbles does: every
        // row is overwritten, so a substep pays no clearing.
        self.spheres.resize(n, Vec4::ZERO);
        self.radii.resize(n, 0.0);
        self.paths.resize(n, Vec3::ZERO);
        let kept = self.entities.len() == n;
        self.entities.resize(n, Entity::PLACEHOLDER);
        self.entities_changed.store(!kept, Ordering::Relaxed);
        self.gather_at = 0;
    }

    /// Phase 1, one table of marbles at a time (in the order their bodies will have):
    /// where the table's rows put their spheres, radii and (the contact stage) free
    /// displacements, to be written by [`Gathered::write`] or
    /// [`Gathered::write_with_paths`] over the rows in order or in chunks
    /// ([`Gathered::split_at`]).
    pub fn gather_table(&mut self, len: usize) -> Gathered<'_> {
        let rows = self.gather_at..self.gather_at + len;
        self.gather_at = rows.end;
        Gathered {
            spheres: &mut self.spheres[rows.clone()],
            radii: &mut self.radii[rows.clone()],
            paths: &mut self.paths[rows.clone()],
            entities: &mut self.entities[rows],
            changed: &self.entities_changed,
        }
    }

    /// Phase 2: forgets the last substep's bodies.
    pub fn clear_bodies(&mut self) {
        let n = self.spheres.len();
        debug_assert_eq!(self.gather_at, n, "every marble's sphere was gathered");
        if n > self.pile_reserved_for {
            self.reserve_pile(n);
        }
        self.bodies.clear();
        self.free_ends.clear();
    }

    /// Phase 3 of the impact stage, once deep impacts were found, for each body in order: its
    /// free path over the substep ends at `x` with velocity `v` (where it would be had no
    /// board touched it), and the first board event of its substep (a collision, or a
    /// landing, after its start) was at `after` s (`f32::INFINITY`: none). A marble that
    /// collides with another before `after` never took the path the board response gave it
    /// from then on; the cascade puts it back on its free path first, and the late search
    /// finds what boards its new path meets.
    #[inline]
    pub fn push_free_end(&mut self, after: f32, x: Vec3, v: Vec3) {
        self.free_ends.push(FreeEnd { after, x, v });
    }

    /// Phase 2: the next marble, in the order of its sphere.
    #[inline]
    pub fn push_body(&mut self, body: Body) {
        self.bodies.push(body);
    }

    /// Phase 2 of the contact stage: the next marble, its [`Body::d`] the free path
    /// gathered with its sphere ([`Gathered::write_with_paths`]).
    #[inline]
    pub fn push_body_on_free_path(&mut self, mut body: Body) {
        body.d = self.paths[self.marble_of(self.bodies.len())];
        self.bodies.push(body);
    }

    /// Phase 2: the marbles to push bodies for, in order, after
    /// [`PairSolver::select_bodies`] (`None`: every marble).
    #[inline]
    pub fn selected(&self) -> Option<&[u32]> {
        self.compact.then_some(self.selected.as_slice())
    }

    /// How many bodies phase 2 pushes: the marbles [`selected`](Self::selected), or every
    /// marble.
    #[inline]
    pub fn chosen(&self) -> usize {
        if self.compact {
            self.selected.len()
        } else {
            self.spheres.len()
        }
    }

    /// The index among all marbles of body `k`'s marble.
    #[inline]
    pub fn marble_of(&self, k: usize) -> usize {
        if self.compact {
            self.selected[k] as usize
        } else {
            k
        }
    }

    /// Body `k`, as the stage left it.
    #[inline]
    pub fn body(&self, k: usize) -> &Body {
        &self.bodies[k]
    }

    /// Body `k` if the stage changed its state (position, velocity, acceleration or spin),
    /// to be written back to its marble.
    #[inline]
    pub fn changed_body(&self, k: usize) -> Option<&Body> {
        self.changed[k].then(|| &self.bodies[k])
    }

    /// Whether body `k` is in a pair row of the contact stage, so that the passes need its
    /// board contacts (after [`PairSolver::find_touching`]).
    #[inline]
    pub fn in_rows(&self, k: usize) -> bool {
        self.in_contact[k]
    }

    /// Phase 3: forgets the last substep's board contacts.
    pub fn begin_board_touches(&mut self) {
        self.board_touches.clear();
        self.touch_start.clear();
    }

    /// Phase 3: the board contacts pushed from here on belong to the next body (called
    /// once per body, in body order, whether or not it has any).
    #[inline]
    pub fn next_body_touches(&mut self) {
        self.touch_start.push(self.board_touches.len() as u32);
    }

    /// Phase 3: a board contact of the current body.
    #[inline]
    pub fn push_board_touch(&mut self, touch: BoardTouch) {
        self.board_touches.push(touch);
    }

    /// Phase 3: every body's board contacts are in.
    pub fn end_board_touches(&mut self) {
        self.touch_start.push(self.board_touches.len() as u32);
        debug_assert_eq!(self.touch_start.len(), self.bodies.len() + 1);
    }

    /// The broad phase on the gathered spheres (module docs, step 1); whether any two
    /// marbles can meet. With `parallel` (and the `parallel` feature), its passes over
    /// the marbles, and the narrow phases' over the candidate pairs that follow, run in
    /// chunks on the task pool, with the same bits.
    pub fn cover_gathered(&mut self, parallel: bool) -> bool {
        self.on_pool = parallel;
        debug_assert_eq!(
            self.gather_at,
            self.spheres.len(),
            "every sphere was gathered"
        );
        self.cover_spheres(parallel);
        !(self.candidates.is_empty() && self.extra.is_empty())
    }

    /// Drops the contact impulses kept for warm starting (no marble touches another).
    pub fn forget_contacts(&mut self) {
        self.warm.clear();
    }

    /// Marble collisions are off: the next contact stage keeps no impulse from before and
    /// drops the marbles' recorded board contacts ([`PairSolver::boards_unchanged`] is then
    /// false).
    pub fn pause(&mut self) {
        self.board_epoch = None;
    }

    /// Whether the board list is the one of the last call (its
    /// [`epoch`](crate::board_contact::BoardCache::epoch)): the marbles' recorded board
    /// contacts name their pieces by place in that list. When it has changed (a board
    /// added, removed or given another shape), the kept impulses are dropped, board rows'
    /// and pairs' alike, and the contact stage drops the recorded board contacts
    /// (`systems::pairs::forget_stale_contacts`).
    pub fn boards_unchanged(&mut self, epoch: u32) -> bool {
        let same = self.board_epoch == Some(epoch);
        if !same {
            self.board_epoch = Some(epoch);
            self.warm.clear();
        }
        same
    }

    /// Copies into `store` the contact impulses kept for warm starting of the marbles whose
    /// entity bits are in `sorted` (ascending), which fall asleep ([`crate::sleep`]): a
    /// pair's key starts with its smaller entity, and a marble falls asleep with every
    /// marble it touches. The store holds them at one substep length, the last solve's
    /// (those stowed at another are rescaled to it: [`Warm::scale`]).
    pub(crate) fn stow_impulses(&self, sorted: &[u64], store: &mut StowedImpulses) {
        let h = self.warm.h();
        let scale = warm_scale(store.h, h);
        if scale != 1.0 && h != 0.0 {
            store.impulses.values_mut().for_each(|l| *l *= scale);
        }
        store.h = h;
        for (key, lambda) in self.warm.iter() {
            if sorted.binary_search(&key.0).is_ok() {
                store.impulses.insert(key, lambda);
            }
        }
    }

    /// Moves back from `store` the impulses of the marbles in `sorted` (ascending), which
    /// wake, so that their first substep is warm started as if they had not slept (at the
    /// kept impulses' substep length, should it have changed since they were stowed).
    pub(crate) fn restore_impulses(&mut self, sorted: &[u64], store: &mut StowedImpulses) {
        let warm = &mut self.warm;
        let scale = match warm.h() {
            0.0 => 1.0,
            h => warm_scale(store.h, h),
        };
        store.impulses.retain(|key, lambda| {
            let woken = sorted.binary_search(&key.0).is_ok();
            if woken {
                warm.restore(*key, *lambda * scale);
            }
            !woken
        });
    }

    /// The contact stage's sphere: around the marble's free path over the substep (its
    /// displacement `d` from `x`, along the boards it rests on), with a margin for the
    /// contact forces' change of path and the touching tolerance.
    #[inline]
    pub fn contact_sphere(p: &PairParams, x: Vec3, d: Vec3, r: f32) -> Vec4 {
        let tol = crate::board_contact::touch_tolerance(p.tolerance, r, x);
        (x + 0.5 * d).extend(r * (1.0 + BOUND_MARGIN) + 0.5 * d.length() + tol)
    }

    /// The impact stage's sphere: around the straight path from `x0` to `x` and the
    /// touching tolerance.
    #[inline]
    pub fn impact_sphere(p: &PairParams, x0: Vec3, x: Vec3, r: f32) -> Vec4 {
        let tol = crate::board_contact::touch_tolerance(p.tolerance, r, x);
        (0.5 * (x0 + x)).extend(r + 0.5 * (x - x0).length() + tol)
    }

    /// The contact stage, before integration (module docs, steps 1–2), after the broad
    /// phase on [`PairSolver::contact_sphere`]s, on the bodies at the
    /// substep's start (`x`, `v`, `a`, `d` set; `x0 = x`, `v0 = v`): finds the touching
    /// pairs, keeps the candidate pairs for [`PairSolver::find_impacts`], and returns
    /// whether any pair touches; then [`PairSolver::solve_touching`] needs the board
    /// contacts.
    pub fn find_touching(&mut self, p: &PairParams) -> bool {
        let n = self.bodies.len();
        self.check_bodies();
        self.changed.clear();
        self.changed.resize(n, false);
        // 2. The touching pairs, and the pairs that could close their gap this substep.
        self.scan_rows(|bodies, at, (i, j), rows| {
            if let Some(row) = narrow(bodies, i, j, p) {
                if row.kind == Found::Start {
                    rows.push(Row { at, ..row });
                }
            } else if let Some(row) = near_row(bodies, i, j, p) {
                rows.push(Row { at, ..row });
            }
        });
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
    /// the board contacts (the previous substep's): collisions
    /// of touching pairs become velocity changes at the start, contacts become forces added
    /// to `a`, overlaps are projected out of `x`. Records the touching pairs in `out`.
    pub fn solve_touching(&mut self, p: &PairParams, out: &mut MarbleContacts) {
        // 3. Collisions of touching pairs: velocity changes at the start.
        self.collide(p, false);
        // Friction between touching marbles that spin, capped by the pair rows' warm-start
        // impulses.
        self.pair_rows(p);
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

    /// The impact stage, after the marble–board response (module docs), on the bodies
    /// (every marble, or those [`PairSolver::select_bodies`] chose) with `x0`, `v0` at the
    /// substep's start and `x`, `v` at its end: whether any pair met during the substep
    /// deeply enough to collide now. Then [`PairSolver::select_every_marble_for_impacts`]
    /// and [`PairSolver::find_impacts`].
    pub fn any_deep_impact(&mut self, p: &PairParams) -> bool {
        self.check_bodies();
        // Only the pairs that moved far enough apart from each other to leave a deep
        // overlap ([`may_impact_deeply`]) go through the narrow phase; most substeps of a
        // pile or of marbles rolling together have none and stop here.
        let bodies = &self.bodies;
        let slack = rounding_slack(bodies);
        let deep = |(i, j): (u32, u32)| {
            may_impact_deeply(bodies, i, j, slack)
                && narrow(bodies, i, j, p).is_some_and(|row| deep_impact(bodies, &row))
        };
        let strays = (self.stray.as_slice(), self.strays.as_slice());
        let local = self.compact.then_some(self.local.as_slice());
        any_body_pair(
            &self.candidates,
            &self.extra,
            strays,
            local,
            self.on_pool,
            deep,
        )
    }

    /// After [`PairSolver::any_deep_impact`] found one: the collisions that follow may
    /// reach any marble, so every marble becomes a body. Returns whether the bodies were
    /// a selection, to be gathered again (phase 2) before [`PairSolver::find_impacts`].
    pub fn select_every_marble_for_impacts(&mut self) -> bool {
        let compact = self.compact;
        #[cfg(test)]
        {
            self.widened += usize::from(compact);
        }
        self.select_every_marble();
        compact
    }

    /// The impact stage's rows, after [`PairSolver::any_deep_impact`] found a deep impact,
    /// on every marble's body: the pairs that met during the substep (the deep impacts
    /// and the shallow ones, which stay for the next substep's contact stage) and those
    /// touching at the start. Then [`PairSolver::resolve_impacts`] needs the board
    /// contacts.
    pub fn find_impacts(&mut self, p: &PairParams) {
        let n = self.bodies.len();
        debug_assert!(!self.compact);
        self.check_bodies();
        self.changed.clear();
        self.changed.resize(n, false);
        self.scan_rows(|bodies, _, (i, j), rows| {
            if let Some(mut row) = narrow(bodies, i, j, p) {
                if row.kind == Found::Impact && shallow(bodies, &row) {
                    // An impact that leaves the pair overlapping by less than a small share
                    // of the radius is left to the next substep's contact stage, which
                    // judges it on the same closing speed; resolving it here would move a
                    // settled pile for nothing.
                    row.limit = f32::INFINITY;
                }
                if row.kind != Found::End {
                    rows.push(row);
                }
            }
        });
        debug_assert!(
            self.rows
                .iter()
                .any(|row| row.kind == Found::Impact && row.limit != f32::INFINITY && row.u < 0.0),
            "the search before found a deep impact"
        );
    }

    /// Makes `rows` what `each` finds of the candidate pairs (in the bodies' indices, with
    /// each pair's place in their order), in their order: with `on_pool`, in chunks on the
    /// task pool ([`scan_body_pairs`]).
    fn scan_rows(&mut self, each: impl Fn(&[Body], u32, (u32, u32), &mut Vec<Row>) + Sync) {
        self.rows.clear();
        let local = self.compact.then_some(self.local.as_slice());
        let strays = (self.stray.as_slice(), self.strays.as_slice());
        let bodies = self.bodies.as_slice();
        scan_body_pairs(
            &self.candidates,
            &self.extra,
            strays,
            local,
            self.on_pool,
            &mut self.row_chunks,
            &mut self.rows,
            |at, pair, rows| each(bodies, at, pair, rows),
        );
    }

    /// Debug builds: the bodies are the marbles the broad phase chose.
    fn check_bodies(&self) {
        debug_assert_eq!(
            self.bodies.len(),
            self.chosen(),
            "a body for every marble chosen"
        );
    }

    /// The rest of the impact stage, after [`PairSolver::find_impacts`] found impacts,
    /// with the board contacts (this substep's): the pairs
    /// collide at their time of impact, exactly, and pass the impact on. Records the
    /// impacts in `out`. `near` gives a marble's [`NearPieces`] list by its entity, where
    /// it has one, for the searches of the boards that the marbles sent off their paths
    /// run (the same answers as searching the boards, where the list covers them).
    pub fn resolve_impacts(
        &mut self,
        p: &PairParams,
        boards: &[BoardSnapshot],
        near: &NearOf<'_>,
        out: &mut MarbleContacts,
    ) {
        if self.collide(p, true) {
            // Collisions moved marbles off their free paths; what they run into there,
            // boards and marbles, is found and resolved in a few rounds.
            let mut settled = false;
            for _ in 0..LATE_ROUNDS {
                self.onto_boards(p, boards, near);
                if !self.late_overlaps(p) {
                    settled = true;
                    break;
                }
            }
            if !settled {
                // The last round's collisions may have sent marbles into boards.
                self.onto_boards(p, boards, near);
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
        // The lower entity first, whatever the bodies' order (tables change order when
        // marbles gain or lose components, or others are despawned).
        let (first, second, normal) = if a.entity <= b.entity {
            (a.entity, b.entity, row.n)
        } else {
            (b.entity, a.entity, -row.n)
        };
        MarbleContact {
            a: first,
            b: second,
            normal,
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

    /// Sizes the broad phase's buffers for `n` marbles (every substep needs them).
    fn reserve(&mut self, n: usize) {
        self.bound.reserve(n);
        self.spheres.reserve(n);
        self.stray.reserve(n);
        self.radii.reserve(n);
        self.paths.reserve(n);
        self.drift_sums.reserve(n.div_ceil(candidates::DRIFT_BLOCK));
        self.strays.reserve(n);
        self.entities.reserve(n);
        self.local.reserve(n);
        self.selected.reserve(n / candidates::SELECT_SHARE + 2);
        self.grid.reserve(n);
        self.reserved_for = n;
    }

    /// Sizes every other buffer for `n` marbles in a dense pile (a marble touches at most
    /// 12 others; rows count each pair once), the first time two of them may meet (and the
    /// stage's records, [`MarbleContacts`], at the next stage's start): so
    /// that marbles spread over a board (which never do) hold none of it, and stepping
    /// allocates nothing once the number of marbles stops growing.
    fn reserve_pile(&mut self, n: usize) {
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
        self.late.reserve(n);
        self.first.reserve(n);
        self.adjacency.reserve(2 * pairs);
        self.queue.reserve(pairs);
        self.pair_keys.reserve(pairs);
        self.board_keys.reserve(touches);
        self.board_places.reserve(touches);
        self.board_push.reserve(touches);
        self.pair_gs.reserve(pairs);
        self.pair_pass.reserve(pairs);
        self.pair_slot.reserve(pairs);
        self.blocks.reserve(pairs / 4);
        self.block_first.reserve(pairs / 4);
        self.spans.reserve(COLOURS);
        self.colours.reserve(n);
        self.board_gs.reserve(touches);
        self.vel.reserve(n);
        self.centres.reserve(n);
        self.sizes.reserve(n);
        self.push_last.reserve(n);
        self.push_level.reserve(pairs);
        // (At most a level a row, a level's end kept for each.)
        self.push_end.reserve(pairs + 1);
        self.push_order.reserve(pairs);
        self.push_blocks.reserve(pairs / 4);
        self.warm.reserve(pairs, touches);
        self.board_touches.reserve(touches);
        self.touch_start.reserve(n + 1);
        self.adjacency_start.reserve(n + 1);
        self.dv.reserve(n);
        self.event.reserve(n);
        self.free_ends.reserve(n);
        self.in_contact.reserve(n);
        self.extra.reserve(pairs);
        self.scratch_bound.reserve(n);
        self.scratch_grid.reserve(n);
        self.pile_reserved_for = n;
    }
}

#[cfg(test)]
mod tests;
