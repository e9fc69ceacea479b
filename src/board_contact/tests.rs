use super::*;
use crate::geometry::PartShape;
use parry3d::shape::{Cuboid, HalfSpace};

/// The substep the boards of [`boards`] are snapshot for, s.
const H: f32 = 1.0 / 60.0;

/// A tilted walled box (floor and four walls, turning when `spin` is not zero) and a
/// plane below it, as the prepare stage would snapshot them.
fn boards(spin: Vec3) -> BoardCache {
    let wall = |half: Vec3, at: Vec3| (at, Quat::IDENTITY, PartShape::Cuboid(Cuboid::new(half)));
    let walled = BoardGeometry::compound(vec![
        wall(Vec3::new(0.3, 0.01, 0.3), Vec3::new(0.0, -0.01, 0.0)),
        wall(Vec3::new(0.01, 0.03, 0.3), Vec3::new(0.29, 0.03, 0.0)),
        wall(Vec3::new(0.01, 0.03, 0.3), Vec3::new(-0.29, 0.03, 0.0)),
        wall(Vec3::new(0.3, 0.03, 0.01), Vec3::new(0.0, 0.03, 0.29)),
        wall(Vec3::new(0.3, 0.03, 0.01), Vec3::new(0.0, 0.03, -0.29)),
    ]);
    let plane = BoardGeometry::single(PartShape::HalfSpace(HalfSpace::new(Vec3::Y)));
    let snapshot =
        |entity: u32, geometry: BoardGeometry, position: Vec3, rotation: Quat| BoardSnapshot {
            entity: Entity::from_raw_u32(entity).unwrap(),
            geometry: Arc::new(geometry),
            position,
            rotation,
            velocity: Vec3::ZERO,
            angular_velocity: Vec3::ZERO,
            restitution: 0.5,
            friction: 0.5,
            rolling_resistance: 0.0,
            spin_damping: 0.0,
            swept_aabb: None,
            reach: f32::INFINITY,
            pose_version: 0,
            poses: None,
        };
    let mut cache = BoardCache::default();
    let mut tilted = snapshot(
        1,
        walled,
        Vec3::new(0.1, 0.5, -0.2),
        Quat::from_rotation_z(0.02),
    );
    tilted.angular_velocity = spin;
    let local = tilted.geometry.local_aabb().unwrap();
    let world = crate::geometry::transform_aabb(&local, tilted.position, tilted.rotation);
    tilted.swept_aabb = Some(Aabb::new(
        world.mins - Vec3::splat(0.05),
        world.maxs + Vec3::splat(0.05),
    ));
    cache.boards.push(snapshot(
        2,
        plane,
        Vec3::new(0.0, -1.0, 0.0),
        Quat::IDENTITY,
    ));
    cache.boards.push(tilted);
    cache.update_epoch();
    cache
}

struct Lcg(u32);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32 - 0.5
    }
    fn vec(&mut self, scale: Vec3) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * scale
    }
}

const R: f32 = 0.008;

/// A marble centre on the box's floor or against a wall or in a corner, world frame.
fn near_the_box(cache: &BoardCache, rng: &mut Lcg) -> Vec3 {
    on_the_box(&cache.boards[1], rng)
}

/// [`near_the_box`] on the box `b`.
fn on_the_box(b: &BoardSnapshot, rng: &mut Lcg) -> Vec3 {
    let mut y = rng.vec(Vec3::new(0.62, 0.0, 0.62));
    y.y = R + 1e-6 * rng.next();
    y.x = y.x.clamp(-0.28 + R, 0.28 - R);
    y.z = y.z.clamp(-0.28 + R, 0.28 - R);
    b.rotation * y + b.position
}

