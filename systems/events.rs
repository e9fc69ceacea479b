//! The event systems ([`crate::events`]): impacts and touches recorded every substep (stage
//! `Events`), contacts that started or ended and sensors entered or left at the step's end
//! (stage `Report`).

use bevy_ecs::entity::Entities;
use bevy_ecs::prelude::*;
use glam::Vec3;
use parry3d::bounding_volume::Aabb;

use super::Stepped;
use crate::components::{
    Board, BoardContacts, CarriedBy, Collider, ContactKind, Marble, Position, Quarantined, Radius,
    Rotation, Sensor,
};
use crate::config::{StepConfig, Substep};
use crate::events::{
    ContactEnded, ContactStarted, EventState, MarbleImpact, Observed, SensorEntered, SensorExited,
    SensorTrack, SensorVolume, emit,
};
use crate::pairs::MarbleContacts;
use crate::sleep::{SleepState, Sleeping};

/// First substep of each step (stage `Events`): notes which of the engine's events have
/// observers, so that only those are triggered.
pub fn find_observers(world: &mut World) {
    fn observed<E: Event>(world: &World, bit: u8) -> u8 {
        let Some(key) = world.event_key::<E>() else {
            return 0;
        };
        let any = world.observers().try_get_observers(key).is_some_and(|o| {
            !o.global_observers().is_empty()
                || !o.entity_observers().is_empty()
                || !o.component_observers().is_empty()
        });
        if any { bit } else { 0 }
    }
    let bits = observed::<MarbleImpact>(world, Observed::IMPACT)
        | observed::<ContactStarted>(world, Observed::STARTED)
        | observed::<ContactEnded>(world, Observed::ENDED)
        | observed::<SensorEntered>(world, Observed::ENTERED)
        | observed::<SensorExited>(world, Observed::EXITED);
    if let Some(mut state) = world.get_resource_mut::<EventState>() {
        state.observed = bits;
    }
}

/// Run condition: impacts and contacts are recorded ([`StepConfig::events`], or
/// [`RecordEvents`] present).
pub fn events_on(config: Res<StepConfig>, plugin: Option<Res<RecordEvents>>) -> bool {
    config.events || plugin.is_some()
}

/// Run condition: events are recorded or there are sensors.
pub fn watching(
    config: Res<StepConfig>,
    plugin: Option<Res<RecordEvents>>,
    sensors: Query<(), With<Sensor>>,
) -> bool {
    config.events || plugin.is_some() || !sensors.is_empty()
}

/// Present in an app with the Bevy plugin's `MarbleEventsPlugin` (a resource): impacts
/// and contacts are recorded whatever [`StepConfig::events`] says, so that a `StepConfig`
/// the game inserts or builds afresh later (whose default leaves them off) keeps them.
#[derive(Resource, Default, Debug)]
pub struct RecordEvents;

/// Run condition: there are sensors, or marbles were inside one at the last step (the
/// last sensor despawned, or its `Sensor` removed: they leave it).
pub fn any_sensor(sensors: Query<(), With<Sensor>>, state: Res<EventState>) -> bool {
    !sensors.is_empty() || !state.was_inside.is_empty()
}

