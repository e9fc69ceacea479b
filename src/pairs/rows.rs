//! The rows of the contact passes: one pair, four pairs in SIMD lanes, a board contact.

use super::*;

/// Over-relaxation of the contact passes (projected successive over-relaxation; 1 is plain
/// Gauss–Seidel, and it converges for any value below 2). On the 1,000-marble pour at 8
/// substeps, 15 passes at 1.5 settle it about as soon as 30 plain passes do, for about 20%
/// less time; 15 plain passes leave it stirring, 10 at 1.5 settle some starts only near
/// 6 s, and 1.7 is no better (`docs/pair-solver.md`).
pub(super) const RELAXATION: f32 = 1.5;

/// One projected Gauss–Seidel update of a contact row with closing speed `u` and effective
/// mass `k`: the accumulated impulse `lambda` moves to stop the approach (over-relaxed by
/// [`RELAXATION`]), never below zero; returns the change to apply, if any.
#[inline]
pub(super) fn accumulate(lambda: &mut f32, u: f32, k: f32) -> Option<f32> {
    let next = (*lambda - u * k * RELAXATION).max(0.0);
    let d = next - *lambda;
    (d != 0.0).then(|| {
        *lambda = next;
        d
    })
}

/// The larger of `a` and `x`, `a` when `x` is NaN: `f32::max` for a running maximum
/// `a` that is never NaN, in one instruction instead of five.
#[inline(always)]
pub(super) fn larger(a: f32, x: f32) -> f32 {
    if x > a { x } else { a }
}

/// A pair row of the contact passes.
#[derive(Clone, Copy, Debug)]
pub(super) struct PairGs {
    pub(super) i: u32,
    pub(super) j: u32,
    pub(super) n: Vec3,
    pub(super) k: f32,
    pub(super) lambda: f32,
    pub(super) target: f32,
}

impl PairGs {
    /// Applies impulse `d` along the row's normal to its two marbles' [`Vel`]s.
    #[inline]
    pub(super) fn apply(&self, vel: &mut [Vel], d: f32) {
        let (i, j) = (self.i as usize, self.j as usize);
        let (a, b) = (vel[i], vel[j]);
        (vel[i], vel[j]) = self.applied(a, b, d);
    }

    /// Marbles `a`, `b` ([`Vel`]s) after impulse `d` along the normal (the same
    /// operations, lane by lane, as on `Vec3`s).
    #[inline(always)]
    pub(super) fn applied(&self, a: Vel, b: Vel, d: f32) -> (Vel, Vel) {
        let n = self.n.extend(0.0);
        (a - (d * a.w) * n, b + (d * b.w) * n)
    }

    /// One projected, over-relaxed update of the row ([`crate::pairs`], step 4), branch-free: a
    /// row that does not change applies zero. Returns the running maximum `largest` of the
    /// velocity changes.
    #[inline(always)]
    pub(super) fn pass(&mut self, vel: &mut [Vel], largest: f32) -> f32 {
        let (i, j) = (self.i as usize, self.j as usize);
        let (a, b) = (vel[i], vel[j]);
        let u = self.closing(a, b);
        let next = (self.lambda - u * self.k * RELAXATION).max(0.0);
        let d = next - self.lambda;
        self.lambda = next;
        (vel[i], vel[j]) = self.applied(a, b, d);
        larger(largest, d.abs() / self.k)
    }

    /// The closing speed of `a` and `b` along the normal less the row's target, `Vec3::dot`'s
    /// sum order, so the same bits as on `Vec3`s.
    #[inline(always)]
    pub(super) fn closing(&self, a: Vel, b: Vel) -> f32 {
        let d = b - a;
        d.x * self.n.x + d.y * self.n.y + d.z * self.n.z - self.target
    }
}

/// A marble in the contact passes: its velocity (`x`, `y`, `z`) and inverse mass (`w`) in
/// one 16-byte lane set, so that a row reads and writes each of its marbles with one load
/// and one store.
pub(super) type Vel = Vec4;

