//! Near-piece lists: the few pieces of a board within reach of a marble, kept while it
//! stays within that reach (a Verlet list for board pieces).

use super::*;

/// Most pieces a [`NearPieces`] list holds.
pub const NEAR_MAX: usize = 5;

/// A list that holds one flat face of a still board reaches up to this many radii (less
/// where another piece or the face's edge is nearer), however short the motion it was
/// built for: a marble sliding on a wide floor keeps its list for many substeps.
const FACE_SKIN: f32 = 16.0;

/// The pieces of one board near a marble, so that its queries visit those instead of
/// searching the board: a Verlet list (a "skin") for board pieces.
///
/// Built around an *anchor*, the marble's centre in the board's frame, it holds every piece
/// whose distance from the anchor, minus the radius, is below `reach`. Any piece within
/// `g` of a centre `y` (board frame) is then within `g + |y − anchor|` of the anchor, so a
/// query whose centres stay within `reach − g` of the anchor needs only the listed pieces
/// ([`NearPieces::covers`]). The test is made in the board's frame at the query's time, so a
/// marble riding a moving or turning board keeps its list as long as it stays near the
/// same spot of the board. Queries the list does not cover search the board, and
/// detection rebuilds a list that no longer covers the substep's start. The pieces are kept
/// in the order a search visits them, so a query gives the same bits either way.
///
/// Laid out for the commonest query, a marble on a still flat face
/// ([`NearPieces::still_face`]): what it reads (the length, board, epoch, radius, the
/// face, the anchor in the world, the reach and the first piece) fills the first 64 bytes,
/// and the list is aligned to them, so that the query reads one cache line of it.
#[derive(Component, Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct NearPieces {
    len: u8,
    /// Index of the board in [`BoardCache::boards`]; [`NO_LIST`]: no list.
    board: u16,
    /// The [`BoardCache::epoch`] it was built in.
    epoch: u32,
    /// The radius it was built for.
    radius: f32,
    /// The board's [`BoardSnapshot::pose_version`] when built: while it is the same, the
    /// board has not moved and the list can be tested in the world frame.
    pose_version: u32,
    /// For a lone piece of a still board, flat under every centre the list covers: its
    /// normal (world; zero otherwise) and the anchor's gap to it.
    face_normal: Vec3,
    face_gap: f32,
    /// Centre when built, world.
    anchor_world: Vec3,
    /// Every piece of the board closer than this to the anchor (distance minus radius) is
    /// listed.
    reach: f32,
    /// The anchor's gap to the nearest piece of the board (the listed gaps, and the reach
    /// for the rest), less a margin for rounding: [`NearPieces::clearance`] at the anchor.
    clear: f32,
    pieces: [PieceId; NEAR_MAX],
    /// Centre when built, board frame.
    anchor: Vec3,
    /// Each listed piece's gap from the anchor (distance minus radius) when built.
    gaps: [f32; NEAR_MAX],
}

/// [`NearPieces::board`] of no list. A board at this index or beyond gets no list (its
/// queries search it; piece identifiers hold 16 bits of the board's index).
const NO_LIST: u16 = u16::MAX;

