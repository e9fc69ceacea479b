//! The physics step's schedule: the one place where the stage order is fixed.

use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{LogLevel, ScheduleBuildSettings, ScheduleLabel};

use crate::config::{StepConfig, Substep};
use crate::systems::{
    board_detection, board_response, boards, events, forces, pairs, sleep, validate,
};
use crate::validate::{InvalidValue, StepRefused};

/// The schedule that runs one substep. A step runs it `substeps` times
/// ([`run_step`]).
#[derive(ScheduleLabel, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MarbleSubstep;

/// The stages of a substep, in order: the one place where the order is fixed. Stages
/// named `Board…` are marble–board work, `Pair…` marble–marble work; each stage's systems
/// are in one file under `systems/` (the table in [`crate::systems`]). Add your own
/// systems to the physics with `.in_set(MarbleSystems::…)` or order them
/// `.before`/`.after` a stage.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MarbleSystems {
    /// First substep: marbles and boards with a bad value are quarantined before anything
    /// moves ([`crate::validate`]).
    Validate,
    /// Boards with a [`NextPose`](crate::components::NextPose) get their velocities (first
    /// substep); every board's pose and motion is snapshot for the substep.
    PrepareBoards,
    /// First substep, with sleeping on or marbles asleep: wake the sleeping marbles
    /// something reaches ([`crate::sleep`]).
    Wake,
    /// Gravity plus user forces → acceleration.
    AccumulateForces,
    /// Marble–marble pairs touching at the substep's start: collisions, friction, contact
    /// forces, overlap (only with `marble_collisions` on).
    PairContacts,
    /// Each marble's start of the substep noted; marble–board touches (collision or
    /// contact), first impact, or end overlap; the closed forms of a marble alone on one
    /// piece; free motion with the chosen integrator for a marble no board touches or
    /// reaches (one pass over the marbles' columns: the others are moved from their start,
    /// here or by the response).
    BoardDetection,
    /// Marble–board response: equation (1), contacts, continuous collision, position
    /// correction; spinning marbles' orientations turned.
    BoardResponse,
    /// Marble–marble pairs that meet inside the substep collide at their time of impact
    /// (only with `marble_collisions` on).
    PairImpacts,
    /// The substep's impacts become [`MarbleImpact`](crate::events::MarbleImpact)
    /// messages, and its touching pairs are noted (only with `events` on).
    Events,
    /// Kinematic boards advance; on the last substep, driven boards are placed at their
    /// [`NextPose`](crate::components::NextPose).
    MoveBoards,
    /// Last substep, with sleeping on: put to sleep the groups that have been slow long
    /// enough ([`crate::sleep`]).
    FallAsleep,
    /// Last substep: clear forces. (A marble a step sent out of the supported range is
    /// quarantined by the next step's `Validate`, before anything moves.)
    Finish,
    /// Last substep: contacts that started or ended, sensors entered or left
    /// ([`crate::events`]).
    Report,
}

