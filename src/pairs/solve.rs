//! The contact passes: projected Gauss–Seidel with warm starting.

use super::*;

/// A Gauss–Seidel pass that changes no velocity by more than this (m/s) ends the solve.
///
/// It rarely does in a pile: in bench scene (b)'s settled 1,000-marble pile the last of
/// the 15 passes still changes some pair's closing speed by about 1.2e-6 m/s (ordinary
/// contacts deep in the pile, each pass moving them by about as much as the one before),
/// and a looser tolerance only moves that level with it: at 1e-5 the change sits at
/// 1.2e-5 m/s, at 1e-4 half the substeps still run all 15 passes. So the passes are not
/// cut by a tolerance.
pub(super) const CONVERGED: f32 = 1e-6;

/// A board row of the overlap projection: the marble, the contact point at the end of the
/// substep, the board's normal there, and the overlap allowed before projection, m.
#[derive(Clone, Copy, Debug)]
pub(super) struct BoardPush {
    pub(super) i: u32,
    pub(super) p: Vec3,
    pub(super) n: Vec3,
    pub(super) slop: f32,
}

impl PairSolver {
    /// The pair rows of the passes, built after the collisions at the start (before
    /// friction, which reads their warm-start impulses): each touching or speculative
    /// pair with the impulse the same contact carried over the last substep (warm start),
    /// by key: the pair's two marbles' entity bits, smaller first.
    pub(super) fn pair_rows(&mut self, p: &PairParams) {
        self.pair_gs.clear();
        self.pair_keys.clear();
        for row in &self.rows {
            let (a, b) = (&self.bodies[row.i as usize], &self.bodies[row.j as usize]);
            let (ka, kb) = (a.entity.to_bits(), b.entity.to_bits());
            self.pair_gs.push(PairGs {
                i: row.i,
                j: row.j,
                n: row.n,
                k: row.k,
                lambda: 0.0,
                target: -row.gap / p.h,
            });
            self.pair_keys.push((ka.min(kb), ka.max(kb)));
        }
        let (rows, places) = (&mut self.pair_gs, self.rows.iter().map(|r| r.at));
        let scale = self.warm.scale(p.h);
        self.warm.find_pairs(&self.pair_keys, places, |k, lambda| {
            rows[k].lambda = lambda * scale
        });
    }

