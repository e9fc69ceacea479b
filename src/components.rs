//! Components carried by marbles and boards.
//!
//! A marble is an entity with [`Marble`]; its `#[require]` list brings every other
//! component it needs with a documented default, so `commands.spawn((Marble,
//! Position(p)))` is a complete 8 mm glass marble. A board is an entity with [`Board`]
//! and a [`Collider`]; boards are kinematic: they move marbles, marbles never move them.
//!
//! All quantities are SI: metres, seconds, kilograms, radians.

use bevy_ecs::prelude::*;
use bevy_ecs::query::QueryData;
#[cfg(feature = "bevy")]
use bevy_ecs::reflect::ReflectComponent;
use glam::{Quat, Vec3};

use crate::geometry::BoardGeometry;
use crate::scene::{SceneError, ShapeDesc};

/// Default marble radius: 8 mm, a common glass marble.
pub const DEFAULT_RADIUS: f32 = 0.008;
/// Density of glass, kg/m³, used for the default marble mass.
pub const GLASS_DENSITY: f32 = 2500.0;

macro_rules! vec3_newtype {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
        #[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
        pub struct $name(pub Vec3);

        impl core::ops::Deref for $name {
            type Target = Vec3;
            fn deref(&self) -> &Vec3 {
                &self.0
            }
        }

        impl core::ops::DerefMut for $name {
            fn deref_mut(&mut self) -> &mut Vec3 {
                &mut self.0
            }
        }
    };
}

vec3_newtype!(
    /// World position, metres. For a marble, its centre; for a board, the origin of its
    /// local frame (and its centre of rotation).
    Position
);
vec3_newtype!(
    /// Linear velocity, m/s. Marbles: integrated from forces. Boards: kinematic, constant
    /// unless a program changes it.
    Velocity
);
vec3_newtype!(
    /// Force on a marble, newtons, accumulated by user systems before the physics step and
    /// cleared after the step (all substeps) has integrated it (in an app, also at each
    /// fixed step the paused physics does not take). Gravity is not stored here: it comes
    /// from [`crate::config::StepConfig::gravity`].
    Force
);
vec3_newtype!(
    /// Angular velocity, rad/s, world frame. A board turns about its [`Position`]: its
    /// surface point `p` moves at `velocity + angular_velocity × (p − position)`. A marble
    /// carries one only when rolling is modelled (with a [`Rotation`] for its orientation):
    /// it is the marble's spin, with the solid-sphere inertia `(2/5) m r²`.
    AngularVelocity
);
vec3_newtype!(
    /// Acceleration of a marble this step, m/s²: gravity plus `Force / mass`. Written by
    /// the force stage, read by integration and response; internal but readable.
    Acceleration
);

/// Orientation (unit quaternion, local → world) of a board, or of a marble that rolls.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Rotation(pub Quat);

impl Default for Rotation {
    fn default() -> Self {
        Rotation(Quat::IDENTITY)
    }
}

/// Marks a marble: a solid sphere moved by forces and contacts.
///
/// Spawned without a [`Position`], it starts at its `Transform`'s translation (with the
/// `bevy` feature), or at the origin.
#[derive(Component, Clone, Copy, Debug, Default)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
#[component(on_add = resolve_unset_pose, on_remove = crate::sleep::note_removed_sleeper)]
#[require(
    Position = Position::UNSET,
    Velocity,
    Force,
    Acceleration,
    Radius,
    Mass,
    Restitution,
    Friction,
    StepStart,
    Contacts,
    MoreContacts,
    PositionCarry,
    crate::board_contact::NearPieces
)]
pub struct Marble;

/// The part of a marble's (or a moving board's) position that f32 could not hold: the
/// compensation term of Kahan summation, kept so that many small steps add up exactly. Far from the origin (at
/// 10 km an f32 resolves 1 mm) or at tiny steps (1e-6 s moves a marble a fraction of an
/// f32 ulp), plain accumulation would lose most of the motion. The position is
/// `Position − PositionCarry` to about an ulp of the carry; writing `Position` directly is
/// fine (the carry is at most an ulp of the old position).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct PositionCarry(pub Vec3);

