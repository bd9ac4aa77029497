//! Ray casts against closed forms: straight-on, oblique, grazing, parallel, behind, inside and
//! cut off by the max distance, for every shape, in rotated and translated poses.

use super::*;
use crate::collision::dbvt::tests::TestRng;
use crate::math::{Quat, vec3};
use crate::shape::ShapeKind;
use std::f32::consts::{FRAC_PI_2, SQRT_2};

const TOLERANCE: f32 = 1e-5;

fn ray(origin: Vec3, direction: Vec3) -> Ray {
    Ray::new(origin, direction, f32::INFINITY).unwrap()
}

fn assert_hit(hit: Option<ShapeHit>, distance: f32, point: Vec3, normal: Vec3) {
    let hit = hit.expect("the ray should hit");
    assert!(
        (hit.distance - distance).abs() <= TOLERANCE * distance.max(1.0),
        "distance {} != {distance}",
        hit.distance
    );
    assert!(
        (hit.point - point).length() <= TOLERANCE * point.length().max(1.0),
        "point {} != {point}",
        hit.point
    );
    assert!(
        (hit.normal - normal).length() <= TOLERANCE,
        "normal {} != {normal}",
        hit.normal
    );
}

/// A pose that moves and turns the shape, so that every test also checks the frame changes.
fn turned(position: Vec3) -> Transform {
    Transform::new(position, Quat::from_rotation_y(FRAC_PI_2))
}

#[test]
fn bad_rays_are_errors() {
    let (o, d) = (Vec3::ZERO, Vec3::X);
    assert_eq!(Ray::new(o, Vec3::ZERO, 1.0), Err(RayError::ZeroDirection));
    assert_eq!(
        Ray::new(o, Vec3::splat(1e-30), 1.0),
        Err(RayError::ZeroDirection)
    );
    assert!(matches!(
        Ray::new(vec3(f32::NAN, 0.0, 0.0), d, 1.0),
        Err(RayError::OriginNotFinite(_))
    ));
    assert!(matches!(
        Ray::new(o, vec3(f32::INFINITY, 0.0, 0.0), 1.0),
        Err(RayError::DirectionNotFinite(_))
    ));
    assert_eq!(Ray::new(o, d, -1.0), Err(RayError::BadMaxDistance(-1.0)));
    assert!(matches!(
        Ray::new(o, d, f32::NAN),
        Err(RayError::BadMaxDistance(_))
    ));
    let unbounded = Ray::new(o, vec3(0.0, 3.0, 4.0), f32::INFINITY).unwrap();
    assert_eq!(unbounded.direction(), vec3(0.0, 0.6, 0.8));
    assert_eq!(unbounded.with_max_distance(-2.0).max_distance(), 0.0);
}

#[test]
fn sphere() {
    let shape = Shape::sphere(1.0);
    let pose = turned(vec3(1.0, 2.0, 3.0));
    let center = pose.position;
    // Straight on: the near pole.
    let straight = ray(center - vec3(5.0, 0.0, 0.0), Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &straight),
        4.0,
        center - Vec3::X,
        -Vec3::X,
    );
    // Off-centre by 0.6: enters at x = -0.8, 4.2 m along.
    let off = ray(center + vec3(-5.0, 0.6, 0.0), Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &off),
        4.2,
        center + vec3(-0.8, 0.6, 0.0),
        vec3(-0.8, 0.6, 0.0),
    );
    // Grazing the top: a hit at the tangent point; a hair above, a miss. A tangent's distance
    // is ill-conditioned (an error ε in the offset moves it by about √(2ε·r)), so this uses an
    // unturned pose, where the arithmetic is exact.
    let moved = Transform::from_position(center);
    let grazing = ray(center + vec3(-5.0, 1.0, 0.0), Vec3::X);
    assert_hit(
        cast_ray(&shape, &moved, &grazing),
        5.0,
        center + Vec3::Y,
        Vec3::Y,
    );
    let above = ray(center + vec3(-5.0, 1.001, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &above), None);
    // Behind the origin.
    let behind = ray(center + vec3(5.0, 0.0, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &behind), None);
    // Inside: distance 0 at the origin, normal against the ray.
    let inside = ray(center + vec3(0.2, -0.3, 0.1), Vec3::Z);
    assert_hit(
        cast_ray(&shape, &pose, &inside),
        0.0,
        inside.origin(),
        -Vec3::Z,
    );
    // Max distance: a little more than 4 m reaches the pole, a little less does not (the
    // turned pose rounds the distance; the plane test checks the exact boundary).
    assert!(cast_ray(&shape, &pose, &straight.with_max_distance(4.001)).is_some());
    assert_eq!(
        cast_ray(&shape, &pose, &straight.with_max_distance(3.99)),
        None
    );
    // Far away, the hit still lands on the surface (the precise discriminant).
    let far = ray(center + vec3(-1.0e4, 0.5, 0.0), Vec3::X);
    let hit = cast_ray(&shape, &pose, &far).unwrap();
    assert!(((hit.point - center).length() - 1.0).abs() < 2e-3);
    assert!((hit.normal - vec3(-(0.75f32).sqrt(), 0.5, 0.0)).length() < 2e-3);
}

