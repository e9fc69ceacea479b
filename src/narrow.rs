//! Marble–board narrow phase: which board pieces a marble touches, and when along its path
//! it first reaches a piece it does not touch yet.
//!
//! # Touching
//! A marble of radius `r` centred at `x` touches a convex piece when the signed distance
//! from `x` to the piece's surface is at most `r + tol` (`tol`: the touching tolerance,
//! [`StepConfig::contact_tolerance`](crate::config::StepConfig) × r plus the f32 resolution
//! of `x`). A marble can touch several pieces; the [`TouchList`] filter keeps only those
//! that constrain it independently: a candidate whose closest point lies on or behind the
//! tangent plane of a nearer accepted contact is implied by that contact (a marble pushed
//! out of the nearer plane is also out of a point behind it). That removes the spurious
//! edge normals of coplanar seams between boards or triangles and of convex ridges, the
//! "ghost bumps" other engines suffer on meshes, while a concave corner (floor and wall)
//! keeps both contacts.
//!
//! # Time of impact
//! Continuous collision asks, for each piece the marble does not yet touch, the first time
//! `τ` in the substep at which `d(τ) = dist(x(τ), piece(τ)) − r` falls within the touching
//! tolerance, where `x(τ)` is the marble's path (the parabola of constant acceleration every
//! integrator follows, see [`Integrator`](crate::config::Integrator)) and the piece moves
//! with its board (translation and rotation). It uses **conservative advancement**: if
//! `|ḋ| ≤ L` on the interval, no root lies before `τ + (d − tol/4)/L`, so stepping by that
//! amount never passes an impact; the search stops within `tol/2`, so that the touch
//! gathered at the impact with the full tolerance includes the piece despite rounding. The
//! bound `L` is the marble's speed bound along its path; for a moving board, the marble's
//! speed relative to the board's material point under it (small for marbles riding a
//! turning board); and where every centre the marble can reach has its closest point on
//! one flat face (a plane, or a box face), only the normal part of that relative motion, so
//! a marble sliding just above a surface does not make the advancement crawl. A head-on
//! approach converges in one or two iterations; grazing approaches converge geometrically.
//! Because each step is safe, a marble at any speed never passes through a board, however
//! thin.
//!
//! # Near pieces
//! Most marbles spend most substeps far from everything but the piece they roll on. Each
//! marble keeps a [`NearPieces`] list (a Verlet list, or "skin", for board pieces): the
//! pieces of one board within a few radii of where the list was built, in the board's
//! frame. While the marble stays within the list's reach of that spot of the board, its
//! touches and impacts need only the listed pieces — the same answers, bit for bit, as a
//! search of the board (the pieces keep the search's order) — and detection rebuilds the
//! list when the marble leaves it. When the list holds one piece of a still board and
//! nothing else is within reach of the marble's substep, it gives the touch directly
//! ([`NearPieces::lone_touch`]; in closed form over a flat face), and a marble resting or
//! sliding there is resolved in closed form ([`crate::response::resolve_resting`]; a
//! spinning one by the event loop on that one touch): no search at all in the commonest
//! case.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;

use crate::geometry::{BoardGeometry, Piece, PieceId, transform_aabb};

/// Conservative-advancement iterations per piece before giving up on convergence (the
/// marble is then advanced to the last safe time and the search resumes from there).
const MAX_ADVANCE_ITERATIONS: u32 = 64;

/// A board as seen by one substep: its pose at the substep's start and its motion.
#[derive(Clone, Debug)]
pub struct BoardSnapshot {
    /// The board entity.
    pub entity: Entity,
    /// Its shape.
    pub geometry: Arc<BoardGeometry>,
    /// Origin at the substep's start, world.
    pub position: Vec3,
    /// Orientation at the substep's start.
    pub rotation: Quat,
    /// Linear velocity, m/s.
    pub velocity: Vec3,
    /// Angular velocity about `position`, rad/s, world.
    pub angular_velocity: Vec3,
    /// Restitution.
    pub restitution: f32,
    /// Friction.
    pub friction: f32,
    /// Rolling resistance coefficient (used when rolling is on).
    pub rolling_resistance: f32,
    /// Spin damping coefficient (used when rolling is on).
    pub spin_damping: f32,
    /// World bounds swept over the substep; `None` when unbounded (planes).
    pub swept_aabb: Option<Aabb>,
    /// Farthest distance of the board's bounds from its origin (for rotation bounds).
    pub reach: f32,
    /// Changes whenever the board's pose at a substep's start differs from the last
    /// substep's (set by the prepare stage).
    pub pose_version: u32,
    /// The substep's length and [`BoardSnapshot::pose_at`] its start and end, computed
    /// once for a turning board ([`BoardSnapshot::with_poses`]): every marble on it asks
    /// for them.
    pub poses: Option<(f32, (Vec3, Quat), (Vec3, Quat))>,
}

impl BoardSnapshot {
    /// True when the board moves or turns.
    #[inline]
    pub fn is_moving(&self) -> bool {
        self.velocity != Vec3::ZERO || self.angular_velocity != Vec3::ZERO
    }

    /// Pose at time `t` after the substep's start.
    #[inline]
    pub fn pose_at(&self, t: f32) -> (Vec3, Quat) {
        if let Some((h, start, end)) = self.poses {
            if t == 0.0 {
                return start;
            }
            if t == h {
                return end;
            }
        }
        self.pose_computed(t)
    }

    /// The snapshot with its poses at the start and end of a substep of length `h`
    /// computed once, when it turns (they cost a sine and a normalisation each).
    pub fn with_poses(mut self, h: f32) -> Self {
        if self.angular_velocity != Vec3::ZERO {
            self.poses = Some((h, self.pose_computed(0.0), self.pose_computed(h)));
        }
        self
    }

    /// [`BoardSnapshot::pose_at`], computed.
    fn pose_computed(&self, t: f32) -> (Vec3, Quat) {
        if self.angular_velocity == Vec3::ZERO {
            (self.position + self.velocity * t, self.rotation)
        } else {
            (
                self.position + self.velocity * t,
                (Quat::from_scaled_axis(self.angular_velocity * t) * self.rotation).normalize(),
            )
        }
    }

    /// Normal component (along `n`) of the acceleration of the board's material point at
    /// world point `p`, time `t`: the centripetal `ω × (ω × (p − c))` of its turning.
    #[inline]
    pub fn surface_accel(&self, t: f32, p: Vec3, n: Vec3) -> f32 {
        if self.angular_velocity == Vec3::ZERO {
            return 0.0;
        }
        let w = self.angular_velocity;
        w.cross(w.cross(p - (self.position + self.velocity * t)))
            .dot(n)
    }

    /// Velocity of the board's material point at world point `p`, time `t`.
    #[inline]
    pub fn point_velocity(&self, t: f32, p: Vec3) -> Vec3 {
        self.velocity
            + self
                .angular_velocity
                .cross(p - (self.position + self.velocity * t))
    }
}

/// The boards of the current substep, rebuilt by the prepare stage (capacity reused).
#[derive(Resource, Default, Debug)]
pub struct BoardCache {
    /// One snapshot per board, in a stable order (by entity).
    pub boards: Vec<BoardSnapshot>,
    /// Substep duration these snapshots were prepared for, s.
    pub h: f32,
    /// Changes whenever the board list changes other than by motion (a board added,
    /// removed or given another shape): [`NearPieces`] lists of an older epoch are stale.
    pub epoch: u32,
    /// Each board's entity, shape, pose and pose version at the last substep.
    pub(crate) layout: Vec<(Entity, usize, Vec3, Quat, u32)>,
    /// The last pose version handed out.
    pose_versions: u32,
}

