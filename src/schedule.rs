//! The physics step's schedule: the one place where the stage order is fixed.

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{LogLevel, ScheduleBuildSettings, ScheduleLabel};

use crate::config::{StepConfig, SubstepCounter};
use crate::sleep;
use crate::systems::{boards, collide, detect, forces, integrate, respond};

/// The schedule that runs one substep. A step runs it `substeps` times
/// ([`run_step`]).
#[derive(ScheduleLabel, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MarbleSubstep;

/// The stages of a substep, in order. Add your own systems to the physics with
/// `.in_set(MarbleSystems::…)` or order them `.before`/`.after` a stage.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MarbleSystems {
    /// Snapshot every board's pose and motion for the substep; on the first substep, wake
    /// the sleeping marbles something reaches ([`crate::sleep`]).
    PrepareBoards,
    /// Gravity plus user forces → acceleration.
    AccumulateForces,
    /// Marble–marble contacts: collisions of touching pairs, contact forces, overlap
    /// (only with `marble_collisions` on).
    MarbleContacts,
    /// Free motion with the chosen integrator.
    Integrate,
    /// Touches (collision or contact), first impact, or end overlap.
    DetectContacts,
    /// Equation (1), contacts, continuous collision, position correction.
    Respond,
    /// Marble–marble collisions and contacts (only with `marble_collisions` on).
    CollideMarbles,
    /// Kinematic boards advance.
    MoveBoards,
    /// Last substep only: with sleeping on, put to sleep the groups that have been slow
    /// long enough ([`crate::sleep`]); clear forces, quarantine non-finite marbles. A step
    /// of a still world (every marble asleep, nothing moving: see [`run_step`]) runs only
    /// its first substep, so this stage does not run in it (it would find no awake marble).
    Finish,
}

/// Builds the substep schedule: every stage chained in order, single-threaded, and
/// ambiguity detection set to error so that any unordered conflicting pair of systems
/// fails to build. It runs on bevy_ecs's default executor (single-threaded without
/// bevy_ecs's `multi_threaded` feature; the stages are a chain either way).
pub fn substep_schedule() -> Schedule {
    let mut schedule = Schedule::new(MarbleSubstep);
    // The stages are one chain: a multi-threaded executor would only add overhead.
    // Parallelism, with the `parallel` feature, is inside the per-marble systems.
    schedule.set_executor(bevy_ecs::schedule::SingleThreadedExecutor::new());
    schedule.set_build_settings(ScheduleBuildSettings {
        ambiguity_detection: LogLevel::Error,
        ..Default::default()
    });
    schedule.configure_sets(
        (
            MarbleSystems::PrepareBoards,
            MarbleSystems::AccumulateForces,
            MarbleSystems::MarbleContacts,
            MarbleSystems::Integrate,
            MarbleSystems::DetectContacts,
            MarbleSystems::Respond,
            MarbleSystems::CollideMarbles,
            MarbleSystems::MoveBoards,
            MarbleSystems::Finish,
        )
            .chain(),
    );
    schedule.add_systems((
        (
            boards::prepare_boards,
            sleep::wake.run_if(sleep::first_substep),
        )
            .chain()
            .in_set(MarbleSystems::PrepareBoards),
        forces::accumulate_forces.in_set(MarbleSystems::AccumulateForces),
        integrate::integrate.in_set(MarbleSystems::Integrate),
        (detect::detect_contacts, detect::detect_contacts_spinning)
            .in_set(MarbleSystems::DetectContacts),
        (
            respond::respond,
            respond::respond_spinning,
            boards::rotate_marbles.run_if(|c: Res<StepConfig>| c.rolling),
        )
            .chain()
            .in_set(MarbleSystems::Respond),
        collide::marble_contacts
            .run_if(|c: Res<StepConfig>| c.marble_collisions)
            .in_set(MarbleSystems::MarbleContacts),
        collide::collide_marbles
            .run_if(|c: Res<StepConfig>| c.marble_collisions)
            .in_set(MarbleSystems::CollideMarbles),
        (
            boards::move_boards,
            boards::advance_tilt.run_if(resource_exists::<crate::config::GravityTilt>),
        )
            .chain()
            .in_set(MarbleSystems::MoveBoards),
        (
            sleep::fall_asleep.run_if(sleep::sleep_on),
            forces::clear_forces,
            forces::quarantine_non_finite,
        )
            .chain()
            .in_set(MarbleSystems::Finish)
            .run_if(forces::last_substep),
    ));
    schedule
}

/// Inserts the resources the substep schedule needs, keeping any already present.
pub fn init_resources(world: &mut World) {
    // The per-marble stages run on the compute task pool with the `parallel` feature; a
    // Bevy app's `TaskPoolPlugin` sets it up, a headless world gets one here.
    #[cfg(feature = "parallel")]
    bevy_tasks::ComputeTaskPool::get_or_init(bevy_tasks::TaskPool::default);
    world.init_resource::<StepConfig>();
    world.init_resource::<SubstepCounter>();
    world.init_resource::<crate::narrow::BoardCache>();
    world.init_resource::<crate::pairs::PairSolver>();
    world.init_resource::<crate::pairs::MarbleContacts>();
    world.init_resource::<crate::sleep::SleepState>();
}

/// Runs one step: `substeps` runs of the substep schedule through `run_substep`; only
/// the first when its [`crate::sleep::wake`] found a still world (every marble asleep,
/// none woken, no board moving, gravity not turning: [`SleepState::is_idle`]), whose
/// other substeps would do nothing. Systems added to [`MarbleSubstep`] then run once in
/// that step, and those of the last substep ([`MarbleSystems::Finish`], or run if
/// [`SubstepCounter::is_last`]) not at all.
///
/// [`SleepState::is_idle`]: crate::sleep::SleepState::is_idle
pub fn run_step(world: &mut World, mut run_substep: impl FnMut(&mut World)) {
    let count = world.resource::<StepConfig>().substeps.max(1);
    for index in 0..count {
        *world.resource_mut::<SubstepCounter>() = SubstepCounter { index, count };
        run_substep(world);
        if world
            .get_resource::<crate::sleep::SleepState>()
            .is_some_and(|s| s.is_idle())
        {
            break;
        }
    }
}
