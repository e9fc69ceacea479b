//! The one resource holding every tunable of the step, and the integrators.

use bevy_ecs::prelude::*;
#[cfg(feature = "bevy")]
use bevy_ecs::reflect::ReflectResource;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// Time integration of a marble's free motion over one substep.
///
/// Forces are accumulated once per step and held constant over it, so within a substep a
/// marble's acceleration `a` is constant, and every integrator's update has the form
/// `x' = x + v h + c·a h²`, `v' = v + a h`:
///
/// | integrator | order | `c` | reported velocity vs. the path's | energy over long runs | cost |
/// | --- | --- | --- | --- | --- | --- |
/// | `ExplicitEuler` | 1 | 0 | ½ a h ahead | grows for oscillators | 1 evaluation |
/// | `SemiImplicitEuler` | 1 | 1 | ½ a h behind | bounded | 1 |
/// | `VelocityVerlet` | 2 | ½ | exact | bounded | 1 |
/// | `Rk4` | 4 | ½ | exact | tiny drift for oscillators | 4 |
///
/// Each is therefore the exact parabola `x + u τ + ½ a τ²` of a *path velocity*
/// `u = v + δ` with `δ = (c − ½) a h` ([`Integrator::velocity_offset`]): semi-implicit
/// Euler is the leapfrog scheme whose stored velocity is the path's half a step earlier,
/// explicit Euler the same half a step later. Impacts and contacts inside a substep are
/// resolved on that path (continuous collision finds impacts on it, equation (1) is applied
/// to its velocity), so the response is exact for every integrator; what remains of the
/// integrator's error is the `δ` offset of its velocities and of its free flight
/// (`½ a h t` in position for the Euler schemes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect))]
pub enum Integrator {
    /// Symplectic Euler: velocity first, then position with the new velocity. The default:
    /// cheap and stable; off by `½ g dt t` in free fall.
    #[default]
    SemiImplicitEuler,
    /// Velocity Verlet: exact for the constant forces of this engine, same cost.
    VelocityVerlet,
    /// Classic fourth-order Runge–Kutta: four acceleration evaluations per substep.
    Rk4,
    /// Forward Euler: position with the old velocity. First order, gains energy; offered
    /// for comparison, not for use.
    ExplicitEuler,
}

impl Integrator {
    /// Every integrator, in the contract's order.
    pub const ALL: [Integrator; 4] = [
        Integrator::SemiImplicitEuler,
        Integrator::VelocityVerlet,
        Integrator::Rk4,
        Integrator::ExplicitEuler,
    ];

    /// Advances `(x, v)` by `tau` seconds under the constant acceleration `a`.
    #[inline]
    pub fn advance(self, x: Vec3, v: Vec3, a: Vec3, tau: f32) -> (Vec3, Vec3) {
        match self {
            Integrator::ExplicitEuler => (x + v * tau, v + a * tau),
            Integrator::SemiImplicitEuler => {
                let v1 = v + a * tau;
                (x + v1 * tau, v1)
            }
            Integrator::VelocityVerlet => {
                // x' = x + v τ + ½ a τ²; v' = v + ½ (a + a') τ with a' = a (forces
                // depend on neither position nor velocity within a step).
                (x + v * tau + a * (0.5 * tau * tau), v + a * tau)
            }
            Integrator::Rk4 => rk4(x, v, tau, |_, _| a),
        }
    }

    /// Displacement and velocity change over `tau` under the constant acceleration `a`
    /// (what [`Self::advance`] adds to `x` and `v`). Always inlined: it is a few
    /// multiplications on the per-marble paths of several stages.
    #[inline(always)]
    pub fn delta(self, v: Vec3, a: Vec3, tau: f32) -> (Vec3, Vec3) {
        match self {
            Integrator::ExplicitEuler => (v * tau, a * tau),
            Integrator::SemiImplicitEuler => ((v + a * tau) * tau, a * tau),
            Integrator::VelocityVerlet => (v * tau + a * (0.5 * tau * tau), a * tau),
            Integrator::Rk4 => {
                let (x, v1) = rk4(Vec3::ZERO, v, tau, |_, _| a);
                (x, v1 - v)
            }
        }
    }