/// Gathering through a marble's list gives the same touches, bit for bit, as searching
/// the boards, for centres anywhere the list covers (on the floor, against walls, in
/// corners); the lone touch of a list, where it vouches for one, is the search's touch.
#[test]
fn near_lists_gather_what_a_search_finds() {
    let cache = boards(Vec3::ZERO);
    let mut rng = Lcg(7);
    let material = Material {
        restitution: 0.5,
        ..Material::default()
    };
    let (mut lone, mut compared) = (0, 0);
    for _ in 0..400 {
        let anchor = near_the_box(&cache, &mut rng);
        let tol = touch_tolerance(1e-4, R, anchor);
        let mut list = NearPieces::default();
        list.rebuild(&cache, anchor, R, tol, 2.0 * R);
        assert!(list.is_fresh(&cache, anchor, R, 0.0, tol));
        for _ in 0..10 {
            // Within the list's reach and beyond it.
            let mut x = anchor + rng.vec(Vec3::splat(8.0 * R));
            if rng.next() > 0.0 {
                // Onto the floor, where the lone touch applies.
                let b = &cache.boards[1];
                let mut y = b.rotation.conjugate() * (x - b.position);
                y.y = R + 0.5 * tol * rng.next();
                x = b.rotation * y + b.position;
            }
            let (mut searched, mut listed) = (TouchList::default(), TouchList::default());
            gather(
                &cache.boards,
                None,
                0.0,
                x,
                R,
                tol,
                &material,
                Vec3::Y,
                &mut searched,
            );
            gather(
                &cache.boards,
                Some(&list),
                0.0,
                x,
                R,
                tol,
                &material,
                Vec3::Y,
                &mut listed,
            );
            let key = |t: &Touch| {
                (
                    t.piece,
                    t.gap.to_bits(),
                    t.normal.to_array().map(f32::to_bits),
                )
            };
            assert_eq!(
                searched.as_slice().iter().map(key).collect::<Vec<_>>(),
                listed.as_slice().iter().map(key).collect::<Vec<_>>(),
            );
            assert_eq!(searched.is_complete(), listed.is_complete());
            compared += 1;
            if let Some(t) = list.lone_touch(
                &cache.boards,
                x,
                -Vec3::Y,
                Vec3::ZERO,
                0.0,
                R,
                tol,
                &material,
                false,
            ) {
                let [s] = searched.as_slice() else {
                    panic!("lone touch {t:?} where the search found {searched:?}");
                };
                assert_eq!(s.piece, t.piece);
                assert!((s.gap - t.gap).abs() < 1e-7, "{} vs {}", s.gap, t.gap);
                assert!((s.normal - t.normal).length() < 1e-6);
                assert!((s.point - t.point).length() < 1e-6);
                lone += 1;
            }
        }
    }
    assert!(compared == 4000 && lone > 150, "{lone} lone touches");
}

/// [`NearPieces::within`] through a list finds exactly the pieces, with the same gaps,
/// that it finds by searching every board (a default list covers nothing), for centres
/// within the list's reach and beyond it, reaches from a fifth of a radius to three
/// radii, on a still board, after the board was moved and turned since the list was
/// built, and on a turning board (its reach grows with its turn). A second board, a
/// plane cutting through the box just above its floor, is near the same marbles: a
/// list holds one board's pieces, so the other must still be searched.
#[test]
fn near_lists_find_the_speculative_pieces_a_search_finds() {
    let mut rng = Lcg(11);
    let mut found = [0usize; 2];
    let with_plane = |spin: Vec3| {
        let mut cache = boards(spin);
        cache.boards[0].position = Vec3::new(0.0, 0.5 + 1.5 * R, 0.0);
        cache
    };
    for spin in [Vec3::ZERO, Vec3::new(0.3, 0.0, 0.5)] {
        for moved in [false, true] {
            let mut cache = with_plane(spin);
            for _ in 0..200 {
                let anchor = near_the_box(&cache, &mut rng);
                let tol = touch_tolerance(1e-4, R, anchor);
                let mut list = NearPieces::default();
                list.rebuild(&cache, anchor, R, tol, 3.0 * R);
                if moved {
                    let b = &mut cache.boards[1];
                    b.position += Vec3::new(0.2, -0.1, 0.3) * R;
                    b.rotation = Quat::from_rotation_y(0.01) * b.rotation;
                    b.pose_version += 1;
                }
                for _ in 0..5 {
                    let x = anchor + rng.vec(Vec3::splat(4.0 * R));
                    let v = rng.vec(Vec3::splat(0.5));
                    for reach in [0.2 * R, R, 3.0 * R] {
                        let collect = |near: &NearPieces| {
                            let mut out = Vec::new();
                            near.within(
                                &cache,
                                x,
                                v,
                                R,
                                reach,
                                H,
                                |_| false,
                                |piece, point, normal, gap| {
                                    out.push((piece, gap.to_bits(), point, normal))
                                },
                            );
                            out.sort_by_key(|t| (t.0, t.1));
                            out
                        };
                        let searched = collect(&NearPieces::default());
                        assert_eq!(collect(&list), searched, "at {x}, reach {reach}");
                        for t in &searched {
                            found[t.0.board()] += 1;
                        }
                    }
                }
                if moved {
                    cache = with_plane(spin);
                }
            }
        }
    }
    assert!(found[0] > 300 && found[1] > 1000, "pieces found: {found:?}");
}

