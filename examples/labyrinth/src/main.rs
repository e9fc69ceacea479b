//! A tilting labyrinth on bevy_marble: tilt the board with the arrow keys, WASD or a
//! gamepad's left stick, steer the marble round the holes to the goal.
//!
//! ```sh
//! cd examples/labyrinth && cargo run --release --ignore-rust-version
//! ```
//!
//! Keys: arrows/WASD tilt · M one marble or 300 · F1 debug drawing · R restart · Esc quit.
//! Flags: `--level FILE` (a scene file with sensors named `goal` and `hole`), `--many`,
//! `--record FILE.csv` (the board's poses, for `marble run --poses`), `--debug` (start
//! with the debug drawing on), `--autoplay` and `--exit-after SECONDS` (for the
//! screenshot script).

use std::path::PathBuf;
use std::sync::Arc;

use bevy::audio::{AudioPlayer, AudioSource, PlaybackSettings, Volume};
use bevy::prelude::*;
use bevy_marble::plugin::debug_draw::{MarbleDebugDraw, MarbleDebugDrawPlugin};
use bevy_marble::prelude::*;
use marble_labyrinth::{
    CLASSIC, LabyrinthPlugin, Level, MANY, MarbleFate, PlayerMarble, Score, SetMarbles, Tilt,
    TiltInput, TiltLog,
};

/// The command line.
#[derive(Resource, Clone, Debug, Default)]
struct Args {
    level: Option<PathBuf>,
    many: bool,
    record: Option<PathBuf>,
    autoplay: bool,
    exit_after: Option<f32>,
    debug: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args::default();
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--level" => args.level = Some(it.next().ok_or("--level needs a file")?.into()),
            "--many" => args.many = true,
            "--record" => args.record = Some(it.next().ok_or("--record needs a file")?.into()),
            "--autoplay" => args.autoplay = true,
            "--debug" => args.debug = true,
            "--exit-after" => {
                let v = it.next().ok_or("--exit-after needs seconds")?;
                let s: f32 = v
                    .parse()
                    .ok()
                    .filter(|s: &f32| s.is_finite() && *s > 0.0)
                    .ok_or(format!("--exit-after must be seconds > 0, got {v:?}"))?;
                args.exit_after = Some(s);
            }
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    Ok(args)
}

fn main() -> AppExit {
    let (args, level) = match parse_args().and_then(|args| {
        let level = match &args.level {
            Some(p) => Scene::from_path(p).map_err(|e| format!("{}: {e}", p.display()))?,
            None => Scene::from_ron_str(CLASSIC).map_err(|e| e.to_string())?,
        };
        Ok((args, level))
    }) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: {e}");
            return AppExit::from_code(2);
        }
    };
    App::new()
        .add_plugins(DefaultPlugins.set(WindowPlugin {
            primary_window: Some(Window {
                title: "bevy_marble · labyrinth".into(),
                resolution: (1280u32, 800u32).into(),
                ..default()
            }),
            ..default()
        }))
        .add_plugins((LabyrinthPlugin { level }, MarbleDebugDrawPlugin))
        .insert_resource(MarbleDebugDraw {
            enabled: args.debug,
            ..default()
        })
        .insert_resource(ClearColor(Color::srgb(0.05, 0.06, 0.08)))
        .insert_resource(GlobalAmbientLight {
            brightness: 300.0,
            ..default()
        })
        .insert_resource(TiltLog {
            enabled: args.record.is_some(),
            ..default()
        })
        .insert_resource(args)
        .init_resource::<FrameCount>()
        .add_systems(
            PostStartup,
            (dress_level, setup_hud, setup_sounds, start_mode),
        )
        .add_systems(
            Update,
            (
                read_input,
                keys,
                dress_marbles,
                follow_camera,
                update_hud,
                bump_sounds,
                count_frames,
            ),
        )
        .add_systems(Last, save_log)
        .run()
}

/// The many-marbles mode from the start, if asked.
fn start_mode(args: Res<Args>, mut set: MessageWriter<SetMarbles>) {
    if args.many {
        set.write(SetMarbles(MANY));
    }
}

/// Meshes and materials shared by every marble.
#[derive(Resource)]
struct MarbleLook(Handle<Mesh>, Handle<StandardMaterial>);

/// The camera and the point it follows.
#[derive(Component)]
struct Follow(Vec3);

#[derive(Component)]
struct Hud;