    /// `δ = (c − ½) a h`: the path velocity is the reported velocity plus this (see the
    /// type's docs). Zero for Verlet and RK4.
    #[inline]
    pub fn velocity_offset(self, a: Vec3, h: f32) -> Vec3 {
        match self {
            Integrator::VelocityVerlet | Integrator::Rk4 => Vec3::ZERO,
            _ => a * self.velocity_lead(h),
        }
    }

    /// `(c − ½) h`: how far, in time, the path velocity is ahead of the reported one
    /// (`h/2` for semi-implicit Euler, `−h/2` for explicit Euler, 0 for the others).
    #[inline]
    pub fn velocity_lead(self, h: f32) -> f32 {
        match self {
            Integrator::SemiImplicitEuler => 0.5 * h,
            Integrator::ExplicitEuler => -0.5 * h,
            Integrator::VelocityVerlet | Integrator::Rk4 => 0.0,
        }
    }
}

/// Named speed-versus-accuracy settings, chosen from the Pareto front `marble tradeoff`
/// measures (README, "Speed versus accuracy").
///
/// The study found one shape of front: VelocityVerlet with continuous collision is the most
/// accurate setting at every cost (integrators cost the same, and CCD costs no more than
/// discrete detection on resting, sliding or bouncing marbles), and accuracy is then bought
/// with a shorter step. So a preset sets the integrator to Verlet, turns CCD on, and splits
/// the scene's (or app's) `dt` into as many substeps as it takes to reach its substep
/// length:
///
/// | preset | substep at most | contact tolerance | measured at dt | bounce | elastic drift, 60 s | moving board | µs per marble per simulated second |
/// | --- | --- | --- | --- | --- | --- | --- | --- |
/// | `Fast` | 1/30 s | 1e-4 × r | 1/30 | 0.505% | 0.002% | 0.000% | 8.4 |
/// | `Balanced` | 1/60 s | 1e-4 × r | 1/60 | 0.017% | 0.002% | 0.001% | 16.6 |
/// | `Precise` | 1/240 s | 1e-5 × r | 1/60 (4 substeps) | 0.017% | 0.002% | 0.000% | 65.1 |
///
/// (Bounce: worst error of five apexes of an e = 0.8 drop, read at step times, which alone
/// accounts for g·dt²/8: the coarser step's figure is mostly that reading; cost: 1,000
/// marbles on the walled board, ±20% between runs.) On these constant-force scenes the
/// engine is at f32 precision with one step of 1/30 s; what shorter substeps buy is time
/// resolution: of impacts between marbles and of board motion that a program changes
/// every step. At a 60 Hz fixed step `Fast` and `Balanced` both run one substep and
/// `Precise` four.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Preset {
    /// Verlet, CCD, substeps of at most 1/30 s.
    Fast,
    /// Verlet, CCD, substeps of at most 1/60 s.
    Balanced,
    /// Verlet, CCD, substeps of at most 1/240 s, contact tolerance 1e-5 × r.
    Precise,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 3] = [Preset::Fast, Preset::Balanced, Preset::Precise];

    /// The longest substep this preset allows, s.
    pub fn max_substep(self) -> f32 {
        match self {
            Preset::Fast => 1.0 / 30.0,
            Preset::Balanced => 1.0 / 60.0,
            Preset::Precise => 1.0 / 240.0,
        }
    }

    /// Sets this preset's choices in `config` for its `dt` (integrator, CCD, substeps,
    /// contact tolerance), leaving `dt`, gravity and thresholds.
    pub fn apply(self, config: &mut StepConfig) {
        config.integrator = Integrator::VelocityVerlet;
        config.ccd = true;
        // The relative slack keeps dt = 1/60 at one substep despite rounding.
        config.substeps = ((config.dt / self.max_substep()) * (1.0 - 1e-6))
            .ceil()
            .max(1.0) as u32;
        config.contact_tolerance = match self {
            Preset::Precise => 1e-5,
            Preset::Fast | Preset::Balanced => 1e-4,
        };
    }
}