/// `sum + delta` with Kahan's compensation `carry`: returns the new sum and carry. With
/// `compensated` false, plain f32 addition (the carry stays zero).
#[inline]
pub fn compensated_add(compensated: bool, sum: Vec3, carry: Vec3, delta: Vec3) -> (Vec3, Vec3) {
    if !compensated {
        return (sum + delta, Vec3::ZERO);
    }
    let y = delta - carry;
    let t = sum + y;
    (t, (t - sum) - y)
}

/// Marks a board: a kinematic body with a [`Collider`] shape.
///
/// Spawned without a [`Position`] or [`Rotation`], it takes its `Transform`'s translation
/// and rotation (with the `bevy` feature), or the origin and no rotation.
#[derive(Component, Clone, Copy, Debug, Default)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
#[component(on_add = resolve_unset_pose)]
#[require(
    Position = Position::UNSET,
    Rotation = Rotation::UNSET,
    Velocity,
    AngularVelocity,
    Restitution,
    Friction,
    PositionCarry
)]
pub struct Board;

/// Marks a sensor: a volume (its [`Collider`], at its pose) that marbles pass through
/// untouched. A marble enters it when its centre moves inside the volume and exits when
/// its centre leaves; the step reports both ([`crate::events`]). Goals, holes and
/// fall-out zones are sensors. A sensor's pose comes from its [`Position`] and
/// [`Rotation`], or, when spawned without them, from its `Transform`; it moves when the
/// program moves it, or with the board it is [`CarriedBy`].
///
/// A point is inside a cuboid, a bowl's sphere below its rim, a half-space (below its
/// plane), a height field (below its surface) or a closed triangle mesh (enclosed by it);
/// a compound sensor is the union of its parts.
///
/// Given to a [`Board`], it makes the board a sensor: marbles pass through it from the next
/// step on (those resting on it fall), while it moves as before; removed, the board holds
/// marbles again.
#[derive(Component, Clone, Copy, Debug, Default)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
#[component(on_add = resolve_unset_pose)]
#[require(Position = Position::UNSET, Rotation = Rotation::UNSET)]
pub struct Sensor;

/// A sensor carried by a board: at the end of every step, before marbles are checked
/// against it, the sensor's [`Position`] and [`Rotation`] become the board's pose composed
/// with this pose in the board's frame. The holes and the goal of a tilting labyrinth tilt
/// with it.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct CarriedBy {
    /// The board.
    pub board: Entity,
    /// The sensor's position in the board's frame, m.
    pub position: Vec3,
    /// The sensor's orientation in the board's frame.
    pub rotation: Quat,
}

/// Drives a board to a pose over the next physics step: during the step the board moves
/// with the constant linear and angular velocity (about its [`Position`]) that bring it
/// exactly to `position` and `rotation` at the step's end, so marbles on it are carried
/// and launched as by any moving board. At the step's end the board is placed exactly at
/// the pose, its [`Velocity`] and [`AngularVelocity`] are set to zero and the component
/// is removed: the board holds still there until a new `NextPose` (or velocity) is given.
/// Tilting a labyrinth from player input is one `NextPose` per fixed step.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct NextPose {
    /// Where the board's origin is at the step's end, world frame, m.
    pub position: Vec3,
    /// The board's orientation at the step's end.
    pub rotation: Quat,
}

impl NextPose {
    /// The constant linear and angular velocity (world frame, about the board's position)
    /// that take a board from `position` and `rotation` to this pose in `dt`, turning the
    /// shorter way round.
    pub fn motion(&self, position: Vec3, rotation: Quat, dt: f32) -> (Vec3, Vec3) {
        let mut turn = self.rotation * rotation.conjugate();
        if turn.w < 0.0 {
            turn = -turn;
        }
        ((self.position - position) / dt, turn.to_scaled_axis() / dt)
    }
}

