//! The kept candidate pairs (a Verlet list over the substeps) and the strays that left
//! their skins.

use super::*;

/// Room added around each marble's bound sphere when the candidate pairs are found, as a
/// fraction of its radius: the pairs stand until a marble moves this far from where it
/// was relative to the marbles' common drift ([`crate::pairs`], step 1).
pub(super) const SKIN: f32 = 0.25;

/// The candidate pairs are found afresh when more than this share of the marbles left
/// their skins (fewer are paired one by one).
pub(super) const STRAY_SHARE: usize = 8;

/// The candidate pairs of the last [`PairSolver::cover`]: the standing candidates of
/// marbles that stayed inside their bounds, and the strays' pairs.
pub(super) fn candidate_pairs<'a>(
    candidates: &'a [(u32, u32)],
    extra: &'a [(u32, u32)],
    stray: &'a [bool],
    strays: &[u32],
) -> impl Iterator<Item = (u32, u32)> + 'a {
    let any = !strays.is_empty();
    candidates
        .iter()
        .filter(move |&&(i, j)| !(any && (stray[i as usize] || stray[j as usize])))
        .chain(extra)
        .copied()
}

impl PairSolver {
    /// Makes the candidate pairs ([`candidate_pairs`]) hold every pair of bodies whose
    /// spheres `sphere(body)` (centre, radius) overlap ([`crate::pairs`], step 1).
    ///
    /// The candidates found on the bound spheres (each body's sphere when they were found,
    /// grown by [`SKIN`]) stand while every body's sphere stays inside its bound, measured
    /// after taking off the bodies' common drift since then (their mean displacement: two
    /// bodies' distance changes only by their displacements relative to any common one, so
    /// marbles sliding down a board together keep their pairs). Bodies that left their
    /// bound (strays) are paired afresh: with the others through the grid of bounds, with
    /// each other through a grid of their own. When the bodies changed, or more than one
    /// in [`STRAY_SHARE`] strayed, the candidates are found afresh.
    #[cfg(test)]
    pub(super) fn cover(&mut self, sphere: impl Fn(&Body) -> Vec4) {
        self.spheres.clear();
        self.radii.clear();
        self.gathered.clear();
        for b in &self.bodies {
            self.spheres.push(sphere(b));
            self.radii.push(b.r);
            self.gathered.push(b.entity);
        }
        self.cover_spheres();
    }

    /// [`PairSolver::cover`] on the gathered spheres.
    pub(super) fn cover_spheres(&mut self) {
        let n = self.spheres.len();
        self.extra.clear();
        self.strays.clear();
        self.stray.clear();
        self.stray.resize(n, false);
        let same =
            self.skin_valid && n > 0 && self.bound.len() == n && self.entities == self.gathered;
        if same {
            let sum = self
                .spheres
                .iter()
                .zip(&self.bound)
                .fold(Vec3::ZERO, |acc, (s, b)| {
                    acc + (s.truncate() - b.truncate())
                });
            let drift = sum / n as f32;
            for (k, (s, b)) in self.spheres.iter().zip(&self.bound).enumerate() {
                if (s.truncate() - drift - b.truncate()).length() + s.w > b.w {
                    self.stray[k] = true;
                    self.strays.push(k as u32);
                }
            }
            if self.strays.len() * STRAY_SHARE <= n {
                self.drift = drift;
                self.pair_strays();
                return;
            }
            self.strays.clear();
            self.stray.fill(false);
        }
        self.bound.clear();
        self.bound.extend(
            self.spheres
                .iter()
                .zip(&self.radii)
                .map(|(s, r)| s.truncate().extend(s.w + SKIN * r)),
        );
        self.grid.build(&self.bound);
        self.candidates.clear();
        let (candidates, grid, bound) = (&mut self.candidates, &self.grid, &self.bound);
        grid.pairs(bound, |i, j| candidates.push((i.min(j), i.max(j))));
        self.entities.clear();
        self.entities.extend_from_slice(&self.gathered);
        self.drift = Vec3::ZERO;
        self.skin_valid = true;
    }

    /// The candidate pairs of the strays of a [`PairSolver::cover`]: each stray against
    /// the bounds (its sphere moved back by the common drift), and strays against each
    /// other on their spheres.
    pub(super) fn pair_strays(&mut self) {
        if self.strays.is_empty() {
            return;
        }
        let (grid, bound, stray, extra) = (&self.grid, &self.bound, &self.stray, &mut self.extra);
        for &i in &self.strays {
            let s = self.spheres[i as usize];
            grid.query(bound, (s.truncate() - self.drift).extend(s.w), |j| {
                if !stray[j as usize] {
                    extra.push((i.min(j), i.max(j)));
                }
            });
        }
        self.scratch_bound.clear();
        self.scratch_bound
            .extend(self.strays.iter().map(|&i| self.spheres[i as usize]));
        self.scratch_grid.build(&self.scratch_bound);
        let strays = &self.strays;
        self.scratch_grid.pairs(&self.scratch_bound, |a, b| {
            let (i, j) = (strays[a as usize], strays[b as usize]);
            extra.push((i.min(j), i.max(j)));
        });
    }
}
