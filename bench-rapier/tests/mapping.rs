//! The rapier mapping of bevy_marble's scenes: the board moves as bevy_marble moves it, the
//! materials are mapped, and marbles stay on the board.

use bench_rapier::{board_pose_at, build, build_substepped, inner_half};
use bevy_marble::scenes::{self, BenchScene};

#[test]
fn a_turning_board_turns_about_its_position() {
    let scene = scenes::labyrinth(48);
    assert_ne!(scene.boards[0].angular_velocity, [0.0; 3]);
    let mut world = build(&scene);
    for _ in 0..240 {
        world.step();
    }
    let got = *world.bodies[world.boards[0]].position();
    let want = board_pose_at(&scene.boards[0], 240.0 * scene.dt);
    assert!(
        (got.translation - want.translation).length() < 1e-5,
        "{got:?} vs {want:?}"
    );
    assert!(got.rotation.angle_between(want.rotation) < 1e-4);
}

#[test]
fn smooth_scenes_have_no_friction_and_rolling_ones_do() {
    for rolling in [false, true] {
        let mut scene = scenes::walled_board(4);
        scene.rolling = rolling;
        let world = build(&scene);
        for (_, co) in world.colliders.iter() {
            assert_eq!(co.friction() > 0.0, rolling);
        }
    }
}

#[test]
fn default_marbles_weigh_as_glass() {
    let scene = scenes::walled_board(1);
    let world = build(&scene);
    let mass = world.bodies[world.marbles[0]].mass();
    let r = scene.marbles[0].radius;
    let glass = 2500.0 * 4.0 / 3.0 * std::f32::consts::PI * r.powi(3);
    assert!(
        (mass - glass).abs() < 1e-6 * glass.max(1.0),
        "{mass} vs {glass}"
    );
}

#[test]
fn marbles_stay_in_the_walled_board_and_the_box() {
    for kind in [BenchScene::WalledBoard, BenchScene::PourBox] {
        let mut scene = kind.build(200);
        scene.marble_collisions = true;
        for mut world in [build(&scene), build_substepped(&scene)] {
            for _ in 0..120 {
                world.step();
            }
            let s = world.stats(inner_half(&scene));
            assert_eq!(s.non_finite, 0, "{}", kind.name());
            assert_eq!(s.outside, 0, "{}: {s:?}", kind.name());
            // Resting on the floor: sunk less than a fifth of the radius.
            assert!(
                s.min_y > 0.8 * scene.marbles[0].radius,
                "{}: {s:?}",
                kind.name()
            );
        }
    }
}
