//! GPU collision front half against the CPU: world AABBs (within a stated tolerance; for hulls,
//! meshes and compounds, boxes that hold the CPU's), the LBVH
//! broadphase (exactly the brute-force overlap pairs, both traversals, bitwise repeatable, no
//! pair lost when the key buffer starts far too small, deep degenerate trees), and the pair
//! cache's diff (the CPU `PairCache`'s added, removed and kept pairs exactly).

use crate::gpu_common;

use std::time::Instant;

use gpu_common::{Random, context};
use tumble::dynamics::body::{BodyPose, BodyVelocity, Collider};
use tumble::gpu::GpuVec;
use tumble::math::{Aabb, Quat, Vec3};
use tumble::shape::Shape;
use tumble::stages::aabb::compute_aabbs;
use tumble::stages::aabb::gpu::GpuAabbs;
use tumble::stages::broadphase::gpu::{GpuBroadphase, Traversal};
use tumble::stages::pairs::gpu::{GpuPairDiff, NEW_PAIR, PairDiff};
use tumble::stages::pairs::{PairCache, pair_key};

fn unit(random: &mut Random) -> f32 {
    (random.next_u32() >> 8) as f32 / (1u32 << 24) as f32
}

fn between(random: &mut Random, low: f32, high: f32) -> f32 {
    low + (high - low) * unit(random)
}

fn vector(random: &mut Random, half: f32) -> Vec3 {
    Vec3::new(
        between(random, -half, half),
        between(random, -half, half),
        between(random, -half, half),
    )
}

fn rotation(random: &mut Random) -> Quat {
    let q = Quat::from_xyzw(
        between(random, -1.0, 1.0),
        between(random, -1.0, 1.0),
        between(random, -1.0, 1.0),
        between(random, -1.0, 1.0),
    );
    if q.length_squared() < 1e-4 {
        Quat::IDENTITY
    } else {
        q.normalize()
    }
}

/// Two children off the origin, one turned: its box about the origin is looser than its own.
fn off_centre_compound(random: &mut Random) -> Shape {
    use tumble::math::Transform;
    use tumble::shape::CompoundChild;
    let ball = CompoundChild {
        shape: Shape::sphere(between(random, 0.05, 1.0)),
        pose: Transform::from_position(vector(random, 2.0)),
    };
    let block = CompoundChild {
        shape: Shape::cuboid(Vec3::new(0.5, 0.2, 0.1)),
        pose: Transform::new(vector(random, 2.0), rotation(random)),
    };
    Shape::compound(vec![ball, block]).unwrap()
}

/// Every overlapping pair (touching counts) with at least one dynamic body, sorted: a sweep
/// along x, which tests exactly the pairs an all-pairs loop would keep.
fn brute_force(aabbs: &[Aabb], is_static: &[bool]) -> Vec<u64> {
    let mut order: Vec<usize> = (0..aabbs.len()).collect();
    order.sort_by(|&a, &b| aabbs[a].min.x.total_cmp(&aabbs[b].min.x));
    let mut keys = Vec::new();
    for (position, &a) in order.iter().enumerate() {
        for &b in &order[position + 1..] {
            if aabbs[b].min.x > aabbs[a].max.x {
                break;
            }
            if !(is_static[a] && is_static[b]) && aabbs[a].overlaps(&aabbs[b]) {
                keys.push(pair_key(a as u32, b as u32));
            }
        }
    }
    keys.sort_unstable();
    keys
}

/// A random scene of `count` AABBs, about a fifth static, a ground plane's box among the
/// statics when there are at least 2 bodies; on average a few overlaps per body.
fn scene(count: usize, seed: u64) -> (Vec<Aabb>, Vec<bool>) {
    let mut random = Random::new(seed);
    let half_world = 0.8 * (count.max(1) as f32).cbrt();
    let mut aabbs = Vec::with_capacity(count);
    let mut is_static = Vec::with_capacity(count);
    for body in 0..count {
        let fixed = random.below(5) == 0 || (count >= 2 && body == count / 2);
        if fixed && body == count / 2 {
            // A ground plane's box: unbounded but below y = -half_world / 2.
            let extent = tumble::shape::PLANE_AABB_EXTENT;
            aabbs.push(Aabb::new(
                Vec3::splat(-extent),
                Vec3::new(extent, -half_world / 2.0, extent),
            ));
        } else {
            let centre = vector(&mut random, half_world);
            let half = Vec3::new(
                between(&mut random, 0.1, 1.0),
                between(&mut random, 0.1, 1.0),
                between(&mut random, 0.1, 1.0),
            );
            aabbs.push(Aabb::from_center_half_extents(centre, half));
        }
        is_static.push(fixed);
    }
    (aabbs, is_static)
}

