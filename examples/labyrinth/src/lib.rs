//! The rules of the tilting labyrinth, apart from drawing them: the level loaded from a
//! scene file, the player's tilt eased and clamped and driven through `NextPose`, marbles
//! home at the goal, lost in a hole (or off the board) and back at the start, the score.
//! [`LabyrinthPlugin`] runs the same in the windowed game (`src/main.rs`) and in a headless
//! `App` (`tests/rules.rs`).

use std::time::Duration;

use bevy::prelude::*;
use bevy_marble::output::PoseRow;
use bevy_marble::prelude::*;
use bevy_marble::scene;
use bevy_marble::simulation::spawn_scene;

/// The steepest the board tilts, rad (Neverball's floor tilts within 20°).
pub const MAX_TILT: f32 = 20.0 * std::f32::consts::PI / 180.0;

/// The time constant of the easing from the player's input to the board's tilt, s
/// (Neverball smooths its input over about 0.05 s).
pub const EASE_SECONDS: f32 = 0.05;

/// The fastest the board turns, rad/s: a physically turning board flicks what is on it
/// (its walls move at this times their distance from the pivot), so the eased tilt is
/// also limited in rate; 20° then takes at least 0.12 s.
pub const MAX_TILT_RATE: f32 = 3.0;

/// Marbles in the "many marbles" mode.
pub const MANY: usize = 300;

/// The built-in level (`levels/classic.ron`).
pub const CLASSIC: &str = include_str!("../levels/classic.ron");

/// The player's tilt, each axis in −1..1: `x` towards +x (right on screen), `y` towards
/// −z (up on screen). Keys, a stick or a test write it.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct TiltInput(pub Vec2);

/// The board's tilt now, rad: the direction it slopes down and by how much (its length
/// is the angle between the board's normal and the vertical, never above [`MAX_TILT`]).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct Tilt(pub Vec2);

impl Tilt {
    /// The board's rotation for this tilt: about the horizontal axis across the downhill
    /// direction, by the tilt's length.
    pub fn rotation(self) -> Quat {
        let angle = self.0.length();
        if angle == 0.0 {
            return Quat::IDENTITY;
        }
        let downhill = Vec3::new(self.0.x, 0.0, -self.0.y) / angle;
        Quat::from_axis_angle(Vec3::Y.cross(downhill), angle)
    }
}

/// The loaded level: its scene, the board, the start (in the board's frame) and the
/// sensors by what they are.
#[derive(Resource, Clone, Debug)]
pub struct Level {
    /// The scene file's contents.
    pub scene: Scene,
    /// The board the player tilts (the scene's first).
    pub board: Entity,
    /// Where marbles start and come back, board frame (the scene's first marble).
    pub start: Vec3,
    /// Sensors named `goal`.
    pub goals: Vec<Entity>,
    /// Sensors named `hole`.
    pub holes: Vec<Entity>,
    /// The board's pose when level (the scene's).
    pub pivot: Vec3,
}

/// The score.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq)]
pub struct Score {
    /// Marbles that reached the goal.
    pub home: u32,
    /// Marbles lost in a hole or off the board.
    pub lost: u32,
    /// Seconds since the current run started (a marble home or lost starts another in
    /// the one-marble mode).
    pub time: f32,
    /// The fastest run home, s.
    pub best: Option<f32>,
}

/// A marble of the game (every marble of the level, and those of the many-marbles mode).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct PlayerMarble;

/// What happened to a marble this step, for the game's sounds and messages.
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub enum MarbleFate {
    /// It reached the goal (then started again).
    Home(Entity),
    /// It fell into a hole or off the board (then started again).
    Lost(Entity),
}

/// Starts again with this many marbles (1: the one-marble mode; more: marble collisions
/// on; the number there is now: a restart).
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct SetMarbles(pub usize);

/// Every board pose the game drove, one row per fixed step: the input a `marble run
/// --poses` replays.
#[derive(Resource, Clone, Debug, Default)]
pub struct TiltLog {
    /// Whether to record.
    pub enabled: bool,
    /// The rows so far.
    pub rows: Vec<PoseRow>,
    /// Fixed steps so far.
    pub steps: u64,
}

/// The rules' systems, for ordering against: the tilt (in `FixedUpdate`) and the judging
/// of marbles home or lost (in `FixedPostUpdate`, after the physics step).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LabyrinthSystems {
    /// Ease the tilt, drive the board.
    Tilt,
    /// Home, lost, back at the start.
    Judge,
}

