//! The marble–board response: one marble through one substep, impacts and contacts.
//!
//! # The problem
//! The seed's response `v' = v_m − (1 + e)((v_m − v_b)·n)n` is exact at the instant of an
//! impact. A discrete step applies it only after the marble has sunk into the board:
//! wrong instant, wrong height (an O(dt) error that compounds bounce after bounce), and a
//! fast marble can pass through a thin board between two steps. A marble resting on a board
//! is the opposite trouble: gravity pulls it in by `g·dt²` every step, and a response that
//! treats that as an impact makes it hop for ever.
//!
//! # The method
//! Each substep of length `h` runs an event loop per marble (`t` from 0 to `h`):
//!
//! 1. **Touches at `t`.** The pieces the marble touches ([`crate::narrow::gather`]).
//! 2. **Velocity response.** For each touch, the normal closing speed
//!    `u_n = (v − v_b(p))·n` decides (the seed's 衝突 / 接触): `u_n < −threshold` is a
//!    *collision* and gets equation (1) — the board's velocity taken at the contact point,
//!    `v_b(p) = v + ω × (p − c)`; otherwise a *contact*, whose approaching normal velocity
//!    is removed (e = 0). At `t = 0` `v` is the velocity before this step's forces, so a
//!    resting marble, whose gravity-induced speed `g·h` may well exceed the threshold, is
//!    never mistaken for an impact. Several touches are solved together by a few
//!    Gauss–Seidel passes that enforce every `u_n ≥ target`.
//! 3. **Constrained acceleration.** For every touch the marble is not leaving, the marble
//!    is put on the surface (it is within the touching tolerance of it), its residual normal
//!    speed relative to the board is removed, and so is the part of the acceleration that
//!    pushes into the board. A resting marble therefore
//!    stays exactly where it is (no sinking, no correction, no jitter), and a marble on a
//!    smooth incline follows its surface exactly (`s = ½ g sinθ t²` with Verlet).
//! 4. **Continuous collision** (`ccd`): the earliest impact along the marble's path (the
//!    exact parabola of its integrator's *path velocity*, see
//!    [`Integrator`]) with a piece not touched yet ([`crate::narrow::earliest_impact`]); advance to it and go to 1.
//!    Without `ccd`, or when no impact remains, integrate to `h`.
//! 5. **End of substep.** Any penetration left (boards that turned into the marble, marbles
//!    spawned inside a board, or every impact when `ccd` is off) is resolved by the same
//!    collision-or-contact rule, judged on the closing speed `u0` before this step's forces,
//!    and without adding energy: the centre is projected onto the surface (no velocity is
//!    added for it), and a collision found this late leaves with normal speed `−e·u0` —
//!    equation (1) on the approach speed, not on the end speed, which carries the gravity of
//!    the time spent inside the board.
//!
//! The impact count per substep is bounded ([`StepConfig::max_impacts`]); a marble wedged so
//! that it would collide for ever stops at its last safe position for the rest of the
//! substep.
//!
//! [`StepConfig::max_impacts`]: crate::config::StepConfig::max_impacts

use glam::Vec3;

use crate::components::{Contact, ContactKind, Contacts};
use crate::config::Integrator;
use crate::narrow::{BoardSnapshot, MAX_TOUCHES, Path, TouchList, earliest_impact, gather};

/// The settings of one substep, copied out of [`crate::config::StepConfig`].
#[derive(Clone, Copy, Debug)]
pub struct SubstepParams {
    /// Substep length, s.
    pub h: f32,
    /// Integrator.
    pub integrator: Integrator,
    /// Continuous collision on.
    pub ccd: bool,
    /// Collision-versus-contact threshold, m/s.
    pub threshold: f32,
    /// Touching tolerance relative to the radius.
    pub tolerance: f32,
    /// Impacts per marble per substep.
    pub max_impacts: u32,
}

/// One marble's input to [`resolve`].
#[derive(Clone, Copy, Debug)]
pub struct MarbleIn {
    /// Centre at the substep's start.
    pub x0: Vec3,
    /// Velocity at the substep's start, before this step's forces.
    pub v0: Vec3,
    /// Acceleration over the substep.
    pub a: Vec3,
    /// Radius.
    pub r: f32,
    /// Restitution.
    pub restitution: f32,
}

/// What detection found for a marble, handed to [`resolve`].
#[derive(Clone, Copy, Debug)]
pub enum Found<'a> {
    /// Touches at the substep's start.
    Touching(&'a TouchList),
    /// No touch at the start; the first impact along the free path at this time.
    Impact(f32),
    /// No touch at the start; overlap at the end of the free path (`ccd` off).
    Overlap,
}

