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
//! 1. **Touches at `t`.** The pieces the marble touches ([`crate::board_contact::gather`]).
//! 2. **Velocity response.** For each touch, the normal closing speed
//!    `u_n = (v − v_b(p))·n` decides (the seed's 衝突 / 接触): `u_n < −threshold` is a
//!    *collision* and gets equation (1) — the board's velocity taken at the contact point,
//!    `v_b(p) = v + ω × (p − c)`; otherwise a *contact*, whose approaching normal velocity
//!    is removed (e = 0). At `t = 0` `v` is the velocity before this step's forces, so a
//!    resting marble, whose gravity-induced speed `g·h` may well exceed the threshold, is
//!    never mistaken for an impact. Several touches are solved together by a few
//!    Gauss–Seidel passes that enforce every `u_n ≥ target`.
//! 3. **Constrained acceleration.** For every touch the marble is not leaving (see `Hold`), the marble
//!    is put on the surface (it is within the touching tolerance of it, or, at the
//!    substep's start, overlapping it: the end-of-substep check would put it there), its
//!    residual normal
//!    speed relative to the board is removed, and so is the part of the acceleration that
//!    pushes into the board. A resting marble therefore stays exactly where it is (no
//!    sinking, no correction, no jitter), and a marble on a smooth incline follows its
//!    surface exactly (`s = ½ g sinθ t²` with Verlet).
//! 4. **Continuous collision** (`ccd`): the earliest impact along the marble's path (the
//!    exact parabola of its integrator's *path velocity*, see [`Integrator`]) with a piece
//!    not touched yet ([`crate::board_contact::earliest_impact`]); advance to it and go to 1.
//!    Without `ccd`, or when no impact remains, integrate to `h`.
//! 5. **End of substep.** Any penetration left (boards that turned into the marble, marbles
//!    spawned inside a board, or every impact when `ccd` is off) is resolved by the same
//!    collision-or-contact rule, judged on the closing speed `u0` before this step's forces,
//!    and without adding energy: the centre is projected onto the surface (no velocity is
//!    added for it), and a collision found this late leaves with normal speed `−e·u0` —
//!    equation (1) on the approach speed, not on the end speed, which carries the gravity of
//!    the time spent inside the board. A marble found past a piece's middle, away from the
//!    face it touched at the start, goes back out through that face (see `came_through`).
//!
//! # Rolling (only for marbles that spin)
//! With rolling on, marbles carry an angular velocity `ω` and the solid-sphere inertia
//! `I = (2/5) m r²`. The contact point moves at `v_c = v + ω × (−r n) − v_b(p)`; its
//! tangential part is the *slip*. Per unit mass, a tangential force `f` at the contact
//! changes the slip at the rate `a_t + (7/2) f` (`f` itself, plus `(5/2) f` through the
//! spin it drives: `α = (5 / 2r) (−n × f)`), so:
//! - at an impact (step 2), the tangential impulse that stops the slip is `−(2/7) v_c,t`,
//!   limited by Coulomb to `μ` × the normal impulse of that impact (an oblique impact puts
//!   spin on the marble);
//! - on a sustained touch (step 3), with normal force `N` (the normal acceleration the
//!   touch removed): if the marble rolls (no slip), static friction
//!   `f = −(2/7)(a_t + α_rr × (−r n))` keeps it rolling, unless that exceeds `μN`; if it
//!   slips, kinetic friction `f = −μN ŝ`. Kinetic friction stops the slip at a time found
//!   in closed form, which is an event of the loop like an impact, so rolling begins at its
//!   exact moment (`2 v0 / (7 μ g)` for a marble launched without spin);
//! - rolling resistance `c` is a torque `c N r` against the rolling spin (a rolling marble
//!   then decelerates at `(5/7) c g`) and spin damping `k` a torque `k N r` against the spin
//!   about the normal; both are opt-in (default 0). A spin whose tangential part is at rest
//!   meets a static resistance (`held_spin`): any torque up to `c N r` that keeps it at
//!   rest, else `c N r` against its start, so a marble stays on an incline with
//!   `tan θ ≤ c`.
//!
//! The forces are constant over each stretch between events, so the exact-parabola path
//! and the spin `ω + α τ` stay exact there. On a turning board the slip also changes with
//! the material under the contact (`board_slip_rate`), which static friction holds
//! against. For the Euler schemes, whose reported velocities lag or lead the path, the
//! regime and the hold of each touch are decided on the path's state (`lead_in`,
//! `normal_speed`; `docs/PHYSICS.md` §5).
//!
//! The commonest case — a marble on one convex piece of a still board, not leaving it,
//! with nothing else within reach of its substep — has this loop's result in closed form
//! ([`resolve_resting`]; [`resolve_rolling`] for a marble that spins, when no friction
//! event falls inside the substep): the response, the constrained (and frictional)
//! accelerations and the exact path to the substep's end, with no search (see
//! [`crate::board_contact`], "Near pieces"). A marble that does not spin, riding convex
//! pieces of a scene's only board while that board moves or turns (its floor, or its
//! floor and a wall), has it too ([`resolve_riding`]): the loop's own operations on
//! those touches, its search for an impact and its end-of-substep gather answered from
//! the marble's near-piece list where the list covers them. Unit tests check that all
//! three give the loop's bits.
//!
//! The impact count per substep is bounded ([`StepConfig::max_impacts`]); a marble wedged so
//! that it would collide for ever finishes the substep as without continuous collision: its
//! free path, then the end-of-substep check. So is the count of friction events
//! ([`MAX_FRICTION_EVENTS`]): a touch changes regime a few times in a substep at most (a
//! slip that stops, a spin that stops), so a marble past the bound is chattering between
//! regimes (a rolling resistance so strong that a spin it stops is restarted by the
//! friction of a turning board, stopped again a picosecond later, and so on, in steps
//! below the resolution of `t`); it finishes the substep without friction, its spin
//! held and its constraints kept, which can only remove the chatter's work.
//!
//! [`StepConfig::max_impacts`]: crate::config::StepConfig::max_impacts

use glam::Vec3;

use crate::board_contact::{
    BoardSnapshot, MAX_TOUCHES, Material, NearPieces, Path, Touch, TouchList, earliest_impact,
    gather, gather_board, touched_path_is_clear,
};
use crate::components::{Contact, ContactKind, ContactList};
use crate::config::Integrator;

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

impl SubstepParams {
    /// The settings of a substep of length `h` under `config`.
    pub fn from_config(config: &crate::config::StepConfig, h: f32) -> Self {
        SubstepParams {
            h,
            integrator: config.integrator,
            ccd: config.ccd,
            threshold: config.restitution_threshold,
            tolerance: config.contact_tolerance,
            max_impacts: config.max_impacts,
        }
    }
}

/// One marble's input to [`resolve`].
#[derive(Clone, Copy, Debug)]
pub struct MarbleIn {
    /// Centre at the substep's start.
    pub x0: Vec3,
    /// Velocity at the substep's start, before this step's forces.
    pub v0: Vec3,
    /// Angular velocity at the substep's start, when the marble spins (rolling on).
    pub w0: Option<Vec3>,
    /// Acceleration over the substep.
    pub a: Vec3,
    /// Radius.
    pub r: f32,
    /// The marble's contact coefficients.
    pub material: Material,
}

/// What detection found for a marble, handed to [`resolve`].
#[derive(Clone, Copy, Debug)]
pub enum Found {
    /// Touches at the substep's start, already in the touch list given to [`resolve`].
    Touching,
    /// No touch at the start; the first impact along the free path at this time.
    Impact(f32),
    /// No touch at the start; overlap at the end of the free path (`ccd` off).
    Overlap,
}

/// How many touching tolerances out the end of a substep looks for a marble held on a
/// turning board all through it (see `resolve_with`, "End of substep").
const DRIFT: f32 = 4.0;