/// The bits of the "not given" value of [`Position::UNSET`] and [`Rotation::UNSET`]: a
/// quiet NaN with a payload no arithmetic produces, so a NaN from a program is never
/// taken for it.
const UNSET_BITS: u32 = 0x7fc5_1a7e;

impl Position {
    /// The value `Marble`, `Board` and `Sensor` require when no `Position` is given,
    /// replaced as soon as the entity is spawned (see [`Marble`]); never seen by a stage.
    pub const UNSET: Position = Position(Vec3::splat(f32::from_bits(UNSET_BITS)));

    fn is_unset(&self) -> bool {
        self.0.x.to_bits() == UNSET_BITS
    }
}

impl Rotation {
    /// The value `Board` and `Sensor` require when no `Rotation` is given, replaced as soon
    /// as the entity is spawned (see [`Board`]); never seen by a stage.
    pub const UNSET: Rotation =
        Rotation(Quat::from_xyzw(f32::from_bits(UNSET_BITS), 0.0, 0.0, 1.0));

    fn is_unset(&self) -> bool {
        self.0.x.to_bits() == UNSET_BITS
    }
}

/// Hook of [`Marble`], [`Board`] and [`Sensor`]: a pose left unset takes the entity's
/// `Transform` (with the `bevy` feature) or the origin and no rotation. In an app with the
/// plugin, a `Transform` inserted or changed before the next step places the entity then
/// (`MarbleTransformPlugin`).
fn resolve_unset_pose(
    mut world: bevy_ecs::world::DeferredWorld,
    context: bevy_ecs::lifecycle::HookContext,
) {
    let entity = context.entity;
    let position_unset = world
        .get::<Position>(entity)
        .is_some_and(Position::is_unset);
    let rotation_unset = world
        .get::<Rotation>(entity)
        .is_some_and(Rotation::is_unset);
    if !position_unset && !rotation_unset {
        return;
    }
    #[cfg(feature = "bevy")]
    let (translation, rotation) = {
        let read = world
            .get::<bevy_transform::components::Transform>(entity)
            .map(|t| (t.translation, t.rotation));
        // A `Transform` inserted or changed later, before the next step, places it then.
        crate::plugin::note_spawned(&mut world, entity, (position_unset, rotation_unset), read);
        read.unwrap_or((Vec3::ZERO, Quat::IDENTITY))
    };
    #[cfg(not(feature = "bevy"))]
    let (translation, rotation) = (Vec3::ZERO, Quat::IDENTITY);
    if position_unset && let Some(mut position) = world.get_mut::<Position>(entity) {
        position.0 = translation;
    }
    if rotation_unset && let Some(mut r) = world.get_mut::<Rotation>(entity) {
        r.0 = rotation;
    }
}

/// A board's shape (parry3d shapes behind a shared pointer, cheap to clone).
#[derive(Component, Clone, Debug)]
pub struct Collider(pub std::sync::Arc<BoardGeometry>);

impl Collider {
    /// Wraps a geometry.
    pub fn new(geometry: BoardGeometry) -> Self {
        Collider(std::sync::Arc::new(geometry))
    }

    /// A shape the scene file can describe, checked as the scene file is (`collider.…`
    /// names the offending field).
    pub fn from_desc(desc: &ShapeDesc) -> Result<Self, SceneError> {
        crate::scene::validate_shape("collider", desc, true)?;
        Ok(Collider::new(desc.build()))
    }

    /// The half-space below the local plane y = 0 (outward normal +Y): a floor.
    pub fn plane() -> Self {
        Collider::new(ShapeDesc::Plane(crate::scene::PlaneDesc {}).build())
    }

    /// A solid box centred on the origin, with these half sizes (m, each > 0).
    pub fn cuboid(half_extents: Vec3) -> Result<Self, SceneError> {
        Collider::from_desc(&ShapeDesc::Cuboid {
            half_extents: half_extents.to_array(),
        })
    }