/// The event loop's result for a marble touching what [`gather`] finds at its start,
/// and its records: the reference the closed forms are checked against.
fn event_loop(
    cache: &BoardCache,
    p: &crate::response::SubstepParams,
    m: &crate::response::MarbleIn,
    tol: f32,
) -> (crate::response::MarbleOut, crate::components::ContactList) {
    let mut touches = TouchList::default();
    gather(
        &cache.boards,
        None,
        0.0,
        m.x0,
        m.r,
        tol,
        &m.material,
        -m.v0,
        &mut touches,
    );
    let mut full = crate::components::ContactList::default();
    let out = crate::response::resolve(
        &cache.boards,
        None,
        p,
        m,
        crate::response::Found::Touching,
        &mut touches,
        &mut full,
    );
    (out, full)
}

/// Substep parameters for case `k` of a closed-form test: the four integrators in turn,
/// continuous collision on.
fn case_params(k: usize, h: f32) -> crate::response::SubstepParams {
    use crate::config::Integrator;
    crate::response::SubstepParams {
        h,
        integrator: [
            Integrator::SemiImplicitEuler,
            Integrator::VelocityVerlet,
            Integrator::Rk4,
            Integrator::ExplicitEuler,
        ][k % 4],
        ccd: true,
        threshold: 0.05,
        tolerance: 1e-4,
        max_impacts: 8,
    }
}

/// A marble's records, bit for bit.
fn records(
    c: &crate::components::ContactList,
) -> Vec<(PieceId, crate::components::ContactKind, u32, [u32; 3])> {
    c.iter()
        .map(|c| {
            (
                c.piece,
                c.kind,
                c.closing_speed.to_bits(),
                c.normal.to_array().map(f32::to_bits),
            )
        })
        .collect()
}

