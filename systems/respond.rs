//! The response: impacts and contacts of the marbles detection flagged.

use bevy_ecs::prelude::*;

use crate::components::{
    Acceleration, AngularVelocity, Contacts, Friction, Marble, Pending, Position, PositionCarry,
    Quarantined, Radius, Restitution, RollingResistance, SpinDamping, StepStart, Velocity,
    compensated_add,
};
use crate::config::StepConfig;
use crate::narrow::{
    BoardCache, BoardSnapshot, Material, NearPieces, TouchList, gather, touch_tolerance,
};
use crate::response::{Found, MarbleIn, MarbleOut, SubstepParams, resolve};
use crate::sleep::Sleeping;

/// Resolves every flagged marble that does not spin through the substep's event loop
/// ([`crate::response`]): equation (1) for collisions, removal of approaching velocity for
/// contacts, continuous collision, and position correction without added energy. Marbles
/// detection did not flag keep their free motion.
pub fn respond(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut marbles: Query<
        (
            (&mut Position, &mut PositionCarry, &mut Velocity),
            (
                &StepStart,
                &Acceleration,
                &Radius,
                &Restitution,
                (&mut Contacts, &NearPieces),
            ),
        ),
        (
            With<Marble>,
            Without<Quarantined>,
            Without<Sleeping>,
            Without<AngularVelocity>,
        ),
    >,
) {
    let boards = cache.boards.as_slice();
    let params = SubstepParams::from_config(&config, cache.h);
    let each = |touches: &mut TouchList,
                (
        (mut position, mut carry, mut velocity),
        (start, acceleration, radius, e, (mut contacts, near)),
    ): (
        (Mut<Position>, Mut<PositionCarry>, Mut<Velocity>),
        (
            &StepStart,
            &Acceleration,
            &Radius,
            &Restitution,
            (Mut<Contacts>, &NearPieces),
        ),
    )| {
        if contacts.pending == Pending::None {
            return;
        }
        let marble = MarbleIn {
            x0: start.position,
            v0: start.velocity,
            w0: None,
            a: acceleration.0,
            r: radius.0,
            material: Material {
                restitution: e.0,
                ..Material::default()
            },
        };
        let out = respond_one(boards, near, &params, &marble, &mut contacts, touches);
        (position.0, carry.0) =
            compensated_add(config.compensated, start.position, start.carry, out.d);
        velocity.0 = out.v;
    };
    super::for_each_marble!(marbles, each);
}

/// [`respond`] for marbles that carry an [`AngularVelocity`]: with rolling on, they spin,
/// with friction, rolling resistance and spin damping at their contacts; with it off they
/// are smooth like the others. A scene without spinning marbles gives this system nothing
/// to iterate.
pub fn respond_spinning(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut marbles: Query<
        (
            (
                &mut Position,
                &mut PositionCarry,
                &mut Velocity,
                &mut AngularVelocity,
            ),
            (&StepStart, &Acceleration, &Radius, &mut Contacts),
            (
                &NearPieces,
                &Restitution,
                &Friction,
                Option<&RollingResistance>,
                Option<&SpinDamping>,
            ),
        ),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
) {
    let boards = cache.boards.as_slice();
    let params = SubstepParams::from_config(&config, cache.h);
    let each = |touches: &mut TouchList,
                (
        (mut position, mut carry, mut velocity, mut spin),
        (start, acceleration, radius, mut contacts),
        (near, restitution, friction, rolling_resistance, spin_damping),
    ): (
        (
            Mut<Position>,
            Mut<PositionCarry>,
            Mut<Velocity>,
            Mut<AngularVelocity>,
        ),
        (&StepStart, &Acceleration, &Radius, Mut<Contacts>),
        (
            &NearPieces,
            &Restitution,
            &Friction,
            Option<&RollingResistance>,
            Option<&SpinDamping>,
        ),
    )| {
        if contacts.pending == Pending::None {
            return;
        }
        let marble = MarbleIn {
            x0: start.position,
            v0: start.velocity,
            w0: config.rolling.then_some(spin.0),
            a: acceleration.0,
            r: radius.0,
            material: Material::of_marble(restitution, friction, rolling_resistance, spin_damping),
        };
        let out = respond_one(boards, near, &params, &marble, &mut contacts, touches);
        (position.0, carry.0) =
            compensated_add(config.compensated, start.position, start.carry, out.d);
        velocity.0 = out.v;
        if config.rolling {
            spin.0 = out.w;
        }
    };
    super::for_each_marble!(marbles, each);
}

/// One flagged marble: the touches detection recorded (gathered again only if it ran out
/// of room), then the event loop.
fn respond_one(
    boards: &[BoardSnapshot],
    near: &NearPieces,
    params: &SubstepParams,
    marble: &MarbleIn,
    contacts: &mut Contacts,
    touches: &mut TouchList,
) -> MarbleOut {
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
    resolve(boards, Some(near), params, marble, found, touches, contacts)
}