#[test]
fn cuboid() {
    // Half extents (1, 2, 3), turned 90° about Y: in the world it spans x ±3, y ±2, z ±1.
    let shape = Shape::cuboid(vec3(1.0, 2.0, 3.0));
    let pose = turned(Vec3::ZERO);
    let straight = ray(vec3(-10.0, 0.5, 0.5), Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &straight),
        7.0,
        vec3(-3.0, 0.5, 0.5),
        -Vec3::X,
    );
    // Down onto the top face.
    let down = ray(vec3(1.0, 9.0, -0.5), -Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &down),
        7.0,
        vec3(1.0, 2.0, -0.5),
        Vec3::Y,
    );
    // Oblique, 45° in XY: from (-5, -3, 0) the x slab is entered last, at t = 2√2 at
    // (-3, -1, 0), on the -x face.
    let oblique = ray(vec3(-5.0, -3.0, 0.0), vec3(1.0, 1.0, 0.0));
    assert_hit(
        cast_ray(&shape, &pose, &oblique),
        2.0 * SQRT_2,
        vec3(-3.0, -1.0, 0.0),
        -Vec3::X,
    );
    // From (-4, -5, 0) the y slab is entered last, at t = 3√2 at (-1, -2, 0), on the bottom.
    let oblique = ray(vec3(-4.0, -5.0, 0.0), vec3(1.0, 1.0, 0.0));
    assert_hit(
        cast_ray(&shape, &pose, &oblique),
        3.0 * SQRT_2,
        vec3(-1.0, -2.0, 0.0),
        -Vec3::Y,
    );
    // Parallel to a face: inside its slab it hits the side face, outside it misses.
    let parallel_out = ray(vec3(-10.0, 2.5, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &parallel_out), None);
    // Grazing along the top face (on the slab's boundary): a hit on the near edge.
    let grazing = ray(vec3(-10.0, 2.0, 0.0), Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &grazing),
        7.0,
        vec3(-3.0, 2.0, 0.0),
        -Vec3::X,
    );
    // Through the edge at (-3, 2) exactly: a grazing hit there; a hair above it, a miss.
    let edge = ray(vec3(-5.0, 0.0, 0.0), vec3(1.0, 1.0, 0.0));
    assert_hit(
        cast_ray(&shape, &pose, &edge),
        2.0 * SQRT_2,
        vec3(-3.0, 2.0, 0.0),
        -Vec3::X,
    );
    let past = ray(vec3(-5.0, 0.01, 0.0), vec3(1.0, 1.0, 0.0));
    assert_eq!(cast_ray(&shape, &pose, &past), None);
    let behind = ray(vec3(10.0, 0.0, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &behind), None);
    let inside = ray(vec3(2.9, -1.9, 0.9), -Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &inside),
        0.0,
        inside.origin(),
        Vec3::Y,
    );
    assert!(cast_ray(&shape, &pose, &straight.with_max_distance(7.001)).is_some());
    assert_eq!(
        cast_ray(&shape, &pose, &straight.with_max_distance(6.99)),
        None
    );
}

#[test]
fn capsule() {
    // Radius 0.5, straight part ±1 along the body's Y, laid along world X by a turn about Z.
    let shape = Shape::capsule(0.5, 1.0);
    let pose = Transform::new(vec3(0.0, 1.0, 0.0), Quat::from_rotation_z(-FRAC_PI_2));
    let at = |p: Vec3| pose.position + p;
    // The side, straight on from above.
    let side = ray(at(vec3(0.3, 5.0, 0.0)), -Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &side),
        4.5,
        at(vec3(0.3, 0.5, 0.0)),
        Vec3::Y,
    );
    // The end cap, along the axis: 5 − 1.5 m.
    let cap = ray(at(vec3(5.0, 0.0, 0.0)), -Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &cap),
        3.5,
        at(vec3(1.5, 0.0, 0.0)),
        Vec3::X,
    );
    // Parallel to the axis, 0.3 off it: the cap ball, at 0.4 past its centre.
    let off_axis = ray(at(vec3(5.0, 0.3, 0.0)), -Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &off_axis),
        3.6,
        at(vec3(1.4, 0.3, 0.0)),
        vec3(0.8, 0.6, 0.0),
    );
    // From above, just past the end of the straight part: the cap ball, not the cylinder.
    let over_cap = ray(at(vec3(1.3, 5.0, 0.0)), -Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &over_cap),
        4.6,
        at(vec3(1.3, 0.4, 0.0)),
        vec3(0.6, 0.8, 0.0),
    );
    // Grazing the side: tangent hit; a hair out, a miss. Unturned, for exact arithmetic (see
    // the sphere's grazing case): the capsule stands along Y.
    let upright = Transform::from_position(pose.position);
    let grazing = ray(at(vec3(0.5, 0.25, -5.0)), Vec3::Z);
    assert_hit(
        cast_ray(&shape, &upright, &grazing),
        5.0,
        at(vec3(0.5, 0.25, 0.0)),
        Vec3::X,
    );
    let outside = ray(at(vec3(0.0, 0.501, -5.0)), Vec3::Z);
    assert_eq!(cast_ray(&shape, &pose, &outside), None);
    // Parallel to the axis outside the radius: a miss.
    let parallel = ray(at(vec3(5.0, 0.6, 0.0)), -Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &parallel), None);
    let behind = ray(at(vec3(0.0, 5.0, 0.0)), Vec3::Y);
    assert_eq!(cast_ray(&shape, &pose, &behind), None);
    let inside = ray(at(vec3(1.2, 0.1, 0.0)), Vec3::X);
    assert_hit(
        cast_ray(&shape, &pose, &inside),
        0.0,
        inside.origin(),
        -Vec3::X,
    );
    assert!(cast_ray(&shape, &pose, &side.with_max_distance(4.501)).is_some());
    assert_eq!(cast_ray(&shape, &pose, &side.with_max_distance(4.49)), None);
}

