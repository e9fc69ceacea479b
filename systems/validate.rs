//! Bad values quarantined before the step uses them ([`crate::validate`]).

use std::sync::atomic::{AtomicBool, Ordering};

use bevy_ecs::prelude::*;
use glam::Vec3;

use crate::board_contact::NearPieces;
use crate::components::{
    Acceleration, AngularVelocity, Board, Contacts, Force, Friction, Marble, Mass, MoreContacts,
    NextPose, Position, PositionCarry, Quarantined, Radius, Restitution, RollingResistance,
    Rotation, SpinDamping, StepStart, Velocity,
};
use crate::config::StepConfig;
use crate::sleep::Sleeping;
use crate::validate::{
    InvalidValue, MAX_COORDINATE, MAX_SPEED, MarbleValues, QuarantineReport, check_board,
    check_next_pose,
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
    (mut commands, config): (Commands, Res<StepConfig>),
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
                Changed<RollingResistance>,
                Changed<SpinDamping>,
            )>,
        ),
    >,
    boards: Query<
        (
            Entity,
            (&Position, &Rotation, &Velocity, &AngularVelocity),
            &Restitution,
            &Friction,
            Option<&NextPose>,
        ),
        (With<Board>, Without<Quarantined>),
    >,
    incomplete: Query<(Entity, Present), (With<Marble>, Without<Quarantined>, Lacks)>,
) {
    // A marble without a component the stages read (removed by the program: `Marble`
    // requires them all) would be stepped by none of them, or, asleep, never woken; it is
    // quarantined like a bad value. Matched by archetype: a world with none costs nothing here.
    for (marble, present) in &incomplete {
        let component = missing_component(present).unwrap_or("Marble");
        let reason = InvalidValue {
            component,
            rule: "present on every marble",
            value: "missing".to_string(),
        };
        quarantine(&mut commands, &mut reports, marble, reason);
    }
    // The common case in one pass of integer comparisons on the values' bits over each
    // table's columns (which the compiler vectorizes); only a table holding a marble that
    // fails is looked at again, for that marble's first bad value.
    // With `parallel`, that pass in chunks on the task pool.
    let parallel = super::on_pool(awake.iter().len());
    let tables = awake
        .contiguous_iter()
        .expect("a marble's components are stored in tables");
    for (entities, (position, velocity, force), (radius, mass, restitution, friction)) in tables {
        let ok = |i: usize| {
            marble_ok(
                (&position[i], &velocity[i], &force[i]),
                (&radius[i], &mass[i], &restitution[i], &friction[i]),
            )
        };
        let bad = AtomicBool::new(false);
        let rows = (
            position,
            velocity,
            force,
            radius,
            mass,
            restitution,
            friction,
        );
        super::run_rows(
            rows,
            parallel,
            |(position, velocity, force, radius, mass, e, mu)| {
                let all = position
                    .iter()
                    .zip(velocity)
                    .zip(force)
                    .zip(radius)
                    .zip(mass)
                    .zip(e)
                    .zip(mu)
                    .fold(true, |all, ((((((x, v), f), r), m), e), mu)| {
                        all & marble_ok((x, v, f), (r, m, e, mu))
                    });
                if !all {
                    bad.store(true, Ordering::Relaxed);
                }
            },
        );
        if !bad.into_inner() {
            continue;
        }
        for (i, &entity) in entities.iter().enumerate() {
            if ok(i) {
                continue;
            }
            let values = MarbleValues::new(
                (&position[i], &velocity[i], &force[i], &radius[i], &mass[i]),
                (&restitution[i], &friction[i]),
                (None, None, None),
            );
            if let Err(reason) = values.check() {
                quarantine(&mut commands, &mut reports, entity, reason);
            }
        }
    }
    for (entity, spin, rolling_resistance, spin_damping) in &spinning {
        let ok = (largest_magnitude(spin.0) <= FINITE)
            & rolling_resistance.is_none_or(|c| c.0.to_bits() <= FINITE)
            & spin_damping.is_none_or(|k| k.0.to_bits() <= FINITE);
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
    for (entity, pose, restitution, friction, next) in &boards {
        let check = check_board(pose, restitution, friction).and_then(|()| {
            next.map_or(Ok(()), |next| {
                check_next_pose(next, (pose.0.0, pose.1.0), config.dt)
            })
        });
        if let Err(reason) = check {
            quarantine(&mut commands, &mut reports, entity, reason);
        }
    }
}

/// The marbles lacking any component a stage reads.
type Lacks = Or<(
    Without<Position>,
    Without<Velocity>,
    Without<Force>,
    Without<Radius>,
    Without<Mass>,
    Without<Restitution>,
    Without<Friction>,
    Without<Acceleration>,
    Without<PositionCarry>,
    Without<StepStart>,
    Without<Contacts>,
    Without<MoreContacts>,
    Without<NearPieces>,
)>;

/// Whether a marble has each component of [`Lacks`], in its order.
type Present = (
    (
        Has<Position>,
        Has<Velocity>,
        Has<Force>,
        Has<Radius>,
        Has<Mass>,
    ),
    (
        Has<Restitution>,
        Has<Friction>,
        Has<Acceleration>,
        Has<PositionCarry>,
    ),
    (
        Has<StepStart>,
        Has<Contacts>,
        Has<MoreContacts>,
        Has<NearPieces>,
    ),
);

/// The name of the first component of [`Lacks`] that a marble lacks (`present`: whether
/// it has each).
fn missing_component(
    ((x, v, f, r, m), (e, mu, a, carry), (start, contacts, more, near)): (
        (bool, bool, bool, bool, bool),
        (bool, bool, bool, bool),
        (bool, bool, bool, bool),
    ),
) -> Option<&'static str> {
    [
        ("Position", x),
        ("Velocity", v),
        ("Force", f),
        ("Radius", r),
        ("Mass", m),
        ("Restitution", e),
        ("Friction", mu),
        ("Acceleration", a),
        ("PositionCarry", carry),
        ("StepStart", start),
        ("Contacts", contacts),
        ("MoreContacts", more),
        ("NearPieces", near),
    ]
    .into_iter()
    .find_map(|(name, has)| (!has).then_some(name))
}