impl BoardCache {
    /// Moves to a new [`BoardCache::epoch`] if the boards' entities or shapes differ from
    /// the last call's, and to a new [`BoardSnapshot::pose_version`] each board whose pose
    /// changed (called by the prepare stage after filling `boards`).
    pub(crate) fn update_epoch(&mut self) {
        let same = self.layout.len() == self.boards.len()
            && self
                .layout
                .iter()
                .zip(&self.boards)
                .all(|(l, b)| (l.0, l.1) == (b.entity, Arc::as_ptr(&b.geometry) as usize));
        if !same {
            self.epoch = self.epoch.wrapping_add(1);
            self.layout.clear();
            self.layout.extend(self.boards.iter().map(|b| {
                (
                    b.entity,
                    Arc::as_ptr(&b.geometry) as usize,
                    b.position,
                    b.rotation,
                    0,
                )
            }));
        }
        for (l, b) in self.layout.iter_mut().zip(self.boards.iter_mut()) {
            if (l.2, l.3) != (b.position, b.rotation) {
                self.pose_versions = self.pose_versions.wrapping_add(1);
                (l.2, l.3, l.4) = (b.position, b.rotation, self.pose_versions);
            }
            b.pose_version = l.4;
        }
    }
}

/// Most pieces a [`NearPieces`] list holds.
pub const NEAR_MAX: usize = 5;

/// The pieces of one board near a marble, so that its queries visit those instead of
/// searching the board: a Verlet list (a "skin") for board pieces.
///
/// Built around an *anchor*, the marble's centre in the board's frame, it holds every piece
/// whose distance from the anchor, minus the radius, is below `reach`. Any piece within
/// `g` of a centre `y` (board frame) is then within `g + |y − anchor|` of the anchor, so a
/// query whose centres stay within `reach − g` of the anchor needs only the listed pieces
/// ([`NearPieces::covers`]). The test is made in the board's frame at the query's time, so a
/// marble riding a moving or turning board keeps its list as long as it stays near the
/// same spot of the board. Queries the list does not cover search the board as before, and
/// detection rebuilds a list that no longer covers the substep's start. The pieces are kept
/// in the order a search visits them, so a query gives the same bits either way.
#[derive(Component, Clone, Copy, Debug)]
pub struct NearPieces {
    pieces: [PieceId; NEAR_MAX],
    len: u8,
    /// Index of the board in [`BoardCache::boards`]; `u32::MAX`: no list.
    board: u32,
    /// The [`BoardCache::epoch`] it was built in.
    epoch: u32,
    /// The radius it was built for.
    radius: f32,
    /// Centre when built, board frame.
    anchor: Vec3,
    /// Every piece of the board closer than this to the anchor (distance minus radius) is
    /// listed.
    reach: f32,
    /// Centre when built, world.
    anchor_world: Vec3,
    /// The board's [`BoardSnapshot::pose_version`] when built: while it is the same, the
    /// board has not moved and the list can be tested in the world frame.
    pose_version: u32,
    /// For a lone piece of a still board, flat under every centre the list covers: its
    /// normal (world; zero otherwise) and the anchor's gap to it.
    face_normal: Vec3,
    face_gap: f32,
    /// Each listed piece's gap from the anchor (distance minus radius) when built.
    gaps: [f32; NEAR_MAX],
}

impl Default for NearPieces {
    fn default() -> Self {
        NearPieces {
            pieces: [PieceId::NONE; NEAR_MAX],
            len: 0,
            board: u32::MAX,
            epoch: 0,
            radius: 0.0,
            anchor: Vec3::ZERO,
            reach: 0.0,
            anchor_world: Vec3::ZERO,
            pose_version: 0,
            face_normal: Vec3::ZERO,
            face_gap: 0.0,
            gaps: [f32::INFINITY; NEAR_MAX],
        }
    }
}

impl NearPieces {
    /// The listed pieces.
    #[inline]
    pub fn pieces(&self) -> &[PieceId] {
        &self.pieces[..self.len as usize]
    }

    /// Calls `f(part, sub, piece)` for every listed piece of `geometry` (the list's
    /// board), in the order a search visits them.
    #[inline]
    fn visit(&self, geometry: &BoardGeometry, mut f: impl FnMut(usize, u32, &Piece)) {
        for id in self.pieces() {
            f(id.part(), id.sub(), &geometry.piece(id.part(), id.sub()));
        }
    }

    /// The list for board `board`, if this is it.
    #[inline]
    fn of(near: Option<&NearPieces>, board: usize) -> Option<&NearPieces> {
        near.filter(|l| l.board as usize == board)
    }

    /// True when every piece within `gap` of some centre within `spread` of `centre` (board
    /// frame) is listed.
    #[inline]
    pub fn covers(&self, centre: Vec3, spread: f32, gap: f32) -> bool {
        (centre - self.anchor).length() + spread + gap < self.reach
    }

    /// True when the list was built for these boards and this radius and covers the
    /// centres within `spread` of `x` (world, at the substep's start) for touches within
    /// `tol`.
    pub fn is_fresh(&self, cache: &BoardCache, x: Vec3, r: f32, spread: f32, tol: f32) -> bool {
        if self.board == u32::MAX || self.epoch != cache.epoch || self.radius != r {
            return false;
        }
        let Some(b) = cache.boards.get(self.board as usize) else {
            return false;
        };
        if b.pose_version == self.pose_version {
            // The board is where it was: its frame moved with it.
            return (x - self.anchor_world).length() + spread + tol < self.reach;
        }
        self.covers(b.rotation.conjugate() * (x - b.position), spread, tol)
    }

