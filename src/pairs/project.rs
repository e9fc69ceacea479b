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

impl PairSolver {
    /// Step 5 of [`crate::pairs`]: overlap beyond the slop out of positions.
    // Out of line: see `PairSolver::run_passes`.
    #[inline(never)]
    pub(super) fn project(&mut self) {
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