/// Most friction events (a slip or a spin that stops) per marble per substep; past it the
/// substep ends without friction (module docs).
pub const MAX_FRICTION_EVENTS: u32 = 16;

/// A marble's state inside the event loop.
#[derive(Clone, Copy, Debug)]
struct State {
    /// Displacement from `x0`: small numbers, added to the position once at the end with
    /// compensated summation, so that f32 keeps sub-ulp motion far from the origin and at
    /// tiny steps.
    d: Vec3,
    /// Velocity: the integrator's reported velocity until converted at the start, then the
    /// path velocity (see `Integrator`).
    v: Vec3,
    /// Angular velocity (zero and unused when the marble does not spin).
    w: Vec3,
    /// Radius.
    r: f32,
}

/// What [`settle`] leaves the marble with until the next event.
#[derive(Clone, Copy, Debug)]
struct Motion {
    /// Linear acceleration (constraints and friction included).
    a: Vec3,
    /// Angular acceleration.
    alpha: Vec3,
    /// Time after which kinetic friction will have stopped a slip, or rolling resistance or
    /// spin damping a spin (an event of the loop), if it does.
    slip_stops: Option<f32>,
    /// Every frictional touch rolls (or rests) under static friction below its Coulomb
    /// bound: no slip can start before the next event.
    rolls: bool,
    /// The touches (bits by index) whose friction is static: rolling, or at rest.
    gripped: u8,
    /// At least one touch, and every touch holds the marble (its normal speed within
    /// [`separation_speed`]): the accelerations are those constraints'.
    held: bool,
}

/// The result of [`resolve`] for one marble.
#[derive(Clone, Copy, Debug)]
pub struct MarbleOut {
    /// Displacement from `x0` over the substep.
    pub d: Vec3,
    /// Velocity at the end (the integrator's reported velocity).
    pub v: Vec3,
    /// Angular velocity at the end (unchanged input when the marble does not spin).
    pub w: Vec3,
}

/// Runs the event loop of the module docs for one marble and records its contacts.
/// `touches` is the loop's working list: it holds the start touches when `found` is
/// [`Found::Touching`].
pub fn resolve(
    boards: &[BoardSnapshot],
    near: Option<&NearPieces>,
    p: &SubstepParams,
    m: &MarbleIn,
    found: Found,
    touches: &mut TouchList,
    contacts: &mut ContactList,
) -> MarbleOut {
    // Two instances of one loop: a marble that does not spin pays nothing for rolling.
    if m.w0.is_some() {
        resolve_with::<true>(boards, near, p, m, found, touches, contacts)
    } else {
        resolve_with::<false>(boards, near, p, m, found, touches, contacts)
    }
}

/// [`resolve`] for a marble that spins (`SPINS`) or not.
fn resolve_with<const SPINS: bool>(
    boards: &[BoardSnapshot],
    near: Option<&NearPieces>,
    p: &SubstepParams,
    m: &MarbleIn,
    found: Found,
    touches: &mut TouchList,
    contacts: &mut ContactList,
) -> MarbleOut {
    let tol = crate::board_contact::touch_tolerance(p.tolerance, m.r, m.x0);
    let hold = Hold::new(p.threshold, p.h);
    let offset = |a: Vec3| p.integrator.velocity_offset(a, p.h);
    let mut t = 0.0f32;
    let mut s = State {
        d: Vec3::ZERO,
        // Collisions and contacts at the start are judged on the velocity before this
        // step's forces.
        v: m.v0,
        w: m.w0.unwrap_or(Vec3::ZERO),
        r: m.r,
    };
    let mut impacts = 0;
    // Friction events so far; past `MAX_FRICTION_EVENTS` the touches are frictionless.
    let mut friction_events = 0;
    contacts.clear();
    // Whether the end-of-substep check can be skipped: see below.
    let mut settled_start = matches!(found, Found::Touching);
    let regather = |t: f32, s: &State, touches: &mut TouchList| {
        gather(
            boards,
            near,
            t,
            m.x0 + s.d,
            m.r,
            tol,
            &m.material,
            -s.v,
            touches,
        );
    };

    // An impact at `t` along the path: the touches there, their response, and the motion
    // they leave.
    let at_impact = |t: f32,
                     s: &mut State,
                     touches: &mut TouchList,
                     contacts: &mut ContactList,
                     friction: bool| {
        regather(t, s, touches);
        respond::<SPINS>(
            touches.as_slice(),
            s,
            p.threshold,
            boards,
            t,
            0.0,
            m.a,
            contacts,
        );
        settle_with::<SPINS>(
            touches.as_slice(),
            s,
            m.a,
            hold.within(p.h - t),
            false,
            0.0,
            friction,
        )
    };

    // From here on `s.v` is the path velocity (see `Integrator`), and `motion` the
    // accelerations left after the constraints and friction of the touches.
    let mut motion = match found {
        Found::Touching => {
            // The start's velocities are the integrator's reported ones, `lead` seconds
            // behind the path (see `lead_in`).
            let lead = p.integrator.velocity_lead(p.h);
            respond::<SPINS>(
                touches.as_slice(),
                &mut s,
                p.threshold,
                boards,
                0.0,
                lead,
                m.a,
                contacts,
            );
            let motion = settle::<SPINS>(touches.as_slice(), &mut s, m.a, hold, true, lead);
            if SPINS {
                lead_in(touches.as_slice(), &mut s, m.a, hold, motion, lead)
            } else {
                s.v += offset(motion.a);
                motion
            }
        }
        Found::Impact(tau) => {
            s.v += offset(m.a);
            advance::<SPINS>(&mut s, &free(m.a), tau);
            t = tau;
            impacts = 1;
            at_impact(t, &mut s, touches, contacts, true)
        }
        Found::Overlap => {
            s.v += offset(m.a);
            free(m.a)
        }
    };

    while t < p.h {
        let span = p.h - t;
        // A slip that stops inside the span is an event: friction changes from kinetic to
        // static there.
        let (reach, slip_event) = match motion.slip_stops {
            Some(ts) if ts < span => (ts, true),
            _ => (span, false),
        };
        // After `max_impacts` events the rest of the substep is left to the end-of-substep
        // check, as without CCD (a wedged marble, or a search that keeps stopping short).
        if p.ccd && impacts < p.max_impacts {
            let path = Path {
                t0: t,
                x: m.x0 + s.d,
                v: s.v,
                a: motion.a,
            };
            if let Some((tau, _)) = earliest_impact(boards, near, &path, reach, m.r, tol, touches) {
                advance::<SPINS>(&mut s, &motion, tau);
                t += tau;
                settled_start = false;
                impacts += 1;
                let friction = friction_events < MAX_FRICTION_EVENTS;
                motion = at_impact(t, &mut s, touches, contacts, friction);
                continue;
            }
        }
        advance::<SPINS>(&mut s, &motion, reach);
        if slip_event {
            t += reach;
            settled_start = false;
            friction_events += 1;
            let friction = friction_events < MAX_FRICTION_EVENTS;
            regather(t, &s, touches);
            motion = settle_with::<SPINS>(
                touches.as_slice(),
                &mut s,
                m.a,
                hold.within(p.h - t),
                false,
                0.0,
                friction,
            );
            continue;
        }
        t = p.h;
        break;
    }

    // The end-of-substep check finds nothing when the marble spent the whole substep on
    // the touches it started with, all of them complete (no other piece within reach),
    // put onto their surfaces at the start, sustained (not leaving: normal speed and acceleration into them
    // removed), convex and on static boards: a convex piece lies behind its tangent plane,
    // and a path that never approaches that plane never enters it; every other piece was
    // watched by continuous collision. That is the common case of a marble resting,
    // sliding or rolling.
    if p.ccd
        && settled_start
        && t >= p.h
        && let Some(out) = held_still::<SPINS>(boards, p, m, hold, touches, motion, &s)
    {
        return out;
    }

    // End of substep: resolve what still overlaps, or touches while approaching.
    // A marble held on a turning board all substep ends with the drift of its held path
    // (constant accelerations, while the board's normal and the Coriolis term turn): off
    // the surface by up to about `h³` times their rates, with a normal speed of order `h²`
    // times them. Both would make the next substep take it for leaving, and a drift past
    // the touching tolerance would lose the touch; so the end looks `DRIFT` tolerances out
    // for such a marble, and where the pull into the surface would bring it back before it
    // rose past that (`u² ≤ 2 |a_n| tol`), it is not leaving: it is put back on the
    // surface, its drift removed.
    let held_turning = settled_start && t >= p.h && turns(touches.as_slice());
    let end_tol = if held_turning { DRIFT * tol } else { tol };
    gather(
        boards,
        near,
        p.h,
        m.x0 + s.d,
        m.r,
        end_tol,
        &m.material,
        -s.v,
        touches,
    );
    // A marble whose centre, at the start, was behind the face it is now found inside
    // did not come in through that face.
    if touches
        .as_slice()
        .iter()
        .any(|tc| past_middle(tc, m.r, s.d))
    {
        came_through(boards, near, p, m, tol, s.d, touches);
    }
    let settled = settled_start && t >= p.h;
    let friction = friction_events < MAX_FRICTION_EVENTS;
    finish::<SPINS>(
        boards,
        p,
        m,
        (tol, end_tol),
        settled,
        held_turning,
        motion,
        friction,
        s,
        touches,
        contacts,
    )
}