    /// The one touch [`gather`] would find at the substep's start for a marble of radius
    /// `r` at `x` (world) moving at `v` under acceleration `a` (and friction, when it
    /// `spins`), when the list can vouch that
    /// it is the only piece within reach of the marble's whole substep of length `h` on it:
    /// the list holds one piece, of a board that does not move, and covers every centre
    /// the marble can reach sliding on the piece (its speed, and the acceleration the piece
    /// leaves it, over `h`), and no other board comes within reach. On a moving board (the
    /// scene's only board) the list vouches only that this is the one touch at the start:
    /// the event loop resolves it, its searches using the list where it covers. `None`
    /// when the list cannot tell or the piece is farther than `tol`.
    #[expect(
        clippy::too_many_arguments,
        reason = "a hot kernel taking plain values"
    )]
    pub fn lone_touch(
        &self,
        boards: &[BoardSnapshot],
        x: Vec3,
        v: Vec3,
        a: Vec3,
        h: f32,
        r: f32,
        tol: f32,
        material: &Material,
        spins: bool,
    ) -> Option<Touch> {
        let [id] = *self.pieces() else {
            return None;
        };
        let bi = self.board as usize;
        let b = boards.get(bi)?;
        let moving = b.is_moving();
        if moving && boards.len() > 1 {
            return None;
        }
        let touch =
            if !moving && self.face_normal != Vec3::ZERO && b.pose_version == self.pose_version {
                // A flat face where it was: the distance is affine in the centre.
                let d = x - self.anchor_world;
                if d.length() + tol >= self.reach {
                    return None;
                }
                let n = self.face_normal;
                let gap = self.face_gap + n.dot(d);
                if gap.abs() > tol {
                    return None;
                }
                Touch {
                    piece: id,
                    point: x - (r + gap) * n,
                    normal: n,
                    gap,
                    board_velocity: Vec3::ZERO,
                    surface_accel: 0.0,
                    board_spin: Vec3::ZERO,
                    material: material.combine(b),
                    convex: true,
                }
            } else {
                // As `gather` computes it (at the board's pose at the start, bit for bit).
                let (c, q) = b.pose_at(0.0);
                let inv = q.conjugate();
                let local = inv * (x - c);
                if !self.covers(local, 0.0, tol) {
                    return None;
                }
                let piece = b.geometry.piece(id.part(), id.sub());
                let p = b.geometry.proximity(id.part(), &piece, local, inv * -v);
                let gap = p.distance - r;
                if gap > tol {
                    return None;
                }
                let point = q * p.point + c;
                let normal = q * p.normal;
                Touch {
                    piece: id,
                    point,
                    normal,
                    gap,
                    board_velocity: b.point_velocity(0.0, point),
                    surface_accel: b.surface_accel(0.0, point, normal),
                    board_spin: b.angular_velocity,
                    material: material.combine(b),
                    convex: piece.is_convex(),
                }
            };
        if moving {
            // The one touch at the start (the list covers the centre, and there is no
            // other board); the event loop does the rest.
            return Some(touch);
        }
        // Where the marble can go: at most its speed, and the acceleration the piece
        // leaves it (none into the piece; friction adds at most μ times the normal force
        // for a marble that spins), over the substep; the list and the other boards must
        // leave nothing within reach of that.
        let n = touch.normal;
        let into = a.dot(n).min(0.0);
        let along = a - into * n;
        let grip = if spins {
            touch.material.friction * -into
        } else {
            0.0
        };
        let spread = (v.length() + 2.0 * (along.length() + grip) * h) * h;
        let clear = if b.pose_version == self.pose_version {
            (x - self.anchor_world).length() + spread + tol < self.reach
        } else {
            self.covers(b.rotation.conjugate() * (x - b.position), spread, tol)
        };
        if !clear {
            return None;
        }
        let reach = r + tol + spread;
        let world = sphere_aabb(x, reach);
        // (With one board, the common case, there are no others: skip the search, whose
        // closure the compiler leaves a call.)
        let others_clear = boards.len() == 1
            || boards.iter().enumerate().all(|(i, o)| {
                if i == bi {
                    return true;
                }
                match &o.swept_aabb {
                    Some(a) => !overlaps(a, &world),
                    // Unbounded (a plane): clear if still and no piece is near.
                    None if !o.is_moving() => {
                        let local = o.rotation.conjugate() * (x - o.position);
                        let mut near = false;
                        o.geometry
                            .for_each_piece(&sphere_aabb(local, reach), |_, _, _| near = true);
                        !near
                    }
                    None => false,
                }
            });
        others_clear.then_some(touch)
    }

    /// Calls `f(piece, point, normal, gap)` (world, at the substep's start) for every
    /// piece, other than those `skip` names, that a marble of radius `r` at `x` (world, at
    /// the substep's start) moving at `v` could reach within a substep of length `h`: one
    /// within `reach` (the marble's own motion) plus how far the piece's board can move
    /// towards it in the substep (its speed plus its turn times the distance, bounded
    /// over the reach). The list's board is read from the list when it covers that reach
    /// (a piece whose gap when the list was built, less how far the marble has moved since
    /// in the board's frame, is out of reach is passed over without a distance query);
    /// every other board, and the list's when it does not cover, is searched. The pair
    /// solver's speculative board rows ([`crate::pairs`]).
    #[expect(clippy::too_many_arguments, reason = "a marble's state, handed over")]
    pub fn within(
        &self,
        cache: &BoardCache,
        x: Vec3,
        v: Vec3,
        r: f32,
        reach: f32,
        h: f32,
        skip: impl Fn(PieceId) -> bool,
        mut f: impl FnMut(PieceId, Vec3, Vec3, f32),
    ) {
        let mut visit =
            |bi: usize, b: &BoardSnapshot, part: usize, sub: u32, piece: &Piece, limit: f32| {
                let id = PieceId::new(bi, part, sub);
                if skip(id) {
                    return;
                }
                let (c, q) = (b.position, b.rotation);
                let inv = q.conjugate();
                let p = b.geometry.proximity(part, piece, inv * (x - c), inv * -v);
                let gap = p.distance - r;
                if gap <= limit {
                    f(id, q * p.point + c, q * p.normal, gap);
                }
            };
        for (bi, b) in cache.boards.iter().enumerate() {
            let turn = b.angular_velocity.length() * ((x - b.position).length() + r + reach);
            let limit = reach + (b.velocity.length() + turn) * h;
            if bi == self.board as usize && self.is_fresh(cache, x, r, 0.0, limit) {
                // A piece's gap is at most how far the marble has moved from where the
                // list was built (in the board's frame) below its gap there.
                let moved = if b.pose_version == self.pose_version {
                    (x - self.anchor_world).length()
                } else {
                    (b.rotation.conjugate() * (x - b.position) - self.anchor).length()
                };
                for (&id, &gap) in self.pieces().iter().zip(&self.gaps) {
                    if gap - moved <= limit {
                        let piece = b.geometry.piece(id.part(), id.sub());
                        visit(bi, b, id.part(), id.sub(), &piece, limit);
                    }
                }
                continue;
            }
            if let Some(a) = &b.swept_aabb
                && !overlaps(a, &sphere_aabb(x, r + limit))
            {
                continue;
            }
            let local = b.rotation.conjugate() * (x - b.position);
            b.geometry
                .for_each_piece(&sphere_aabb(local, r + limit), |part, sub, piece| {
                    visit(bi, b, part, sub, piece, limit)
                });
        }
    }

    /// Rebuilds the list around a marble of radius `r` at `x` (world, the substep's start):
    /// the board with the nearest piece within `tol + skin`, and its pieces within that
    /// reach (the nearest [`NEAR_MAX`] of them, the reach shrunk to exclude the rest; only
    /// the nearest, when the next is beyond half the reach).
    /// Leaves no list when there is no board.
    pub fn rebuild(&mut self, cache: &BoardCache, x: Vec3, r: f32, tol: f32, skin: f32) {
        *self = NearPieces {
            epoch: cache.epoch,
            radius: r,
            ..NearPieces::default()
        };
        let limit = tol + skin;
        let world = sphere_aabb(x, r + limit);
        // The best board so far: its nearest gap, its pieces (visit order, piece, gap)
        // and the smallest gap left out.
        let mut best: Option<(f32, Candidates)> = None;
        for (bi, b) in cache.boards.iter().enumerate() {
            if let Some(a) = &b.swept_aabb
                && !overlaps(a, &world)
            {
                continue;
            }
            let inv = b.rotation.conjugate();
            let local = inv * (x - b.position);
            let mut found = Candidates::new(limit);
            let mut order = 0u32;
            b.geometry
                .for_each_piece(&sphere_aabb(local, r + limit), |part, sub, piece| {
                    let gap = b
                        .geometry
                        .proximity(part, piece, local, Vec3::ZERO)
                        .distance
                        - r;
                    found.offer(order, PieceId::new(bi, part, sub), gap);
                    order += 1;
                });
            let nearest = found.nearest();
            if best.as_ref().is_none_or(|(g, _)| nearest < *g) {
                self.board = bi as u32;
                self.anchor = local;
                self.pose_version = b.pose_version;
                best = Some((nearest, found));
            }
        }
        let Some((_, mut found)) = best else {
            // Every board is out of reach: a list of none of the first board's pieces.
            if let Some(b) = cache.boards.first() {
                self.board = 0;
                self.anchor = b.rotation.conjugate() * (x - b.position);
                self.pose_version = b.pose_version;
                self.anchor_world = x;
                self.reach = limit;
            }
            return;
        };
        found.isolate_nearest();
        found.kept[..found.len].sort_unstable_by_key(|c| c.0);
        for (k, c) in found.kept[..found.len].iter().enumerate() {
            self.pieces[k] = c.1;
            self.gaps[k] = c.2;
        }
        self.len = found.len as u8;
        self.anchor_world = x;
        // A margin for the rounding of the distances the list was built from.
        self.reach = found.excluded
            - 8.0 * f32::EPSILON * (r + found.excluded + self.anchor.abs().max_element());
        let b = &cache.boards[self.board as usize];
        if let [id] = *self.pieces()
            && !b.is_moving()
            && let Some(n) = b
                .geometry
                .flat_face(id.part(), id.sub(), self.anchor, self.reach)
        {
            self.face_normal = b.rotation * n;
            self.face_gap = found.kept[0].2;
        }
    }
}

