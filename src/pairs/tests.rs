use super::candidates::{candidate_pairs, for_body_pairs};
use super::late::LateSearch;
use super::project::{Centre, PushBlock, Size, project_block, project_pair};
use super::*;

/// The grid reports exactly the pairs whose bound spheres overlap, each once, for
/// mixed sizes (some large) and random positions.
/// The late-pair searches that look only at the marbles the collisions moved (one by
/// one, or through a grid of their own) find exactly the pairs that re-pairing every
/// marble finds, checked at every substep of a pour in which tens to hundreds of
/// marbles are moved per substep.
#[test]
fn late_pair_searches_match_re_pairing_every_marble() {
    let scene = crate::scenes::pour_box(1200);
    let mut sim = crate::simulation::Simulation::from_scene(&scene).unwrap();
    sim.step();
    sim.world_mut()
        .resource_mut::<PairSolver>()
        .cross_check_late = true;
    for _ in 0..20 {
        sim.step();
    }
    let checked = sim.world().resource::<PairSolver>().cross_checked;
    eprintln!("late-pair searches checked (direct, own grid): {checked:?}");
    assert!(
        checked[LateSearch::Direct as usize] > 0 && checked[LateSearch::OwnGrid as usize] > 0,
        "both searches ran: {checked:?}"
    );
}

/// A fixed pseudo-random sequence in [0, 1) from `seed` (a 32-bit LCG).
fn uniform(mut seed: u32) -> impl FnMut() -> f32 {
    move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// The impact stage's screen ([`may_impact_deeply`]) never drops a pair the narrow
/// phase calls a deep impact: random pairs (radii from 0.1 mm to 10 cm, in ratios to
/// 100; near the origin and a kilometre out) apart at the start, moved towards each
/// other by their gap and a few times the depth that counts, or by up to four radii.
#[test]
fn the_impact_screen_keeps_every_deep_impact() {
    let mut uniform = uniform(0x2f6b_51c3);
    let p = PairParams {
        h: 1.0 / 240.0,
        ccd: true,
        threshold: 0.0,
        tolerance: 1e-4,
        iterations: 1,
    };
    let (mut deep, mut near_limit, mut screened_out) = (0, 0, 0);
    for case in 0..200_000 {
        let mut unit =
            || Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5).normalize_or(Vec3::X);
        let (u1, u2, u3) = (unit(), unit(), unit());
        let ra = 1e-4 * 1e3f32.powf(uniform());
        let rb = ra * 10f32.powf(2.0 * uniform() - 1.0);
        let origin = if case % 4 == 0 { 1e3 * u1 } else { 0.1 * u1 };
        // Apart at the start by up to the depth that counts or up to a diameter, then
        // moved towards each other (roughly along the line of centres) by the gap
        // and from minus one to two times the depth that counts more, or by up to
        // four radii.
        let limit = DISCRETE_OVERLAP * ra.min(rb);
        let gap = 2e-4 * (ra + rb)
            + if case % 3 == 0 {
                (ra + rb) * uniform()
            } else {
                limit * uniform()
            };
        let (x0a, x0b) = (origin, origin + (ra + rb + gap) * u2);
        let travel = if case % 2 == 0 {
            (gap + limit * (3.0 * uniform() - 1.0)).max(0.0)
        } else {
            gap + 4.0 * ra.max(rb) * uniform()
        };
        let towards = (-(u2 + 0.3 * u3)).normalize();
        let body = |x0: Vec3, x: Vec3, r: f32| Body {
            x0,
            v: (x - x0) / p.h,
            v0: (x - x0) / p.h,
            mu: 0.0,
            ..resting(0, x, r)
        };
        let bodies = [body(x0a, x0a, ra), body(x0b, x0b + travel * towards, rb)];
        let kept = may_impact_deeply(&bodies, 0, 1, rounding_slack(&bodies));
        screened_out += usize::from(!kept);
        if let Some(row) = narrow(&bodies, 0, 1, &p)
            && deep_impact(&bodies, &row)
        {
            deep += 1;
            near_limit += usize::from(travel - gap < 2.0 * limit);
            assert!(kept, "case {case}: a deep impact screened out: {row:?}");
        }
    }
    assert!(
        deep > 10_000 && near_limit > 1_000 && screened_out > 10_000,
        "all kinds of pair exercised: {deep} deep ({near_limit} near the limit), \
         {screened_out} screened out"
    );
}

