//! bevy_marble's scenes in rapier3d, so that the two engines can be timed on the same work.
//!
//! [`build`] turns a [`Scene`] (the scene-file types of bevy_marble) into a [`RapierWorld`]:
//!
//! - a board becomes one rigid body at the board's pose, *fixed* when its velocity and
//!   angular velocity are zero and *kinematic velocity-based* (with that linear and angular
//!   velocity) otherwise, carrying one collider per part (a half-space for `Plane`, a cuboid,
//!   a triangle mesh, a height field; the parts of a `Compound` each at their pose in the
//!   board's frame); its colliders have the board's restitution and friction. The body's
//!   centre of mass is pinned at its origin, so that a turning board turns about the board's
//!   `position` as in bevy_marble. `Bowl` parts are not mapped (no bench scene uses them):
//!   they are counted in [`RapierWorld::skipped_parts`].
//! - a marble becomes a dynamic body with a ball collider of its radius, its mass (or glass,
//!   2500 kg/m³, solid) and restitution. bevy_marble's smooth model (`rolling: false`) has no
//!   friction: then every collider, board and marble, has friction 0, so that the pair's
//!   friction is 0; with `rolling: true` each has its own friction. Both coefficients combine
//!   by [`CoefficientCombineRule::Average`], as in bevy_marble.
//! - with `marble_collisions: false`, collision groups keep marbles from touching each other
//!   (they still touch boards).
//! - [`IntegrationParameters`]: `dt` is the scene's step; `length_unit` is the mean marble
//!   diameter (rapier's tolerances are tuned for metre-sized bodies; see its docs), with the
//!   speed cap, which rapier scales by the length unit too, kept at its default 400 m/s;
//!   solver iterations, sleeping and the rest are rapier's defaults. No body has CCD ("bullet")
//!   turned on; rapier's automatic sweep of fast bodies against fixed colliders is left on
//!   (it is on by default and only acts on bodies that move far in one step).

use bevy_marble::Scene;
use bevy_marble::components::Mass;
use bevy_marble::scene::{BoardDesc, ShapeDesc};
use rapier3d::prelude::*;

/// Boards' collision group.
const BOARDS: Group = Group::GROUP_1;
/// Marbles' collision group.
const MARBLES: Group = Group::GROUP_2;

/// Everything rapier needs to step a scene.
pub struct RapierWorld {
    /// m/s².
    pub gravity: Vector,
    /// Step length, solver settings, length unit.
    pub params: IntegrationParameters,
    /// The step driver.
    pub pipeline: PhysicsPipeline,
    /// Islands and sleeping.
    pub islands: IslandManager,
    /// Broad phase (a BVH in rapier 0.36).
    pub broad_phase: DefaultBroadPhase,
    /// Narrow phase: contact manifolds.
    pub narrow_phase: NarrowPhase,
    /// Rigid bodies: boards first, then marbles.
    pub bodies: RigidBodySet,
    /// Colliders.
    pub colliders: ColliderSet,
    /// Unused (no joints), required by the pipeline.
    pub impulse_joints: ImpulseJointSet,
    /// Unused (no joints), required by the pipeline.
    pub multibody_joints: MultibodyJointSet,
    /// Unused (no soft bodies), required by the pipeline.
    pub soft_bodies: SoftBodySet,
    /// Continuous collision detection.
    pub ccd: CCDSolver,
    /// The boards' bodies, in scene order.
    pub boards: Vec<RigidBodyHandle>,
    /// The marbles' bodies, in scene order.
    pub marbles: Vec<RigidBodyHandle>,
    /// Board parts that have no rapier counterpart here (`Bowl`), left out.
    pub skipped_parts: usize,
    /// rapier steps per [`RapierWorld::step`] (1, or the scene's substeps with
    /// [`build_substepped`]).
    pub pipeline_steps_per_step: u32,
    steps: u64,
}

