//! Headless stepping: a scene's world and the physics schedule, without `bevy_app`.

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};

use crate::components::{
    AngularVelocity, Board, CarriedBy, Collider, Friction, Marble, Mass, Position, Quarantined,
    Radius, Restitution, RollingResistance, Rotation, Sensor, SpinDamping, Velocity,
};
use crate::config::GravityTilt;
use crate::scene::{MarbleDesc, Scene, SceneError, quat};
use crate::schedule::{init_resources, run_step, substep_schedule};

/// A scene's `World` and the physics schedule. Stepping one marble or a million goes
/// through the same systems as [`crate::MarblePhysicsPlugin`].
///
/// ```
/// use bevy_marble::prelude::*;
///
/// let scene = Scene::from_ron_str(
///     "(boards: [(shape: Plane(()))], marbles: [(position: (0.0, 1.0, 0.0))])",
/// )?;
/// let mut sim = Simulation::from_scene(&scene)?;
/// for _ in 0..240 {
///     sim.step();
/// }
/// let marble = sim.marbles()[0];
/// let y = sim.world().get::<Position>(marble).unwrap().y;
/// assert!(y < 1.0);
/// # Ok::<(), SceneError>(())
/// ```
pub struct Simulation {
    world: World,
    schedule: Schedule,
    marbles: Vec<Entity>,
    boards: Vec<Entity>,
    sensors: Vec<Entity>,
    steps: u64,
}

/// The entities [`spawn_scene`] made, each list in the scene's order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneEntities {
    /// One per board.
    pub boards: Vec<Entity>,
    /// One per marble.
    pub marbles: Vec<Entity>,
    /// One per sensor, with a `Name` from the scene.
    pub sensors: Vec<Entity>,
}

/// Spawns a validated scene's boards, marbles and sensors into `world`, in that order and
/// each in the scene's order, with the components a [`Simulation`] gives them; under
/// `tilt_as_gravity` it also inserts the [`GravityTilt`] resource. The step settings are
/// left to the caller ([`Scene::step_config`] as a resource). A Bevy game spawns its level
/// this way, adds its own components (meshes, `Transform`s), and steps the same physics as
/// `marble run` does on the same file.
pub fn spawn_scene(scene: &Scene, world: &mut World) -> SceneEntities {
    // Neverball's model: the turning board stands still and gravity turns instead.
    let tilt = scene
        .boards
        .iter()
        .find(|b| scene.tilt_as_gravity && b.angular_velocity != [0.0; 3])
        .map(|b| GravityTilt {
            angular_velocity: Vec3::from_array(b.angular_velocity),
            pivot: Vec3::from_array(b.position),
            rotation: Quat::IDENTITY,
        });
    if let Some(tilt) = tilt {
        world.insert_resource(tilt);
    }
    let boards: Vec<Entity> = scene
        .boards
        .iter()
        .map(|b| {
            world
                .spawn((
                    Board,
                    Collider::new(b.shape.build()),
                    Position(Vec3::from_array(b.position)),
                    Rotation(quat(b.rotation)),
                    Velocity(Vec3::from_array(b.velocity)),
                    AngularVelocity(if tilt.is_some() {
                        Vec3::ZERO
                    } else {
                        Vec3::from_array(b.angular_velocity)
                    }),
                    Restitution(b.restitution),
                    Friction(b.friction),
                    RollingResistance(b.rolling_resistance),
                    SpinDamping(b.spin_damping),
                ))
                .id()
        })
        .collect();
    // One batch, so that the marbles' table is sized for them at once (spawned one by one,
    // its columns grow by doubling, up to twice the memory they need).
    let marble = |m: &MarbleDesc| {
        (
            Marble,
            Position(Vec3::from_array(m.position)),
            Velocity(Vec3::from_array(m.velocity)),
            Radius(m.radius),
            m.mass.map_or_else(|| Mass::glass(m.radius), Mass::new),
            Restitution(m.restitution),
            Friction(m.friction),
        )
    };
    // Spin exists only when the scene asks for rolling.
    let marbles: Vec<Entity> = if scene.rolling {
        world
            .spawn_batch(scene.marbles.iter().map(|m| {
                (
                    marble(m),
                    AngularVelocity(Vec3::from_array(m.angular_velocity)),
                    Rotation::default(),
                    RollingResistance(m.rolling_resistance),
                    SpinDamping(m.spin_damping),
                )
            }))
            .collect()
    } else {
        world
            .spawn_batch(scene.marbles.iter().map(marble))
            .collect()
    };
    let sensors = scene
        .sensors
        .iter()
        .map(|s| {
            let (p, q) = (Vec3::from_array(s.position), quat(s.rotation));
            // Carried by a board: placed at the board's pose now, and at every step's end.
            let (pose, carried) = match s.board {
                Some(b) => {
                    let board = boards[b];
                    let bp = world.get::<Position>(board).expect("a board").0;
                    let bq = world.get::<Rotation>(board).expect("a board").0;
                    let carried = CarriedBy {
                        board,
                        position: p,
                        rotation: q,
                    };
                    ((bp + bq * p, bq * q), Some(carried))
                }
                None => ((p, q), None),
            };
            let mut sensor = world.spawn((
                Sensor,
                Collider::new(s.shape.build()),
                Position(pose.0),
                Rotation(pose.1),
                bevy_ecs::name::Name::new(s.name.clone()),
            ));
            if let Some(carried) = carried {
                sensor.insert(carried);
            }
            sensor.id()
        })
        .collect();
    SceneEntities {
        boards,
        marbles,
        sensors,
    }
}

