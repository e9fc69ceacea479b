//! The exact sphere–sphere narrow phase: touching at the start, meeting inside the substep.

use super::*;

/// Whether impact `row` ends with the pair overlapping by less than [`DISCRETE_OVERLAP`]
/// of the smaller radius, measured along the impact normal (a pair that passed through
/// each other is deep, however far apart it ends).
#[inline]
pub(super) fn shallow(bodies: &[Body], row: &Row) -> bool {
    let (a, b) = (&bodies[row.i as usize], &bodies[row.j as usize]);
    let overlap = a.r + b.r - (b.x - a.x).dot(row.n);
    overlap < DISCRETE_OVERLAP * a.r.min(b.r)
}

/// Whether `row` is an impact the impact stage resolves now: a deep one (not
/// [`shallow`]) whose marbles close.
#[inline]
pub(super) fn deep_impact(bodies: &[Body], row: &Row) -> bool {
    row.kind == Found::Impact && !shallow(bodies, row) && row.u < 0.0
}

/// A necessary condition for marbles `i` and `j` to meet during the substep and end it
/// overlapping deeply (not [`shallow`]): their displacements over the substep differ by
/// at least half the depth that counts, less `slack` ([`rounding_slack`]).
///
/// Why: on the relative path `d(τ) = d₀ + m τ` (`m` the difference of the
/// displacements) the pair meets at `τ*` with `|d(τ*)| = r₁ + r₂` and normal
/// `n = d(τ*) / |d(τ*)|`, so the end overlap along `n` is
/// `r₁ + r₂ − d(1)·n = −(1 − τ*) m·n ≤ |m|`. The factor of one half, and the slack far
/// from the origin, cover the rounding of the narrow phase's root and normal, so that the
/// test never drops a pair the narrow phase would call deep. (Impacts are found only
/// with continuous collision on, but the test does not need to know.)
#[inline]
pub(super) fn may_impact_deeply(bodies: &[Body], i: u32, j: u32, slack: f32) -> bool {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let m = (b.x - b.x0) - (a.x - a.x0);
    let least = 0.5 * DISCRETE_OVERLAP * a.r.min(b.r) - slack;
    least <= 0.0 || m.length_squared() >= least * least
}

/// Sixteen f32 ulps of the largest coordinate and diameter among `bodies` (at the start
/// and end of the substep): more than the narrow phase's rounding of an impact's depth.
pub(super) fn rounding_slack(bodies: &[Body]) -> f32 {
    let far = bodies.iter().fold(0.0f32, |far, b| {
        far.max(b.x.abs().max(b.x0.abs()).max_element() + 2.0 * b.r)
    });
    16.0 * f32::EPSILON * far
}

