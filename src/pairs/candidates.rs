//! The kept candidate pairs (a Verlet list over the substeps) and the strays that left
//! their skins.

use std::ops::Range;
use std::sync::atomic::AtomicUsize;

use super::*;

/// Room added around each marble's bound sphere when the candidate pairs are found, as a
/// fraction of its radius: the pairs stand until a marble moves this far from where it
/// was relative to the marbles' common drift ([`crate::pairs`], step 1).
pub(super) const SKIN: f32 = 0.25;

/// A marble that moved relative to the drift gets, when the candidate pairs are found
/// afresh, a skin it would take about this many covers to cross at its pace since the
/// last bounds (at least [`SKIN`], at most [`MAX_SKIN`] of its radius).
pub(super) const SKIN_COVERS: f32 = 32.0;

/// The largest skin, as a fraction of the radius.
pub(super) const MAX_SKIN: f32 = 1.0;

/// The candidate pairs are found afresh when more than this share of the marbles left
/// their skins (fewer are paired one by one).
pub(super) const STRAY_SHARE: usize = 8;

/// Bodies per block of the common drift's sum ([`PairSolver::cover`]).
pub(super) const DRIFT_BLOCK: usize = 1024;

/// Blocks of [`DRIFT_BLOCK`] bodies: each block's slot for its sum, its spheres and its
/// bounds (the last block may be short).
struct DriftBlocks<'a> {
    sums: &'a mut [Vec3],
    spheres: &'a [Vec4],
    bound: &'a [Vec4],
}

impl crate::systems::Rows for DriftBlocks<'_> {
    const MIN_CHUNK: usize = 1;

    fn len(&self) -> usize {
        self.sums.len()
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        let at = (mid * DRIFT_BLOCK).min(self.spheres.len());
        let (sums0, sums1) = self.sums.split_at_mut(mid);
        let (s0, s1) = self.spheres.split_at(at);
        let (b0, b1) = self.bound.split_at(at);
        let head = DriftBlocks {
            sums: sums0,
            spheres: s0,
            bound: b0,
        };
        let tail = DriftBlocks {
            sums: sums1,
            spheres: s1,
            bound: b1,
        };
        (head, tail)
    }
}

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

/// [`for_placed_body_pairs`] without the places.
#[cfg(test)]
pub(super) fn for_body_pairs(
    candidates: &[(u32, u32)],
    extra: &[(u32, u32)],
    strays: (&[bool], &[u32]),
    local: Option<&[u32]>,
    mut each: impl FnMut((u32, u32)),
) {
    for_placed_body_pairs(0, candidates, extra, strays, local, |_, pair| each(pair));
}

/// Calls `each` with every candidate pair ([`candidate_pairs`]) in the bodies' indices (with
/// `local`, a selection ([`PairSolver::select_bodies`]), each marble's index among the
/// bodies) and its place in the order of `candidates` then `extra`, counted from `first`
/// (the pairs of strays left out counted too).
#[inline]
fn for_placed_body_pairs(
    first: u32,
    candidates: &[(u32, u32)],
    extra: &[(u32, u32)],
    (stray, strays): (&[bool], &[u32]),
    local: Option<&[u32]>,
    mut each: impl FnMut(u32, (u32, u32)),
) {
    let any = !strays.is_empty();
    let standing = (first..)
        .zip(candidates)
        .filter(move |&(_, &(i, j))| !(any && (stray[i as usize] || stray[j as usize])));
    let fresh = (first + candidates.len() as u32..).zip(extra);
    match local {
        Some(local) => {
            let mut each = |(at, &(i, j)): (u32, &(u32, u32))| {
                each(at, (local[i as usize], local[j as usize]))
            };
            standing.for_each(&mut each);
            fresh.for_each(each);
        }
        None => {
            let mut each = |(at, &pair): (u32, &(u32, u32))| each(at, pair);
            standing.for_each(&mut each);
            fresh.for_each(each);
        }
    }
}

/// The kept candidates and the strays' pairs (`extra`) at `range` of their order, the
/// kept ones first: a chunk of the candidate pairs.
#[inline]
fn cut<'a>(
    range: Range<usize>,
    candidates: &'a [(u32, u32)],
    extra: &'a [(u32, u32)],
) -> (&'a [(u32, u32)], &'a [(u32, u32)]) {
    let n = candidates.len();
    (
        &candidates[range.start.min(n)..range.end.min(n)],
        &extra[range.start.saturating_sub(n)..range.end.saturating_sub(n)],
    )
}