    /// A triangle mesh (both faces collide): vertices in the local frame (m) and triangles
    /// as vertex indices, each of non-zero area.
    pub fn trimesh(vertices: &[Vec3], indices: &[[u32; 3]]) -> Result<Self, SceneError> {
        Collider::from_desc(&ShapeDesc::TriMesh {
            vertices: vertices.iter().map(|v| v.to_array()).collect(),
            indices: indices.to_vec(),
        })
    }

    /// A height field centred on the origin: `heights[i][j]`, row i along Z and column j
    /// along X (at least 2 × 2, rectangular, finite), spanning `scale.x` × `scale.z` with
    /// heights multiplied by `scale.y` (each > 0).
    pub fn heightfield(heights: Vec<Vec<f32>>, scale: Vec3) -> Result<Self, SceneError> {
        Collider::from_desc(&ShapeDesc::HeightField {
            heights,
            scale: scale.to_array(),
        })
    }

    /// A spherical bowl: the lower half (y ≤ 0) of the sphere of this radius (m, > 0)
    /// about the origin, as a surface (both faces collide).
    pub fn bowl(radius: f32) -> Result<Self, SceneError> {
        Collider::from_desc(&ShapeDesc::Bowl { radius })
    }

    /// Shapes posed in the collider's frame (`(position, rotation, shape)`; no part a
    /// compound): a board of several parts, such as a floor with walls.
    pub fn compound(parts: Vec<(Vec3, Quat, ShapeDesc)>) -> Result<Self, SceneError> {
        Collider::from_desc(&ShapeDesc::Compound(
            parts
                .into_iter()
                .map(|(position, rotation, shape)| crate::scene::PartDesc {
                    shape,
                    position: position.to_array(),
                    rotation: rotation.to_array(),
                })
                .collect(),
        ))
    }
}

/// Marble radius, metres, > 0. Default 8 mm.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Radius(pub f32);

impl Default for Radius {
    fn default() -> Self {
        Radius(DEFAULT_RADIUS)
    }
}

/// Marble mass, kg, with its inverse stored beside it (the response divides by mass).
///
/// The default is a glass sphere of the default radius (5.36 g). Spawn a marble of another
/// radius with [`Mass::glass`] or [`Mass::new`].
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Mass {
    mass: f32,
    inverse: f32,
}

impl Mass {
    /// A mass of `mass` kg. Panics in debug builds unless `mass` is finite and > 0 with a
    /// finite inverse (scene loading validates it first and reports an error instead).
    pub fn new(mass: f32) -> Self {
        debug_assert!(
            mass.is_finite() && mass > 0.0 && (1.0 / mass).is_finite(),
            "mass must be > 0 with a finite inverse, got {mass}"
        );
        Mass {
            mass,
            inverse: 1.0 / mass,
        }
    }

    /// The mass of a solid glass sphere (2500 kg/m³) of the given radius.
    pub fn glass(radius: f32) -> Self {
        Mass::new(Mass::glass_mass(radius))
    }

    /// The mass, kg, of a solid glass sphere (2500 kg/m³) of the given radius.
    pub fn glass_mass(radius: f32) -> f32 {
        GLASS_DENSITY * 4.0 / 3.0 * core::f32::consts::PI * radius.powi(3)
    }

    /// Mass, kg.
    pub fn get(&self) -> f32 {
        self.mass
    }

    /// Inverse mass, 1/kg.
    pub fn inverse(&self) -> f32 {
        self.inverse
    }
}

impl Default for Mass {
    fn default() -> Self {
        Mass::glass(DEFAULT_RADIUS)
    }
}

/// Coefficient of restitution in [0, 1]: the ratio of separating to approaching normal
/// speed in a collision. A pair uses the average of its two parties' values. Default 0.5.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Restitution(pub f32);

impl Default for Restitution {
    fn default() -> Self {
        Restitution(0.5)
    }
}

