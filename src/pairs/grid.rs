//! The broad phase's uniform grid, and the hasher of the warm-start keys.

use super::*;
use std::ops::Range;

/// A fast hasher for warm-start keys (entity bits are already well spread).
#[derive(Default, Clone, Copy)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Contact impulses by warm-start key: a pair's two marbles' entity bits (smaller first),
/// or a marble's entity bits and a board piece's id with its bits flipped.
pub(crate) type KeyMap = HashMap<(u64, u64), f32, BuildHasherDefault<KeyHasher>>;

/// The hashed uniform grid of the broad phase (buffers reused between substeps).
#[derive(Default, Debug)]
pub(crate) struct Grid {
    cell: f32,
    mask: u32,
    /// Dense mode: the lowest cell (less one in every axis) and the cell counts, when the
    /// marbles' cells span few enough cells for one table entry per cell: neighbouring
    /// cells are then neighbours in memory, and no two cells share a bucket. Otherwise
    /// (`None`) cells are hashed.
    pub(super) dense: Option<(IVec3, IVec3)>,
    /// In dense mode, whether the padding cells exist (no cell index saturated at `i32`'s
    /// ends): every neighbour of an occupied cell is then at a fixed offset in the table.
    padded: bool,
    /// Bucket of each body.
    bucket: Vec<u32>,
    /// Start of each bucket in `order` (`mask + 2` entries).
    start: Vec<u32>,
    /// Ordinary bodies sorted by bucket.
    order: Vec<u32>,
    /// Cell of each entry of `order`.
    cells: Vec<IVec3>,
    /// Bound sphere (centre, radius) of each entry of `order`.
    bounds: Vec<Vec4>,
    /// Bodies too large or fast for the cell size.
    large: Vec<u32>,
}

/// The 13 neighbours of a cell that come after it: with the cell itself they visit every
/// pair of neighbouring cells once.
pub(super) const FORWARD: [IVec3; 13] = [
    IVec3::new(1, -1, -1),
    IVec3::new(1, -1, 0),
    IVec3::new(1, -1, 1),
    IVec3::new(1, 0, -1),
    IVec3::new(1, 0, 0),
    IVec3::new(1, 0, 1),
    IVec3::new(1, 1, -1),
    IVec3::new(1, 1, 0),
    IVec3::new(1, 1, 1),
    IVec3::new(0, 1, -1),
    IVec3::new(0, 1, 0),
    IVec3::new(0, 1, 1),
    IVec3::new(0, 0, 1),
];

/// The cell of point `p` for cells of size `1 / inv`: `floor(p · inv)` per axis, without
/// a call to libm's `floorf` (baseline x86-64 has no rounding instruction). Cells past
/// `i32`'s range (a point 10⁶ m out with micrometre cells) saturate to its ends: the cells
/// there hold more marbles, but every pair is still found.
#[inline]
pub(super) fn cell_of(p: Vec3, inv: f32) -> IVec3 {
    let q = p * inv;
    let t = q.as_ivec3();
    t.saturating_sub(IVec3::from(t.as_vec3().cmpgt(q)))
}

/// The multipliers of [`hash_cell`], per axis.
const HASH: [u32; 3] = [0x8da6_b343, 0xd816_3841, 0xcb1a_b31f];

#[inline]
pub(super) fn hash_cell(c: IVec3) -> u32 {
    (c.x as u32).wrapping_mul(HASH[0])
        ^ (c.y as u32).wrapping_mul(HASH[1])
        ^ (c.z as u32).wrapping_mul(HASH[2])
}

/// [`hash_cell`] of cell `c`, and of each of its [`FORWARD`] neighbours in that order,
/// from the three per-axis terms of each axis (each multiplied once).
#[inline(always)]
pub(super) fn forward_hashes(c: IVec3) -> (u32, [u32; 13]) {
    let terms =
        |c: i32, m: u32| [-1, 0, 1].map(|d: i32| (c.wrapping_add(d) as u32).wrapping_mul(m));
    let ([_, x1, x2], [y0, y1, y2], [z0, z1, z2]) = (
        terms(c.x, HASH[0]),
        terms(c.y, HASH[1]),
        terms(c.z, HASH[2]),
    );
    let (a, b) = (x2 ^ y0, x2 ^ y1);
    let (e, g) = (x2 ^ y2, x1 ^ y2);
    let forward = [
        a ^ z0,
        a ^ z1,
        a ^ z2,
        b ^ z0,
        b ^ z1,
        b ^ z2,
        e ^ z0,
        e ^ z1,
        e ^ z2,
        g ^ z0,
        g ^ z1,
        g ^ z2,
        x1 ^ y1 ^ z2,
    ];
    (x1 ^ y1 ^ z1, forward)
}

