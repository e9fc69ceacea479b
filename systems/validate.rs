//! Bad values quarantined before the step uses them ([`crate::validate`]).

use bevy_ecs::prelude::*;
use glam::Vec3;

use crate::components::{
    AngularVelocity, Board, Force, Friction, Marble, Mass, Position, Quarantined, Radius,
    Restitution, RollingResistance, Rotation, SpinDamping, Velocity,
};
use crate::sleep::Sleeping;
use crate::validate::{
    InvalidValue, MAX_COORDINATE, MAX_SPEED, MarbleValues, QuarantineReport, check_board,
};

/// Quarantines `entity` for `reason`: the component, a message and a log warning.
pub(crate) fn quarantine(
    commands: &mut Commands,
    reports: &mut Messages<QuarantineReport>,
    entity: Entity,
    reason: InvalidValue,
) {
    log::warn!("bevy_marble: {entity} quarantined: {reason}");
    commands.entity(entity).insert(Quarantined);
    reports.write(QuarantineReport { entity, reason });
}

/// First substep of each step (stage `Validate`): every awake marble and every board is
/// checked, and a sleeping marble whose components the program changed; one with a bad
/// value is quarantined before anything moves ([`crate::validate`]). A marble whose
/// position or speed left the supported range during the last step (an overflow) is
/// caught here too, where that step left it.
#[expect(clippy::type_complexity, reason = "a marble's components, read once")]
pub fn validate(
    mut commands: Commands,
    mut reports: ResMut<Messages<QuarantineReport>>,
    awake: Query<
        (
            Entity,
            (&Position, &Velocity, &Force),
            (&Radius, &Mass, &Restitution, &Friction),
        ),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
    spinning: Query<
        (
            Entity,
            &AngularVelocity,
            Option<&RollingResistance>,
            Option<&SpinDamping>,
        ),
        (With<Marble>, Without<Quarantined>, Without<Sleeping>),
    >,
    changed_asleep: Query<
        (
            Entity,
            (&Position, &Velocity, &Force, &Radius, &Mass),
            (&Restitution, &Friction),
            (
                Option<&AngularVelocity>,
                Option<&RollingResistance>,
                Option<&SpinDamping>,
            ),
        ),
        (
            With<Marble>,
            With<Sleeping>,
            Without<Quarantined>,
            Or<(
                Changed<Position>,
                Changed<Velocity>,
                Changed<Force>,
                Changed<Radius>,
                Changed<Mass>,
                Changed<Restitution>,
                Changed<Friction>,
                Changed<AngularVelocity>,
            )>,
        ),
    >,
    boards: Query<
        (
            Entity,
            (&Position, &Rotation, &Velocity, &AngularVelocity),
            &Restitution,
            &Friction,
        ),
        (With<Board>, Without<Quarantined>),
    >,
) {
    // The common case in one pass of comparisons, without branches per value; a marble
    // that fails is looked at again for the first bad value.
    for (entity, (position, velocity, force), (radius, mass, restitution, friction)) in &awake {
        // (Comparisons with NaN are false, so NaN fails each.)
        let ok = position.0.abs().cmple(Vec3::splat(MAX_COORDINATE)).all()
            & velocity.0.abs().cmple(Vec3::splat(MAX_SPEED)).all()
            & force.0.is_finite()
            & (radius.0 > 0.0)
            & (radius.0 <= f32::MAX)
            & (mass.inverse() > 0.0)
            & (mass.inverse() <= f32::MAX)
            & (mass.get() <= f32::MAX)
            & (restitution.0 >= 0.0)
            & (restitution.0 <= 1.0)
            & (friction.0 >= 0.0)
            & (friction.0 <= f32::MAX);
        if ok {
            continue;
        }
        let values = MarbleValues::new(
            (position, velocity, force, radius, mass),
            (restitution, friction),
            (None, None, None),
        );
        if let Err(reason) = values.check() {
            quarantine(&mut commands, &mut reports, entity, reason);
        }
    }
    for (entity, spin, rolling_resistance, spin_damping) in &spinning {
        let in_range = |c: f32| (0.0..=f32::MAX).contains(&c);
        let ok = spin.0.is_finite()
            & rolling_resistance.is_none_or(|c| in_range(c.0))
            & spin_damping.is_none_or(|k| in_range(k.0));
        if ok {
            continue;
        }
        let check = AngularVelocity::new(spin.0)
            .and(rolling_resistance.map_or(Ok(()), |c| RollingResistance::new(c.0).map(|_| ())))
            .and(spin_damping.map_or(Ok(()), |k| SpinDamping::new(k.0).map(|_| ())));
        if let Err(reason) = check {
            quarantine(&mut commands, &mut reports, entity, reason);
        }
    }
    for (entity, values, material, extra) in &changed_asleep {
        if let Err(reason) = MarbleValues::new(values, material, extra).check() {
            quarantine(&mut commands, &mut reports, entity, reason);
        }
    }
    for (entity, pose, restitution, friction) in &boards {
        if let Err(reason) = check_board(pose, restitution, friction) {
            quarantine(&mut commands, &mut reports, entity, reason);
        }
    }
}