impl Default for NearPieces {
    fn default() -> Self {
        NearPieces {
            pieces: [PieceId::NONE; NEAR_MAX],
            len: 0,
            board: NO_LIST,
            epoch: 0,
            radius: 0.0,
            anchor: Vec3::ZERO,
            reach: 0.0,
            anchor_world: Vec3::ZERO,
            pose_version: 0,
            face_normal: Vec3::ZERO,
            face_gap: 0.0,
            gaps: [f32::INFINITY; NEAR_MAX],
            clear: f32::NEG_INFINITY,
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
    pub(super) fn visit(&self, geometry: &BoardGeometry, mut f: impl FnMut(usize, u32, &Piece)) {
        for id in self.pieces() {
            f(id.part(), id.sub(), &geometry.piece(id.part(), id.sub()));
        }
    }

    /// The list for board `board`, if this is it.
    #[inline]
    pub(super) fn of(near: Option<&NearPieces>, board: usize) -> Option<&NearPieces> {
        near.filter(|l| l.board != NO_LIST && l.board as usize == board)
    }

    /// True when every piece within `gap` of some centre within `spread` of `centre` (board
    /// frame) is listed.
    #[inline]
    pub fn covers(&self, centre: Vec3, spread: f32, gap: f32) -> bool {
        (centre - self.anchor).length() + spread + gap < self.reach
    }

    /// A lower bound on the gap (distance minus the radius) between every piece of the
    /// list's board and a marble centred anywhere within `spread` of `centre` (board
    /// frame): the listed pieces' gaps from the anchor, and the reach for those left out,
    /// less how far such a centre can be from the anchor (a distance changes no faster than
    /// the point it is measured from), less a margin for the rounding of the distances
    /// compared with it. A query that finds only what lies within `tol` has nothing to
    /// visit where this exceeds `tol`.
    #[inline(always)]
    pub fn clearance(&self, centre: Vec3, spread: f32) -> f32 {
        // (`clear` allows for the rounding of distances measured from the anchor; one
        // from `centre` adds at most that of the distance between the two.)
        let away = (centre - self.anchor).length() + spread;
        self.clear - away * (1.0 + 8.0 * f32::EPSILON)
    }

    /// True when the list was built for these boards and this radius and covers the
    /// centres within `spread` of `x` (world, at the substep's start) for touches within
    /// `tol`.
    pub fn is_fresh(&self, cache: &BoardCache, x: Vec3, r: f32, spread: f32, tol: f32) -> bool {
        if self.board == NO_LIST || self.epoch != cache.epoch || self.radius != r {
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
        let touch = if !moving && self.holds_still_face(b) {
            self.face_touch(b, id, x, r, (tol, false), material)?
        } else {
            // As `gather` computes it (at the board's pose at the start, bit for bit).
            let (c, q) = b.pose_at(0.0);
            let inv = q.conjugate();
            let local = inv * (x - c);
            // Covered, and not clear of the piece by more than `tol` (`covers` and
            // `clearance` on one distance): else no touch, without computing it.
            let away = (local - self.anchor).length();
            if away + tol >= self.reach || self.clear - away * (1.0 + 8.0 * f32::EPSILON) > tol {
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
                board_accel: b.point_accel(0.0, point),
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
        self.vouches(boards, &touch, x, v, a, h, r, (tol, false), spins)
            .then_some(touch)
    }

    /// [`NearPieces::lone_touch`] for a marble that does not spin, when the list holds a
    /// flat face of a still board where it was, for a list [`NearPieces::is_fresh`] keeps
    /// for this marble (so detection need not ask): the same touch, in closed form, and
    /// the same test that nothing else is within reach of the substep. `None` in every
    /// other case (the caller then asks `is_fresh` and `lone_touch`).
    #[expect(
        clippy::too_many_arguments,
        reason = "a hot kernel taking plain values"
    )]
    #[inline(always)]
    pub fn still_face(
        &self,
        boards: &[BoardSnapshot],
        epoch: u32,
        x: Vec3,
        v: Vec3,
        a: Vec3,
        h: f32,
        r: f32,
        tol: f32,
        material: &Material,
    ) -> Option<Touch> {
        let [id] = *self.pieces() else {
            return None;
        };
        if self.epoch != epoch || self.radius != r {
            return None;
        }
        let b = boards.get(self.board as usize)?;
        if b.is_moving() || !self.holds_still_face(b) {
            return None;
        }
        // Most substeps the marble is well inside the list's reach: a test without square
        // roots shows that, and both reach tests below are then passed (they answer as
        // they would: the test implies theirs).
        let inside = self.well_inside(x, v, a, h, tol);
        let touch = self.face_touch(b, id, x, r, (tol, inside), material)?;
        // `vouches` asks more of the list than `is_fresh` does (the substep's whole
        // spread, not its speed alone).
        self.vouches(boards, &touch, x, v, a, h, r, (tol, inside), false)
            .then_some(touch)
    }

    /// A sufficient condition, without square roots, for [`NearPieces::vouches`]'s reach
    /// test on the list's flat face (a marble that does not spin, the board where it was):
    /// `|x − anchor| + spread + tol < reach`, with `spread = (|v| + 2|a_t| h) h` and `a_t`
    /// the acceleration the face leaves. As `p + q ≤ √(2(p² + q²))` twice, it holds when
    /// `2(|x − anchor|² + 2h²(|v|² + 4h²|a_t|²)) < (reach − tol)²`; the factor
    /// `1 ± 1e-4` covers every rounding of both sides (each a few parts in 1e7), so where
    /// this is true the exact test is too. False near the edge of the reach, and for NaN:
    /// the exact test decides there.
    #[inline(always)]
    fn well_inside(&self, x: Vec3, v: Vec3, a: Vec3, h: f32, tol: f32) -> bool {
        let n = self.face_normal;
        let along = a - a.dot(n).min(0.0) * n;
        let d = x - self.anchor_world;
        let hh = h * h;
        let spread = 2.0 * hh * (v.length_squared() + 4.0 * hh * along.length_squared());
        let room = self.reach - tol;
        room > 0.0 && 2.0 * (d.length_squared() + spread) * 1.0001 < room * room * 0.9999
    }

    /// True when the list holds a flat face of board `b` (which does not move), and the
    /// board is where it was when the list was built.
    #[inline(always)]
    fn holds_still_face(&self, b: &BoardSnapshot) -> bool {
        self.face_normal != Vec3::ZERO && b.pose_version == self.pose_version
    }

    /// The touch of the list's flat face `id` of board `b` ([`NearPieces::holds_still_face`])
    /// for a marble of radius `r` at `x`: the distance is affine in the centre. `None`
    /// when the list does not cover `x` (known to, with `inside`) or the face is farther
    /// than `tol`.
    #[inline(always)]
    fn face_touch(
        &self,
        b: &BoardSnapshot,
        id: PieceId,
        x: Vec3,
        r: f32,
        (tol, inside): (f32, bool),
        material: &Material,
    ) -> Option<Touch> {
        let d = x - self.anchor_world;
        if !inside && d.length() + tol >= self.reach {
            return None;
        }
        let n = self.face_normal;
        let gap = self.face_gap + n.dot(d);
        if gap.abs() > tol {
            return None;
        }
        Some(Touch {
            piece: id,
            point: x - (r + gap) * n,
            normal: n,
            gap,
            board_velocity: Vec3::ZERO,
            board_accel: Vec3::ZERO,
            board_spin: Vec3::ZERO,
            material: material.combine(b),
            convex: true,
        })
    }

    /// True when `touch`, on a piece of the list's board (which does not move), is the
    /// only piece within reach of the whole substep of length `h` of a marble of radius
    /// `r` at `x` (world) moving at `v` under acceleration `a` (and friction, when it
    /// `spins`): the list covers every centre it can reach sliding on the piece (its
    /// speed, and the acceleration the piece leaves it, over `h`), and no other board
    /// comes within reach. `inside`: the reach test is known to pass
    /// ([`NearPieces::well_inside`]).
    #[expect(
        clippy::too_many_arguments,
        reason = "a hot kernel taking plain values"
    )]
    #[inline(always)]
    fn vouches(
        &self,
        boards: &[BoardSnapshot],
        touch: &Touch,
        x: Vec3,
        v: Vec3,
        a: Vec3,
        h: f32,
        r: f32,
        (tol, inside): (f32, bool),
        spins: bool,
    ) -> bool {
        let bi = self.board as usize;
        let b = &boards[bi];
        // Shown well inside the reach ([`NearPieces::well_inside`]), with no other board.
        if inside && boards.len() == 1 {
            return true;
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
        let clear = if inside {
            true
        } else if b.pose_version == self.pose_version {
            (x - self.anchor_world).length() + spread + tol < self.reach
        } else {
            self.covers(b.rotation.conjugate() * (x - b.position), spread, tol)
        };
        if !clear {
            return false;
        }
        let reach = r + tol + spread;
        let world = sphere_aabb(x, reach);
        // (With one board, the common case, there are no others: skip the search, whose
        // closure the compiler leaves a call.)
        boards.len() == 1
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
            })
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
        self.build(cache, x, r, tol, skin);
        let nearest = self.gaps[..self.len as usize]
            .iter()
            .fold(self.reach, |g, &p| g.min(p));
        self.clear = nearest
            - 8.0 * f32::EPSILON * (r + nearest.abs() + 2.0 * self.anchor.abs().max_element());
    }