/// Every substep, after the marble–board and marble–marble stages: each collision of the
/// substep becomes a [`MarbleImpact`] and its pair is noted as touching during the step;
/// in the last substep, every touching pair is (what [`ContactStarted`] and
/// [`ContactEnded`] compare: a pair touches during a step when it is hit in any substep or
/// touches at the end).
#[allow(clippy::too_many_arguments)]
pub fn record_touches(
    mut commands: Commands,
    substep: Res<Substep>,
    mut state: ResMut<EventState>,
    mut impacts: ResMut<Messages<MarbleImpact>>,
    pairs: Res<MarbleContacts>,
    marbles: Query<(Entity, BoardContacts), Stepped>,
    positions: Query<(&Position, &Radius), With<Marble>>,
) {
    let state = state.as_mut();
    let observed = state.observed & Observed::IMPACT != 0;
    let last = substep.is_last();
    for (marble, contacts) in &marbles {
        for c in contacts.iter() {
            let hit = c.kind == ContactKind::Collision;
            if last || hit {
                state.touching.push((marble, c.board));
            }
            if hit {
                let impact = MarbleImpact {
                    marble,
                    other: c.board,
                    point: c.point,
                    normal: c.normal,
                    speed: -c.closing_speed,
                };
                emit(&mut commands, &mut impacts, impact, observed);
            }
        }
    }
    for c in pairs.as_slice() {
        let hit = c.kind == ContactKind::Collision;
        if last || hit {
            state.touching.push((c.a, c.b));
        }
        if hit {
            // The point on the line of centres where the two surfaces meet.
            let point = match (positions.get(c.a), positions.get(c.b)) {
                (Ok((a, ra)), Ok((b, rb))) => {
                    let overlap = ra.0 + rb.0 - (b.0 - a.0).length();
                    a.0 + c.normal * (ra.0 - 0.5 * overlap)
                }
                _ => Vec3::ZERO,
            };
            let impact = MarbleImpact {
                marble: c.a,
                other: c.b,
                point,
                normal: -c.normal,
                speed: -c.closing_speed,
            };
            emit(&mut commands, &mut impacts, impact, observed);
        }
    }
}

/// Last substep: the pairs touching during this step against those of the last step; a
/// pair with a sleeping marble keeps touching while it sleeps. A pair whose marble or
/// board is gone by now (despawned during the step, by an observer of its impact) does not
/// start touching.
#[allow(clippy::type_complexity)]
pub fn finish_touches(
    mut commands: Commands,
    mut state: ResMut<EventState>,
    mut started: ResMut<Messages<ContactStarted>>,
    mut ended: ResMut<Messages<ContactEnded>>,
    (asleep, sleep): (
        Query<(), (With<Marble>, With<Sleeping>, Without<Quarantined>)>,
        Res<SleepState>,
    ),
    entities: &Entities,
) {
    let state = state.as_mut();
    // A step that touched what the last one did, in the same order (a pile at rest), with
    // the same marbles asleep, has nothing to report and needs no sorting.
    let sleepers = (asleep.iter().len(), sleep.naps);
    if state.touching == state.touched_raw && sleepers == state.sleepers {
        state.touching.clear();
        return;
    }
    state.sleepers = sleepers;
    std::mem::swap(&mut state.touched_raw, &mut state.touching);
    state.touching.clear();
    state.touching.extend_from_slice(&state.touched_raw);
    if !asleep.is_empty() {
        for &(m, o) in &state.touched {
            if asleep.contains(m) || asleep.contains(o) {
                state.touching.push((m, o));
            }
        }
    }
    state.touching.sort_unstable();
    state.touching.dedup();
    state
        .touching
        .retain(|&(m, o)| entities.contains_spawned(m) && entities.contains_spawned(o));
    let on_start = state.observed & Observed::STARTED != 0;
    let on_end = state.observed & Observed::ENDED != 0;
    diff(&state.touched, &state.touching, |&(marble, other), now| {
        if now {
            let event = ContactStarted { marble, other };
            emit(&mut commands, &mut started, event, on_start);
        } else {
            ended.write(ContactEnded { marble, other });
            // Triggering needs the marble; a despawned one only gets the message.
            if on_end {
                commands.queue(move |world: &mut World| {
                    if world.get_entity(marble).is_ok() {
                        world.trigger(ContactEnded { marble, other });
                    }
                });
            }
        }
    });
    std::mem::swap(&mut state.touched, &mut state.touching);
    state.touching.clear();
}

