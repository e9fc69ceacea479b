//! The ordered ECS systems of the physics step, one file per stage.
//!
//! The order lives in one place, [`crate::schedule::MarbleSystems`]; each stage here is a
//! set of plain `pub fn` systems that can be run on a raw `World` with a `Schedule`.
//!
//! | stage | file | does |
//! | --- | --- | --- |
//! | `PrepareBoards` | `boards.rs` | snapshots every board's pose and motion for the substep |
//! | `AccumulateForces` | `forces.rs` | acceleration = gravity + force / mass |
//! | `MarbleContacts` | `collide.rs` | touching marble pairs: collisions at the start, friction, contact forces, overlap (only with `marble_collisions`) |
//! | `Integrate` | `integrate.rs` | free motion over the substep with the chosen integrator |
//! | `DetectContacts` | `detect.rs` | touches at the start (collision or contact), else the first impact (CCD) or the end overlap |
//! | `Respond` | `respond.rs` | impacts and contacts of the marbles detection flagged |
//! | `CollideMarbles` | `collide.rs` | marble pairs that meet inside the substep collide at their time of impact (only with `marble_collisions`) |
//! | `MoveBoards` | `boards.rs` | kinematic boards advance by their velocities |
//! | `Finish` | `forces.rs` | on the last substep: clear forces, quarantine non-finite marbles |

pub mod boards;
pub mod collide;
pub mod detect;
pub mod forces;
pub mod integrate;
pub mod respond;