/// The closed form for a marble resting or sliding on one piece
/// ([`crate::response::resolve_resting`]) gives the event loop's result, bit for bit,
/// whenever it applies: on the floor, slow or fast, approaching (a collision) or not,
/// for every integrator; and the still-face path ([`NearPieces::still_face`] and
/// [`crate::response::resolve_resting_still`]), wherever it answers, is the same.
#[test]
fn resting_closed_form_is_the_event_loop() {
    use crate::components::ContactList;
    use crate::response::{MarbleIn, resolve_resting, resolve_resting_still};
    let cache = boards(Vec3::ZERO);
    let b = &cache.boards[1];
    let mut rng = Lcg(5);
    let (mut applied, mut still_faces) = (0, 0);
    for k in 0..4000 {
        let p = case_params(k, H);
        let x0 = near_the_box(&cache, &mut rng);
        let tol = touch_tolerance(p.tolerance, R, x0);
        let speed = if k % 3 == 0 { 0.02 } else { 0.5 };
        let m = MarbleIn {
            x0,
            v0: rng.vec(Vec3::splat(speed)),
            w0: None,
            a: b.rotation * Vec3::new(0.0, -9.81, 0.0) + rng.vec(Vec3::splat(2.0)),
            r: R,
            material: Material {
                restitution: 0.7,
                ..Material::default()
            },
        };
        let mut list = NearPieces::default();
        list.rebuild(&cache, x0, R, tol, 4.0 * R);
        let Some(tc) = list.lone_touch(
            &cache.boards,
            x0,
            m.v0,
            m.a,
            p.h,
            R,
            tol,
            &m.material,
            false,
        ) else {
            continue;
        };
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut fast = ContactList::default();
        let closed = resolve_resting(&cache.boards, &p, &m, &tc, &mut fast);
        // The still-face path, where it answers, is the same touch and the same result.
        if let Some(still) = list.still_face(
            &cache.boards,
            cache.epoch,
            x0,
            m.v0,
            m.a,
            p.h,
            R,
            tol,
            &m.material,
        ) {
            let touch = |t: &Touch| {
                (
                    t.piece,
                    bits(t.point),
                    bits(t.normal),
                    t.gap.to_bits(),
                    t.convex,
                )
            };
            assert_eq!(touch(&still), touch(&tc), "case {k}");
            let mut quick = ContactList::default();
            let same = resolve_resting_still(&cache.boards, &p, &m, &still, &mut quick);
            assert_eq!(
                same.map(|o| (bits(o.d), bits(o.v))),
                closed.map(|o| (bits(o.d), bits(o.v))),
                "case {k}"
            );
            assert_eq!(records(&quick), records(&fast), "case {k}");
            still_faces += 1;
        }
        let Some(closed) = closed else {
            continue;
        };
        let (looped, full) = event_loop(&cache, &p, &m, tol);
        assert_eq!(
            (bits(closed.d), bits(closed.v)),
            (bits(looped.d), bits(looped.v)),
            "case {k}"
        );
        assert_eq!(records(&fast), records(&full), "case {k}");
        applied += 1;
    }
    assert!(applied > 400, "applied {applied} times");
    assert!(
        still_faces > 400,
        "the still-face path answered {still_faces} times"
    );
}

/// The closed form for a spinning marble on one piece
/// ([`crate::response::resolve_rolling`]) gives the event loop's result, bit for bit
/// (position, velocity, spin and records), whenever it applies: rolling, slipping,
/// with and without rolling resistance and spin damping, for every integrator; and it
/// declines when a friction event falls inside the substep.
#[test]
fn rolling_closed_form_is_the_event_loop() {
    use crate::components::ContactList;
    use crate::response::{MarbleIn, resolve_rolling};
    let cache = boards(Vec3::ZERO);
    let b = &cache.boards[1];
    let mut rng = Lcg(7);
    let (mut applied, mut declined) = (0, 0);
    for k in 0..4000 {
        let p = case_params(k, H);
        let x0 = near_the_box(&cache, &mut rng);
        let tol = touch_tolerance(p.tolerance, R, x0);
        let speed = if k % 3 == 0 { 0.02 } else { 0.5 };
        let v0 = rng.vec(Vec3::splat(speed));
        let up = b.rotation * Vec3::Y;
        // Rolling on the floor (no slip), or spinning at random.
        let w0 = if k % 2 == 0 {
            up.cross(v0) / R
        } else {
            rng.vec(Vec3::splat(200.0))
        };
        let m = MarbleIn {
            x0,
            v0,
            w0: Some(w0),
            a: b.rotation * Vec3::new(0.0, -9.81, 0.0) + rng.vec(Vec3::splat(2.0)),
            r: R,
            material: Material {
                restitution: 0.7,
                friction: 0.5,
                rolling_resistance: if k % 5 < 2 { 0.02 } else { 0.0 },
                spin_damping: if k % 7 < 3 { 0.05 } else { 0.0 },
            },
        };
        let mut list = NearPieces::default();
        list.rebuild(&cache, x0, R, tol, 4.0 * R);
        let Some(tc) =
            list.lone_touch(&cache.boards, x0, m.v0, m.a, p.h, R, tol, &m.material, true)
        else {
            continue;
        };
        let mut fast = ContactList::default();
        let Some(closed) = resolve_rolling(&cache.boards, &p, &m, &tc, &mut fast) else {
            declined += 1;
            continue;
        };
        let (looped, full) = event_loop(&cache, &p, &m, tol);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        assert_eq!(
            (bits(closed.d), bits(closed.v), bits(closed.w)),
            (bits(looped.d), bits(looped.v), bits(looped.w)),
            "case {k}"
        );
        assert_eq!(records(&fast), records(&full), "case {k}");
        applied += 1;
    }
    assert!(
        applied > 400 && declined > 20,
        "applied {applied} times, declined {declined}"
    );
}