#[test]
fn aabbs_match_cpu() {
    let context = context();
    let mut random = Random::new(11);
    // One stage for all sizes: its device copies are reused, growing and shrinking.
    let mut stage = GpuAabbs::new();
    for count in [0usize, 1, 2, 100, 10_000, 257] {
        let mut poses = Vec::new();
        let mut velocities = Vec::new();
        let mut colliders = Vec::new();
        for body in 0..count {
            let shape = match random.below(8) {
                0 => Shape::sphere(between(&mut random, 0.05, 2.0)),
                1 => Shape::capsule(
                    between(&mut random, 0.05, 1.0),
                    between(&mut random, 0.1, 2.0),
                ),
                2 | 3 => Shape::cuboid(Vec3::new(
                    between(&mut random, 0.05, 2.0),
                    between(&mut random, 0.05, 2.0),
                    between(&mut random, 0.05, 2.0),
                )),
                // Shapes the kernel bounds by a box about the body origin (see below).
                5 => {
                    let offset = vector(&mut random, 1.0);
                    let points: Vec<Vec3> = tumble::scene::barrel_points()
                        .into_iter()
                        .map(|p| p + offset)
                        .collect();
                    Shape::convex_hull(&points).unwrap()
                }
                6 => off_centre_compound(&mut random),
                7 => Shape::trimesh(
                    tumble::shape::TriMesh::new(
                        vec![
                            Vec3::new(5.0, 1.0, -2.0),
                            Vec3::new(5.0, 1.0, 2.0),
                            Vec3::new(9.0, 1.0, -2.0),
                            Vec3::new(9.0, 1.0, 2.0),
                        ],
                        vec![[0, 1, 2], [2, 1, 3]],
                    )
                    .unwrap(),
                ),
                // Planes: axis-aligned (bounded on that axis) and tilted (unbounded).
                _ => match body % 3 {
                    0 => Shape::plane(Vec3::Y, between(&mut random, -5.0, 5.0)),
                    1 => Shape::plane(-Vec3::X, between(&mut random, -5.0, 5.0)),
                    _ => Shape::plane(Vec3::new(1.0, 2.0, 0.5), 1.0),
                },
            };
            let is_plane = matches!(shape, Shape::Plane(_));
            poses.push(BodyPose::new(
                vector(&mut random, 100.0),
                if is_plane {
                    Quat::IDENTITY
                } else {
                    rotation(&mut random)
                },
            ));
            velocities.push(BodyVelocity::new(
                if is_plane {
                    Vec3::ZERO
                } else {
                    vector(&mut random, 20.0)
                },
                vector(&mut random, 5.0),
            ));
            colliders.push(Collider {
                shape,
                friction: 0.5,
                restitution: 0.0,
            });
        }
        let (margin, dt) = (0.02, 1.0 / 60.0);
        let mut exact = Vec::new();
        compute_aabbs(&poses, &velocities, &colliders, margin, dt, &mut exact);
        // Hulls, meshes and compounds have no vertices on the GPU: the kernel turns the box of
        // half extents `ColliderData::params` about the body origin, as the CPU turns a cuboid.
        let boxed: Vec<Collider> = colliders
            .iter()
            .map(|collider| match collider.shape {
                Shape::ConvexHull(_) | Shape::TriMesh(_) | Shape::Compound(_) => Collider {
                    shape: Shape::cuboid(collider.data().params.truncate()),
                    ..collider.clone()
                },
                _ => collider.clone(),
            })
            .collect();
        let mut expected = Vec::new();
        compute_aabbs(&poses, &velocities, &boxed, margin, dt, &mut expected);
        // Tolerance: both executors compute the same expressions, but a GPU may fuse a
        // multiply-add or order a dot product differently; each coordinate is a sum of a few
        // rounded terms no larger than the body's position, shape extent, motion and margin, so
        // it can differ by a few f32 roundings (ε = 2^-23) of their sum. The bounding box and
        // the shape's own box round apart as much where they touch (a flat mesh's face).
        let tolerance = |body: usize| {
            let scale = poses[body].position.abs().max_element()
                + boxed[body].shape.bounding_radius()
                + velocities[body].linear.abs().max_element() * dt
                + margin
                + 1.0;
            16.0 * f32::EPSILON * scale
        };
        for (body, (bound, cpu)) in expected.iter().zip(&exact).enumerate() {
            let slack = Vec3::splat(tolerance(body));
            assert!(
                (bound.min - slack).cmple(cpu.min).all()
                    && (bound.max + slack).cmpge(cpu.max).all(),
                "body {body}: the bounding box {bound:?} does not hold {cpu:?}"
            );
        }
        let mut found = Vec::new();
        stage
            .run(
                &context,
                &poses,
                &velocities,
                &colliders,
                margin,
                dt,
                &mut found,
            )
            .expect("gpu aabbs");
        assert_eq!(found.len(), count);
        for (body, (gpu, cpu)) in found.iter().zip(&expected).enumerate() {
            let tolerance = tolerance(body);
            for (g, c) in [(gpu.min, cpu.min), (gpu.max, cpu.max)] {
                // Plane boxes hold ±PLANE_AABB_EXTENT exactly on both sides.
                assert!(
                    (g - c).abs().max_element() <= tolerance.max(c.abs().max_element() * 1e-7),
                    "body {body} of {count}: gpu {gpu:?} cpu {cpu:?}"
                );
            }
        }
    }
}

