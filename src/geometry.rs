//! Board shapes, reduced to convex pieces for sphere queries.
//!
//! A marble is a sphere, so every marble–board question is a question about the marble's
//! *centre* and the board's surface: the marble touches a board when its centre lies within
//! `r` of it. Every contract shape is built from parry3d shapes whose point projection
//! answers that exactly:
//!
//! - `Plane` → parry's [`HalfSpace`] (solid below local y = 0),
//! - `Cuboid` → [`Cuboid`] (solid),
//! - `TriMesh` → [`TriMesh`]: its triangles, found through the mesh's BVH (both faces
//!   collide; a triangle has no inside),
//! - `HeightField` → [`HeightField`]: its triangles, found by cell range,
//! - `Compound` → a list of posed parts, each one of the above.
//!
//! Detection and continuous collision work on **pieces**: a half-space, a cuboid or a single
//! triangle. Each piece is convex, so the distance from a point to it is a well-behaved
//! function of time along a marble's path (continuous collision advances on it), and the
//! closest point on a piece gives an exact contact normal. Working per triangle rather than
//! per mesh lets a marble touch several faces of a concave mesh at once; the contact filter
//! in [`crate::board_contact`] drops the redundant contacts that internal edges and coplanar seams
//! would add ("ghost bumps").

use std::fmt;

use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;
use parry3d::query::PointQuery;
use parry3d::shape::{Cuboid, HalfSpace, HeightField, TriMesh, Triangle};

/// Identifies one convex piece of one board within a substep: the board's index in the
/// substep's board list, the compound part, and the triangle (0 for solid parts).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PieceId(pub u64);

impl PieceId {
    /// No piece.
    pub const NONE: PieceId = PieceId(u64::MAX);

    pub(crate) fn new(board: usize, part: usize, sub: u32) -> PieceId {
        PieceId(((board as u64) << 48) | ((part as u64 & 0xFFFF) << 32) | sub as u64)
    }

    /// Index of the board in the substep's board list.
    pub fn board(self) -> usize {
        (self.0 >> 48) as usize
    }

    /// Part within a compound board (0 otherwise).
    pub fn part(self) -> usize {
        ((self.0 >> 32) & 0xFFFF) as usize
    }

    /// Triangle index within a mesh or height field part (0 for solid parts).
    pub fn sub(self) -> u32 {
        self.0 as u32
    }
}

impl fmt::Debug for PieceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if *self == PieceId::NONE {
            return write!(f, "PieceId::NONE");
        }
        write!(
            f,
            "PieceId({}/{}/{})",
            self.board(),
            self.part(),
            self.sub()
        )
    }
}

/// One primitive shape of a board.
#[derive(Clone, Debug)]
pub enum PartShape {
    /// The half-space below the local plane y = 0 (outward normal +Y).
    HalfSpace(HalfSpace),
    /// A solid box centred on the part's origin.
    Cuboid(Cuboid),
    /// A triangle mesh; both faces collide.
    TriMesh(Box<TriMesh>),
    /// A height field centred on the part's origin.
    HeightField(Box<HeightField>),
    /// A spherical bowl: the lower half (y ≤ 0) of the sphere of this radius about the
    /// part's origin, as a surface (both faces collide). parry3d has no concave sphere, so
    /// this one piece is the engine's own; its distance is exact.
    Bowl(f32),
}

/// A shape with its pose in the board's frame.
#[derive(Clone, Debug)]
pub struct Part {
    /// Position of the part's origin in the board frame.
    pub translation: Vec3,
    /// Orientation of the part in the board frame.
    pub rotation: Quat,
    /// The shape.
    pub shape: PartShape,
    /// No rotation and no translation.
    identity: bool,
    /// No rotation (translation only).
    unrotated: bool,
    /// Bounds in the board frame; `None` for unbounded parts (half-spaces).
    aabb: Option<Aabb>,
}

/// A board's geometry: one or more posed parts (more than one for `Compound` boards).
#[derive(Clone, Debug)]
pub struct BoardGeometry {
    parts: Vec<Part>,
    aabb: Option<Aabb>,
    /// For compounds of many parts: a BVH over the bounded parts' bounds (leaf = part
    /// index), and the unbounded parts, so that a query visits only the parts it can reach
    /// (a labyrinth tiled over a large board has thousands of walls).
    index: Option<(parry3d::partitioning::Bvh, Vec<usize>)>,
}