/// Gives the board, its holes and goal meshes; lights and a camera.
fn dress_level(
    mut commands: Commands,
    level: Res<Level>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let wood = materials.add(StandardMaterial {
        base_color: Color::srgb(0.80, 0.66, 0.46),
        perceptual_roughness: 0.7,
        ..default()
    });
    let wall = materials.add(StandardMaterial {
        base_color: Color::srgb(0.42, 0.28, 0.18),
        perceptual_roughness: 0.6,
        ..default()
    });
    let pit = materials.add(StandardMaterial {
        base_color: Color::srgb(0.02, 0.02, 0.03),
        perceptual_roughness: 1.0,
        ..default()
    });
    let goal = materials.add(StandardMaterial {
        base_color: Color::srgb(0.2, 0.9, 0.4),
        emissive: LinearRgba::rgb(0.2, 2.0, 0.6),
        ..default()
    });
    let board = &level.scene.boards[0];
    let parts: Vec<(Vec3, Quat, Vec3)> = match &board.shape {
        ShapeDesc::Compound(parts) => parts
            .iter()
            .filter_map(|p| match p.shape {
                ShapeDesc::Cuboid { half_extents } => Some((
                    Vec3::from_array(p.position),
                    bevy_marble::scene::quat(p.rotation),
                    Vec3::from_array(half_extents),
                )),
                _ => None,
            })
            .collect(),
        ShapeDesc::Cuboid { half_extents } => {
            vec![(Vec3::ZERO, Quat::IDENTITY, Vec3::from_array(*half_extents))]
        }
        _ => Vec::new(),
    };
    commands
        .entity(level.board)
        .insert((
            Transform::from_translation(level.pivot),
            TransformInterpolation,
            Visibility::default(),
        ))
        .with_children(|b| {
            for (p, q, h) in parts {
                // The floor's pieces lie below y = 0; the walls stand on it.
                let material = if p.y < 0.0 {
                    wood.clone()
                } else {
                    wall.clone()
                };
                b.spawn((
                    Mesh3d(meshes.add(Cuboid::from_size(2.0 * h))),
                    MeshMaterial3d(material),
                    Transform::from_translation(p).with_rotation(q),
                ));
            }
            for s in &level.scene.sensors {
                let (p, size, material) = match (s.name.as_str(), &s.shape) {
                    ("hole", ShapeDesc::Cuboid { half_extents }) => {
                        let h = Vec3::from_array(*half_extents);
                        // A dark pit below the hole, so that it reads as a hole.
                        (
                            Vec3::from_array(s.position),
                            Vec3::new(2.0 * h.x, 0.002, 2.0 * h.z),
                            pit.clone(),
                        )
                    }
                    ("goal", ShapeDesc::Cuboid { half_extents }) => {
                        let p = Vec3::from_array(s.position);
                        let h = Vec3::from_array(*half_extents);
                        (
                            Vec3::new(p.x, 0.0006, p.z),
                            Vec3::new(2.0 * h.x, 0.001, 2.0 * h.z),
                            goal.clone(),
                        )
                    }
                    _ => continue,
                };
                b.spawn((
                    Mesh3d(meshes.add(Cuboid::from_size(size))),
                    MeshMaterial3d(material),
                    Transform::from_translation(p),
                ));
            }
        });
    let r = level.scene.marbles.first().map_or(0.008, |m| m.radius);
    commands.insert_resource(MarbleLook(
        meshes.add(Sphere::new(r).mesh().uv(32, 18)),
        materials.add(StandardMaterial {
            base_color: Color::srgb(0.55, 0.75, 0.95),
            metallic: 0.4,
            perceptual_roughness: 0.15,
            reflectance: 0.8,
            ..default()
        }),
    ));
    commands.spawn((
        DirectionalLight {
            illuminance: 9000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(0.4, 1.0, 0.6).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let start = level.pivot + level.start;
    commands.spawn((
        Camera3d::default(),
        Transform::from_translation(start + CAMERA_OFFSET).looking_at(start, Vec3::Y),
        Follow(start),
    ));
}

/// Where the camera sits relative to what it follows: above and towards +z (the player's
/// side of the board), m.
const CAMERA_OFFSET: Vec3 = Vec3::new(0.0, 0.42, 0.36);

/// New marbles get their mesh, a `Transform` at their place and interpolation.
fn dress_marbles(
    mut commands: Commands,
    look: Option<Res<MarbleLook>>,
    marbles: Query<(Entity, &Position), (With<PlayerMarble>, Without<Mesh3d>)>,
) {
    let Some(look) = look else { return };
    for (e, p) in &marbles {
        commands.entity(e).insert((
            Mesh3d(look.0.clone()),
            MeshMaterial3d(look.1.clone()),
            Transform::from_translation(p.0),
            TransformInterpolation,
        ));
    }
}

/// Keys and the first gamepad's left stick (or the autoplay script) into the tilt input.
fn read_input(
    keys: Res<ButtonInput<KeyCode>>,
    gamepads: Query<&Gamepad>,
    args: Res<Args>,
    time: Res<Time>,
    mut input: ResMut<TiltInput>,
) {
    if args.autoplay {
        // Right along the first row, then back a little: the marble in motion, the board
        // tilted, for the screenshot.
        let t = time.elapsed_secs();
        input.0 = if t < 1.5 {
            Vec2::ZERO
        } else if t < 2.6 {
            Vec2::new(0.8, -0.15)
        } else {
            Vec2::new(-0.5, 0.2)
        };
        return;
    }
    let key = |a: KeyCode, b: KeyCode| keys.pressed(a) || keys.pressed(b);
    let mut v = Vec2::new(
        key(KeyCode::ArrowRight, KeyCode::KeyD) as i32 as f32
            - key(KeyCode::ArrowLeft, KeyCode::KeyA) as i32 as f32,
        key(KeyCode::ArrowUp, KeyCode::KeyW) as i32 as f32
            - key(KeyCode::ArrowDown, KeyCode::KeyS) as i32 as f32,
    );
    if let Some(pad) = gamepads.iter().next() {
        let stick = pad.left_stick();
        if stick.length() > 0.12 {
            v = stick;
        }
    }
    input.0 = v.clamp_length_max(1.0);
}

fn keys(
    keys: Res<ButtonInput<KeyCode>>,
    mut draw: ResMut<MarbleDebugDraw>,
    mut set: MessageWriter<SetMarbles>,
    marbles: Query<(), With<PlayerMarble>>,
    mut exit: MessageWriter<AppExit>,
) {
    if keys.just_pressed(KeyCode::F1) {
        draw.enabled = !draw.enabled;
    }
    let n = marbles.iter().count();
    if keys.just_pressed(KeyCode::KeyM) {
        set.write(SetMarbles(if n > 1 { 1 } else { MANY }));
    }
    if keys.just_pressed(KeyCode::KeyR) {
        set.write(SetMarbles(n));
    }
    if keys.just_pressed(KeyCode::Escape) {
        exit.write(AppExit::Success);
    }
}

/// The camera eases towards a point between the marbles' centre and the board's, so that
/// the way ahead stays in view.
fn follow_camera(
    time: Res<Time>,
    level: Res<Level>,
    marbles: Query<&Transform, (With<PlayerMarble>, Without<Follow>)>,
    boards: Query<&Position, With<Board>>,
    mut camera: Query<(&mut Transform, &mut Follow)>,
) {
    let (mut sum, mut n) = (Vec3::ZERO, 0.0);
    for t in &marbles {
        if t.translation.y > -0.2 {
            sum += t.translation;
            n += 1.0;
        }
    }
    let Ok((mut transform, mut follow)) = camera.single_mut() else {
        return;
    };
    let centre = boards.get(level.board).map_or(level.pivot, |p| p.0);
    if n > 0.0 {
        let k = 1.0 - (-4.0 * time.delta_secs()).exp();
        follow.0 = follow.0.lerp((sum / n).lerp(centre, 0.4), k);
    }
    // Many marbles: stand back to see the board.
    let back = if n > 1.0 { 1.8 } else { 1.0 };
    *transform =
        Transform::from_translation(follow.0 + CAMERA_OFFSET * back).looking_at(follow.0, Vec3::Y);
}

fn setup_hud(mut commands: Commands) {
    commands.spawn((
        Text::new(""),
        TextFont {
            font_size: FontSize::Px(20.0),
            ..default()
        },
        TextColor(Color::srgb(0.92, 0.94, 0.97)),
        Node {
            position_type: PositionType::Absolute,
            top: px(12),
            left: px(16),
            ..default()
        },
        Hud,
    ));
    commands.spawn((
        Text::new("arrows / WASD / stick: tilt   M: one marble or 300   F1: debug drawing   R: restart   Esc: quit"),
        TextFont {
            font_size: FontSize::Px(15.0),
            ..default()
        },
        TextColor(Color::srgb(0.65, 0.7, 0.78)),
        Node {
            position_type: PositionType::Absolute,
            bottom: px(10),
            left: px(16),
            ..default()
        },
    ));
}

fn update_hud(
    score: Res<Score>,
    tilt: Res<Tilt>,
    marbles: Query<(), With<PlayerMarble>>,
    frames: Res<FrameCount>,
    mut hud: Query<&mut Text, With<Hud>>,
) {
    let Ok(mut text) = hud.single_mut() else {
        return;
    };
    let best = score
        .best
        .map_or(String::new(), |b| format!("   best {b:.1} s"));
    **text = format!(
        "time {:5.1} s   home {}   lost {}{best}\n{} marble{}   tilt {:4.1} deg   {:.0} fps",
        score.time,
        score.home,
        score.lost,
        marbles.iter().count(),
        if marbles.iter().count() == 1 { "" } else { "s" },
        tilt.0.length().to_degrees(),
        frames.fps,
    );
}

/// A short click, synthesized: a 2 kHz tone dying away over 40 ms, as 16-bit WAV.
#[derive(Resource)]
struct Bump(Handle<AudioSource>);

fn setup_sounds(mut commands: Commands, mut sources: ResMut<Assets<AudioSource>>) {
    const RATE: u32 = 44_100;
    let n = RATE as usize / 25;
    let mut pcm = Vec::with_capacity(2 * n);
    for i in 0..n {
        let t = i as f32 / RATE as f32;
        let s = (t * 2100.0 * std::f32::consts::TAU).sin() * (-t * 90.0).exp();
        pcm.extend_from_slice(&((s * 0.8 * i16::MAX as f32) as i16).to_le_bytes());
    }
    let mut wav = Vec::with_capacity(44 + pcm.len());
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&(36 + pcm.len() as u32).to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&1u16.to_le_bytes()); // mono
    wav.extend_from_slice(&RATE.to_le_bytes());
    wav.extend_from_slice(&(2 * RATE).to_le_bytes());
    wav.extend_from_slice(&2u16.to_le_bytes());
    wav.extend_from_slice(&16u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&(pcm.len() as u32).to_le_bytes());
    wav.extend_from_slice(&pcm);
    let handle = sources.add(AudioSource {
        bytes: Arc::from(wav.into_boxed_slice()),
    });
    commands.insert_resource(Bump(handle));
}

/// A click per impact, louder for harder hits (at most four a frame).
fn bump_sounds(
    mut commands: Commands,
    bump: Option<Res<Bump>>,
    mut impacts: MessageReader<MarbleImpact>,
    mut fates: MessageReader<MarbleFate>,
) {
    let Some(bump) = bump else { return };
    let mut loudest: Vec<f32> = impacts
        .read()
        .map(|i| i.speed)
        .filter(|&s| s > 0.05)
        .collect();
    loudest.sort_by(|a, b| b.total_cmp(a));
    for speed in loudest.into_iter().take(4) {
        commands.spawn((
            AudioPlayer(bump.0.clone()),
            PlaybackSettings::DESPAWN.with_volume(Volume::Linear((speed / 1.5).clamp(0.05, 1.0))),
        ));
    }
    for fate in fates.read() {
        let speed = match fate {
            MarbleFate::Home(_) => 1.6,
            MarbleFate::Lost(_) => 0.6,
        };
        commands.spawn((
            AudioPlayer(bump.0.clone()),
            PlaybackSettings::DESPAWN
                .with_speed(speed)
                .with_volume(Volume::Linear(0.8)),
        ));
    }
}

/// Frames per second over the last second, and the exit after `--exit-after` seconds
/// (with the average frame rate and the recorded poses written).
#[derive(Resource, Default)]
struct FrameCount {
    frames: u64,
    window: (f32, u64),
    fps: f32,
}

fn count_frames(
    time: Res<Time<Real>>,
    args: Res<Args>,
    mut count: ResMut<FrameCount>,
    mut exit: MessageWriter<AppExit>,
) {
    count.frames += 1;
    let now = time.elapsed_secs();
    if now - count.window.0 >= 1.0 {
        count.fps = (count.frames - count.window.1) as f32 / (now - count.window.0);
        count.window = (now, count.frames);
    }
    if let Some(limit) = args.exit_after
        && now >= limit
    {
        println!(
            "{} frames in {now:.1} s: {:.1} fps on average",
            count.frames,
            count.frames as f32 / now
        );
        exit.write(AppExit::Success);
    }
}

/// On the way out, the board's poses of the whole game (`--record`), for `marble run
/// --poses`.
fn save_log(args: Res<Args>, log: Res<TiltLog>, mut exits: MessageReader<AppExit>) {
    if exits.read().next().is_none() {
        return;
    }
    let Some(path) = &args.record else { return };
    let mut out = Vec::new();
    use std::io::Write;
    let _ = writeln!(out, "{}", bevy_marble::output::POSES_HEADER);
    for row in &log.rows {
        let _ = bevy_marble::output::write_pose_row(&mut out, row);
    }
    match std::fs::write(path, out) {
        Ok(()) => println!(
            "{} board poses written to {}",
            log.rows.len(),
            path.display()
        ),
        Err(e) => eprintln!("error: {}: {e}", path.display()),
    }
}
