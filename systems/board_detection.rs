//! Marble–board detection: collision versus contact (the seed's 衝突 / 接触), the first
//! impact along the free path, and the closed forms of the commonest case.

use std::sync::atomic::{AtomicBool, Ordering};

use bevy_ecs::prelude::*;

use super::integrate::{FreeStep, move_freely, start_substep};
use super::{
    BoardRows, BoardStaged, BoardStagedItem, Smooth, SpinStaged, SpinStagedItem, Stepped,
    smooth_material,
};
use crate::board_contact::{
    BoardCache, Material, NearPieces, Path, Touch, TouchList, earliest_impact, gather,
    gather_single, path_is_clear, touch_tolerance,
};
use crate::components::{
    Acceleration, AngularVelocity, Contact, ContactKind, ContactList, Pending, Position,
    PositionCarry, StepStart, Velocity, compensated_add,
};
use crate::config::{StepConfig, Substep};
use crate::response::{
    Found, MarbleIn, SubstepParams, resolve, resolve_resting, resolve_resting_still,
    resolve_riding, resolve_rolling,
};

/// Whether detection flagged any marble for the response stage this substep, one flag for
/// the marbles that do not spin and one for those that do: a response system whose
/// detection flagged none iterates nothing (most substeps of spread marbles, every one of
/// which detection resolves in closed form).
#[derive(Resource, Default)]
pub struct Flagged {
    smooth: AtomicBool,
    spinning: AtomicBool,
}

impl Flagged {
    /// True when the detection of the marbles that spin (`spinning`) or of those that do
    /// not flagged any since the last call, which clears the flag.
    pub(crate) fn take(&self, spinning: bool) -> bool {
        self.flag(spinning).swap(false, Ordering::Relaxed)
    }

    fn flag(&self, spinning: bool) -> &AtomicBool {
        if spinning {
            &self.spinning
        } else {
            &self.smooth
        }
    }
}

/// A rebuilt [`NearPieces`] list reaches this many substeps of the marble's motion beyond
/// it (within two and eight radii; a marble moving more than four radii a substep gets
/// none): rebuilt every few substeps at most, short enough to hold only the pieces around
/// the marble.
const NEAR_SKIN: f32 = 4.0;

/// For every marble that does not spin: the board pieces it touches at the substep's
/// start, each classified by its normal closing speed *before this step's forces* (a
/// collision above `restitution_threshold`, else a contact); if it touches nothing, the
/// first impact along its free path (`ccd`) or its overlap at the end of the path (no
/// `ccd`). Marbles with anything to resolve are flagged for the response stage, except
/// those resting or sliding on one piece with nothing else near ([`resolve_resting`]),
/// and those that do not spin on the scene's only board (riding it where it moves; where
/// it does not, those the closed form above leaves: against a wall, in a corner, beside
/// another listed piece) whose list answers their substep's searches ([`resolve_riding`]),
/// resolved here. The marble's [`NearPieces`] list is rebuilt when it no longer covers
/// the substep.
pub fn detect_board_contacts(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    flagged: Res<Flagged>,
    mut marbles: Query<BoardStaged, Smooth>,
) {
    let stage = Stage::new(&config, &cache, flagged.flag(false), substep.h);
    let parallel = super::on_pool(marbles.iter().len());
    // Table by table over the columns as slices (`BoardRows::of_table`: which change
    // ticks are set, and why). Each marble's contacts are built in one list and stored in its components (the first
    // contact in `Contacts`, `MoreContacts` only for a marble with more). With `parallel`
    // the rows go to the task pool in chunks, each walked by the same loop.
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for t in tables {
        let rows = BoardRows::of_table(t, false);
        super::run_rows(rows, parallel, |rows| stage.detect_rows(rows));
    }
}

/// [`detect_board_contacts`] for marbles that carry an [`AngularVelocity`]: with rolling
/// on, a marble rolling on one piece with nothing else near is resolved here by the event
/// loop on that one touch (friction included). A scene without spinning marbles gives
/// this system nothing to iterate.
pub fn detect_board_contacts_spinning(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    flagged: Res<Flagged>,
    mut marbles: Query<(BoardStaged, SpinStaged), Stepped>,
) {
    let stage = Stage::new(&config, &cache, flagged.flag(true), substep.h);
    let each = |touches: &mut TouchList,
                (m, s): (BoardStagedItem<'_, '_>, SpinStagedItem<'_, '_>)| {
        let material = s.material(m.restitution);
        super::CONTACT_LIST.with_borrow_mut(|list| {
            stage.detect_staged(touches, list, m, Some(s.spin), material);
        });
    };
    super::for_each_marble!(marbles, each);
}