    /// [`NearPieces::rebuild`] less its clearance.
    fn build(&mut self, cache: &BoardCache, x: Vec3, r: f32, tol: f32, skin: f32) {
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
            let Some(index) = u16::try_from(bi).ok().filter(|&i| i != NO_LIST) else {
                break;
            };
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
                self.board = index;
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
            // A marble on the face (not one falling onto it, whose list lasts a substep or
            // two whatever its reach).
            if self.face_gap <= tol {
                self.extend_face(b, id, r, tol + FACE_SKIN * r);
            }
        }
    }

    /// Widens a list that holds one flat face `id` of the still board `b`, built for a
    /// marble on it, to the nearest other piece of that board, or to `limit`, while the
    /// face stays flat under every centre it covers: such a list stands until the marble
    /// nears another piece or the face's edge, not only for the few substeps of motion it
    /// was built for.
    fn extend_face(&mut self, b: &BoardSnapshot, id: PieceId, r: f32, limit: f32) {
        if limit <= self.reach {
            return;
        }
        let (bi, anchor) = (self.board as usize, self.anchor);
        let mut next = limit;
        b.geometry
            .for_each_piece(&sphere_aabb(anchor, r + limit), |part, sub, piece| {
                if PieceId::new(bi, part, sub) != id {
                    let gap = b
                        .geometry
                        .proximity(part, piece, anchor, Vec3::ZERO)
                        .distance
                        - r;
                    next = next.min(gap);
                }
            });
        let reach = next - 8.0 * f32::EPSILON * (r + next + anchor.abs().max_element());
        if reach > self.reach
            && b.geometry
                .flat_face(id.part(), id.sub(), anchor, reach)
                .is_some()
        {
            self.reach = reach;
        }
    }
}

