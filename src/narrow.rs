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

use std::sync::Arc;

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;

use crate::geometry::{BoardGeometry, PieceId, transform_aabb};

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
#[expect(
    clippy::too_many_arguments,
    reason = "a hot kernel taking plain values"
)]
pub fn gather(
    boards: &[BoardSnapshot],
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
        // A sphere's bounds are the same in any frame.
        let query = sphere_aabb(local, reach);
        b.geometry.for_each_piece(&query, |part, sub, piece| {
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
        });
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
pub fn earliest_impact(
    boards: &[BoardSnapshot],
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
        // Everything the marble can reach this substep, in the board's frame; a moving
        // board sees it through both end poses and, if it turns, a margin for the turn.
        let mut query = transform_aabb(&world, q0.conjugate() * -c0, q0.conjugate());
        let mut centre_query = transform_aabb(&centres, q0.conjugate() * -c0, q0.conjugate());
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
        // marble's own speed bound).
        let mut speed = marble_speed;
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
            // The distance to a piece changes no faster than the marble's position in the
            // board's frame, y = Rᵀ(x − c), whose rate is the marble's velocity relative to
            // the board's material point under it:
            //   ẏ = Rᵀ(u0 + τ (a − ω × (v − v_b)) − ½ τ² ω × a),
            //   u0 = v − v_b − ω × (x − c) at the path's start.
            // A marble riding a turning board has u0 ≈ 0, so the bound stays tight where
            // the board's own speed would make conservative advancement crawl.
            speed = u0.length() + span * bb.length() + curl;
        }
        if speed <= 0.0 {
            continue;
        }
        let limit = best.map_or(span, |(t, _)| t);
        b.geometry.for_each_piece(&query, |part, sub, piece| {
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
        });
    }
    best
}
