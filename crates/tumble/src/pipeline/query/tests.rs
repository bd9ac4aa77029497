//! World queries against brute force over every body, on random worlds that have stepped (so
//! that some bodies have left their fat AABBs) and lost some bodies.

use super::*;
use crate::collision::dbvt::tests::TestRng;
use crate::collision::ray::{RayError, ShapeSweep, cast_shape, cast_sphere};
use crate::dynamics::body::BodyDesc;
use crate::math::{Quat, Transform, vec3};
use crate::pipeline::config::StepConfig;
use crate::shape::Shape;

/// A ground plane, a static box and `count` random spheres, boxes, capsules and hulls in the air,
/// thrown and spun fast, stepped `steps` times; a third of them then removed.
fn random_world(rng: &mut TestRng, count: usize, steps: usize) -> World {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::cuboid(vec3(3.0, 1.0, 3.0))).position(vec3(4.0, 1.0, 0.0)))
        .unwrap();
    let mut handles = Vec::new();
    for index in 0..count {
        let shape = match index % 4 {
            0 => Shape::sphere(rng.range(0.2, 1.0)),
            1 => Shape::cuboid(rng.vec3(0.2, 1.0)),
            2 => Shape::capsule(rng.range(0.2, 0.6), rng.range(0.1, 1.0)),
            _ => Shape::convex_hull(&crate::scene::barrel_points()).unwrap(),
        };
        let axis = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
        let body = BodyDesc::dynamic(shape)
            .position(vec3(0.0, 8.0, 0.0) + rng.vec3(-8.0, 8.0))
            .rotation(Quat::from_axis_angle(axis, rng.range(0.0, 6.0)))
            .linear_velocity(rng.vec3(-10.0, 10.0))
            .angular_velocity(rng.vec3(-20.0, 20.0));
        handles.push(world.add_body(body).unwrap());
    }
    for _ in 0..steps {
        world.step();
    }
    for handle in handles {
        if rng.below(3) == 0 {
            world.remove_body(handle).unwrap();
        }
    }
    world
}

/// Every body's hit, by testing each body's shape.
fn brute_force_hits(world: &World, ray: &Ray, filter: &QueryFilter) -> Vec<RayHit> {
    let mut hits: Vec<RayHit> = world
        .bodies()
        .filter_map(|body| world.ray_hit(body.index(), ray, filter))
        .collect();
    hits.sort_by(|a, b| {
        a.distance
            .total_cmp(&b.distance)
            .then(a.body.index.cmp(&b.body.index))
    });
    hits
}

fn random_ray(rng: &mut TestRng) -> Ray {
    let origin = vec3(0.0, 6.0, 0.0) + rng.vec3(-15.0, 15.0);
    let target = vec3(0.0, 4.0, 0.0) + rng.vec3(-8.0, 8.0);
    let max = if rng.below(4) == 0 {
        f32::INFINITY
    } else {
        rng.range(1.0, 40.0)
    };
    Ray::new(origin, target - origin, max).unwrap()
}