/// Fourth-order Runge–Kutta for `x'' = f(x, x')`.
#[inline]
fn rk4(x: Vec3, v: Vec3, h: f32, f: impl Fn(Vec3, Vec3) -> Vec3) -> (Vec3, Vec3) {
    let k1x = v;
    let k1v = f(x, v);
    let k2x = v + k1v * (0.5 * h);
    let k2v = f(x + k1x * (0.5 * h), k2x);
    let k3x = v + k2v * (0.5 * h);
    let k3v = f(x + k2x * (0.5 * h), k3x);
    let k4x = v + k3v * h;
    let k4v = f(x + k3x * h, k4x);
    let s = h / 6.0;
    (
        x + (k1x + (k2x + k3x) * 2.0 + k4x) * s,
        v + (k1v + (k2v + k3v) * 2.0 + k4v) * s,
    )
}

/// Every tunable of the physics step, in one resource.
///
/// `Simulation` fills it from the scene file; `MarblePhysicsPlugin` inserts the default and
/// sets `dt` from the app's fixed timestep each step.
#[derive(Resource, Clone, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Resource))]
pub struct StepConfig {
    /// Gravity, m/s². Default `(0, −9.81, 0)`; finite, each coordinate within
    /// [`MAX_GRAVITY`](crate::validate::MAX_GRAVITY).
    pub gravity: Vec3,
    /// Seconds per step. Default 1/240 s. Sensible: 1/30 s (coarse, games at low rates)
    /// to 1e-4 s (reference runs); must be > 0 and at most
    /// [`MAX_DT`](crate::validate::MAX_DT) (1 s). The plugin overwrites it with the app's
    /// fixed timestep times the plugin's `PhysicsClock::speed`.
    pub dt: f32,
    /// Substeps per step (≥ 1). Default 1. Each step is split into this many equal
    /// substeps; 2–8 buy accuracy for fast or densely touching marbles.
    pub substeps: u32,
    /// Time integrator. Default [`Integrator::SemiImplicitEuler`].
    pub integrator: Integrator,
    /// Continuous collision: impacts are found at their time inside the substep (no
    /// tunnelling, bounces at the right height). Default `true`; `false` detects overlap
    /// at the end of the substep only: cheaper, wrong by O(dt) at impacts.
    pub ccd: bool,
    /// m/s. A touching pair closing faster than this along the normal is a collision
    /// (restitution applies), otherwise a contact (no bounce). Default 0.05 m/s, the
    /// speed a marble reaches falling 0.13 mm; sensible 0.001–0.5 m/s. Must be at least
    /// `|g|·dt/substeps`-independent: detection measures the closing speed before this
    /// step's forces, so a resting marble never counts as a collision.
    pub restitution_threshold: f32,
    /// Touching tolerance as a fraction of the marble radius. Default 1e-4 (0.8 µm for an
    /// 8 mm marble); sensible 1e-5–1e-2. A marble closer to a surface than this is in
    /// contact; continuous collision stops this far from the surface.
    pub contact_tolerance: f32,
    /// Model spin and friction at contacts (marbles roll). Default `false`: the seed's
    /// smooth surfaces, and no rolling system runs. Only marbles that carry an
    /// [`AngularVelocity`](crate::components::AngularVelocity) spin (scene files give every
    /// marble one when `rolling: true`); a [`Rotation`](crate::components::Rotation) on them
    /// is turned by it.
    pub rolling: bool,
    /// Add each substep's motion to positions with compensated (Kahan) summation, keeping
    /// the rounding error in [`PositionCarry`](crate::components::PositionCarry). Default
    /// `true`. Off, f32 rounding loses motion that is small against the coordinates: at
    /// dt = 1e-6 s or 10 km from the origin. `marble tradeoff` reports its cost and effect.
    pub compensated: bool,
    /// Most impacts resolved per marble per substep with continuous collision. Default 8;
    /// a marble still colliding after that many events (wedged between boards) finishes the
    /// substep as without continuous collision (free path, then the end-of-substep check).
    pub max_impacts: u32,
    /// Marbles collide with each other ([`crate::pairs`]). Default `false`: the
    /// marble–marble stage does not run and costs nothing.
    pub marble_collisions: bool,
    /// Passes of the marble–marble contact solver per substep (projected Gauss–Seidel,
    /// over-relaxed, warm started from the previous substep's impulses; it stops early once
    /// converged). Default 10; sensible 4–50: piles deeper than a few marbles settle faster
    /// with more (the 1,000-marble pour of bench scene (b) uses 15 at 8 substeps).
    pub solver_iterations: u32,
    /// Put marbles that have stopped to sleep ([`crate::sleep`]). Default `None`: every
    /// marble is stepped every substep, as the physics asks. With `Some`, a group of
    /// touching marbles that has all stayed slower than [`Sleep::speed`] for
    /// [`Sleep::time`] is stopped and skipped by every stage until something wakes it, so a
    /// settled pile costs next to nothing.
    pub sleep: Option<Sleep>,
    /// Record impacts and contacts that start and end as messages and observer events
    /// ([`crate::events`]). Default `false` in a [`crate::Simulation`], `true` with the
    /// Bevy plugin, whose `MarbleEventsPlugin` records them whatever this says (a
    /// `StepConfig` the game inserts later keeps them); off, no code runs for them.
    /// Sensors report whenever there are any.
    pub events: bool,
}