/// Rolling resistance coefficient ≥ 0 (dimensionless), used when rolling is modelled: a
/// torque `c·N·r` against the rolling spin, so a rolling marble decelerates at
/// `(5/7)·c·g` on level ground. A pair uses the average of its two parties' values.
/// Default 0 (optional: absent means 0).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct RollingResistance(pub f32);

/// Spin damping coefficient ≥ 0 (dimensionless), used when rolling is modelled: a torque
/// `k·N·r` against the spin about the contact normal. A pair uses the average of its two
/// parties' values. Default 0 (optional: absent means 0).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct SpinDamping(pub f32);

/// Coulomb friction coefficient ≥ 0, used when rolling is modelled. A pair uses the
/// average of its two parties' values. Default 0.5.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Friction(pub f32);

impl Default for Friction {
    fn default() -> Self {
        Friction(0.5)
    }
}

/// A marble's state at the start of the current substep, before forces were integrated.
/// Written by the detection stage as it starts (after the pair contact stage's changes);
/// detection measures closing speeds against it.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStart {
    /// Centre at the start of the substep, m.
    pub position: Vec3,
    /// The position's [`PositionCarry`] at the start of the substep.
    pub carry: Vec3,
    /// Velocity at the start of the substep, before this step's forces, m/s.
    pub velocity: Vec3,
}

/// Whether a touching pair was an impact or a touch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ContactKind {
    /// Closing speed above `restitution_threshold`: the seed's equation (1) was applied.
    Collision,
    /// Touching, resting, or sliding: approaching normal velocity was removed (e = 0).
    #[default]
    Contact,
}

/// One marble–board contact found during the last substep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// The board touched.
    pub board: Entity,
    /// Contact point on the board's surface, world frame, m.
    pub point: Vec3,
    /// Unit normal out of the board's surface, towards the marble.
    pub normal: Vec3,
    /// Penetration depth, m (≤ 0 means a gap within the touching tolerance).
    pub depth: f32,
    /// Normal closing speed `(v_m − v_b(p))·n` when the contact was classified, m/s
    /// (negative: approaching).
    pub closing_speed: f32,
    /// Collision or contact.
    pub kind: ContactKind,
    /// When in the substep it was found, s from the substep's start.
    pub time: f32,
    /// Which convex piece of the board (internal identifier; stable within a substep).
    pub piece: crate::geometry::PieceId,
}

/// How many contacts a marble keeps per substep. A marble in a box corner touches three
/// boards; further contacts are still resolved, only not recorded.
pub const MAX_CONTACTS: usize = 4;

/// The board contacts of a marble during the last substep, as a component: how many, whether
/// any was a collision, and the first of them.
///
/// A marble on one piece, the commonest marble, has one contact, and every substep writes
/// it: the component holds that one (64 bytes), and the others a marble touching several
/// pieces had are kept apart, in [`MoreContacts`], which the stages visit only for such a
/// marble. The whole list: a [`BoardContacts`] query item (`Query<BoardContacts>`), or
/// [`Simulation::contacts`](crate::Simulation::contacts) headless.
#[derive(Component, Clone, Copy, Debug)]
pub struct Contacts {
    len: u8,
    collision: bool,
    /// What detection left for the response stage ([`Pending`], packed with
    /// `pending_time`).
    pending_kind: u8,
    /// The time of a [`Pending::Impact`], s.
    pending_time: f32,
    first: Contact,
}

impl Default for Contacts {
    fn default() -> Self {
        Contacts {
            len: 0,
            collision: false,
            pending_kind: PENDING_NONE,
            pending_time: 0.0,
            first: EMPTY_CONTACT,
        }
    }
}

impl Contacts {
    /// Number of recorded contacts (all of them, [`MoreContacts`]' included).
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// True when the marble touched nothing in the last substep.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when any recorded contact was a collision.
    pub fn has_collision(&self) -> bool {
        self.collision
    }

    /// The first recorded contact (the only one, for a marble on one piece).
    pub fn first(&self) -> Option<&Contact> {
        (self.len > 0).then_some(&self.first)
    }