/// First substep, while there are sensors: each marble's [`SensorTrack`] starts where
/// the step starts it, so that a marble moved since the last check (by the program, or by
/// an observer of the last step's events: a labyrinth sending a marble back to its start)
/// is checked along its motion in this step, not along the jump.
pub fn start_sensor_tracks(
    mut marbles: Query<(&Position, &mut SensorTrack), (With<Marble>, Without<Quarantined>)>,
) {
    for (position, mut track) in &mut marbles {
        if track.0 != position.0 {
            track.0 = position.0;
        }
    }
}

/// Run condition: there are sensors, and observers of impacts or contacts, which can move
/// a marble during the step.
pub fn observers_may_move(sensors: Query<(), With<Sensor>>, state: Res<EventState>) -> bool {
    let movers = Observed::IMPACT | Observed::STARTED | Observed::ENDED;
    state.observed & movers != 0 && !sensors.is_empty()
}

/// Before each substep's impact and contact observers can run: notes where every marble
/// tracked for sensors is ([`catch_observer_moves`] compares).
pub fn note_positions(
    mut state: ResMut<EventState>,
    marbles: Query<(Entity, &Position), (With<SensorTrack>, Without<Quarantined>)>,
) {
    state.noted.clear();
    state.noted.extend(marbles.iter().map(|(e, p)| (e, p.0)));
}

/// Run condition: [`note_positions`] noted marbles not yet compared.
pub fn any_noted(state: Res<EventState>) -> bool {
    !state.noted.is_empty()
}

/// After the observers of the last substep's impacts (at the next substep's start, or
/// before the sensors are checked) and of the step's contacts: a marble that is not where
/// [`note_positions`] saw it was sent there by an observer (lava sending it back to the
/// start); its [`SensorTrack`] starts over there, so that the jump crosses no sensor.
pub fn catch_observer_moves(
    mut state: ResMut<EventState>,
    mut marbles: Query<(&Position, &mut SensorTrack)>,
) {
    for (entity, seen) in state.noted.drain(..) {
        if let Ok((position, mut track)) = marbles.get_mut(entity)
            && position.0 != seen
        {
            track.0 = position.0;
        }
    }
}

/// Places each sensor [`CarriedBy`] a board at the board's pose composed with its own.
pub fn carry_sensors(
    mut sensors: Query<(&CarriedBy, &mut Position, &mut Rotation), (With<Sensor>, Without<Board>)>,
    boards: Query<(&Position, &Rotation), With<Board>>,
) {
    for (carried, mut position, mut rotation) in &mut sensors {
        if let Ok((p, q)) = boards.get(carried.board) {
            let (p, q) = (p.0 + q.0 * carried.position, q.0 * carried.rotation);
            // Written only when it changes: a still board's sensors stay unchanged.
            if position.0 != p {
                position.0 = p;
            }
            if rotation.0 != q {
                rotation.0 = q;
            }
        }
    }
}

