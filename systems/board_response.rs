//! Marble–board response: the event loop for the marbles detection flagged, then the
//! spinning marbles' orientations turned by their spin.

use bevy_ecs::prelude::*;

use super::board_detection::Flagged;
use super::{
    BoardRows, BoardStaged, BoardStagedItem, Smooth, SpinStaged, SpinStagedItem, Stepped,
    smooth_material,
};
use crate::board_contact::{
    BoardCache, BoardSnapshot, NearPieces, TouchList, gather, touch_tolerance,
};
use crate::components::{
    Acceleration, AngularVelocity, Board, Position, PositionCarry, Radius, Restitution, Rotation,
    StepStart, Velocity,
};
use crate::components::{ContactList, Contacts, MoreContacts, Pending, compensated_add};
use crate::config::{StepConfig, Substep};
use crate::response::{Found, MarbleIn, MarbleOut, SubstepParams, resolve};
use glam::{Quat, Vec3};

/// Resolves every flagged marble that does not spin through the substep's event loop
/// ([`crate::response`]): equation (1) for collisions, removal of approaching velocity for
/// contacts, continuous collision, and position correction without added energy. Marbles
/// detection did not flag keep their free motion.
pub fn respond_to_boards(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    flagged: Res<Flagged>,
    mut marbles: Query<BoardStaged, Smooth>,
) {
    if !flagged.take(false) {
        return;
    }
    let boards = cache.boards.as_slice();
    let params = SubstepParams::from_config(&config, substep.h);
    // One flagged marble: its motion over the substep through the event loop.
    let respond = |touches: &mut TouchList,
                   (x, carry, v): (&mut Position, &mut PositionCarry, &mut Velocity),
                   start: &StepStart,
                   marble: MarbleIn,
                   (contacts, more): (&mut Contacts, &mut MoreContacts),
                   near: &NearPieces| {
        let out = respond_one(boards, near, &params, &marble, (contacts, more), touches);
        (x.0, carry.0) = compensated_add(config.compensated, start.position, start.carry, out.d);
        v.0 = out.v;
    };
    let marble = |start: &StepStart, a: &Acceleration, r: &Radius, e: &Restitution| MarbleIn {
        x0: start.position,
        v0: start.velocity,
        w0: None,
        a: a.0,
        r: r.0,
        material: smooth_material(e),
    };
    let parallel = super::on_pool(marbles.iter().len());
    // Table by table over the columns as slices (see `detect_board_contacts`).
    let tables = marbles
        .contiguous_iter_mut()
        .expect("a marble's components are stored in tables");
    for t in tables {
        let rows = BoardRows::of_table(t, true);
        super::run_rows(rows, parallel, |t| {
            let mut touches = TouchList::default();
            let rows = t
                .position
                .iter_mut()
                .zip(t.carry.iter_mut())
                .zip(t.velocity.iter_mut())
                .zip(t.start)
                .zip(t.acceleration)
                .zip(t.radius)
                .zip(t.restitution)
                .zip(t.contacts.iter_mut())
                .zip(t.more.iter_mut())
                .zip(t.near.iter());
            for (((((((((x, carry), v), start), a), r), e), contacts), more), near) in rows {
                if !contacts.nothing_pending() {
                    let marble = marble(start, a, r, e);
                    let stored = (contacts, more);
                    respond(&mut touches, (x, carry, v), start, marble, stored, near);
                }
            }
        });
    }
}

/// [`respond_to_boards`] for marbles that carry an [`AngularVelocity`]: with rolling on,
/// they spin, with friction, rolling resistance and spin damping at their contacts; with
/// it off they are smooth like the others. A scene without spinning marbles gives this
/// system nothing to iterate.
pub fn respond_to_boards_spinning(
    config: Res<StepConfig>,
    substep: Res<Substep>,
    cache: Res<BoardCache>,
    flagged: Res<Flagged>,
    mut marbles: Query<(BoardStaged, SpinStaged), Stepped>,
) {
    if !flagged.take(true) {
        return;
    }
    let boards = cache.boards.as_slice();
    let params = SubstepParams::from_config(&config, substep.h);
    let each = |touches: &mut TouchList,
                (mut m, mut s): (BoardStagedItem<'_, '_>, SpinStagedItem<'_, '_>)| {
        if m.contacts.nothing_pending() {
            return;
        }
        let marble = MarbleIn {
            x0: m.start.position,
            v0: m.start.velocity,
            w0: config.rolling.then_some(s.spin.0),
            a: m.acceleration.0,
            r: m.radius.0,
            material: s.material(m.restitution),
        };
        let stored = (&mut *m.contacts, &mut *m.more);
        let out = respond_one(boards, &m.near, &params, &marble, stored, touches);
        (m.position.0, m.carry.0) =
            compensated_add(config.compensated, m.start.position, m.start.carry, out.d);
        m.velocity.0 = out.v;
        if config.rolling {
            s.spin.0 = out.w;
        }
    };
    super::for_each_marble!(marbles, each);
}

/// One flagged marble: the touches detection recorded (gathered again only if it ran out
/// of room), then the event loop; the contacts it records are stored back in `stored`.
fn respond_one(
    boards: &[BoardSnapshot],
    near: &NearPieces,
    params: &SubstepParams,
    marble: &MarbleIn,
    stored: (&mut Contacts, &mut MoreContacts),
    touches: &mut TouchList,
) -> MarbleOut {
    let mut list = ContactList::load(stored.0, stored.1);
    let contacts = &mut list;
    let found = match contacts.pending {
        Pending::Touching { complete } => {
            if contacts.len() < crate::components::MAX_CONTACTS {
                touches.clear();
                for c in contacts.iter() {
                    touches.push_recorded(c, boards, &marble.material);
                }
                touches.set_complete(complete);
            } else {
                let tol = touch_tolerance(params.tolerance, marble.r, marble.x0);
                gather(
                    boards,
                    Some(near),
                    0.0,
                    marble.x0,
                    marble.r,
                    tol,
                    &marble.material,
                    -marble.v0,
                    touches,
                );
            }
            Found::Touching
        }
        Pending::Impact(tau) => Found::Impact(tau),
        Pending::Overlap | Pending::None => Found::Overlap,
    };
    let out = resolve(boards, Some(near), params, marble, found, touches, contacts);
    list.store(stored.0, stored.1);
    out
}

/// Turns every spinning marble's [`Rotation`] by its angular velocity over the substep
/// (runs only when rolling is modelled).
pub fn rotate_marbles(
    substep: Res<Substep>,
    mut marbles: Query<
        (&mut Rotation, &AngularVelocity),
        (With<crate::components::Marble>, Without<Board>),
    >,
) {
    let h = substep.h;
    for (mut rotation, angular) in &mut marbles {
        if angular.0 != Vec3::ZERO {
            rotation.0 = (Quat::from_scaled_axis(angular.0 * h) * rotation.0).normalize();
        }
    }
}