impl RapierWorld {
    /// Advances the world by one scene step (`scene.dt`).
    pub fn step(&mut self) {
        for _ in 0..self.pipeline_steps_per_step {
            self.pipeline.step(
                self.gravity,
                &self.params,
                &mut self.islands,
                &mut self.broad_phase,
                &mut self.narrow_phase,
                &mut self.bodies,
                &mut self.colliders,
                &mut self.impulse_joints,
                &mut self.multibody_joints,
                &mut self.soft_bodies,
                &mut self.ccd,
                &(),
                &(),
            );
        }
        self.steps += 1;
    }

    /// Scene steps taken since [`build`].
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Where the marbles are, in the frame of the first board (its current pose), and how
    /// fast they go; see [`Stats`]. `inner_half`: the half-width inside the board's walls,
    /// to count the marbles that left the board.
    pub fn stats(&self, inner_half: Option<f32>) -> Stats {
        let frame = self
            .boards
            .first()
            .map(|&h| *self.bodies[h].position())
            .unwrap_or(Pose::IDENTITY);
        // A body asleep is out of the island manager's active set (rapier 0.36 puts
        // islands to sleep without setting each body's `is_sleeping` flag).
        let active: std::collections::HashSet<RigidBodyHandle> =
            self.islands.active_bodies().collect();
        let sleeping = self.marbles.iter().filter(|h| !active.contains(h)).count();
        let mut s = Stats::of(
            frame,
            self.marbles.iter().map(|&h| {
                let rb = &self.bodies[h];
                (rb.translation().to_array(), rb.linvel().to_array())
            }),
            inner_half,
        );
        s.sleeping = sleeping;
        s
    }
}

/// Marble positions in the first board's frame, and speeds.
#[derive(Clone, Copy, Debug)]
pub struct Stats {
    /// Lowest centre height above the board's local y = 0, m.
    pub min_y: f32,
    /// Largest |x| of a centre, m.
    pub max_abs_x: f32,
    /// Largest |z| of a centre, m.
    pub max_abs_z: f32,
    /// Fastest marble, m/s.
    pub max_speed: f32,
    /// Marbles with a non-finite position or velocity.
    pub non_finite: usize,
    /// Marbles whose centre is below the board's floor (local y < 0) or outside its walls
    /// (|x| or |z| past the inner half-width, when given).
    pub outside: usize,
    /// Marbles rapier has put to sleep.
    pub sleeping: usize,
}

impl Stats {
    /// The stats of marbles given as world `(position, velocity)`, seen from the board pose
    /// `frame`.
    pub fn of(
        frame: Pose,
        marbles: impl IntoIterator<Item = ([f32; 3], [f32; 3])>,
        inner_half: Option<f32>,
    ) -> Stats {
        let inv = frame.inverse();
        let mut s = Stats {
            min_y: f32::INFINITY,
            max_abs_x: 0.0,
            max_abs_z: 0.0,
            max_speed: 0.0,
            non_finite: 0,
            outside: 0,
            sleeping: 0,
        };
        for (p, v) in marbles {
            let p = inv * Vector::from_array(p);
            let v = Vector::from_array(v);
            if !p.is_finite() || !v.is_finite() {
                s.non_finite += 1;
                continue;
            }
            let half = inner_half.unwrap_or(f32::INFINITY);
            if p.y < 0.0 || p.x.abs() > half || p.z.abs() > half {
                s.outside += 1;
            }
            s.min_y = s.min_y.min(p.y);
            s.max_abs_x = s.max_abs_x.max(p.x.abs());
            s.max_abs_z = s.max_abs_z.max(p.z.abs());
            s.max_speed = s.max_speed.max(v.length());
        }
        s
    }
}

/// For a board built by `bevy_marble::scenes::walled_floor` (floor, then the +x wall, ...):
/// the distance from the centre to the inner face of the walls.
pub fn inner_half(scene: &Scene) -> Option<f32> {
    let ShapeDesc::Compound(parts) = &scene.boards.first()?.shape else {
        return None;
    };
    let wall = parts.get(1)?;
    let ShapeDesc::Cuboid { half_extents } = wall.shape else {
        return None;
    };
    Some(wall.position[0] - half_extents[0])
}

