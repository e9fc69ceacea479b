//! Scene files: RON or JSON, the same serde types, validated once on entry.
//!
//! Every field has a default except a board's `shape` and a marble's `position`; unknown
//! fields are errors. [`Scene::validate`] checks every value and names the offending field
//! path and value (`marbles[3].radius must be > 0, got -0.01`); nothing is clamped.

use std::path::Path;

use glam::{Quat, Vec3};
use parry3d::shape::{Cuboid, HalfSpace, HeightField, TriMesh};
use parry3d::utils::Array2;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::config::{Integrator, Preset, Sleep, StepConfig};
use crate::geometry::{BoardGeometry, PartShape};
use crate::validate::{MAX_BOARD_SPIN, MAX_COORDINATE, MAX_DT, MAX_GRAVITY, MAX_SPEED};

/// Why a scene could not be loaded or used. Each is the user's input at fault.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read the file: {0}")]
    Io(#[from] std::io::Error),
    /// The extension is neither `.ron` nor `.json`.
    #[error("unknown scene format {0:?}: use a .ron or .json file")]
    Format(String),
    /// Syntax errors, unknown fields, wrong types.
    #[error("{0}")]
    Parse(String),
    /// A value out of its range: `{field} must be {rule}, got {value}`.
    #[error("{field} must be {rule}, got {value}")]
    Invalid {
        /// Path of the field, e.g. `marbles[3].radius`.
        field: String,
        /// What it must be.
        rule: String,
        /// What it was.
        value: String,
    },
    /// A switch for physics this version does not model yet.
    #[error("{field}: {what} is not yet supported")]
    Unsupported {
        /// Path of the field.
        field: String,
        /// What is missing.
        what: String,
    },
}

/// A scene: step settings, boards and marbles (the contract's scene file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scene {
    /// m/s².
    pub gravity: [f32; 3],
    /// Seconds per step, > 0 and at most [`MAX_DT`] (1 s).
    pub dt: f32,
    /// Substeps per step, ≥ 1.
    pub substeps: u32,
    /// Time integrator.
    pub integrator: Integrator,
    /// A named speed-versus-accuracy setting (`Fast`, `Balanced`, `Precise`): sets the
    /// integrator, CCD and the substeps `dt` needs, which the scene must then leave at their
    /// defaults.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    /// Continuous collision.
    pub ccd: bool,
    /// Spin and friction at contacts (marbles roll).
    pub rolling: bool,
    /// Marble–marble collisions.
    pub marble_collisions: bool,
    /// Passes of the marble–marble contact solver per substep, ≥ 1 (default 10). An
    /// extension of the contract.
    #[serde(skip_serializing_if = "is_default_iterations")]
    pub solver_iterations: u32,
    /// Model the turning board by turning gravity instead (Neverball's way): the board
    /// stays still, gravity tilts back. Cheaper and approximate; see
    /// [`GravityTilt`](crate::config::GravityTilt). Where a board turns, every board must
    /// share its angular velocity and position (a board that does not turn cannot be
    /// modelled: in the turning frame it would turn), and the sensors not carried by a
    /// board turn with that frame too. An extension of the contract.
    #[serde(skip_serializing_if = "is_false")]
    pub tilt_as_gravity: bool,
    /// Collision-versus-contact threshold, m/s, ≥ 0.
    pub restitution_threshold: f32,
    /// Marbles whose touching group stays slower than this (m/s) for `sleep_time` fall
    /// asleep until something wakes them ([`crate::sleep`]); 0 (the default) never. ≥ 0. An
    /// extension of the contract.
    #[serde(skip_serializing_if = "is_zero")]
    pub sleep_speed: f32,
    /// Seconds a touching group must stay slower than `sleep_speed` before it sleeps, > 0
    /// (default 0.5). An extension of the contract.
    #[serde(skip_serializing_if = "is_default_sleep_time")]
    pub sleep_time: f32,
    /// Seconds `marble run` simulates without `--steps`, ≥ 0.
    pub duration: f32,
    /// Boards.
    pub boards: Vec<BoardDesc>,
    /// Marbles.
    pub marbles: Vec<MarbleDesc>,
    /// Sensor volumes (goals, holes): they report marbles entering and leaving and never
    /// touch them ([`crate::events`]). An extension of the contract.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<SensorDesc>,
}