/// Step 5 of the module docs after the end-of-substep gather: `touches` holds what the
/// marble touches (or overlaps) where its path `s` ended, found within `end_tol` (`tol`:
/// the touching tolerance; `end_tol` is wider for a marble `held_turning`, held on a
/// turning board all through the substep). Resolves what still overlaps or approaches,
/// then goes back from the path's velocity to the integrator's. `settled`: the marble
/// spent the whole substep on the touches it started with (no event), under `motion`;
/// `friction`: below [`MAX_FRICTION_EVENTS`].
#[expect(
    clippy::too_many_arguments,
    reason = "the event loop's state, handed over"
)]
#[inline(always)]
fn finish<const SPINS: bool>(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    (tol, end_tol): (f32, f32),
    settled: bool,
    held_turning: bool,
    motion: Motion,
    friction: bool,
    mut s: State,
    touches: &mut TouchList,
    contacts: &mut ContactList,
) -> MarbleOut {
    let hold = Hold::new(p.threshold, p.h);
    let sep = hold.speed;
    // Touches found only by the wider look that are not the held drift are no touches.
    let mut beyond = [false; MAX_TOUCHES];
    for (i, tc) in touches.as_slice().iter().enumerate() {
        let u = (s.v - tc.board_velocity).dot(tc.normal);
        if held_turning && tc.gap >= 0.0 && tc.board_spin != Vec3::ZERO {
            let pull = m.a.dot(tc.normal) - surface_need(tc, s.v - tc.board_velocity);
            if pull < 0.0 && u.abs() < p.threshold && u * u <= -2.0 * pull * end_tol {
                // (`settle` below puts it onto the surface.)
                s.v -= u * tc.normal;
                record(contacts, boards, tc, ContactKind::Contact, u, p.h);
                continue;
            }
        }
        if tc.gap > tol {
            beyond[i] = true;
            continue;
        }
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
            s.v += (-tc.material.restitution * u0 - u) * tc.normal;
        } else if u < 0.0 {
            s.v -= u * tc.normal;
        }
        if tc.gap < 0.0 {
            // Onto the surface; no velocity is added for it.
            s.d -= tc.gap * tc.normal;
        }
        record(contacts, boards, tc, kind, if p.ccd { u } else { u0 }, p.h);
    }
    if held_turning {
        touches.retain_indices(|i| !beyond[i]);
    }
    // Back from the path velocity to the integrator's, with the acceleration the marble
    // is left with.
    let end_hold = if settled && motion.rolls {
        hold.within(0.0).rolled()
    } else {
        hold.within(0.0)
    };
    let end = settle_with::<SPINS>(
        touches.as_slice(),
        &mut s,
        m.a,
        end_hold,
        false,
        0.0,
        friction,
    );
    if settled
        && matches!(p.integrator, Integrator::VelocityVerlet | Integrator::Rk4)
        && !touches.as_slice().is_empty()
        && touches
            .as_slice()
            .iter()
            .all(|tc| (s.v - tc.board_velocity).dot(tc.normal) <= sep)
    {
        // On a curved surface, or a turning one, the constrained acceleration depends on
        // where the marble is and how it moves (a marble in a bowl is a pendulum; the
        // Coriolis term of a turning board follows the marble's speed). The path above
        // held the start's value; velocity Verlet takes the mean of the start's and the
        // end's, which keeps the oscillation's energy bounded instead of growing and the
        // turning board's path second order. (On still flat surfaces the two are equal and
        // nothing changes.) The correction stays in the surface, and is made only when the
        // marble is still held by it at the end: a marble found off its surface there (a
        // drift of the held path by a fraction of a micrometre) has no end constraint to
        // average with, and gravity's full pull would be mistaken for one.
        let mut dv = 0.5 * p.h * (end.a - motion.a);
        for tc in touches.as_slice() {
            dv -= dv.dot(tc.normal) * tc.normal;
        }
        s.v += dv;
        if SPINS {
            s.w += 0.5 * p.h * (end.alpha - motion.alpha);
            if motion.rolls && end.rolls {
                // Rolling all through: the mean leaves the slip what is left of the held
                // path's drift (order `h³` times the rates of the friction rolling needs),
                // which goes, as the drift of the normal does, rather than be taken for a
                // slip by the next substep.
                for (i, tc) in touches.as_slice().iter().enumerate() {
                    if end.gripped & (1 << i) != 0 {
                        let drift = slip(&s, tc);
                        push_tangential(&mut s, tc.normal, -(2.0 / 7.0) * drift);
                    }
                }
            }
        }
    }
    // Semi-implicit Euler is `v' = v + h a(x)`, `x' = x + h v'`: when the same touches
    // held the marble all through the substep (no event, held at its start and its end),
    // its reported velocity gets the acceleration the substep ran on, the start's, which
    // makes it the symplectic scheme on a curved or turning surface too. Taken from the end
    // instead, the force a marble in a bowl feels would be held from the start and reported
    // from the end, and its swing would grow as `exp(ω² h t / 4)`. When the touches change
    // (a marble that lands, or leaves), the end's is the one it goes on with.
    let end = if settled && motion.held && end.held && p.integrator == Integrator::SemiImplicitEuler
    {
        Motion {
            a: motion.a,
            alpha: motion.alpha,
            ..end
        }
    } else {
        end
    };
    let (v, w) = reported::<SPINS>(
        touches.as_slice(),
        &s,
        m.a,
        hold.within(0.0),
        end,
        motion,
        p,
    );
    MarbleOut { d: s.d, v, w }
}

/// True when a marble of radius `r` that moved by `d` over the substep ends overlapping
/// `tc` with its centre, at the start, behind the touch's face: it did not come in
/// through that face ([`came_through`]).
#[inline]
fn past_middle(tc: &Touch, r: f32, d: Vec3) -> bool {
    tc.gap < 0.0 && r + tc.gap < d.dot(tc.normal)
}