/// The nearest pieces offered to a [`NearPieces`] build: up to [`NEAR_MAX`] with their
/// gaps, and the smallest gap of those left out (the limit when none was).
pub(super) struct Candidates {
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `vouches`'s reach test on a still face, as it computes it.
    fn exact(list: &NearPieces, x: Vec3, v: Vec3, a: Vec3, h: f32, tol: f32) -> bool {
        let n = list.face_normal;
        let along = a - a.dot(n).min(0.0) * n;
        let spread = (v.length() + 2.0 * along.length() * h) * h;
        (x - list.anchor_world).length() + spread + tol < list.reach
    }

    fn unit(u: [f32; 3]) -> Vec3 {
        Vec3::from_array(u).try_normalize().unwrap_or(Vec3::Y)
    }

    /// A still-face list and a marble whose reach test is within `closeness` of the edge
    /// of the square-root-free test, where that test is tightest: the marble's distance
    /// from the anchor equal to its spread (`p + q = √(2(p² + q²))` for `p = q`) and its
    /// speed twice its acceleration's share (`2|a_t|h`) of the spread.
    fn tight_case(
        (normal, anchor, reach, tol): ([f32; 3], [f32; 3], f32, f32),
        (h, into, dirs): (f32, f32, [[f32; 3]; 3]),
        (share, ratio, closeness): (f32, f32, f32),
    ) -> (NearPieces, Vec3, Vec3, Vec3) {
        let n = unit(normal);
        let list = NearPieces {
            face_normal: n,
            anchor_world: Vec3::from_array(anchor),
            reach,
            ..NearPieces::default()
        };
        let room = reach - tol;
        // `spread = (|v| + 2|a_t|h)h` with `|v| = share·2|a_t|h`, the distance `ratio`
        // times the spread, both sized so that `2(d² + s²) = closeness · room²`.
        let spread = room * (closeness / (2.0 * (1.0 + ratio * ratio))).sqrt();
        let along_len = spread / (2.0 * h * h * (1.0 + share));
        let t = unit(dirs[0]);
        let along = (t - t.dot(n) * n)
            .try_normalize()
            .unwrap_or(n.any_orthonormal_vector());
        let a = along * along_len + into * n;
        let v = unit(dirs[1]) * (share * 2.0 * along_len * h);
        let x = list.anchor_world + unit(dirs[2]) * (ratio * spread);
        (list, x, v, a)
    }