fn gpu_pairs(
    broadphase: &mut GpuBroadphase,
    traversal: Traversal,
    aabbs: &[Aabb],
    is_static: &[bool],
) -> Vec<u64> {
    let context = context();
    broadphase.set_traversal(traversal);
    broadphase
        .find_pairs(&context, aabbs, is_static)
        .expect("gpu broadphase")
}

#[test]
fn pairs_match_brute_force() {
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    for (seed, count) in [0usize, 1, 2, 3, 100, 257, 10_000].into_iter().enumerate() {
        let (aabbs, is_static) = scene(count, 100 + seed as u64);
        let expected = brute_force(&aabbs, &is_static);
        if count >= 100 {
            assert!(expected.len() > count, "the scene has pairs to find");
        }
        for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
            let found = gpu_pairs(&mut broadphase, traversal, &aabbs, &is_static);
            assert_eq!(found, expected, "{traversal:?}, {count} bodies");
            // Run again: bitwise the same.
            let again = gpu_pairs(&mut broadphase, traversal, &aabbs, &is_static);
            assert_eq!(again, found, "{traversal:?}, {count} bodies, second run");
        }
    }
}

/// A walk appends its pairs sixteen at a time (`lbvh_traverse.wgsl`): bodies piled on one
/// another, so that the first of them has 59 pairs to append, the next 58, and so on, besides
/// a random scene.
#[test]
fn bodies_with_many_pairs_append_them_all() {
    let (mut aabbs, mut is_static) = scene(300, 11);
    let mut random = Random::new(12);
    for _ in 0..60 {
        let centre = Vec3::splat(50.0) + vector(&mut random, 0.1);
        aabbs.push(Aabb::from_center_half_extents(centre, Vec3::splat(0.5)));
        is_static.push(false);
    }
    let expected = brute_force(&aabbs, &is_static);
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
        let found = gpu_pairs(&mut broadphase, traversal, &aabbs, &is_static);
        assert_eq!(found, expected, "{traversal:?}");
    }
}

/// Between two whole builds the dynamic tree keeps its leaf order and is only refit to the
/// bodies' boxes (`REFITS_PER_BUILD`): bodies moving step after step, the pairs found are the
/// brute force's at every step, on both walks.
#[test]
fn trees_refit_between_builds_find_the_moved_pairs() {
    let (mut aabbs, is_static) = scene(2000, 13);
    let mut random = Random::new(14);
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    for step in 0..9 {
        for (aabb, &fixed) in aabbs.iter_mut().zip(&is_static) {
            if !fixed {
                let offset = vector(&mut random, 0.4);
                *aabb = Aabb::new(aabb.min + offset, aabb.max + offset);
            }
        }
        let expected = brute_force(&aabbs, &is_static);
        let traversal = [Traversal::HistoryFlags, Traversal::Ropes][step % 2];
        let found = gpu_pairs(&mut broadphase, traversal, &aabbs, &is_static);
        assert_eq!(found, expected, "step {step}, {traversal:?}");
    }
}

/// Past 65 536 bodies a packed key (lower << 17 | higher) spans both words of the sort key.
#[test]
fn pairs_past_16_bit_body_indices() {
    let (aabbs, is_static) = scene(70_000, 9);
    let expected = brute_force(&aabbs, &is_static);
    assert!(expected.iter().any(|&key| key >> 32 >= 1 << 15));
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    let found = gpu_pairs(&mut broadphase, Traversal::Ropes, &aabbs, &is_static);
    assert_eq!(found, expected);
}

