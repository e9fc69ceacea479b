//! Coulomb friction between touching marbles that spin.

use super::*;

impl PairSolver {
    /// Coulomb friction between touching marbles that both spin (rolling on), as impulses
    /// at the substep's start: the contact point's slip
    /// `s = (v₂ + ω₂ × (−r₂ n)) − (v₁ + ω₁ × (r₁ n))`, tangential part, is stopped by the
    /// impulse `−s / ((7/2)(1/m₁ + 1/m₂))` (a solid sphere's contact point has effective
    /// mass `2/7 m` against a tangential push), capped by `μ λ_n`, where `λ_n` is the normal
    /// impulse the pair's contact carried over the last substep (warm start) and `μ` the
    /// pair's mean friction. Piecewise-constant Coulomb friction, exact substep by substep;
    /// it never adds energy and conserves momentum. Impacts inside a substep are smooth.
    pub(super) fn friction(&mut self) {
        if !self.bodies.iter().any(|b| b.spins) {
            return;
        }
        for (row, gs) in self.rows.iter().zip(&self.pair_gs) {
            let (i, j) = (row.i as usize, row.j as usize);
            let (a, b) = (&self.bodies[i], &self.bodies[j]);
            // The row's warm-start impulse ([`PairSolver::pair_rows`]): none kept, none
            // carried.
            let normal = gs.lambda;
            if !(a.spins && b.spins) || row.kind != Found::Start || normal == 0.0 {
                continue;
            }
            let n = row.n;
            let vc = (b.v + b.omega.cross(-b.r * n)) - (a.v + a.omega.cross(a.r * n));
            let slip = vc - vc.dot(n) * n;
            let mut j_t = slip * (-1.0 / (3.5 * (a.w + b.w)));
            let cap = 0.5 * (a.mu + b.mu) * normal;
            let len = j_t.length();
            if len > cap {
                j_t *= cap / len;
            }
            if j_t == Vec3::ZERO {
                continue;
            }
            let spin = n.cross(j_t);
            let (wa, wb, ra, rb) = (a.w, b.w, a.r, b.r);
            let a = &mut self.bodies[i];
            a.v -= wa * j_t;
            a.omega -= (2.5 * wa / ra) * spin;
            let b = &mut self.bodies[j];
            b.v += wb * j_t;
            b.omega -= (2.5 * wb / rb) * spin;
            self.changed[i] = true;
            self.changed[j] = true;
        }
    }
}
