//! Bad values never reach the physics, whichever door they come in by.
//!
//! A marble with a non-finite or out-of-range [`Position`] or [`Velocity`], a non-finite
//! [`Force`] or spin, a [`Radius`] or [`Mass`] that is not finite and > 0, a
//! [`Restitution`] outside [0, 1], or a negative or non-finite [`Friction`], rolling
//! resistance or spin damping, a marble from which the program removed a component the
//! stages read (one that [`Marble`](crate::components::Marble) requires, reported as
//! `missing`), and a board with a non-finite or out-of-range pose or velocity, gets [`Quarantined`](crate::components::Quarantined) at the start of the next step (stage `Validate`): it is
//! left where it is and out of every stage, and a [`QuarantineReport`] message and a log
//! warning name the entity, the component and the value. The rest of the world steps as if
//! it were not there. Scene files are refused with the same rules before anything runs
//! ([`crate::Scene::validate`]), and the newtypes' constructors (`Radius::new` and the
//! like) tell a program at once.
//!
//! **Supported range.** Positions within [`MAX_COORDINATE`] of the origin, speeds up to
//! [`MAX_SPEED`], board spins up to [`MAX_BOARD_SPIN`] and gravity up to [`MAX_GRAVITY`]:
//! f32 resolves 6 cm at 10⁶ m,
//! where a marble is no longer a marble, a finite but astronomical coordinate would make a
//! step's searches span more cells than memory holds, and a board turning thousands of
//! turns in a step makes continuous collision against it crawl. Everything inside the range
//! steps in bounded time.

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};

use crate::components::{
    AngularVelocity, Force, Friction, Mass, Position, Radius, Restitution, RollingResistance,
    Rotation, SpinDamping, Velocity,
};

/// Largest supported coordinate of a marble or board position, m.
pub const MAX_COORDINATE: f32 = 1e6;
/// Largest supported speed of a marble or board (and spin times radius), m/s.
pub const MAX_SPEED: f32 = 1e5;
/// Largest supported angular speed of a board about each axis, rad/s (1,600 turns a
/// second). Continuous collision against a turning board advances in steps bounded by its
/// turn; at 10⁷ rad/s a single marble's step took minutes.
pub const MAX_BOARD_SPIN: f32 = 1e4;
/// Largest supported gravity of a scene file, each coordinate, m/s² (about 1,000 g). A
/// marble under 10⁷ m/s² leaves the supported speeds within a step, and that step's
/// marble–board response took minutes (a fuzzing finding).
pub const MAX_GRAVITY: f32 = 1e4;

/// Longest supported step, s (a scene's `dt`, [`StepConfig::dt`](crate::config::StepConfig)). One
/// step from any supported state under the largest supported gravity stays finite (a marble
/// at [`MAX_SPEED`] under [`MAX_GRAVITY`] goes at most 1.05e5 m and gains 1e4 m/s), so the
/// next step's validation finds and quarantines a marble that left the supported range
/// instead of an overflow; at 10²⁰ s one step under 9.81 m/s² overflows to infinity.
pub const MAX_DT: f32 = 1.0;

/// A component value the engine refuses: `{component} must be {rule}, got {value}`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{component} must be {rule}, got {value}")]
pub struct InvalidValue {
    /// The component, e.g. `Radius`.
    pub component: &'static str,
    /// What it must be.
    pub rule: &'static str,
    /// What it was.
    pub value: String,
}

/// An entity quarantined for a bad value (a message; read it with
/// `MessageReader<QuarantineReport>`, or from `Messages<QuarantineReport>` in a
/// [`Simulation`](crate::Simulation)).
#[derive(Message, Debug, Clone, PartialEq)]
pub struct QuarantineReport {
    /// The marble or board.
    pub entity: Entity,
    /// What was wrong with it.
    pub reason: InvalidValue,
}

/// A step refused because a [`StepConfig`](crate::config::StepConfig) value is bad (a message; read
/// it with `MessageReader<StepRefused>`, or from `Messages<StepRefused>` in a
/// [`Simulation`](crate::Simulation)): nothing in the world changed, and each step is
/// refused until the value is mended. A log error names the field and value when the
/// reason first appears.
#[derive(Message, Debug, Clone, PartialEq)]
pub struct StepRefused {
    /// The field (`StepConfig.dt` and the like), its rule and its value.
    pub reason: InvalidValue,
}

pub(crate) fn invalid(
    component: &'static str,
    rule: &'static str,
    value: impl std::fmt::Debug,
) -> InvalidValue {
    InvalidValue {
        component,
        rule,
        value: format!("{value:?}"),
    }
}