/// A marble's motion state, as the detection systems hand it over.
type MarbleState<'w> = (
    &'w mut Position,
    &'w mut PositionCarry,
    &'w mut Velocity,
    Option<&'w mut AngularVelocity>,
);

/// What every marble's detection shares in a substep.
struct Stage<'a> {
    config: &'a StepConfig,
    cache: &'a BoardCache,
    /// Set when a marble is flagged for the response stage.
    flagged: &'a AtomicBool,
    params: SubstepParams,
    /// The substep's length, s.
    h: f32,
    /// Free motion over the substep, for the marbles no board touches or reaches.
    free: FreeStep,
}

impl<'a> Stage<'a> {
    fn new(config: &'a StepConfig, cache: &'a BoardCache, flagged: &'a AtomicBool, h: f32) -> Self {
        Stage {
            config,
            cache,
            flagged,
            params: SubstepParams::from_config(config, h),
            h,
            free: (config.integrator, config.compensated, h),
        }
    }

    /// Flags a marble for the response stage with what it is to resolve.
    #[inline(always)]
    fn flag(&self, contacts: &mut ContactList, pending: Pending) {
        contacts.pending = pending;
        self.flagged.store(true, Ordering::Relaxed);
    }

    /// [`Stage::detect`] for the staged components of a marble that carries a spin, handed
    /// over one by one (always inlined: passing the whole item costs a copy of it per
    /// marble), its contacts built in `list` and stored.
    #[inline(always)]
    fn detect_staged(
        &self,
        touches: &mut TouchList,
        list: &mut ContactList,
        m: BoardStagedItem<'_, '_>,
        spin: Option<Mut<AngularVelocity>>,
        material: Material,
    ) {
        let motion = (
            m.position.into_inner(),
            m.carry.into_inner(),
            m.velocity.into_inner(),
            spin.map(Mut::into_inner),
        );
        let (mut contacts, mut more, mut near, mut start) = (m.contacts, m.more, m.near, m.start);
        let start = start.bypass_change_detection();
        start_substep(motion.0, motion.1, motion.2, start);
        self.detect::<true>(
            touches,
            motion,
            start,
            m.acceleration,
            m.radius.0,
            material,
            list,
            near.bypass_change_detection(),
        );
        list.store(
            contacts.bypass_change_detection(),
            more.bypass_change_detection(),
        );
    }

    /// [`Stage::detect`] for every row of a table's (or a chunk's) marbles that do not
    /// spin, in order.
    #[inline(always)]
    fn detect_rows(&self, t: BoardRows<'_>) {
        let (mut touches, mut list) = (TouchList::default(), ContactList::default());
        let rows = t
            .position
            .iter_mut()
            .zip(t.carry.iter_mut())
            .zip(t.velocity.iter_mut())
            .zip(t.start.iter_mut())
            .zip(t.acceleration)
            .zip(t.radius)
            .zip(t.restitution)
            .zip(t.contacts.iter_mut())
            .zip(t.more.iter_mut())
            .zip(t.near.iter_mut());
        for (((((((((x, carry), v), start), a), r), e), contacts), more), near) in rows {
            start_substep(x, carry, v, start);
            self.detect::<false>(
                &mut touches,
                (x, carry, v, None),
                start,
                a,
                r.0,
                smooth_material(e),
                &mut list,
                near,
            );
            list.store(contacts, more);
        }
    }

    /// [`NearPieces::still_face`] for a marble that does not spin (`still`: else `None`).
    #[expect(clippy::too_many_arguments, reason = "a marble's state, handed over")]
    #[inline(always)]
    fn still_face(
        &self,
        still: bool,
        near: &NearPieces,
        start: &StepStart,
        acceleration: &Acceleration,
        r: f32,
        tol: f32,
        material: &Material,
    ) -> Option<Touch> {
        if !still {
            return None;
        }
        near.still_face(
            &self.cache.boards,
            self.cache.epoch,
            start.position,
            start.velocity,
            acceleration.0,
            self.h,
            r,
            tol,
            material,
        )
    }