/// Four rows of a colour updated together in SIMD lanes give bit for bit what the
/// rows give one after another: velocities, impulses and the running maximum, over
/// random rows, masses, impulses (zero ones among them) and velocities.
#[test]
fn row_blocks_are_four_single_rows() {
    let mut uniform = uniform(0x9e37_79b9);
    let mut rnd = move || uniform() * 2.0 - 1.0;
    for _ in 0..2000 {
        let vel: Vec<Vel> = (0..8)
            .map(|_| Vec4::new(rnd(), rnd(), rnd(), 1.0 + 100.0 * rnd().abs()))
            .collect();
        // Marbles 0..4 against 4..8 in a shuffled order: no two rows share a marble.
        let rows: [PairGs; 4] = std::array::from_fn(|k| {
            let n = Vec3::new(rnd(), rnd(), rnd()).normalize();
            let (i, j) = (k as u32, 4 + ((k as u32 + 1) % 4));
            PairGs {
                i,
                j,
                n,
                k: 1.0 / (vel[i as usize].w + vel[j as usize].w),
                lambda: if rnd() > 0.0 { 0.0 } else { rnd().abs() },
                target: 0.1 * rnd(),
            }
        });
        let (mut one, mut rows_one, mut largest) = (vel.clone(), rows, 0.0f32);
        for r in &mut rows_one {
            largest = r.pass(&mut one, largest);
        }
        let (mut four, mut block) = (vel.clone(), RowBlock::new(&rows));
        let wide = block.pass(&mut four, Vec4::ZERO);
        let bits = |v: &[Vel]| {
            v.iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&one), bits(&four));
        let lambdas = rows_one.map(|r| r.lambda.to_bits());
        assert_eq!(lambdas, block.lambda.to_array().map(f32::to_bits));
        assert_eq!(largest.to_bits(), wide.max_element().to_bits());
    }
}

/// The projection's blocks of four rows push each pair exactly as its row alone does, one
/// after another: random pairs overlapping by up to a third of their radii or apart,
/// some coincident, some marbles with nothing left to move, bit for bit (centres, what is
/// left of each marble's move, which marbles changed), and whether anything moved.
#[test]
fn projection_blocks_are_four_single_rows() {
    let mut uniform = uniform(0x85eb_ca6b);
    let mut rnd = move || uniform() * 2.0 - 1.0;
    let (mut pushed, mut still) = (0, 0);
    for case in 0..2000 {
        let sizes: Vec<Size> = (0..8)
            .map(|_| {
                Vec4::new(
                    0.01 + 0.01 * rnd().abs(),
                    1.0 / (0.01 + rnd().abs()),
                    0.0,
                    0.0,
                )
            })
            .collect();
        let mut centres: Vec<Centre> = vec![Vec4::ZERO; 8];
        // Marbles 0..4 against 4..8 in a shuffled order: no two rows share a marble.
        let pairs: [(usize, usize); 4] = std::array::from_fn(|k| (k, 4 + (k + 1) % 4));
        for (k, &(i, j)) in pairs.iter().enumerate() {
            let left = |r: f32, x: f32| if x > 0.6 { 0.0 } else { r * x.abs() };
            let x = Vec3::new(rnd(), rnd(), rnd());
            let reach = sizes[i].x + sizes[j].x;
            let apart = Vec3::new(rnd(), rnd(), rnd()).normalize() * reach * (1.0 - 0.35 * rnd());
            // Now and then a coincident pair, beside pairs that are not.
            let y = if (4 * case + k) % 97 == 0 {
                x
            } else {
                x + apart
            };
            centres[i] = x.extend(left(sizes[i].x, rnd()));
            centres[j] = y.extend(left(sizes[j].x, rnd()));
        }
        let rows: [PairGs; 4] = pairs.map(|(i, j)| PairGs {
            i: i as u32,
            j: j as u32,
            n: Vec3::new(rnd(), rnd(), rnd()).normalize(),
            k: 1.0 / (sizes[i].y + sizes[j].y),
            lambda: 0.0,
            target: 0.0,
        });
        let (mut one, mut changed_one, mut moved_one) = (centres.clone(), [false; 8], false);
        for r in &rows {
            moved_one |= project_pair(r, &mut one, &sizes, &mut changed_one);
        }
        let (mut four, mut changed_four) = (centres.clone(), [false; 8]);
        let block = PushBlock::new(rows.each_ref());
        let moved_four = project_block(&block, &mut four, &sizes, &mut changed_four);
        let bits = |v: &[Centre]| {
            v.iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&one), bits(&four), "case {case}");
        assert_eq!(changed_one, changed_four, "case {case}");
        assert_eq!(moved_one, moved_four, "case {case}");
        if moved_one {
            pushed += 1;
        } else {
            still += 1;
        }
    }
    assert!(
        pushed > 500 && still > 100,
        "{pushed} pushed, {still} still"
    );
}