impl Default for Scene {
    fn default() -> Self {
        let c = StepConfig::default();
        Scene {
            gravity: c.gravity.to_array(),
            dt: c.dt,
            substeps: c.substeps,
            integrator: c.integrator,
            preset: None,
            ccd: c.ccd,
            rolling: false,
            marble_collisions: false,
            solver_iterations: c.solver_iterations,
            tilt_as_gravity: false,
            restitution_threshold: c.restitution_threshold,
            sleep_speed: 0.0,
            sleep_time: DEFAULT_SLEEP_TIME,
            duration: 10.0,
            boards: Vec::new(),
            marbles: Vec::new(),
            sensors: Vec::new(),
        }
    }
}

/// A kinematic board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardDesc {
    /// Its shape.
    pub shape: ShapeDesc,
    /// World position of the board's origin, m.
    #[serde(default)]
    pub position: [f32; 3],
    /// Orientation quaternion `[x, y, z, w]`, normalized on load.
    #[serde(default = "identity_rotation")]
    pub rotation: [f32; 4],
    /// m/s.
    #[serde(default)]
    pub velocity: [f32; 3],
    /// rad/s, world frame, about `position`.
    #[serde(default)]
    pub angular_velocity: [f32; 3],
    /// In [0, 1].
    #[serde(default = "half")]
    pub restitution: f32,
    /// ≥ 0.
    #[serde(default = "half")]
    pub friction: f32,
    /// Rolling resistance, ≥ 0 (used when rolling is on).
    #[serde(default)]
    pub rolling_resistance: f32,
    /// Spin damping about the contact normal, ≥ 0 (used when rolling is on).
    #[serde(default)]
    pub spin_damping: f32,
}

/// A sensor volume: a [`Sensor`](crate::components::Sensor) entity named `name`, fixed in
/// the world or carried by a board ([`CarriedBy`](crate::components::CarriedBy)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorDesc {
    /// What the game calls it (a `Name`): `"goal"`, `"hole"`, …
    #[serde(default)]
    pub name: String,
    /// Its volume (any board shape).
    pub shape: ShapeDesc,
    /// The index of the board that carries it, if any; its pose is then in that board's
    /// frame and it moves with the board.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board: Option<usize>,
    /// Position, m: world frame, or the board's frame when `board` is given.
    #[serde(default)]
    pub position: [f32; 3],
    /// Orientation `[x, y, z, w]`, normalized on load (world or board frame, as above).
    #[serde(default = "identity_rotation")]
    pub rotation: [f32; 4],
}

/// A marble.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarbleDesc {
    /// Centre, m.
    pub position: [f32; 3],
    /// m/s.
    #[serde(default)]
    pub velocity: [f32; 3],
    /// rad/s (used when rolling is on).
    #[serde(default)]
    pub angular_velocity: [f32; 3],
    /// m, > 0.
    #[serde(default = "default_radius")]
    pub radius: f32,
    /// kg, > 0; default: glass (2500 kg/m³) of this radius.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f32>,
    /// In [0, 1].
    #[serde(default = "half")]
    pub restitution: f32,
    /// ≥ 0.
    #[serde(default = "half")]
    pub friction: f32,
    /// Rolling resistance, ≥ 0 (used when rolling is on).
    #[serde(default)]
    pub rolling_resistance: f32,
    /// Spin damping about the contact normal, ≥ 0 (used when rolling is on).
    #[serde(default)]
    pub spin_damping: f32,
}

impl MarbleDesc {
    /// A default marble (8 mm glass) at `position`.
    pub fn at(position: [f32; 3]) -> Self {
        MarbleDesc {
            position,
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
            radius: default_radius(),
            mass: None,
            restitution: 0.5,
            friction: 0.5,
            rolling_resistance: 0.0,
            spin_damping: 0.0,
        }
    }
}

