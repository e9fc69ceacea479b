//! Line drawings of board shapes for the replay page and the top-view plot: each shape as
//! segments in the board's frame, outlines and edges only (the edges of a box, the rim of a
//! bowl, the border, holes and creases of a mesh).

use std::collections::HashMap;

use glam::Vec3;

use crate::geometry::{BoardGeometry, PartShape};

/// A mesh edge whose two faces meet at more than this angle is drawn (cos of 8°); flat
/// and gently curved surfaces show only their borders, holes and creases.
const CREASE_COS: f32 = 0.990;

/// The most segments drawn for one board; a larger drawing keeps every k-th segment.
pub const MAX_SEGMENTS: usize = 40_000;

/// The segments of `geometry` in the board's frame. A half-space (unbounded) is drawn as
/// a square grid of half-size `extent` on its plane.
pub fn segments(geometry: &BoardGeometry, extent: f32) -> Vec<[Vec3; 2]> {
    let mut out = Vec::new();
    for part in geometry.parts() {
        let start = out.len();
        match &part.shape {
            PartShape::HalfSpace(_) => grid(&mut out, extent),
            PartShape::Cuboid(c) => cuboid(&mut out, c.half_extents),
            PartShape::TriMesh(m) => {
                let v = m.vertices();
                creases(
                    &mut out,
                    m.indices().iter().map(|t| t.map(|i| v[i as usize])),
                );
            }
            PartShape::HeightField(h) => creases(&mut out, h.triangles().map(|t| [t.a, t.b, t.c])),
            PartShape::Bowl(r) => bowl(&mut out, *r),
        }
        for s in &mut out[start..] {
            *s = s.map(|p| part.translation + part.rotation * p);
        }
    }
    if out.len() > MAX_SEGMENTS {
        let k = out.len().div_ceil(MAX_SEGMENTS);
        out = out.into_iter().step_by(k).collect();
    }
    out
}

fn grid(out: &mut Vec<[Vec3; 2]>, extent: f32) {
    const LINES: i32 = 10;
    for i in -LINES / 2..=LINES / 2 {
        let c = extent * i as f32 / (LINES / 2) as f32;
        out.push([Vec3::new(c, 0.0, -extent), Vec3::new(c, 0.0, extent)]);
        out.push([Vec3::new(-extent, 0.0, c), Vec3::new(extent, 0.0, c)]);
    }
}

fn cuboid(out: &mut Vec<[Vec3; 2]>, h: Vec3) {
    let corner = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { -h.x } else { h.x },
            if i & 2 == 0 { -h.y } else { h.y },
            if i & 4 == 0 { -h.z } else { h.z },
        )
    };
    for i in 0..8u32 {
        for bit in [1, 2, 4] {
            if i & bit == 0 {
                out.push([corner(i), corner(i | bit)]);
            }
        }
    }
}

fn bowl(out: &mut Vec<[Vec3; 2]>, r: f32) {
    const AROUND: usize = 48;
    let at = |polar: f32, azimuth: f32| {
        Vec3::new(
            r * polar.sin() * azimuth.cos(),
            -r * polar.cos(),
            r * polar.sin() * azimuth.sin(),
        )
    };
    let tau = std::f32::consts::TAU;
    // The rim and two circles below it, then eight meridians from the rim to the bottom.
    for polar in [90f32, 60.0, 30.0].map(f32::to_radians) {
        for k in 0..AROUND {
            let (a0, a1) = (
                tau * k as f32 / AROUND as f32,
                tau * (k + 1) as f32 / AROUND as f32,
            );
            out.push([at(polar, a0), at(polar, a1)]);
        }
    }
    for m in 0..8 {
        let azimuth = tau * m as f32 / 8.0;
        for k in 0..12 {
            let (p0, p1) = (
                std::f32::consts::FRAC_PI_2 * k as f32 / 12.0,
                std::f32::consts::FRAC_PI_2 * (k + 1) as f32 / 12.0,
            );
            out.push([at(p0, azimuth), at(p1, azimuth)]);
        }
    }
}