#[test]
fn plane() {
    // y <= 0 in the body, moved up 1 m: the ground is y <= 1.
    let shape = Shape::plane(Vec3::Y, 0.0);
    let pose = Transform::from_position(vec3(0.0, 1.0, 0.0));
    let down = ray(vec3(2.0, 3.0, 0.0), -Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &down),
        2.0,
        vec3(2.0, 1.0, 0.0),
        Vec3::Y,
    );
    let oblique = ray(vec3(0.0, 3.0, 0.0), vec3(1.0, -1.0, 0.0));
    assert_hit(
        cast_ray(&shape, &pose, &oblique),
        2.0 * SQRT_2,
        vec3(2.0, 1.0, 0.0),
        Vec3::Y,
    );
    let parallel = ray(vec3(0.0, 3.0, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &parallel), None);
    let away = ray(vec3(0.0, 3.0, 0.0), Vec3::Y);
    assert_eq!(cast_ray(&shape, &pose, &away), None);
    // Below the surface is inside the half-space; on it counts as inside too.
    let below = ray(vec3(0.0, 0.5, 0.0), Vec3::Y);
    assert_hit(
        cast_ray(&shape, &pose, &below),
        0.0,
        below.origin(),
        -Vec3::Y,
    );
    let on = ray(vec3(0.0, 1.0, 0.0), Vec3::X);
    assert_eq!(cast_ray(&shape, &pose, &on).unwrap().distance, 0.0);
    // The cut-off is inclusive: a hit exactly at max_distance counts.
    assert!(cast_ray(&shape, &pose, &down.with_max_distance(2.0)).is_some());
    assert_eq!(cast_ray(&shape, &pose, &down.with_max_distance(1.99)), None);
    // The body's turn turns the plane: y <= 0 turned +90° about Z is x >= 0, i.e. -x <= 0.
    let wall = Transform::new(Vec3::ZERO, Quat::from_rotation_z(FRAC_PI_2));
    let toward = ray(vec3(-4.0, 0.0, 0.0), Vec3::X);
    assert_hit(cast_ray(&shape, &wall, &toward), 4.0, Vec3::ZERO, -Vec3::X);
    // An offset plane: n·x <= 2 along n = +Y.
    let raised = Shape::plane(Vec3::Y, 2.0);
    assert_hit(
        cast_ray(&raised, &Transform::IDENTITY, &down),
        1.0,
        vec3(2.0, 2.0, 0.0),
        Vec3::Y,
    );
}

/// Signed distance of a point (body frame) to a primitive: the oracle for the random test.
fn signed_distance(shape: &Shape, p: Vec3) -> f32 {
    match shape {
        Shape::Sphere(s) => p.length() - s.radius,
        Shape::Cuboid(c) => {
            let q = p.abs() - c.half_extents;
            q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
        }
        Shape::Capsule(c) => {
            let on_axis = vec3(0.0, p.y.clamp(-c.half_height, c.half_height), 0.0);
            (p - on_axis).length() - c.radius
        }
        Shape::Plane(plane) => plane.normal.dot(p) - plane.offset,
        Shape::ConvexHull(_) | Shape::TriMesh(_) | Shape::Compound(_) => {
            unreachable!("the oracle covers primitives")
        }
    }
}