/// The earliest impact along a path the list covers is the search's, on a still and on
/// a turning board: for marbles near the floor, walls and corners, and for marbles
/// falling from up to 10 radii above them (where the list's clearance passes over its
/// pieces).
#[test]
fn near_lists_find_the_searched_impacts() {
    for spin in [Vec3::ZERO, Vec3::new(0.0, 0.0, 0.4)] {
        let cache = boards(spin);
        let mut rng = Lcg(11);
        let mut impacts = 0;
        for i in 0..4000 {
            let lift = if i < 2000 {
                0.0
            } else {
                R * (6.0 + 8.0 * rng.next())
            };
            let up = cache.boards[1].rotation * Vec3::Y;
            let anchor = near_the_box(&cache, &mut rng) + lift * up;
            let tol = touch_tolerance(1e-4, R, anchor);
            let mut list = NearPieces::default();
            list.rebuild(&cache, anchor, R, tol, 4.0 * R);
            let path = Path {
                t0: 0.0,
                x: anchor + rng.vec(Vec3::splat(R)) + Vec3::new(0.0, 0.5 * R, 0.0),
                v: rng.vec(Vec3::splat(if i < 2000 { 6.0 } else { 1.0 })),
                a: Vec3::new(0.0, -9.81, 0.0),
            };
            let touching = TouchList::default();
            let searched = earliest_impact(&cache.boards, None, &path, H, R, tol, &touching);
            let listed = earliest_impact(&cache.boards, Some(&list), &path, H, R, tol, &touching);
            assert_eq!(
                searched.map(|(t, p)| (t.to_bits(), p)),
                listed.map(|(t, p)| (t.to_bits(), p))
            );
            impacts += usize::from(searched.is_some());
        }
        assert!(impacts > 300, "{impacts} impacts");
    }
}

/// The closed form for a marble riding the scene's only board
/// ([`crate::response::resolve_riding`]) gives the event loop's result, bit for bit
/// (position, velocity and records), whenever it applies: on the floor of a turning or a
/// still box, on the floor against a wall or in a corner, or beside a wall its list holds,
/// resting, sliding or arriving, for every integrator, with continuous collision on and
/// off and with no impacts allowed; and it declines where the list does not cover the
/// substep.
#[test]
fn riding_closed_form_is_the_event_loop() {
    use crate::components::ContactList;
    use crate::response::{MarbleIn, resolve_riding};
    let mut rng = Lcg(13);
    let (mut applied, mut several, mut beside, mut declined) = (0, 0, 0, 0);
    let mut still = 0;
    for spin in [
        Vec3::ZERO,
        Vec3::new(0.0, 0.0, 0.4),
        Vec3::new(0.02, 0.0, 0.0),
        Vec3::new(1.5, 0.3, -0.8),
    ] {
        let mut cache = boards(spin);
        cache.boards.remove(0);
        cache.boards[0] = cache.boards[0].clone().with_poses(H);
        cache.update_epoch();
        let b = &cache.boards[0];
        for k in 0..3000 {
            // Continuous collision off in one case in five, no impacts allowed in one in
            // seven (the loop then searches nothing either).
            let p = crate::response::SubstepParams {
                ccd: k % 5 != 4,
                max_impacts: if k % 7 == 6 { 0 } else { 8 },
                ..case_params(k, H)
            };
            let x0 = on_the_box(b, &mut rng);
            let tol = touch_tolerance(p.tolerance, R, x0);
            // Riding with the board, sliding over it, or arriving at it.
            let speed = [0.0, 0.02, 0.5][k % 3];
            let m = MarbleIn {
                x0,
                v0: b.point_velocity(0.0, x0) + rng.vec(Vec3::splat(speed)),
                w0: None,
                a: b.rotation * Vec3::new(0.0, -9.81, 0.0) + rng.vec(Vec3::splat(2.0)),
                r: R,
                material: Material {
                    restitution: 0.7,
                    ..Material::default()
                },
            };
            let mut list = NearPieces::default();
            list.rebuild(&cache, x0, R, tol, 4.0 * R);
            // What detection hands over: the touches at the start, all convex (the list
            // may hold pieces it does not touch).
            let mut touches = TouchList::default();
            gather(
                &cache.boards,
                Some(&list),
                0.0,
                x0,
                R,
                tol,
                &m.material,
                -m.v0,
                &mut touches,
            );
            if touches.is_empty() || !touches.as_slice().iter().all(|t| t.convex) {
                continue;
            }
            let count = touches.as_slice().len();
            let untouched = list.pieces().iter().any(|&id| !touches.contains(id));
            let mut fast = ContactList::default();
            let Some(closed) =
                resolve_riding(&cache.boards, &list, &p, &m, &mut touches, &mut fast)
            else {
                declined += 1;
                continue;
            };
            let (looped, full) = event_loop(&cache, &p, &m, tol);
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(
                (bits(closed.d), bits(closed.v)),
                (bits(looped.d), bits(looped.v)),
                "spin {spin}, case {k}"
            );
            assert_eq!(records(&fast), records(&full), "spin {spin}, case {k}");
            applied += 1;
            still += usize::from(spin == Vec3::ZERO);
            several += usize::from(count > 1);
            beside += usize::from(untouched);
        }
    }
    assert!(
        applied > 10000 && still > 2500 && several > 2000 && beside > 900 && declined > 200,
        "applied {applied} times ({still} on the still box, {several} on several pieces, \
         {beside} beside a listed piece not touched), declined {declined}"
    );
}