impl Grid {
    /// Sizes the buffers for `n` bodies.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.bucket.reserve(n);
        self.start.reserve(8 * n + 66);
        self.order.reserve(n);
        self.cells.reserve(n);
        self.bounds.reserve(n);
        self.large.reserve(n);
    }

    /// Sorts the bodies into cells from their bound spheres `b` (centre, radius).
    pub(crate) fn build(&mut self, b: &[Vec4]) {
        let n = b.len();
        self.large.clear();
        self.order.clear();
        self.cells.clear();
        self.bounds.clear();
        self.bucket.clear();
        if n == 0 {
            return;
        }
        let mean = b.iter().map(|s| s.w as f64).sum::<f64>() / n as f64;
        let limit = 2.0 * mean as f32;
        let largest = b
            .iter()
            .map(|s| s.w)
            .filter(|&w| w <= limit)
            .fold(0.0f32, f32::max);
        self.cell = (2.0 * largest).max(f32::MIN_POSITIVE);
        let inv = 1.0 / self.cell;
        // The span of the ordinary marbles' cells, padded by one cell on every side so
        // that every neighbour of an occupied cell has a table entry.
        let (mut lo, mut hi) = (IVec3::MAX, IVec3::MIN);
        for s in b.iter().filter(|s| s.w <= limit) {
            let c = cell_of(s.truncate(), inv);
            lo = lo.min(c);
            hi = hi.max(c);
        }
        let dims = hi.as_i64vec3() - lo.as_i64vec3() + glam::I64Vec3::splat(3);
        let cells = dims.x.saturating_mul(dims.y).saturating_mul(dims.z);
        // (No ordinary body at all, as when every bound is NaN, leaves `lo` above `hi`:
        // no span, so the hashed table.)
        self.padded = lo.cmpgt(IVec3::MIN).all() && hi.cmplt(IVec3::MAX).all();
        let table = if lo.cmple(hi).all() && cells <= 8 * n as i64 + 64 {
            self.dense = Some((lo.saturating_sub(IVec3::ONE), dims.as_ivec3()));
            cells as usize
        } else {
            self.dense = None;
            (2 * n).next_power_of_two().max(16)
        };
        self.mask = (table - 1) as u32;
        self.start.clear();
        self.start.resize(table + 1, 0);
        for (k, s) in b.iter().enumerate() {
            if s.w > limit {
                self.large.push(k as u32);
                self.bucket.push(u32::MAX);
                continue;
            }
            let h = self.bucket_of(cell_of(s.truncate(), inv));
            self.bucket.push(h as u32);
            self.start[h + 1] += 1;
        }
        for h in 0..table {
            self.start[h + 1] += self.start[h];
        }
        let ordinary = n - self.large.len();
        self.order.resize(ordinary, 0);
        self.cells.resize(ordinary, IVec3::ZERO);
        self.bounds.resize(ordinary, Vec4::ZERO);
        // Scatter with a running cursor per bucket (the bucket starts, shifted back after).
        for (k, s) in b.iter().enumerate() {
            let h = self.bucket[k];
            if h == u32::MAX {
                continue;
            }
            let slot = self.start[h as usize] as usize;
            self.start[h as usize] += 1;
            self.order[slot] = k as u32;
            self.cells[slot] = cell_of(s.truncate(), inv);
            self.bounds[slot] = *s;
        }
        for h in (1..=table).rev() {
            self.start[h] = self.start[h - 1];
        }
        self.start[0] = 0;
    }

    /// The bucket of cell `c`: its index in the dense table, or its hash. In dense mode
    /// a cell outside the padded span (only large marbles ask for those) has no marbles:
    /// it maps to the padding cell `0`, which is always empty.
    #[inline]
    fn bucket_of(&self, c: IVec3) -> usize {
        match self.dense {
            Some((lo, dims)) => {
                let d = c.saturating_sub(lo);
                if d.cmplt(IVec3::ZERO).any() || d.cmpge(dims).any() {
                    0
                } else {
                    ((d.x as usize * dims.y as usize) + d.y as usize) * dims.z as usize
                        + d.z as usize
                }
            }
            None => (hash_cell(c) & self.mask) as usize,
        }
    }

    /// Entries of `order` in the bucket of cell `c`.
    #[inline]
    fn bucket_range(&self, c: IVec3) -> std::ops::Range<usize> {
        let h = self.bucket_of(c);
        self.start[h] as usize..self.start[h + 1] as usize
    }

    /// Calls `f(j)` for every body whose bound sphere overlaps sphere `s` (centre, radius).
    pub(crate) fn query(&self, b: &[Vec4], s: Vec4, mut f: impl FnMut(u32)) {
        let near = |q: Vec4| {
            let r = s.w + q.w;
            (s.truncate() - q.truncate()).length_squared() <= r * r
        };
        let half = 0.5 * self.cell;
        let inv = 1.0 / self.cell;
        let lo = cell_of(s.truncate() - Vec3::splat(s.w + half), inv);
        let hi = cell_of(s.truncate() + Vec3::splat(s.w + half), inv);
        let span = (hi.as_vec3() - lo.as_vec3()) + Vec3::ONE;
        if (span.x * span.y * span.z) as f64 > self.order.len() as f64 {
            for q in 0..self.order.len() {
                if near(self.bounds[q]) {
                    f(self.order[q]);
                }
            }
        } else {
            for x in lo.x..=hi.x {
                for y in lo.y..=hi.y {
                    for z in lo.z..=hi.z {
                        let c = IVec3::new(x, y, z);
                        for q in self.bucket_range(c) {
                            if self.cells[q] == c && near(self.bounds[q]) {
                                f(self.order[q]);
                            }
                        }
                    }
                }
            }
        }
        for &l in &self.large {
            if near(b[l as usize]) {
                f(l);
            }
        }
    }

    /// The pairs of ordinary bodies, in the order of [`Grid::pairs_by_bucket`], with the
    /// forward neighbours' buckets found at less cost: in dense mode at a fixed offset
    /// from the cell's own (the padding keeps every neighbour of an occupied cell in the
    /// table, and a bucket holds one cell, so no cell is compared); hashed, from the
    /// per-axis terms of the hash, each multiplied once per body.
    pub(super) fn ordinary_pairs(&self, f: &mut impl FnMut(u32, u32)) {
        self.ordinary_pairs_of(0..self.order.len(), f);
    }

    /// [`Grid::ordinary_pairs`] of the bodies in the bucket slots `slots` (each with the
    /// later bodies of its cell and those of its forward neighbours, wherever they are):
    /// the pairs of consecutive ranges of slots, one after another, are those of the
    /// whole, in its order.
    fn ordinary_pairs_of(&self, slots: Range<usize>, f: &mut impl FnMut(u32, u32)) {
        // Once here, so that the slots' own loads need no check of their own.
        let n = self.order.len();
        assert!(slots.end <= n && self.cells.len() == n && self.bounds.len() == n);
        let near = |p: Vec4, q: Vec4| {
            let r = p.w + q.w;
            (p.truncate() - q.truncate()).length_squared() <= r * r
        };
        match self.dense {
            Some((_, dims)) if self.padded => {
                let offset = FORWARD.map(|d| ((d.x * dims.y + d.y) * dims.z + d.z) as isize);
                for p in slots {
                    let bp = self.bounds[p];
                    let h = self.bucket_of(self.cells[p]);
                    for q in p + 1..self.start[h + 1] as usize {
                        if near(bp, self.bounds[q]) {
                            f(self.order[p], self.order[q]);
                        }
                    }
                    for o in offset {
                        let h = h.wrapping_add_signed(o);
                        for q in self.start[h] as usize..self.start[h + 1] as usize {
                            if near(bp, self.bounds[q]) {
                                f(self.order[p], self.order[q]);
                            }
                        }
                    }
                }
            }
            Some(_) => self.pairs_by_bucket_of(slots, f),
            None => {
                if slots.is_empty() {
                    // (An empty grid has no table.)
                    return;
                }
                // Every masked hash's bucket range is in the table (`mask + 2` starts).
                let mask = self.mask;
                let start = &self.start[..mask as usize + 2];
                for p in slots {
                    let c = self.cells[p];
                    let bp = self.bounds[p];
                    let (own, hashes) = forward_hashes(c);
                    let own = own & mask;
                    for q in p + 1..start[own as usize + 1] as usize {
                        if self.cells[q] == c && near(bp, self.bounds[q]) {
                            f(self.order[p], self.order[q]);
                        }
                    }
                    for (d, h) in FORWARD.iter().zip(hashes) {
                        let h = (h & mask) as usize;
                        let bucket = start[h] as usize..start[h + 1] as usize;
                        if bucket.is_empty() {
                            continue;
                        }
                        let cd = c.wrapping_add(*d);
                        for q in bucket {
                            if self.cells[q] == cd && near(bp, self.bounds[q]) {
                                f(self.order[p], self.order[q]);
                            }
                        }
                    }
                }
            }
        }
    }

    /// The pairs of ordinary bodies: each (in the order of its bucket) against the later
    /// ones of its cell, then against those of each of its [`FORWARD`] neighbours in turn,
    /// every cell's bucket looked up.
    #[cfg(test)]
    pub(super) fn pairs_by_bucket(&self, f: &mut impl FnMut(u32, u32)) {
        self.pairs_by_bucket_of(0..self.order.len(), f);
    }

    /// [`Grid::pairs_by_bucket`] of the bodies in the bucket slots `slots`.
    fn pairs_by_bucket_of(&self, slots: Range<usize>, f: &mut impl FnMut(u32, u32)) {
        let near = |p: Vec4, q: Vec4| {
            let r = p.w + q.w;
            (p.truncate() - q.truncate()).length_squared() <= r * r
        };
        for p in slots {
            let c = self.cells[p];
            let bp = self.bounds[p];
            for q in p + 1..self.bucket_range(c).end {
                if self.cells[q] == c && near(bp, self.bounds[q]) {
                    f(self.order[p], self.order[q]);
                }
            }
            for d in &FORWARD {
                let cd = c.wrapping_add(*d);
                for q in self.bucket_range(cd) {
                    if self.cells[q] == cd && near(bp, self.bounds[q]) {
                        f(self.order[p], self.order[q]);
                    }
                }
            }
        }
    }

    /// Calls `f(i, j)` once for every pair of bodies whose bound spheres overlap.
    pub(crate) fn pairs(&self, b: &[Vec4], mut f: impl FnMut(u32, u32)) {
        self.ordinary_pairs(&mut f);
        self.large_pairs(b, f);
    }

    /// [`Grid::pairs`] pushed onto `out` as `(smaller, larger)`, in the same order. With
    /// `parallel` (and the `parallel` feature) the ordinary bodies' pairs are found in
    /// chunks of bucket slots on the task pool, each chunk's into its own buffer of
    /// `chunks` (kept from call to call), and joined in the chunks' order.
    pub(crate) fn pairs_into(
        &self,
        b: &[Vec4],
        out: &mut Vec<(u32, u32)>,
        chunks: &mut Vec<Vec<(u32, u32)>>,
        parallel: bool,
    ) {
        self.scan_pairs(b, out, chunks, parallel, |i, j, out| {
            out.push((i.min(j), i.max(j)));
        });
    }

    /// [`Grid::pairs`] with `each` pushing what it finds of a pair onto a buffer, which
    /// is `out`: with `parallel` (and the `parallel` feature) the ordinary bodies' pairs
    /// are found in chunks of bucket slots on the task pool, each chunk pushing onto its
    /// own buffer of `chunks` (kept from call to call), joined onto `out` in the chunks'
    /// order. Either way `out` gets the same values in the same order.
    pub(crate) fn scan_pairs<T: Copy + Send>(
        &self,
        b: &[Vec4],
        out: &mut Vec<T>,
        chunks: &mut Vec<Vec<T>>,
        parallel: bool,
        each: impl Fn(u32, u32, &mut Vec<T>) + Sync,
    ) {
        scan_chunked(self.order.len(), parallel, chunks, out, |slots, found| {
            self.ordinary_pairs_of(slots, &mut |i, j| each(i, j, found));
        });
        self.large_pairs(b, |i, j| each(i, j, out));
    }

    /// The pairs of the large bodies: with every ordinary body, then with each other.
    fn large_pairs(&self, b: &[Vec4], mut f: impl FnMut(u32, u32)) {
        let near = |p: Vec4, q: Vec4| {
            let r = p.w + q.w;
            (p.truncate() - q.truncate()).length_squared() <= r * r
        };
        // Large bodies: against every ordinary body through the cells their bound covers
        // (or all of them, when that is fewer), then against each other.
        let half = 0.5 * self.cell;
        let inv = 1.0 / self.cell;
        for (a, &l) in self.large.iter().enumerate() {
            let s = b[l as usize];
            let lo = ((s.truncate() - Vec3::splat(s.w + half)) * inv).floor();
            let hi = ((s.truncate() + Vec3::splat(s.w + half)) * inv).floor();
            let span = hi - lo + Vec3::ONE;
            if (span.x * span.y * span.z) as f64 > self.order.len() as f64 {
                for q in 0..self.order.len() {
                    if near(s, self.bounds[q]) {
                        f(l, self.order[q]);
                    }
                }
            } else {
                let (lo, hi) = (lo.as_ivec3(), hi.as_ivec3());
                for x in lo.x..=hi.x {
                    for y in lo.y..=hi.y {
                        for z in lo.z..=hi.z {
                            let c = IVec3::new(x, y, z);
                            for q in self.bucket_range(c) {
                                if self.cells[q] == c && near(s, self.bounds[q]) {
                                    f(l, self.order[q]);
                                }
                            }
                        }
                    }
                }
            }
            for &m in &self.large[a + 1..] {
                if near(s, b[m as usize]) {
                    f(l, m);
                }
            }
        }
    }
}