/// The projection's order of the pair rows ([`PairSolver::order_pushes`]) takes every
/// row once, never puts two rows of a marble in one level (so a block's lanes share no
/// marble), and keeps each marble's rows in their order: random rows over a few marbles
/// (long chains through each) and over many (wide levels).
#[test]
fn projection_order_keeps_each_marbles_rows_in_order() {
    let mut uniform = uniform(0x27d4_eb2f);
    for (marbles, rows) in [(6, 40), (60, 400), (2000, 6000)] {
        let mut solver = PairSolver {
            bodies: (0..marbles).map(|k| resting(k, Vec3::ZERO, 0.01)).collect(),
            pair_gs: (0..rows)
                .map(|row| {
                    let i = (uniform() * marbles as f32) as u32 % marbles as u32;
                    let j = (i + 1 + (uniform() * (marbles - 1) as f32) as u32) % marbles as u32;
                    PairGs {
                        i: i.min(j),
                        j: i.max(j),
                        n: Vec3::Y,
                        // Tells the rows apart.
                        k: row as f32,
                        lambda: 0.0,
                        target: 0.0,
                    }
                })
                .collect(),
            ..PairSolver::default()
        };
        solver.order_pushes();
        let mut placed = Vec::new();
        let (mut from, mut blocks) = (0, solver.push_blocks.iter());
        for &to in &solver.push_end {
            let of_level = &solver.push_order[from..to as usize];
            let wide = of_level.len() / 4 * 4;
            let mut level: Vec<(u32, u32)> = Vec::new();
            for (b, four) in blocks.by_ref().take(wide / 4).zip(of_level.chunks(4)) {
                for (l, &k) in four.iter().enumerate() {
                    let r = &solver.pair_gs[k as usize];
                    assert_eq!((b.i[l], b.j[l], b.k[l]), (r.i, r.j, r.k), "a block's lane");
                    level.push((r.i, r.j));
                }
            }
            level.extend(of_level[wide..].iter().map(|&k| {
                let r = &solver.pair_gs[k as usize];
                (r.i, r.j)
            }));
            let mut seen: Vec<u32> = level.iter().flat_map(|&(i, j)| [i, j]).collect();
            seen.sort_unstable();
            assert!(
                seen.windows(2).all(|w| w[0] != w[1]),
                "a level shares a marble ({marbles} marbles)"
            );
            placed.extend(level);
            from = to as usize;
        }
        assert!(blocks.next().is_none(), "every block in a level");
        let mut order = solver.push_order.clone();
        order.sort_unstable();
        assert!(
            order.iter().copied().eq(0..rows as u32),
            "every row once ({marbles} marbles)"
        );
        if marbles > 1000 {
            assert!(
                solver.push_blocks.len() > rows / 8,
                "rows go four at a time"
            );
        }
        assert_eq!(placed.len(), rows, "every row once");
        for m in 0..marbles as u32 {
            let own = |list: &mut dyn Iterator<Item = (u32, u32)>| {
                list.filter(|&(i, j)| i == m || j == m).collect::<Vec<_>>()
            };
            let mut order = solver.pair_gs.iter().map(|r| (r.i, r.j));
            assert_eq!(
                own(&mut placed.iter().copied()),
                own(&mut order),
                "marble {m}'s rows out of order"
            );
        }
    }
}