/// Runs the event loop of the module docs for one marble; returns its displacement from
/// `m.x0` over the substep and its end velocity, and records its contacts.
pub fn resolve(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    found: Found<'_>,
    contacts: &mut Contacts,
) -> (Vec3, Vec3) {
    let tol = crate::narrow::touch_tolerance(p.tolerance, m.r, m.x0);
    let sep = separation_speed(p.threshold);
    let offset = |a: Vec3| p.integrator.velocity_offset(a, p.h);
    let mut touches = TouchList::default();
    let mut t = 0.0f32;
    // Displacement from `x0`: small numbers, added to the position once at the end with
    // compensated summation, so that f32 keeps sub-ulp motion far from the origin and at
    // tiny steps.
    let mut d = Vec3::ZERO;
    // The integrator's reported velocity until converted: collisions and contacts at the
    // start are judged on the velocity before this step's forces.
    let mut v = m.v0;
    let mut impacts = 0;
    contacts.clear();
    // Whether the end-of-substep check can be skipped: see below.
    let mut settled_start = matches!(found, Found::Touching(_));

    // From here on `v` is the path velocity (see `Integrator`), and `a` the acceleration
    // left after the constraints of the touches the marble rests on.
    let mut a = match found {
        Found::Touching(start) => {
            touches = *start;
            respond(&touches, &mut v, p.threshold, boards, 0.0, contacts);
            let a = settle(&touches, &mut d, &mut v, m.a, sep);
            v += offset(a);
            a
        }
        Found::Impact(tau) => {
            v += offset(m.a);
            let (dd, vv) = free_step(v, m.a, tau);
            (d, v) = (d + dd, vv);
            t = tau;
            impacts = 1;
            gather(
                boards,
                t,
                m.x0 + d,
                m.r,
                tol,
                m.restitution,
                -v,
                &mut touches,
            );
            respond(&touches, &mut v, p.threshold, boards, t, contacts);
            settle(&touches, &mut d, &mut v, m.a, sep)
        }
        Found::Overlap => {
            v += offset(m.a);
            m.a
        }
    };

    while t < p.h {
        let span = p.h - t;
        if p.ccd {
            if impacts >= p.max_impacts {
                // Wedged: stay at the last safe position for the rest of the substep.
                break;
            }
            let path = Path {
                t0: t,
                x: m.x0 + d,
                v,
                a,
            };
            if let Some((tau, _)) = earliest_impact(boards, &path, span, m.r, tol, &touches) {
                let (dd, vv) = free_step(v, a, tau);
                (d, v) = (d + dd, vv);
                t += tau;
                settled_start = false;
                impacts += 1;
                gather(
                    boards,
                    t,
                    m.x0 + d,
                    m.r,
                    tol,
                    m.restitution,
                    -v,
                    &mut touches,
                );
                respond(&touches, &mut v, p.threshold, boards, t, contacts);
                a = settle(&touches, &mut d, &mut v, m.a, sep);
                continue;
            }
        }
        let (dd, vv) = free_step(v, a, span);
        (d, v) = (d + dd, vv);
        t = p.h;
        break;
    }

    // The end-of-substep check finds nothing when the marble spent the whole substep on
    // the touches it started with, all of them complete (no other piece within reach),
    // not overlapping, sustained (not leaving: normal speed and acceleration into them
    // removed) and on static boards: each piece is convex, so it lies behind its tangent plane, and a path
    // that never approaches that plane never enters it; every other piece was watched by
    // continuous collision. That is the common case of a marble resting or sliding.
    if p.ccd
        && settled_start
        && t >= p.h
        && touches.is_complete()
        && touches.as_slice().iter().all(|tc| {
            !boards[tc.piece.board()].is_moving()
                && tc.gap >= 0.0
                && (v - tc.board_velocity).dot(tc.normal) <= sep
                && a.dot(tc.normal) >= 0.0
        })
    {
        return (d, v - offset(a));
    }

    // End of substep: resolve what still overlaps, or touches while approaching.
    gather(
        boards,
        p.h,
        m.x0 + d,
        m.r,
        tol,
        m.restitution,
        -v,
        &mut touches,
    );
    for tc in touches.as_slice() {
        let u = (v - tc.board_velocity).dot(tc.normal);
        if tc.gap >= 0.0 && u >= 0.0 {
            record(contacts, boards, tc, ContactKind::Contact, u, p.h);
            continue;
        }
        // Classify by the closing speed before this step's forces (the start velocity).
        let u0 = (m.v0 - tc.board_velocity).dot(tc.normal);
        let kind = if !p.ccd && u0 < -p.threshold {
            ContactKind::Collision
        } else {
            ContactKind::Contact
        };
        if kind == ContactKind::Collision {
            // Found late (no CCD): the end velocity carries the gravity of the time spent
            // inside the board, so equation (1) takes the approach speed before this step's
            // forces: the normal speed after is `−e·u0`, never more than came in.
            v += (-tc.restitution * u0 - u) * tc.normal;
        } else if u < 0.0 {
            v -= u * tc.normal;
        }
        if tc.gap < 0.0 {
            // Onto the surface; no velocity is added for it.
            d -= tc.gap * tc.normal;
        }
        record(contacts, boards, tc, kind, if p.ccd { u } else { u0 }, p.h);
    }
    // Back from the path velocity to the integrator's, with the acceleration the marble
    // is left with.
    let a_end = settle(&touches, &mut d, &mut v, m.a, sep);
    (d, v - offset(a_end))
}