/// Compounds with more parts than this get a BVH over their parts.
const PART_BVH_MIN: usize = 16;

/// A convex piece of a board, in its part's frame.
#[derive(Clone, Copy, Debug)]
pub enum Piece {
    /// The half-space below y = 0.
    HalfSpace,
    /// A solid box.
    Cuboid(Cuboid),
    /// One triangle (two-sided).
    Triangle(Triangle),
    /// The lower half of a sphere of this radius (two-sided, concave from inside).
    Bowl(f32),
}

/// Where a point is relative to a piece, in the board frame.
#[derive(Clone, Copy, Debug)]
pub struct Proximity {
    /// Signed distance from the point to the piece's surface, m (negative inside a solid).
    pub distance: f32,
    /// Closest point on the surface, board frame.
    pub point: Vec3,
    /// Unit normal from the surface towards the point, board frame.
    pub normal: Vec3,
}

impl BoardGeometry {
    /// A geometry with a single part at the board's origin.
    pub fn single(shape: PartShape) -> Self {
        BoardGeometry::compound(vec![(Vec3::ZERO, Quat::IDENTITY, shape)])
    }

    /// A geometry made of posed parts (pose in the board's frame).
    pub fn compound(parts: Vec<(Vec3, Quat, PartShape)>) -> Self {
        let parts: Vec<Part> = parts
            .into_iter()
            .map(|(translation, rotation, shape)| {
                let rotation = rotation.normalize();
                let local = match &shape {
                    PartShape::HalfSpace(_) => None,
                    PartShape::Cuboid(c) => Some(Aabb::new(-c.half_extents, c.half_extents)),
                    PartShape::TriMesh(m) => Some(m.local_aabb()),
                    PartShape::HeightField(h) => Some(*h.root_aabb()),
                    PartShape::Bowl(r) => {
                        Some(Aabb::new(Vec3::new(-r, -r, -r), Vec3::new(*r, 0.0, *r)))
                    }
                };
                Part {
                    translation,
                    rotation,
                    identity: translation == Vec3::ZERO && rotation == Quat::IDENTITY,
                    unrotated: rotation == Quat::IDENTITY,
                    aabb: local.map(|a| transform_aabb(&a, translation, rotation)),
                    shape,
                }
            })
            .collect();
        let aabb = parts.iter().try_fold(None::<Aabb>, |acc, p| {
            let a = p.aabb?;
            Some(Some(match acc {
                None => a,
                Some(b) => Aabb::new(b.mins.min(a.mins), b.maxs.max(a.maxs)),
            }))
        });
        let index = (parts.len() > PART_BVH_MIN).then(|| {
            let bvh = parry3d::partitioning::Bvh::from_iter(
                parry3d::partitioning::BvhBuildStrategy::Binned,
                parts
                    .iter()
                    .enumerate()
                    .filter_map(|(i, p)| p.aabb.map(|a| (i, a))),
            );
            let unbounded = (0..parts.len())
                .filter(|&i| parts[i].aabb.is_none())
                .collect();
            (bvh, unbounded)
        });
        BoardGeometry {
            parts,
            aabb: aabb.flatten(),
            index,
        }
    }

    /// The parts.
    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// Bounds in the board frame, `None` when a part is unbounded.
    pub fn local_aabb(&self) -> Option<Aabb> {
        self.aabb
    }

    /// Calls `f(part, sub, piece)` for every piece that may intersect `query` (board frame).
    #[inline]
    pub fn for_each_piece(&self, query: &Aabb, mut f: impl FnMut(usize, u32, &Piece)) {
        if let Some((bvh, unbounded)) = &self.index {
            for &i in unbounded {
                self.part_pieces(i, query, &mut f);
            }
            for i in bvh.intersect_aabb(query) {
                self.part_pieces(i as usize, query, &mut f);
            }
            return;
        }
        for (i, part) in self.parts.iter().enumerate() {
            if let Some(a) = &part.aabb
                && !overlaps(a, query)
            {
                continue;
            }
            self.part_pieces(i, query, &mut f);
        }
    }

