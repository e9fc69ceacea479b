//! Overlap beyond the slop projected out of positions.

use super::*;

/// Share of an overlap the projection removes per pass.
pub(super) const PROJECTION: f32 = 0.5;
/// Most a pass moves a pair apart, as a fraction of the smaller radius; and however many
/// contacts push it, a marble moves at most one radius in a substep's projection. A
/// marble that does not touch a board is more than a radius from it, so its centre never
/// crosses a board however thin (the board stage pushes it back out), while a crash's deep
/// overlaps go within a few substeps (at a fiftieth of the radius per pass, pairs of a
/// one-substep pour stay 1.9 r inside each other for good).
pub(super) const MAX_PROJECTION: f32 = 0.25;

/// Position-projection passes per substep.
pub(super) const PROJECTION_PASSES: usize = 4;

/// A marble in the projection: its centre (`x`, `y`, `z`) and how far the projection may
/// still move it this substep (`w`), in one 16-byte lane set, as [`Vel`] holds its
/// velocity in the passes.
pub(super) type Centre = Vec4;

/// A marble's radius (`x`) and inverse mass (`y`) in the projection (`z`, `w` unused).
pub(super) type Size = Vec4;

/// Four pair rows of the projection side by side, a row to a lane, none sharing a marble
/// with another ([`PairSolver::order_pushes`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct PushBlock {
    pub(super) i: [u32; 4],
    pub(super) j: [u32; 4],
    /// The rows' normals' `x`, `y` and `z` (for a coincident pair).
    n: [Vec4; 3],
    pub(super) k: Vec4,
}

impl PushBlock {
    /// The block of four rows.
    pub(super) fn new(r: [&PairGs; 4]) -> PushBlock {
        let lanes = |f: fn(&PairGs) -> f32| Vec4::new(f(r[0]), f(r[1]), f(r[2]), f(r[3]));
        PushBlock {
            i: r.map(|r| r.i),
            j: r.map(|r| r.j),
            n: [lanes(|r| r.n.x), lanes(|r| r.n.y), lanes(|r| r.n.z)],
            k: lanes(|r| r.k),
        }
    }
}