    /// What detection left for the response stage.
    #[inline(always)]
    pub(crate) fn pending(&self) -> Pending {
        Pending::unpack(self.pending_kind, self.pending_time)
    }

    /// True when detection left nothing for the response stage.
    #[inline(always)]
    pub(crate) fn nothing_pending(&self) -> bool {
        self.pending_kind == PENDING_NONE
    }

    /// Forgets the recorded contacts and anything pending.
    pub(crate) fn clear(&mut self) {
        self.len = 0;
        self.collision = false;
        self.pending_kind = PENDING_NONE;
    }
}

/// The contacts of a marble beyond the first ([`Contacts`]), in the order recorded: a
/// column of their own, so that the stages visit it only for the marbles that touch more
/// than one piece. Read through [`BoardContacts`].
#[derive(Component, Clone, Copy, Debug)]
pub struct MoreContacts([Contact; MAX_CONTACTS - 1]);

impl Default for MoreContacts {
    fn default() -> Self {
        MoreContacts([EMPTY_CONTACT; MAX_CONTACTS - 1])
    }
}

/// A marble's whole board contact list, as a query item: `Query<BoardContacts>`.
#[derive(QueryData)]
pub struct BoardContacts {
    head: &'static Contacts,
    more: &'static MoreContacts,
}

impl BoardContactsItem<'_, '_> {
    /// The recorded contacts, the first first.
    pub fn iter(&self) -> impl Iterator<Item = &Contact> + '_ {
        contact_iter(self.head, self.more)
    }

    /// Number of recorded contacts.
    pub fn len(&self) -> usize {
        self.head.len()
    }

    /// True when the marble touched nothing in the last substep.
    pub fn is_empty(&self) -> bool {
        self.head.is_empty()
    }

    /// True when any recorded contact was a collision.
    pub fn has_collision(&self) -> bool {
        self.head.has_collision()
    }

    /// The list as a value.
    pub fn list(&self) -> ContactList {
        ContactList::load(self.head, self.more)
    }
}

/// The contacts `head` and `more` record, the first first.
#[inline]
pub(crate) fn contact_iter<'a>(
    head: &'a Contacts,
    more: &'a MoreContacts,
) -> impl Iterator<Item = &'a Contact> + 'a {
    let (first, rest) = contact_slices(head, more);
    first.iter().chain(rest)
}

/// The contacts `head` and `more` record as two slices, the first contact (none or one)
/// and the rest: for loops that visit them once each, without an iterator chain's branch
/// per item.
#[inline(always)]
pub(crate) fn contact_slices<'a>(
    head: &'a Contacts,
    more: &'a MoreContacts,
) -> (&'a [Contact], &'a [Contact]) {
    let len = head.len as usize;
    let first = std::slice::from_ref(&head.first);
    (&first[..len.min(1)], &more.0[..len.saturating_sub(1)])
}

/// A marble's board contacts as one value (fixed capacity, no allocation): what the
/// marble–board stages build a substep's contacts in, and what [`BoardContactsItem::list`]
/// and [`Simulation::contacts`](crate::Simulation::contacts) return.
#[derive(Clone, Copy, Debug)]
pub struct ContactList {
    list: [Contact; MAX_CONTACTS],
    len: u8,
    /// Set by detection when the response stage must resolve this marble.
    pub(crate) pending: Pending,
}

/// What detection left for the response stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) enum Pending {
    /// Free motion stands.
    #[default]
    None,
    /// Touches at the substep's start (recorded in the list); `complete` when no other
    /// piece was within reach (see `TouchList::is_complete`).
    Touching {
        /// Every piece within reach was recorded.
        complete: bool,
    },
    /// First impact along the free path at this time, s.
    Impact(f32),
    /// Overlap at the end of the free path (continuous collision off).
    Overlap,
}