/// The pose of a scene board after `t` seconds of its constant velocity and angular
/// velocity (world frame, about its position), as bevy_marble moves it.
pub fn board_pose_at(b: &BoardDesc, t: f32) -> Pose {
    let p0 = pose(b.position, b.rotation);
    let turn = Rotation::from_scaled_axis(Vector::from_array(b.angular_velocity) * t);
    Pose::from_parts(
        p0.translation + Vector::from_array(b.velocity) * t,
        (turn * p0.rotation).normalize(),
    )
}

/// The scene in rapier, one [`RapierWorld::step`] per scene step of `scene.dt` (rapier's own
/// solver substeps, `num_solver_iterations`, at their default).
pub fn build(scene: &Scene) -> RapierWorld {
    build_with(scene, 1)
}

/// As [`build`], but each [`RapierWorld::step`] runs `scene.substeps` rapier steps of
/// `scene.dt / scene.substeps`, collision detection included, as bevy_marble's substeps do.
pub fn build_substepped(scene: &Scene) -> RapierWorld {
    build_with(scene, scene.substeps.max(1))
}

fn build_with(scene: &Scene, pipeline_steps_per_step: u32) -> RapierWorld {
    let mut params = IntegrationParameters {
        dt: scene.dt / pipeline_steps_per_step as f32,
        ..IntegrationParameters::default()
    };
    if !scene.marbles.is_empty() {
        let mean_radius =
            scene.marbles.iter().map(|m| m.radius).sum::<f32>() / scene.marbles.len() as f32;
        params.length_unit = 2.0 * mean_radius;
        // Rapier scales its speed cap by the length unit too (400 units/s: 6.4 m/s for 8 mm
        // marbles, less than a marble reaches falling off a board); keep it at 400 m/s.
        params.normalized_max_linear_velocity =
            IntegrationParameters::default().normalized_max_linear_velocity / params.length_unit;
    }

    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let mut skipped_parts = 0;

    let board_groups = InteractionGroups::new(BOARDS, Group::ALL, InteractionTestMode::And);
    let marble_groups = if scene.marble_collisions {
        InteractionGroups::new(MARBLES, Group::ALL, InteractionTestMode::And)
    } else {
        InteractionGroups::new(MARBLES, BOARDS, InteractionTestMode::And)
    };

    let boards = scene
        .boards
        .iter()
        .map(|b| {
            let handle = bodies.insert(board_body(b));
            let friction = if scene.rolling { b.friction } else { 0.0 };
            let parts: Vec<(Pose, &ShapeDesc)> = match &b.shape {
                ShapeDesc::Compound(parts) => parts
                    .iter()
                    .map(|p| (pose(p.position, p.rotation), &p.shape))
                    .collect(),
                other => vec![(Pose::IDENTITY, other)],
            };
            for (at, shape) in parts {
                let Some(builder) = collider(shape) else {
                    skipped_parts += 1;
                    continue;
                };
                let co = builder
                    .position(at)
                    // Massless: the body's mass properties are pinned in `board_body`.
                    .density(0.0)
                    .restitution(b.restitution)
                    .restitution_combine_rule(CoefficientCombineRule::Average)
                    .friction(friction)
                    .friction_combine_rule(CoefficientCombineRule::Average)
                    .collision_groups(board_groups)
                    .build();
                colliders.insert_with_parent(co, handle, &mut bodies);
            }
            handle
        })
        .collect();

    let marbles = scene
        .marbles
        .iter()
        .map(|m| {
            let mut rb = RigidBodyBuilder::dynamic()
                .translation(Vector::from_array(m.position))
                .linvel(Vector::from_array(m.velocity));
            if scene.rolling {
                rb = rb.angvel(Vector::from_array(m.angular_velocity));
            }
            let handle = bodies.insert(rb);
            let co = ColliderBuilder::ball(m.radius)
                .mass(m.mass.unwrap_or_else(|| Mass::glass_mass(m.radius)))
                .restitution(m.restitution)
                .restitution_combine_rule(CoefficientCombineRule::Average)
                .friction(if scene.rolling { m.friction } else { 0.0 })
                .friction_combine_rule(CoefficientCombineRule::Average)
                .collision_groups(marble_groups)
                .build();
            colliders.insert_with_parent(co, handle, &mut bodies);
            handle
        })
        .collect();

    RapierWorld {
        gravity: Vector::from_array(scene.gravity),
        params,
        pipeline: PhysicsPipeline::new(),
        islands: IslandManager::new(),
        broad_phase: DefaultBroadPhase::new(),
        narrow_phase: NarrowPhase::new(),
        bodies,
        colliders,
        impulse_joints: ImpulseJointSet::new(),
        multibody_joints: MultibodyJointSet::new(),
        soft_bodies: SoftBodySet::new(),
        ccd: CCDSolver::new(),
        boards,
        marbles,
        skipped_parts,
        pipeline_steps_per_step,
        steps: 0,
    }
}

