//! After collisions: what the marbles they sent off their free paths run into, boards and
//! marbles.

use super::*;

/// Up to this many marbles moved by collisions are looked up one by one after collisions
/// (and checked against each other directly); more, and they are paired with each other
/// (and with the strays) through a grid of their own.
pub(super) const LATE_DIRECT: usize = 256;

/// When more than one marble in this many was moved by collisions, every marble is paired
/// again on the end positions instead (it costs about as much, and is simpler).
pub(super) const LATE_SHARE: usize = 4;

/// How [`PairSolver::late_overlaps`] looks for pairs the collisions brought together.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum LateSearch {
    /// The moved marbles against the kept grid, each other and the strays, one by one.
    Direct,
    /// The moved marbles against the kept grid, and through a grid of their own with each
    /// other and the strays.
    OwnGrid,
    /// Every marble paired again on the end positions.
    All,
}

/// Most board impacts followed per marble when collisions sent it off its path.
pub(super) const BOARD_IMPACTS: usize = 4;

impl PairSolver {
    /// The search of [`PairSolver::late_overlaps`] for pairs that overlap at the end and
    /// are not among the rows, into `late` (rows not yet collided), by `search`.
    pub(super) fn find_late(&mut self, p: &PairParams, search: LateSearch) {
        self.late.clear();
        let n = self.bodies.len();
        let few = search == LateSearch::Direct;
        let all = search == LateSearch::All;
        let end_sphere = |b: &Body| {
            b.x.extend(b.r + crate::board_contact::touch_tolerance(p.tolerance, b.r, b.x))
        };
        self.late_bodies.clear();
        if all {
            self.late_bodies.extend(0..n as u32);
        } else if !few {
            self.late_bodies.extend_from_slice(&self.moved);
            self.late_bodies.extend(
                self.strays
                    .iter()
                    .copied()
                    .filter(|&j| !self.changed[j as usize]),
            );
        }
        if !few {
            self.scratch_bound.clear();
            self.scratch_bound.extend(
                self.late_bodies
                    .iter()
                    .map(|&i| end_sphere(&self.bodies[i as usize])),
            );
            self.scratch_grid.build(&self.scratch_bound);
        }
        let (bodies, known_start, known, event, changed, stray) = (
            &self.bodies,
            &self.known_start,
            &self.known,
            &self.event,
            &self.changed,
            &self.stray,
        );
        let check = |i: u32, j: u32, late: &mut Vec<Row>| {
            let (i, j) = (i.min(j), i.max(j));
            if i == j {
                return;
            }
            // Most candidates do not overlap, and in a pile most that do are rows
            // already: the distance test, then the row lookup, then the tracing back.
            if late_touch(bodies, i, j, p)
                && !known[known_start[i as usize] as usize..known_start[i as usize + 1] as usize]
                    .contains(&j)
                && let Some(row) = late_row(bodies, event, i, j, p)
            {
                late.push(row);
            }
        };
        // With `parallel`, each search in chunks on the task pool, joined in their order.
        let (parallel, chunks, late) = (self.on_pool, &mut self.row_chunks, &mut self.late);
        if !all {
            let (grid, bound, moved, strays) = (&self.grid, &self.bound, &self.moved, &self.strays);
            let drift = self.drift;
            grid::scan_chunked(moved.len(), parallel, chunks, late, |of, late| {
                for m in of {
                    let i = moved[m];
                    let b = &bodies[i as usize];
                    let tol = crate::board_contact::touch_tolerance(p.tolerance, b.r, b.x);
                    let s = (b.x - drift).extend(b.r + tol);
                    grid.query(bound, s, |j| {
                        // Pairs of moved marbles, and strays (outside their bounds), are
                        // checked below, once.
                        if !changed[j as usize] && !stray[j as usize] {
                            check(i, j, late);
                        }
                    });
                    if few {
                        for &j in &moved[m + 1..] {
                            check(i, j, late);
                        }
                        for &j in strays {
                            if !changed[j as usize] {
                                check(i, j, late);
                            }
                        }
                    }
                }
            });
        }
        let (grid, bound) = (&self.scratch_grid, &self.scratch_bound);
        if all {
            grid.scan_pairs(bound, late, chunks, parallel, check);
        } else if !few {
            // Moved marbles with each other and with the strays they did not move.
            let late_bodies = &self.late_bodies;
            grid.scan_pairs(bound, late, chunks, parallel, |a, b, late| {
                let (i, j) = (late_bodies[a as usize], late_bodies[b as usize]);
                if changed[i as usize] || changed[j as usize] {
                    check(i, j, late);
                }
            });
        }
    }

