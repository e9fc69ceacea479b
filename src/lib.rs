#![doc = include_str!("../docs/crate.md")]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod board_contact;
pub mod components;
pub mod config;
pub mod events;
pub mod geometry;
pub mod output;
pub mod pairs;
#[cfg(feature = "bevy")]
pub mod plugin;
pub mod replay;
pub mod response;
pub mod scene;
pub mod scenes;
pub mod schedule;
pub mod simulation;
pub mod sleep;
pub mod study;
pub mod validate;

// The ECS systems live in the top-level `systems/` folder, one file per stage, so that the
// pipeline is visible at a glance from the repository root; `#[path]` includes that folder
// as this crate's `systems` module.
#[path = "../systems/mod.rs"]
pub mod systems;

/// The README's Rust examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeExamples;

#[cfg(feature = "bevy")]
pub use plugin::MarblePhysicsPlugin;
pub use scene::{Scene, SceneError};
pub use simulation::Simulation;

/// Everything a user of the engine needs.
pub mod prelude {
    pub use crate::components::{
        AngularVelocity, Board, BoardContacts, CarriedBy, Collider, Contact, ContactKind,
        ContactList, Contacts, Force, Friction, Marble, Mass, NextPose, Position, Quarantined,
        Radius, Restitution, Rotation, Sensor, Velocity,
    };
    pub use crate::config::{GravityTilt, Integrator, Preset, Sleep, StepConfig};
    pub use crate::events::{
        ContactEnded, ContactStarted, MarbleImpact, SensorEntered, SensorExited,
    };
    pub use crate::geometry::{BoardGeometry, PartShape};
    pub use crate::pairs::{MarbleContact, MarbleContacts};
    #[cfg(feature = "bevy")]
    pub use crate::plugin::{
        MarbleDiagnostics, MarblePhysicsPlugin, MarblePhysicsPlugins, PhysicsClock,
        TransformInterpolation,
    };
    pub use crate::scene::{BoardDesc, MarbleDesc, Scene, SceneError, ShapeDesc};
    pub use crate::schedule::{MarbleSubstep, MarbleSystems};
    pub use crate::simulation::Simulation;
    pub use crate::sleep::{Drowsy, Sleeping};
    pub use crate::validate::{InvalidValue, QuarantineReport, StepRefused};
}