/// What sending a marble somewhere changes: where it is and how it moves.
type Motion = (
    Entity,
    &'static mut Position,
    &'static mut Velocity,
    Option<&'static mut AngularVelocity>,
);

/// Puts a marble at `at` (world frame), at rest: a teleport.
fn place_at_rest(
    (_, mut position, mut velocity, spin): bevy::ecs::query::QueryItem<'_, '_, Motion>,
    at: Vec3,
) {
    position.0 = at;
    velocity.0 = Vec3::ZERO;
    if let Some(mut w) = spin {
        w.0 = Vec3::ZERO;
    }
}

/// A marble this far below the board's lowest point has left it, m.
const FALL_OUT: f32 = 0.5;

/// The labyrinth's rules; adds [`MarblePhysicsPlugin`] (bring `TimePlugin` or
/// `DefaultPlugins`).
pub struct LabyrinthPlugin {
    /// The level.
    pub level: Scene,
}

impl Default for LabyrinthPlugin {
    fn default() -> Self {
        LabyrinthPlugin {
            level: Scene::from_ron_str(CLASSIC).expect("the built-in level is valid"),
        }
    }
}

impl Plugin for LabyrinthPlugin {
    fn build(&self, app: &mut App) {
        // The level's settings first: the plugin keeps them and turns its events on.
        app.insert_resource(self.level.step_config())
            .add_plugins(MarblePhysicsPlugin::default())
            // The physics steps at the level's own dt, as `marble run` does.
            .insert_resource(Time::<Fixed>::from_duration(Duration::from_secs_f64(
                self.level.dt as f64,
            )))
            .insert_resource(LevelScene(self.level.clone()))
            .init_resource::<TiltInput>()
            .init_resource::<Tilt>()
            .init_resource::<Score>()
            .init_resource::<TiltLog>()
            .add_message::<MarbleFate>()
            .add_message::<SetMarbles>()
            .add_systems(Startup, load_level)
            .add_systems(
                FixedUpdate,
                (set_marbles, tilt_board)
                    .chain()
                    .in_set(LabyrinthSystems::Tilt),
            )
            .add_systems(
                FixedPostUpdate,
                // After the step's poses are recorded and written out: a marble sent back
                // to the start is then a teleport, which the next step's interpolation
                // takes without a streak.
                judge
                    .in_set(LabyrinthSystems::Judge)
                    .after(bevy_marble::plugin::MarblePluginSystems::SyncTransforms),
            );
    }
}

/// The scene to load at startup.
#[derive(Resource, Clone, Debug)]
struct LevelScene(Scene);

fn load_level(world: &mut World) {
    let scene = world.resource::<LevelScene>().0.clone();
    let spawned = spawn_scene(&scene, world);
    let named = |name: &str| -> Vec<Entity> {
        spawned
            .sensors
            .iter()
            .zip(&scene.sensors)
            .filter(|(_, s)| s.name == name)
            .map(|(e, _)| *e)
            .collect()
    };
    let (goals, holes) = (named("goal"), named("hole"));
    for &m in &spawned.marbles {
        world.entity_mut(m).insert(PlayerMarble);
    }
    let board = *spawned.boards.first().expect("a level has a board");
    let pivot = Vec3::from_array(scene.boards[0].position);
    let first = scene
        .marbles
        .first()
        .map_or(Vec3::Y * 0.01, |m| Vec3::from_array(m.position));
    let start = scene::quat(scene.boards[0].rotation).conjugate() * (first - pivot);
    world.insert_resource(Level {
        scene,
        board,
        start,
        goals,
        holes,
        pivot,
    });
}