/// Random rays from outside at random shapes and poses: every hit lies on the surface, with
/// the normal of the signed distance's gradient, and no sampled point of the ray before it (or
/// anywhere, for a miss) is inside the shape.
#[test]
fn random_rays_agree_with_signed_distance() {
    let mut rng = TestRng::new(11);
    let mut hits = 0;
    for case in 0..3000 {
        let shape = match case % 3 {
            0 => Shape::sphere(rng.range(0.2, 2.0)),
            1 => Shape::cuboid(rng.vec3(0.2, 2.0)),
            _ => Shape::capsule(rng.range(0.2, 1.0), rng.range(0.0, 2.0)),
        };
        let axis = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
        let pose = Transform::new(
            rng.vec3(-2.0, 2.0),
            Quat::from_axis_angle(axis, rng.range(0.0, 6.0)),
        );
        let origin = pose.position + rng.vec3(-6.0, 6.0);
        let local = |p: Vec3| signed_distance(&shape, pose.inverse_transform_point(p));
        if local(origin) <= 0.0 {
            continue;
        }
        // Aim near the shape so that about half the rays hit.
        let target = pose.position + rng.vec3(-2.0, 2.0);
        let ray = Ray::new(origin, target - origin, 20.0).unwrap();
        let hit = cast_ray(&shape, &pose, &ray);
        let end = hit.map_or(ray.max_distance(), |hit| hit.distance);
        for sample in 0..200 {
            let distance = end * sample as f32 / 200.0;
            assert!(
                local(ray.at(distance)) > -1e-4,
                "case {case}: inside before the hit"
            );
        }
        if let Some(hit) = hit {
            hits += 1;
            assert!(
                local(hit.point).abs() < 1e-4,
                "case {case}: not on the surface"
            );
            let step = 1e-3;
            let gradient = vec3(
                local(hit.point + step * Vec3::X) - local(hit.point - step * Vec3::X),
                local(hit.point + step * Vec3::Y) - local(hit.point - step * Vec3::Y),
                local(hit.point + step * Vec3::Z) - local(hit.point - step * Vec3::Z),
            );
            // Away from box edges the gradient is the face normal.
            if gradient.length() > 1.9 * step {
                assert!(
                    (gradient.normalize() - hit.normal).length() < 1e-2,
                    "case {case}: normal {} vs gradient {}",
                    hit.normal,
                    gradient.normalize()
                );
            }
        }
    }
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn sphere_cast_closed_forms() {
    let ball = 0.5;
    let cast = |shape: Shape, origin: Vec3, direction: Vec3| {
        cast_sphere(ball, &shape, &Transform::IDENTITY, &ray(origin, direction))
    };
    // Ball against ball: the centres meet at 1.5 m.
    assert_hit(
        cast(Shape::sphere(1.0), vec3(-5.0, 0.0, 0.0), Vec3::X),
        3.5,
        -Vec3::X,
        -Vec3::X,
    );
    assert_hit(
        cast(Shape::plane(Vec3::Y, 0.0), vec3(1.0, 3.0, 0.0), -Vec3::Y),
        2.5,
        vec3(1.0, 0.0, 0.0),
        Vec3::Y,
    );
    assert_hit(
        cast(Shape::capsule(0.5, 1.0), vec3(-5.0, 0.7, 0.0), Vec3::X),
        4.0,
        vec3(-0.5, 0.7, 0.0),
        -Vec3::X,
    );
    let cube = Shape::cuboid(Vec3::ONE);
    // A face.
    assert_hit(
        cast(cube.clone(), vec3(-5.0, 0.2, 0.0), Vec3::X),
        3.5,
        vec3(-1.0, 0.2, 0.0),
        -Vec3::X,
    );
    // An edge: the centre passes 0.3 above the top face, the ball touches the edge at y = 1
    // when (x + 1)² + 0.3² = 0.5², x = -1.4.
    assert_hit(
        cast(cube.clone(), vec3(-5.0, 1.3, 0.0), Vec3::X),
        3.6,
        vec3(-1.0, 1.0, 0.0),
        vec3(-0.8, 0.6, 0.0),
    );
    // A corner: (x + 1)² + 2 · 0.3² = 0.5².
    let reach = (0.25f32 - 0.18).sqrt();
    assert_hit(
        cast(cube.clone(), vec3(-5.0, 1.3, 1.3), Vec3::X),
        4.0 - reach,
        Vec3::new(-1.0, 1.0, 1.0),
        vec3(-reach, 0.3, 0.3) / 0.5,
    );
    // Passing 0.6 above the top: a miss; starting within 0.5 of it: a hit at 0.
    assert_eq!(cast(cube.clone(), vec3(-5.0, 1.6, 0.0), Vec3::X), None);
    let start = vec3(0.0, 1.4, 0.0);
    assert_hit(cast(cube.clone(), start, Vec3::X), 0.0, start, -Vec3::X);
    // A negative radius sweeps nothing.
    assert_eq!(
        cast_sphere(
            -1.0,
            &cube,
            &Transform::IDENTITY,
            &ray(vec3(-5.0, 0.0, 0.0), Vec3::X)
        ),
        None
    );
}

/// Random sphere casts: at the hit the centre is `radius` from the shape, and no sampled
/// centre before it is closer; the contact point is on the surface.
#[test]
fn random_sphere_casts_agree_with_signed_distance() {
    let mut rng = TestRng::new(23);
    let mut hits = 0;
    for case in 0..3000 {
        let shape = match case % 3 {
            0 => Shape::sphere(rng.range(0.2, 2.0)),
            1 => Shape::cuboid(rng.vec3(0.2, 2.0)),
            _ => Shape::capsule(rng.range(0.2, 1.0), rng.range(0.0, 2.0)),
        };
        let radius = rng.range(0.05, 1.0);
        let axis = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
        let pose = Transform::new(
            rng.vec3(-2.0, 2.0),
            Quat::from_axis_angle(axis, rng.range(0.0, 6.0)),
        );
        let origin = pose.position + rng.vec3(-6.0, 6.0);
        let local = |p: Vec3| signed_distance(&shape, pose.inverse_transform_point(p));
        if local(origin) <= radius {
            continue;
        }
        let target = pose.position + rng.vec3(-2.5, 2.5);
        let ray = Ray::new(origin, target - origin, 20.0).unwrap();
        let hit = cast_sphere(radius, &shape, &pose, &ray);
        let end = hit.map_or(ray.max_distance(), |hit| hit.distance);
        for sample in 0..200 {
            let distance = end * sample as f32 / 200.0;
            assert!(
                local(ray.at(distance)) > radius - 1e-4,
                "case {case}: overlapping before the hit"
            );
        }
        if let Some(hit) = hit {
            hits += 1;
            let center = ray.at(hit.distance);
            assert!(
                (local(center) - radius).abs() < 1e-4,
                "case {case}: not touching"
            );
            assert!(
                local(hit.point).abs() < 1e-4,
                "case {case}: contact off the surface"
            );
            assert!((center - hit.point - radius * hit.normal).length() < 1e-4);
        }
    }
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn rays_hit_hulls_as_the_boxes_they_span_and_meshes_from_either_side() {
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            vec3(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -2.0 } else { 2.0 },
            )
        })
        .collect();
    let hull = Shape::convex_hull(&corners).unwrap();
    let cuboid = Shape::cuboid(vec3(1.0, 0.5, 2.0));
    for (origin, direction) in [
        (vec3(0.3, 5.0, 0.2), -Vec3::Y),
        (vec3(-4.0, 0.1, 1.0), Vec3::X),
        (vec3(3.0, 3.0, 3.0), vec3(-1.0, -1.0, -1.0)),
        (vec3(0.2, 0.1, 0.0), Vec3::Z),
    ] {
        let ray = Ray::new(origin, direction, 100.0).unwrap();
        let (a, b) = (
            cast_ray(&hull, &Transform::IDENTITY, &ray),
            cast_ray(&cuboid, &Transform::IDENTITY, &ray),
        );
        assert_eq!(a.is_some(), b.is_some(), "{origin} {direction}");
        if let (Some(a), Some(b)) = (a, b) {
            assert!((a.distance - b.distance).abs() < 1e-5, "{a:?} {b:?}");
            assert!((a.normal - b.normal).length() < 1e-5, "{a:?} {b:?}");
        }
    }
    let floor = Shape::trimesh(
        crate::shape::TriMesh::new(
            vec![
                vec3(-1.0, 0.0, -1.0),
                vec3(-1.0, 0.0, 1.0),
                vec3(1.0, 0.0, -1.0),
                vec3(1.0, 0.0, 1.0),
            ],
            vec![[0, 1, 2], [2, 1, 3]],
        )
        .unwrap(),
    );
    let down = Ray::new(vec3(0.5, 2.0, 0.5), -Vec3::Y, 10.0).unwrap();
    assert_hit(
        cast_ray(&floor, &Transform::IDENTITY, &down),
        2.0,
        vec3(0.5, 0.0, 0.5),
        Vec3::Y,
    );
    let up = Ray::new(vec3(-0.5, -3.0, 0.2), Vec3::Y, 10.0).unwrap();
    assert_hit(
        cast_ray(&floor, &Transform::IDENTITY, &up),
        3.0,
        vec3(-0.5, 0.0, 0.2),
        -Vec3::Y,
    );
    let beside = Ray::new(vec3(1.5, 2.0, 0.0), -Vec3::Y, 10.0).unwrap();
    assert!(cast_ray(&floor, &Transform::IDENTITY, &beside).is_none());
}