impl BoardDesc {
    /// A static board of the given shape at the origin, default materials.
    pub fn new(shape: ShapeDesc) -> Self {
        BoardDesc {
            shape,
            position: [0.0; 3],
            rotation: identity_rotation(),
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
            restitution: 0.5,
            friction: 0.5,
            rolling_resistance: 0.0,
            spin_damping: 0.0,
        }
    }
}

/// The fields of `Plane` (none). In RON write `Plane(())`, in JSON `{"Plane": {}}`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneDesc {}

/// A board shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ShapeDesc {
    /// The half-space below the local plane y = 0 (normal +Y).
    Plane(PlaneDesc),
    /// A box centred on the board's origin.
    Cuboid {
        /// Half sizes, m, each > 0.
        half_extents: [f32; 3],
    },
    /// A triangle mesh; both faces collide.
    TriMesh {
        /// Vertices, board frame, m.
        vertices: Vec<[f32; 3]>,
        /// Triangles as vertex indices.
        indices: Vec<[u32; 3]>,
    },
    /// A height field: row i runs along Z, column j along X; centred on the origin,
    /// spanning `scale.x` × `scale.z`, heights multiplied by `scale.y`.
    HeightField {
        /// `heights[i][j]`, at least 2 × 2, rectangular.
        heights: Vec<Vec<f32>>,
        /// Size, m, each > 0.
        scale: [f32; 3],
    },
    /// Parts posed in the board's frame; parts are not compounds.
    Compound(Vec<PartDesc>),
    /// A spherical bowl: the lower half (y ≤ 0) of a sphere of this radius about the
    /// board's origin, a surface (both faces collide). An extension of the contract.
    Bowl {
        /// m, > 0.
        radius: f32,
    },
}

/// A part of a compound board.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartDesc {
    /// Its shape (not a compound).
    pub shape: ShapeDesc,
    /// Position in the board frame, m.
    #[serde(default)]
    pub position: [f32; 3],
    /// Orientation in the board frame `[x, y, z, w]`, normalized on load.
    #[serde(default = "identity_rotation")]
    pub rotation: [f32; 4],
}

