//! Scenes defined once and shared by the CLI, tests, benches and examples.

use crate::scene::{BoardDesc, MarbleDesc, PartDesc, PlaneDesc, Scene, ShapeDesc};

fn cuboid(half_extents: [f32; 3], position: [f32; 3]) -> PartDesc {
    PartDesc {
        shape: ShapeDesc::Cuboid { half_extents },
        position,
        rotation: [0.0, 0.0, 0.0, 1.0],
    }
}

/// A walled square board, `half` metres from centre to wall, as compound parts: a floor
/// whose top face is at local y = 0 and four walls `wall_height` high.
pub fn walled_floor(half: f32, wall_height: f32) -> Vec<PartDesc> {
    let t = 0.01; // wall and floor half thickness
    let h = wall_height * 0.5;
    vec![
        cuboid([half + 2.0 * t, t, half + 2.0 * t], [0.0, -t, 0.0]),
        cuboid([t, h, half + 2.0 * t], [half + t, h, 0.0]),
        cuboid([t, h, half + 2.0 * t], [-half - t, h, 0.0]),
        cuboid([half, h, t], [0.0, h, half + t]),
        cuboid([half, h, t], [0.0, h, -half - t]),
    ]
}

/// The built-in scene of `marble` and `marble scene`: bench scene (c) with 48 marbles, a
/// 40 cm labyrinth board with walls and inner baffles, tilting slowly through level
/// (−0.1 rad about X to +0.1 rad over 10 s), the marbles dropped onto it and colliding
/// with each other.
pub fn default_scene() -> Scene {
    labyrinth(48)
}

/// Marbles per labyrinth tile in [`labyrinth`].
const LABYRINTH_TILE: usize = 48;

/// Bench scene (c): the default labyrinth scaled to `n` marbles. The 40 cm labyrinth
/// pattern (three baffles, 48 marbles dropped in an 8 × 6 grid) is tiled `k × k` times,
/// `k = ⌈√(n / 48)⌉`, inside one walled board `0.4 k` metres wide that tilts about X
/// through level (−0.1 rad to +0.1 rad over 10 s); tiles fill in order until `n` marbles
/// are placed, 6–7 cm above the board's floor in its frame. Marbles collide with each
/// other.
pub fn labyrinth(n: usize) -> Scene {
    let tile = 0.4f32;
    let k = n.div_ceil(LABYRINTH_TILE).max(1).isqrt();
    let k = if k * k * LABYRINTH_TILE < n { k + 1 } else { k };
    let half = 0.5 * tile * k as f32;
    let mut parts = walled_floor(half, 0.03);
    let centre = |t: usize| (t as f32 - 0.5 * (k as f32 - 1.0)) * tile;
    for ti in 0..k {
        for tj in 0..k {
            let (cx, cz) = (centre(ti), centre(tj));
            // The inner baffles of the labyrinth.
            for (i, z) in [-0.1f32, 0.0, 0.1].iter().enumerate() {
                let x = if i % 2 == 0 { -0.05 } else { 0.05 };
                parts.push(cuboid([0.15, 0.015, 0.005], [cx + x, 0.015, cz + z]));
            }
        }
    }
    let tilt = -0.1f32;
    let mut board = BoardDesc::new(ShapeDesc::Compound(parts));
    board.rotation = [libm::sinf(tilt / 2.0), 0.0, 0.0, libm::cosf(tilt / 2.0)];
    board.angular_velocity = [0.02, 0.0, 0.0];
    board.restitution = 0.6;
    // Marbles are placed in the board's frame (above its tilted floor: on a large board
    // the high side rises well above any fixed world height).
    let pose = glam::Quat::from_array(board.rotation);
    let marbles = (0..n)
        .map(|m| {
            let (t, q) = (m / LABYRINTH_TILE, m % LABYRINTH_TILE);
            let (cx, cz) = (centre(t % k), centre(t / k));
            let (i, j) = (q / 6, q % 6);
            let x = -0.17 + 0.048 * i as f32;
            let z = -0.17 + 0.065 * j as f32 + 0.01;
            let local = glam::Vec3::new(cx + x, 0.06 + 0.004 * ((i + j) % 3) as f32, cz + z);
            let mut marble = MarbleDesc::at((pose * local).to_array());
            marble.restitution = 0.7;
            marble
        })
        .collect();
    Scene {
        dt: 1.0 / 240.0,
        duration: 10.0,
        marble_collisions: true,
        boards: vec![board],
        marbles,
        ..Scene::default()
    }
}

/// Seconds of [`labyrinth`] stepped before [`labyrinth_steady`] takes its state.
pub const LABYRINTH_STEADY: f32 = 5.0;