/// The end of a substep found the marble inside a piece, past the piece's middle: the
/// nearest way out is through the far side, where its centre was behind that side's
/// face at the substep's start. When the marble touched the piece at the start on
/// another face (turned away from the far one), it went in through that face within the
/// substep: pushed into it by its neighbours harder than it was moving off it, or
/// knocked back into it after leaving it, on a path continuous collision does not watch
/// (the marble starts on the piece). Its way out is back through that face, where the
/// board has carried it by the substep's end: the touch is turned to it, so that the
/// end-of-substep check puts the marble onto the face it came from, not out of the
/// board's far side (a marble at the bottom of a pile would otherwise fall through a
/// floor thinner than its diameter).
#[cold]
#[inline(never)]
fn came_through(
    boards: &[BoardSnapshot],
    near: Option<&NearPieces>,
    p: &SubstepParams,
    m: &MarbleIn,
    tol: f32,
    d: Vec3,
    touches: &mut TouchList,
) {
    let mut start = TouchList::default();
    gather(
        boards,
        near,
        0.0,
        m.x0,
        m.r,
        tol,
        &m.material,
        -m.v0,
        &mut start,
    );
    let x = m.x0 + d;
    for tc in touches.as_mut_slice() {
        if !past_middle(tc, m.r, d) {
            continue;
        }
        let Some(entry) = start
            .as_slice()
            .iter()
            .find(|st| st.piece == tc.piece && st.normal.dot(tc.normal) < 0.0)
        else {
            continue;
        };
        // The face it came through, where the board has carried it.
        let b = &boards[tc.piece.board()];
        let ((c0, q0), (c1, q1)) = (b.pose_at(0.0), b.pose_at(p.h));
        let turn = q1 * q0.conjugate();
        let normal = (turn * entry.normal).normalize();
        let on_face = turn * (entry.point - c0) + c1;
        let gap = (x - on_face).dot(normal) - m.r;
        let point = x - (m.r + gap) * normal;
        *tc = Touch {
            point,
            normal,
            gap,
            board_velocity: b.point_velocity(p.h, point),
            board_accel: b.point_accel(p.h, point),
            ..*tc
        };
    }
}

/// From the path's velocity and spin at the substep's end back to the integrator's
/// reported ones, the converse of [`lead_in`]: `lead` seconds before the path's for
/// semi-implicit Euler, whose path leads, and `−lead` after them for explicit Euler, whose
/// path lags, under the end's accelerations `motion`. Where those would stop a slip or a
/// spin within the `lead` seconds (a friction event), extrapolating them across it would
/// report by as much as their rate times `h/2`: reversed going forward, grown going back
/// (a marble whose huge rolling resistance the turning of its board's normal restarts at
/// the end reported spinning at 10⁸ rad/s, and the next substep's rounding of that number
/// left in its spin). So going forward the regime changes at the event as in the event
/// loop, and going back the reported state follows the accelerations of the path's own
/// last stretch, `last`.
#[inline]
#[allow(clippy::too_many_arguments)]
fn reported<const SPINS: bool>(
    list: &[Touch],
    s: &State,
    a: Vec3,
    hold: Hold,
    motion: Motion,
    last: Motion,
    p: &SubstepParams,
) -> (Vec3, Vec3) {
    let lead = p.integrator.velocity_lead(p.h);
    let event_within = SPINS && motion.slip_stops.is_some_and(|ts| ts < lead.abs());
    let offset = |a: Vec3| p.integrator.velocity_offset(a, p.h);
    if event_within && lead < 0.0 {
        let mut e = *s;
        lead_in(list, &mut e, a, hold, motion, -lead);
        (e.v, e.w)
    } else if event_within {
        (s.v - offset(last.a), s.w - offset(last.alpha))
    } else {
        (s.v - offset(motion.a), s.w - offset(motion.alpha))
    }
}

/// [`resolve`] in closed form for its commonest case, a marble resting, sliding or
/// rolling on one piece: a marble that does not spin, whose only touch at the substep's
/// start is `tc` (on a convex piece of a still board, not overlapping it), that does not
/// leave it, and for which nothing else is within reach of its substep (its
/// [`NearPieces`] list says so: continuous collision has nothing to search, and without
/// it the end-of-substep check would find the marble on the piece's tangent plane). The same
/// operations as the event loop in that case, without its searches: the response, the
/// constrained acceleration, the exact path to the substep's end. `None` (and `contacts`
/// to be rewritten) when the marble leaves the piece: the event loop handles that.
pub fn resolve_resting(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    tc: &Touch,
    contacts: &mut ContactList,
) -> Option<MarbleOut> {
    resting::<false>(boards, p, m, tc, contacts)
}

/// [`resolve_resting`] on a touch whose material does not move (a still board: no
/// velocity, acceleration or spin at the touch, all exactly zero), inlined in its caller:
/// the same bits with the board's terms left out (`v − 0` is `v`, and the zero need of a
/// surface that does not accelerate changes nothing but the sign of a zero), for the
/// commonest case of all, a marble on a still flat face ([`NearPieces::still_face`]).
#[inline(always)]
pub fn resolve_resting_still(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    tc: &Touch,
    contacts: &mut ContactList,
) -> Option<MarbleOut> {
    debug_assert!(
        tc.board_velocity == Vec3::ZERO
            && tc.board_accel == Vec3::ZERO
            && tc.board_spin == Vec3::ZERO
    );
    resting::<true>(boards, p, m, tc, contacts)
}

/// [`resolve_resting`], and with `STILL` [`resolve_resting_still`].
#[inline(always)]
fn resting<const STILL: bool>(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    tc: &Touch,
    contacts: &mut ContactList,
) -> Option<MarbleOut> {
    debug_assert!(m.w0.is_none() && tc.convex);
    // `respond`, `settle` and `advance` on one touch, written out: the same operations in
    // the same order (so the same bits, NaN included), without their lists.
    let hold = Hold::new(p.threshold, p.h);
    let sep = hold.speed;
    let n = tc.normal;
    let relative = |v: Vec3| if STILL { v } else { v - tc.board_velocity };
    let mut v = m.v0;
    let mut d = Vec3::ZERO;
    contacts.clear();
    // Step 2: equation (1) for a collision, the approach removed for a contact.
    let u = relative(v).dot(n);
    let kind = if u < -p.threshold {
        ContactKind::Collision
    } else {
        ContactKind::Contact
    };
    record(contacts, boards, tc, kind, u, 0.0);
    if u < 0.0 {
        let target = if kind == ContactKind::Collision {
            -tc.material.restitution * u
        } else {
            0.0
        };
        for _ in 0..4 {
            let u = relative(v).dot(n);
            if u < target {
                v += (target - u) * n;
            } else {
                break;
            }
        }
    }
    // Step 3: on the surface, no normal speed, no acceleration into it.
    let u = relative(v).dot(n);
    let pull = || {
        if STILL {
            m.a.dot(n)
        } else {
            m.a.dot(n) - (tc.board_accel.dot(n) - 2.0 * relative(v).dot(tc.board_spin.cross(n)))
        }
    };
    if hold.holds(u, pull, tc.gap) {
        if tc.gap.abs() > 0.0 {
            d -= tc.gap * n;
        }
        v -= u * n;
    }
    let mut a = m.a;
    for _ in 0..4 {
        let rel = relative(v);
        let an = if rel.dot(n) <= sep {
            if STILL {
                a.dot(n)
            } else {
                let need = tc.board_accel.dot(n) - 2.0 * rel.dot(tc.board_spin.cross(n));
                a.dot(n) - need
            }
        } else {
            0.0
        };
        if an < 0.0 {
            a -= an * n;
        } else {
            break;
        }
    }
    // The exact path to the substep's end.
    let offset = p.integrator.velocity_offset(a, p.h);
    v += offset;
    d += v * p.h + a * (0.5 * p.h * p.h);
    v += a * p.h;
    // The event loop's test for skipping its end-of-substep check.
    let stays = relative(v).dot(n) <= sep && a.dot(n) >= 0.0;
    stays.then(|| MarbleOut {
        d,
        v: v - offset,
        w: Vec3::ZERO,
    })
}