    /// Test only: the late pairs `search` found involving a moved marble are exactly
    /// those re-pairing every marble finds (which also sees pairs of unmoved marbles).
    #[cfg(test)]
    pub(super) fn cross_check(&mut self, p: &PairParams, search: LateSearch) {
        let pairs = |late: &[Row], changed: &[bool]| {
            let mut v: Vec<(u32, u32)> = late
                .iter()
                .filter(|r| changed[r.i as usize] || changed[r.j as usize])
                .map(|r| (r.i, r.j))
                .collect();
            v.sort_unstable();
            v
        };
        let found = pairs(&self.late, &self.changed);
        self.find_late(p, LateSearch::All);
        let every = pairs(&self.late, &self.changed);
        assert_eq!(found, every, "{search:?} missed or added late pairs");
        self.cross_checked[search as usize] += 1;
        self.find_late(p, search);
    }

    /// After collisions moved marbles off their free paths, pairs that overlap at the end
    /// of the substep are found on the end positions: pairs that were not among the rows
    /// (the broad phase saw the free paths), and rows whose marbles were hit again after
    /// the row's time (they can meet again). Each is traced back along the marbles' new
    /// straight paths to where they met ([`late_row`]); a pair approaching faster than the
    /// threshold collides there, and every one is then a contact.
    /// Returns whether any marble collided.
    pub(super) fn late_overlaps(&mut self, p: &PairParams) -> bool {
        // The rows' pairs by first body, a counting sort.
        let n = self.bodies.len();
        self.known_start.clear();
        self.known_start.resize(n + 2, 0);
        for row in &self.rows {
            self.known_start[row.i.min(row.j) as usize + 2] += 1;
        }
        for k in 2..n + 2 {
            self.known_start[k] += self.known_start[k - 1];
        }
        self.known.clear();
        self.known.resize(self.rows.len(), 0);
        for row in &self.rows {
            let slot = &mut self.known_start[row.i.min(row.j) as usize + 1];
            self.known[*slot as usize] = row.i.max(row.j);
            *slot += 1;
        }
        self.moved.clear();
        self.moved
            .extend((0..self.bodies.len() as u32).filter(|&i| self.changed[i as usize]));
        // The grid still bounds every marble's path over the substep, and a marble the
        // cascade did not touch ends inside its bound: the moved marbles are looked up
        // against it, and against each other and the strays (outside their bounds)
        // directly when few, else through a grid of their own on the end positions (the
        // cost stays linear in the marbles moved). When a large share moved, every marble
        // is paired again on the end positions.
        let search = if self.moved.len() <= LATE_DIRECT {
            LateSearch::Direct
        } else if self.moved.len() * LATE_SHARE > n {
            LateSearch::All
        } else {
            LateSearch::OwnGrid
        };
        self.find_late(p, search);
        #[cfg(test)]
        if self.cross_check_late && search != LateSearch::All {
            self.cross_check(p, search);
        }
        // A pair already among the rows can meet (again) when one of them is hit later in
        // the substep (a marble knocked onto the floor rebounds into the one that knocked
        // it): such a pair found approaching and overlapping at the end is traced back to
        // its new meeting.
        // A shallow impact left to the next substep (its limit infinite) is taken up only
        // if the later hits drove it deep.
        let first_again = self.late.len();
        for row in &self.rows {
            let (i, j) = (row.i as usize, row.j as usize);
            if !(self.changed[i] || self.changed[j]) || self.event[i].max(self.event[j]) <= row.t {
                continue;
            }
            let (a, b) = (&self.bodies[i], &self.bodies[j]);
            let d = b.x - a.x;
            let deferred = row.limit == f32::INFINITY
                && a.r + b.r - d.length() < DISCRETE_OVERLAP * a.r.min(b.r);
            if !deferred
                && (b.v - a.v).dot(d) < -p.threshold * d.length()
                && let Some(again) = late_row(&self.bodies, &self.event, row.i, row.j, p)
            {
                self.late.push(again);
            }
        }
        // A pair with several rows is traced once.
        self.late[first_again..].sort_unstable_by_key(|r| (r.i, r.j));
        let mut kept = first_again;
        for k in first_again..self.late.len() {
            let pair = (self.late[k].i, self.late[k].j);
            if kept == first_again || pair != (self.late[kept - 1].i, self.late[kept - 1].j) {
                self.late[kept] = self.late[k];
                kept += 1;
            }
        }
        self.late.truncate(kept);
        // Earliest first, so that a marble's later impact sees what its earlier one did.
        self.late
            .sort_by(|a, b| a.t.total_cmp(&b.t).then((a.i, a.j).cmp(&(b.i, b.j))));
        let mut any = false;
        for row in self.late.iter_mut() {
            let (i, j) = (row.i as usize, row.j as usize);
            let u = (self.bodies[j].v - self.bodies[i].v).dot(row.n);
            if u < -p.threshold {
                let impulse = -(1.0 + row.e) * u * row.k;
                let (wi, wj) = (self.bodies[i].w, self.bodies[j].w);
                let rest = p.h - row.t;
                self.bodies[i].v -= (impulse * wi) * row.n;
                self.bodies[j].v += (impulse * wj) * row.n;
                self.bodies[i].x -= (impulse * wi * rest) * row.n;
                self.bodies[j].x += (impulse * wj * rest) * row.n;
                self.event[i] = self.event[i].max(row.t);
                self.event[j] = self.event[j].max(row.t);
                self.changed[i] = true;
                self.changed[j] = true;
                row.collided = true;
                any = true;
            }
        }
        self.rows.extend_from_slice(&self.late);
        any
    }