// `Contacts::pending_kind`'s values, one for each [`Pending`].
const PENDING_NONE: u8 = 0;
const PENDING_TOUCHING: u8 = 1;
const PENDING_TOUCHING_COMPLETE: u8 = 2;
const PENDING_IMPACT: u8 = 3;
const PENDING_OVERLAP: u8 = 4;

impl Pending {
    /// As [`Contacts`] holds it: a kind (one of the `PENDING_` values) and an impact's time.
    #[inline(always)]
    fn pack(self) -> (u8, f32) {
        match self {
            Pending::None => (PENDING_NONE, 0.0),
            Pending::Touching { complete: false } => (PENDING_TOUCHING, 0.0),
            Pending::Touching { complete: true } => (PENDING_TOUCHING_COMPLETE, 0.0),
            Pending::Impact(tau) => (PENDING_IMPACT, tau),
            Pending::Overlap => (PENDING_OVERLAP, 0.0),
        }
    }

    /// The inverse of [`Pending::pack`].
    #[inline(always)]
    fn unpack(kind: u8, time: f32) -> Pending {
        match kind {
            PENDING_NONE => Pending::None,
            PENDING_TOUCHING => Pending::Touching { complete: false },
            PENDING_TOUCHING_COMPLETE => Pending::Touching { complete: true },
            PENDING_IMPACT => Pending::Impact(time),
            _ => Pending::Overlap,
        }
    }
}

/// Marks a marble whose position or velocity stopped being finite. Quarantined marbles are
/// skipped by every stage; nothing else is affected.
#[derive(Component, Clone, Copy, Debug, Default)]
#[cfg_attr(feature = "bevy", derive(bevy_reflect::Reflect), reflect(Component))]
pub struct Quarantined;

const EMPTY_CONTACT: Contact = Contact {
    board: Entity::PLACEHOLDER,
    point: Vec3::ZERO,
    normal: Vec3::Y,
    depth: 0.0,
    closing_speed: 0.0,
    kind: ContactKind::Contact,
    time: 0.0,
    piece: crate::geometry::PieceId::NONE,
};

impl Default for ContactList {
    fn default() -> Self {
        ContactList {
            list: [EMPTY_CONTACT; MAX_CONTACTS],
            len: 0,
            pending: Pending::None,
        }
    }
}

impl ContactList {
    /// The list `head` and `more` record, with what is pending.
    #[inline]
    pub(crate) fn load(head: &Contacts, more: &MoreContacts) -> ContactList {
        let mut list = ContactList::default();
        list.load_from(head, more);
        list
    }

    /// Makes this the list `head` and `more` record, with what is pending (reading
    /// `more` only when there is more than one contact).
    #[inline]
    pub(crate) fn load_from(&mut self, head: &Contacts, more: &MoreContacts) {
        let len = head.len as usize;
        self.len = head.len;
        self.pending = head.pending();
        if len > 0 {
            self.list[0] = head.first;
        }
        if len > 1 {
            self.list[1..len].copy_from_slice(&more.0[..len - 1]);
        }
    }

    /// Records this list, and what is pending, in `head` and `more` (writing `more` only
    /// when there is more than one contact).
    #[inline(always)]
    pub(crate) fn store(&self, head: &mut Contacts, more: &mut MoreContacts) {
        let len = self.len as usize;
        let (pending_kind, pending_time) = self.pending.pack();
        // The whole component in one write (the first contact's place is filled whatever
        // the count: the list keeps what it held there).
        *head = Contacts {
            len: self.len,
            collision: self.has_collision(),
            pending_kind,
            pending_time,
            first: self.list[0],
        };
        if len > 1 {
            more.0[..len - 1].copy_from_slice(&self.list[1..len]);
        }
    }

    /// The recorded contacts.
    pub fn as_slice(&self) -> &[Contact] {
        &self.list[..self.len as usize]
    }

    /// Iterates the recorded contacts.
    pub fn iter(&self) -> impl Iterator<Item = &Contact> {
        self.as_slice().iter()
    }