// Shape casts.

fn sweep(shape: &Shape, pose: Transform, direction: Vec3, max_distance: f32) -> ShapeSweep<'_> {
    ShapeSweep::new(shape, &pose, direction, max_distance).unwrap()
}

fn box_hull(half: Vec3) -> Shape {
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            half * vec3(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            )
        })
        .collect();
    Shape::convex_hull(&corners).unwrap()
}

#[test]
fn shape_cast_closed_forms() {
    // Ball onto ball, off-centre: the centres are r1 + r2 apart at impact.
    let (r1, r2, offset) = (0.4, 0.7, 0.5);
    let target = vec3(5.0, offset, 0.0);
    let ball = Shape::sphere(r1);
    let hit = cast_shape(
        &sweep(&ball, Transform::IDENTITY, Vec3::X, 10.0),
        &Shape::sphere(r2),
        &Transform::from_position(target),
    );
    let distance = 5.0 - ((r1 + r2) * (r1 + r2) - offset * offset).sqrt();
    let normal = (vec3(distance, 0.0, 0.0) - target).normalize();
    assert_hit(hit, distance, target + r2 * normal, normal);

    // A box face-first onto a box, a hull box and a plane, from any turned frame: exact.
    let falling = Shape::cuboid(vec3(0.5, 0.25, 0.5));
    let start = Transform::from_position(vec3(0.1, 4.0, -0.2));
    for (target, pose) in [
        (Shape::cuboid(vec3(2.0, 1.0, 2.0)), turned(Vec3::ZERO)),
        (box_hull(vec3(2.0, 1.0, 2.0)), turned(Vec3::ZERO)),
        (
            Shape::plane(Vec3::Y, 1.0),
            Transform::from_position(vec3(3.0, 0.0, 1.0)),
        ),
    ] {
        let hit = cast_shape(&sweep(&falling, start, -Vec3::Y, 10.0), &target, &pose);
        let hit = hit.expect("falls onto it");
        assert!((hit.distance - 2.75).abs() < 1e-5, "{target:?}: {hit:?}");
        assert!(
            (hit.normal - Vec3::Y).length() < 1e-5,
            "{target:?}: {hit:?}"
        );
        assert!((hit.point.y - 1.0).abs() < 1e-5, "{target:?}: {hit:?}");
    }
    // Turned 45° about Z, the box leads with an edge, 0.5·√2·... lower than its centre.
    let edge_first = Transform::new(vec3(0.0, 4.0, 0.0), Quat::from_rotation_z(FRAC_PI_2 / 2.0));
    let lowest = (0.5f32 * 0.5 + 0.25 * 0.25).sqrt() * (FRAC_PI_2 / 2.0 + 0.25f32.atan2(0.5)).sin();
    for target in [
        Shape::plane(Vec3::Y, 0.0),
        Shape::cuboid(vec3(3.0, 1.0, 3.0)),
    ] {
        let pose = match target {
            Shape::Plane(_) => Transform::IDENTITY,
            _ => Transform::from_position(vec3(0.0, -1.0, 0.0)),
        };
        let hit = cast_shape(&sweep(&falling, edge_first, -Vec3::Y, 10.0), &target, &pose);
        let hit = hit.expect("falls onto it");
        assert!((hit.distance - (4.0 - lowest)).abs() < 1e-5, "{hit:?}");
        assert!((hit.normal - Vec3::Y).length() < 1e-5);
    }

    // A lying capsule onto a box, and a standing one onto a ball.
    let capsule = Shape::capsule(0.3, 1.0);
    let lying = Transform::new(vec3(0.0, 3.0, 0.0), Quat::from_rotation_z(FRAC_PI_2));
    let hit = cast_shape(
        &sweep(&capsule, lying, -Vec3::Y, 10.0),
        &Shape::cuboid(Vec3::splat(1.0)),
        &turned(Vec3::ZERO),
    );
    assert_hit(hit, 1.7, vec3(0.0, 1.0, 0.0), Vec3::Y);
    let standing = Transform::from_position(vec3(0.0, 5.0, 0.0));
    let hit = cast_shape(
        &sweep(&capsule, standing, -Vec3::Y, 10.0),
        &Shape::sphere(0.5),
        &Transform::IDENTITY,
    );
    assert_hit(hit, 5.0 - 1.0 - 0.3 - 0.5, vec3(0.0, 0.5, 0.0), Vec3::Y);

    // Already overlapping: a hit at 0 where the shape stands, against the direction.
    let hit = cast_shape(
        &sweep(
            &falling,
            Transform::from_position(vec3(0.0, 1.1, 0.0)),
            Vec3::X,
            10.0,
        ),
        &box_hull(Vec3::ONE),
        &Transform::IDENTITY,
    );
    assert_eq!(
        hit,
        Some(ShapeHit {
            distance: 0.0,
            point: vec3(0.0, 1.1, 0.0),
            normal: -Vec3::X
        })
    );
    // Moving away, passing beside, stopping short: misses.
    for (direction, max) in [(Vec3::Y, 10.0), (Vec3::X, 10.0), (-Vec3::Y, 2.7)] {
        let hit = cast_shape(
            &sweep(&falling, start, direction, max),
            &box_hull(vec3(2.0, 1.0, 2.0)),
            &Transform::IDENTITY,
        );
        assert_eq!(hit, None, "{direction} {max}");
    }
}