/// [`for_placed_body_pairs`] with `each` pushing what it finds of a pair (given with its
/// place) onto a buffer, which is `out`: with `parallel` (and the `parallel` feature), in
/// chunks of the pairs on the task pool, each chunk's into its own buffer of `chunks`,
/// joined in the chunks' order ([`grid::scan_chunked`]): the same values in the same order
/// either way.
#[expect(
    clippy::too_many_arguments,
    reason = "the candidate lists, handed over"
)]
pub(super) fn scan_body_pairs<T: Copy + Send>(
    candidates: &[(u32, u32)],
    extra: &[(u32, u32)],
    strays: (&[bool], &[u32]),
    local: Option<&[u32]>,
    parallel: bool,
    chunks: &mut Vec<Vec<T>>,
    out: &mut Vec<T>,
    each: impl Fn(u32, (u32, u32), &mut Vec<T>) + Sync,
) {
    let total = candidates.len() + extra.len();
    grid::scan_chunked(total, parallel, chunks, out, |range, found| {
        let first = range.start as u32;
        let (kept, extra) = cut(range, candidates, extra);
        for_placed_body_pairs(first, kept, extra, strays, local, |at, pair| {
            each(at, pair, found)
        });
    });
}

/// Whether `test` holds for any candidate pair ([`for_placed_body_pairs`]): with `parallel` (and
/// the `parallel` feature), the pairs are cut into chunks on the task pool, each of which
/// stops once any chunk has found one.
pub(super) fn any_body_pair(
    candidates: &[(u32, u32)],
    extra: &[(u32, u32)],
    strays: (&[bool], &[u32]),
    local: Option<&[u32]>,
    parallel: bool,
    test: impl Fn((u32, u32)) -> bool + Sync,
) -> bool {
    let total = candidates.len() + extra.len();
    if crate::systems::pool_chunks::<Range<usize>>(total, parallel) == 1 {
        return any_pair_in(0..total, candidates, extra, strays, local, test);
    }
    let found = AtomicBool::new(false);
    crate::systems::run_rows(0..total, parallel, |range| {
        let test = |pair| found.load(Ordering::Relaxed) || test(pair);
        if any_pair_in(range, candidates, extra, strays, local, test) {
            found.store(true, Ordering::Relaxed);
        }
    });
    found.into_inner()
}

/// Whether `test` holds for any candidate pair at `range` of their order ([`cut`]).
#[inline]
fn any_pair_in(
    range: Range<usize>,
    candidates: &[(u32, u32)],
    extra: &[(u32, u32)],
    strays: (&[bool], &[u32]),
    local: Option<&[u32]>,
    test: impl FnMut((u32, u32)) -> bool,
) -> bool {
    let (kept, extra) = cut(range, candidates, extra);
    let mut pairs = candidate_pairs(kept, extra, strays.0, strays.1);
    match local {
        Some(local) => pairs
            .map(|(i, j)| (local[i as usize], local[j as usize]))
            .any(test),
        None => pairs.any(test),
    }
}

/// The bodies are the marbles of the candidate pairs, not every marble, when those are
/// at most one marble in this many ([`PairSolver::select_bodies`]).
pub(super) const SELECT_SHARE: usize = 8;

/// [`PairSolver::local`]'s mark of a marble that is not a body.
pub(super) const NOT_A_BODY: u32 = u32::MAX;

impl PairSolver {
    /// Makes the candidate pairs ([`candidate_pairs`]) hold every pair of bodies whose
    /// spheres `sphere(body)` (centre, radius) overlap ([`crate::pairs`], step 1).
    ///
    /// The candidates found on the bound spheres (each body's sphere when they were found,
    /// grown by its skin) stand while every body's sphere stays inside its bound, measured
    /// after taking off the bodies' common drift since then (their mean displacement: two
    /// bodies' distance changes only by their displacements relative to any common one, so
    /// marbles sliding down a board together keep their pairs). Bodies that left their
    /// bound (strays) are paired afresh: with the others through the grid of bounds, with
    /// each other through a grid of their own. When the bodies changed, or more than one
    /// in [`STRAY_SHARE`] strayed, the candidates are found afresh.
    ///
    /// A skin is [`SKIN`] of the radius, except when the candidates are found afresh
    /// because too many strayed: then a body that had no candidate partner gets a skin
    /// sized for its pace relative to the drift since the last bounds, one it would take
    /// [`SKIN_COVERS`] covers to cross, within [`MAX_SKIN`] of its radius. Sparse marbles
    /// that fall and bounce (the labyrinth) then keep their bounds for several substeps
    /// instead of straying at each; a marble in a crowd keeps the least skin, where a
    /// wider one would pair it with the neighbours around it.
    #[cfg(test)]
    pub(super) fn cover(&mut self, sphere: impl Fn(&Body) -> Vec4) {
        self.cover_with(sphere, false);
    }

