//! The fuzz targets' shared half: raw scene text, or a scene built field by field from the
//! fuzzer's bytes (`arbitrary`) and written out as text, then through the engine's harness
//! (`bevy_marble::scene::fuzz_scene_ron` / `fuzz_scene_json`: parse, validate, 30 steps).
//!
//! Raw text mutated byte by byte rarely gets past the parser into a valid mesh or height
//! field; the built scenes are always well-formed text, with values drawn from a mix of
//! ordinary ranges and the edges of what validation accepts (zero, subnormals, the largest
//! coordinate and speed, NaN, infinities), indices in and out of range, ragged height rows
//! and nested compounds, so that the fuzzer's time goes into validation and stepping.

use arbitrary::{Result, Unstructured};
use bevy_marble::config::{Integrator, Preset};
use bevy_marble::scene::{
    BoardDesc, MarbleDesc, PartDesc, PlaneDesc, Scene, SensorDesc, ShapeDesc, fuzz_scene_json,
    fuzz_scene_ron,
};

/// Which scene-file format a target feeds.
#[derive(Clone, Copy, Debug)]
pub enum Format {
    /// RON.
    Ron,
    /// JSON.
    Json,
}

/// The first byte that selects a built scene; it is never the first byte of UTF-8 text, so
/// raw inputs (the kept `.ron` and `.json` seeds) are read as text whole.
pub const BUILT: u8 = 0xFF;

/// One fuzz input: raw text, or after [`BUILT`] a scene built from the remaining bytes.
pub fn run(format: Format, data: &[u8]) {
    match data.split_first() {
        Some((&BUILT, rest)) => {
            let Ok(scene) = scene(&mut Unstructured::new(rest)) else {
                return;
            };
            harness(format, text(format, &scene).as_bytes());
        }
        _ => harness(format, data),
    }
}

/// The scene as the text of `format`.
pub fn text(format: Format, scene: &Scene) -> String {
    match format {
        Format::Ron => scene.to_ron_string(),
        Format::Json => scene.to_json_string(),
    }
}

fn harness(format: Format, data: &[u8]) {
    match format {
        Format::Ron => fuzz_scene_ron(data),
        Format::Json => fuzz_scene_json(data),
    }
}

/// A float: mostly ordinary values in `[-range, range]`, sometimes one of the edges.
fn float(u: &mut Unstructured, range: f32) -> Result<f32> {
    const EDGES: [f32; 14] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        f32::MIN_POSITIVE,
        1e-40,
        f32::EPSILON,
        1e6,
        -1e6,
        1e7,
        1e38,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    Ok(match u.int_in_range(0u8..=15)? {
        0 => EDGES[u.choose_index(EDGES.len())?],
        1 => f32::from_bits(u.arbitrary()?),
        _ => {
            let t: u16 = u.arbitrary()?;
            (f32::from(t) / f32::from(u16::MAX) * 2.0 - 1.0) * range
        }
    })
}

/// A float in `[0, range]` mostly (an edge now and then, some of them negative).
fn positive(u: &mut Unstructured, range: f32) -> Result<f32> {
    let x = float(u, range)?;
    Ok(if u.ratio(1u8, 16)? { x } else { x.abs() })
}

fn vec3(u: &mut Unstructured, range: f32) -> Result<[f32; 3]> {
    Ok([float(u, range)?, float(u, range)?, float(u, range)?])
}

fn rotation(u: &mut Unstructured) -> Result<[f32; 4]> {
    if u.ratio(1u8, 2)? {
        return Ok([0.0, 0.0, 0.0, 1.0]);
    }
    Ok([
        float(u, 1.0)?,
        float(u, 1.0)?,
        float(u, 1.0)?,
        float(u, 1.0)?,
    ])
}

