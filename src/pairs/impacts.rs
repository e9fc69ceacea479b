//! Collisions as a cascade: the two-body equation, earliest first, passed on through
//! touching neighbours and boards.

use super::*;

/// [`FreeEnd::after`] of a marble the cascade put back on its free path.
const REWOUND: f32 = f32::NEG_INFINITY;

/// The state of the collision cascade ([`crate::pairs`], step 3).
pub(super) struct Cascade<'a> {
    p: &'a PairParams,
    /// Move marbles for the time left after each impact (impacts inside the substep,
    /// after integration); off for impacts at the substep's start, before integration.
    shift: bool,
    rows: &'a mut [Row],
    bodies: &'a mut [Body],
    /// Impact stage: each body's free path (empty in the contact stage).
    free_ends: &'a mut [FreeEnd],
    touches: &'a [BoardTouch],
    touch_start: &'a [u32],
    /// Velocity change per body.
    dv: &'a mut [Vec3],
    /// Time of each body's last impact.
    event: &'a mut [f32],
    changed: &'a mut [bool],
    /// Bodies whose velocity changed, to look at next.
    queue: &'a mut Vec<u32>,
}

impl Cascade<'_> {
    /// Row `k`: the two-body equation if its marbles approach faster than the threshold.
    fn pair(&mut self, k: usize) {
        let (i, j) = (self.rows[k].i as usize, self.rows[k].j as usize);
        let t = self.rows[k].t.max(self.event[i]).max(self.event[j]);
        if self.shift && self.on_changed_path(i, t) | self.on_changed_path(j, t) {
            self.rewind(k, t);
        }
        let row = &mut self.rows[k];
        let u = row.u + (self.dv[j] - self.dv[i]).dot(row.n);
        if u >= -row.limit {
            return;
        }
        // The impulse is added to the velocities the marbles have now, so it is at most
        // what restitution 1 gives on their closing speed along `n` now: the largest
        // impulse along `n` that adds no energy to the pair, whatever the normal. The
        // judged closing speed is faster than that only where the judgement saw a path the
        // marbles no longer take (a board met, the pair stage's contacts, a rewind).
        let now = ((self.bodies[j].v + self.dv[j]) - (self.bodies[i].v + self.dv[i])).dot(row.n);
        let u = u.max(2.0 * now / (1.0 + row.e));
        if u >= 0.0 {
            return;
        }
        let t = row.t.max(self.event[i]).max(self.event[j]);
        let impulse = -(1.0 + row.e) * u * row.k;
        let (wi, wj) = (self.bodies[i].w, self.bodies[j].w);
        self.dv[i] -= impulse * wi * row.n;
        self.dv[j] += impulse * wj * row.n;
        if self.shift {
            // The marbles leave the impact with their new velocities.
            let rest = self.p.h - t;
            self.bodies[i].x -= (impulse * wi * rest) * row.n;
            self.bodies[j].x += (impulse * wj * rest) * row.n;
        }
        self.event[i] = t;
        self.event[j] = t;
        // The impact happened at `t` (later than found when a neighbour's impact passed it
        // on): a later hit of either marble is what can make the pair meet again.
        row.t = t;
        row.collided = true;
        self.changed[i] = true;
        self.changed[j] = true;
        self.queue.push(i as u32);
        self.queue.push(j as u32);
    }

    /// Body `b` meets another marble at `t`, before a board changed its path.
    #[inline]
    fn on_changed_path(&self, b: usize, t: f32) -> bool {
        self.free_ends
            .get(b)
            .is_some_and(|f| f.after > t && f.after < f32::INFINITY)
    }

    /// Row `k` meets at a time before a board changed the path of one of its marbles (the
    /// impact stage): the marble never took that path, since the pair's impact comes
    /// first. Judged on the path the board gave it, the impulse would be the closing speed
    /// before the board's reaction applied to the velocity after it (a marble sent through
    /// its neighbour onto a wall, bounced, then hit by the neighbour's impulse too, leaves
    /// faster than it came). If the pair, judged again with that marble back on its free
    /// path, collides, the marble stays there and the row takes the new judgement (normal,
    /// closing speed, time); the late search finds what boards the new path meets.
    fn rewind(&mut self, k: usize, t: f32) {
        let row = self.rows[k];
        let (i, j) = (row.i as usize, row.j as usize);
        let kept = (self.bodies[i], self.bodies[j]);
        let back = [i, j].map(|b| self.on_changed_path(b, t));
        for (b, back) in [i, j].into_iter().zip(back) {
            if back {
                let f = self.free_ends[b];
                self.bodies[b].x = f.x;
                self.bodies[b].v = f.v;
            }
        }
        let judged =
            narrow(&*self.bodies, row.i, row.j, self.p).filter(|r| r.kind == Found::Impact);
        let collides = judged.is_some_and(|r| r.u + (self.dv[j] - self.dv[i]).dot(r.n) < -r.limit);
        match judged {
            Some(r) if collides => {
                for (b, back) in [i, j].into_iter().zip(back) {
                    if back {
                        self.free_ends[b].after = REWOUND;
                        self.changed[b] = true;
                    }
                }
                self.rows[k] = Row {
                    collided: row.collided,
                    at: row.at,
                    ..r
                };
            }
            _ => (self.bodies[i], self.bodies[j]) = kept,
        }
    }

    /// The boards body `b` touches: equation (1) against each one the cascade drives it
    /// into (judged on its end velocity, which the board response already made leave or
    /// rest on the board).
    fn boards(&mut self, b: usize) {
        if self.free_ends.get(b).is_some_and(|f| f.after == REWOUND) {
            // Its touches are those of the path it no longer takes; the late search finds
            // the boards of its new one.
            return;
        }
        let mut hit = false;
        let range = self.touch_start[b] as usize..self.touch_start[b + 1] as usize;
        for t in &self.touches[range] {
            if t.gap > 0.0 {
                // A speculative row: the marble does not touch this piece.
                continue;
            }
            let u = (self.bodies[b].v + self.dv[b] - t.velocity).dot(t.normal);
            if u < -self.p.threshold {
                let change = -(1.0 + t.restitution) * u * t.normal;
                self.dv[b] += change;
                if self.shift {
                    self.bodies[b].x += change * (self.p.h - self.event[b]);
                }
                hit = true;
            }
        }
        if hit {
            self.queue.push(b as u32);
        }
    }
}