#[test]
fn queries_match_brute_force_on_random_worlds() {
    let mut rng = TestRng::new(77);
    let odd = |body: BodyHandle| body.index() % 2 == 1;
    let mut escaped_seen = 0;
    for (count, steps) in [(0, 0), (1, 3), (40, 10), (300, 20)] {
        let world = random_world(&mut rng, count, steps);
        escaped_seen += world.escaped_bodies().len();
        let some_body = world.bodies().last();
        let filters = [
            QueryFilter::default(),
            QueryFilter::default().exclude_static(),
            QueryFilter::default().exclude_dynamic(),
            QueryFilter {
                exclude_body: some_body,
                predicate: Some(&odd),
                ..QueryFilter::default()
            },
        ];
        let mut all = Vec::new();
        let mut found = Vec::new();
        for case in 0..300 {
            let filter = &filters[case % filters.len()];
            let ray = random_ray(&mut rng);
            let expected = brute_force_hits(&world, &ray, filter);
            world.cast_ray_all(&ray, filter, &mut all);
            assert_eq!(all, expected, "case {case}: all hits");
            assert_eq!(
                world.cast_ray(&ray, filter),
                expected.first().copied(),
                "case {case}: closest hit"
            );

            let radius = rng.range(0.0, 1.5);
            let expected_sphere = world
                .bodies()
                .filter(|body| world.passes(body.index(), filter))
                .filter_map(|body| {
                    let i = body.index() as usize;
                    let pose = world.poses[i].transform();
                    let hit = cast_sphere(radius, &world.colliders[i].shape, &pose, &ray)?;
                    Some((hit.distance, body.index(), hit))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                .map(|(_, index, hit)| (index, hit.distance, hit.point, hit.normal));
            let sphere = world.cast_sphere(radius, &ray, filter).unwrap();
            assert_eq!(
                sphere.map(|h| (h.body.index(), h.distance, h.point, h.normal)),
                expected_sphere,
                "case {case}: sphere cast"
            );

            let swept = [
                Shape::sphere(rng.range(0.1, 1.0)),
                Shape::cuboid(rng.vec3(0.1, 1.0)),
                Shape::capsule(rng.range(0.1, 0.5), rng.range(0.0, 1.0)),
                Shape::convex_hull(&crate::scene::barrel_points()).unwrap(),
            ];
            let shape = &swept[case % swept.len()];
            let axis = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
            let start = Transform::new(
                ray.origin(),
                Quat::from_axis_angle(axis, rng.range(0.0, 6.0)),
            );
            let (direction, max) = (ray.direction(), ray.max_distance());
            let sweep = ShapeSweep::new(shape, &start, direction, max).unwrap();
            let expected_shape = world
                .bodies()
                .filter(|body| world.passes(body.index(), filter))
                .filter_map(|body| {
                    let i = body.index() as usize;
                    let pose = world.poses[i].transform();
                    let hit = cast_shape(&sweep, &world.colliders[i].shape, &pose)?;
                    Some((hit.distance, body.index(), hit))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                .map(|(_, index, hit)| (index, hit.distance, hit.point, hit.normal));
            let cast = world
                .cast_shape(shape, &start, direction, max, filter)
                .unwrap();
            assert_eq!(
                cast.map(|h| (h.body.index(), h.distance, h.point, h.normal)),
                expected_shape,
                "case {case}: shape cast"
            );

            let probe = Aabb::from_center_half_extents(
                vec3(0.0, 5.0, 0.0) + rng.vec3(-12.0, 12.0),
                rng.vec3(0.1, 4.0),
            );
            world.intersect_aabb(&probe, filter, &mut found).unwrap();
            let expected: Vec<BodyHandle> = world
                .bodies()
                .filter(|body| {
                    let pose = world.pose(*body).unwrap();
                    let shape = &world.colliders[body.index() as usize].shape;
                    shape.aabb(&pose).overlaps(&probe) && world.passes(body.index(), filter)
                })
                .collect();
            assert_eq!(found, expected, "case {case}: box query");
        }
    }
    // Without bodies outside their fat boxes the test would not cover that path.
    assert!(escaped_seen > 0);
}

#[test]
fn ties_go_to_the_lower_index_and_removed_bodies_are_gone() {
    let mut world = World::new(StepConfig::default()).unwrap();
    let unit = || BodyDesc::fixed(Shape::cuboid(Vec3::splat(0.5)));
    let a = world.add_body(unit()).unwrap();
    let b = world.add_body(unit()).unwrap();
    let ray = Ray::new(vec3(-5.0, 0.0, 0.0), Vec3::X, f32::INFINITY).unwrap();
    let filter = QueryFilter::default();
    assert_eq!(world.cast_ray(&ray, &filter).unwrap().body, a);
    let mut hits = Vec::new();
    world.cast_ray_all(&ray, &filter, &mut hits);
    assert_eq!(hits.iter().map(|h| h.body).collect::<Vec<_>>(), [a, b]);
    world.remove_body(a).unwrap();
    assert_eq!(world.cast_ray(&ray, &filter).unwrap().body, b);
    let mut found = Vec::new();
    let everything = Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0));
    world
        .intersect_aabb(&everything, &filter, &mut found)
        .unwrap();
    assert_eq!(found, [b]);
}

#[test]
fn a_ray_from_inside_hits_at_zero() {
    let mut world = World::new(StepConfig::default()).unwrap();
    let ball = world
        .add_body(BodyDesc::dynamic(Shape::sphere(1.0)).position(vec3(0.0, 5.0, 0.0)))
        .unwrap();
    let ray = Ray::new(vec3(0.0, 5.2, 0.0), Vec3::X, 10.0).unwrap();
    let hit = world.cast_ray(&ray, &QueryFilter::default()).unwrap();
    assert_eq!((hit.body, hit.distance, hit.normal), (ball, 0.0, -Vec3::X));
    assert_eq!(hit.point, ray.origin());
    let pose = world.pose(ball).unwrap();
    assert_eq!(pose, Transform::from_position(vec3(0.0, 5.0, 0.0)));
}

#[test]
fn bad_boxes_are_errors() {
    let world = World::new(StepConfig::default()).unwrap();
    let mut found = Vec::new();
    let filter = QueryFilter::default();
    let nan = Aabb::new(Vec3::splat(f32::NAN), Vec3::ONE);
    assert!(matches!(
        world.intersect_aabb(&nan, &filter, &mut found),
        Err(QueryError::AabbNotFinite { .. })
    ));
    let ray = Ray::new(Vec3::ZERO, Vec3::X, 1.0).unwrap();
    assert_eq!(
        world.cast_sphere(-0.5, &ray, &filter),
        Err(QueryError::BadRadius(-0.5))
    );
    let unit = Shape::cuboid(Vec3::ONE);
    let at = Transform::IDENTITY;
    assert_eq!(
        world.cast_shape(&unit, &at, Vec3::ZERO, 1.0, &filter),
        Err(QueryError::Cast(CastError::Path(RayError::ZeroDirection)))
    );
    assert_eq!(
        world.cast_shape(&Shape::sphere(0.0), &at, Vec3::X, 1.0, &filter),
        Err(QueryError::Cast(CastError::DegenerateShape(
            crate::shape::ShapeKind::Sphere
        )))
    );
    let inverted = Aabb::new(Vec3::ONE, Vec3::ZERO);
    assert!(matches!(
        world.intersect_aabb(&inverted, &filter, &mut found),
        Err(QueryError::AabbInverted { .. })
    ));
}

/// A compound swept through a random world hits what its first child to hit hits: the oracle
/// sweeps each child alone from its own pose through `World::cast_shape` and takes the
/// smallest (distance, body), ties to the lower child. Compounds of 3 and of 64 children (the
/// targets' compounds too go through their child BVHs), turned at random, with and without a
/// filter.
#[test]
fn a_swept_compound_hits_first_where_its_first_child_does() {
    use crate::shape::compound::{random_children, random_rotation};
    let mut rng = TestRng::new(31);
    let mut world = random_world(&mut rng, 60, 10);
    // Compounds among the targets as well.
    for _ in 0..6 {
        let target = Shape::compound(random_children(&mut rng, 20)).unwrap();
        world
            .add_body(
                BodyDesc::fixed(target)
                    .position(vec3(0.0, 4.0, 0.0) + rng.vec3(-8.0, 8.0))
                    .rotation(random_rotation(&mut rng)),
            )
            .unwrap();
    }
    let small = Shape::compound(random_children(&mut rng, 3)).unwrap();
    let large = Shape::compound(random_children(&mut rng, 64)).unwrap();
    let odd = |body: BodyHandle| body.index() % 2 == 1;
    let filters = [
        QueryFilter::default(),
        QueryFilter::default().predicate(&odd),
    ];
    let (mut hits, mut starts) = (0, 0);
    for case in 0..200 {
        let shape = [&small, &large][case % 2];
        let Shape::Compound(compound) = shape else {
            unreachable!("built as compounds")
        };
        let filter = &filters[case / 2 % filters.len()];
        let ray = random_ray(&mut rng);
        let pose = Transform::new(ray.origin(), random_rotation(&mut rng));
        let (direction, max) = (ray.direction(), ray.max_distance());
        let cast = world
            .cast_shape(shape, &pose, direction, max, filter)
            .unwrap();
        let mut expected: Option<RayHit> = None;
        // The children are placed by the pose with its rotation normalized, as the cast does.
        let unit = Transform::new(
            pose.position,
            pose.rotation / pose.rotation.length_squared().sqrt(),
        );
        for child in compound.children() {
            let child_pose = unit.mul_transform(&child.pose);
            let hit = world
                .cast_shape(&child.shape, &child_pose, direction, max, filter)
                .unwrap();
            if let Some(hit) = hit
                && expected.is_none_or(|best| {
                    (hit.distance, hit.body.index()) < (best.distance, best.body.index())
                })
            {
                expected = Some(hit);
            }
        }
        // A child touching at the start makes the compound's start hit, at its own origin.
        if let Some(hit) = &mut expected
            && hit.distance == 0.0
        {
            hit.point = pose.position;
            starts += 1;
        }
        assert_eq!(cast, expected, "case {case}");
        hits += usize::from(cast.is_some());
    }
    assert!(hits > 50 && hits < 200, "{hits} hits");
    assert!(starts > 0, "no start hit tested");
    // Bad poses are typed errors, as for convex shapes; planes and meshes still cannot sweep.
    let bad = Transform::new(Vec3::ZERO, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0));
    assert_eq!(
        world.cast_shape(&large, &bad, Vec3::X, 1.0, &QueryFilter::default()),
        Err(QueryError::Cast(CastError::ZeroRotation))
    );
    assert_eq!(
        world.cast_shape(
            &large,
            &Transform::IDENTITY,
            Vec3::ZERO,
            1.0,
            &QueryFilter::default()
        ),
        Err(QueryError::Cast(CastError::Path(RayError::ZeroDirection)))
    );
    assert_eq!(
        world.cast_shape(
            &Shape::plane(Vec3::Y, 0.0),
            &Transform::IDENTITY,
            Vec3::X,
            1.0,
            &QueryFilter::default()
        ),
        Err(QueryError::Cast(CastError::NotConvex(
            crate::shape::ShapeKind::Plane
        )))
    );
}