/// The border, hole and crease edges of a triangle soup: edges with one face, more than
/// two, or two whose normals differ by more than the crease angle. Vertices are matched
/// by their exact coordinates.
fn creases(out: &mut Vec<[Vec3; 2]>, triangles: impl Iterator<Item = [Vec3; 3]>) {
    type Key = [u32; 3];
    let key = |p: Vec3| p.to_array().map(f32::to_bits);
    let mut edges: HashMap<(Key, Key), (Vec3, Vec3, Vec3, u32)> = HashMap::new();
    for t in triangles {
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (ka, kb) = (key(a), key(b));
            let (k, a, b) = if ka <= kb {
                ((ka, kb), a, b)
            } else {
                ((kb, ka), b, a)
            };
            edges
                .entry(k)
                .and_modify(|e| {
                    // Two-sided faces: the crease is the angle between the lines of the
                    // normals, whichever way each face was wound.
                    if e.2.dot(n).abs() < CREASE_COS {
                        e.3 = e.3.max(3);
                    }
                    e.3 += 1;
                })
                .or_insert((a, b, n, 1));
        }
    }
    let mut kept: Vec<_> = edges
        .into_iter()
        .filter(|(_, e)| e.3 != 2)
        .map(|(k, e)| (k, [e.0, e.1]))
        .collect();
    // HashMap order is not deterministic: sort, so the same board draws the same file.
    kept.sort_unstable_by_key(|(k, _)| *k);
    out.extend(kept.into_iter().map(|(_, s)| s));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::ShapeDesc;

    #[test]
    fn a_box_has_twelve_edges_of_its_sizes() {
        let g = ShapeDesc::Cuboid {
            half_extents: [1.0, 2.0, 3.0],
        }
        .build();
        let s = segments(&g, 1.0);
        assert_eq!(s.len(), 12);
        let mut lengths: Vec<f32> = s.iter().map(|[a, b]| (*b - *a).length()).collect();
        lengths.sort_by(f32::total_cmp);
        assert_eq!(lengths, [[2.0; 4], [4.0; 4], [6.0; 4]].concat());
    }

    #[test]
    fn a_flat_mesh_shows_its_border_and_its_hole_only() {
        // A 3 × 3 grid of unit squares (two triangles each) with the middle square left
        // out: 12 border edges outside, 4 around the hole, none inside.
        let mut vertices = Vec::new();
        for i in 0..4 {
            for j in 0..4 {
                vertices.push([j as f32, 0.0, i as f32]);
            }
        }
        let mut indices = Vec::new();
        for i in 0..3u32 {
            for j in 0..3u32 {
                if (i, j) == (1, 1) {
                    continue;
                }
                let v = i * 4 + j;
                indices.push([v, v + 4, v + 1]);
                indices.push([v + 1, v + 4, v + 5]);
            }
        }
        let g = ShapeDesc::TriMesh { vertices, indices }.build();
        let s = segments(&g, 1.0);
        assert_eq!(s.len(), 16);
        let inner = s
            .iter()
            .filter(|[a, b]| {
                [a, b]
                    .iter()
                    .all(|p| (1.0..=2.0).contains(&p.x) && (1.0..=2.0).contains(&p.z))
            })
            .count();
        assert_eq!(inner, 4);
    }

    #[test]
    fn a_folded_mesh_shows_its_crease() {
        // Two triangles meeting at 90° along the Z axis: the shared edge is a crease.
        let vertices = vec![
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let indices = vec![[0, 1, 2], [0, 3, 1]];
        let g = ShapeDesc::TriMesh { vertices, indices }.build();
        assert_eq!(segments(&g, 1.0).len(), 5);
    }

    #[test]
    fn compound_parts_are_drawn_at_their_pose() {
        let g = ShapeDesc::Compound(vec![crate::scene::PartDesc {
            shape: ShapeDesc::Cuboid {
                half_extents: [0.5; 3],
            },
            position: [10.0, 0.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        }])
        .build();
        for p in segments(&g, 1.0).iter().flatten() {
            assert!((p.x - 10.0).abs() == 0.5, "{p}");
        }
    }
}