    fn case() -> impl Strategy<Value = (NearPieces, Vec3, Vec3, Vec3, f32, f32)> {
        let v3 = || prop::array::uniform3(-1.0f32..1.0);
        let list = (
            v3(),
            prop::array::uniform3(-1e3f32..1e3),
            1e-3f32..2.0,
            0.0f32..0.01,
        );
        let motion = (1e-4f32..0.1, -20.0f32..0.0, prop::array::uniform3(v3()));
        let shape = prop_oneof![
            (0.0f32..2.0, 0.0f32..2.0, 0.9995f32..1.0005),
            // Near the bound's tightest point, and within rounding of its edge.
            (
                0.999f32..1.001,
                0.999f32..1.001,
                // (Steps of half an ulp of 1: proptest cannot sample a range this narrow.)
                (-16i32..16).prop_map(|k| 1.0 + k as f32 * 0.5 * f32::EPSILON),
            ),
        ];
        (list, motion, shape).prop_map(|(list, motion, shape)| {
            let (h, tol) = (motion.0, list.3 * list.2);
            let (near, x, v, a) = tight_case((list.0, list.1, list.2, tol), motion, shape);
            (near, x, v, a, h, tol)
        })
    }

    proptest! {
        /// Where the square-root-free test passes, the exact reach test it stands in for
        /// passes too, at the edge of the former and where its bound is tightest.
        #[test]
        fn well_inside_implies_the_exact_reach_test((list, x, v, a, h, tol) in case()) {
            if list.well_inside(x, v, a, h, tol) {
                prop_assert!(exact(&list, x, v, a, h, tol));
            }
        }
    }

    /// The test is not vacuous, and where its bound is tightest it is as tight as the
    /// exact test: a marble a little inside its edge passes both, one a little outside
    /// neither.
    #[test]
    fn well_inside_passes_inside_its_edge_only() {
        let shape = |closeness| {
            let list = ([0.3, 1.0, 0.1], [12.0, 0.5, -3.0], 0.2, 2e-6);
            tight_case(
                list,
                (
                    1.0 / 240.0,
                    -9.0,
                    [[1.0, 0.0, 0.2], [0.5, 0.1, 1.0], [0.0, 0.3, 1.0]],
                ),
                (1.0, 1.0, closeness),
            )
        };
        let (h, tol) = (1.0 / 240.0, 2e-6);
        let (list, x, v, a) = shape(0.999);
        assert!(list.well_inside(x, v, a, h, tol));
        assert!(exact(&list, x, v, a, h, tol));
        let (list, x, v, a) = shape(1.001);
        assert!(!list.well_inside(x, v, a, h, tol));
        assert!(!exact(&list, x, v, a, h, tol));
    }
}