impl Simulation {
    /// Validates the scene and builds its world: one entity per board and marble, in the
    /// scene's order, and the [`crate::config::StepConfig`] from its settings.
    pub fn from_scene(scene: &Scene) -> Result<Simulation, SceneError> {
        scene.validate()?;
        let mut world = World::new();
        world.insert_resource(scene.step_config());
        init_resources(&mut world);
        let SceneEntities {
            boards,
            marbles,
            sensors,
        } = spawn_scene(scene, &mut world);
        let mut schedule = substep_schedule();
        schedule
            .initialize(&mut world)
            .expect("the physics schedule is well formed");
        Ok(Simulation {
            world,
            schedule,
            marbles,
            boards,
            sensors,
            steps: 0,
        })
    }

    /// Advances one scene `dt` (all substeps). The messages of the step before stay
    /// readable through this step ([`crate::events`]); older ones are dropped. A program
    /// that gave the [`StepConfig`](crate::config::StepConfig) a bad value gets the step
    /// refused: nothing moves, a [`StepRefused`](crate::validate::StepRefused) message says
    /// why, and the step is not counted in [`Simulation::steps`].
    pub fn step(&mut self) {
        crate::events::update_messages(&mut self.world);
        let schedule = &mut self.schedule;
        if run_step(&mut self.world, |world| schedule.run(world)) {
            self.steps += 1;
        }
    }

    /// The world: marbles and boards are entities, settings are resources.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, mutably (spawn marbles, change settings, apply forces).
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// The marbles of the scene, in its order.
    pub fn marbles(&self) -> &[Entity] {
        &self.marbles
    }

    /// The board contacts of `marble` during the last substep, in the order recorded
    /// (`None` for an entity that is not a marble). [`Contacts`](crate::components::Contacts)
    /// alone holds how many there were and the first.
    pub fn contacts(&self, marble: Entity) -> Option<crate::components::ContactList> {
        let entity = self.world.get_entity(marble).ok()?;
        let head = entity.get::<crate::components::Contacts>()?;
        let more = entity.get::<crate::components::MoreContacts>()?;
        Some(crate::components::ContactList::load(head, more))
    }

    /// The boards of the scene, in its order.
    pub fn boards(&self) -> &[Entity] {
        &self.boards
    }

    /// The sensors of the scene, in its order.
    pub fn sensors(&self) -> &[Entity] {
        &self.sensors
    }