/// Eases the tilt towards the input (clamped to [`MAX_TILT`], and in rate to
/// [`MAX_TILT_RATE`]) and drives the board there over this step. With one marble the
/// board turns about the marble's contact point, as Neverball's floor turns about its
/// ball: the floor under the marble stays put, so tilting never flicks it; with many it
/// turns about its own origin.
#[expect(
    clippy::too_many_arguments,
    reason = "the tilt reads the board and the marbles"
)]
fn tilt_board(
    input: Res<TiltInput>,
    mut tilt: ResMut<Tilt>,
    mut log: ResMut<TiltLog>,
    level: Option<Res<Level>>,
    time: Res<Time<Fixed>>,
    boards: Query<(&Position, &Rotation), (With<Board>, Without<PlayerMarble>)>,
    marbles: Query<(&Position, &Radius), With<PlayerMarble>>,
    mut commands: Commands,
) {
    let Some(level) = level else { return };
    let Ok((board_p, board_q)) = boards.get(level.board) else {
        return;
    };
    // An input that is not a number (a broken device) counts as none.
    let input = if input.0.is_finite() {
        input.0
    } else {
        Vec2::ZERO
    };
    let target = input.clamp_length_max(1.0) * MAX_TILT;
    let h = time.timestep().as_secs_f32();
    let now = tilt.0;
    let eased = (target - now) * (1.0 - (-h / EASE_SECONDS).exp());
    // Both the target and the tilt stay inside the disc: the tilt is a convex combination.
    tilt.0 = (now + eased.clamp_length_max(MAX_TILT_RATE * h)).clamp_length_max(MAX_TILT);
    let rotation = tilt.rotation();
    let pivot = match marbles.iter().collect::<Vec<_>>()[..] {
        [(p, r)] if p.0.y > board_p.0.y - FALL_OUT => p.0 - board_q.0 * Vec3::Y * r.0,
        _ => board_p.0,
    };
    let turn = rotation * board_q.0.conjugate();
    let pose = NextPose {
        position: pivot + turn * (board_p.0 - pivot),
        rotation,
    };
    commands.entity(level.board).insert(pose);
    log.steps += 1;
    if log.enabled {
        let step = log.steps;
        log.rows.push(PoseRow {
            step,
            board: 0,
            position: pose.position,
            rotation: pose.rotation,
        });
    }
}

/// After each physics step: marbles in the goal are home, in a hole or fallen off are
/// lost; either way they start again (the one-marble mode restarts the clock).
#[expect(
    clippy::too_many_arguments,
    reason = "a game rule reads what it judges"
)]
fn judge(
    mut entered: MessageReader<SensorEntered>,
    mut fates: MessageWriter<MarbleFate>,
    level: Option<Res<Level>>,
    mut score: ResMut<Score>,
    time: Res<Time<Fixed>>,
    boards: Query<(&Position, &Rotation), (With<Board>, Without<PlayerMarble>)>,
    mut marbles: Query<Motion, With<PlayerMarble>>,
    mut respawned: Local<u32>,
) {
    let Some(level) = level else { return };
    score.time += time.timestep().as_secs_f32();
    let Ok((board_p, board_q)) = boards.get(level.board) else {
        return;
    };
    let (board_p, board_q) = (board_p.0, board_q.0);
    let single = marbles.iter().count() == 1;
    let mut fate_of = |marble: Entity, home: bool, score: &mut Score| {
        if home {
            score.home += 1;
            if single {
                score.best = Some(score.best.map_or(score.time, |b| b.min(score.time)));
            }
            fates.write(MarbleFate::Home(marble));
        } else {
            score.lost += 1;
            fates.write(MarbleFate::Lost(marble));
        }
        if single {
            score.time = 0.0;
        }
    };
    let mut restart: Vec<Entity> = Vec::new();
    for e in entered.read() {
        if level.goals.contains(&e.sensor) {
            fate_of(e.marble, true, &mut score);
            restart.push(e.marble);
        } else if level.holes.contains(&e.sensor) {
            fate_of(e.marble, false, &mut score);
            restart.push(e.marble);
        }
    }
    let floor = board_p.y - FALL_OUT;
    for (marble, position, _, _) in &marbles {
        if position.0.y < floor && !restart.contains(&marble) {
            fate_of(marble, false, &mut score);
            restart.push(marble);
        }
    }
    for marble in restart {
        if let Ok(motion) = marbles.get_mut(marble) {
            // The start, in the board's frame as it is now; many marbles spread over the
            // first cell's width so that they do not all land on one spot.
            let spread = if single {
                Vec3::ZERO
            } else {
                *respawned = respawned.wrapping_add(1);
                let k = *respawned as f32;
                Vec3::new(
                    (k * 0.618_034).fract() - 0.5,
                    0.0,
                    (k * 0.414_214).fract() - 0.5,
                ) * 0.03
            };
            let lift = if single { Vec3::ZERO } else { Vec3::Y * 0.02 };
            place_at_rest(motion, board_p + board_q * (level.start + spread + lift));
        }
    }
}