/// A sphere cast against a box hull is the analytic rounded-box cast against the same box.
#[test]
fn sphere_casts_against_a_box_hull_match_the_rounded_box() {
    let mut rng = TestRng::new(31);
    let mut hits = 0;
    for case in 0..2000 {
        let half = rng.vec3(0.2, 2.0);
        let (hull, cuboid) = (box_hull(half), Shape::cuboid(half));
        let axis = rng.vec3(-1.0, 1.0).normalize_or(Vec3::X);
        let pose = Transform::new(
            rng.vec3(-2.0, 2.0),
            Quat::from_axis_angle(axis, rng.range(0.0, 6.0)),
        );
        let radius = rng.range(0.0, 1.0);
        let origin = pose.position + rng.vec3(-6.0, 6.0);
        let target = pose.position + rng.vec3(-2.5, 2.5);
        let ray = Ray::new(origin, target - origin, 20.0).unwrap();
        let expected = cast_sphere(radius, &cuboid, &pose, &ray);
        let hit = cast_sphere(radius, &hull, &pose, &ray);
        match (hit, expected) {
            (Some(hit), Some(expected)) => {
                hits += 1;
                assert!(
                    (hit.distance - expected.distance).abs() < 1e-4,
                    "case {case}: {hit:?} != {expected:?}"
                );
                // On an edge or corner of the rounded box the normal turns fast along the
                // path, so it is compared through the contact geometry instead: the centre
                // sits `radius` out along the normal from the contact point.
                if expected.distance > 0.0 {
                    let center = ray.at(hit.distance);
                    assert!((center - hit.point - radius * hit.normal).length() < 1e-4);
                    assert!(
                        (hit.point - expected.point).length() < 1e-3,
                        "case {case}: {hit:?} != {expected:?}"
                    );
                }
            }
            (None, None) => {}
            // A path that grazes the rounded box may hit it in one and miss in the other.
            (hit, expected) => {
                let grazing = hit.or(expected).unwrap();
                assert!(
                    -grazing.normal.dot(ray.direction()) < 1e-2,
                    "case {case}: {hit:?} != {expected:?}"
                );
            }
        }
    }
    assert!(hits > 500, "{hits} hits");
}