/// [`resolve_resting`] for a marble that spins (rolling on): rolling, or slipping on its
/// one touch with friction, rolling resistance and spin damping. The same operations as
/// the event loop (with continuous collision) when no friction event falls inside the
/// substep (a slip that stops, a spin that rolling resistance or damping stops): the
/// response, the constrained and frictional accelerations, the exact path to the
/// substep's end. `None` (and `contacts` to be rewritten) when an event falls inside the
/// substep, the marble leaves the piece, or continuous collision is off: the event loop
/// handles those.
pub fn resolve_rolling(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    tc: &Touch,
    contacts: &mut ContactList,
) -> Option<MarbleOut> {
    let w0 = m.w0?;
    debug_assert!(tc.convex);
    if !p.ccd {
        return None;
    }
    let hold = Hold::new(p.threshold, p.h);
    let sep = hold.speed;
    let offset = |a: Vec3| p.integrator.velocity_offset(a, p.h);
    let mut s = State {
        d: Vec3::ZERO,
        v: m.v0,
        w: w0,
        r: m.r,
    };
    let touch = std::slice::from_ref(tc);
    contacts.clear();
    // A still board: the lag of the reported velocities changes nothing in the response,
    // and the turning-board terms are all zero (see `settle`).
    debug_assert!(tc.board_spin == Vec3::ZERO);
    let lead = p.integrator.velocity_lead(p.h);
    respond_on::<true, false>(touch, &mut s, p.threshold, boards, 0.0, 0.0, m.a, contacts);
    let mut motion = settle_on::<true, false>(touch, &mut s, m.a, hold, true, 0.0);
    if let Some(ts) = motion.slip_stops {
        // `lead_in` without an event in the lead, and none in the substep after it.
        let after = ts - lead;
        if (lead > 0.0 && ts < lead) || after < p.h + (-lead).max(0.0) {
            return None;
        }
        motion.slip_stops = Some(after);
    }
    s.v += offset(motion.a);
    s.w += offset(motion.alpha);
    advance::<true>(&mut s, &motion, p.h);
    // The event loop's test for skipping its end-of-substep check.
    let stays = (s.v - tc.board_velocity).dot(tc.normal) <= sep && motion.a.dot(tc.normal) >= 0.0;
    stays.then(|| MarbleOut {
        d: s.d,
        v: s.v - offset(motion.a),
        w: s.w - offset(motion.alpha),
    })
}

/// [`resolve`] in closed form for a marble riding the scene's only board: a marble that
/// does not spin, touching at the substep's start the pieces in `touches` (convex pieces
/// of that board, which moves or turns, or stands still: its floor, or also a wall, or a
/// corner), `near` its near-piece list. The event loop's operations in that case, with
/// its searches answered by the list: continuous collision finds nothing while the list
/// covers the path and every listed piece it does not touch is out of the path's reach at
/// its start or within the touching tolerance (the search's own test of each, its first
/// step); on a still board that held the marble all through, the loop's end check is
/// skipped as the loop skips it; otherwise the end of the substep finds at most the
/// listed pieces, computed directly, while the list covers the end. `None` (and
/// `contacts` and `touches` to be rewritten) where those fail, or the marble ends past a
/// piece's middle: the event loop handles those.
pub fn resolve_riding(
    boards: &[BoardSnapshot],
    near: &NearPieces,
    p: &SubstepParams,
    m: &MarbleIn,
    touches: &mut TouchList,
    contacts: &mut ContactList,
) -> Option<MarbleOut> {
    let [board] = boards else {
        return None;
    };
    let start = touches.as_slice();
    debug_assert!(m.w0.is_none());
    debug_assert!(!start.is_empty() && start.iter().all(|tc| tc.convex));
    let tol = crate::board_contact::touch_tolerance(p.tolerance, m.r, m.x0);
    let hold = Hold::new(p.threshold, p.h);
    let mut s = State {
        d: Vec3::ZERO,
        v: m.v0,
        w: Vec3::ZERO,
        r: m.r,
    };
    contacts.clear();
    // The event loop's start on its touches (`Found::Touching`).
    let lead = p.integrator.velocity_lead(p.h);
    respond::<false>(start, &mut s, p.threshold, boards, 0.0, lead, m.a, contacts);
    let motion = settle::<false>(start, &mut s, m.a, hold, true, lead);
    s.v += p.integrator.velocity_offset(motion.a, p.h);
    // Its search for an impact, which finds none where the list covers the path.
    if p.ccd && p.max_impacts > 0 {
        let path = Path {
            t0: 0.0,
            x: m.x0 + s.d,
            v: s.v,
            a: motion.a,
        };
        if !touched_path_is_clear(board, near, touches, &path, p.h, m.r, tol) {
            return None;
        }
    }
    advance::<false>(&mut s, &motion, p.h);
    // The loop's skip of its end check, for touches on a still board that held the
    // marble all through the substep.
    if p.ccd
        && !board.is_moving()
        && let Some(out) = held_still::<false>(boards, p, m, hold, touches, motion, &s)
    {
        return Some(out);
    }
    // Its end: the pieces again, where the board has carried it (the loop's end gather,
    // on the list).
    let held_turning = turns(touches.as_slice());
    let end_tol = if held_turning { DRIFT * tol } else { tol };
    touches.clear();
    if !gather_board::<false>(
        0,
        board,
        Some(near),
        p.h,
        m.x0 + s.d,
        m.r,
        end_tol,
        &m.material,
        -s.v,
        touches,
        &mut None,
    ) || touches
        .as_slice()
        .iter()
        .any(|tc| past_middle(tc, m.r, s.d))
    {
        return None;
    }
    Some(finish::<false>(
        boards,
        p,
        m,
        (tol, end_tol),
        true,
        held_turning,
        motion,
        true,
        s,
        touches,
        contacts,
    ))
}

/// The event loop's skip of its end-of-substep check (for [`resolve_with`], and
/// [`resolve_riding`] on a still board), for a marble that spent the whole substep on the
/// touches it started with: where those are all it can touch (complete), each convex, on
/// a still board and holding it all through (sustained: no normal speed or acceleration
/// leaving it), the path's end `s` is reported as it stands; `None` where the check must
/// run.
#[inline(never)]
fn held_still<const SPINS: bool>(
    boards: &[BoardSnapshot],
    p: &SubstepParams,
    m: &MarbleIn,
    hold: Hold,
    touches: &TouchList,
    motion: Motion,
    s: &State,
) -> Option<MarbleOut> {
    let list = touches.as_slice();
    let sep = hold.speed;
    let held = touches.is_complete()
        && list.iter().all(|tc| {
            tc.convex
                && !boards[tc.piece.board()].is_moving()
                && (s.v - tc.board_velocity).dot(tc.normal) <= sep
                && motion.a.dot(tc.normal) >= 0.0
        });
    held.then(|| {
        let (v, w) = reported::<SPINS>(list, s, m.a, hold.within(0.0), motion, motion, p);
        MarbleOut { d: s.d, v, w }
    })
}

/// From the integrator's reported velocity and spin to the path's, for a marble that
/// spins and touches at the substep's start: the path is `lead` seconds ahead
/// ([`Integrator::velocity_lead`]), so over those seconds the velocity and spin change
/// at the touches' accelerations, and a friction event that falls inside them (a slip that
/// stops) changes the regime there, as in the event loop. Deciding the regime on the
/// reported velocities alone would let the path overshoot the stop by `lead`: a slip
/// reversed every substep, rolling never reached, and on a turning board energy gained.
/// Returns the motion at the path's start, its event times counted from there.
#[inline]
fn lead_in(
    list: &[Touch],
    s: &mut State,
    a: Vec3,
    hold: Hold,
    mut motion: Motion,
    lead: f32,
) -> Motion {
    let mut left = lead;
    // A regime change takes a slip to rolling or a spin to rest, each at most once; the
    // bound only guards against rounding.
    for _ in 0..4 {
        match motion.slip_stops {
            Some(ts) if ts < left => {
                s.v += motion.a * ts;
                s.w += motion.alpha * ts;
                left -= ts;
                motion = settle::<true>(list, s, a, hold, false, left);
            }
            _ => break,
        }
    }
    s.v += motion.a * left;
    s.w += motion.alpha * left;
    motion.slip_stops = motion.slip_stops.map(|ts| ts - left);
    motion
}