/// The bits of `f32::MAX`. A float's bits, read as an unsigned integer, order the
/// non-negative floats as their values do; a negative float (sign bit set) and NaN read
/// larger than these bits, so `x.to_bits() <= FINITE` is "finite and ≥ 0" (−0.0 excepted,
/// which fails the fast test and passes the full one).
const FINITE: u32 = 0x7f7f_ffff;

/// The bits of the largest of `|v.x|`, `|v.y|`, `|v.z|`, NaN reading larger than infinity.
#[inline]
fn largest_magnitude(v: Vec3) -> u32 {
    let bits = |x: f32| x.to_bits() & 0x7fff_ffff;
    bits(v.x).max(bits(v.y)).max(bits(v.z))
}

/// The fast test of a marble's values: `true` when every one is in range.
#[inline(always)]
fn marble_ok(
    (position, velocity, force): (&Position, &Velocity, &Force),
    (radius, mass, restitution, friction): (&Radius, &Mass, &Restitution, &Friction),
) -> bool {
    (largest_magnitude(position.0) <= MAX_COORDINATE.to_bits())
        & (largest_magnitude(velocity.0) <= MAX_SPEED.to_bits())
        & (largest_magnitude(force.0) <= FINITE)
        & positive_finite(radius.0)
        & positive_finite(mass.inverse())
        & positive_finite(mass.get())
        & (restitution.0.to_bits() <= 1.0f32.to_bits())
        & (friction.0.to_bits() <= FINITE)
}

/// `x` finite and > 0.
#[inline]
fn positive_finite(x: f32) -> bool {
    x.to_bits().wrapping_sub(1) < FINITE
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edge values of an f32 field.
    const EDGES: [f32; 16] = [
        0.0,
        -0.0,
        1e-45,
        f32::MIN_POSITIVE,
        0.5,
        1.0,
        1.000_000_1,
        -1.0,
        1e5,
        100_000.01,
        1e6,
        1_000_000.1,
        f32::MAX,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];

    /// The fast test never passes a marble the full check refuses, and refuses only what
    /// the full check refuses or −0.0 (which the full check then passes): each field of a
    /// marble at every edge value, the others ordinary.
    #[test]
    fn the_fast_test_agrees_with_the_full_check() {
        let (x, v, f) = (
            Vec3::new(0.1, 0.2, 0.3),
            Vec3::new(1.0, -2.0, 0.5),
            Vec3::ZERO,
        );
        let (r, m, e, mu) = (
            Radius(0.008),
            Mass::default(),
            Restitution(0.5),
            Friction(0.5),
        );
        let mut cases = 0;
        for field in 0..12 {
            for &a in &EDGES {
                let set = |w: Vec3, k: usize| {
                    let mut w = w.to_array();
                    w[k] = a;
                    Vec3::from_array(w)
                };
                let (mut x, mut v, mut f) = (x, v, f);
                let (mut r, mut e, mut mu) = (r, e, mu);
                match field {
                    0..3 => x = set(x, field),
                    3..6 => v = set(v, field - 3),
                    6..9 => f = set(f, field - 6),
                    9 => r = Radius(a),
                    10 => e = Restitution(a),
                    _ => mu = Friction(a),
                }
                let (x, v, f) = (Position(x), Velocity(v), Force(f));
                let fast = marble_ok((&x, &v, &f), (&r, &m, &e, &mu));
                let full =
                    MarbleValues::new((&x, &v, &f, &r, &m), (&e, &mu), (None, None, None)).check();
                assert!(
                    fast == full.is_ok() || (!fast && a.to_bits() == (-0.0f32).to_bits()),
                    "field {field} = {a:e}: fast {fast}, full {full:?}"
                );
                cases += 1;
            }
        }
        assert_eq!(cases, 12 * EDGES.len());
    }
}