/// The nearest pieces offered to a [`NearPieces`] build: up to [`NEAR_MAX`] with their
/// gaps, and the smallest gap of those left out (the limit when none was).
struct Candidates {
    kept: [(u32, PieceId, f32); NEAR_MAX],
    len: usize,
    excluded: f32,
    /// The reach asked for.
    limit: f32,
}

impl Candidates {
    fn new(limit: f32) -> Self {
        Candidates {
            kept: [(0, PieceId::NONE, 0.0); NEAR_MAX],
            len: 0,
            excluded: limit,
            limit,
        }
    }

    /// Offers a piece at `gap`: kept if within the limit and among the nearest.
    fn offer(&mut self, order: u32, piece: PieceId, gap: f32) {
        if gap >= self.excluded {
            return;
        }
        if self.len < NEAR_MAX {
            self.kept[self.len] = (order, piece, gap);
            self.len += 1;
            return;
        }
        // Full: the farthest kept one makes way if it is farther.
        let (far, _) = self
            .kept
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.2.total_cmp(&b.1.2))
            .expect("NEAR_MAX > 0");
        if self.kept[far].2 > gap {
            self.excluded = self.excluded.min(self.kept[far].2);
            self.kept[far] = (order, piece, gap);
        } else {
            self.excluded = self.excluded.min(gap);
        }
    }

    /// Keeps only the nearest piece, the reach shrunk to the next one's gap, when that
    /// one is at least half the limit away: a marble on a floor a few radii from a wall
    /// then holds a one-piece list (the closed form of [`NearPieces::lone_touch`] applies
    /// to it) that lasts at least half as far as the full one.
    fn isolate_nearest(&mut self) {
        if self.len < 2 {
            return;
        }
        let kept = &self.kept[..self.len];
        let nearest = (0..kept.len())
            .min_by(|&i, &j| kept[i].2.total_cmp(&kept[j].2))
            .expect("two or more kept");
        let next = (0..kept.len())
            .filter(|&i| i != nearest)
            .map(|i| kept[i].2)
            .fold(f32::INFINITY, f32::min);
        if next >= 0.5 * self.limit {
            self.kept[0] = self.kept[nearest];
            self.len = 1;
            self.excluded = self.excluded.min(next);
        }
    }

    /// The smallest gap offered (infinite when none).
    fn nearest(&self) -> f32 {
        self.kept[..self.len]
            .iter()
            .map(|c| c.2)
            .fold(f32::INFINITY, f32::min)
    }
}

/// A marble touching a board piece at some time in the substep.
#[derive(Clone, Copy, Debug)]
pub struct Touch {
    /// The piece.
    pub piece: PieceId,
    /// Closest point on the piece, world.
    pub point: Vec3,
    /// Unit normal out of the piece towards the marble, world.
    pub normal: Vec3,
    /// Centre-to-surface distance minus radius, m (negative: penetration).
    pub gap: f32,
    /// Board material velocity at `point`.
    pub board_velocity: Vec3,
    /// Normal acceleration the marble needs to stay on a turning board's surface:
    /// `(ω × (ω × (p − c)))·n` of the surface point (zero for boards that do not turn).
    /// The term `−(v − v_b)·(ω × n)` of the turning normal is added where `v` is known.
    pub surface_accel: f32,
    /// The board's angular velocity (zero when it does not turn).
    pub board_spin: Vec3,
    /// Combined material of the pair (averages of the two parties' coefficients).
    pub material: Material,
    /// Whether the piece is convex (it then lies behind its tangent plane at the contact).
    pub convex: bool,
}

/// Contact coefficients of a marble or of a marble–board pair.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Material {
    /// Restitution, [0, 1].
    pub restitution: f32,
    /// Coulomb friction, ≥ 0.
    pub friction: f32,
    /// Rolling resistance, ≥ 0.
    pub rolling_resistance: f32,
    /// Spin damping about the normal, ≥ 0.
    pub spin_damping: f32,
}

impl Material {
    /// A marble's coefficients from its components (rolling resistance and spin damping
    /// are zero where the marble has none).
    #[inline]
    pub fn of_marble(
        restitution: &crate::components::Restitution,
        friction: &crate::components::Friction,
        rolling_resistance: Option<&crate::components::RollingResistance>,
        spin_damping: Option<&crate::components::SpinDamping>,
    ) -> Material {
        Material {
            restitution: restitution.0,
            friction: friction.0,
            rolling_resistance: rolling_resistance.map_or(0.0, |c| c.0),
            spin_damping: spin_damping.map_or(0.0, |c| c.0),
        }
    }

    /// The pair's material: the average of each coefficient (the contract's default rule).
    #[inline]
    pub fn combine(&self, b: &BoardSnapshot) -> Material {
        Material {
            restitution: 0.5 * (self.restitution + b.restitution),
            friction: 0.5 * (self.friction + b.friction),
            rolling_resistance: 0.5 * (self.rolling_resistance + b.rolling_resistance),
            spin_damping: 0.5 * (self.spin_damping + b.spin_damping),
        }
    }
}

/// Most touches considered at once by one marble.
pub const MAX_TOUCHES: usize = 8;

/// A small, allocation-free set of independent touches, nearest first.
#[derive(Clone, Copy, Debug)]
pub struct TouchList {
    items: [Touch; MAX_TOUCHES],
    len: usize,
    /// Candidates within reach that were left out (implied by a nearer touch, or no room).
    dropped: usize,
}

impl Default for TouchList {
    fn default() -> Self {
        TouchList {
            items: [Touch {
                piece: PieceId::NONE,
                point: Vec3::ZERO,
                normal: Vec3::Y,
                gap: 0.0,
                board_velocity: Vec3::ZERO,
                surface_accel: 0.0,
                board_spin: Vec3::ZERO,
                material: Material::default(),
                convex: true,
            }; MAX_TOUCHES],
            len: 0,
            dropped: 0,
        }
    }
}

impl TouchList {
    /// The touches.
    #[inline]
    pub fn as_slice(&self) -> &[Touch] {
        &self.items[..self.len]
    }

    /// True when empty.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Empties the list.
    #[inline]
    pub fn clear(&mut self) {
        self.len = 0;
        self.dropped = 0;
    }

    /// True when every piece within reach is in the list (none was implied by another or
    /// left out for room).
    #[inline]
    pub fn is_complete(&self) -> bool {
        self.dropped == 0
    }

    /// Marks the list complete or not (for a list rebuilt from recorded contacts).
    #[inline]
    pub fn set_complete(&mut self, complete: bool) {
        self.dropped = usize::from(!complete);
    }