/// Free motion under `a`: no constraint, no friction.
#[inline]
fn free(a: Vec3) -> Motion {
    Motion {
        a,
        alpha: Vec3::ZERO,
        slip_stops: None,
        rolls: true,
        gripped: 0,
        held: false,
    }
}

/// Advances the state by `tau` on the exact path of constant accelerations:
/// `d += v τ + ½ a τ²`, `v += a τ`, `ω += α τ`.
#[inline]
fn advance<const SPINS: bool>(s: &mut State, m: &Motion, tau: f32) {
    s.d += s.v * tau + m.a * (0.5 * tau * tau);
    s.v += m.a * tau;
    if SPINS {
        s.w += m.alpha * tau;
    }
}

/// Below this normal speed (m/s) a marble is not leaving the surface it touches.
#[inline]
pub fn separation_speed(threshold: f32) -> f32 {
    (1e-3 * threshold).max(1e-6)
}

/// When a touch holds a marble (step 3 of the module docs): its normal speed `u` off the
/// surface is within [`separation_speed`], or the pull into the surface brings it back
/// within the rest of the substep (`span`) slower than the restitution threshold. In the
/// second case the return would be a contact, which stops the normal motion: the marble
/// ends held either way, and holding it at once differs only by a hop of at most
/// `u²/2|a_n|` (the lowest marbles of a pile, pressed into the floor at hundreds of m/s²
/// while their velocity leaves it at a fraction of a mm/s, hop by nanometres). Judged to
/// leave, it would be free of a surface its path returns into, which continuous
/// collision does not watch (the marble starts on it): a marble at the bottom of a pile
/// ended its substep deep in a floor 2 cm thick and was pushed out under it.
#[derive(Clone, Copy, Debug)]
struct Hold {
    /// [`separation_speed`], m/s.
    speed: f32,
    /// The restitution threshold, m/s.
    threshold: f32,
    /// What is left of the substep, s.
    span: f32,
    /// Slip below this speed (m/s) is rolling: [`ROLLING_SLIP`], or unbounded for
    /// [`Hold::rolled`].
    rolling_slip: f32,
}

impl Hold {
    fn new(threshold: f32, span: f32) -> Hold {
        Hold {
            speed: separation_speed(threshold),
            threshold,
            span,
            rolling_slip: ROLLING_SLIP,
        }
    }

    /// The same with `span` seconds of the substep left.
    fn within(self, span: f32) -> Hold {
        Hold { span, ..self }
    }

    /// The same for the end of a substep whose touches rolled all through it under static
    /// friction below its bound ([`Motion::rolls`], no event): the slip they end with is
    /// the drift of the held path, which kept the start's friction while the friction
    /// rolling needs changed (on a turning board with the marble's velocity and spin, on a
    /// curved face with its normal), of order `h²` times that change. A real marble's
    /// static friction follows the need within its bound, so no slip ever starts: the
    /// touches still roll, their drift removed, with static friction at most `μN`. Taken
    /// for a slip when it passes [`ROLLING_SLIP`] (as it does for a marble rolling at
    /// 2.5 m/s on a board turning at 0.1 rad/s, 1/60 s substeps), the end's kinetic
    /// friction, in the drift's direction, would go into velocity Verlet's average of the
    /// start's and the end's accelerations: a kick of `½ h μ N`.
    fn rolled(self) -> Hold {
        Hold {
            rolling_slip: f32::INFINITY,
            ..self
        }
    }

    /// Whether a marble at normal speed `u` off a surface `gap` away (negative: into it),
    /// pulled into it at `pull()` (its acceleration's normal part less what the surface
    /// needs, asked only when `u` leaves), stays: the return of `gap + u τ + ½ pull τ² = 0` comes within the span at
    /// a speed `√(u² − 2 pull gap)` under the threshold (or never, from inside: at once).
    #[inline(always)]
    fn holds(self, u: f32, pull: impl FnOnce() -> f32, gap: f32) -> bool {
        if u <= self.speed {
            return true;
        }
        if u >= self.threshold && gap >= 0.0 {
            return false;
        }
        let pull = pull();
        if pull >= 0.0 {
            return false;
        }
        let disc = u * u - 2.0 * pull * gap;
        if u >= self.threshold {
            // Inside the surface (`gap < 0`), turned back before it gets out: it never
            // leaves, however fast it starts.
            return disc < 0.0;
        }
        let back = disc.max(0.0).sqrt();
        back < self.threshold && u + back <= -pull * self.span
    }
}

/// Velocity of the marble's contact point relative to the board, tangential part.
#[inline]
fn slip(s: &State, tc: &Touch) -> Vec3 {
    let vc = s.v + s.w.cross(-s.r * tc.normal) - tc.board_velocity;
    vc - vc.dot(tc.normal) * tc.normal
}

/// Applies a tangential impulse per unit mass `j` at the contact of normal `n`: the
/// velocity changes by `j`, the spin by `(5 / 2r²)(−r n × j)`.
#[inline]
fn push_tangential(s: &mut State, n: Vec3, j: Vec3) {
    s.v += j;
    s.w += (-2.5 / s.r) * n.cross(j);
}

/// Step 2 of the module docs: collisions get equation (1), contacts lose their approaching
/// normal velocity, and (for spinning marbles) friction impulses at most `μ` × each normal
/// impulse act against the slip; every touch is recorded. `lag`: how far the state is
/// behind the board's under the free acceleration `a` ([`normal_speed`]).
#[allow(clippy::too_many_arguments)]
#[inline]
fn respond<const SPINS: bool>(
    list: &[Touch],
    s: &mut State,
    threshold: f32,
    boards: &[BoardSnapshot],
    t: f32,
    lag: f32,
    a: Vec3,
    contacts: &mut ContactList,
) {
    if turns(list) {
        respond_on::<SPINS, true>(list, s, threshold, boards, t, lag, a, contacts);
    } else {
        respond_on::<SPINS, false>(list, s, threshold, boards, t, 0.0, a, contacts);
    }
}

/// Whether any of the touches is on a turning board. The response and the hold are
/// written twice ([`respond_on`], [`settle_on`]): with the turning-board terms, and
/// without them for the common case of still boards, which then carries not even their
/// tests (nor the register pressure of their out-of-line calls) in its loops.
#[inline]
fn turns(list: &[Touch]) -> bool {
    list.iter().any(|tc| tc.board_spin != Vec3::ZERO)
}