/// Four pair rows of one colour side by side, a row to a lane. No two of them share a
/// marble, so updating them together is updating them one after another, and each lane
/// does [`PairGs::pass`]'s operations in its order: the same bits, four rows at a time.
#[derive(Clone, Copy, Debug)]
pub(super) struct RowBlock {
    pub(super) i: [u32; 4],
    pub(super) j: [u32; 4],
    /// The normals' `x`, `y` and `z`.
    pub(super) n: [Vec4; 3],
    pub(super) k: Vec4,
    pub(super) lambda: Vec4,
    pub(super) target: Vec4,
}

impl RowBlock {
    /// The block of four rows.
    pub(super) fn new(r: &[PairGs; 4]) -> RowBlock {
        let lanes = |f: fn(&PairGs) -> f32| Vec4::new(f(&r[0]), f(&r[1]), f(&r[2]), f(&r[3]));
        RowBlock {
            i: r.each_ref().map(|r| r.i),
            j: r.each_ref().map(|r| r.j),
            n: [lanes(|r| r.n.x), lanes(|r| r.n.y), lanes(|r| r.n.z)],
            k: lanes(|r| r.k),
            lambda: lanes(|r| r.lambda),
            target: lanes(|r| r.target),
        }
    }

    /// [`PairGs::pass`] on the four rows; `wide` is the running maximum by lane.
    #[inline(always)]
    pub(super) fn pass(&mut self, vel: &mut [Vel], wide: Vec4) -> Vec4 {
        let [i0, i1, i2, i3] = self.i.map(|i| i as usize);
        let [j0, j1, j2, j3] = self.j.map(|j| j as usize);
        // By lane: x_axis holds the four marbles' x, and so on (w: inverse masses).
        let a = Mat4::from_cols(vel[i0], vel[i1], vel[i2], vel[i3]).transpose();
        let b = Mat4::from_cols(vel[j0], vel[j1], vel[j2], vel[j3]).transpose();
        let [nx, ny, nz] = self.n;
        let u =
            (b.x_axis - a.x_axis) * nx + (b.y_axis - a.y_axis) * ny + (b.z_axis - a.z_axis) * nz
                - self.target;
        let next = (self.lambda - u * self.k * RELAXATION).max(Vec4::ZERO);
        let d = next - self.lambda;
        self.lambda = next;
        let (sa, sb) = (d * a.w_axis, d * b.w_axis);
        let a = Mat4::from_cols(
            a.x_axis - sa * nx,
            a.y_axis - sa * ny,
            a.z_axis - sa * nz,
            a.w_axis,
        )
        .transpose();
        let b = Mat4::from_cols(
            b.x_axis + sb * nx,
            b.y_axis + sb * ny,
            b.z_axis + sb * nz,
            b.w_axis,
        )
        .transpose();
        (vel[i0], vel[i1], vel[i2], vel[i3]) = (a.x_axis, a.y_axis, a.z_axis, a.w_axis);
        (vel[j0], vel[j1], vel[j2], vel[j3]) = (b.x_axis, b.y_axis, b.z_axis, b.w_axis);
        // `larger` lane by lane.
        (d.abs() / self.k).max(wide)
    }
}

/// The rows of one colour in the passes: `blocks` of four, then the rest one by one
/// (`tail`, slots of [`PairSolver::pair_pass`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct ColourSpan {
    pub(super) blocks: (u32, u32),
    pub(super) tail: (u32, u32),
}

/// A board row of the contact passes.
#[derive(Clone, Copy, Debug)]
pub(super) struct BoardGs {
    pub(super) i: u32,
    pub(super) n: Vec3,
    pub(super) vb: Vec3,
    pub(super) k: f32,
    pub(super) lambda: f32,
    pub(super) target: f32,
}

impl BoardGs {
    #[inline]
    pub(super) fn apply(&self, vel: &mut [Vel], d: f32) {
        let i = self.i as usize;
        let a = vel[i];
        vel[i] = a + (d * a.w) * self.n.extend(0.0);
    }
}