/// `Ok(())` when `v` is finite with every coordinate within `max`.
pub(crate) fn within(
    component: &'static str,
    v: Vec3,
    max: f32,
    rule: &'static str,
) -> Result<(), InvalidValue> {
    if v.is_finite() && v.abs().max_element() <= max {
        Ok(())
    } else {
        Err(invalid(component, rule, v))
    }
}

fn finite3(component: &'static str, v: Vec3) -> Result<(), InvalidValue> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(component, "finite", v))
    }
}

pub(crate) fn positive(component: &'static str, x: f32) -> Result<(), InvalidValue> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(invalid(component, "finite and > 0", x))
    }
}

pub(crate) fn non_negative(component: &'static str, x: f32) -> Result<(), InvalidValue> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(invalid(component, "finite and >= 0", x))
    }
}

const POSITION_RULE: &str = "finite, each coordinate within 1e6 m";
const SPEED_RULE: &str = "finite, each coordinate within 1e5 m/s";
const BOARD_SPIN_RULE: &str = "finite, each coordinate within 1e4 rad/s (a board's)";

impl Position {
    /// A position, refused unless finite and within [`MAX_COORDINATE`].
    pub fn new(p: Vec3) -> Result<Self, InvalidValue> {
        within("Position", p, MAX_COORDINATE, POSITION_RULE).map(|()| Position(p))
    }
}

impl Velocity {
    /// A velocity, refused unless finite and within [`MAX_SPEED`].
    pub fn new(v: Vec3) -> Result<Self, InvalidValue> {
        within("Velocity", v, MAX_SPEED, SPEED_RULE).map(|()| Velocity(v))
    }
}

impl Force {
    /// A force, refused unless finite.
    pub fn new(f: Vec3) -> Result<Self, InvalidValue> {
        finite3("Force", f).map(|()| Force(f))
    }
}

impl AngularVelocity {
    /// An angular velocity, refused unless finite.
    pub fn new(w: Vec3) -> Result<Self, InvalidValue> {
        finite3("AngularVelocity", w).map(|()| AngularVelocity(w))
    }
}

impl Rotation {
    /// An orientation, normalized; refused unless finite and of non-zero length.
    pub fn new(q: Quat) -> Result<Self, InvalidValue> {
        if q.is_finite() && q.length_squared() > 0.0 {
            Ok(Rotation(q.normalize()))
        } else {
            Err(invalid("Rotation", "finite and of non-zero length", q))
        }
    }
}

impl Radius {
    /// A radius, m, refused unless finite and > 0.
    pub fn new(r: f32) -> Result<Self, InvalidValue> {
        positive("Radius", r).map(|()| Radius(r))
    }
}

impl Mass {
    /// A mass, kg, refused unless finite and > 0 with a finite inverse.
    pub fn try_new(m: f32) -> Result<Self, InvalidValue> {
        positive("Mass", m)?;
        if (1.0 / m).is_finite() {
            Ok(Mass::new(m))
        } else {
            Err(invalid("Mass", "finite and > 0 with a finite inverse", m))
        }
    }
}

impl Restitution {
    /// A coefficient of restitution, refused unless in [0, 1].
    pub fn new(e: f32) -> Result<Self, InvalidValue> {
        if (0.0..=1.0).contains(&e) {
            Ok(Restitution(e))
        } else {
            Err(invalid("Restitution", "in [0, 1]", e))
        }
    }
}

impl Friction {
    /// A Coulomb coefficient, refused unless finite and ≥ 0.
    pub fn new(mu: f32) -> Result<Self, InvalidValue> {
        non_negative("Friction", mu).map(|()| Friction(mu))
    }
}

impl RollingResistance {
    /// A rolling resistance coefficient, refused unless finite and ≥ 0.
    pub fn new(c: f32) -> Result<Self, InvalidValue> {
        non_negative("RollingResistance", c).map(|()| RollingResistance(c))
    }
}

impl SpinDamping {
    /// A spin damping coefficient, refused unless finite and ≥ 0.
    pub fn new(k: f32) -> Result<Self, InvalidValue> {
        non_negative("SpinDamping", k).map(|()| SpinDamping(k))
    }
}

/// A marble's components as the validation reads them.
pub(crate) struct MarbleValues<'a> {
    pub(crate) position: &'a Position,
    pub(crate) velocity: &'a Velocity,
    pub(crate) force: &'a Force,
    pub(crate) radius: &'a Radius,
    pub(crate) mass: &'a Mass,
    pub(crate) restitution: &'a Restitution,
    pub(crate) friction: &'a Friction,
    pub(crate) spin: Option<&'a AngularVelocity>,
    pub(crate) rolling_resistance: Option<&'a RollingResistance>,
    pub(crate) spin_damping: Option<&'a SpinDamping>,
}