fn is_default_iterations(n: &u32) -> bool {
    *n == StepConfig::default().solver_iterations
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// Default of [`Scene::sleep_time`], s.
const DEFAULT_SLEEP_TIME: f32 = 0.5;

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

fn is_default_sleep_time(x: &f32) -> bool {
    *x == DEFAULT_SLEEP_TIME
}

fn identity_rotation() -> [f32; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

fn half() -> f32 {
    0.5
}

fn default_radius() -> f32 {
    crate::components::DEFAULT_RADIUS
}

impl Scene {
    /// Reads a scene file; the extension (`.ron`, `.json`) chooses the format. Parses and
    /// validates.
    pub fn from_path(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        let path = path.as_ref();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let format = match ext.as_deref() {
            Some("ron") => "ron",
            Some("json") => "json",
            _ => return Err(SceneError::Format(path.display().to_string())),
        };
        let text = std::fs::read_to_string(path)?;
        if format == "ron" {
            Scene::from_ron_str(&text)
        } else {
            Scene::from_json_str(&text)
        }
    }

    /// Parses and validates a RON scene.
    pub fn from_ron_str(text: &str) -> Result<Scene, SceneError> {
        // `mass: 0.01` rather than `mass: Some(0.01)`.
        let options = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME);
        let mut de = ron::Deserializer::from_str_with_options(text, &options)
            .map_err(|e| SceneError::Parse(e.to_string()))?;
        // Through `serde_path_to_error`, so that a value of the wrong type or out of its
        // type's range is named by its field path, and by the text it was at.
        let scene: Scene = match serde_path_to_error::deserialize(&mut de) {
            Ok(scene) => scene,
            Err(e) => {
                let path = e.path().to_string();
                let spanned = de.span_error(e.into_inner());
                let at = span_text(text, &spanned.span)
                    .map(|t| format!(", got {t}"))
                    .unwrap_or_default();
                let message = format!("{}{at} ({})", spanned.code, spanned.span);
                return Err(parse_error(&path, message));
            }
        };
        de.end()
            .map_err(|e| SceneError::Parse(de.span_error(e).to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// Parses and validates a JSON scene.
    pub fn from_json_str(text: &str) -> Result<Scene, SceneError> {
        let mut de = serde_json::Deserializer::from_str(text);
        let scene: Scene = serde_path_to_error::deserialize(&mut de)
            .map_err(|e| parse_error(&e.path().to_string(), e.into_inner().to_string()))?;
        de.end().map_err(|e| SceneError::Parse(e.to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// The scene as pretty RON.
    pub fn to_ron_string(&self) -> String {
        let config = ron::ser::PrettyConfig::default()
            .extensions(ron::extensions::Extensions::IMPLICIT_SOME);
        ron::ser::to_string_pretty(self, config).expect("scenes always serialize")
    }

    /// The scene as pretty JSON.
    pub fn to_json_string(&self) -> String {
        serde_json::to_string_pretty(self).expect("scenes always serialize")
    }

    /// Checks every value; the first offence is returned with its field path.
    pub fn validate(&self) -> Result<(), SceneError> {
        in_range("gravity", self.gravity, MAX_GRAVITY, GRAVITY_RANGE)?;
        positive("dt", self.dt)?;
        if self.dt > MAX_DT {
            return invalid("dt", "at most 1 s", self.dt);
        }
        if self.substeps < 1 {
            return invalid("substeps", ">= 1", self.substeps);
        }
        non_negative("restitution_threshold", self.restitution_threshold)?;
        if let Some(preset) = self.preset {
            let defaults = Scene::default();
            let conflict = if self.integrator != defaults.integrator {
                Some(("integrator", format!("{:?}", self.integrator)))
            } else if self.substeps != defaults.substeps {
                Some(("substeps", self.substeps.to_string()))
            } else if self.ccd != defaults.ccd {
                Some(("ccd", self.ccd.to_string()))
            } else {
                None
            };
            if let Some((field, value)) = conflict {
                return invalid(
                    field,
                    &format!("left out when preset {preset:?} sets it"),
                    value,
                );
            }
        }
        non_negative("duration", self.duration)?;
        non_negative("sleep_speed", self.sleep_speed)?;
        positive("sleep_time", self.sleep_time)?;
        if self.solver_iterations == 0 {
            return invalid("solver_iterations", ">= 1", self.solver_iterations);
        }
        for (i, b) in self.boards.iter().enumerate() {
            let f = |name: &str| format!("boards[{i}].{name}");
            validate_shape(&f("shape"), &b.shape, true)?;
            in_range(&f("position"), b.position, MAX_COORDINATE, POSITION_RANGE)?;
            rotation(&f("rotation"), b.rotation)?;
            in_range(&f("velocity"), b.velocity, MAX_SPEED, SPEED_RANGE)?;
            in_range(
                &f("angular_velocity"),
                b.angular_velocity,
                MAX_BOARD_SPIN,
                BOARD_SPIN_RANGE,
            )?;
            unit_interval(&f("restitution"), b.restitution)?;
            non_negative(&f("friction"), b.friction)?;
            non_negative(&f("rolling_resistance"), b.rolling_resistance)?;
            non_negative(&f("spin_damping"), b.spin_damping)?;
        }
        // The engine models the turning board in its own frame, where every board stands
        // still: a board that does not turn would turn with that frame.
        if self.tilt_as_gravity
            && let Some(first) = self.boards.iter().find(|b| b.angular_velocity != [0.0; 3])
            && let Some((i, other)) = self.boards.iter().enumerate().find(|(_, b)| {
                b.angular_velocity != first.angular_velocity || b.position != first.position
            })
        {
            return invalid(
                &format!("boards[{i}].angular_velocity"),
                "the same angular velocity and position as the first turning board when \
                 tilt_as_gravity is on (every board turns with it)",
                format!("{:?} about {:?}", other.angular_velocity, other.position),
            );
        }
        for (i, m) in self.marbles.iter().enumerate() {
            // A million marbles are checked without formatting a field name.
            let f = |name: &'static str| Lazy(move || format!("marbles[{i}].{name}"));
            in_range(f("position"), m.position, MAX_COORDINATE, POSITION_RANGE)?;
            in_range(f("velocity"), m.velocity, MAX_SPEED, SPEED_RANGE)?;
            finite3(f("angular_velocity"), m.angular_velocity)?;
            positive(f("radius"), m.radius)?;
            if let Some(mass) = m.mass {
                positive(f("mass"), mass)?;
                if !(1.0 / mass).is_finite() {
                    return invalid(f("mass"), "large enough to have a finite inverse", mass);
                }
            } else if !crate::components::Mass::glass_mass(m.radius).is_normal() {
                return invalid(
                    f("radius"),
                    "small and large enough for a finite, non-zero glass mass (or give mass)",
                    m.radius,
                );
            }
            unit_interval(f("restitution"), m.restitution)?;
            non_negative(f("friction"), m.friction)?;
            non_negative(f("rolling_resistance"), m.rolling_resistance)?;
            non_negative(f("spin_damping"), m.spin_damping)?;
        }
        for (i, s) in self.sensors.iter().enumerate() {
            let f = |name: &str| format!("sensors[{i}].{name}");
            validate_shape(&f("shape"), &s.shape, true)?;
            in_range(&f("position"), s.position, MAX_COORDINATE, POSITION_RANGE)?;
            rotation(&f("rotation"), s.rotation)?;
            if let Some(b) = s.board
                && b >= self.boards.len()
            {
                return invalid(
                    &f("board"),
                    &format!("the index of one of the {} boards", self.boards.len()),
                    b,
                );
            }
        }
        Ok(())
    }

    /// Settings that are valid but measured to misbehave (see `marble tradeoff`), each as
    /// one line of advice. The CLI prints them as warnings.
    pub fn warnings(&self) -> Vec<String> {
        let config = self.step_config();
        let mut out = Vec::new();
        if !config.ccd {
            let r = self
                .marbles
                .iter()
                .map(|m| m.radius)
                .fold(f32::INFINITY, f32::min);
            let speed = if r.is_finite() {
                format!(" ({} m/s for the smallest marble)", r / self.dt)
            } else {
                String::new()
            };
            out.push(format!(
                "ccd is off: marbles faster than radius/dt{speed} can pass through thin \
                 boards, and bounces lose height (15% by the fifth bounce at 1/60 s); \
                 `ccd: true` measured no slower"
            ));
            if config.integrator == Integrator::ExplicitEuler {
                out.push(
                    "ExplicitEuler without ccd gains energy at every bounce (an elastic \
                     bounce at 1/60 s ends a minute 2.6 times as high); use VelocityVerlet, \
                     which costs the same"
                        .into(),
                );
            }
        }
        out
    }

    /// The step settings of this scene (its preset applied, if any).
    pub fn step_config(&self) -> StepConfig {
        let mut config = StepConfig {
            gravity: Vec3::from_array(self.gravity),
            dt: self.dt,
            substeps: self.substeps,
            integrator: self.integrator,
            ccd: self.ccd,
            restitution_threshold: self.restitution_threshold,
            rolling: self.rolling,
            marble_collisions: self.marble_collisions,
            solver_iterations: self.solver_iterations,
            sleep: (self.sleep_speed > 0.0).then_some(Sleep {
                speed: self.sleep_speed,
                time: self.sleep_time,
            }),
            ..StepConfig::default()
        };
        if let Some(preset) = self.preset {
            preset.apply(&mut config);
        }
        config
    }

    /// Number of steps `marble run` takes without `--steps`: `duration / dt`, rounded.
    pub fn default_steps(&self) -> u64 {
        (self.duration as f64 / self.dt as f64).round() as u64
    }
}

impl ShapeDesc {
    /// Builds the parry3d geometry. The shape must have passed validation.
    pub fn build(&self) -> BoardGeometry {
        match self {
            ShapeDesc::Compound(parts) => BoardGeometry::compound(
                parts
                    .iter()
                    .map(|p| {
                        (
                            Vec3::from_array(p.position),
                            quat(p.rotation),
                            p.shape.build_part(),
                        )
                    })
                    .collect(),
            ),
            other => BoardGeometry::single(other.build_part()),
        }
    }

    fn build_part(&self) -> PartShape {
        match self {
            ShapeDesc::Plane(_) => PartShape::HalfSpace(HalfSpace::new(Vec3::Y)),
            ShapeDesc::Cuboid { half_extents } => {
                PartShape::Cuboid(Cuboid::new(Vec3::from_array(*half_extents)))
            }
            ShapeDesc::TriMesh { vertices, indices } => PartShape::TriMesh(Box::new(
                TriMesh::new(
                    vertices.iter().map(|v| Vec3::from_array(*v)).collect(),
                    indices.clone(),
                )
                .expect("validated mesh"),
            )),
            ShapeDesc::HeightField { heights, scale } => {
                let nrows = heights.len();
                let ncols = heights[0].len();
                // parry's Array2 is column-major: element (i, j) at i + j·nrows.
                let mut data = vec![0.0; nrows * ncols];
                for (i, row) in heights.iter().enumerate() {
                    for (j, h) in row.iter().enumerate() {
                        data[i + j * nrows] = *h;
                    }
                }
                PartShape::HeightField(Box::new(HeightField::new(
                    Array2::new(nrows, ncols, data),
                    Vec3::from_array(*scale),
                )))
            }
            ShapeDesc::Bowl { radius } => PartShape::Bowl(*radius),
            ShapeDesc::Compound(_) => unreachable!("validation refuses nested compounds"),
        }
    }
}

/// A quaternion from `[x, y, z, w]`, normalized (in f64, so that components far from 1,
/// whose squares overflow or underflow f32, normalize too).
pub fn quat(q: [f32; 4]) -> Quat {
    let n = norm64(q);
    Quat::from_array(q.map(|x| (f64::from(x) / n) as f32)).normalize()
}

pub(crate) fn validate_shape(field: &str, shape: &ShapeDesc, top: bool) -> Result<(), SceneError> {
    match shape {
        ShapeDesc::Plane(_) => Ok(()),
        ShapeDesc::Bowl { radius } => positive(&format!("{field}.Bowl.radius"), *radius),
        ShapeDesc::Cuboid { half_extents } => {
            for (k, h) in ["x", "y", "z"].iter().zip(half_extents) {
                positive(&format!("{field}.Cuboid.half_extents.{k}"), *h)?;
            }
            Ok(())
        }
        ShapeDesc::TriMesh { vertices, indices } => {
            if indices.is_empty() {
                return invalid(&format!("{field}.TriMesh.indices"), "non-empty", "[]");
            }
            for (i, v) in vertices.iter().enumerate() {
                in_range(
                    &format!("{field}.TriMesh.vertices[{i}]"),
                    *v,
                    MAX_COORDINATE,
                    POSITION_RANGE,
                )?;
            }
            for (i, tri) in indices.iter().enumerate() {
                for (k, &ix) in tri.iter().enumerate() {
                    if ix as usize >= vertices.len() {
                        return invalid(
                            &format!("{field}.TriMesh.indices[{i}][{k}]"),
                            &format!("< {} (the number of vertices)", vertices.len()),
                            ix,
                        );
                    }
                }
                let [a, b, c] = tri.map(|ix| Vec3::from_array(vertices[ix as usize]));
                let area = (b - a).cross(c - a).length_squared();
                if area.is_nan() || area <= 0.0 {
                    return invalid(
                        &format!("{field}.TriMesh.indices[{i}]"),
                        "a triangle of non-zero area",
                        format!("{tri:?}"),
                    );
                }
            }
            Ok(())
        }
        ShapeDesc::HeightField { heights, scale } => {
            if heights.len() < 2 {
                return invalid(
                    &format!("{field}.HeightField.heights"),
                    "at least 2 rows",
                    heights.len(),
                );
            }
            let ncols = heights[0].len();
            if ncols < 2 {
                return invalid(
                    &format!("{field}.HeightField.heights[0]"),
                    "at least 2 columns",
                    ncols,
                );
            }
            for (i, row) in heights.iter().enumerate() {
                if row.len() != ncols {
                    return invalid(
                        &format!("{field}.HeightField.heights[{i}]"),
                        &format!("{ncols} long like row 0"),
                        row.len(),
                    );
                }
                for (j, h) in row.iter().enumerate() {
                    finite(&format!("{field}.HeightField.heights[{i}][{j}]"), *h)?;
                }
            }
            for (k, s) in ["x", "y", "z"].iter().zip(scale) {
                positive(&format!("{field}.HeightField.scale.{k}"), *s)?;
            }
            Ok(())
        }
        ShapeDesc::Compound(parts) => {
            if !top {
                return invalid(
                    field,
                    "not a Compound (parts are not compounds)",
                    "Compound",
                );
            }
            if parts.is_empty() {
                return invalid(&format!("{field}.Compound"), "non-empty", "[]");
            }
            for (i, p) in parts.iter().enumerate() {
                let f = format!("{field}.Compound[{i}]");
                validate_shape(&format!("{f}.shape"), &p.shape, false)?;
                in_range(
                    &format!("{f}.position"),
                    p.position,
                    MAX_COORDINATE,
                    POSITION_RANGE,
                )?;
                rotation(&format!("{f}.rotation"), p.rotation)?;
            }
            Ok(())
        }
    }
}

/// A field's name in an error message, built only when there is an error.
trait FieldName {
    fn name(&self) -> String;
}

impl FieldName for &str {
    fn name(&self) -> String {
        (*self).to_string()
    }
}

impl FieldName for &String {
    fn name(&self) -> String {
        (*self).clone()
    }
}

/// A field name formatted on demand.
struct Lazy<F>(F);

impl<F: Fn() -> String> FieldName for Lazy<F> {
    fn name(&self) -> String {
        (self.0)()
    }
}

/// A parse error at field `path` (`serde_path_to_error`'s: `.` for the whole scene).
fn parse_error(path: &str, message: String) -> SceneError {
    match path {
        "." | "" => SceneError::Parse(message),
        path => SceneError::Parse(format!("{path}: {message}")),
    }
}

/// The text of `text` that `span` covers (RON's 1-based lines and columns of characters),
/// or, for a span of at most one character (where the parser stopped), the value there (up
/// to the next `,`, bracket or line end); trimmed, `None` where there is none.
fn span_text<'a>(text: &'a str, span: &ron::error::Span) -> Option<&'a str> {
    let offset = |p: &ron::error::Position| {
        let line_start: usize = text
            .split_inclusive('\n')
            .take(p.line.checked_sub(1)?)
            .map(str::len)
            .sum();
        let line = &text[line_start..];
        let col = line
            .char_indices()
            .nth(p.col.checked_sub(1)?)
            .map_or(line.len(), |(i, _)| i);
        Some(line_start + col)
    };
    let (start, end) = (offset(&span.start)?, offset(&span.end)?);
    let end = if text.get(start..end)?.chars().count() <= 1 {
        let rest = &text[start..];
        start + rest.find([',', ')', ']', '}', '\n']).unwrap_or(rest.len())
    } else {
        end
    };
    let t = text.get(start..end)?.trim();
    (!t.is_empty()).then_some(t)
}

fn invalid<T>(
    field: impl FieldName,
    rule: &str,
    value: impl std::fmt::Display,
) -> Result<T, SceneError> {
    Err(SceneError::Invalid {
        field: field.name(),
        rule: rule.to_string(),
        value: value.to_string(),
    })
}

fn finite(field: impl FieldName, x: f32) -> Result<(), SceneError> {
    if x.is_finite() {
        Ok(())
    } else {
        invalid(field, "finite", x)
    }
}

/// What [`in_range`] asks of a position and of a velocity (the supported range of
/// [`crate::validate`]).
const POSITION_RANGE: &str = "within 1e6 m of the origin in each coordinate";
const SPEED_RANGE: &str = "within 1e5 m/s in each coordinate";
const BOARD_SPIN_RANGE: &str = "within 1e4 rad/s in each coordinate";
const GRAVITY_RANGE: &str = "within 1e4 m/s² in each coordinate";

/// Finite, with every coordinate within `max`.
fn in_range(field: impl FieldName, v: [f32; 3], max: f32, rule: &str) -> Result<(), SceneError> {
    if !v.iter().all(|x| x.is_finite()) {
        invalid(field, "finite", format!("{v:?}"))
    } else if v.iter().all(|x| x.abs() <= max) {
        Ok(())
    } else {
        invalid(field, rule, format!("{v:?}"))
    }
}

fn finite3(field: impl FieldName, v: [f32; 3]) -> Result<(), SceneError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        invalid(field, "finite", format!("{v:?}"))
    }
}

fn positive(field: impl FieldName, x: f32) -> Result<(), SceneError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        invalid(field, "> 0", x)
    }
}

fn non_negative(field: impl FieldName, x: f32) -> Result<(), SceneError> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        invalid(field, ">= 0", x)
    }
}