impl PairSolver {
    /// Step 5 of [`crate::pairs`]: overlap beyond the slop out of positions, in passes
    /// over the pair rows and then the board rows, each in the rows' own order
    /// (`pair_gs`, then `board_push`).
    ///
    /// In a pile nearly every pair row pushes in every pass (the 10,000-marble pour at
    /// the pile bar, over its first second: 24,000 of its 33,000 rows on average, in each
    /// of the four), and the order
    /// matters: a pass in the rows' order sweeps the pile, one taken colour by colour
    /// does not (it left that pour stirring). So the pair rows keep their order, and are
    /// only regrouped where that changes nothing, by level ([`PairSolver::order_pushes`]),
    /// four rows of a level at once: the same bits as one row after another.
    // Out of line: see `PairSolver::run_passes`.
    #[inline(never)]
    pub(super) fn project(&mut self) {
        self.order_pushes();
        let (centres, sizes) = (&mut self.centres, &mut self.sizes);
        // Each marble moves at most one radius in all (see [`MAX_PROJECTION`]).
        centres.clear();
        centres.extend(self.bodies.iter().map(|b| b.x.extend(b.r)));
        sizes.clear();
        sizes.extend(self.bodies.iter().map(|b| Vec4::new(b.r, b.w, 0.0, 0.0)));
        let changed = &mut self.changed;
        for _ in 0..PROJECTION_PASSES {
            let mut moved = false;
            // Level by level: its rows' blocks, then the rest of its rows one by one.
            let (mut from, mut blocks) = (0, self.push_blocks.iter());
            for &to in &self.push_end {
                let of_level = &self.push_order[from..to as usize];
                let wide = of_level.len() / 4 * 4;
                for b in blocks.by_ref().take(wide / 4) {
                    moved |= project_block(b, centres, sizes, changed);
                }
                for &r in &of_level[wide..] {
                    moved |= project_pair(&self.pair_gs[r as usize], centres, sizes, changed);
                }
                from = to as usize;
            }
            for c in &self.board_push {
                let i = c.i as usize;
                let (x, left, r) = (centres[i].truncate(), centres[i].w, sizes[i].x);
                let gap = (x - c.p).dot(c.n) - r;
                if gap < -c.slop && left > 0.0 {
                    let most = (MAX_PROJECTION * r).min(left);
                    let push = (PROJECTION * (-c.slop - gap)).min(most);
                    centres[i] = (x + push * c.n).extend(left - push);
                    changed[i] = true;
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        for (b, c) in self.bodies.iter_mut().zip(centres.iter()) {
            b.x = c.truncate();
        }
    }

    /// The projection's order of the pair rows: by level, a row's level being one more
    /// than the highest of the earlier rows (in `pair_gs`) of its two marbles, and within a
    /// level in the rows' order, as blocks of four and then single rows. Rows of a level
    /// share no marble; rows that share one keep their order (the later one's level is
    /// higher), and rows that share none commute, so a pass in this order gives the bits
    /// of a pass in the rows' own, with the rows of a level free to go at once (the
    /// 10,000-marble pour's 35,000 rows at half a second fall into about 860 levels).
    /// Leaves `push_order` (the rows by level), `push_end` (where each level ends
    /// there) and `push_blocks`
    /// (each level's rows by four, the last one to three of a level left out).
    pub(super) fn order_pushes(&mut self) {
        let rows = &self.pair_gs;
        let (last, level, end, order) = (
            &mut self.push_last,
            &mut self.push_level,
            &mut self.push_end,
            &mut self.push_order,
        );
        // `last[m]`: one more than the level of marble m's latest row.
        last.clear();
        last.resize(self.bodies.len(), 0);
        level.clear();
        let mut levels = 0;
        for r in rows {
            let (i, j) = (r.i as usize, r.j as usize);
            let l = last[i].max(last[j]);
            level.push(l);
            last[i] = l + 1;
            last[j] = l + 1;
            levels = levels.max(l + 1);
        }
        // The rows by level, in order within each (a counting sort: `end[l]` is where
        // level l starts until the scatter has moved it past the level's rows).
        end.clear();
        end.resize(levels as usize + 1, 0);
        for &l in level.iter() {
            end[l as usize + 1] += 1;
        }
        for l in 0..levels as usize {
            end[l + 1] += end[l];
        }
        order.clear();
        order.resize(rows.len(), 0);
        for (k, &l) in level.iter().enumerate() {
            order[end[l as usize] as usize] = k as u32;
            end[l as usize] += 1;
        }
        // `end[l]`: where level l ends in `order`.
        end.pop();
        let blocks = &mut self.push_blocks;
        blocks.clear();
        let mut from = 0;
        for &to in end.iter() {
            let of_level = &order[from..to as usize];
            for four in of_level.chunks_exact(4) {
                blocks.push(PushBlock::new(
                    [0, 1, 2, 3].map(|l| &rows[four[l] as usize]),
                ));
            }
            from = to as usize;
        }
    }
}

/// One pair row's projection: a pair overlapping beyond the slop (0.2% of the smaller
/// radius) is pushed apart by [`PROJECTION`] of the excess, at most [`MAX_PROJECTION`] of
/// the smaller radius, shared by inverse mass and within what each marble may still move.
/// Returns whether it moved them.
#[inline(always)]
pub(super) fn project_pair(
    row: &PairGs,
    centres: &mut [Centre],
    sizes: &[Size],
    changed: &mut [bool],
) -> bool {
    let (i, j) = (row.i as usize, row.j as usize);
    let (a, b) = (centres[i], centres[j]);
    let (ra, rb) = (sizes[i].x, sizes[j].x);
    let d = b.truncate() - a.truncate();
    let dist = d.length();
    let gap = dist - ra - rb;
    // The pair's allowed overlap (0.2% of the smaller radius).
    let slop = PAIR_SLOP * ra.min(rb);
    if gap < -slop {
        let n = if dist > 0.0 { d / dist } else { row.n };
        let push = (PROJECTION * (-slop - gap)).min(MAX_PROJECTION * ra.min(rb)) * row.k;
        let pi = (push * sizes[i].y).min(a.w);
        let pj = (push * sizes[j].y).min(b.w);
        if pi <= 0.0 && pj <= 0.0 {
            return false;
        }
        centres[i] = (a.truncate() - pi * n).extend(a.w - pi);
        centres[j] = (b.truncate() + pj * n).extend(b.w - pj);
        changed[i] = true;
        changed[j] = true;
        return true;
    }
    false
}

/// [`project_pair`] on a block's four rows, a row to a lane: no two of them share a
/// marble, so each lane does that row's operations in their order (the same bits as the
/// four one after another), a lane that pushes nothing keeping its marbles as they were.
#[inline(always)]
pub(super) fn project_block(
    block: &PushBlock,
    centres: &mut [Centre],
    sizes: &[Size],
    changed: &mut [bool],
) -> bool {
    let [i0, i1, i2, i3] = block.i.map(|i| i as usize);
    let [j0, j1, j2, j3] = block.j.map(|j| j as usize);
    // By lane: x_axis holds the four marbles' x, and so on (w: what each may still move).
    let a = Mat4::from_cols(centres[i0], centres[i1], centres[i2], centres[i3]).transpose();
    let b = Mat4::from_cols(centres[j0], centres[j1], centres[j2], centres[j3]).transpose();
    // x_axis: radii, y_axis: inverse masses.
    let sa = Mat4::from_cols(sizes[i0], sizes[i1], sizes[i2], sizes[i3]).transpose();
    let sb = Mat4::from_cols(sizes[j0], sizes[j1], sizes[j2], sizes[j3]).transpose();
    let (ra, rb) = (sa.x_axis, sb.x_axis);
    let (dx, dy, dz) = (
        b.x_axis - a.x_axis,
        b.y_axis - a.y_axis,
        b.z_axis - a.z_axis,
    );
    // `Vec3::length`'s sum order.
    let dist = (dx * dx + dy * dy + dz * dz).sqrt();
    let gap = dist - ra - rb;
    let smaller = ra.min(rb);
    let slop = PAIR_SLOP * smaller;
    let over = gap.cmplt(-slop);
    if !over.any() {
        return false;
    }
    let [nx, ny, nz] = block.n;
    let apart = dist.cmpgt(Vec4::ZERO);
    let (nx, ny, nz) = (
        Vec4::select(apart, dx / dist, nx),
        Vec4::select(apart, dy / dist, ny),
        Vec4::select(apart, dz / dist, nz),
    );
    let push = (PROJECTION * (-slop - gap)).min(MAX_PROJECTION * smaller) * block.k;
    let pi = (push * sa.y_axis).min(a.w_axis);
    let pj = (push * sb.y_axis).min(b.w_axis);
    let moves = over & !(pi.cmple(Vec4::ZERO) & pj.cmple(Vec4::ZERO));
    if !moves.any() {
        return false;
    }
    let a = Mat4::from_cols(
        Vec4::select(moves, a.x_axis - pi * nx, a.x_axis),
        Vec4::select(moves, a.y_axis - pi * ny, a.y_axis),
        Vec4::select(moves, a.z_axis - pi * nz, a.z_axis),
        Vec4::select(moves, a.w_axis - pi, a.w_axis),
    )
    .transpose();
    let b = Mat4::from_cols(
        Vec4::select(moves, b.x_axis + pj * nx, b.x_axis),
        Vec4::select(moves, b.y_axis + pj * ny, b.y_axis),
        Vec4::select(moves, b.z_axis + pj * nz, b.z_axis),
        Vec4::select(moves, b.w_axis - pj, b.w_axis),
    )
    .transpose();
    (centres[i0], centres[i1], centres[i2], centres[i3]) = (a.x_axis, a.y_axis, a.z_axis, a.w_axis);
    (centres[j0], centres[j1], centres[j2], centres[j3]) = (b.x_axis, b.y_axis, b.z_axis, b.w_axis);
    let mut lanes = moves.bitmask();
    while lanes != 0 {
        let lane = lanes.trailing_zeros() as usize;
        changed[block.i[lane] as usize] = true;
        changed[block.j[lane] as usize] = true;
        lanes &= lanes - 1;
    }
    true
}