fn shape(u: &mut Unstructured, depth: u32) -> Result<ShapeDesc> {
    Ok(match u.int_in_range(0u8..=5)? {
        0 => ShapeDesc::Plane(PlaneDesc {}),
        1 => ShapeDesc::Cuboid {
            half_extents: [positive(u, 2.0)?, positive(u, 2.0)?, positive(u, 2.0)?],
        },
        2 => {
            let n = u.int_in_range(0usize..=24)?;
            let vertices = (0..n).map(|_| vec3(u, 1.0)).collect::<Result<Vec<_>>>()?;
            let t = u.int_in_range(0usize..=32)?;
            let bound = n as u32 + u32::from(u.ratio(1u8, 8)?) * 3;
            let index = |u: &mut Unstructured| -> Result<u32> {
                if bound == 0 {
                    u.arbitrary()
                } else {
                    u.int_in_range(0..=bound - 1)
                }
            };
            let indices = (0..t)
                .map(|_| Ok([index(u)?, index(u)?, index(u)?]))
                .collect::<Result<Vec<_>>>()?;
            ShapeDesc::TriMesh { vertices, indices }
        }
        3 => {
            let rows = u.int_in_range(0usize..=8)?;
            let cols = u.int_in_range(0usize..=8)?;
            let ragged = u.ratio(1u8, 8)?;
            let heights = (0..rows)
                .map(|_| {
                    let n = if ragged {
                        u.int_in_range(0usize..=8)?
                    } else {
                        cols
                    };
                    (0..n).map(|_| float(u, 0.2)).collect::<Result<Vec<_>>>()
                })
                .collect::<Result<Vec<_>>>()?;
            ShapeDesc::HeightField {
                heights,
                scale: [positive(u, 4.0)?, positive(u, 1.0)?, positive(u, 4.0)?],
            }
        }
        4 => {
            let n = if depth >= 2 {
                0
            } else {
                u.int_in_range(0usize..=4)?
            };
            let parts = (0..n)
                .map(|_| {
                    Ok(PartDesc {
                        shape: shape(u, depth + 1)?,
                        position: vec3(u, 1.0)?,
                        rotation: rotation(u)?,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            ShapeDesc::Compound(parts)
        }
        _ => ShapeDesc::Bowl {
            radius: positive(u, 2.0)?,
        },
    })
}

fn board(u: &mut Unstructured) -> Result<BoardDesc> {
    let moving = u.ratio(1u8, 3)?;
    Ok(BoardDesc {
        shape: shape(u, 0)?,
        position: vec3(u, 1.0)?,
        rotation: rotation(u)?,
        velocity: if moving { vec3(u, 5.0)? } else { [0.0; 3] },
        angular_velocity: if moving { vec3(u, 5.0)? } else { [0.0; 3] },
        restitution: positive(u, 1.0)?,
        friction: positive(u, 1.0)?,
        rolling_resistance: positive(u, 0.01)?,
        spin_damping: positive(u, 0.01)?,
    })
}

fn marble(u: &mut Unstructured) -> Result<MarbleDesc> {
    Ok(MarbleDesc {
        position: vec3(u, 1.0)?,
        velocity: vec3(u, 20.0)?,
        angular_velocity: vec3(u, 200.0)?,
        radius: positive(u, 0.05)?,
        mass: if u.ratio(1u8, 4)? {
            Some(positive(u, 0.1)?)
        } else {
            None
        },
        restitution: positive(u, 1.0)?,
        friction: positive(u, 1.0)?,
        rolling_resistance: positive(u, 0.01)?,
        spin_damping: positive(u, 0.01)?,
    })
}

fn sensor(u: &mut Unstructured, boards: usize) -> Result<SensorDesc> {
    Ok(SensorDesc {
        name: String::from(["goal", "hole", ""][u.choose_index(3)?]),
        shape: shape(u, 1)?,
        board: if u.ratio(1u8, 2)? {
            Some(u.int_in_range(0..=boards)?)
        } else {
            None
        },
        position: vec3(u, 1.0)?,
        rotation: rotation(u)?,
    })
}

/// A scene built from the fuzzer's bytes: every field of the scene file, a few boards (any
/// shape, moving or not), up to 40 marbles and a few sensors.
pub fn scene(u: &mut Unstructured) -> Result<Scene> {
    let mut scene = Scene {
        gravity: if u.ratio(3u8, 4)? {
            [0.0, -9.81, 0.0]
        } else {
            vec3(u, 20.0)?
        },
        dt: if u.ratio(3u8, 4)? {
            1.0 / 240.0
        } else {
            positive(u, 0.05)?
        },
        substeps: u.int_in_range(0..=17)?,
        integrator: [
            Integrator::SemiImplicitEuler,
            Integrator::VelocityVerlet,
            Integrator::Rk4,
            Integrator::ExplicitEuler,
        ][u.choose_index(4)?],
        ccd: u.arbitrary()?,
        rolling: u.arbitrary()?,
        marble_collisions: u.arbitrary()?,
        solver_iterations: u.int_in_range(0..=20)?,
        tilt_as_gravity: u.ratio(1u8, 8)?,
        restitution_threshold: positive(u, 1.0)?,
        sleep_speed: if u.ratio(1u8, 4)? {
            positive(u, 0.1)?
        } else {
            0.0
        },
        sleep_time: if u.ratio(1u8, 4)? {
            positive(u, 1.0)?
        } else {
            0.5
        },
        duration: positive(u, 10.0)?,
        ..Scene::default()
    };
    if u.ratio(1u8, 8)? {
        scene.preset = Some([Preset::Fast, Preset::Balanced, Preset::Precise][u.choose_index(3)?]);
    }
    let boards = u.int_in_range(0usize..=5)?;
    scene.boards = (0..boards).map(|_| board(u)).collect::<Result<_>>()?;
    let marbles = u.int_in_range(0usize..=40)?;
    scene.marbles = (0..marbles).map(|_| marble(u)).collect::<Result<_>>()?;
    let sensors = u.int_in_range(0usize..=3)?;
    scene.sensors = (0..sensors)
        .map(|_| sensor(u, boards))
        .collect::<Result<_>>()?;
    Ok(scene)
}