    /// True when `piece` is in the list.
    #[inline]
    pub fn contains(&self, piece: PieceId) -> bool {
        self.as_slice().iter().any(|t| t.piece == piece)
    }

    /// Appends a touch that detection recorded as a [`Contact`](crate::components::Contact)
    /// at the substep's start (already filtered and sorted).
    pub fn push_recorded(
        &mut self,
        c: &crate::components::Contact,
        boards: &[BoardSnapshot],
        marble: &Material,
    ) {
        if self.len == MAX_TOUCHES {
            return;
        }
        let b = &boards[c.piece.board()];
        self.items[self.len] = Touch {
            piece: c.piece,
            point: c.point,
            normal: c.normal,
            gap: -c.depth,
            board_velocity: b.point_velocity(0.0, c.point),
            surface_accel: b.surface_accel(0.0, c.point, c.normal),
            board_spin: b.angular_velocity,
            material: marble.combine(b),
            convex: b.geometry.part_is_convex(c.piece.part()),
        };
        self.len += 1;
    }

    /// Inserts a candidate keeping the list sorted by gap and free of implied contacts
    /// (see the module docs). `plane_tol` is how far in front of an accepted tangent plane
    /// a closest point must lie to count as independent.
    pub fn insert(&mut self, t: Touch, plane_tol: f32) {
        let implied_by = |a: &Touch, b: &Touch| (b.point - a.point).dot(a.normal) <= plane_tol;
        let pos = self.as_slice().partition_point(|a| a.gap <= t.gap);
        if self.as_slice()[..pos].iter().any(|a| implied_by(a, &t)) {
            self.dropped += 1;
            return;
        }
        // Insert, then drop the farther touches the newcomer implies.
        if self.len == MAX_TOUCHES {
            self.dropped += 1;
            if pos == MAX_TOUCHES {
                return;
            }
            self.len -= 1;
        }
        self.items.copy_within(pos..self.len, pos + 1);
        self.items[pos] = t;
        self.len += 1;
        let mut w = pos + 1;
        for r in pos + 1..self.len {
            if !implied_by(&t, &self.items[r]) {
                self.items[w] = self.items[r];
                w += 1;
            }
        }
        self.dropped += self.len - w;
        self.len = w;
    }
}

/// Touching tolerance for a marble of radius `r` near `x`: the configured fraction of the
/// radius plus two f32 ulps of the coordinates (so that far from the origin, where f32
/// cannot resolve the fraction, contact is still recognised).
#[inline]
pub fn touch_tolerance(relative: f32, r: f32, x: Vec3) -> f32 {
    relative * r + 2.0 * f32::EPSILON * x.abs().max_element()
}

/// World-frame bounds of everything within `reach` of `x`.
#[inline]
fn sphere_aabb(x: Vec3, reach: f32) -> Aabb {
    Aabb::new(x - Vec3::splat(reach), x + Vec3::splat(reach))
}

#[inline]
fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    a.mins.cmple(b.maxs).all() && b.mins.cmple(a.maxs).all()
}

/// Collects into `out` the independent pieces within `tol` of a marble of radius `r`
/// centred at `x`, at time `t` of the substep. The marble's `material` is combined with
/// each board's; `hint` orients normals in degenerate cases (the marble's velocity reversed).
/// `near`, the marble's [`NearPieces`], stands in for its board's search where it covers
/// `x` (the same touches either way).
#[expect(
    clippy::too_many_arguments,
    reason = "a hot kernel taking plain values"
)]
pub fn gather(
    boards: &[BoardSnapshot],
    near: Option<&NearPieces>,
    t: f32,
    x: Vec3,
    r: f32,
    tol: f32,
    material: &Material,
    hint: Vec3,
    out: &mut TouchList,
) {
    out.clear();
    let reach = r + tol;
    let world = sphere_aabb(x, reach);
    for (bi, b) in boards.iter().enumerate() {
        if let Some(a) = &b.swept_aabb
            && !overlaps(a, &world)
        {
            continue;
        }
        let (c, q) = b.pose_at(t);
        let inv = q.conjugate();
        let local = inv * (x - c);
        let local_hint = inv * hint;
        let visit = |part: usize, sub: u32, piece: &Piece| {
            let p = b.geometry.proximity(part, piece, local, local_hint);
            let gap = p.distance - r;
            if gap <= tol {
                let point = q * p.point + c;
                out.insert(
                    Touch {
                        piece: PieceId::new(bi, part, sub),
                        point,
                        normal: q * p.normal,
                        gap,
                        board_velocity: b.point_velocity(t, point),
                        surface_accel: b.surface_accel(t, point, q * p.normal),
                        board_spin: b.angular_velocity,
                        material: material.combine(b),
                        convex: piece.is_convex(),
                    },
                    tol,
                );
            }
        };
        match NearPieces::of(near, bi) {
            Some(list) if list.covers(local, 0.0, tol) => list.visit(&b.geometry, visit),
            // A sphere's bounds are the same in any frame.
            _ => b.geometry.for_each_piece(&sphere_aabb(local, reach), visit),
        }
    }
}

/// The path of a marble over part of a substep: centre `x` and path velocity `v` at time
/// `t0` of the substep, constant acceleration `a`: `x(τ) = x + v τ + ½ a τ²`.
#[derive(Clone, Copy, Debug)]
pub struct Path {
    /// Time of the path's start within the substep, s.
    pub t0: f32,
    /// Centre at `t0`.
    pub x: Vec3,
    /// Path velocity at `t0`.
    pub v: Vec3,
    /// Acceleration.
    pub a: Vec3,
}

impl Path {
    /// Centre at `t0 + tau`.
    #[inline]
    pub fn position(&self, tau: f32) -> Vec3 {
        self.x + self.v * tau + self.a * (0.5 * tau * tau)
    }

    /// Centre and velocity at `t0 + tau`.
    #[inline]
    pub fn state(&self, tau: f32) -> (Vec3, Vec3) {
        (self.position(tau), self.v + self.a * tau)
    }
}

