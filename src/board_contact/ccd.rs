//! Continuous collision: the first time along a marble's path at which it reaches a piece
//! it does not touch yet (conservative advancement).

use super::*;

/// Conservative-advancement iterations per piece before giving up on convergence (the
/// marble is then advanced to the last safe time and the search resumes from there).
pub(super) const MAX_ADVANCE_ITERATIONS: u32 = 64;

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
    let PathBounds {
        end,
        bulge,
        world,
        centres,
        marble_speed,
    } = PathBounds::new(path, span, r, tol);
    let hint = -path.v;
    let mut best: Option<(f32, PieceId)> = None;

    for (bi, b) in boards.iter().enumerate() {
        if let Some(a) = &b.swept_aabb
            && !overlaps(a, &world)
        {
            continue;
        }
        let sweep = Sweep::new(b, path, span, marble_speed);
        let Sweep {
            c0,
            q0,
            moving,
            w,
            u0,
            bb,
            curl,
            speed,
        } = sweep;
        let face_speed = |n0: Vec3| {
            n0.dot(u0).abs()
                + span * n0.dot(bb).abs()
                + curl
                + w * span * (u0.length() + span * bb.length() + curl)
        };
        if speed <= 0.0 {
            continue;
        }
        let list = NearPieces::of(near, bi);
        let covered = list.is_some_and(|l| sweep.covered(l, path, end, bulge, span, tol));
        if covered && list.is_some_and(|l| l.pieces().iter().all(|&p| touching.contains(p))) {
            continue;
        }
        // Every piece farther at the start than the marble can close on it in the span
        // (with `tol` to spare): the first step of the advancement below passes the span's
        // end for each of them (`speed` bounds every piece's own, and the factor covers
        // the step's rounding), so none is met. (A marble touching a piece is not clear
        // of the board: not asked.)
        if covered
            && touching.is_empty()
            && list.is_some_and(|l| {
                l.clearance(q0.conjugate() * (path.x - c0), 0.0)
                    > speed * span * (1.0 + 16.0 * f32::EPSILON) + tol
            })
        {
            continue;
        }
        // Where the centre can be this substep, in the board's frame (for the flat-face
        // bound); a moving board sees it through both end poses and, if it turns, a margin
        // for the turn. Everything the marble can reach, the same way, bounds the board's
        // search where the list does not cover the path.
        let to_start = AabbTransform::new(q0.conjugate() * -c0, q0.conjugate());
        let to_end = moving.then(|| {
            let (c1, q1) = b.pose_at(path.t0 + span);
            AabbTransform::new(q1.conjugate() * -c1, q1.conjugate())
        });
        let turn = if moving {
            let far = (path.x - c0).length() + (marble_speed + b.velocity.length()) * span;
            w * span * far
        } else {
            0.0
        };
        let board_frame = |a: &Aabb| {
            let start = to_start.apply(a);
            match &to_end {
                Some(to_end) => {
                    let end = to_end.apply(a);
                    Aabb::new(
                        start.mins.min(end.mins) - Vec3::splat(turn),
                        start.maxs.max(end.maxs) + Vec3::splat(turn),
                    )
                }
                None => start,
            }
        };
        let centre_query = board_frame(&centres);
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
            _ => b.geometry.for_each_piece(&board_frame(&world), each),
        }
    }
    best
}

/// The bounds of a path over `span` for a marble of radius `r` (touching tolerance `tol`).
struct PathBounds {
    /// Centre at the span's end.
    end: Vec3,
    /// The parabola's bulge beyond its chord (⅛ |a| span², rounded up).
    bulge: f32,
    /// Everything the marble can reach, world.
    world: Aabb,
    /// Where the centre itself can be (no radius), world: for the flat-face bound.
    centres: Aabb,
    /// Bound of the marble's speed over the span.
    marble_speed: f32,
}

impl PathBounds {
    #[inline(always)]
    fn new(path: &Path, span: f32, r: f32, tol: f32) -> Self {
        let end = path.position(span);
        let bulge = 0.25 * path.a.length() * span * span;
        let reach = r + tol + bulge;
        PathBounds {
            end,
            bulge,
            world: Aabb::new(
                path.x.min(end) - Vec3::splat(reach),
                path.x.max(end) + Vec3::splat(reach),
            ),
            centres: Aabb::new(
                path.x.min(end) - Vec3::splat(bulge),
                path.x.max(end) + Vec3::splat(bulge),
            ),
            marble_speed: path.v.length() + path.a.length() * span,
        }
    }
}