/// Runs `each` over the work `0..len`, pushing what it finds onto a buffer, which is
/// `out`: with `parallel` (and the `parallel` feature), the work is cut into ranges
/// handed to the task pool, each pushing onto its own buffer of `chunks` (kept from call
/// to call), joined onto `out` in the ranges' order. When `each` over consecutive ranges
/// finds what it finds over their union, in its order, `out` gets the same values in the
/// same order either way.
pub(super) fn scan_chunked<T: Copy + Send>(
    len: usize,
    parallel: bool,
    chunks: &mut Vec<Vec<T>>,
    out: &mut Vec<T>,
    each: impl Fn(Range<usize>, &mut Vec<T>) + Sync,
) {
    let pieces = crate::systems::pool_chunks::<Slots<'_, T>>(len, parallel);
    if pieces > 1 {
        chunks.resize_with(chunks.len().max(pieces), Vec::new);
        let rows = Slots {
            slots: 0..len,
            out: &mut chunks[..pieces],
        };
        crate::systems::run_rows(rows, parallel, |rows| {
            let [found] = rows.out else {
                unreachable!("one buffer a chunk");
            };
            found.clear();
            each(rows.slots, found);
        });
        for found in &chunks[..pieces] {
            out.extend_from_slice(found);
        }
    } else {
        each(0..len, out);
    }
}

/// A range of work (bucket slots, strays, candidate pairs, …) and one buffer for each
/// chunk that [`crate::systems::run_rows`] cuts it into ([`scan_chunked`]).
struct Slots<'a, T> {
    slots: Range<usize>,
    out: &'a mut [Vec<T>],
}

impl<T: Send> crate::systems::Rows for Slots<'_, T> {
    fn len(&self) -> usize {
        ExactSizeIterator::len(&self.slots)
    }

    fn split_at(self, mid: usize) -> (Self, Self) {
        let at = self.slots.start + mid;
        let (head, tail) = self.out.split_at_mut(1);
        let first = Slots {
            slots: self.slots.start..at,
            out: head,
        };
        let rest = Slots {
            slots: at..self.slots.end,
            out: tail,
        };
        (first, rest)
    }
}