/// [`respond`] on touches that may be on turning boards (`TURNING`) or are not.
#[allow(clippy::too_many_arguments)]
#[inline]
fn respond_on<const SPINS: bool, const TURNING: bool>(
    list: &[Touch],
    s: &mut State,
    threshold: f32,
    boards: &[BoardSnapshot],
    t: f32,
    lag: f32,
    a: Vec3,
    contacts: &mut ContactList,
) {
    let mut target = [f32::NEG_INFINITY; MAX_TOUCHES];
    let mut normal_impulse = [0.0f32; MAX_TOUCHES];
    // The lag's share of each normal speed (`normal_speed`), taken once: the impulses
    // below act along normals, to which the Coriolis term's `ω × n` is perpendicular.
    let mut shift = [0.0f32; MAX_TOUCHES];
    let mut any = false;
    for (i, tc) in list.iter().enumerate() {
        let rel = s.v - tc.board_velocity;
        let mut u = rel.dot(tc.normal);
        if TURNING && lag != 0.0 && tc.board_spin != Vec3::ZERO {
            shift[i] = lagged_need(tc, rel, lag, a);
            u += shift[i];
        }
        let kind = if u < -threshold {
            ContactKind::Collision
        } else {
            ContactKind::Contact
        };
        if u < 0.0 {
            // In the board's frame the normal part of the relative velocity becomes
            // −e·u_n: equation (1) written as a target normal speed.
            target[i] = if kind == ContactKind::Collision {
                -tc.material.restitution * u
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
            let mut u = (s.v - tc.board_velocity).dot(tc.normal);
            if TURNING {
                u += shift[i];
            }
            if u < target[i] {
                s.v += (target[i] - u) * tc.normal;
                normal_impulse[i] += target[i] - u;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    if SPINS {
        for (i, tc) in list.iter().enumerate() {
            if normal_impulse[i] <= 0.0 {
                continue;
            }
            // The impulse that stops the slip is −(2/7) of it (the contact point's
            // effective mass for a solid sphere is 2/7 m); Coulomb caps it at μ·J_n.
            let slip = slip(s, tc);
            let mut j = -(2.0 / 7.0) * slip;
            let cap = tc.material.friction * normal_impulse[i];
            let len = j.length();
            if len > cap {
                j *= cap / len;
            }
            push_tangential(s, tc.normal, j);
        }
    }
}

/// [`settle`] with friction, or (`friction` false: past [`MAX_FRICTION_EVENTS`]) with the
/// constraints alone, the spin held.
#[inline]
fn settle_with<const SPINS: bool>(
    list: &[Touch],
    s: &mut State,
    a: Vec3,
    hold: Hold,
    overlap: bool,
    lag: f32,
    friction: bool,
) -> Motion {
    if friction {
        settle::<SPINS>(list, s, a, hold, overlap, lag)
    } else {
        settle::<false>(list, s, a, hold, overlap, lag)
    }
}

/// Step 3 of the module docs: for every touch the marble is not leaving (normal speed
/// relative to the board within `sep`), the marble is put on the surface (it is within the
/// touching tolerance, so this moves it by less than that; with `overlap`, at the
/// substep's start, also out of an overlap), its residual normal speed
/// relative to the board is removed, and so is the part of the acceleration that pushes
/// into the board. Without the first two, rounding would let a resting or sliding marble
/// drift off its surface by ulps per step. For spinning marbles, friction, rolling
/// resistance and spin damping then act on those touches (module docs, "Rolling").
#[inline]
fn settle<const SPINS: bool>(
    list: &[Touch],
    s: &mut State,
    a: Vec3,
    hold: Hold,
    overlap: bool,
    lag: f32,
) -> Motion {
    if turns(list) {
        settle_on::<SPINS, true>(list, s, a, hold, overlap, lag)
    } else {
        settle_on::<SPINS, false>(list, s, a, hold, overlap, 0.0)
    }
}

/// [`settle`] on touches that may be on turning boards (`TURNING`) or are not.
#[inline]
fn settle_on<const SPINS: bool, const TURNING: bool>(
    list: &[Touch],
    s: &mut State,
    a: Vec3,
    hold: Hold,
    overlap: bool,
    lag: f32,
) -> Motion {
    let mut a = a;
    for tc in list {
        let rel = s.v - tc.board_velocity;
        let u = normal_speed::<TURNING>(tc, rel, lag, a);
        let pull = || {
            if TURNING && tc.board_spin != Vec3::ZERO {
                a.dot(tc.normal) - turning_need(tc, rel, lag, a)
            } else {
                a.dot(tc.normal)
            }
        };
        if hold.holds(u, pull, tc.gap) {
            if tc.gap > 0.0 || (overlap && tc.gap < 0.0) {
                s.d -= tc.gap * tc.normal;
            }
            s.v -= u * tc.normal;
        }
    }
    // Which touches hold the marble, and the normal acceleration each needs (of the
    // velocity when the path starts, `lag` later): the loop below changes only the
    // acceleration, so both are taken once.
    let mut held = [false; MAX_TOUCHES];
    let mut need = [0.0f32; MAX_TOUCHES];
    for (i, tc) in list.iter().enumerate() {
        let rel = s.v - tc.board_velocity;
        held[i] = normal_speed::<TURNING>(tc, rel, lag, a) <= hold.speed;
        if TURNING && tc.board_spin != Vec3::ZERO {
            need[i] = turning_need(tc, rel, lag, a);
        }
    }
    let mut normal_force = [0.0f32; MAX_TOUCHES];
    for _ in 0..4 {
        let mut changed = false;
        for (i, tc) in list.iter().enumerate() {
            if held[i] {
                let an = a.dot(tc.normal) - need[i];
                if an < 0.0 {
                    a -= an * tc.normal;
                    if SPINS {
                        normal_force[i] -= an;
                    }
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let mut motion = free(a);
    motion.held = !list.is_empty() && held[..list.len()].iter().all(|&h| h);
    if SPINS {
        for (i, tc) in list.iter().enumerate() {
            let nf = normal_force[i];
            if nf > 0.0 && friction::<TURNING>(s, tc, nf, lag, hold.rolling_slip, &mut motion) {
                motion.gripped |= 1 << i;
            }
        }
    }
    motion
}

/// The normal acceleration a marble at velocity `rel` relative to the touch's board needs
/// to stay on its surface. On a turning board the contact point slides over material
/// points of different velocities (`v_b(p)` changes at `a_b + ω × (v − v_b)`) while the
/// normal turns (`ṅ = ω × n`), so `d/dt((v − v_b)·n) = (a − a_b)·n + 2 (v − v_b)·(ω × n)`,
/// centripetal and Coriolis terms, must stay ≥ 0.
#[inline]
fn surface_need(tc: &Touch, rel: Vec3) -> f32 {
    tc.board_accel.dot(tc.normal) - 2.0 * rel.dot(tc.board_spin.cross(tc.normal))
}

/// The normal speed `rel·n` that decides whether a marble stays on a touch, for a state
/// `lag` seconds behind the board's (see [`friction`]) under the free acceleration `a`: a
/// marble held on a turning board's surface has normal acceleration [`surface_need`] (of
/// its velocity then, whose tangential part is `rel + lag a`'s), so its lagging state
/// reports `lag` times that less than the path will have.
#[inline]
fn normal_speed<const TURNING: bool>(tc: &Touch, rel: Vec3, lag: f32, a: Vec3) -> f32 {
    let u = rel.dot(tc.normal);
    if TURNING && lag != 0.0 && tc.board_spin != Vec3::ZERO {
        u + lagged_need(tc, rel, lag, a)
    } else {
        u
    }
}

/// [`surface_need`] at the velocity `lag` later, for a touch on a turning board (on a
/// still one it is zero).
#[inline]
fn turning_need(tc: &Touch, rel: Vec3, lag: f32, a: Vec3) -> f32 {
    surface_need(tc, rel + lag * a)
}

/// `lag` times [`surface_need`] at the velocity `lag` later: the turning board's part of
/// [`normal_speed`].
#[inline]
fn lagged_need(tc: &Touch, rel: Vec3, lag: f32, a: Vec3) -> f32 {
    lag * surface_need(tc, rel + lag * a)
}

/// Slip below this speed (m/s) is rolling.
const ROLLING_SLIP: f32 = 1e-5;

/// Friction, rolling resistance and spin damping of one sustained touch with normal force
/// `nf` per unit mass, added to `motion` (module docs, "Rolling"). `lag`: how many seconds
/// the marble's state is behind the board's (the reported velocities of an integrator
/// whose path leads them, [`lead_in`]); over that time a rolling marble's slip against a
/// turning board's material changes at [`board_slip_rate`], so that is the slip it has.
fn friction<const TURNING: bool>(
    s: &mut State,
    tc: &Touch,
    nf: f32,
    lag: f32,
    rolling_slip: f32,
    motion: &mut Motion,
) -> bool {
    let n = tc.normal;
    let r = s.r;
    let rc = -r * n;
    let mu = tc.material.friction;
    // Rolling resistance: a torque c·N·r against the spin's tangential part, and spin
    // damping: k·N·r against its normal part; per unit mass, α = torque · 5 / (2 r²). Each
    // stops its spin component at a time found in closed form (an event, after which that
    // component is zero and the torque is off), so neither ever reverses the spin.
    let mut alpha = Vec3::ZERO;
    let w_t = s.w - s.w.dot(n) * n;
    let rr = 2.5 * tc.material.rolling_resistance * nf / r;
    let rolling_spin = rr > 0.0 && w_t.length() * r > ROLLING_SLIP;
    if rolling_spin {
        alpha -= rr * w_t.normalize();
    }
    let w_n = s.w.dot(n);
    let sd = 2.5 * tc.material.spin_damping * nf / r;
    if sd > 0.0 && w_n.abs() * r > ROLLING_SLIP {
        alpha -= sd * w_n.signum() * n;
        stop_at(motion, w_n.abs() / sd);
    }
    // The slip's rate of change without friction: the contact point's acceleration, less
    // what the board's material under it does (`board_slip_rate`, zero on boards that do
    // not turn), tangential part.
    let turning = TURNING && tc.board_spin != Vec3::ZERO;
    let a_c = {
        let mut raw = motion.a + (motion.alpha + alpha).cross(rc);
        if turning {
            raw -= board_slip_rate(s, tc);
        }
        raw - raw.dot(n) * n
    };
    let mut slip = slip(s, tc);
    if turning && lag != 0.0 {
        let lagged = lag * board_slip_rate(s, tc);
        slip += lagged - lagged.dot(n) * n;
    }
    if rr > 0.0 && !rolling_spin {
        return held_spin::<TURNING>(s, tc, nf, slip, rr, alpha, rolling_slip, motion);
    }
    let gripped = slip.length() <= rolling_slip;
    let f = if gripped {
        // Rolling: remove the residual slip (rounding, or the held path's drift), then
        // hold it at zero with static friction if Coulomb allows.
        push_tangential(s, n, -(2.0 / 7.0) * slip);
        let need = -(2.0 / 7.0) * a_c;
        motion.rolls &= need.length() <= mu * nf;
        capped(need, mu * nf)
    } else {
        motion.rolls = false;
        let dir = slip.normalize();
        let f = -mu * nf * dir;
        // The slip changes at a_c + (7/2) f; along its own direction it reaches zero at
        // `|slip| / rate` when the rate opposes it.
        let rate = (a_c + 3.5 * f).dot(dir);
        if rate < 0.0 {
            stop_at(motion, slip.length() / -rate);
        }
        f
    };
    let alpha = alpha + (-2.5 / r) * n.cross(f);
    if rolling_spin {
        // The rolling spin decays at its total rate (static friction included).
        let rate = alpha.dot(w_t.normalize());
        if rate < 0.0 {
            stop_at(motion, w_t.length() / -rate);
        }
    }
    motion.a += f;
    motion.alpha += alpha;
    gripped
}

/// [`friction`] for a touch with rolling resistance whose marble's spin has no tangential
/// part: the resistance is then static, like friction on a contact point at rest. It
/// supplies whatever tangential torque, up to its `c N r`, keeps the spin at rest against
/// the other torques (friction's among them), and when that is not enough the spin starts
/// against the full `c N r`, from the first instant. Without this the spin would start
/// unopposed and be stopped again an instant later, every substep: a marble creeping down
/// an incline the resistance holds (`tan θ ≤ c`), and with `c > μ` a chatter of events.
/// `rr` is the resistance's angular acceleration `(5/2) c N / r`; `alpha` this touch's
/// angular acceleration so far (the spin damping's, along the normal).
#[allow(clippy::too_many_arguments)]
fn held_spin<const TURNING: bool>(
    s: &mut State,
    tc: &Touch,
    nf: f32,
    slip: Vec3,
    rr: f32,
    alpha: Vec3,
    rolling_slip: f32,
    motion: &mut Motion,
) -> bool {
    let n = tc.normal;
    let r = s.r;
    let rc = -r * n;
    let cap = tc.material.friction * nf;
    let tangential = |x: Vec3| x - x.dot(n) * n;
    let board = if TURNING && tc.board_spin != Vec3::ZERO {
        board_slip_rate(s, tc)
    } else {
        Vec3::ZERO
    };
    // The tangential angular acceleration the other torques and a friction `f` drive,
    // and the resistance's answer to it: all of it up to `rr`, else `rr` against it.
    let other = tangential(motion.alpha + alpha);
    let drive = |f: Vec3| other + (-2.5 / r) * n.cross(f);
    let gripped = slip.length() <= rolling_slip;
    let (f, alpha_rr) = if gripped {
        // The contact point and the spin both at rest: the rounding residue of the slip
        // goes from the velocity (the spin stays at rest), then friction holds the contact
        // point with the spin held, `f = −a_t`, if Coulomb allows.
        s.v -= slip;
        let need = -tangential(motion.a - board);
        motion.rolls &= need.length() <= cap;
        let f = capped(need, cap);
        let d = drive(f);
        let alpha_rr = capped(-d, rr);
        if d.length() <= rr {
            (f, alpha_rr)
        } else {
            // The resistance cannot hold the spin: the marble rolls, the resistance at
            // `rr` against the spin's start, static friction as for any rolling marble.
            let a_c = tangential(motion.a + (motion.alpha + alpha + alpha_rr).cross(rc) - board);
            let need = -(2.0 / 7.0) * a_c;
            motion.rolls &= need.length() <= cap;
            (capped(need, cap), alpha_rr)
        }
    } else {
        motion.rolls = false;
        let dir = slip.normalize();
        let f = -cap * dir;
        let alpha_rr = capped(-drive(f), rr);
        // The slip changes at the contact point's acceleration: `a + f`, plus the spin's
        // part, `α × (−r n)`, with `α` this touch's (the friction's `(5/2) f` held back
        // by the resistance) and the others'.
        let alpha_f = (-2.5 / r) * n.cross(f);
        let a_c = tangential(
            motion.a + f + (motion.alpha + alpha + alpha_rr + alpha_f).cross(rc) - board,
        );
        let rate = a_c.dot(dir);
        if rate < 0.0 {
            stop_at(motion, slip.length() / -rate);
        }
        (f, alpha_rr)
    };
    motion.a += f;
    motion.alpha += alpha + alpha_rr + (-2.5 / r) * n.cross(f);
    gripped
}

/// `x`, scaled down to length `max` if it is longer: a static force or torque that supplies
/// what is asked of it up to its Coulomb-like bound (friction's `μ N`, rolling
/// resistance's `c N r`).
#[inline]
fn capped(x: Vec3, max: f32) -> Vec3 {
    let m = x.length();
    if m <= max { x } else { x * (max / m) }
}

/// What a turning board adds to the rate of change of the slip (module docs, "Rolling"):
/// with the board turning at a constant `Ω` about a centre moving at constant velocity,
/// and the contact point `p = x − r n` moving over it, the slip `σ = v + ω × (−r n) − v_b(p)`
/// changes at `a + α × (−r n)` minus
/// `a_b(p) + Ω × (v − v_b(p)) + r ω × (Ω × n) − r Ω × (Ω × n)`: the material point's own
/// acceleration, and the turning of the normal and of the material under a moving contact.
/// Static friction holds the slip at zero against this, so that a marble rolls on a
/// turning board as on a still one.
#[inline]
fn board_slip_rate(s: &State, tc: &Touch) -> Vec3 {
    let (n, om) = (tc.normal, tc.board_spin);
    let om_n = om.cross(n);
    tc.board_accel + om.cross(s.v - tc.board_velocity) + s.r * (s.w.cross(om_n) - om.cross(om_n))
}

/// Notes that the friction regime changes (a slip or a spin stops) `after` seconds.
#[inline]
fn stop_at(motion: &mut Motion, after: f32) {
    motion.slip_stops = Some(motion.slip_stops.map_or(after, |t| t.min(after)));
}

#[inline(always)]
fn record(
    contacts: &mut ContactList,
    boards: &[BoardSnapshot],
    tc: &Touch,
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