/// Bench scene (c) in its steady state: [`labyrinth`] stepped for [`LABYRINTH_STEADY`]
/// seconds, as a scene that starts where it got to — every marble at the position and
/// velocity it reached (sliding on the floor, piled against the baffles and walls), the
/// board turned as far as it had (level by then) and turning on as before, for the 5 s
/// left of its tilt. The contact impulses kept for warm starting are not part of a scene,
/// so its first substeps are solved cold. The benches time its first quarter second, as
/// they do [`labyrinth`]'s, whose first quarter second is marbles falling onto the floor.
/// Building it steps the whole labyrinth for 5 s (about 10 s of this machine's time at
/// 10,000 marbles).
pub fn labyrinth_steady(n: usize) -> Scene {
    let mut scene = labyrinth(n);
    scene.duration -= LABYRINTH_STEADY;
    assert!(
        !scene.tilt_as_gravity,
        "the labyrinth turns its board, not gravity"
    );
    let mut sim = crate::Simulation::from_scene(&scene).expect("bench scene (c) is valid");
    for _ in 0..(LABYRINTH_STEADY / scene.dt).round() as u64 {
        sim.step();
    }
    for (i, m) in scene.marbles.iter_mut().enumerate() {
        let (x, v) = sim.marble_state(i);
        m.position = x.to_array();
        m.velocity = v.to_array();
    }
    for (b, &entity) in scene.boards.iter_mut().zip(sim.boards()) {
        let world = sim.world();
        let position = world
            .get::<crate::components::Position>(entity)
            .expect("a board has a position");
        let rotation = world
            .get::<crate::components::Rotation>(entity)
            .expect("a board has a rotation");
        b.position = position.0.to_array();
        b.rotation = rotation.0.to_array();
    }
    scene
}

/// Layers of marbles in [`pour_box`].
const POUR_LAYERS: usize = 10;

/// Bench scene (b): `n` marbles poured into a walled box (dense contact). The marbles
/// start in ten layers on a lattice 2.2 radii apart, each nudged sideways by up to 0.1 r
/// (a fixed pseudo-random pattern, so that they fall into a packing rather than balance
/// in columns), over a square box just wide enough for them; they fall, collide, and
/// settle into a pile. dt = 1/60 s in 8 substeps, 15 solver passes, restitution 0.5,
/// marble collisions on.
pub fn pour_box(n: usize) -> Scene {
    let r = crate::components::DEFAULT_RADIUS;
    let spacing = 2.2 * r;
    let side = n.div_ceil(POUR_LAYERS).max(1).isqrt();
    let side = if side * side * POUR_LAYERS < n {
        side + 1
    } else {
        side
    };
    let half = 0.5 * spacing * side as f32;
    let layers = n.div_ceil(side * side);
    let wall = spacing * layers as f32 + 0.1;
    let board = BoardDesc::new(ShapeDesc::Compound(walled_floor(half, wall)));
    // A fixed pattern of nudges in [−1, 1] (a 32-bit LCG), the same on every machine.
    let mut seed = 0x2545_f491u32;
    let mut nudge = move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 23) as f32 - 1.0
    };
    let marbles = (0..n)
        .map(|m| {
            let (layer, q) = (m / (side * side), m % (side * side));
            let (i, j) = (q % side, q / side);
            let x = -half + spacing * (i as f32 + 0.5) + 0.1 * r * nudge();
            let z = -half + spacing * (j as f32 + 0.5) + 0.1 * r * nudge();
            MarbleDesc::at([x, 1.2 * r + spacing * layer as f32, z])
        })
        .collect();
    Scene {
        dt: 1.0 / 60.0,
        // A dense pile at 1/60 s needs substeps: in one 1/60 s step a marble falls a third
        // of its radius, and a crash of ten layers then leaves overlaps the solver cannot
        // take out; at 1/480 s with 15 (over-relaxed) solver passes the pile settles, with
        // overlaps at the 0.2% slop: in each of fifteen starts the last marble above 5 cm/s
        // stopped by 5.4 s (thirteen by 3.2 s), and at 6 s none moved faster than 1.1 mm/s
        // (measured with `examples/marble_pile.rs`; `docs/pair-solver.md`, "What piles need").
        substeps: 8,
        solver_iterations: 15,
        duration: 5.0,
        marble_collisions: true,
        boards: vec![board],
        marbles,
        ..Scene::default()
    }
}

/// Steps of [`pour_box`] after which its pile has settled (6 s): the `settled_pile`
/// benches start timing there.
pub const SETTLE_STEPS: u64 = 360;