    /// [`PairSolver::cover`], its passes on the task pool with `parallel` (and the
    /// `parallel` feature).
    #[cfg(test)]
    pub(super) fn cover_with(&mut self, sphere: impl Fn(&Body) -> Vec4, parallel: bool) {
        let n = self.bodies.len();
        self.begin(n, &mut MarbleContacts::default());
        let entities: Vec<Entity> = self.bodies.iter().map(|b| b.entity).collect();
        let rows: Vec<(Vec4, f32)> = self.bodies.iter().map(|b| (sphere(b), b.r)).collect();
        self.gather_table(n).write(&entities, rows.into_iter());
        self.cover_spheres(parallel);
    }

    /// [`PairSolver::cover`] on the gathered spheres; with `parallel`, the passes over
    /// the bodies in chunks on the task pool ([`crate::systems::run_rows`]), with the
    /// same bits.
    pub(super) fn cover_spheres(&mut self, parallel: bool) {
        let n = self.spheres.len();
        self.extra.clear();
        self.strays.clear();
        self.stray.resize(n, false);
        self.select_every_marble();
        let same = self.skin_valid
            && n > 0
            && self.bound.len() == n
            && !self.entities_changed.load(Ordering::Relaxed);
        let mut moved = None;
        if same {
            self.covers = self.covers.saturating_add(1);
            let drift = self.drift_since_bound(parallel);
            let count = AtomicUsize::new(0);
            let rows = (&mut self.stray[..], &self.spheres[..], &self.bound[..]);
            crate::systems::run_rows(rows, parallel, |(stray, spheres, bound)| {
                let mut strays = 0;
                for ((stray, s), b) in stray.iter_mut().zip(spheres).zip(bound) {
                    *stray = (s.truncate() - drift - b.truncate()).length() + s.w > b.w;
                    strays += usize::from(*stray);
                }
                if strays > 0 {
                    count.fetch_add(strays, Ordering::Relaxed);
                }
            });
            let count = count.into_inner();
            if count * STRAY_SHARE <= n {
                if count > 0 {
                    let strays = (0u32..).zip(&self.stray).filter(|&(_, &s)| s);
                    self.strays.extend(strays.map(|(k, _)| k));
                }
                self.drift = drift;
                self.pair_strays(parallel);
                return;
            }
            moved = Some(drift);
        }
        match moved {
            // Too many strayed: each skin sized for the marble's pace since the last
            // bounds, relative to the drift (the docs of `cover`).
            Some(drift) => {
                // `stray` now marks the marbles that had a candidate partner.
                self.stray.fill(false);
                for &(i, j) in &self.candidates {
                    self.stray[i as usize] = true;
                    self.stray[j as usize] = true;
                }
                let per_cover = SKIN_COVERS / self.covers as f32;
                let rows = (self.bound.iter_mut().zip(&self.spheres))
                    .zip(self.radii.iter().zip(&self.stray));
                for ((b, s), (r, &crowded)) in rows {
                    let pace = (s.truncate() - drift - b.truncate()).length() * per_cover;
                    let most = if crowded { SKIN } else { MAX_SKIN };
                    let skin = pace.clamp(SKIN * r, most * r);
                    *b = s.truncate().extend(s.w + skin);
                }
            }
            None => {
                self.bound.clear();
                self.bound.extend(
                    self.spheres
                        .iter()
                        .zip(&self.radii)
                        .map(|(s, r)| s.truncate().extend(s.w + SKIN * r)),
                );
            }
        }
        self.stray.fill(false);
        self.covers = 0;
        self.grid.build(&self.bound);
        self.candidates.clear();
        let chunks = &mut self.pair_chunks;
        (self.grid).pairs_into(&self.bound, &mut self.candidates, chunks, parallel);
        self.drift = Vec3::ZERO;
        self.skin_valid = true;
    }