#[test]
fn shape_casts_hit_meshes_from_either_side_at_the_nearest_triangle() {
    // Two stacked floors at y = 0 and y = 2, each of two triangles.
    let quad = |y: f32, base: u32| {
        (
            [
                vec3(-1.0, y, -1.0),
                vec3(-1.0, y, 1.0),
                vec3(1.0, y, -1.0),
                vec3(1.0, y, 1.0),
            ],
            [[base, base + 1, base + 2], [base + 2, base + 1, base + 3]],
        )
    };
    let (low, low_triangles) = quad(0.0, 0);
    let (high, high_triangles) = quad(2.0, 4);
    let mesh = crate::shape::TriMesh::new(
        [low, high].concat(),
        [low_triangles, high_triangles].concat(),
    )
    .unwrap();
    let floors = Shape::trimesh(mesh);
    let pose = Transform::new(vec3(0.0, 1.0, 0.0), Quat::from_rotation_y(0.3));
    let cube = Shape::cuboid(Vec3::splat(0.25));
    let from_above = Transform::from_position(vec3(0.2, 6.0, 0.1));
    let hit = cast_shape(&sweep(&cube, from_above, -Vec3::Y, 10.0), &floors, &pose);
    assert_hit(hit, 2.75, hit.map_or(Vec3::ZERO, |h| h.point), Vec3::Y);
    assert!((hit.unwrap().point.y - 3.0).abs() < 1e-5);
    let from_below = Transform::from_position(vec3(0.2, -3.0, 0.1));
    let hit = cast_shape(&sweep(&cube, from_below, Vec3::Y, 10.0), &floors, &pose);
    assert_hit(hit, 3.75, hit.map_or(Vec3::ZERO, |h| h.point), -Vec3::Y);
    // Between the floors: touching the lower one at the start.
    let between = Transform::from_position(vec3(0.2, 1.2, 0.1));
    let hit = cast_shape(&sweep(&cube, between, Vec3::X, 10.0), &floors, &pose);
    assert_eq!(hit.map(|h| h.distance), Some(0.0));
    // Beside the mesh: nothing.
    let beside = Transform::from_position(vec3(3.0, 6.0, 0.0));
    assert_eq!(
        cast_shape(&sweep(&cube, beside, -Vec3::Y, 10.0), &floors, &pose),
        None
    );
    // A sphere cast goes through the same code.
    let down = Ray::new(vec3(0.2, 6.0, 0.1), -Vec3::Y, 10.0).unwrap();
    assert_hit(
        cast_sphere(0.5, &floors, &pose, &down),
        2.5,
        vec3(0.2, 3.0, 0.1),
        Vec3::Y,
    );
}