    /// Step 4 of [`crate::pairs`]: sequential impulses over every touching pair (the rows
    /// of [`PairSolver::pair_rows`]) and the board contacts of their marbles, warm
    /// started, on the velocities the marbles would reach at the end of the substep; the
    /// impulses become forces over the substep (added to `a`), so every integrator moves
    /// the marbles consistently with them.
    pub(super) fn solve_contacts(&mut self, p: &PairParams) {
        // The board rows, each with the impulse the same contact carried over the last
        // substep, by key: the marble's entity bits and the piece's, the piece's flipped
        // so that they never equal a pair's.
        // (`in_contact` marks the marbles in the rows: [`PairSolver::find_touching`].)
        self.board_gs.clear();
        self.board_keys.clear();
        self.board_places.clear();
        self.board_push.clear();
        for t in &self.board_touches {
            if !self.in_contact[t.body as usize] {
                continue;
            }
            let b = &self.bodies[t.body as usize];
            if t.gap > 0.0 && (b.v - t.velocity).dot(t.normal) < -p.threshold {
                // A speculative row closing faster than the threshold (after the cascade):
                // a collision coming, which the marble–board response resolves at its
                // instant. Held here as well, the marble would be both stopped by this
                // row's force and bounced by the response, and leave faster than it came.
                continue;
            }
            let key = (b.entity.to_bits(), !t.piece.0);
            self.board_gs.push(BoardGs {
                i: t.body,
                n: t.normal,
                vb: t.velocity,
                k: 1.0 / b.w,
                lambda: 0.0,
                // A speculative row may close its gap within the substep.
                target: if t.gap > 0.0 { -t.gap / p.h } else { 0.0 },
            });
            self.board_keys.push(key);
            self.board_places
                .push(self.marble_of(t.body as usize) as u32);
            self.board_push.push(BoardPush {
                i: t.body,
                p: t.point,
                n: t.normal,
                slop: PAIR_SLOP * b.r,
            });
        }
        let (rows, places) = (&mut self.board_gs, self.board_places.iter().copied());
        let scale = self.warm.scale(p.h);
        self.warm
            .find_boards(&self.board_keys, places, |k, lambda| {
                rows[k].lambda = lambda * scale
            });
        let h = p.h;
        // From here on `v` is the velocity each marble would reach at the end of the
        // substep without contact forces, `v0` its velocity at the start.
        for b in self.bodies.iter_mut() {
            b.v0 = b.v;
            b.v += b.a * h;
        }
        // The passes run on the compact rows (pair and board apart) and a compact copy of
        // the velocities and inverse masses by body, so that the inner loops are short and
        // branch-free.
        self.vel.clear();
        self.vel.extend(self.bodies.iter().map(|b| b.v.extend(b.w)));
        self.colour_rows();
        // A marble approaching a board it touches at the substep's start (slower than the
        // threshold: faster ones the cascade bounced) has that approach removed by the
        // marble–board response at the start, as a contact. The passes start from it
        // removed too, and it is not turned into a force: held here as well, the marble
        // would be stopped twice and leave as fast as it came.
        self.dv.clear();
        self.dv.resize(self.bodies.len(), Vec3::ZERO);
        for r in &self.board_gs {
            if r.target == 0.0 {
                let i = r.i as usize;
                let v0 = self.bodies[i].v0 + self.dv[i];
                let u0 = (v0 - r.vb).dot(r.n);
                if u0 < 0.0 {
                    self.dv[i] -= u0 * r.n;
                }
            }
        }
        for (v, d) in self.vel.iter_mut().zip(&self.dv) {
            *v += d.extend(0.0);
        }
        let vel = self.vel.as_mut_slice();
        // Warm start.
        for r in &self.pair_pass {
            if r.lambda != 0.0 {
                r.apply(vel, r.lambda);
            }
        }
        for r in &self.board_gs {
            if r.lambda != 0.0 {
                r.apply(vel, r.lambda);
            }
        }
        self.run_passes(p);
        let vel = self.vel.as_mut_slice();
        for (b, &first) in self.blocks.iter().zip(&self.block_first) {
            let rows = &mut self.pair_pass[first as usize..first as usize + 4];
            for (r, lambda) in rows.iter_mut().zip(b.lambda.to_array()) {
                r.lambda = lambda;
            }
        }
        for (r, &slot) in self.pair_gs.iter_mut().zip(&self.pair_slot) {
            r.lambda = self.pair_pass[slot as usize].lambda;
        }
        // A speculative board row holds its marble in the solve, so that the pair impulses
        // are those of marbles that the board will stop, but its impulse is not a force:
        // the marble does not touch the board, and if it reaches it during the substep the
        // marble–board response stops or bounces it there. As a force as well, it would
        // push the marble back off a board it reaches anyway (any integrator whose path
        // runs ahead of the end velocity does), and it would leave.
        for r in &self.board_gs {
            if r.target < 0.0 && r.lambda != 0.0 {
                r.apply(vel, -r.lambda);
            }
        }
        let bodies = &mut self.bodies;
        for ((b, v), d) in bodies.iter_mut().zip(vel.iter()).zip(&self.dv) {
            b.v = v.truncate() - *d;
        }
        let pairs = (self.pair_keys.iter().zip(&self.rows).zip(&self.pair_gs))
            .map(|((&key, row), gs)| (key, row.at, gs.lambda));
        let boards = (self
            .board_keys
            .iter()
            .zip(&self.board_places)
            .zip(&self.board_gs))
        .map(|((&key, &place), gs)| (key, place, gs.lambda));
        self.warm.keep(pairs, boards, h);
        // The impulses are forces over the substep.
        for (k, b) in bodies.iter_mut().enumerate() {
            let free = b.v0 + b.a * h;
            let dv = b.v - free;
            if dv != Vec3::ZERO {
                b.a += dv / h;
                self.changed[k] = true;
            }
            b.v = b.v0;
        }
    }

    /// The contact passes of [`PairSolver::solve_contacts`] on the compact rows, colour
    /// by colour, until one changes no velocity by more than [`CONVERGED`] or
    /// `p.iterations` have run. Kept out of line, as are the colouring and the
    /// projection, so that a profile shows each step of the solve apart (inlined into the
    /// one function, they also took 1.2% more of the pour's instructions).
    #[inline(never)]
    fn run_passes(&mut self, p: &PairParams) {
        let vel = self.vel.as_mut_slice();
        let (blocks, pass) = (&mut self.blocks, &mut self.pair_pass);
        for _ in 0..p.iterations {
            // Colour by colour, its blocks of four and then its single rows.
            let mut wide = Vec4::ZERO;
            let mut largest = 0.0f32;
            for span in &self.spans {
                for b in &mut blocks[span.blocks.0 as usize..span.blocks.1 as usize] {
                    wide = b.pass(vel, wide);
                }
                for r in &mut pass[span.tail.0 as usize..span.tail.1 as usize] {
                    largest = r.pass(vel, largest);
                }
            }
            largest = larger(largest, wide.max_element());
            for r in self.board_gs.iter_mut() {
                let u = (vel[r.i as usize].truncate() - r.vb).dot(r.n) - r.target;
                if let Some(d) = accumulate(&mut r.lambda, u, r.k) {
                    r.apply(vel, d);
                    largest = larger(largest, d.abs() / r.k);
                }
            }
            if largest < CONVERGED {
                break;
            }
        }
    }
}