    /// Number of recorded contacts.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// True when the marble touched nothing in the last substep.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when any recorded contact was a collision.
    pub fn has_collision(&self) -> bool {
        self.iter().any(|c| c.kind == ContactKind::Collision)
    }

    pub(crate) fn clear(&mut self) {
        self.len = 0;
        self.pending = Pending::None;
    }

    /// Records a contact; when full, keeps the deepest ones. Always inlined: the caller
    /// builds the contact in its place (passed by reference, the 48-byte contact would be
    /// read back in wide loads from its narrow stores, a store-forwarding stall each).
    #[inline(always)]
    pub(crate) fn push(&mut self, contact: Contact) {
        if (self.len as usize) < MAX_CONTACTS {
            self.list[self.len as usize] = contact;
            self.len += 1;
            return;
        }
        let (shallowest, _) = self
            .list
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.depth.total_cmp(&b.1.depth))
            .expect("MAX_CONTACTS > 0");
        if self.list[shallowest].depth < contact.depth {
            self.list[shallowest] = contact;
        }
    }
}

/// Registers the engine's components and resources for reflection (inspectors, scenes).
#[cfg(feature = "bevy")]
pub(crate) fn register_types(app: &mut bevy_app::App) {
    app.register_type::<Position>()
        .register_type::<Velocity>()
        .register_type::<Force>()
        .register_type::<AngularVelocity>()
        .register_type::<Acceleration>()
        .register_type::<Rotation>()
        .register_type::<Marble>()
        .register_type::<Board>()
        .register_type::<Sensor>()
        .register_type::<CarriedBy>()
        .register_type::<NextPose>()
        .register_type::<Radius>()
        .register_type::<Mass>()
        .register_type::<Restitution>()
        .register_type::<RollingResistance>()
        .register_type::<SpinDamping>()
        .register_type::<Friction>()
        .register_type::<Quarantined>()
        .register_type::<crate::sleep::Sleeping>()
        .register_type::<crate::sleep::Drowsy>()
        .register_type::<crate::config::StepConfig>()
        .register_type::<crate::plugin::PhysicsClock>();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(depth: f32, kind: ContactKind) -> Contact {
        Contact {
            depth,
            kind,
            ..EMPTY_CONTACT
        }
    }

    /// What every marble-substep writes of a marble's contacts fits one 64-byte line's
    /// worth: the count, the collision flag, what is pending and the first contact.
    #[test]
    fn the_contacts_component_is_64_bytes() {
        assert_eq!(std::mem::size_of::<Contacts>(), 64);
    }

    /// A list stored in the two components and loaded back is the same list, in the same
    /// order, with the same pending state, for every count; `Contacts` alone tells the
    /// count, the first contact and whether any was a collision.
    #[test]
    fn contacts_round_trip_through_both_components() {
        let (mut head, mut more) = (Contacts::default(), MoreContacts::default());
        for n in 0..=MAX_CONTACTS {
            for pending in [
                Pending::None,
                Pending::Touching { complete: false },
                Pending::Touching { complete: true },
                Pending::Impact(0.0021),
                Pending::Overlap,
            ] {
                let mut list = ContactList::default();
                for k in 0..n {
                    let kind = if k == n - 1 && n > 1 {
                        ContactKind::Collision
                    } else {
                        ContactKind::Contact
                    };
                    list.push(contact(0.001 * (k + 1) as f32, kind));
                }
                list.pending = pending;
                list.store(&mut head, &mut more);
                let back = ContactList::load(&head, &more);
                assert_eq!(back.as_slice(), list.as_slice(), "{n} contacts");
                assert_eq!(back.pending, pending);
                assert_eq!(head.len(), n);
                assert_eq!(head.has_collision(), n > 1);
                assert_eq!(head.first(), list.as_slice().first());
                assert_eq!(head.nothing_pending(), pending == Pending::None);
                assert!(contact_iter(&head, &more).eq(list.iter()));
            }
        }
        head.clear();
        assert!(head.is_empty() && !head.has_collision() && head.nothing_pending());
    }
}