#[test]
fn all_static_or_all_dynamic() {
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    let (aabbs, _) = scene(300, 7);
    for fixed in [false, true] {
        let is_static = vec![fixed; aabbs.len()];
        let expected = brute_force(&aabbs, &is_static);
        assert_eq!(expected.is_empty(), fixed);
        for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
            let found = gpu_pairs(&mut broadphase, traversal, &aabbs, &is_static);
            assert_eq!(found, expected, "{traversal:?}, all static: {fixed}");
        }
    }
}

/// The key buffer starts 1 key long, far below the pair count: the first run overflows, the
/// buffers grow and the rerun loses nothing.
#[test]
fn tiny_capacity_grows_and_loses_nothing() {
    let context = context();
    let (aabbs, is_static) = scene(2000, 31);
    let expected = brute_force(&aabbs, &is_static);
    assert!(expected.len() >= 10, "at least 10 times the capacity");
    for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
        let mut broadphase = GpuBroadphase::new(&context).expect("broadphase");
        broadphase.set_capacity(&context, 1).expect("capacity");
        broadphase.set_traversal(traversal);
        let found = broadphase
            .find_pairs(&context, &aabbs, &is_static)
            .expect("gpu broadphase");
        assert_eq!(found, expected, "{traversal:?}");
        assert!(broadphase.capacity() >= expected.len());
    }
}

/// Static bodies that move between calls rebuild the static tree; dynamic bodies moving alone
/// reuse it.
#[test]
fn static_tree_follows_changes() {
    let mut broadphase = GpuBroadphase::new(&context()).expect("broadphase");
    let (mut aabbs, is_static) = scene(500, 41);
    for round in 0..4 {
        let expected = brute_force(&aabbs, &is_static);
        let found = gpu_pairs(&mut broadphase, Traversal::HistoryFlags, &aabbs, &is_static);
        assert_eq!(found, expected, "round {round}");
        let shift = Vec3::new(0.7, -0.3, 0.4);
        for (aabb, &fixed) in aabbs.iter_mut().zip(&is_static) {
            // Rounds 0 and 2 move only dynamic bodies, rounds 1 and 3 move everything.
            if !fixed || round % 2 == 1 {
                *aabb = Aabb::new(aabb.min + shift, aabb.max + shift);
            }
        }
    }
}

/// Morton codes 2^k (one leaf split off per code bit: 30 levels) above 64 bodies sharing code
/// 0 (6 more levels of index ties): a 37-level tree, deeper than the history flags' 32 levels.
#[test]
fn degenerate_deep_tree() {
    let mut aabbs = Vec::new();
    // Quantized centres are (centre - min) · 1024 / 1023 in a 1023-wide scene: 2^k stays 2^k.
    for k in 0..30u32 {
        let mut centre = Vec3::ZERO;
        // Bit k of a code is bit k / 3 of axis z, y, x for k % 3 = 0, 1, 2.
        centre[2 - (k % 3) as usize] = (1u32 << (k / 3)) as f32;
        aabbs.push(Aabb::from_center_half_extents(centre, Vec3::splat(0.6)));
    }
    aabbs.push(Aabb::from_center_half_extents(
        Vec3::splat(1023.0),
        Vec3::splat(0.5),
    ));
    for tie in 0..64 {
        // Tiny boxes at the origin cell, overlapping in a chain along y.
        let centre = Vec3::new(0.0, tie as f32 * 0.01, 0.0);
        aabbs.push(Aabb::from_center_half_extents(centre, Vec3::splat(0.006)));
    }
    let is_static = vec![false; aabbs.len()];
    let expected = brute_force(&aabbs, &is_static);
    let context = context();
    let mut broadphase = GpuBroadphase::new(&context).expect("broadphase");
    for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
        broadphase.set_traversal(traversal);
        let found = broadphase
            .find_pairs(&context, &aabbs, &is_static)
            .expect("gpu broadphase");
        assert_eq!(found, expected, "{traversal:?}");
    }
    let depth = broadphase.dynamic_tree_depth(&context).expect("depth");
    assert!(depth > 32, "the tree is {depth} deep");
}

