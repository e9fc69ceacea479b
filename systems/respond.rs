//! The response: impacts and contacts of the marbles detection flagged.

use bevy_ecs::prelude::*;

use crate::components::{
    Acceleration, AngularVelocity, Contacts, Friction, Marble, Pending, Position, PositionCarry,
    Quarantined, Radius, Restitution, RollingResistance, SpinDamping, StepStart, Velocity,
    compensated_add,
};
use crate::config::StepConfig;
use crate::narrow::{BoardCache, Material, TouchList, gather, touch_tolerance};
use crate::response::{Found, MarbleIn, SubstepParams, resolve};

/// Resolves every flagged marble through the substep's event loop
/// ([`crate::response`]): equation (1) for collisions, removal of approaching velocity for
/// contacts, continuous collision, and position correction without added energy. Marbles
/// detection did not flag keep their free motion.
pub fn respond(
    config: Res<StepConfig>,
    cache: Res<BoardCache>,
    mut marbles: Query<
        (
            (
                &mut Position,
                &mut PositionCarry,
                &mut Velocity,
                Option<&mut AngularVelocity>,
            ),
            (&StepStart, &Acceleration, &Radius, &mut Contacts),
            (
                &Restitution,
                &Friction,
                Option<&RollingResistance>,
                Option<&SpinDamping>,
            ),
        ),
        (With<Marble>, Without<Quarantined>),
    >,
) {
    let boards = cache.boards.as_slice();
    let params = SubstepParams {
        h: cache.h,
        integrator: config.integrator,
        ccd: config.ccd,
        threshold: config.restitution_threshold,
        tolerance: config.contact_tolerance,
        max_impacts: config.max_impacts,
    };
    let mut touches = TouchList::default();
    for (
        (mut position, mut carry, mut velocity, mut spin),
        (start, acceleration, radius, mut contacts),
        (restitution, friction, rolling_resistance, spin_damping),
    ) in &mut marbles
    {
        if contacts.pending == Pending::None {
            continue;
        }
        let marble = MarbleIn {
            x0: start.position,
            v0: start.velocity,
            w0: if config.rolling {
                spin.as_ref().map(|w| w.0)
            } else {
                None
            },
            a: acceleration.0,
            r: radius.0,
            material: Material {
                restitution: restitution.0,
                friction: friction.0,
                rolling_resistance: rolling_resistance.map_or(0.0, |c| c.0),
                spin_damping: spin_damping.map_or(0.0, |c| c.0),
            },
        };
        let found = match contacts.pending {
            Pending::Touching { complete } => {
                // Detection recorded these touches; gather again only if it ran out of
                // room to record them all.
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
                        0.0,
                        marble.x0,
                        marble.r,
                        tol,
                        &marble.material,
                        -marble.v0,
                        &mut touches,
                    );
                }
                Found::Touching(&touches)
            }
            Pending::Impact(tau) => Found::Impact(tau),
            Pending::Overlap | Pending::None => Found::Overlap,
        };
        let out = resolve(boards, &params, &marble, found, &mut contacts);
        (position.0, carry.0) =
            compensated_add(config.compensated, start.position, start.carry, out.d);
        velocity.0 = out.v;
        if marble.w0.is_some()
            && let Some(w) = spin.as_mut()
        {
            w.0 = out.w;
        }
    }
}