    /// The pieces of part `i` that may intersect `query` (board frame).
    #[inline]
    fn part_pieces(&self, i: usize, query: &Aabb, f: &mut impl FnMut(usize, u32, &Piece)) {
        let part = &self.parts[i];
        {
            let q = if part.identity {
                *query
            } else if part.unrotated {
                Aabb::new(query.mins - part.translation, query.maxs - part.translation)
            } else {
                inverse_transform_aabb(query, part.translation, part.rotation)
            };
            match &part.shape {
                PartShape::HalfSpace(_) => {
                    if q.mins.y <= 0.0 {
                        f(i, 0, &Piece::HalfSpace)
                    }
                }
                PartShape::Cuboid(c) => f(i, 0, &Piece::Cuboid(*c)),
                PartShape::TriMesh(m) => {
                    for id in m.bvh().intersect_aabb(&q) {
                        f(i, id, &Piece::Triangle(m.triangle(id)));
                    }
                }
                PartShape::Bowl(r) => f(i, 0, &Piece::Bowl(*r)),
                PartShape::HeightField(h) => {
                    h.map_elements_in_local_aabb(&q, &mut |id, tri| {
                        f(i, id, &Piece::Triangle(*tri))
                    });
                }
            }
        }
    }

    /// When every marble centre in `region` (board frame) has its closest point on one flat
    /// face of `piece` — so that its distance to the piece is affine in the centre — that
    /// face's outward normal, board frame. Continuous collision then bounds the distance's
    /// rate by the normal speed alone.
    pub fn face_normal(&self, part: usize, piece: &Piece, region: &Aabb) -> Option<Vec3> {
        let p = &self.parts[part];
        let local = if p.identity {
            *region
        } else if p.unrotated {
            Aabb::new(region.mins - p.translation, region.maxs - p.translation)
        } else {
            inverse_transform_aabb(region, p.translation, p.rotation)
        };
        let n = match piece {
            Piece::HalfSpace => Vec3::Y,
            Piece::Cuboid(c) => {
                let h = c.half_extents;
                let within = |j: usize| local.mins[j] >= -h[j] && local.maxs[j] <= h[j];
                let mut found = None;
                for i in 0..3 {
                    let (j, k) = ((i + 1) % 3, (i + 2) % 3);
                    if within(j) && within(k) {
                        if local.mins[i] >= h[i] {
                            found = Some(Vec3::AXES[i]);
                        } else if local.maxs[i] <= -h[i] {
                            found = Some(-Vec3::AXES[i]);
                        }
                    }
                }
                found?
            }
            Piece::Triangle(_) | Piece::Bowl(_) => return None,
        };
        Some(if p.unrotated { n } else { p.rotation * n })
    }

    /// When piece `(part, sub)` is a half-space or a box and every centre within `spread` of
    /// `centre` (board frame) that lies in front of one of its faces has its closest point
    /// on that face, the face's outward normal (board frame): the distance from such a
    /// centre is then affine, `n·(y − centre)` plus the distance from `centre`.
    pub fn flat_face(&self, part: usize, sub: u32, centre: Vec3, spread: f32) -> Option<Vec3> {
        let p = &self.parts[part];
        let local = p.rotation.conjugate() * (centre - p.translation);
        let n = match self.piece(part, sub) {
            Piece::HalfSpace => Vec3::Y,
            Piece::Cuboid(c) => {
                let h = c.half_extents;
                // The face the centre is farthest in front of; the centres within `spread`
                // must stay inside that face's outline (those in front of the face then
                // have their closest point on it).
                let out = local.abs() - h;
                let i = if out.x >= out.y && out.x >= out.z {
                    0
                } else if out.y >= out.z {
                    1
                } else {
                    2
                };
                let (j, k) = ((i + 1) % 3, (i + 2) % 3);
                let inside = |a: usize| local[a].abs() + spread <= h[a];
                if !(inside(j) && inside(k)) {
                    return None;
                }
                Vec3::AXES[i] * local[i].signum()
            }
            Piece::Triangle(_) | Piece::Bowl(_) => return None,
        };
        Some(if p.unrotated { n } else { p.rotation * n })
    }

    /// Whether every piece of part `part` is convex.
    #[inline]
    pub fn part_is_convex(&self, part: usize) -> bool {
        match self.parts[part].shape {
            PartShape::HalfSpace(_)
            | PartShape::Cuboid(_)
            | PartShape::TriMesh(_)
            | PartShape::HeightField(_) => true,
            PartShape::Bowl(_) => false,
        }
    }