impl PairSolver {
    /// Step 3 of [`crate::pairs`]: the cascade of exact two-body impacts. A marble the
    /// cascade drives into a board it touches bounces off that board in turn (the board's
    /// restitution, the board not moving); boards it did not touch are the impact stage's
    /// [`PairSolver::onto_boards`].
    /// Returns whether any marble collided.
    pub(super) fn collide(&mut self, p: &PairParams, shift: bool) -> bool {
        let n = self.bodies.len();
        self.first.clear();
        for (k, row) in self.rows.iter().enumerate() {
            if row.u < -row.limit {
                self.first.push(k as u32);
            }
        }
        if self.first.is_empty() {
            return false;
        }
        let rows = &mut self.rows;
        self.first.sort_unstable_by(|&a, &b| {
            rows[a as usize]
                .t
                .total_cmp(&rows[b as usize].t)
                .then(a.cmp(&b))
        });
        // Which rows each body is in (compressed adjacency).
        self.adjacency_start.clear();
        self.adjacency_start.resize(n + 1, 0);
        for row in rows.iter() {
            self.adjacency_start[row.i as usize + 1] += 1;
            self.adjacency_start[row.j as usize + 1] += 1;
        }
        for k in 0..n {
            self.adjacency_start[k + 1] += self.adjacency_start[k];
        }
        self.adjacency.clear();
        self.adjacency.resize(2 * rows.len(), 0);
        self.queue.clear();
        self.queue.extend_from_slice(&self.adjacency_start[..n]);
        for (k, row) in rows.iter().enumerate() {
            for b in [row.i, row.j] {
                let slot = &mut self.queue[b as usize];
                self.adjacency[*slot as usize] = k as u32;
                *slot += 1;
            }
        }
        self.queue.clear();
        self.dv.clear();
        self.dv.resize(n, Vec3::ZERO);
        self.event.clear();
        self.event.resize(n, 0.0);
        // A cap on the cascade: with e = 1 a jammed cluster could pass impulses round for
        // ever; what is left then goes to the contact solver (inelastic).
        let mut budget = 8 * (rows.len() + self.board_touches.len()) + 64;
        let mut c = Cascade {
            p,
            shift,
            rows,
            bodies: &mut self.bodies,
            free_ends: &mut self.free_ends,
            touches: &self.board_touches,
            touch_start: &self.touch_start,
            dv: &mut self.dv,
            event: &mut self.event,
            changed: &mut self.changed,
            queue: &mut self.queue,
        };
        for f in 0..self.first.len() {
            // Every impact found is resolved; only what they pass on is capped.
            c.pair(self.first[f] as usize);
            budget = budget.saturating_sub(1);
            // Whatever this impact set moving collides next, at once.
            let mut head = 0;
            while head < c.queue.len() && budget > 0 {
                let b = c.queue[head] as usize;
                head += 1;
                budget =
                    budget.saturating_sub(1 + (c.touch_start[b + 1] - c.touch_start[b]) as usize);
                c.boards(b);
                for a in self.adjacency_start[b]..self.adjacency_start[b + 1] {
                    if budget == 0 {
                        break;
                    }
                    budget -= 1;
                    c.pair(self.adjacency[a as usize] as usize);
                }
            }
            c.queue.clear();
        }
        let (bodies, dv) = (&mut self.bodies, &self.dv);
        for (b, d) in bodies.iter_mut().zip(dv.iter()) {
            b.v += *d;
        }
        true
    }
}