/// Wall time of both traversals at 10 000 bodies: trees built once, then the pair search
/// (fill, traversal, key sort) submitted and waited for. Prints only: on a CPU driver the
/// numbers say that it works, not how fast a GPU is.
#[test]
fn time_traversals_at_10k() {
    let (aabbs, is_static) = scene(10_000, 77);
    let context = context();
    let mut broadphase = GpuBroadphase::new(&context).expect("broadphase");
    let expected = broadphase
        .find_pairs(&context, &aabbs, &is_static)
        .expect("gpu broadphase");
    let aabb_buffer = GpuVec::from_slice(&context, "aabbs", &aabbs).expect("upload");
    let median_ms = |encode: &mut dyn FnMut(&mut wgpu::ComputePass<'_>)| {
        let mut times: Vec<f64> = (0..7)
            .map(|_| {
                let start = Instant::now();
                context.submit_pass("timed", |pass| encode(pass));
                context.wait().expect("wait");
                start.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        times.sort_by(f64::total_cmp);
        times[3]
    };
    let build = median_ms(&mut |pass| {
        broadphase
            .encode_trees(&context, pass, &aabb_buffer)
            .expect("encode")
    });
    println!("dynamic tree build median {build:.2} ms, 10 000 bodies");
    for traversal in [Traversal::HistoryFlags, Traversal::Ropes] {
        broadphase.set_traversal(traversal);
        let search =
            median_ms(&mut |pass| broadphase.encode_pairs(&context, pass).expect("encode"));
        let count = broadphase.pair_count(&context).expect("count");
        assert_eq!(count, expected.len(), "{traversal:?}");
        println!(
            "{traversal:?}: pair search median {search:.2} ms, {count} pairs, 10 000 bodies, {}",
            context.describe()
        );
    }
}

/// The device-resident chain in one submission: bodies → GPU AABBs → broadphase → keys, then
/// static bodies moved with the static tree invalidated. Checked against brute force on the
/// AABBs the GPU computed.
#[test]
fn aabbs_to_pairs_on_the_device() {
    let context = context();
    let mut random = Random::new(61);
    let count = 2000;
    let mut poses = Vec::new();
    let mut velocities = Vec::new();
    let mut colliders = Vec::new();
    let mut is_static = Vec::new();
    let half_world = 0.8 * (count as f32).cbrt();
    for body in 0..count {
        let fixed = body % 7 == 0;
        let shape = if body == 0 {
            Shape::plane(Vec3::Y, -half_world / 2.0)
        } else if body % 2 == 0 {
            Shape::sphere(between(&mut random, 0.1, 0.8))
        } else {
            Shape::cuboid(Vec3::splat(between(&mut random, 0.1, 0.6)))
        };
        poses.push(BodyPose::new(
            if body == 0 {
                Vec3::ZERO
            } else {
                vector(&mut random, half_world)
            },
            if body == 0 {
                Quat::IDENTITY
            } else {
                rotation(&mut random)
            },
        ));
        velocities.push(BodyVelocity::new(
            if fixed {
                Vec3::ZERO
            } else {
                vector(&mut random, 3.0)
            },
            Vec3::ZERO,
        ));
        colliders.push(Collider {
            shape,
            friction: 0.5,
            restitution: 0.0,
        });
        is_static.push(fixed);
    }
    let data: Vec<_> = colliders.iter().map(Collider::data).collect();
    let mut pose_buffer = GpuVec::from_slice(&context, "poses", &poses).expect("upload");
    let velocity_buffer = GpuVec::from_slice(&context, "velocities", &velocities).expect("upload");
    let collider_buffer = GpuVec::from_slice(&context, "colliders", &data).expect("upload");
    let mut aabb_buffer = GpuVec::with_capacity(&context, "aabbs", count).expect("alloc");
    let mut stage = GpuAabbs::new();
    let mut broadphase = GpuBroadphase::new(&context).expect("broadphase");
    broadphase.set_bodies(&context, &is_static).expect("bodies");
    for round in 0..2 {
        loop {
            context
                .submit_pass("front half", |pass| {
                    stage.encode(
                        &context,
                        pass,
                        &pose_buffer,
                        &velocity_buffer,
                        &collider_buffer,
                        0.02,
                        1.0 / 60.0,
                        &mut aabb_buffer,
                    )?;
                    broadphase.encode(&context, pass, &aabb_buffer)
                })
                .expect("encode");
            if !broadphase.check_capacity(&context).expect("count") {
                break;
            }
        }
        let aabbs = aabb_buffer.download(&context).expect("aabbs");
        let expected = brute_force(&aabbs, &is_static);
        let keys = broadphase.download_keys(&context).expect("keys");
        assert_eq!(keys, expected, "round {round}");
        // Lift every static body (the plane too) by 1 m.
        for (pose, &fixed) in poses.iter_mut().zip(&is_static) {
            if fixed {
                pose.position.y += 1.0;
            }
        }
        pose_buffer.upload(&context, &poses).expect("upload");
        broadphase.invalidate_static_tree();
    }
}

/// The CPU pair cache's view of old → new: each kept pair carries its old position (stored
/// + 1, so that the default 0 marks an added pair).
fn cpu_diff(old: &[u64], new: &[u64]) -> PairDiff {
    let mut cache = PairCache::<u32>::new();
    cache.update(old);
    for (position, value) in cache.values_mut().iter_mut().enumerate() {
        *value = position as u32 + 1;
    }
    cache.update(new);
    PairDiff {
        old_index: cache
            .values()
            .iter()
            .map(|&value| value.checked_sub(1).unwrap_or(NEW_PAIR))
            .collect(),
        added: cache.added().to_vec(),
        removed: cache.removed().to_vec(),
    }
}

/// `count` distinct sorted keys among the pairs of `bodies` bodies.
fn random_keys(random: &mut Random, count: usize, bodies: u32) -> Vec<u64> {
    let mut keys = std::collections::BTreeSet::new();
    while keys.len() < count {
        let a = random.below(bodies);
        let b = random.below(bodies);
        if a != b {
            keys.insert(pair_key(a, b));
        }
    }
    keys.into_iter().collect()
}

#[test]
fn pair_diff_matches_pair_cache() {
    let context = context();
    let mut random = Random::new(5);
    let mut diff = GpuPairDiff::new(&context).expect("pair diff");
    let shared = random_keys(&mut random, 300, 40);
    let cases: Vec<(Vec<u64>, Vec<u64>)> = vec![
        (Vec::new(), Vec::new()),
        (Vec::new(), shared.clone()),
        (shared.clone(), Vec::new()),
        (shared.clone(), shared.clone()),
        (
            random_keys(&mut random, 1, 3),
            random_keys(&mut random, 1, 3),
        ),
        (
            random_keys(&mut random, 200, 30),
            random_keys(&mut random, 250, 30),
        ),
        (
            random_keys(&mut random, 40_000, 1000),
            random_keys(&mut random, 45_000, 1000),
        ),
    ];
    for (case, (old, new)) in cases.iter().enumerate() {
        let expected = cpu_diff(old, new);
        if case >= 5 {
            assert!(
                !expected.added.is_empty()
                    && !expected.removed.is_empty()
                    && expected.old_index.iter().any(|&index| index != NEW_PAIR),
                "case {case} has adds, removals and kept pairs"
            );
        }
        let found = diff.run(&context, old, new).expect("gpu pair diff");
        assert_eq!(
            found,
            expected,
            "case {case}: {} → {} keys",
            old.len(),
            new.len()
        );
    }
}

/// The diff straight on two broadphases' device buffers, capacity-long with u64::MAX padding.
#[test]
fn pair_diff_on_broadphase_keys() {
    let context = context();
    let (aabbs, is_static) = scene(3000, 51);
    let shift = Vec3::new(0.3, 0.2, -0.1);
    let moved: Vec<Aabb> = aabbs
        .iter()
        .zip(&is_static)
        .map(|(aabb, &fixed)| {
            if fixed {
                *aabb
            } else {
                Aabb::new(aabb.min + shift, aabb.max + shift)
            }
        })
        .collect();
    let mut before = GpuBroadphase::new(&context).expect("broadphase");
    let mut after = GpuBroadphase::new(&context).expect("broadphase");
    let old = before
        .find_pairs(&context, &aabbs, &is_static)
        .expect("gpu broadphase");
    let new = after
        .find_pairs(&context, &moved, &is_static)
        .expect("gpu broadphase");
    assert!(before.capacity() > old.len() && after.capacity() > new.len());
    let mut diff = GpuPairDiff::new(&context).expect("pair diff");
    context
        .submit_pass("pair diff", |pass| {
            diff.encode(&context, pass, before.keys(), after.keys())
        })
        .expect("encode");
    let mut found = diff.read_back(&context, &old, &new).expect("read back");
    assert_eq!(found.old_index.len(), after.capacity());
    assert!(
        found.old_index[new.len()..]
            .iter()
            .all(|&index| index == NEW_PAIR)
    );
    found.old_index.truncate(new.len());
    let expected = cpu_diff(&old, &new);
    assert!(!expected.added.is_empty() && !expected.removed.is_empty());
    assert_eq!(found, expected);
}
