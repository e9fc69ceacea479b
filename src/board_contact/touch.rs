//! Which pieces a marble touches: the touch record, the filter that keeps only independent
//! contacts, and the pair's material.

use super::*;

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
    /// Board material acceleration at `point`: the centripetal `ω × (ω × (p − c))` of a
    /// turning board (zero for boards that do not turn). Its normal part is what a marble
    /// needs to stay on the surface, its tangential part what a rolling marble's contact
    /// point must follow; the terms of the turning normal that depend on the marble's
    /// velocity are added where that is known.
    pub board_accel: Vec3,
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
                board_accel: Vec3::ZERO,
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

    /// The touches, to change in place.
    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [Touch] {
        &mut self.items[..self.len]
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

    /// Keeps the touches whose index `keep` accepts, in order.
    #[inline]
    pub fn retain_indices(&mut self, mut keep: impl FnMut(usize) -> bool) {
        let mut w = 0;
        for r in 0..self.len {
            if keep(r) {
                self.items[w] = self.items[r];
                w += 1;
            }
        }
        self.len = w;
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
            board_accel: b.point_accel(0.0, c.point),
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
pub(super) fn sphere_aabb(x: Vec3, reach: f32) -> Aabb {
    Aabb::new(x - Vec3::splat(reach), x + Vec3::splat(reach))
}

#[inline]
pub(super) fn overlaps(a: &Aabb, b: &Aabb) -> bool {
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
    for (bi, b) in boards.iter().enumerate() {
        gather_board::<true>(bi, b, near, t, x, r, tol, material, hint, out, &mut None);
    }
}

/// [`gather`] at time `t` of the substep in a scene of one board, `b`: the list's
/// clearance ([`NearPieces::clearance`]) when the list covers the centre and shows the
/// marble clear of every piece by more than `tol`, so that nothing was visited (`out`
/// empty); `None` when the board was searched, or is out of reach.
#[expect(
    clippy::too_many_arguments,
    reason = "a hot kernel taking plain values"
)]
#[inline(never)]
pub(crate) fn gather_single(
    b: &BoardSnapshot,
    near: &NearPieces,
    t: f32,
    x: Vec3,
    r: f32,
    tol: f32,
    material: &Material,
    hint: Vec3,
    out: &mut TouchList,
) -> Option<f32> {
    out.clear();
    let mut clear = None;
    gather_board::<true>(
        0,
        b,
        Some(near),
        t,
        x,
        r,
        tol,
        material,
        hint,
        out,
        &mut clear,
    );
    clear
}

/// [`gather`] on board `bi` alone, adding to `out`. Without `SEARCH`, a board that the
/// list does not cover where it could reach the marble is not searched: `false`, and
/// `out` as it was (the caller then gathers in full). Where the list shows the marble
/// clear of the board by more than `tol` (nothing visited), `clear` gets that clearance.
#[expect(
    clippy::too_many_arguments,
    reason = "a hot kernel taking plain values"
)]
#[inline(always)]
pub(crate) fn gather_board<const SEARCH: bool>(
    bi: usize,
    b: &BoardSnapshot,
    near: Option<&NearPieces>,
    t: f32,
    x: Vec3,
    r: f32,
    tol: f32,
    material: &Material,
    hint: Vec3,
    out: &mut TouchList,
    clear: &mut Option<f32>,
) -> bool {
    let reach = r + tol;
    let world = sphere_aabb(x, reach);
    if let Some(a) = &b.swept_aabb
        && !overlaps(a, &world)
    {
        return true;
    }
    let (c, q) = b.pose_at(t);
    let inv = q.conjugate();
    let local = inv * (x - c);
    let list = NearPieces::of(near, bi).filter(|l| l.covers(local, 0.0, tol));
    // Clear of every piece by more than `tol`, the list finds nothing to visit.
    if let Some(list) = list {
        let shown = list.clearance(local, 0.0);
        if shown > tol {
            *clear = Some(shown);
            return true;
        }
    }
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
                    board_accel: b.point_accel(t, point),
                    board_spin: b.angular_velocity,
                    material: material.combine(b),
                    convex: piece.is_convex(),
                },
                tol,
            );
        }
    };
    match list {
        Some(list) => list.visit(&b.geometry, visit),
        // A sphere's bounds are the same in any frame.
        _ if SEARCH => b.geometry.for_each_piece(&sphere_aabb(local, reach), visit),
        _ => return false,
    }
    true
}