    /// Steps taken so far (refused steps not counted).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The scene's marbles that have been quarantined (their state stopped being finite).
    pub fn quarantined(&self) -> Vec<usize> {
        self.marbles
            .iter()
            .enumerate()
            .filter(|(_, e)| self.world.get::<Quarantined>(**e).is_some())
            .map(|(i, _)| i)
            .collect()
    }

    /// Whether the scene's marble `index` is asleep ([`crate::sleep`]; never with sleeping
    /// off).
    pub fn is_asleep(&self, index: usize) -> bool {
        self.world
            .get::<crate::sleep::Sleeping>(self.marbles[index])
            .is_some()
    }

    /// How many of the scene's marbles are asleep.
    pub fn asleep(&self) -> usize {
        (0..self.marbles.len())
            .filter(|&i| self.is_asleep(i))
            .count()
    }

    /// [`Self::marble_spin`] in the world: the same unless the scene models its tilting
    /// board by tilting gravity, whose board-frame spin this maps back to the world (as
    /// [`Self::marble_world_state`] does the position and velocity) for a marble that
    /// spins (zero for one that does not: its spin is not modelled).
    pub fn marble_world_spin(&self, index: usize) -> Vec3 {
        let Some(w) = self.world.get::<AngularVelocity>(self.marbles[index]) else {
            return Vec3::ZERO;
        };
        match self.world.get_resource::<GravityTilt>() {
            Some(tilt) => tilt.spin_to_world(w.0),
            None => w.0,
        }
    }

    /// Angular velocity of the scene's marble `index` (zero when it does not spin; in the
    /// still board's frame when the scene tilts gravity instead of its board).
    pub fn marble_spin(&self, index: usize) -> Vec3 {
        self.world
            .get::<AngularVelocity>(self.marbles[index])
            .map_or(Vec3::ZERO, |w| w.0)
    }

    /// Position and velocity of the scene's marble `index` in the world: the same as
    /// [`Self::marble_state`] unless the scene models its tilting board by tilting gravity,
    /// whose board-frame results this maps back to the world.
    pub fn marble_world_state(&self, index: usize) -> (Vec3, Vec3) {
        let (x, v) = self.marble_state(index);
        self.to_world(x, v)
    }

    /// [`Self::marble_world_state`], `None` for a marble the program despawned (or took
    /// the `Position` or `Velocity` of).
    ///
    /// # Panics
    ///
    /// If `index` is not one of the scene's marbles.
    pub fn try_marble_world_state(&self, index: usize) -> Option<(Vec3, Vec3)> {
        let (x, v) = self.try_marble_state(index)?;
        Some(self.to_world(x, v))
    }

    /// A state in the still board's frame mapped to the world (the identity unless the
    /// scene tilts gravity).
    fn to_world(&self, x: Vec3, v: Vec3) -> (Vec3, Vec3) {
        match self.world.get_resource::<GravityTilt>() {
            Some(tilt) => tilt.to_world(x, v),
            None => (x, v),
        }
    }

    /// [`Self::marble_state`], `None` for a marble the program despawned (or took the
    /// `Position` or `Velocity` of).
    ///
    /// # Panics
    ///
    /// If `index` is not one of the scene's marbles.
    pub fn try_marble_state(&self, index: usize) -> Option<(Vec3, Vec3)> {
        let e = self.marbles[index];
        Some((
            self.world.get::<Position>(e)?.0,
            self.world.get::<Velocity>(e)?.0,
        ))
    }

    /// Position and velocity of the scene's marble `index` (in the still board's frame when
    /// the scene tilts gravity instead of its board).
    ///
    /// # Panics
    ///
    /// If `index` is not one of the scene's marbles, or the program despawned that marble
    /// or removed its `Position` or `Velocity` ([`Self::try_marble_state`] for such a
    /// marble).
    pub fn marble_state(&self, index: usize) -> (Vec3, Vec3) {
        self.try_marble_state(index)
            .expect("a marble with a position and a velocity")
    }
}