/// The earliest impact along `path` within `span` seconds with a piece the marble does not
/// touch at the path's start: `(tau, piece)`, `tau` measured from `path.t0`.
///
/// Pieces in `touching` are skipped without a distance query (the marble touches them).
/// `near`, the marble's [`NearPieces`], stands in for its board's search where it covers
/// the path (the same answer either way).
pub fn earliest_impact(
    boards: &[BoardSnapshot],
    near: Option<&NearPieces>,
    path: &Path,
    span: f32,
    r: f32,
    tol: f32,
    touching: &TouchList,
) -> Option<(f32, PieceId)> {
    let end = path.position(span);
    // Bounds of the path: the chord plus the parabola's bulge (⅛ |a| span², rounded up).
    let bulge = 0.25 * path.a.length() * span * span;
    let reach = r + tol + bulge;
    let world = Aabb::new(
        path.x.min(end) - Vec3::splat(reach),
        path.x.max(end) + Vec3::splat(reach),
    );
    // Where the centre itself can be (no radius): for the flat-face bound below.
    let centres = Aabb::new(
        path.x.min(end) - Vec3::splat(bulge),
        path.x.max(end) + Vec3::splat(bulge),
    );
    let marble_speed = path.v.length() + path.a.length() * span;
    let hint = -path.v;
    let mut best: Option<(f32, PieceId)> = None;

    for (bi, b) in boards.iter().enumerate() {
        if let Some(a) = &b.swept_aabb
            && !overlaps(a, &world)
        {
            continue;
        }
        let (c0, q0) = b.pose_at(path.t0);
        let moving = b.is_moving();
        // The rate of the centre's distance to a flat face with normal n0 (world, at the
        // path's start) is n(τ)·ẏ(τ) with |n(τ) − n0| ≤ |ω| τ: bounded by the normal
        // component of the relative motion plus the turning terms (module docs).
        let wv = b.angular_velocity;
        let w = wv.length();
        let rel = path.v - b.velocity;
        let u0 = rel - wv.cross(path.x - c0);
        let bb = path.a - wv.cross(rel);
        let curl = 0.5 * span * span * w * path.a.length();
        let face_speed = |n0: Vec3| {
            n0.dot(u0).abs()
                + span * n0.dot(bb).abs()
                + curl
                + w * span * (u0.length() + span * bb.length() + curl)
        };
        // Speed bound of the marble relative to the board's frame (a still board: the
        // marble's own speed bound). For a moving board: the distance to a piece changes
        // no faster than the marble's position in the board's frame, y = Rᵀ(x − c), whose
        // rate is the marble's velocity relative to the board's material point under it:
        //   ẏ = Rᵀ(u0 + τ (a − ω × (v − v_b)) − ½ τ² ω × a),
        //   u0 = v − v_b − ω × (x − c) at the path's start.
        // A marble riding a turning board has u0 ≈ 0, so the bound stays tight where
        // the board's own speed would make conservative advancement crawl.
        let speed = if moving {
            u0.length() + span * bb.length() + curl
        } else {
            marble_speed
        };
        if speed <= 0.0 {
            continue;
        }
        // Whether the marble's list covers every centre of the path in the board's frame:
        // on a still board they lie within half the chord and the bulge of the chord's
        // middle, on a moving one within `speed · span` of the start. A list that covers
        // them and holds only touched pieces leaves nothing to search.
        let list = NearPieces::of(near, bi);
        let covered = list.is_some_and(|l| {
            if moving {
                l.covers(q0.conjugate() * (path.x - c0), speed * span, tol)
            } else {
                let spread = 0.5 * (end - path.x).length() + bulge;
                l.covers(q0.conjugate() * (0.5 * (path.x + end) - c0), spread, tol)
            }
        });
        if covered && list.is_some_and(|l| l.pieces().iter().all(|&p| touching.contains(p))) {
            continue;
        }
        // Everything the marble can reach this substep, in the board's frame; a moving
        // board sees it through both end poses and, if it turns, a margin for the turn.
        let mut query = transform_aabb(&world, q0.conjugate() * -c0, q0.conjugate());
        let mut centre_query = transform_aabb(&centres, q0.conjugate() * -c0, q0.conjugate());
        if moving {
            let (c1, q1) = b.pose_at(path.t0 + span);
            let q_end = transform_aabb(&world, q1.conjugate() * -c1, q1.conjugate());
            query = Aabb::new(query.mins.min(q_end.mins), query.maxs.max(q_end.maxs));
            let c_end = transform_aabb(&centres, q1.conjugate() * -c1, q1.conjugate());
            centre_query = Aabb::new(
                centre_query.mins.min(c_end.mins),
                centre_query.maxs.max(c_end.maxs),
            );
            let far = (path.x - c0).length() + (marble_speed + b.velocity.length()) * span;
            let turn = w * span * far;
            query = Aabb::new(
                query.mins - Vec3::splat(turn),
                query.maxs + Vec3::splat(turn),
            );
            centre_query = Aabb::new(
                centre_query.mins - Vec3::splat(turn),
                centre_query.maxs + Vec3::splat(turn),
            );
        }
        let limit = best.map_or(span, |(t, _)| t);
        let each = |part: usize, sub: u32, piece: &Piece| {
            if touching.contains(PieceId::new(bi, part, sub)) {
                return;
            }
            let limit = best.map_or(limit, |(t, _)| t.min(limit));
            let gap_at = |tau: f32| {
                let (c, q) = if moving {
                    b.pose_at(path.t0 + tau)
                } else {
                    (c0, q0)
                };
                let inv = q.conjugate();
                let local = inv * (path.position(tau) - c);
                b.geometry
                    .proximity(part, piece, local, inv * hint)
                    .distance
                    - r
            };
            let mut gap = gap_at(0.0);
            if gap <= tol {
                return; // touching already: a contact, not an impact
            }
            // Over a flat face, only the normal motion counts: a marble sliding or riding
            // just above a surface would otherwise make the advancement crawl.
            let speed = match b.geometry.face_normal(part, piece, &centre_query) {
                Some(n) => speed.min(face_speed(q0 * n)),
                None => speed,
            };
            if speed <= 0.0 {
                return;
            }
            // With |ḋ| ≤ L, the gap cannot fall to `tol` inside [τ, end] and climb back to
            // its value at the end unless (d(τ) − tol) + (d(end) − tol) ≤ L (end − τ): where
            // that fails, no impact is possible in the rest of the span.
            // (Evaluated from the second step on: most pieces are done in one.)
            let mut gap_end = None;
            let mut tau = 0.0;
            for i in 0..MAX_ADVANCE_ITERATIONS {
                if i > 0 {
                    let end = *gap_end.get_or_insert_with(|| gap_at(limit));
                    if end > tol && (gap - tol) + (end - tol) > speed * (limit - tau) {
                        return;
                    }
                }
                // Stop within half the tolerance (never closer than a quarter): the touch
                // gathered at the impact, with the full tolerance, then certainly includes
                // this piece despite rounding in positions.
                tau += (gap - 0.25 * tol) / speed;
                if tau >= limit {
                    return;
                }
                gap = gap_at(tau);
                if gap <= 0.5 * tol {
                    break;
                }
            }
            // Converged, or out of iterations at a safe time: either way report it, the
            // caller advances there and searches again.
            best = Some((tau, PieceId::new(bi, part, sub)));
        };
        match list {
            Some(l) if covered => l.visit(&b.geometry, each),
            _ => b.geometry.for_each_piece(&query, each),
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PartShape;
    use parry3d::shape::{Cuboid, HalfSpace};

    /// A tilted walled box (floor and four walls, turning when `spin` is not zero) and a
    /// plane below it, as the prepare stage would snapshot them.
    fn boards(spin: Vec3) -> BoardCache {
        let wall =
            |half: Vec3, at: Vec3| (at, Quat::IDENTITY, PartShape::Cuboid(Cuboid::new(half)));
        let walled = BoardGeometry::compound(vec![
            wall(Vec3::new(0.3, 0.01, 0.3), Vec3::new(0.0, -0.01, 0.0)),
            wall(Vec3::new(0.01, 0.03, 0.3), Vec3::new(0.29, 0.03, 0.0)),
            wall(Vec3::new(0.01, 0.03, 0.3), Vec3::new(-0.29, 0.03, 0.0)),
            wall(Vec3::new(0.3, 0.03, 0.01), Vec3::new(0.0, 0.03, 0.29)),
            wall(Vec3::new(0.3, 0.03, 0.01), Vec3::new(0.0, 0.03, -0.29)),
        ]);
        let plane = BoardGeometry::single(PartShape::HalfSpace(HalfSpace::new(Vec3::Y)));
        let snapshot =
            |entity: u32, geometry: BoardGeometry, position: Vec3, rotation: Quat| BoardSnapshot {
                entity: Entity::from_raw_u32(entity).unwrap(),
                geometry: Arc::new(geometry),
                position,
                rotation,
                velocity: Vec3::ZERO,
                angular_velocity: Vec3::ZERO,
                restitution: 0.5,
                friction: 0.5,
                rolling_resistance: 0.0,
                spin_damping: 0.0,
                swept_aabb: None,
                reach: f32::INFINITY,
                pose_version: 0,
                poses: None,
            };
        let mut cache = BoardCache {
            h: 1.0 / 60.0,
            ..BoardCache::default()
        };
        let mut tilted = snapshot(
            1,
            walled,
            Vec3::new(0.1, 0.5, -0.2),
            Quat::from_rotation_z(0.02),
        );
        tilted.angular_velocity = spin;
        let local = tilted.geometry.local_aabb().unwrap();
        let world = crate::geometry::transform_aabb(&local, tilted.position, tilted.rotation);
        tilted.swept_aabb = Some(Aabb::new(
            world.mins - Vec3::splat(0.05),
            world.maxs + Vec3::splat(0.05),
        ));
        cache.boards.push(snapshot(
            2,
            plane,
            Vec3::new(0.0, -1.0, 0.0),
            Quat::IDENTITY,
        ));
        cache.boards.push(tilted);
        cache.update_epoch();
        cache
    }

    struct Lcg(u32);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (self.0 >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        }
        fn vec(&mut self, scale: Vec3) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next()) * scale
        }
    }

    const R: f32 = 0.008;

    /// A marble centre on the box's floor or against a wall or in a corner, world frame.
    fn near_the_box(cache: &BoardCache, rng: &mut Lcg) -> Vec3 {
        let b = &cache.boards[1];
        let mut y = rng.vec(Vec3::new(0.62, 0.0, 0.62));
        y.y = R + 1e-6 * rng.next();
        y.x = y.x.clamp(-0.28 + R, 0.28 - R);
        y.z = y.z.clamp(-0.28 + R, 0.28 - R);
        b.rotation * y + b.position
    }

    /// Gathering through a marble's list gives the same touches, bit for bit, as searching
    /// the boards, for centres anywhere the list covers (on the floor, against walls, in
    /// corners); the lone touch of a list, where it vouches for one, is the search's touch.
    #[test]
    fn near_lists_gather_what_a_search_finds() {
        let cache = boards(Vec3::ZERO);
        let mut rng = Lcg(7);
        let material = Material {
            restitution: 0.5,
            ..Material::default()
        };
        let (mut lone, mut compared) = (0, 0);
        for _ in 0..400 {
            let anchor = near_the_box(&cache, &mut rng);
            let tol = touch_tolerance(1e-4, R, anchor);
            let mut list = NearPieces::default();
            list.rebuild(&cache, anchor, R, tol, 2.0 * R);
            assert!(list.is_fresh(&cache, anchor, R, 0.0, tol));
            for _ in 0..10 {
                // Within the list's reach and beyond it.
                let mut x = anchor + rng.vec(Vec3::splat(8.0 * R));
                if rng.next() > 0.0 {
                    // Onto the floor, where the lone touch applies.
                    let b = &cache.boards[1];
                    let mut y = b.rotation.conjugate() * (x - b.position);
                    y.y = R + 0.5 * tol * rng.next();
                    x = b.rotation * y + b.position;
                }
                let (mut searched, mut listed) = (TouchList::default(), TouchList::default());
                gather(
                    &cache.boards,
                    None,
                    0.0,
                    x,
                    R,
                    tol,
                    &material,
                    Vec3::Y,
                    &mut searched,
                );
                gather(
                    &cache.boards,
                    Some(&list),
                    0.0,
                    x,
                    R,
                    tol,
                    &material,
                    Vec3::Y,
                    &mut listed,
                );
                let key = |t: &Touch| {
                    (
                        t.piece,
                        t.gap.to_bits(),
                        t.normal.to_array().map(f32::to_bits),
                    )
                };
                assert_eq!(
                    searched.as_slice().iter().map(key).collect::<Vec<_>>(),
                    listed.as_slice().iter().map(key).collect::<Vec<_>>(),
                );
                assert_eq!(searched.is_complete(), listed.is_complete());
                compared += 1;
                if let Some(t) = list.lone_touch(
                    &cache.boards,
                    x,
                    -Vec3::Y,
                    Vec3::ZERO,
                    0.0,
                    R,
                    tol,
                    &material,
                    false,
                ) {
                    let [s] = searched.as_slice() else {
                        panic!("lone touch {t:?} where the search found {searched:?}");
                    };
                    assert_eq!(s.piece, t.piece);
                    assert!((s.gap - t.gap).abs() < 1e-7, "{} vs {}", s.gap, t.gap);
                    assert!((s.normal - t.normal).length() < 1e-6);
                    assert!((s.point - t.point).length() < 1e-6);
                    lone += 1;
                }
            }
        }
        assert!(compared == 4000 && lone > 150, "{lone} lone touches");
    }

    /// [`NearPieces::within`] through a list finds exactly the pieces, with the same gaps,
    /// that it finds by searching every board (a default list covers nothing), for centres
    /// within the list's reach and beyond it, reaches from a fifth of a radius to three
    /// radii, on a still board, after the board was moved and turned since the list was
    /// built, and on a turning board (its reach grows with its turn). A second board, a
    /// plane cutting through the box just above its floor, is near the same marbles: a
    /// list holds one board's pieces, so the other must still be searched.
    #[test]
    fn near_lists_find_the_speculative_pieces_a_search_finds() {
        let mut rng = Lcg(11);
        let mut found = [0usize; 2];
        let with_plane = |spin: Vec3| {
            let mut cache = boards(spin);
            cache.boards[0].position = Vec3::new(0.0, 0.5 + 1.5 * R, 0.0);
            cache
        };
        for spin in [Vec3::ZERO, Vec3::new(0.3, 0.0, 0.5)] {
            for moved in [false, true] {
                let mut cache = with_plane(spin);
                for _ in 0..200 {
                    let anchor = near_the_box(&cache, &mut rng);
                    let tol = touch_tolerance(1e-4, R, anchor);
                    let mut list = NearPieces::default();
                    list.rebuild(&cache, anchor, R, tol, 3.0 * R);
                    if moved {
                        let b = &mut cache.boards[1];
                        b.position += Vec3::new(0.2, -0.1, 0.3) * R;
                        b.rotation = Quat::from_rotation_y(0.01) * b.rotation;
                        b.pose_version += 1;
                    }
                    for _ in 0..5 {
                        let x = anchor + rng.vec(Vec3::splat(4.0 * R));
                        let v = rng.vec(Vec3::splat(0.5));
                        for reach in [0.2 * R, R, 3.0 * R] {
                            let collect = |near: &NearPieces| {
                                let mut out = Vec::new();
                                near.within(
                                    &cache,
                                    x,
                                    v,
                                    R,
                                    reach,
                                    cache.h,
                                    |_| false,
                                    |piece, point, normal, gap| {
                                        out.push((piece, gap.to_bits(), point, normal))
                                    },
                                );
                                out.sort_by_key(|t| (t.0, t.1));
                                out
                            };
                            let searched = collect(&NearPieces::default());
                            assert_eq!(collect(&list), searched, "at {x}, reach {reach}");
                            for t in &searched {
                                found[t.0.board()] += 1;
                            }
                        }
                    }
                    if moved {
                        cache = with_plane(spin);
                    }
                }
            }
        }
        assert!(found[0] > 300 && found[1] > 1000, "pieces found: {found:?}");
    }

    /// The event loop's result for a marble touching what [`gather`] finds at its start,
    /// and its records: the reference the closed forms are checked against.
    fn event_loop(
        cache: &BoardCache,
        p: &crate::response::SubstepParams,
        m: &crate::response::MarbleIn,
        tol: f32,
    ) -> (crate::response::MarbleOut, crate::components::Contacts) {
        let mut touches = TouchList::default();
        gather(
            &cache.boards,
            None,
            0.0,
            m.x0,
            m.r,
            tol,
            &m.material,
            -m.v0,
            &mut touches,
        );
        let mut full = crate::components::Contacts::default();
        let out = crate::response::resolve(
            &cache.boards,
            None,
            p,
            m,
            crate::response::Found::Touching,
            &mut touches,
            &mut full,
        );
        (out, full)
    }

    /// Substep parameters for case `k` of a closed-form test: the four integrators in turn,
    /// continuous collision on.
    fn case_params(k: usize, h: f32) -> crate::response::SubstepParams {
        use crate::config::Integrator;
        crate::response::SubstepParams {
            h,
            integrator: [
                Integrator::SemiImplicitEuler,
                Integrator::VelocityVerlet,
                Integrator::Rk4,
                Integrator::ExplicitEuler,
            ][k % 4],
            ccd: true,
            threshold: 0.05,
            tolerance: 1e-4,
            max_impacts: 8,
        }
    }

    /// A marble's records, bit for bit.
    fn records(
        c: &crate::components::Contacts,
    ) -> Vec<(PieceId, crate::components::ContactKind, u32, [u32; 3])> {
        c.iter()
            .map(|c| {
                (
                    c.piece,
                    c.kind,
                    c.closing_speed.to_bits(),
                    c.normal.to_array().map(f32::to_bits),
                )
            })
            .collect()
    }

    /// The closed form for a marble resting or sliding on one piece
    /// ([`crate::response::resolve_resting`]) gives the event loop's result, bit for bit,
    /// whenever it applies: on the floor, slow or fast, approaching (a collision) or not,
    /// for every integrator.
    #[test]
    fn resting_closed_form_is_the_event_loop() {
        use crate::components::Contacts;
        use crate::response::{MarbleIn, resolve_resting};
        let cache = boards(Vec3::ZERO);
        let b = &cache.boards[1];
        let mut rng = Lcg(5);
        let mut applied = 0;
        for k in 0..4000 {
            let p = case_params(k, cache.h);
            let x0 = near_the_box(&cache, &mut rng);
            let tol = touch_tolerance(p.tolerance, R, x0);
            let speed = if k % 3 == 0 { 0.02 } else { 0.5 };
            let m = MarbleIn {
                x0,
                v0: rng.vec(Vec3::splat(speed)),
                w0: None,
                a: b.rotation * Vec3::new(0.0, -9.81, 0.0) + rng.vec(Vec3::splat(2.0)),
                r: R,
                material: Material {
                    restitution: 0.7,
                    ..Material::default()
                },
            };
            let mut list = NearPieces::default();
            list.rebuild(&cache, x0, R, tol, 4.0 * R);
            let Some(tc) = list.lone_touch(
                &cache.boards,
                x0,
                m.v0,
                m.a,
                p.h,
                R,
                tol,
                &m.material,
                false,
            ) else {
                continue;
            };
            let mut fast = Contacts::default();
            let Some(closed) = resolve_resting(&cache.boards, &p, &m, &tc, &mut fast) else {
                continue;
            };
            let (looped, full) = event_loop(&cache, &p, &m, tol);
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(
                (bits(closed.d), bits(closed.v)),
                (bits(looped.d), bits(looped.v)),
                "case {k}"
            );
            assert_eq!(records(&fast), records(&full), "case {k}");
            applied += 1;
        }
        assert!(applied > 400, "applied {applied} times");
    }

    /// The closed form for a spinning marble on one piece
    /// ([`crate::response::resolve_rolling`]) gives the event loop's result, bit for bit
    /// (position, velocity, spin and records), whenever it applies: rolling, slipping,
    /// with and without rolling resistance and spin damping, for every integrator; and it
    /// declines when a friction event falls inside the substep.
    #[test]
    fn rolling_closed_form_is_the_event_loop() {
        use crate::components::Contacts;
        use crate::response::{MarbleIn, resolve_rolling};
        let cache = boards(Vec3::ZERO);
        let b = &cache.boards[1];
        let mut rng = Lcg(7);
        let (mut applied, mut declined) = (0, 0);
        for k in 0..4000 {
            let p = case_params(k, cache.h);
            let x0 = near_the_box(&cache, &mut rng);
            let tol = touch_tolerance(p.tolerance, R, x0);
            let speed = if k % 3 == 0 { 0.02 } else { 0.5 };
            let v0 = rng.vec(Vec3::splat(speed));
            let up = b.rotation * Vec3::Y;
            // Rolling on the floor (no slip), or spinning at random.
            let w0 = if k % 2 == 0 {
                up.cross(v0) / R
            } else {
                rng.vec(Vec3::splat(200.0))
            };
            let m = MarbleIn {
                x0,
                v0,
                w0: Some(w0),
                a: b.rotation * Vec3::new(0.0, -9.81, 0.0) + rng.vec(Vec3::splat(2.0)),
                r: R,
                material: Material {
                    restitution: 0.7,
                    friction: 0.5,
                    rolling_resistance: if k % 5 < 2 { 0.02 } else { 0.0 },
                    spin_damping: if k % 7 < 3 { 0.05 } else { 0.0 },
                },
            };
            let mut list = NearPieces::default();
            list.rebuild(&cache, x0, R, tol, 4.0 * R);
            let Some(tc) =
                list.lone_touch(&cache.boards, x0, m.v0, m.a, p.h, R, tol, &m.material, true)
            else {
                continue;
            };
            let mut fast = Contacts::default();
            let Some(closed) = resolve_rolling(&cache.boards, &p, &m, &tc, &mut fast) else {
                declined += 1;
                continue;
            };
            let (looped, full) = event_loop(&cache, &p, &m, tol);
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(
                (bits(closed.d), bits(closed.v), bits(closed.w)),
                (bits(looped.d), bits(looped.v), bits(looped.w)),
                "case {k}"
            );
            assert_eq!(records(&fast), records(&full), "case {k}");
            applied += 1;
        }
        assert!(
            applied > 400 && declined > 20,
            "applied {applied} times, declined {declined}"
        );
    }

    /// The earliest impact along a path the list covers is the search's, on a still and on
    /// a turning board.
    #[test]
    fn near_lists_find_the_searched_impacts() {
        for spin in [Vec3::ZERO, Vec3::new(0.0, 0.0, 0.4)] {
            let cache = boards(spin);
            let mut rng = Lcg(11);
            let mut impacts = 0;
            for _ in 0..2000 {
                let anchor = near_the_box(&cache, &mut rng);
                let tol = touch_tolerance(1e-4, R, anchor);
                let mut list = NearPieces::default();
                list.rebuild(&cache, anchor, R, tol, 4.0 * R);
                let path = Path {
                    t0: 0.0,
                    x: anchor + rng.vec(Vec3::splat(R)) + Vec3::new(0.0, 0.5 * R, 0.0),
                    v: rng.vec(Vec3::splat(6.0)),
                    a: Vec3::new(0.0, -9.81, 0.0),
                };
                let touching = TouchList::default();
                let searched =
                    earliest_impact(&cache.boards, None, &path, cache.h, R, tol, &touching);
                let listed = earliest_impact(
                    &cache.boards,
                    Some(&list),
                    &path,
                    cache.h,
                    R,
                    tol,
                    &touching,
                );
                assert_eq!(
                    searched.map(|(t, p)| (t.to_bits(), p)),
                    listed.map(|(t, p)| (t.to_bits(), p))
                );
                impacts += usize::from(searched.is_some());
            }
            assert!(impacts > 300, "{impacts} impacts");
        }
    }
}