    /// One marble's detection (see [`detect_board_contacts`]): its motion state (with its
    /// spin when it carries one: `SPIN`), `material` its side of its contacts. A copy for
    /// the marbles that do not spin (`SPIN` false) leaves every spin branch out, whether or
    /// not the compiler inlines it into their loop (called, the copy with those branches
    /// cost the walled board a tenth more instructions).
    #[expect(
        clippy::too_many_arguments,
        reason = "a marble's components, handed over one by one"
    )]
    #[inline]
    fn detect<const SPIN: bool>(
        &self,
        touches: &mut TouchList,
        (position, carry, velocity, spin): MarbleState<'_>,
        start: &StepStart,
        acceleration: &Acceleration,
        r: f32,
        material: Material,
        contacts: &mut ContactList,
        near: &mut NearPieces,
    ) {
        let (config, cache, params) = (self.config, self.cache, &self.params);
        let boards = cache.boards.as_slice();
        let h = self.h;
        contacts.clear();
        if boards.is_empty() {
            move_freely(self.free, start, acceleration, (position, carry, velocity));
            return;
        }
        let tol = touch_tolerance(config.contact_tolerance, r, start.position);
        // The spin, when the marble spins (rolling on and an angular velocity).
        let w0 = if SPIN {
            spin.as_ref().filter(|_| config.rolling).map(|w| w.0)
        } else {
            None
        };
        // The commonest case of all, a marble that does not spin resting or sliding on a
        // still flat face with nothing else near, when its list vouches for that as it
        // stands (after a rebuild, `lone_touch` finds it).
        let face = self.still_face(w0.is_none(), near, start, acceleration, r, tol, &material);
        // The board pieces near the marble should cover where it can go this substep
        // (each query checks that they do, and searches the boards where not; a list that
        // vouches for a still face covers it).
        if face.is_none()
            && !near.is_fresh(cache, start.position, r, start.velocity.length() * h, tol)
        {
            let motion = (start.velocity.length() + acceleration.0.length() * h) * h;
            if motion < 4.0 * r {
                let skin = (NEAR_SKIN * motion).clamp(2.0 * r, 8.0 * r);
                near.rebuild(cache, start.position, r, tol, skin);
            } else {
                // Too fast for a list to last: search the boards.
                *near = NearPieces::default();
            }
        }
        if let Some(tc) = face {
            let marble = MarbleIn {
                x0: start.position,
                v0: start.velocity,
                w0: None,
                a: acceleration.0,
                r,
                material,
            };
            if let Some(out) = resolve_resting_still(boards, params, &marble, &tc, contacts) {
                (position.0, carry.0) =
                    compensated_add(config.compensated, start.position, start.carry, out.d);
                velocity.0 = out.v;
                return;
            }
            // It leaves the face (`lone_touch` would find the same touch, and the closed
            // form the same answer): to the search.
            contacts.clear();
        }
        // The commonest case, a marble resting, sliding or rolling on one piece with
        // nothing else near, is resolved here (the response stage skips it): in closed
        // form, or, for a marble that spins or a board that moves, by the event loop on
        // that one touch.
        // (With or without continuous collision: nothing else is within reach.)
        else if let Some(tc) = near.lone_touch(
            boards,
            start.position,
            start.velocity,
            acceleration.0,
            h,
            r,
            tol,
            &material,
            w0.is_some(),
        ) && tc.convex
        {
            let marble = MarbleIn {
                x0: start.position,
                v0: start.velocity,
                w0,
                a: acceleration.0,
                r,
                material,
            };
            let moving = boards[tc.piece.board()].is_moving();
            // The closed form where it applies: on a still board, and for a marble that
            // does not spin riding a moving one.
            let closed = if moving {
                if w0.is_none() {
                    touches.clear();
                    touches.insert(tc, tol);
                    resolve_riding(boards, near, params, &marble, touches, contacts)
                } else {
                    None
                }
            } else if w0.is_some() {
                resolve_rolling(boards, params, &marble, &tc, contacts)
            } else {
                resolve_resting(boards, params, &marble, &tc, contacts)
            };
            let out = match closed {
                Some(out) => Some(out),
                // Where the list does not cover a moving board's path, and for a spinning
                // marble's friction events: the event loop on that one touch.
                None if moving || w0.is_some() => {
                    touches.clear();
                    touches.insert(tc, tol);
                    Some(resolve(
                        boards,
                        Some(&*near),
                        params,
                        &marble,
                        Found::Touching,
                        touches,
                        contacts,
                    ))
                }
                None => None,
            };
            if let Some(out) = out {
                (position.0, carry.0) =
                    compensated_add(config.compensated, start.position, start.carry, out.d);
                velocity.0 = out.v;
                if SPIN && let Some(spin) = spin.filter(|_| config.rolling) {
                    spin.0 = out.w;
                }
                return;
            }
            contacts.clear();
        }
        let near_list = &*near;
        let near = Some(near_list);
        // With one board, the clearance the list shows when it shows the marble clear of
        // the board.
        let clear = match boards {
            [board] => gather_single(
                board,
                near_list,
                0.0,
                start.position,
                r,
                tol,
                &material,
                -start.velocity,
                touches,
            ),
            _ => {
                gather(
                    boards,
                    near,
                    0.0,
                    start.position,
                    r,
                    tol,
                    &material,
                    -start.velocity,
                    touches,
                );
                None
            }
        };
        // A marble that does not spin on the scene's only board, moving or still (on its
        // floor, against a wall too, in a corner): in closed form where its list answers
        // the substep's searches, else as below, the touches gathered again.
        if let Some(list) = near
            && w0.is_none()
            && !touches.is_empty()
            && boards.len() == 1
            && touches.as_slice().iter().all(|tc| tc.convex)
        {
            let marble = MarbleIn {
                x0: start.position,
                v0: start.velocity,
                w0: None,
                a: acceleration.0,
                r,
                material,
            };
            if let Some(out) = resolve_riding(boards, list, params, &marble, touches, contacts) {
                (position.0, carry.0) =
                    compensated_add(config.compensated, start.position, start.carry, out.d);
                velocity.0 = out.v;
                return;
            }
            contacts.clear();
            gather(
                boards,
                near,
                0.0,
                start.position,
                r,
                tol,
                &material,
                -start.velocity,
                touches,
            );
        }
        if !touches.is_empty() {
            for tc in touches.as_slice() {
                let u = (start.velocity - tc.board_velocity).dot(tc.normal);
                contacts.push(Contact {
                    board: boards[tc.piece.board()].entity,
                    point: tc.point,
                    normal: tc.normal,
                    depth: -tc.gap,
                    closing_speed: u,
                    kind: if u < -config.restitution_threshold {
                        ContactKind::Collision
                    } else {
                        ContactKind::Contact
                    },
                    time: 0.0,
                    piece: tc.piece,
                });
            }
            self.flag(
                contacts,
                Pending::Touching {
                    complete: touches.is_complete(),
                },
            );
        } else if config.ccd {
            let path = Path {
                t0: 0.0,
                x: start.position,
                v: start.velocity + config.integrator.velocity_offset(acceleration.0, h),
                a: acceleration.0,
            };
            // A marble in the air over the scene's only board, clear of it for the whole
            // substep by its list's word: the search would skip the board on this same
            // test.
            if let (Some(clear), [board]) = (clear, boards)
                && path_is_clear(board, near_list, &path, h, r, tol, clear)
            {
                move_freely(self.free, start, acceleration, (position, carry, velocity));
                return;
            }
            match earliest_impact(boards, near, &path, h, r, tol, touches) {
                Some((tau, _)) => self.flag(contacts, Pending::Impact(tau)),
                None => move_freely(self.free, start, acceleration, (position, carry, velocity)),
            }
        } else {
            move_freely(self.free, start, acceleration, (position, carry, velocity));
            let tol_end = touch_tolerance(config.contact_tolerance, r, position.0);
            gather(
                boards,
                near,
                h,
                position.0,
                r,
                tol_end,
                &material,
                -start.velocity,
                touches,
            );
            if touches.as_slice().iter().any(|t| t.gap < 0.0) {
                self.flag(contacts, Pending::Overlap);
            }
        }
    }
}