/// When marbles fall asleep ([`StepConfig::sleep`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect))]
pub struct Sleep {
    /// m/s, > 0: a marble is slow while its speed (and, when it spins, its spin times its
    /// radius) stays below this.
    pub speed: f32,
    /// s, > 0: how long every marble of a touching group must stay slow before the group
    /// sleeps.
    pub time: f32,
}

impl Default for StepConfig {
    fn default() -> Self {
        StepConfig {
            gravity: Vec3::new(0.0, -9.81, 0.0),
            dt: 1.0 / 240.0,
            substeps: 1,
            integrator: Integrator::default(),
            ccd: true,
            restitution_threshold: 0.05,
            contact_tolerance: 1e-4,
            rolling: false,
            compensated: true,
            max_impacts: 8,
            marble_collisions: false,
            solver_iterations: 10,
            sleep: None,
            events: false,
        }
    }
}

impl StepConfig {
    /// The default settings at step `dt` with a preset applied.
    pub fn with_preset(preset: Preset, dt: f32) -> Self {
        let mut config = StepConfig {
            dt,
            ..StepConfig::default()
        };
        preset.apply(&mut config);
        config
    }

    /// Seconds per substep.
    #[inline]
    pub fn substep_dt(&self) -> f32 {
        self.dt / self.substeps.max(1) as f32
    }

    /// Checks the values a step reads, by the rules a scene file's are checked by: the
    /// first bad one, named `StepConfig.<field>`. A step with a bad value is refused
    /// ([`crate::validate::StepRefused`]): the world is left as it was.
    pub fn validate(&self) -> Result<(), crate::validate::InvalidValue> {
        use crate::validate::{MAX_DT, MAX_GRAVITY, invalid, non_negative, positive, within};
        within(
            "StepConfig.gravity",
            self.gravity,
            MAX_GRAVITY,
            "finite, each coordinate within 1e4 m/s²",
        )?;
        if !(self.dt > 0.0 && self.dt <= MAX_DT) {
            return Err(invalid("StepConfig.dt", "> 0 and at most 1 s", self.dt));
        }
        if self.substeps < 1 {
            return Err(invalid("StepConfig.substeps", ">= 1", self.substeps));
        }
        non_negative(
            "StepConfig.restitution_threshold",
            self.restitution_threshold,
        )?;
        non_negative("StepConfig.contact_tolerance", self.contact_tolerance)?;
        if let Some(sleep) = self.sleep {
            positive("StepConfig.sleep.speed", sleep.speed)?;
            positive("StepConfig.sleep.time", sleep.time)?;
        }
        Ok(())
    }
}

/// The cheap model of a tilting board, after Neverball: the board stays where it is and
/// gravity turns the other way instead. Present as a resource only when a scene asks for it
/// (`tilt_as_gravity: true`); then the turning boards are simulated still, in their own
/// frame, and [`GravityTilt::to_world`] maps results back.
///
/// What it leaves out is everything the board's turning does besides tilting gravity: the
/// surface's own velocity `ω × r` at the contact (a turning board pushes marbles), and the
/// centrifugal, Coriolis and Euler forces of the turning frame. `marble tradeoff` measures
/// how far that drifts from the true moving board as the tilt rate grows.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub struct GravityTilt {
    /// The board's angular velocity, rad/s, world frame.
    pub angular_velocity: Vec3,
    /// The point it turns about (the board's position), m.
    pub pivot: Vec3,
    /// How far the board has turned since the start.
    pub rotation: Quat,
}

impl GravityTilt {
    /// Gravity as the still board sees it: the world's gravity turned back by the tilt.
    #[inline]
    pub fn gravity(&self, world_gravity: Vec3) -> Vec3 {
        self.rotation.conjugate() * world_gravity
    }