/// [`NearPieces::clearance`], by which gathers and the impact search pass over a list's
/// pieces, is a lower bound on the gap between every piece of the list's board and any
/// centre within the spread asked of it, and at the anchor it is the nearest piece's gap
/// (less its rounding margin): centres above the floor of a tilted box, by its walls and
/// in its corners, up to 10 radii above it, lists built with reaches of 2 to 8 radii,
/// centres up to 4 radii from the anchor with spreads up to 2 radii.
#[test]
fn clearance_bounds_every_gap() {
    let cache = boards(Vec3::ZERO);
    let mut rng = Lcg(17);
    let (mut clear, mut tight) = (0, 0);
    for _ in 0..2000 {
        let b = &cache.boards[1];
        let above = b.rotation * Vec3::new(0.0, 10.0 * R * (rng.next() + 0.5), 0.0);
        let anchor = near_the_box(&cache, &mut rng) + above;
        let tol = touch_tolerance(1e-4, R, anchor);
        let mut list = NearPieces::default();
        let skin = (5.0 + 6.0 * rng.next()) * R;
        list.rebuild(&cache, anchor, R, tol, skin);
        let bi = (0..cache.boards.len())
            .find(|&bi| NearPieces::of(Some(&list), bi).is_some())
            .expect("a list of some board");
        let b = &cache.boards[bi];
        let local = |x: Vec3| b.rotation.conjugate() * (x - b.position);
        let nearest = |y: Vec3| {
            let mut g = f32::INFINITY;
            let all = Aabb::new(Vec3::splat(-100.0), Vec3::splat(100.0));
            b.geometry.for_each_piece(&all, |part, _, piece| {
                g = g.min(b.geometry.proximity(part, piece, y, Vec3::ZERO).distance - R);
            });
            g
        };
        if !list.pieces().is_empty() {
            let at = local(anchor);
            let (c, g) = (list.clearance(at, 0.0), nearest(at));
            assert!(c <= g && g - c < 1e-6, "at the anchor: {c} against {g}");
            tight += 1;
        }
        let centre = local(anchor) + rng.vec(Vec3::splat(8.0 * R));
        let spread = 2.0 * R * (rng.next() + 0.5);
        let c = list.clearance(centre, spread);
        for k in 0..8 {
            let out = rng.vec(Vec3::ONE).normalize_or(Vec3::X);
            let y = centre + out * spread * if k == 0 { 1.0 } else { rng.next() + 0.5 };
            let g = nearest(y);
            assert!(c <= g, "clearance {c} above the gap {g} at {y}");
        }
        clear += usize::from(c > tol);
    }
    assert!(
        clear > 200 && tight > 1000,
        "{clear} clear, {tight} at the anchor"
    );
}