    /// The piece `(part, sub)` as enumerated by [`Self::for_each_piece`].
    #[inline]
    pub fn piece(&self, part: usize, sub: u32) -> Piece {
        match &self.parts[part].shape {
            PartShape::HalfSpace(_) => Piece::HalfSpace,
            PartShape::Cuboid(c) => Piece::Cuboid(*c),
            PartShape::TriMesh(m) => Piece::Triangle(m.triangle(sub)),
            PartShape::Bowl(r) => Piece::Bowl(*r),
            PartShape::HeightField(h) => Piece::Triangle(
                h.triangle_at_id(sub)
                    .expect("piece ids come from this height field"),
            ),
        }
    }

    /// Where the board-frame point `p` is relative to piece `piece` of part `part`.
    /// `hint` breaks the tie when `p` lies exactly on a triangle: the normal then points
    /// along it.
    #[inline]
    pub fn proximity(&self, part: usize, piece: &Piece, p: Vec3, hint: Vec3) -> Proximity {
        let part = &self.parts[part];
        if part.identity {
            return piece.proximity(p, hint);
        }
        if part.unrotated {
            let local = piece.proximity(p - part.translation, hint);
            return Proximity {
                point: local.point + part.translation,
                ..local
            };
        }
        let inv = part.rotation.conjugate();
        let local = piece.proximity(inv * (p - part.translation), inv * hint);
        Proximity {
            distance: local.distance,
            point: part.rotation * local.point + part.translation,
            normal: part.rotation * local.normal,
        }
    }
}

impl Piece {
    /// Whether the piece is convex.
    #[inline]
    pub fn is_convex(&self) -> bool {
        !matches!(self, Piece::Bowl(_))
    }

    /// Signed distance, closest point and normal of the piece-frame point `q`.
    #[inline]
    pub fn proximity(&self, q: Vec3, hint: Vec3) -> Proximity {
        match self {
            Piece::HalfSpace => Proximity {
                distance: q.y,
                point: Vec3::new(q.x, 0.0, q.z),
                normal: Vec3::Y,
            },
            Piece::Cuboid(c) => {
                let proj = c.project_local_point(q, false);
                let d = q - proj.point;
                let len = d.length();
                if len > f32::MIN_POSITIVE * 1e6 {
                    let n = d / len;
                    if proj.is_inside {
                        Proximity {
                            distance: -len,
                            point: proj.point,
                            normal: -n,
                        }
                    } else {
                        Proximity {
                            distance: len,
                            point: proj.point,
                            normal: n,
                        }
                    }
                } else {
                    // On the surface: the face whose plane is nearest.
                    let r = q.abs() / c.half_extents.max(Vec3::splat(f32::MIN_POSITIVE));
                    let axis = if r.x >= r.y && r.x >= r.z {
                        Vec3::X * q.x.signum()
                    } else if r.y >= r.z {
                        Vec3::Y * q.y.signum()
                    } else {
                        Vec3::Z * q.z.signum()
                    };
                    Proximity {
                        distance: 0.0,
                        point: q,
                        normal: axis,
                    }
                }
            }
            Piece::Bowl(radius) => bowl_proximity(*radius, q, hint),
            Piece::Triangle(t) => {
                let proj = t.project_local_point(q, false);
                let d = q - proj.point;
                let len = d.length();
                if len > f32::MIN_POSITIVE * 1e6 {
                    let mut normal = d / len;
                    // Over the face, or over an edge or vertex the face meets flush
                    // (within the f32 resolution of its coordinates), the exact normal is the face's: the radial
                    // direction would carry the projection's rounding error (1e-5 rad for
                    // a marble above a seam) into the contact normal.
                    if let Some(face) = t.normal() {
                        let along = d.dot(face);
                        let off_plane = (d - along * face).length();
                        let scale = t.a.abs().max(t.b.abs()).max(t.c.abs()).max(q.abs());
                        if off_plane <= 16.0 * f32::EPSILON * (scale.max_element() + len) {
                            normal = face * along.signum();
                        }
                    }
                    Proximity {
                        distance: len,
                        point: proj.point,
                        normal,
                    }
                } else {
                    let mut n = t.normal().unwrap_or(Vec3::Y);
                    if n.dot(hint) < 0.0 {
                        n = -n;
                    }
                    Proximity {
                        distance: 0.0,
                        point: q,
                        normal: n,
                    }
                }
            }
        }
    }
}