/// The stages that run only in the substep that ends a step: its last, or, in a step of a
/// still world (every marble asleep, nothing moving: see [`run_step`]), its first and
/// only one (they find no awake marble then, but sensors added, moved or removed are
/// still reported).
pub const LAST_SUBSTEP_STAGES: [MarbleSystems; 3] = [
    MarbleSystems::FallAsleep,
    MarbleSystems::Finish,
    MarbleSystems::Report,
];

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
            MarbleSystems::Validate,
            MarbleSystems::PrepareBoards,
            MarbleSystems::Wake,
            MarbleSystems::AccumulateForces,
            MarbleSystems::PairContacts,
            MarbleSystems::BoardDetection,
            MarbleSystems::BoardResponse,
            MarbleSystems::PairImpacts,
            MarbleSystems::Events,
            MarbleSystems::MoveBoards,
            MarbleSystems::FallAsleep,
            MarbleSystems::Finish,
            MarbleSystems::Report,
        )
            .chain(),
    );
    for stage in LAST_SUBSTEP_STAGES {
        schedule.configure_sets(stage.run_if(forces::step_ends));
    }
    let rolling = |c: Res<StepConfig>| c.rolling;
    let collisions = |c: Res<StepConfig>| c.marble_collisions;
    schedule.add_systems((
        (
            (
                validate::validate,
                events::start_sensor_tracks.run_if(events::any_sensor),
            )
                .chain()
                .run_if(sleep::first_substep),
            events::catch_observer_moves.run_if(events::any_noted),
        )
            .chain()
            .in_set(MarbleSystems::Validate),
        (
            boards::drive_boards.run_if(sleep::first_substep),
            boards::prepare_boards,
        )
            .chain()
            .in_set(MarbleSystems::PrepareBoards),
        sleep::wake
            .run_if(sleep::first_substep)
            .in_set(MarbleSystems::Wake),
        forces::accumulate_forces.in_set(MarbleSystems::AccumulateForces),
        (
            pairs::forget_stale_contacts.run_if(collisions),
            pairs::pair_contacts.run_if(collisions),
            pairs::forget_pairs.run_if(not(collisions)),
        )
            .chain()
            .in_set(MarbleSystems::PairContacts),
        (
            board_detection::detect_board_contacts,
            board_detection::detect_board_contacts_spinning,
        )
            .in_set(MarbleSystems::BoardDetection),
        (
            board_response::respond_to_boards,
            board_response::respond_to_boards_spinning,
            board_response::rotate_marbles.run_if(rolling),
        )
            .chain()
            .in_set(MarbleSystems::BoardResponse),
        pairs::pair_impacts
            .run_if(collisions)
            .in_set(MarbleSystems::PairImpacts),
        (
            events::find_observers
                .run_if(sleep::first_substep)
                .run_if(events::watching),
            events::note_positions.run_if(events::observers_may_move),
            events::record_touches.run_if(events::events_on),
        )
            .chain()
            .in_set(MarbleSystems::Events),
        (
            boards::move_boards,
            boards::advance_tilt.run_if(resource_exists::<crate::config::GravityTilt>),
            boards::finish_driven_boards.run_if(forces::last_substep),
        )
            .chain()
            .in_set(MarbleSystems::MoveBoards),
        sleep::fall_asleep
            .run_if(sleep::sleep_on)
            .in_set(MarbleSystems::FallAsleep),
        forces::clear_forces.in_set(MarbleSystems::Finish),
        (
            events::finish_touches.run_if(events::events_on),
            (
                events::carry_sensors,
                events::catch_observer_moves.run_if(events::any_noted),
                events::update_sensors,
            )
                .chain()
                .run_if(events::any_sensor),
        )
            .chain()
            .in_set(MarbleSystems::Report),
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
    world.init_resource::<Substep>();
    world.init_resource::<crate::board_contact::BoardCache>();
    world.init_resource::<crate::systems::board_detection::Flagged>();
    world.init_resource::<crate::pairs::PairSolver>();
    world.init_resource::<crate::pairs::MarbleContacts>();
    world.init_resource::<crate::sleep::SleepState>();
    world.init_resource::<crate::events::EventState>();
    world.init_resource::<Messages<crate::events::MarbleImpact>>();
    world.init_resource::<Messages<crate::events::ContactStarted>>();
    world.init_resource::<Messages<crate::events::ContactEnded>>();
    world.init_resource::<Messages<crate::events::SensorEntered>>();
    world.init_resource::<Messages<crate::events::SensorExited>>();
    world.init_resource::<Messages<crate::validate::QuarantineReport>>();
    world.init_resource::<Messages<StepRefused>>();
}

/// Runs one step: `substeps` runs of the substep schedule through `run_substep`; only
/// the first when its [`crate::systems::sleep::wake`] found a still world (every marble asleep,
/// none woken, no board moving, gravity not turning: [`SleepState::is_idle`]), whose
/// other substeps would do nothing. Systems added to [`MarbleSubstep`] then run once in
/// that step; the [`LAST_SUBSTEP_STAGES`] run in it too, while systems run if
/// [`Substep::is_last`] do not. It sets the [`Substep`] resource before each substep.
///
/// A [`StepConfig`] with a bad value ([`StepConfig::validate`]) runs no substep: the step
/// is refused, a [`StepRefused`] message names the field and value (and a log error, when
/// that reason first appears), and `false` is returned; otherwise `true`.
///
/// [`SleepState::is_idle`]: crate::sleep::SleepState::is_idle
pub fn run_step(world: &mut World, mut run_substep: impl FnMut(&mut World)) -> bool {
    let config = world.resource::<StepConfig>();
    if let Err(reason) = config.validate() {
        let mut last = world.get_resource_or_init::<LastRefusal>();
        if last.0.as_ref() != Some(&reason) {
            log::error!("bevy_marble: step refused: {reason}");
            last.0 = Some(reason.clone());
        }
        if let Some(mut reports) = world.get_resource_mut::<Messages<StepRefused>>() {
            reports.write(StepRefused { reason });
        }
        return false;
    }
    let (h, count) = (config.substep_dt(), config.substeps.max(1));
    for index in 0..count {
        *world.resource_mut::<Substep>() = Substep { h, index, count };
        run_substep(world);
        if world
            .get_resource::<crate::sleep::SleepState>()
            .is_some_and(|s| s.is_idle())
        {
            break;
        }
    }
    if let Some(mut last) = world.get_resource_mut::<LastRefusal>() {
        last.0 = None;
    }
    true
}

/// The reason the last step was refused, kept so that a refusal repeated every step logs
/// once.
#[derive(Resource, Default)]
struct LastRefusal(Option<InvalidValue>);