/// [`pour_box`] with sleeping on: marbles slower than 5 mm/s for half a second fall asleep
/// ([`crate::sleep`]). Over thirteen starts of the 1,000-marble pour (`examples/marble_pile`
/// with seeds 0–12) the whole pile was asleep by 2.0–7.5 s (median 3.5 s).
pub fn pour_box_sleeping(n: usize) -> Scene {
    Scene {
        sleep_speed: 0.005,
        sleep_time: 0.5,
        ..pour_box(n)
    }
}

/// The fewest substeps of bench scene (b)'s 1/60 s step (at its 15 solver passes) at
/// which its pour meets the pile bar, and four starts in five do: after 6 s, no marble at
/// 5 cm/s or more, none out of the box or under the floor, the deepest overlap under 5% of
/// the radius. At 1,000 marbles the scene's own start ends at 4.7 cm/s with overlaps of
/// 0.95% of r, and thirteen of fifteen starts meet the bar (the others at 5.2 and
/// 7.6 cm/s); at 2 substeps nine do (the scene's own start among them, but not four in
/// five); at 4, fourteen (`examples/marble_pile.rs`, `docs/pair-solver.md`, "What piles need"). The
/// criterion group `marble_collisions` times it as `pour_box_bar`.
pub const POUR_BOX_BAR_SUBSTEPS: u32 = 3;

/// The three bench scenes, shared by the criterion benches, the tests, the rapier
/// comparison and `marble scene --bench`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchScene {
    /// (a) [`walled_board`]: marbles spread over a tilted walled board, which meet only
    /// where they slide into its lower wall.
    WalledBoard,
    /// (b) [`pour_box`]: marbles poured into a walled box (dense contact).
    PourBox,
    /// (c) [`labyrinth`]: the default labyrinth scaled to N marbles.
    Labyrinth,
}

impl BenchScene {
    /// All three, in order (a), (b), (c).
    pub const ALL: [BenchScene; 3] = [
        BenchScene::WalledBoard,
        BenchScene::PourBox,
        BenchScene::Labyrinth,
    ];

    /// The scene with `n` marbles.
    pub fn build(self, n: usize) -> Scene {
        match self {
            BenchScene::WalledBoard => walled_board(n),
            BenchScene::PourBox => pour_box(n),
            BenchScene::Labyrinth => labyrinth(n),
        }
    }

    /// Short name, as on the command line and in bench ids.
    pub fn name(self) -> &'static str {
        match self {
            BenchScene::WalledBoard => "walled_board",
            BenchScene::PourBox => "pour_box",
            BenchScene::Labyrinth => "labyrinth",
        }
    }

    /// The scene of this short name.
    pub fn from_name(name: &str) -> Option<BenchScene> {
        BenchScene::ALL.into_iter().find(|b| b.name() == name)
    }
}

/// Bench scene (a): `n` marbles resting in a square grid on a walled board tilted by
/// 1°, spaced four radii apart. They slide down the tilt together; with marble collisions
/// on, the rows that reach the lower wall meet it and each other from the 47th step of
/// the first second on (at most 64 touching pairs at 1,000 marbles, 200 at 10,000, in
/// the first 60 steps).
pub fn walled_board(n: usize) -> Scene {
    let r = crate::components::DEFAULT_RADIUS;
    let spacing = 4.0 * r;
    let side = (n as f64).sqrt().ceil() as usize;
    let half = spacing * side as f32 * 0.5 + spacing;
    let tilt = 1.0f32.to_radians();
    let mut board = BoardDesc::new(ShapeDesc::Compound(walled_floor(half, 0.03)));
    board.rotation = [0.0, 0.0, libm::sinf(tilt / 2.0), libm::cosf(tilt / 2.0)];
    let (s, c) = libm::sincosf(tilt);
    let marbles = (0..n)
        .map(|k| {
            let (i, j) = (k % side, k / side);
            let u = -half + spacing * (i as f32 + 1.5);
            let w = -half + spacing * (j as f32 + 1.5);
            // On the tilted floor: local (u, r, w) rotated about Z.
            MarbleDesc::at([u * c - r * s, u * s + r * c, w])
        })
        .collect();
    Scene {
        dt: 1.0 / 60.0,
        boards: vec![board],
        marbles,
        ..Scene::default()
    }
}

/// A marble of radius `r` dropped from `height` (bottom above the surface) onto a plane,
/// both with restitution `e`.
pub fn drop_on_plane(height: f32, r: f32, e: f32) -> Scene {
    let mut board = BoardDesc::new(ShapeDesc::Plane(PlaneDesc {}));
    board.restitution = e;
    let mut m = MarbleDesc::at([0.0, height + r, 0.0]);
    m.radius = r;
    m.restitution = e;
    Scene {
        boards: vec![board],
        marbles: vec![m],
        ..Scene::default()
    }
}