    /// Marbles the cascade moved off their paths, checked against the boards along them. A
    /// collision can send a marble in flight into a board it did not touch during the
    /// substep (the cascade only knows the boards each marble touched). Since its last
    /// event the marble has moved on a straight line; that path, from where the marble was
    /// then, is searched for its earliest impact with a board it did not touch there
    /// ([`crate::board_contact::earliest_impact`]: exact for planes, meshes, thin boxes and moving
    /// boards alike). There, faster than the threshold it rebounds (equation (1) with the
    /// pair's restitution), slower it stops approaching, and it moves on for the rest of the
    /// substep (a few impacts at most). Boards it already touched at its last event that
    /// it now presses into put it back on their surface and stop its approach.
    ///
    /// Each marble's search depends on that marble alone: with `parallel`, the marbles
    /// are cut into chunks on the task pool, with the same bits.
    pub(super) fn onto_boards(
        &mut self,
        p: &PairParams,
        boards: &[BoardSnapshot],
        near: &NearOf<'_>,
    ) {
        let rows = (
            self.bodies.as_mut_slice(),
            self.changed.as_slice(),
            self.event.as_mut_slice(),
        );
        crate::systems::run_rows(rows, self.on_pool, |(bodies, changed, event)| {
            onto_boards_of(p, boards, near, bodies, changed, event);
        });
    }
}

/// [`PairSolver::onto_boards`] for `bodies`, with their `changed` marks and `event`
/// times, each marble's board searches through its near-piece list (`near`) where it has
/// one.
fn onto_boards_of(
    p: &PairParams,
    boards: &[BoardSnapshot],
    near: &NearOf<'_>,
    bodies: &mut [Body],
    changed: &[bool],
    event: &mut [f32],
) {
    let (mut touching, mut touches) = (TouchList::default(), TouchList::default());
    for (k, b) in bodies.iter_mut().enumerate() {
        if !changed[k] {
            continue;
        }
        let tol = crate::board_contact::touch_tolerance(p.tolerance, b.r, b.x);
        let material = Material {
            restitution: b.e,
            ..Material::default()
        };
        let r = b.r;
        let list = near(b.entity);
        // The boards within touching distance of centre `x` moving at `v`, at time `t`.
        let gather = |t: f32, x: Vec3, v: Vec3, out: &mut TouchList| {
            crate::board_contact::gather(boards, list, t, x, r, tol, &material, -v, out);
        };
        let mut t0 = event[k].min(p.h);
        let mut start = b.x - b.v * (p.h - t0);
        // With one board, the clearance the list shows when it shows the marble clear of
        // the board there (as detection asks it).
        let mut clear = match (boards, list) {
            ([board], Some(list)) => crate::board_contact::gather_single(
                board,
                list,
                t0,
                start,
                r,
                tol,
                &material,
                -b.v,
                &mut touching,
            ),
            _ => {
                gather(t0, start, b.v, &mut touching);
                None
            }
        };
        for _ in 0..BOARD_IMPACTS {
            let path = Path {
                t0,
                x: start,
                v: b.v,
                a: Vec3::ZERO,
            };
            // Clear of the scene's only board for the rest of the substep by its list's
            // word: the search would skip the board on this same test.
            if let (Some(clear), [board], Some(list)) = (clear.take(), boards, list)
                && crate::board_contact::path_is_clear(board, list, &path, p.h - t0, r, tol, clear)
            {
                break;
            }
            let Some((tau, piece)) = crate::board_contact::earliest_impact(
                boards,
                list,
                &path,
                p.h - t0,
                b.r,
                tol,
                &touching,
            ) else {
                break;
            };
            let at = path.position(tau);
            gather(t0 + tau, at, b.v, &mut touches);
            let Some(t) = touches.as_slice().iter().find(|t| t.piece == piece) else {
                break;
            };
            let u = (b.v - t.board_velocity).dot(t.normal);
            if u < -p.threshold {
                b.v -= (1.0 + t.material.restitution) * u * t.normal;
            } else if u < 0.0 {
                b.v -= u * t.normal;
            }
            t0 += tau;
            start = at;
            b.x = at + b.v * (p.h - t0);
            event[k] = t0;
            touching = touches;
        }
        // The boards it touched when it was last set moving: pressed into, it stays on
        // them.
        for t in touching.as_slice() {
            let depth = b.r - (b.x - t.point).dot(t.normal);
            let u = (b.v - t.board_velocity).dot(t.normal);
            if depth > 0.0 && u < 0.0 {
                b.v -= u * t.normal;
                b.x += depth * t.normal;
            }
        }
    }
}