/// Whether marbles `i` and `j` touch or overlap at the end of the substep (the test
/// [`late_row`] starts with).
#[inline]
pub(super) fn late_touch(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> bool {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let tol =
        crate::board_contact::touch_tolerance(p.tolerance, a.r.min(b.r), a.x.abs().max(b.x.abs()));
    (b.x - a.x).length() - (a.r + b.r) <= tol
}

/// A pair of marbles `i < j` that a collision sent into each other off their free paths,
/// found overlapping (or touching) at the end of the substep: back along their new straight
/// paths to the later of their last impacts, then forward to where they meet.
pub(super) fn late_row(
    bodies: &[Body],
    event: &[f32],
    i: u32,
    j: u32,
    p: &PairParams,
) -> Option<Row> {
    if !late_touch(bodies, i, j, p) {
        return None;
    }
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let d = b.x - a.x;
    let te = event[i as usize].max(event[j as usize]);
    let rest = p.h - te;
    let de = d - (b.v - a.v) * rest;
    let reach = a.r + b.r;
    let le = de.length();
    let m = d - de;
    let (t, n) = if le > reach && m.length_squared() > 0.0 {
        let half_b = de.dot(m);
        let c = (le - reach) * (le + reach);
        let disc = (half_b * half_b - m.length_squared() * c).max(0.0);
        let tau = (c / (-half_b + disc.sqrt())).clamp(0.0, 1.0);
        (te + tau * rest, (de + m * tau).normalize_or(Vec3::Y))
    } else {
        (te, d.normalize_or(Vec3::Y))
    };
    Some(Row {
        i,
        j,
        n,
        u: (b.v - a.v).dot(n),
        t,
        e: 0.5 * (a.e + b.e),
        k: 1.0 / (a.w + b.w),
        limit: p.threshold,
        kind: Found::Impact,
        collided: false,
        gap: 0.0,
        at: u32::MAX,
    })
}

/// A speculative contact for bodies `i < j`, apart at the substep's start (contact stage):
/// a row if they close no faster than the restitution threshold (faster is an impact) and
/// their gap is within what they could close during the substep, their free paths'
/// approach plus what their accelerations alone could close (a marble held by a board or
/// another marble does not follow its free path). The row lets the pair close its gap
/// and no more ([`crate::pairs`], step 4).
#[inline]
pub(super) fn near_row(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> Option<Row> {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let d = b.x - a.x;
    let l = d.length();
    let gap = l - (a.r + b.r);
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    let n = d / l;
    let u = (b.v0 - a.v0).dot(n);
    let closing = (-(b.d - a.d).dot(n)).max(0.0) + (a.a.length() + b.a.length()) * p.h * p.h;
    // A pair closing faster than the threshold is an impact to come, for the impact stage
    // (with its restitution), not a contact.
    (gap <= closing && u >= -p.threshold).then_some(Row {
        i,
        j,
        n,
        u,
        t: 0.0,
        e: 0.0,
        k: 1.0 / (a.w + b.w),
        // Never a collision of the start's cascade.
        limit: f32::INFINITY,
        kind: Found::Near,
        collided: false,
        gap,
        at: u32::MAX,
    })
}

/// Step 2 of [`crate::pairs`] for bodies `i < j`: the pair's row, if they touch at the
/// start, meet during the substep, or touch at its end.
#[inline]
pub(super) fn narrow(bodies: &[Body], i: u32, j: u32, p: &PairParams) -> Option<Row> {
    let (a, b) = (&bodies[i as usize], &bodies[j as usize]);
    let reach = a.r + b.r;
    let tol =
        crate::board_contact::touch_tolerance(p.tolerance, a.r.min(b.r), a.x.abs().max(b.x.abs()));
    let d0 = b.x0 - a.x0;
    let d1 = b.x - a.x;
    let l0 = d0.length();
    let e = 0.5 * (a.e + b.e);
    let k = 1.0 / (a.w + b.w);
    let unit = |d: Vec3, fallback: Vec3| {
        let l = d.length();
        if l > 0.0 { d / l } else { fallback }
    };
    let row = |n: Vec3, u: f32, t: f32, kind: Found| {
        // A pair meeting slower than the threshold is a contact: its approach is removed
        // at the impact (restitution 0), as on boards.
        let slow = kind == Found::Impact && u >= -p.threshold;
        Row {
            i,
            j,
            n,
            u,
            t,
            e: if slow { 0.0 } else { e },
            k,
            limit: if slow { 0.0 } else { p.threshold },
            kind,
            collided: false,
            gap: 0.0,
            at: u32::MAX,
        }
    };
    if l0 - reach <= tol {
        // Touching at the start: judged before this step's forces.
        let n = unit(d0, unit(d1, Vec3::Y));
        return Some(row(n, (b.v0 - a.v0).dot(n), 0.0, Found::Start));
    }
    let l1 = d1.length();
    if p.ccd {
        // |d0 + m τ| = reach on τ ∈ [0, 1].
        let m = d1 - d0;
        let half_b = d0.dot(m);
        if half_b < 0.0 {
            let aa = m.length_squared();
            let c = (l0 - reach) * (l0 + reach);
            let disc = half_b * half_b - aa * c;
            if disc >= 0.0 {
                let tau = c / (-half_b + disc.sqrt());
                if tau <= 1.0 {
                    let n = unit(d0 + m * tau, d0 / l0);
                    // The closing speed at the impact: exact on the linear relative path
                    // (marbles under the same gravity), unless a marble's velocity jumped
                    // during the substep (a board stopped it): then the pair closes at
                    // least as fast as at the end, and judging it slower would leave it
                    // still closing, and sinking into each other, after the impulse.
                    let v_rel = (b.v0 - a.v0).lerp(b.v - a.v, tau);
                    let u = v_rel.dot(n).min((b.v - a.v).dot(n));
                    return Some(row(n, u, tau * p.h, Found::Impact));
                }
            }
        }
    }
    if l1 - reach <= tol {
        let n = unit(d1, d0 / l0);
        return Some(row(n, (b.v0 - a.v0).dot(n), p.h, Found::End));
    }
    None
}