fn unit_interval(field: impl FieldName, x: f32) -> Result<(), SceneError> {
    if (0.0..=1.0).contains(&x) {
        Ok(())
    } else {
        invalid(field, "in [0, 1]", x)
    }
}

fn rotation(field: &str, q: [f32; 4]) -> Result<(), SceneError> {
    if !q.iter().all(|x| x.is_finite()) {
        return invalid(field, "finite", format!("{q:?}"));
    }
    // Its length in f64: a quaternion with a component past 1e19 (whose square overflows
    // f32) or below 1e-19 (whose square underflows) is still a rotation.
    if norm64(q) <= 0.0 {
        return invalid(field, "a non-zero quaternion", format!("{q:?}"));
    }
    Ok(())
}

/// The length of `q`, in f64.
fn norm64(q: [f32; 4]) -> f64 {
    q.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt()
}

/// The fuzz harness of `fuzz/`'s corpus regression test: `data` as a scene file in both
/// formats, [`fuzz_scene_ron`] then [`fuzz_scene_json`].
#[doc(hidden)]
pub fn fuzz_scene_file(data: &[u8]) {
    fuzz_scene_ron(data);
    fuzz_scene_json(data);
}

/// The fuzz harness of `fuzz/`'s target `scene_ron`: `data` as a RON scene file is either
/// refused (not UTF-8, or a [`SceneError`] with a message) or gives a scene that builds and
/// steps 30 steps, after which every marble not quarantined has a finite position and
/// velocity. Panics on a finding. Scenes that are valid but costly by design (more than 64
/// marbles or 16 boards, more than 16 substeps) are skipped after parsing, so that the
/// fuzzer spends its time on inputs rather than on long runs.
#[doc(hidden)]
pub fn fuzz_scene_ron(data: &[u8]) {
    fuzz_parsed(data, Scene::from_ron_str);
}

/// The fuzz harness of `fuzz/`'s target `scene_json`: as [`fuzz_scene_ron`], for JSON.
#[doc(hidden)]
pub fn fuzz_scene_json(data: &[u8]) {
    fuzz_parsed(data, Scene::from_json_str);
}

fn fuzz_parsed(data: &[u8], parse: fn(&str) -> Result<Scene, SceneError>) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match parse(text) {
        Ok(scene) => fuzz_steps(&scene),
        Err(e) => assert!(!e.to_string().is_empty(), "an error without a message"),
    }
}

/// The stepping half of the fuzz harnesses.
fn fuzz_steps(scene: &Scene) {
    if scene.marbles.len() > 64 || scene.boards.len() > 16 || scene.substeps > 16 {
        return;
    }
    let Ok(mut sim) = crate::simulation::Simulation::from_scene(scene) else {
        return;
    };
    for _ in 0..30 {
        sim.step();
    }
    let quarantined = sim.quarantined();
    for i in 0..scene.marbles.len() {
        if quarantined.contains(&i) {
            continue;
        }
        let (x, v) = sim.marble_state(i);
        assert!(
            x.is_finite() && v.is_finite(),
            "marble {i} left finite values without being quarantined: {x} {v}"
        );
    }
}