/// Distance from `q` to the lower half (y ≤ 0) of the sphere of radius `radius` about the
/// origin: to the sphere itself below the equator, to its rim circle above it.
fn bowl_proximity(radius: f32, q: Vec3, hint: Vec3) -> Proximity {
    let len = q.length();
    let closest = if q.y <= 0.0 {
        if len <= f32::MIN_POSITIVE * 1e6 {
            // The centre: every point of the bowl is `radius` away; take the bottom.
            return Proximity {
                distance: radius,
                point: Vec3::new(0.0, -radius, 0.0),
                normal: Vec3::Y,
            };
        }
        q * (radius / len)
    } else {
        let flat = Vec3::new(q.x, 0.0, q.z);
        let f = flat.length();
        if f > 0.0 {
            flat * (radius / f)
        } else {
            Vec3::new(radius, 0.0, 0.0)
        }
    };
    let d = q - closest;
    let distance = d.length();
    let normal = if distance > f32::MIN_POSITIVE * 1e6 {
        d / distance
    } else {
        // On the surface: the sphere's normal, oriented by the hint.
        let n = closest / radius;
        if n.dot(hint) < 0.0 { -n } else { n }
    };
    Proximity {
        distance,
        point: closest,
        normal,
    }
}

fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    a.mins.cmple(b.maxs).all() && b.mins.cmple(a.maxs).all()
}

/// Bounds of `a` after rotating by `r` then translating by `t`.
pub(crate) fn transform_aabb(a: &Aabb, t: Vec3, r: Quat) -> Aabb {
    AabbTransform::new(t, r).apply(a)
}

/// A rotation `r` then a translation `t` of bounds, its matrices made once for every
/// box it applies to ([`transform_aabb`] of each, the same bits).
#[derive(Clone, Copy)]
pub(crate) struct AabbTransform {
    m: glam::Mat3,
    abs: glam::Mat3,
    t: Vec3,
}

impl AabbTransform {
    #[inline(always)]
    pub(crate) fn new(t: Vec3, r: Quat) -> Self {
        let m = glam::Mat3::from_quat(r);
        let abs = glam::Mat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        AabbTransform { m, abs, t }
    }

    /// The bounds of `a` moved.
    #[inline(always)]
    pub(crate) fn apply(&self, a: &Aabb) -> Aabb {
        let c = (a.mins + a.maxs) * 0.5;
        let h = (a.maxs - a.mins) * 0.5;
        let c2 = self.m * c + self.t;
        let h2 = self.abs * h;
        Aabb::new(c2 - h2, c2 + h2)
    }
}

/// Bounds of `a` brought into the frame whose pose (in `a`'s frame) is `(t, r)`.
pub(crate) fn inverse_transform_aabb(a: &Aabb, t: Vec3, r: Quat) -> Aabb {
    let inv = r.conjugate();
    transform_aabb(a, inv * -t, inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cuboid_signed_distance_inside_and_outside() {
        let c = Piece::Cuboid(Cuboid::new(Vec3::new(1.0, 0.5, 1.0)));
        let out = c.proximity(Vec3::new(0.2, 0.8, 0.0), Vec3::Y);
        assert!((out.distance - 0.3).abs() < 1e-6);
        assert!((out.normal - Vec3::Y).length() < 1e-6);
        let inside = c.proximity(Vec3::new(0.2, 0.4, 0.0), Vec3::Y);
        assert!((inside.distance + 0.1).abs() < 1e-6);
        assert!((inside.normal - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn compound_part_pose_is_applied() {
        let g = BoardGeometry::compound(vec![(
            Vec3::new(0.0, 1.0, 0.0),
            Quat::from_rotation_z(core::f32::consts::FRAC_PI_2),
            PartShape::HalfSpace(HalfSpace::new(Vec3::Y)),
        )]);
        // The part's +Y points along world −X; its plane passes through (0, 1, 0).
        let p = g.proximity(0, &Piece::HalfSpace, Vec3::new(-0.5, 3.0, 0.0), Vec3::Y);
        assert!((p.distance - 0.5).abs() < 1e-6);
        assert!((p.normal - -Vec3::X).length() < 1e-6);
    }

    #[test]
    fn piece_id_round_trips() {
        let id = PieceId::new(3, 7, 123_456);
        assert_eq!((id.board(), id.part(), id.sub()), (3, 7, 123_456));
    }
}
