//! Collision-versus-contact detection (the seed's 衝突 / 接触).

use bevy_ecs::prelude::*;

use crate::components::{
    Acceleration, Contact, ContactKind, Contacts, Marble, Pending, Position, Quarantined, Radius,
    Restitution, StepStart,
};
use crate::config::StepConfig;
use crate::narrow::{
    BoardCache, Material, Path, TouchList, earliest_impact, gather, touch_tolerance,
};

/// For every marble: the board pieces it touches at the substep's start, each classified
/// by its normal closing speed *before this step's forces* (a collision above
/// `restitution_threshold`, else a contact); if it touches nothing, the first impact along
/// its free path (`ccd`) or its overlap at the end of the path (no `ccd`). Marbles with
/// anything to resolve are flagged for the response stage.
pub fn detect_contacts(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut marbles: Query<
        (
            &Position,
            &StepStart,
            &Acceleration,
            &Radius,
            &Restitution,
            &mut Contacts,
        ),
        (With<Marble>, Without<Quarantined>),
    >,
) {
    let boards = cache.boards.as_slice();
    let h = cache.h;
    let each = |touches: &mut TouchList,
                (position, start, acceleration, radius, restitution, mut contacts): (
        &Position,
        &StepStart,
        &Acceleration,
        &Radius,
        &Restitution,
        Mut<Contacts>,
    )| {
        let contacts = contacts.bypass_change_detection();
        contacts.clear();
        if boards.is_empty() {
            return;
        }
        let r = radius.0;
        let tol = touch_tolerance(config.contact_tolerance, r, start.position);
        gather(
            boards,
            0.0,
            start.position,
            r,
            tol,
            &Material {
                restitution: restitution.0,
                ..Material::default()
            },
            -start.velocity,
            touches,
        );
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
            contacts.pending = Pending::Touching {
                complete: touches.is_complete(),
            };
        } else if config.ccd {
            let path = Path {
                t0: 0.0,
                x: start.position,
                v: start.velocity + config.integrator.velocity_offset(acceleration.0, h),
                a: acceleration.0,
            };
            if let Some((tau, _)) = earliest_impact(boards, &path, h, r, tol, touches) {
                contacts.pending = Pending::Impact(tau);
            }
        } else {
            let tol_end = touch_tolerance(config.contact_tolerance, r, position.0);
            gather(
                boards,
                h,
                position.0,
                r,
                tol_end,
                &Material {
                    restitution: restitution.0,
                    ..Material::default()
                },
                -start.velocity,
                touches,
            );
            if touches.as_slice().iter().any(|t| t.gap < 0.0) {
                contacts.pending = Pending::Overlap;
            }
        }
    };
    super::for_each_marble!(marbles, each);
}