/// Displacement and velocity after `tau` on the exact path of constant acceleration:
/// `(v τ + ½ a τ², v + a τ)`.
#[inline]
fn free_step(v: Vec3, a: Vec3, tau: f32) -> (Vec3, Vec3) {
    (v * tau + a * (0.5 * tau * tau), v + a * tau)
}

/// Below this normal speed (m/s) a marble is not leaving the surface it touches.
#[inline]
pub fn separation_speed(threshold: f32) -> f32 {
    (1e-3 * threshold).max(1e-6)
}

/// Step 2 of the module docs: collisions get equation (1), contacts lose their approaching
/// normal velocity; every touch is recorded.
fn respond(
    touches: &TouchList,
    v: &mut Vec3,
    threshold: f32,
    boards: &[BoardSnapshot],
    t: f32,
    contacts: &mut Contacts,
) {
    let list = touches.as_slice();
    let mut target = [f32::NEG_INFINITY; MAX_TOUCHES];
    let mut any = false;
    for (i, tc) in list.iter().enumerate() {
        let u = (*v - tc.board_velocity).dot(tc.normal);
        let kind = if u < -threshold {
            ContactKind::Collision
        } else {
            ContactKind::Contact
        };
        if u < 0.0 {
            // In the board's frame the normal part of the relative velocity becomes
            // −e·u_n: equation (1) written as a target normal speed.
            target[i] = if kind == ContactKind::Collision {
                -tc.restitution * u
            } else {
                0.0
            };
            any = true;
        }
        record(contacts, boards, tc, kind, u, t);
    }
    if !any {
        return;
    }
    for _ in 0..4 {
        let mut changed = false;
        for (i, tc) in list.iter().enumerate() {
            let u = (*v - tc.board_velocity).dot(tc.normal);
            if u < target[i] {
                *v += (target[i] - u) * tc.normal;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Step 3 of the module docs: for every touch the marble is not leaving (normal speed
/// relative to the board within `sep`), the marble is put on the surface (it is within the
/// touching tolerance, so this moves it by less than that), its residual normal speed
/// relative to the board is removed, and so is the part of the acceleration that pushes
/// into the board. Returns that constrained acceleration. Without the first two, rounding
/// would let a resting or sliding marble drift off its surface by ulps per step.
#[inline]
fn settle(touches: &TouchList, d: &mut Vec3, v: &mut Vec3, a: Vec3, sep: f32) -> Vec3 {
    let mut a = a;
    for tc in touches.as_slice() {
        let u = (*v - tc.board_velocity).dot(tc.normal);
        if u <= sep {
            if tc.gap > 0.0 {
                *d -= tc.gap * tc.normal;
            }
            *v -= u * tc.normal;
        }
    }
    for _ in 0..4 {
        let mut changed = false;
        for tc in touches.as_slice() {
            if (*v - tc.board_velocity).dot(tc.normal) <= sep {
                let an = a.dot(tc.normal);
                if an < 0.0 {
                    a -= an * tc.normal;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    a
}

fn record(
    contacts: &mut Contacts,
    boards: &[BoardSnapshot],
    tc: &crate::narrow::Touch,
    kind: ContactKind,
    closing_speed: f32,
    time: f32,
) {
    if contacts.iter().any(|c| c.piece == tc.piece) {
        return;
    }
    contacts.push(Contact {
        board: boards[tc.piece.board()].entity,
        point: tc.point,
        normal: tc.normal,
        depth: -tc.gap,
        closing_speed,
        kind,
        time,
        piece: tc.piece,
    });
}