/// Last substep (and with sensors only): which marbles' centres are inside which sensors,
/// against the last step; a marble whose centre passed through a sensor since the last
/// step, neither end inside, enters and leaves it in this step. The sensors are found
/// through a grid over their bounds, so a marble costs one cell lookup however many
/// sensors there are. Runs after `carry_sensors`.
#[expect(
    clippy::type_complexity,
    reason = "a query of sensors and one of marbles"
)]
pub fn update_sensors(
    mut commands: Commands,
    mut state: ResMut<EventState>,
    mut entered: ResMut<Messages<SensorEntered>>,
    mut exited: ResMut<Messages<SensorExited>>,
    sensors: Query<(Entity, &Collider, &Position, &Rotation), With<Sensor>>,
    mut marbles: Query<
        (Entity, &Position, Option<&mut SensorTrack>),
        (With<Marble>, Without<Quarantined>, Without<Sensor>),
    >,
) {
    let state = state.as_mut();
    state.bounded.clear();
    state.unbounded.clear();
    state.sensor_bounds.clear();
    for (entity, collider, position, rotation) in &sensors {
        let volume = SensorVolume {
            entity,
            position: position.0,
            inverse: rotation.0.conjugate(),
            geometry: collider.0.clone(),
        };
        match collider.0.local_aabb() {
            Some(aabb) => {
                let world = crate::geometry::transform_aabb(&aabb, position.0, rotation.0);
                state.sensor_bounds.push(world);
                state.bounded.push(volume);
            }
            None => state.unbounded.push(volume),
        }
    }
    state.sensor_grid.build(&state.sensor_bounds);
    state.inside.clear();
    state.crossed.clear();
    for (marble, position, track) in &mut marbles {
        let p = position.0;
        let Some(mut track) = track else {
            // Seen for the first time: where it is now.
            commands.entity(marble).insert(SensorTrack(p));
            let (grid, bounded) = (&state.sensor_grid, &state.bounded);
            let inside = &mut state.inside;
            grid.query(&Aabb::new(p, p), |k| {
                let volume = &bounded[k as usize];
                if volume.contains(p) {
                    inside.push((volume.entity, marble));
                }
            });
            for volume in &state.unbounded {
                if volume.contains(p) {
                    inside.push((volume.entity, marble));
                }
            }
            continue;
        };
        let from = track.0;
        track.0 = p;
        // The sensors near the segment from the last check to here: inside at its end, or
        // passed through on the way.
        let (grid, bounded) = (&state.sensor_grid, &state.bounded);
        let (inside, crossed) = (&mut state.inside, &mut state.crossed);
        let moved = from != p;
        let mut visit = |volume: &SensorVolume| {
            if volume.contains(p) {
                inside.push((volume.entity, marble));
            } else if moved && !volume.contains(from) && volume.crossed(from, p) {
                crossed.push((volume.entity, marble));
            }
        };
        let path = Aabb::new(from.min(p), from.max(p));
        grid.query(&path, |k| visit(&bounded[k as usize]));
        for volume in &state.unbounded {
            visit(volume);
        }
    }
    state.crossed.sort_unstable();
    state.crossed.dedup();
    let on_enter = state.observed & Observed::ENTERED != 0;
    let on_exit = state.observed & Observed::EXITED != 0;
    for &(sensor, marble) in &state.crossed {
        emit(
            &mut commands,
            &mut entered,
            SensorEntered { sensor, marble },
            on_enter,
        );
        emit(
            &mut commands,
            &mut exited,
            SensorExited { sensor, marble },
            on_exit,
        );
    }
    state.inside.sort_unstable();
    state.inside.dedup();
    diff(
        &state.was_inside,
        &state.inside,
        |&(sensor, marble), now| {
            if now {
                emit(
                    &mut commands,
                    &mut entered,
                    SensorEntered { sensor, marble },
                    on_enter,
                );
            } else {
                exited.write(SensorExited { sensor, marble });
                if on_exit {
                    commands.queue(move |world: &mut World| {
                        if world.get_entity(marble).is_ok() {
                            world.trigger(SensorExited { sensor, marble });
                        }
                    });
                }
            }
        },
    );
    std::mem::swap(&mut state.was_inside, &mut state.inside);
}

/// Calls `f(pair, true)` for each pair of the sorted `now` not in the sorted `before`, and
/// `f(pair, false)` for each of `before` not in `now`, in one merge of the two.
fn diff<T: Ord + Copy>(before: &[T], now: &[T], mut f: impl FnMut(&T, bool)) {
    let (mut i, mut j) = (0, 0);
    while i < before.len() && j < now.len() {
        match before[i].cmp(&now[j]) {
            std::cmp::Ordering::Less => {
                f(&before[i], false);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                f(&now[j], true);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                i += 1;
                j += 1;
            }
        }
    }
    before[i..].iter().for_each(|p| f(p, false));
    now[j..].iter().for_each(|p| f(p, true));
}