/// A marble that a board's list shows clear of it ([`gather_single`] returns the
/// clearance) touches nothing there, and one whose path [`path_is_clear`] then passes meets
/// nothing in the rest of the substep: the boards searched without the list find no touch
/// and no impact. Marbles in the air over a still and a turning box, the scene's only
/// board, falling, thrown at it, or moving with it, on paths from the substep's start or
/// from a time inside it (as after a collision); many clear at the start meet the box
/// within the substep (the test of the path must not pass them).
#[test]
fn clear_paths_meet_nothing() {
    use crate::board_contact::{gather_single, path_is_clear};
    let mut rng = Lcg(17);
    let (mut clear_start, mut clear_path, mut impacts, mut landing) = (0, 0, 0, 0);
    let mut later = 0;
    for spin in [
        Vec3::ZERO,
        Vec3::new(0.0, 0.0, 0.4),
        Vec3::new(1.5, 0.3, -0.8),
    ] {
        let mut cache = boards(spin);
        cache.boards.remove(0);
        cache.boards[0] = cache.boards[0].clone().with_poses(H);
        cache.update_epoch();
        let b = &cache.boards[0];
        let up = b.rotation * Vec3::Y;
        for k in 0..3000 {
            let lift = R * [0.0, 0.05, 0.5, 2.0, 6.0][k % 5] * (1.0 + rng.next());
            let x = on_the_box(b, &mut rng) + lift * up;
            let tol = touch_tolerance(1e-4, R, x);
            let mut list = NearPieces::default();
            list.rebuild(&cache, x, R, tol, 4.0 * R);
            let speed = [0.0, 0.1, 1.0, 3.0][k % 4];
            // From the substep's start, or from a time inside it without acceleration
            // (a marble's straight path after a collision).
            let t0 = [0.0, 0.0, 0.3 * H, 0.8 * H][(k % 4) ^ ((k / 4) % 4)];
            let path = Path {
                t0,
                x,
                v: b.point_velocity(t0, x) + rng.vec(Vec3::splat(speed)),
                a: if t0 == 0.0 {
                    Vec3::new(0.0, -9.81, 0.0)
                } else {
                    Vec3::ZERO
                },
            };
            let span = H - t0;
            let material = Material::default();
            let mut touches = TouchList::default();
            let clear = gather_single(b, &list, t0, x, R, tol, &material, -path.v, &mut touches);
            let mut searched = TouchList::default();
            gather(
                &cache.boards,
                None,
                t0,
                x,
                R,
                tol,
                &material,
                -path.v,
                &mut searched,
            );
            let impact = earliest_impact(&cache.boards, None, &path, span, R, tol, &searched);
            impacts += usize::from(impact.is_some());
            let Some(clear) = clear else {
                continue;
            };
            assert!(
                touches.is_empty() && searched.is_empty(),
                "spin {spin}, case {k}"
            );
            clear_start += 1;
            landing += usize::from(impact.is_some());
            if path_is_clear(b, &list, &path, span, R, tol, clear) {
                assert_eq!(impact, None, "spin {spin}, case {k}");
                let listed =
                    earliest_impact(&cache.boards, Some(&list), &path, span, R, tol, &touches);
                assert_eq!(listed, None, "spin {spin}, case {k}");
                clear_path += 1;
                later += usize::from(t0 > 0.0);
            }
        }
    }
    assert!(
        clear_start > 5000
            && clear_path > 2000
            && later > 800
            && clear_start - clear_path > 2000
            && landing > 800
            && impacts > 1200,
        "{clear_start} clear at the start ({landing} of them meet the box in the substep), \
         {clear_path} for the substep ({later} from inside it), {impacts} impacts"
    );
}