/// The board's body: fixed, or kinematic velocity-based when it moves. Its mass properties
/// are a unit mass at its origin (its colliders are massless), so that rapier, which turns a
/// body about its centre of mass, turns it about the board's `position`.
fn board_body(b: &BoardDesc) -> RigidBody {
    let moving = b.velocity != [0.0; 3] || b.angular_velocity != [0.0; 3];
    let builder = if moving {
        RigidBodyBuilder::kinematic_velocity_based()
            .linvel(Vector::from_array(b.velocity))
            .angvel(Vector::from_array(b.angular_velocity))
    } else {
        RigidBodyBuilder::fixed()
    };
    builder
        .pose(pose(b.position, b.rotation))
        .additional_mass_properties(MassProperties::new(Vector::ZERO, 1.0, Vector::ONE))
        .build()
}

/// A rapier collider of a (non-compound) part shape; `None` for `Bowl`.
fn collider(shape: &ShapeDesc) -> Option<ColliderBuilder> {
    Some(match shape {
        ShapeDesc::Plane(_) => ColliderBuilder::new(SharedShape::halfspace(Vector::Y)),
        ShapeDesc::Cuboid {
            half_extents: [x, y, z],
        } => ColliderBuilder::cuboid(*x, *y, *z),
        ShapeDesc::TriMesh { vertices, indices } => ColliderBuilder::trimesh(
            vertices.iter().map(|v| Vector::from_array(*v)).collect(),
            indices.clone(),
        )
        .expect("a validated scene's mesh"),
        ShapeDesc::HeightField { heights, scale } => {
            // As bevy_marble builds it: row i along Z, column j along X; parry's Array2 is
            // column-major, element (i, j) at i + j·nrows.
            let (nrows, ncols) = (heights.len(), heights[0].len());
            let mut data = vec![0.0; nrows * ncols];
            for (i, row) in heights.iter().enumerate() {
                for (j, h) in row.iter().enumerate() {
                    data[i + j * nrows] = *h;
                }
            }
            ColliderBuilder::heightfield(
                Array2::new(nrows, ncols, data),
                Vector::from_array(*scale),
            )
        }
        ShapeDesc::Bowl { .. } => return None,
        ShapeDesc::Compound(_) => unreachable!("a validated scene has no nested compounds"),
    })
}

/// A pose from a position and an `[x, y, z, w]` quaternion (normalized).
fn pose(position: [f32; 3], rotation: [f32; 4]) -> Pose {
    let [x, y, z, w] = rotation;
    Pose::from_parts(
        Vector::from_array(position),
        Rotation::from_xyzw(x, y, z, w).normalize(),
    )
}