impl<'a> MarbleValues<'a> {
    /// The values as the validation's queries hand them over.
    pub(crate) fn new(
        (position, velocity, force, radius, mass): (
            &'a Position,
            &'a Velocity,
            &'a Force,
            &'a Radius,
            &'a Mass,
        ),
        (restitution, friction): (&'a Restitution, &'a Friction),
        (spin, rolling_resistance, spin_damping): (
            Option<&'a AngularVelocity>,
            Option<&'a RollingResistance>,
            Option<&'a SpinDamping>,
        ),
    ) -> Self {
        MarbleValues {
            position,
            velocity,
            force,
            radius,
            mass,
            restitution,
            friction,
            spin,
            rolling_resistance,
            spin_damping,
        }
    }

    /// The first bad value, if any.
    #[inline]
    pub(crate) fn check(&self) -> Result<(), InvalidValue> {
        // The common case in one test: every value in range.
        let v = self.velocity.0;
        let ok = self
            .position
            .0
            .abs()
            .cmple(Vec3::splat(MAX_COORDINATE))
            .all()
            && v.abs().cmple(Vec3::splat(MAX_SPEED)).all()
            && self.force.0.is_finite()
            && self.radius.0.is_finite()
            && self.radius.0 > 0.0
            && (0.0..=1.0).contains(&self.restitution.0)
            && self.friction.0.is_finite()
            && self.friction.0 >= 0.0
            && self.spin.is_none_or(|w| w.0.is_finite())
            && self
                .rolling_resistance
                .is_none_or(|c| c.0.is_finite() && c.0 >= 0.0)
            && self
                .spin_damping
                .is_none_or(|k| k.0.is_finite() && k.0 >= 0.0);
        if ok && self.mass.get() > 0.0 && self.mass.inverse().is_finite() {
            return Ok(());
        }
        Position::new(self.position.0)?;
        Velocity::new(v)?;
        Force::new(self.force.0)?;
        Radius::new(self.radius.0)?;
        Mass::try_new(self.mass.get())?;
        Restitution::new(self.restitution.0)?;
        Friction::new(self.friction.0)?;
        if let Some(w) = self.spin {
            AngularVelocity::new(w.0)?;
        }
        if let Some(c) = self.rolling_resistance {
            RollingResistance::new(c.0)?;
        }
        if let Some(k) = self.spin_damping {
            SpinDamping::new(k.0)?;
        }
        Ok(())
    }
}

/// A board's [`NextPose`](crate::components::NextPose), for a board at `position` and
/// `rotation` and a step of `dt`: within the range of a position, a rotation finite and of
/// non-zero length, and reached within the step at a velocity and spin a board may have
/// (those `drive_boards` gives it: [`NextPose::motion`](crate::components::NextPose::motion));
/// the first bad value, if any, as `NextPose`'s.
pub(crate) fn check_next_pose(
    next: &crate::components::NextPose,
    (position, rotation): (Vec3, Quat),
    dt: f32,
) -> Result<(), InvalidValue> {
    const COMPONENT: &str = "NextPose";
    within(COMPONENT, next.position, MAX_COORDINATE, POSITION_RULE)?;
    if !(next.rotation.is_finite() && next.rotation.length_squared() > 0.0) {
        return Err(invalid(
            COMPONENT,
            "a rotation finite and of non-zero length",
            next.rotation,
        ));
    }
    let (velocity, spin) = next.motion(position, rotation, dt);
    if !velocity.is_finite() || velocity.abs().max_element() > MAX_SPEED {
        return Err(invalid(
            COMPONENT,
            "reached within one step at a velocity within 1e5 m/s",
            next.position,
        ));
    }
    if !spin.is_finite() || spin.abs().max_element() > MAX_BOARD_SPIN {
        return Err(invalid(
            COMPONENT,
            "reached within one step at a spin within 1e4 rad/s",
            next.rotation,
        ));
    }
    Ok(())
}

/// A board's pose, motion and material: the first bad value, if any (a board's spin
/// within [`MAX_BOARD_SPIN`]).
pub(crate) fn check_board(
    (position, rotation, velocity, spin): (&Position, &Rotation, &Velocity, &AngularVelocity),
    restitution: &Restitution,
    friction: &Friction,
) -> Result<(), InvalidValue> {
    Position::new(position.0)?;
    Rotation::new(rotation.0)?;
    Velocity::new(velocity.0)?;
    within("AngularVelocity", spin.0, MAX_BOARD_SPIN, BOARD_SPIN_RULE)?;
    Restitution::new(restitution.0)?;
    Friction::new(friction.0)?;
    Ok(())
}