/// Starts again with `n` marbles (the same number: a restart). The level's marble goes
/// back to the start and the others to places in one layer over the board's free floor
/// (a grid 2.6 radii apart, clear of walls and holes), at rest; marbles are spawned or
/// removed to make `n`; marble collisions are on with more than one; the score is reset.
fn set_marbles(
    mut requests: MessageReader<SetMarbles>,
    level: Option<Res<Level>>,
    mut config: ResMut<StepConfig>,
    mut marbles: Query<Motion, With<PlayerMarble>>,
    boards: Query<(&Position, &Rotation), (With<Board>, Without<PlayerMarble>)>,
    mut score: ResMut<Score>,
    mut commands: Commands,
) {
    let (Some(level), Some(&SetMarbles(n))) = (level, requests.read().last()) else {
        return;
    };
    let Ok((board_p, board_q)) = boards.get(level.board) else {
        return;
    };
    let (board_p, board_q) = (board_p.0, board_q.0);
    let n = n.max(1);
    config.marble_collisions = n > 1;
    *score = Score::default();
    let template = level
        .scene
        .marbles
        .first()
        .cloned()
        .unwrap_or_else(|| MarbleDesc::at([0.0; 3]));
    let r = template.radius;
    // The start first, then the free floor (the start cell's own spots left out).
    let mut places = vec![level.start];
    places.extend(
        free_floor(&level.scene, r)
            .into_iter()
            .filter(|p| (*p - level.start).length() >= 2.0 * r),
    );
    // The level's marble (spawned first) keeps the start.
    let mut have: Vec<Entity> = marbles.iter().map(|m| m.0).collect();
    have.sort();
    for (k, &e) in have.iter().enumerate() {
        if k >= n {
            commands.entity(e).despawn();
            continue;
        }
        if let Ok(motion) = marbles.get_mut(e) {
            place_at_rest(motion, board_p + board_q * places[k.min(places.len() - 1)]);
        }
    }
    for local in places
        .iter()
        .skip(have.len())
        .take(n.saturating_sub(have.len()))
    {
        let mut marble = commands.spawn((
            PlayerMarble,
            Marble,
            Position(board_p + board_q * *local),
            Velocity::default(),
            Radius(r),
            Restitution(template.restitution),
            Friction(template.friction),
        ));
        if level.scene.rolling {
            marble.insert((AngularVelocity::default(), Rotation::default()));
        }
    }
}

/// Places for marbles of radius `r` resting on the first board's floor (its parts below
/// y = 0), in its frame: a grid 2.6 r apart, each point over floor, at least r clear of
/// every wall (the parts above y = 0) and of every hole.
pub fn free_floor(scene: &Scene, r: f32) -> Vec<Vec3> {
    let ShapeDesc::Compound(parts) = &scene.boards[0].shape else {
        return Vec::new();
    };
    // Boxes in the board's xz plane: (centre, half extents), grown by `grow`.
    let boxes =
        |keep: &dyn Fn(&bevy_marble::scene::PartDesc) -> bool, grow: f32| -> Vec<(Vec2, Vec2)> {
            parts
                .iter()
                .filter(|p| keep(p))
                .filter_map(|p| match p.shape {
                    ShapeDesc::Cuboid { half_extents: h } => Some((
                        Vec2::new(p.position[0], p.position[2]),
                        Vec2::new(h[0], h[2]) + Vec2::splat(grow),
                    )),
                    _ => None,
                })
                .collect()
        };
    let floor = boxes(&|p| p.position[1] < 0.0, -r * 0.5);
    let walls = boxes(&|p| p.position[1] >= 0.0, r);
    let holes: Vec<(Vec2, Vec2)> = scene
        .sensors
        .iter()
        .filter(|s| s.name == "hole")
        .filter_map(|s| match s.shape {
            ShapeDesc::Cuboid { half_extents: h } => Some((
                Vec2::new(s.position[0], s.position[2]),
                Vec2::new(h[0], h[2]) + Vec2::splat(r),
            )),
            _ => None,
        })
        .collect();
    let inside = |p: Vec2, (c, h): &(Vec2, Vec2)| (p - *c).abs().cmple(*h).all();
    let (lo, hi) = floor
        .iter()
        .fold((Vec2::MAX, Vec2::MIN), |(lo, hi), (c, h)| {
            (lo.min(*c - *h), hi.max(*c + *h))
        });
    let step = 2.6 * r;
    let mut out = Vec::new();
    let mut z = lo.y + r;
    while z <= hi.y - r {
        let mut x = lo.x + r;
        while x <= hi.x - r {
            let p = Vec2::new(x, z);
            if floor.iter().any(|b| inside(p, b))
                && !walls.iter().any(|b| inside(p, b))
                && !holes.iter().any(|b| inside(p, b))
            {
                out.push(Vec3::new(x, r + 0.001, z));
            }
            x += step;
        }
        z += step;
    }
    out
}