    /// A board-frame position and velocity in the world.
    pub fn to_world(&self, x: Vec3, v: Vec3) -> (Vec3, Vec3) {
        let xw = self.pivot + self.rotation * (x - self.pivot);
        let vw = self.rotation * v + self.angular_velocity.cross(xw - self.pivot);
        (xw, vw)
    }

    /// A board-frame spin in the world: turned with the board, plus the board's own turn.
    pub fn spin_to_world(&self, w: Vec3) -> Vec3 {
        self.rotation * w + self.angular_velocity
    }
}

/// The running substep: its length, which one of the step it is (0-based) and how many
/// the step has. [`crate::schedule::run_step`] sets it before each substep; every stage
/// reads the substep's length here.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct Substep {
    /// Length of the substep, s ([`StepConfig::substep_dt`]).
    pub h: f32,
    /// Index of the running substep.
    pub index: u32,
    /// Substeps in this step.
    pub count: u32,
}

impl Substep {
    /// True during the first substep of the step.
    pub fn is_first(&self) -> bool {
        self.index == 0
    }

    /// True during the last substep of the step.
    pub fn is_last(&self) -> bool {
        self.index + 1 >= self.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every integrator advances free flight from rest by the right amount in one
    /// step: exact `½ a τ²` for Verlet and RK4, `a τ²` for semi-implicit Euler, 0 for
    /// explicit Euler.
    #[test]
    fn one_step_from_rest() {
        let a = Vec3::new(0.0, -10.0, 0.0);
        let tau = 0.1;
        let y = |i: Integrator| i.advance(Vec3::ZERO, Vec3::ZERO, a, tau).0.y;
        assert!((y(Integrator::VelocityVerlet) - -0.05).abs() < 1e-7);
        assert!((y(Integrator::Rk4) - -0.05).abs() < 1e-7);
        assert!((y(Integrator::SemiImplicitEuler) - -0.1).abs() < 1e-7);
        assert_eq!(y(Integrator::ExplicitEuler), 0.0);
        for i in Integrator::ALL {
            assert!((i.advance(Vec3::ZERO, Vec3::ZERO, a, tau).1.y - -1.0).abs() < 1e-6);
        }
    }

    /// `Integrator::delta`, what every stage calls, over a substep τ under constant
    /// acceleration `a` from velocity `v`: each integrator's exact parabola, offset as its
    /// type's docs say (Verlet and RK4: `v τ + ½ a τ²`; semi-implicit Euler: `(v + a τ) τ`;
    /// explicit Euler: `v τ`), and the velocity change `a τ` for all; `advance` adds it.
    #[test]
    fn delta_is_each_integrators_step() {
        let (v, a, tau) = (Vec3::new(1.5, 2.0, -0.5), Vec3::new(0.3, -9.81, 0.2), 0.01);
        let want = |i: Integrator| match i {
            Integrator::VelocityVerlet | Integrator::Rk4 => v * tau + 0.5 * a * tau * tau,
            Integrator::SemiImplicitEuler => (v + a * tau) * tau,
            Integrator::ExplicitEuler => v * tau,
        };
        for i in Integrator::ALL {
            let (dx, dv) = i.delta(v, a, tau);
            assert!(
                (dx - want(i)).length() <= 1e-7,
                "{i:?}: {dx} against {}",
                want(i)
            );
            assert!((dv - a * tau).length() <= 1e-7, "{i:?}: {dv}");
            let x0 = Vec3::new(3.0, 1.0, 2.0);
            let (x, v1) = i.advance(x0, v, a, tau);
            assert!((x - (x0 + dx)).length() <= 1e-6 && (v1 - (v + dv)).length() <= 1e-7);
        }
        // The semi-implicit and explicit Euler parabolas differ from the exact one by
        // `± ½ a τ²`, the offset `velocity_offset` gives as a velocity.
        let exact = v * tau + 0.5 * a * tau * tau;
        for i in [Integrator::SemiImplicitEuler, Integrator::ExplicitEuler] {
            let off = i.velocity_offset(a, tau) * tau;
            assert!(
                (i.delta(v, a, tau).0 - (exact + off)).length() <= 1e-7,
                "{i:?}"
            );
        }
    }
}
