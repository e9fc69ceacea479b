//! The ordered ECS systems of the physics step, one file per stage.
//!
//! The order lives in one place, [`crate::schedule::MarbleSystems`]; each stage here is a
//! set of plain `pub fn` systems that can be run on a raw `World` with a `Schedule`.
//!
//! | stage | file | does |
//! | --- | --- | --- |
//! | `PrepareBoards` | `boards.rs`, `src/sleep.rs` | snapshots every board's pose and motion for the substep; on the first substep, with sleeping on, wakes the sleeping marbles something reaches |
//! | `AccumulateForces` | `forces.rs` | acceleration = gravity + force / mass |
//! | `MarbleContacts` | `collide.rs` | touching marble pairs: collisions at the start, friction, contact forces, overlap (only with `marble_collisions`) |
//! | `Integrate` | `integrate.rs` | free motion over the substep with the chosen integrator |
//! | `DetectContacts` | `detect.rs` | touches at the start (collision or contact), else the first impact (CCD) or the end overlap; marbles resting, sliding or rolling on one piece with nothing else near are resolved here (in closed form on a still board, unless a spinning marble's friction event falls inside the substep; by the event loop on that touch otherwise) |
//! | `Respond` | `respond.rs` | impacts and contacts of the marbles detection flagged |
//! | `CollideMarbles` | `collide.rs` | marble pairs that meet inside the substep collide at their time of impact (only with `marble_collisions`) |
//! | `MoveBoards` | `boards.rs` | kinematic boards advance by their velocities |
//! | `Finish` | `forces.rs`, `src/sleep.rs` | on the last substep: clear forces, quarantine non-finite marbles; with sleeping on, put to sleep the groups that have been slow long enough |

/// With the `parallel` feature, queries of fewer marbles than this run in order: handing
/// a few marbles to the task pool costs more than their work (a study of thousands of
/// one-marble scenes ran ten times slower).
#[cfg(feature = "parallel")]
pub(crate) const PARALLEL_MIN: usize = 1024;

/// Runs `each(&mut touches, item)` for every item of the marble query `query`, with a
/// scratch [`TouchList`](crate::narrow::TouchList): on bevy's compute task pool with the
/// `parallel` feature (one scratch list per batch) when there are at least
/// [`PARALLEL_MIN`] marbles, in order otherwise. Each marble's work depends on that marble
/// alone, so both give the same bits.
macro_rules! for_each_marble {
    ($query:expr, $each:expr) => {{
        #[cfg(feature = "parallel")]
        let parallel = $query.iter().len() >= crate::systems::PARALLEL_MIN;
        #[cfg(not(feature = "parallel"))]
        let parallel = false;
        if parallel {
            #[cfg(feature = "parallel")]
            $query
                .par_iter_mut()
                .for_each_init(crate::narrow::TouchList::default, $each);
        } else {
            let mut touches = crate::narrow::TouchList::default();
            for item in &mut $query {
                ($each)(&mut touches, item);
            }
        }
    }};
}
pub(crate) use for_each_marble;

pub mod boards;
pub mod collide;
pub mod detect;
pub mod forces;
pub mod integrate;
pub mod respond;