    /// The bodies' mean displacement from their bounds: the sum of each block of
    /// [`DRIFT_BLOCK`] bodies in order, then of the blocks' sums in order, so that it has
    /// the same bits however the blocks are shared out.
    fn drift_since_bound(&mut self, parallel: bool) -> Vec3 {
        let n = self.spheres.len();
        self.drift_sums.resize(n.div_ceil(DRIFT_BLOCK), Vec3::ZERO);
        let rows = DriftBlocks {
            sums: &mut self.drift_sums,
            spheres: &self.spheres,
            bound: &self.bound,
        };
        crate::systems::run_rows(rows, parallel, |blocks| {
            let spheres = blocks.spheres.chunks(DRIFT_BLOCK);
            let bound = blocks.bound.chunks(DRIFT_BLOCK);
            for ((sum, spheres), bound) in blocks.sums.iter_mut().zip(spheres).zip(bound) {
                *sum = spheres.iter().zip(bound).fold(Vec3::ZERO, |acc, (s, b)| {
                    acc + (s.truncate() - b.truncate())
                });
            }
        });
        let sum = self.drift_sums.iter().fold(Vec3::ZERO, |acc, &s| acc + s);
        sum / n as f32
    }

    /// Phase 2's choice of bodies, after [`PairSolver::cover_gathered`] found candidate
    /// pairs: when the marbles in them are few (at most one in eight), only
    /// those, in the marbles' order ([`PairSolver::selected`]), so that a substep in
    /// which a few marbles of a large scene meet costs what they do; every marble
    /// otherwise. A marble's body index is then its place among the chosen: the same
    /// relative order, so the stage does the same work in the same order either way.
    pub fn select_bodies(&mut self) {
        self.select_every_marble();
        let n = self.spheres.len();
        self.local.resize(n, NOT_A_BODY);
        let most = n / SELECT_SHARE;
        let pairs = candidate_pairs(&self.candidates, &self.extra, &self.stray, &self.strays);
        #[cfg(test)]
        if self.never_select {
            return;
        }
        let mut few = true;
        for (i, j) in pairs {
            for m in [i, j] {
                let mark = &mut self.local[m as usize];
                if *mark == NOT_A_BODY {
                    *mark = 0;
                    self.selected.push(m);
                }
            }
            if self.selected.len() > most {
                few = false;
                break;
            }
        }
        if !few {
            self.select_every_marble();
            return;
        }
        self.selected.sort_unstable();
        for (k, &m) in (0u32..).zip(&self.selected) {
            self.local[m as usize] = k;
        }
        self.compact = true;
        #[cfg(test)]
        {
            self.selections += 1;
        }
    }

    /// Makes every marble a body again (the body index is the marble's).
    pub(super) fn select_every_marble(&mut self) {
        for &m in &self.selected {
            self.local[m as usize] = NOT_A_BODY;
        }
        self.selected.clear();
        self.compact = false;
    }

    /// The candidate pairs of the strays of a [`PairSolver::cover`]: each stray against
    /// the bounds (its sphere moved back by the common drift), and strays against each
    /// other on their spheres. With `parallel`, the strays' searches of the bounds run in
    /// chunks on the task pool, each chunk's pairs in a kept buffer, joined in the chunks'
    /// order: the same pairs in the same order.
    pub(super) fn pair_strays(&mut self, parallel: bool) {
        if self.strays.is_empty() {
            return;
        }
        let (grid, bound, stray) = (&self.grid, &self.bound, &self.stray);
        let (strays, spheres, drift) = (&self.strays, &self.spheres, self.drift);
        let search = |of: Range<usize>, out: &mut Vec<(u32, u32)>| {
            for &i in &strays[of] {
                let s = spheres[i as usize];
                grid.query(bound, (s.truncate() - drift).extend(s.w), |j| {
                    if !stray[j as usize] {
                        out.push((i.min(j), i.max(j)));
                    }
                });
            }
        };
        let (chunks, extra) = (&mut self.pair_chunks, &mut self.extra);
        grid::scan_chunked(strays.len(), parallel, chunks, extra, search);
        self.scratch_bound.clear();
        self.scratch_bound
            .extend(self.strays.iter().map(|&i| self.spheres[i as usize]));
        self.scratch_grid.build(&self.scratch_bound);
        let (chunks, extra, strays) = (&mut self.pair_chunks, &mut self.extra, &self.strays);
        (self.scratch_grid).scan_pairs(
            &self.scratch_bound,
            extra,
            chunks,
            parallel,
            |a, b, out| {
                let (i, j) = (strays[a as usize], strays[b as usize]);
                out.push((i.min(j), i.max(j)));
            },
        );
    }
}