/// The projection ([`PairSolver::project`]) gives, bit for bit, what its passes give one
/// row after another in the rows' order, pair rows first, then board rows: a random
/// crushed pile of 400 marbles of mixed sizes and masses on a floor, every overlapping
/// pair a row (in the marbles' order, as the candidate pairs come), centres, what was
/// changed, and a few marbles left that the pushes move.
#[test]
fn projection_is_the_rows_one_after_another() {
    use super::project::{MAX_PROJECTION, PROJECTION, PROJECTION_PASSES};
    let mut uniform = uniform(0x1656_67b1);
    let n = 400;
    let bodies: Vec<Body> = (0..n)
        .map(|k| {
            let r = 0.01 + 0.005 * uniform();
            let x = Vec3::new(uniform(), 0.3 * uniform(), uniform()) * 0.12;
            Body {
                w: 1.0 / (0.5 + 2.0 * uniform()),
                ..resting(k, x, r)
            }
        })
        .collect();
    let mut pair_gs = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (&bodies[i], &bodies[j]);
            if (b.x - a.x).length() < a.r + b.r {
                pair_gs.push(PairGs {
                    i: i as u32,
                    j: j as u32,
                    n: Vec3::Y,
                    k: 1.0 / (a.w + b.w),
                    lambda: 0.0,
                    target: 0.0,
                });
            }
        }
    }
    let board_push: Vec<BoardPush> = bodies
        .iter()
        .enumerate()
        .filter(|(_, b)| b.x.y < b.r)
        .map(|(i, b)| BoardPush {
            i: i as u32,
            p: Vec3::new(b.x.x, 0.0, b.x.z),
            n: Vec3::Y,
            slop: PAIR_SLOP * b.r,
        })
        .collect();
    assert!(pair_gs.len() > 2 * n && !board_push.is_empty());
    // One row after another.
    let mut x: Vec<Vec3> = bodies.iter().map(|b| b.x).collect();
    let mut left: Vec<f32> = bodies.iter().map(|b| b.r).collect();
    let mut changed = vec![false; n];
    for _ in 0..PROJECTION_PASSES {
        let mut moved = false;
        for c in &pair_gs {
            let (i, j) = (c.i as usize, c.j as usize);
            let (ri, rj) = (bodies[i].r, bodies[j].r);
            let slop = PAIR_SLOP * ri.min(rj);
            let d = x[j] - x[i];
            let dist = d.length();
            let gap = dist - ri - rj;
            if gap < -slop {
                let nn = if dist > 0.0 { d / dist } else { c.n };
                let push = (PROJECTION * (-slop - gap)).min(MAX_PROJECTION * ri.min(rj)) * c.k;
                let pi = (push * bodies[i].w).min(left[i]);
                let pj = (push * bodies[j].w).min(left[j]);
                if pi <= 0.0 && pj <= 0.0 {
                    continue;
                }
                x[i] -= pi * nn;
                x[j] += pj * nn;
                left[i] -= pi;
                left[j] -= pj;
                changed[i] = true;
                changed[j] = true;
                moved = true;
            }
        }
        for c in &board_push {
            let i = c.i as usize;
            let gap = (x[i] - c.p).dot(c.n) - bodies[i].r;
            if gap < -c.slop && left[i] > 0.0 {
                let most = (MAX_PROJECTION * bodies[i].r).min(left[i]);
                let push = (PROJECTION * (-c.slop - gap)).min(most);
                x[i] += push * c.n;
                left[i] -= push;
                changed[i] = true;
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
    let mut solver = PairSolver {
        bodies,
        pair_gs,
        board_push,
        changed: vec![false; n],
        ..PairSolver::default()
    };
    solver.project();
    let bits = |x: &mut dyn Iterator<Item = Vec3>| {
        x.map(|v| v.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    assert_eq!(
        bits(&mut solver.bodies.iter().map(|b| b.x)),
        bits(&mut x.iter().copied())
    );
    assert_eq!(solver.changed, changed);
    let pushed = changed.iter().filter(|&&c| c).count();
    assert!(pushed > n / 2, "{pushed} of {n} pushed");
    assert!(
        solver.push_blocks.len() > solver.pair_gs.len() / 8,
        "rows go four at a time"
    );
}

#[test]
fn grid_pairs_match_brute_force() {
    let mut dense = 0;
    let mut rnd = uniform(12345);
    // Spread wide (hashed cells) and packed (the dense table).
    for case in 0..40 {
        let spread = if case % 2 == 0 { 1.0 } else { 0.15 };
        let n = 50 + 30 * (case / 2);
        let b: Vec<Vec4> = (0..n)
            .map(|k| {
                let r = if k % 37 == 0 {
                    0.2
                } else {
                    0.01 + 0.01 * rnd()
                };
                let p = spread * (Vec3::new(rnd(), 0.3 * rnd(), rnd()) - 0.5);
                p.extend(r)
            })
            .collect();
        let mut grid = Grid::default();
        grid.build(&b);
        dense += grid.dense.is_some() as usize;
        let mut found = Vec::new();
        grid.pairs(&b, |i, j| found.push((i.min(j), i.max(j))));
        let len = found.len();
        found.sort_unstable();
        found.dedup();
        assert_eq!(found.len(), len, "case {case}: a pair reported twice");
        let mut want = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                let (p, q) = (b[i], b[j]);
                let r = p.w + q.w;
                if (p.truncate() - q.truncate()).length_squared() <= r * r {
                    want.push((i as u32, j as u32));
                }
            }
        }
        assert_eq!(found, want, "case {case}");
    }
    assert!(
        dense > 0 && dense < 40,
        "both modes exercised: {dense} dense"
    );
}

/// The grid's pairs come in the order of a walk that looks up every neighbour cell's
/// bucket ([`Grid::pairs_by_bucket`]), in both of its modes: the order of the candidate
/// pairs, and so of the solver's rows, does not depend on how the buckets are found; nor
/// on whether they are found in chunks on the task pool ([`Grid::pairs_into`], with the
/// `parallel` feature), whose pairs are joined in the order of one walk.
#[test]
fn grid_pairs_keep_the_bucket_walk_order() {
    start_pool();
    let mut rnd = uniform(54321);
    let mut chunks = Vec::new();
    let (mut dense, mut pairs) = (0, 0);
    for case in 0..40 {
        let spread = if case % 2 == 0 { 1.0 } else { 0.12 };
        let n = 60 + 40 * (case / 2);
        let b: Vec<Vec4> = (0..n)
            .map(|_| {
                (spread * (Vec3::new(rnd(), 0.3 * rnd(), rnd()) - 0.5)).extend(0.01 + 0.01 * rnd())
            })
            .collect();
        let mut grid = Grid::default();
        grid.build(&b);
        dense += grid.dense.is_some() as usize;
        let (mut fast, mut walked) = (Vec::new(), Vec::new());
        grid.ordinary_pairs(&mut |i, j| fast.push((i, j)));
        grid.pairs_by_bucket(&mut |i, j| walked.push((i, j)));
        assert_eq!(fast, walked, "case {case}");
        let (mut whole, mut joined) = (Vec::new(), Vec::new());
        grid.pairs(&b, |i, j| whole.push((i.min(j), i.max(j))));
        grid.pairs_into(&b, &mut joined, &mut chunks, true);
        assert_eq!(joined, whole, "case {case}: pairs found in chunks");
        pairs += fast.len();
    }
    assert!(
        dense > 10 && dense < 30 && pairs > 100_000,
        "{dense} dense of 40, {pairs} pairs"
    );
}

/// A grid built on no bodies, or never built, has no pairs and no table to read (with
/// `parallel`, the pool's walk over the empty slots asks it all the same).
#[test]
fn an_empty_grid_has_no_pairs() {
    start_pool();
    let mut chunks = Vec::new();
    for built in [false, true] {
        let mut grid = Grid::default();
        if built {
            grid.build(&[]);
        }
        let mut pairs = Vec::new();
        grid.pairs(&[], |i, j| pairs.push((i, j)));
        grid.pairs_into(&[], &mut pairs, &mut chunks, true);
        grid.ordinary_pairs(&mut |i, j| pairs.push((i, j)));
        grid.query(&[], Vec4::new(0.0, 0.0, 0.0, 1.0), |j| pairs.push((j, j)));
        assert!(pairs.is_empty(), "built {built}: {pairs:?}");
    }
}

/// The hashes of a cell and its forward neighbours, taken from per-axis terms, are the
/// cells' own hashes, in [`grid::FORWARD`]'s order, for cells anywhere (at `i32`'s ends
/// the neighbours' indices wrap, as `IVec3::wrapping_add` wraps them).
#[test]
fn forward_hashes_are_the_neighbours_hashes() {
    let mut rnd = uniform(777);
    let ends = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
    for case in 0..2000 {
        let pick = |r: f32| {
            if case % 3 == 0 {
                ends[(r * ends.len() as f32) as usize % ends.len()]
            } else {
                ((r - 0.5) * 2.0e6) as i32
            }
        };
        let c = IVec3::new(pick(rnd()), pick(rnd()), pick(rnd()));
        let (own, forward) = grid::forward_hashes(c);
        assert_eq!(own, grid::hash_cell(c), "cell {c}");
        for (d, h) in grid::FORWARD.iter().zip(forward) {
            assert_eq!(
                h,
                grid::hash_cell(c.wrapping_add(*d)),
                "cell {c}, neighbour {d}"
            );
        }
    }
}

/// Marble `k` (entity `k + 1`) at rest at `x`, radius `r`, unit mass: a body for the
/// broad phase's tests, which read only its place and size.
fn resting(k: usize, x: Vec3, r: f32) -> Body {
    Body {
        entity: Entity::from_raw_u32(k as u32 + 1).unwrap(),
        x,
        x0: x,
        v: Vec3::ZERO,
        v0: Vec3::ZERO,
        w: 1.0,
        r,
        e: 0.5,
        a: Vec3::ZERO,
        d: Vec3::ZERO,
        omega: Vec3::ZERO,
        spins: false,
        mu: 0.5,
    }
}

/// Over many substeps of marbles drifting together, jittering, a few jumping far, a third
/// of them rising through the rest for a while and one leaving, the candidate pairs of
/// [`PairSolver::cover`] hold every pair whose spheres overlap, each once, while the skin
/// is kept (strays paired on their own) and rebuilt, with skins grown for the marbles
/// that move relative to the drift.
#[test]
fn kept_candidates_cover_every_overlapping_pair() {
    let mut uniform = uniform(99);
    let mut rnd = move || uniform() - 0.5;
    let r = 0.008;
    let mut solver = PairSolver::default();
    let n = 600;
    solver.bodies = (0..n)
        .map(|k| {
            let x = Vec3::new(rnd(), 0.3 * rnd(), rnd()) * 0.5;
            resting(k, x, if k % 50 == 0 { 4.0 * r } else { r })
        })
        .collect();
    let (mut kept, mut with_strays, mut grown) = (0, 0, 0);
    for step in 0..200 {
        let drift = Vec3::new(0.004, -0.001, 0.002);
        for (k, b) in solver.bodies.iter_mut().enumerate() {
            let jitter = Vec3::new(rnd(), rnd(), rnd()) * 0.0008;
            b.x += drift + jitter;
            if (k + step) % 97 == 0 {
                b.x += Vec3::new(rnd(), rnd(), rnd()) * 0.05;
            }
            if (60..100).contains(&step) && k % 3 == 0 {
                b.x.y += 0.003;
            }
        }
        if step == 150 {
            solver.bodies.pop();
        }
        let was_valid = solver.skin_valid && solver.bound.len() == solver.bodies.len();
        solver.cover(|b| b.x.extend(1.1 * b.r));
        kept += usize::from(was_valid && solver.drift != Vec3::ZERO);
        with_strays += usize::from(!solver.strays.is_empty());
        let least = |b: &Body| 1.1 * b.r + 1.01 * candidates::SKIN * b.r;
        let mut bounds = solver.bound.iter().zip(&solver.bodies);
        grown += usize::from(solver.drift == Vec3::ZERO && bounds.any(|(w, b)| w.w > least(b)));
        let mut found: Vec<(u32, u32)> = candidate_pairs(
            &solver.candidates,
            &solver.extra,
            &solver.stray,
            &solver.strays,
        )
        .collect();
        let mut overlapping = Vec::new();
        let b = &solver.bodies;
        for i in 0..b.len() {
            for j in i + 1..b.len() {
                let reach = 1.1 * (b[i].r + b[j].r);
                if (b[i].x - b[j].x).length() <= reach {
                    overlapping.push((i as u32, j as u32));
                }
            }
        }
        let len = found.len();
        found.sort_unstable();
        found.dedup();
        assert_eq!(found.len(), len, "step {step}: a pair reported twice");
        for pair in overlapping {
            assert!(
                found.binary_search(&pair).is_ok(),
                "step {step}: {pair:?} missed"
            );
        }
    }
    assert!(
        kept > 100 && with_strays > 50 && grown > 10,
        "kept {kept}, with strays {with_strays}, rebuilt with grown skins {grown}"
    );
}

/// The strays' searches of the bounds find the same pairs in the same order in chunks on
/// the task pool (with the `parallel` feature) as in one walk: 4,000 marbles, of which
/// every tenth moves 2–4 cm after the candidates are found (400 strays, each chunk a few
/// hundred of them).
#[test]
fn stray_pairs_found_in_chunks_keep_their_order() {
    start_pool();
    let mut uniform = uniform(7);
    let mut rnd = move || uniform() - 0.5;
    let r = 0.008;
    let n = 4000;
    let bodies: Vec<Body> = (0..n)
        .map(|k| {
            let x = Vec3::new(rnd(), 0.2 * rnd(), rnd()) * 0.6;
            resting(k, x, r)
        })
        .collect();
    let moves: Vec<Vec3> = (0..n / 10)
        .map(|_| {
            let dir = Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::X);
            dir * (0.03 + 0.02 * rnd())
        })
        .collect();
    let sphere = |b: &Body| b.x.extend(1.1 * b.r);
    let mut found = Vec::new();
    for parallel in [false, true] {
        let mut solver = PairSolver {
            bodies: bodies.clone(),
            ..Default::default()
        };
        solver.cover_with(sphere, parallel);
        for (b, &d) in solver.bodies.iter_mut().step_by(10).zip(&moves) {
            b.x += d;
        }
        solver.cover_with(sphere, parallel);
        assert_eq!(solver.strays.len(), n / 10, "every moved marble strayed");
        found.push(solver.extra.clone());
    }
    assert!(found[0].len() > 100, "{} stray pairs", found[0].len());
    assert_eq!(found[0], found[1], "stray pairs found in chunks");
}

/// The candidate pairs' narrow phase in chunks on the task pool (with the `parallel`
/// feature) sees the pairs of one walk, in its order: 6,000 kept candidates (those with a
/// stray marble left out) and 3,000 strays' pairs, through a selection's indices, cut
/// into chunks of which one spans the two lists, each with its place in the two lists; and
/// whether any pair passes a test is the same either way.
#[test]
fn candidate_pairs_scanned_in_chunks_keep_their_order() {
    start_pool();
    let mut uniform = uniform(11);
    let n = 2000;
    let mut pick = move || ((uniform() * n as f32) as u32).min(n as u32 - 1);
    let candidates: Vec<(u32, u32)> = (0..6000).map(|_| (pick(), pick())).collect();
    let extra: Vec<(u32, u32)> = (0..3000).map(|_| (pick(), pick())).collect();
    let stray: Vec<bool> = (0..n).map(|k| k % 17 == 0).collect();
    let strays: Vec<u32> = (0..n as u32).filter(|&k| stray[k as usize]).collect();
    let local: Vec<u32> = (0..n as u32).rev().collect();
    let strays = (stray.as_slice(), strays.as_slice());
    let mut walked = Vec::new();
    for_body_pairs(&candidates, &extra, strays, Some(&local), |pair| {
        walked.push(pair);
    });
    let pairs = walked.len();
    assert!(pairs > 8000 && pairs < 9000, "{pairs} pairs");
    let (mut chunks, mut placed) = (Vec::new(), Vec::new());
    let each = |at: u32, pair: (u32, u32), out: &mut Vec<(u32, (u32, u32))>| out.push((at, pair));
    scan_body_pairs(
        &candidates,
        &extra,
        strays,
        Some(&local),
        true,
        &mut chunks,
        &mut placed,
        each,
    );
    let scanned: Vec<(u32, u32)> = placed.iter().map(|&(_, pair)| pair).collect();
    assert_eq!(walked, scanned, "candidate pairs scanned in chunks");
    // Each pair's place is where it stands in the candidates, then the strays' pairs.
    assert!(placed.windows(2).all(|w| w[0].0 < w[1].0), "places ascend");
    for &(at, pair) in &placed {
        let at = at as usize;
        let (i, j) = candidates
            .get(at)
            .copied()
            .unwrap_or_else(|| extra[at - candidates.len()]);
        assert_eq!(pair, (local[i as usize], local[j as usize]), "pair at {at}");
    }
    #[cfg(feature = "parallel")]
    assert!(chunks.len() > 1, "the scan was cut into chunks");
    let last = *walked.last().unwrap();
    for (target, expected) in [(last, true), ((n as u32, n as u32), false)] {
        let any = any_body_pair(&candidates, &extra, strays, Some(&local), true, |pair| {
            pair == target
        });
        assert_eq!(any, expected, "any pair equal to {target:?}");
    }
}

/// Bodies for only the marbles of the candidate pairs ([`PairSolver::select_bodies`]) give
/// the bits of bodies for every marble: the walled board with collisions, its marbles
/// sliding into the lower wall's row, and every tenth marble of one row sent fast into its
/// neighbour (deep impacts, after which the impact stage takes every marble), stepped both
/// ways; every marble's position and velocity bits and every recorded contact agree.
#[test]
fn selected_bodies_give_the_bits_of_every_marble() {
    let run = |never_select: bool| {
        let mut scene = crate::scenes::walled_board(2500);
        scene.marble_collisions = true;
        for m in scene.marbles.iter_mut().skip(1200).step_by(10).take(5) {
            m.velocity = [1.5, 0.0, 0.0];
        }
        let mut sim = crate::simulation::Simulation::from_scene(&scene).unwrap();
        sim.world_mut().resource_mut::<PairSolver>().never_select = never_select;
        let mut contacts = Vec::new();
        for _ in 0..90 {
            sim.step();
            let recorded = sim.world().resource::<MarbleContacts>();
            contacts.extend(recorded.as_slice().iter().map(|c| {
                (
                    c.a,
                    c.b,
                    c.normal.to_array().map(f32::to_bits),
                    c.depth.to_bits(),
                    c.kind,
                )
            }));
        }
        let state: Vec<[u32; 6]> = (0..sim.marbles().len())
            .map(|i| {
                let (x, v) = sim.marble_state(i);
                let mut bits = [0; 6];
                for (b, f) in bits
                    .iter_mut()
                    .zip(x.to_array().into_iter().chain(v.to_array()))
                {
                    *b = f.to_bits();
                }
                bits
            })
            .collect();
        let solver = sim.world().resource::<PairSolver>();
        (state, contacts, solver.selections, solver.widened)
    };
    let (selected, selected_contacts, selections, widened) = run(false);
    let (every, every_contacts, none, _) = run(true);
    assert_eq!(none, 0);
    assert!(
        selections > 20 && widened > 0,
        "bodies selected in {selections} stages, every marble taken after a deep impact \
         among them in {widened}"
    );
    assert!(
        selected_contacts
            .iter()
            .any(|c| c.4 == ContactKind::Collision),
        "some marbles collide"
    );
    assert_eq!(selected_contacts, every_contacts, "the same contacts");
    assert_eq!(selected, every, "the same positions and velocities");
}

/// Starts the task pool that the chunked searches run on (with the `parallel` feature).
fn start_pool() {
    #[cfg(feature = "parallel")]
    bevy_tasks::ComputeTaskPool::get_or_init(bevy_tasks::TaskPool::default);
}

/// One substep's next rows of one kind for the warm-start test: each row (key, place)
/// kept in place, ended, or moved to the end (a stray's pair); rows begun beside a kept
/// one, at its place; with `reshuffle`, the order shuffled and the places renumbered (the
/// candidates found afresh). Places ascend. `fresh` makes a new key from a kept one.
fn next_warm_rows(
    rows: &[((u64, u64), u32)],
    uniform: &mut impl FnMut() -> f32,
    reshuffle: bool,
    fresh: impl Fn((u64, u64), f32) -> (u64, u64),
) -> Vec<((u64, u64), u32)> {
    let mut next = Vec::new();
    let mut moved = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for &(k, place) in rows {
        let u = uniform();
        if u < 0.03 || !seen.insert(k) {
            continue; // ended
        }
        if u < 0.05 {
            moved.push(k);
            continue;
        }
        next.push((k, place));
        let new = fresh(k, uniform());
        if uniform() < 0.03 && seen.insert(new) {
            next.push((new, place)); // begun beside it
        }
    }
    let mut last = next.last().map_or(0, |r| r.1);
    if reshuffle {
        for i in (1..next.len()).rev() {
            let j = (uniform() * (i + 1) as f32) as usize % (i + 1);
            next.swap(i, j);
        }
        last = 0;
        for r in next.iter_mut() {
            last += (uniform() * 3.0) as u32;
            r.1 = last;
        }
    }
    for k in moved {
        last += 1;
        next.push((k, last));
    }
    next
}

/// The warm-start impulses that a substep's rows find are what a map from key to the last
/// substep's impulse gives, however the rows change: over 300 substeps of random pair rows
/// (one place each) and board rows (a few to a marble's place), contacts kept in place,
/// ended and begun, rows moved to the end as a stray's pairs are, the whole order
/// shuffled and renumbered as when the candidates are found afresh, impulses zero or
/// positive, impulses put back for marbles that woke (for rows kept and for rows that
/// come back), everything forgotten now and then: each row's impulse against a
/// `HashMap`'s, and every impulse kept (what a marble falling asleep stows) against the
/// map's contents, put-back impulses included. Rows kept in place are found by the walk,
/// not by hashing.
#[test]
fn warm_start_finds_what_a_map_of_the_last_impulses_gives() {
    use super::warm::{Key, Warm};
    let mut uniform = uniform(0x7f4a_7c15);
    let mut warm = Warm::default();
    let mut reference: HashMap<Key, f32> = HashMap::new();
    let pair = |a: u64, b: u64| (a.min(b), a.max(b));
    // Pair keys below 1 << 20; board keys a marble and a piece with its bits flipped.
    let mut pairs: Vec<(Key, u32)> = (0..300u64)
        .map(|k| (pair(k, k + 1), 2 * k as u32))
        .collect();
    let mut boards: Vec<(Key, u32)> = (0..200u64)
        .flat_map(|m| (0..1 + m % 3).map(move |piece| ((m, !piece), m as u32)))
        .collect();
    let mut hits = 0usize;
    for substep in 0..300 {
        let woke = substep % 7 == 3;
        if woke {
            // Marbles that woke: impulses put back for some rows kept and for rows that
            // come back with them (a place of their own at the end).
            for _ in 0..4 {
                let k = pairs[(uniform() * pairs.len() as f32) as usize % pairs.len()].0;
                let lambda = 1.0 + uniform();
                warm.restore(k, lambda);
                reference.insert(k, lambda);
            }
            let back = pair(1 << 19 | substep as u64, 1 << 20);
            let place = pairs.last().map_or(0, |r| r.1) + 1;
            pairs.push((back, place));
            warm.restore(back, 2.0);
            reference.insert(back, 2.0);
            let stowed: HashMap<Key, f32> = warm.iter().collect();
            assert_eq!(stowed, reference, "substep {substep}: kept and put back");
            assert_eq!(warm.iter().count(), reference.len(), "each key once");
        }
        if substep % 97 == 3 {
            warm.clear();
            reference.clear();
        }
        for (rows, is_pairs) in [(&pairs, true), (&boards, false)] {
            let keys: Vec<Key> = rows.iter().map(|r| r.0).collect();
            let places = rows.iter().map(|r| r.1);
            let mut found = vec![0.0f32; rows.len()];
            let set = |k: usize, lambda: f32| found[k] = lambda;
            if is_pairs {
                warm.find_pairs(&keys, places, set);
            } else {
                warm.find_boards(&keys, places, set);
            }
            for (k, key) in keys.iter().enumerate() {
                let expected = reference.get(key).copied().unwrap_or(0.0);
                assert_eq!(
                    found[k].to_bits(),
                    expected.to_bits(),
                    "substep {substep}, row {k}"
                );
                hits += usize::from(expected > 0.0);
            }
        }
        // The solve's impulses, kept for the next substep.
        let mut solve = |rows: &[(Key, u32)]| -> Vec<(Key, u32, f32)> {
            let impulse = |u: f32, v: f32| if u < 0.2 { 0.0 } else { v };
            rows.iter()
                .map(|r| (r.0, r.1, impulse(uniform(), uniform())))
                .collect()
        };
        let (kept_pairs, kept_boards) = (solve(&pairs), solve(&boards));
        warm.keep(
            kept_pairs.iter().copied(),
            kept_boards.iter().copied(),
            0.01,
        );
        reference.clear();
        for &(key, _, lambda) in kept_pairs.iter().chain(&kept_boards) {
            if lambda > 0.0 {
                reference.insert(key, lambda);
            }
        }
        let stowed: HashMap<Key, f32> = warm.iter().collect();
        assert_eq!(stowed, reference, "substep {substep}: every impulse kept");
        // The next substep's rows.
        let reshuffle = substep % 11 == 10;
        let fresh_pair = |k: Key, u: f32| pair(1 << 21 | (u * 4000.0) as u64, k.1);
        pairs = next_warm_rows(&pairs, &mut uniform, reshuffle, fresh_pair);
        let fresh_piece = |k: Key, u: f32| (k.0, !(8 + (u * 4000.0) as u64));
        boards = next_warm_rows(&boards, &mut uniform, reshuffle, fresh_piece);
    }
    assert!(hits > 50_000, "{hits} rows warm started");
    for (kind, w) in [("pair", &warm.pairs), ("board", &warm.boards)] {
        assert!(
            w.walked > 4 * w.hashed,
            "{kind} rows: {} walked, {} hashed",
            w.walked,
            w.hashed
        );
    }
}

/// In a pile the warm start finds most impulses by walking the last substep's rows, not by
/// hashing: the rows' places (`Row::at`, each board row's marble) are set and follow the
/// rows from substep to substep. Bench scene (b) with 300 marbles at 3 substeps, its
/// first second (the pile forms at about half a second).
#[test]
fn a_pile_warm_starts_by_walking_its_rows() {
    let mut scene = crate::scenes::pour_box(300);
    scene.substeps = 3;
    let mut sim = crate::simulation::Simulation::from_scene(&scene).unwrap();
    for _ in 0..60 {
        sim.step();
    }
    let warm = &sim.world().resource::<PairSolver>().warm;
    for (kind, w) in [("pair", &warm.pairs), ("board", &warm.boards)] {
        eprintln!(
            "{kind} rows warm started: {} walked, {} hashed",
            w.walked, w.hashed
        );
        assert!(
            w.walked > 5_000 && w.walked > 5 * w.hashed,
            "{kind} rows: {} walked, {} hashed",
            w.walked,
            w.hashed
        );
    }
}