/// A path's motion relative to one board over `span`.
#[derive(Clone, Copy)]
struct Sweep {
    /// The board's pose at the path's start.
    c0: Vec3,
    q0: Quat,
    moving: bool,
    /// The board's turning rate, rad/s.
    w: f32,
    /// The marble's velocity relative to the board's material point under it, at the
    /// path's start.
    u0: Vec3,
    /// The rate of that relative velocity, less the turning of the frame.
    bb: Vec3,
    /// The bound of the frame's turning of the acceleration over the span.
    curl: f32,
    /// Speed bound of the marble relative to the board's frame (a still board: the
    /// marble's own speed bound).
    speed: f32,
}

impl Sweep {
    #[inline(always)]
    fn new(b: &BoardSnapshot, path: &Path, span: f32, marble_speed: f32) -> Self {
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
        // For a moving board: the distance to a piece changes no faster than the
        // marble's position in the board's frame, y = Rᵀ(x − c), whose rate is the
        // marble's velocity relative to the board's material point under it:
        //   ẏ = Rᵀ(u0 + τ (a − ω × (v − v_b)) − ½ τ² ω × a),
        //   u0 = v − v_b − ω × (x − c) at the path's start.
        // A marble riding a turning board has u0 ≈ 0, so the bound stays tight where
        // the board's own speed would make conservative advancement crawl.
        let speed = if moving {
            u0.length() + span * bb.length() + curl
        } else {
            marble_speed
        };
        Sweep {
            c0,
            q0,
            moving,
            w,
            u0,
            bb,
            curl,
            speed,
        }
    }

    /// Whether the marble's list covers every centre of the path in the board's frame:
    /// on a still board they lie within half the chord and the bulge of the chord's
    /// middle, on a moving one within `speed · span` of the start.
    #[inline(always)]
    fn covered(
        &self,
        list: &NearPieces,
        path: &Path,
        end: Vec3,
        bulge: f32,
        span: f32,
        tol: f32,
    ) -> bool {
        if self.moving {
            list.covers(
                self.q0.conjugate() * (path.x - self.c0),
                self.speed * span,
                tol,
            )
        } else {
            let spread = 0.5 * (end - path.x).length() + bulge;
            list.covers(
                self.q0.conjugate() * (0.5 * (path.x + end) - self.c0),
                spread,
                tol,
            )
        }
    }
}

/// Whether a marble at the start of `path` (time `path.t0` of the substep), shown `clear`
/// of `board`, the scene's only board, by its list `near` there (the clearance
/// [`gather_single`](super::gather_single) returns at that time and centre), stays clear
/// for the whole `span`: the list covers the path, and `clear` exceeds what the marble
/// can close on any piece in the span, with `tol` to spare. Then [`earliest_impact`]
/// finds no impact, skipping the board on this same test, bit for bit.
pub(crate) fn path_is_clear(
    board: &BoardSnapshot,
    near: &NearPieces,
    path: &Path,
    span: f32,
    r: f32,
    tol: f32,
    clear: f32,
) -> bool {
    let bounds = PathBounds::new(path, span, r, tol);
    let sweep = Sweep::new(board, path, span, bounds.marble_speed);
    sweep.covered(near, path, bounds.end, bounds.bulge, span, tol)
        && clear > sweep.speed * span * (1.0 + 16.0 * f32::EPSILON) + tol
}

/// Whether [`earliest_impact`] of `path` over `span` finds nothing, for a marble touching
/// the pieces in `touching` of `board`, the only board, with `list` its near-piece list:
/// the path stays away from the board, or within what the list covers, and each listed
/// piece the marble does not touch is, at the path's start, within `tol` (the search
/// takes it for touched) or farther than the marble can close in the span with `tol` to
/// spare (the search's first step passes the span's end: `speed` bounds every piece's
/// own, and the factor covers the step's rounding). The gaps are the search's own, bit
/// for bit.
pub(crate) fn touched_path_is_clear(
    board: &BoardSnapshot,
    list: &NearPieces,
    touching: &TouchList,
    path: &Path,
    span: f32,
    r: f32,
    tol: f32,
) -> bool {
    let bounds = PathBounds::new(path, span, r, tol);
    if let Some(a) = &board.swept_aabb
        && !overlaps(a, &bounds.world)
    {
        return true;
    }
    let sweep = Sweep::new(board, path, span, bounds.marble_speed);
    if sweep.speed <= 0.0 {
        return true;
    }
    if !sweep.covered(list, path, bounds.end, bounds.bulge, span, tol) {
        return false;
    }
    let closing = sweep.speed * span * (1.0 + 16.0 * f32::EPSILON) + tol;
    // As the search's `gap_at(0)`: the board at the path's start.
    let inv = sweep.q0.conjugate();
    let local = inv * (path.position(0.0) - sweep.c0);
    let hint = inv * -path.v;
    list.pieces().iter().all(|&id| {
        touching.contains(id) || {
            let piece = board.geometry.piece(id.part(), id.sub());
            let gap = board
                .geometry
                .proximity(id.part(), &piece, local, hint)
                .distance
                - r;
            gap <= tol || gap > closing
        }
    })
}