#[test]
fn bad_sweeps_are_errors() {
    let unit = Shape::cuboid(Vec3::ONE);
    let at = Transform::IDENTITY;
    let error = |shape: &Shape, pose: Transform, direction: Vec3, max: f32| {
        ShapeSweep::new(shape, &pose, direction, max).unwrap_err()
    };
    assert_eq!(
        error(&unit, at, Vec3::ZERO, 1.0),
        CastError::Path(RayError::ZeroDirection)
    );
    assert!(matches!(
        error(&unit, at, vec3(f32::NAN, 0.0, 0.0), 1.0),
        CastError::Path(RayError::DirectionNotFinite(_))
    ));
    assert!(matches!(
        error(&unit, at, Vec3::X, -1.0),
        CastError::Path(RayError::BadMaxDistance(_))
    ));
    assert!(matches!(
        error(&unit, at, Vec3::X, f32::NAN),
        CastError::Path(RayError::BadMaxDistance(_))
    ));
    assert!(matches!(
        error(
            &unit,
            Transform::from_position(Vec3::splat(f32::INFINITY)),
            Vec3::X,
            1.0
        ),
        CastError::Path(RayError::OriginNotFinite(_))
    ));
    let zero_rotation = Transform::new(Vec3::ZERO, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0));
    assert_eq!(
        error(&unit, zero_rotation, Vec3::X, 1.0),
        CastError::ZeroRotation
    );
    let nan_rotation = Transform::new(Vec3::ZERO, Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0));
    assert!(matches!(
        error(&unit, nan_rotation, Vec3::X, 1.0),
        CastError::RotationNotFinite(_)
    ));
    for (shape, kind) in [
        (Shape::sphere(0.0), ShapeKind::Sphere),
        (Shape::sphere(f32::NAN), ShapeKind::Sphere),
        (Shape::capsule(0.0, 1.0), ShapeKind::Capsule),
        (Shape::capsule(0.5, -1.0), ShapeKind::Capsule),
        (Shape::cuboid(vec3(1.0, 0.0, 1.0)), ShapeKind::Cuboid),
        (
            Shape::cuboid(vec3(1.0, f32::INFINITY, 1.0)),
            ShapeKind::Cuboid,
        ),
    ] {
        assert_eq!(
            error(&shape, at, Vec3::X, 1.0),
            CastError::DegenerateShape(kind)
        );
    }
    assert_eq!(
        error(&Shape::plane(Vec3::Y, 0.0), at, Vec3::X, 1.0),
        CastError::NotConvex(ShapeKind::Plane)
    );
    // A capsule with no straight part is a ball, and fine.
    assert!(ShapeSweep::new(&Shape::capsule(0.5, 0.0), &at, Vec3::X, 1.0).is_ok());
}

/// Rays, sphere casts and shape casts against a compound of 64 children take the same hit
/// through its child BVH as through the flat loop, bit for bit, from random origins aimed near
/// it (most hit, some miss, some start inside), near the origin and 1 km out.
#[test]
fn compound_child_bvh_casts_equal_the_flat_loop() {
    use crate::shape::Compound;
    use crate::shape::compound::{random_children, random_rotation};
    use std::sync::Arc;
    let mut rng = TestRng::new(11);
    let compound = Compound::new(random_children(&mut rng, 64)).unwrap();
    let [tree, flat] =
        [true, false].map(|bvh| Shape::Compound(Arc::new(compound.clone().with_child_bvh(bvh))));
    let swept = [
        Shape::cuboid(vec3(0.3, 0.1, 0.2)),
        Shape::capsule(0.1, 0.2),
        Shape::convex_hull(&crate::scene::barrel_points()).unwrap(),
    ];
    let (mut casts, mut hits) = (0, 0);
    for trial in 0..300 {
        let centre = if trial % 2 == 0 {
            Vec3::ZERO
        } else {
            vec3(1000.0, -20.0, 500.0)
        };
        let pose = Transform::new(centre, random_rotation(&mut rng));
        let origin = centre + rng.vec3(-4.0, 4.0);
        let aim = centre + rng.vec3(-1.2, 1.2);
        let max_distance = [f32::INFINITY, 3.0][trial % 2];
        let ray = Ray::new(origin, aim - origin, max_distance).unwrap();
        let mut same = |with_tree: Option<ShapeHit>, without: Option<ShapeHit>, what: &str| {
            assert_eq!(with_tree, without, "trial {trial}: {what}");
            casts += 1;
            hits += usize::from(without.is_some());
        };
        same(
            cast_ray(&tree, &pose, &ray),
            cast_ray(&flat, &pose, &ray),
            "ray",
        );
        let radius = rng.range(0.0, 0.4);
        same(
            cast_sphere(radius, &tree, &pose, &ray),
            cast_sphere(radius, &flat, &pose, &ray),
            "sphere",
        );
        let moving = &swept[trial % swept.len()];
        let sweep = ShapeSweep::new(
            moving,
            &Transform::new(origin, random_rotation(&mut rng)),
            aim - origin,
            max_distance,
        )
        .unwrap();
        same(
            cast_shape(&sweep, &tree, &pose),
            cast_shape(&sweep, &flat, &pose),
            "shape",
        );
    }
    assert!(hits > casts / 2 && hits < casts, "{hits} of {casts}");
}
