//! Sphere casts: a ball of radius r swept along a ray, against one shape. The ball first
//! touches the shape when its centre first enters the shape grown by r (the Minkowski sum), so
//! each case is a ray cast against a grown shape: a ball of radius R + r, a capsule of radius
//! R + r, a plane moved out by r, and a box with rounded edges. That rounded box is the union of
//! three boxes (the box grown by r along one axis each) and twelve capsules of radius r on its
//! edges (their end balls are the rounded corners), and from outside the first entry into a
//! union is the first entry into any of its parts.

use super::shape_cast::{ShapeSweep, cast_shape};
use super::{
    INSIDE, LocalHit, Ray, ShapeHit, cylinder_side_hit, nearest_child_hit, ray_capsule, ray_cuboid,
    ray_plane, ray_sphere,
};
use crate::math::{Transform, Vec3};
use crate::shape::{Capsule, Cuboid, Plane, Shape, Sphere};

/// Sweeps a ball of `radius` (m, >= 0) whose centre follows `ray` and returns its first contact
/// with `shape` at `pose`: `distance` is how far the centre travelled, `point` the contact
/// point on the shape's surface, `normal` the shape's outward normal there. A ball that
/// already touches or overlaps the shape at the ray's origin hits at distance 0, at the
/// origin, with the normal `-direction` (as a ray from inside does). `None` for a miss and for
/// a negative or non-finite radius (no ball to sweep). Convex hulls and triangle meshes have no
/// closed form here and go through [`cast_shape`].
pub fn cast_sphere(radius: f32, shape: &Shape, pose: &Transform, ray: &Ray) -> Option<ShapeHit> {
    if !(radius.is_finite() && radius >= 0.0) {
        return None;
    }
    let origin = pose.inverse_transform_point(ray.origin);
    let direction = pose.inverse_transform_vector(ray.direction);
    let hit = match shape {
        Shape::Sphere(s) => ray_sphere(
            &Sphere {
                radius: s.radius + radius,
            },
            origin,
            direction,
        ),
        Shape::Capsule(c) => ray_capsule(
            &Capsule {
                radius: c.radius + radius,
                half_height: c.half_height,
            },
            origin,
            direction,
        ),
        Shape::Plane(p) => ray_plane(
            &Plane {
                normal: p.normal,
                offset: p.offset + radius,
            },
            origin,
            direction,
        ),
        Shape::Cuboid(c) => rounded_box_hit(c, radius, origin, direction),
        // No closed form: the general shape cast (conservative advancement on GJK).
        Shape::ConvexHull(_) | Shape::TriMesh(_) => {
            let ball = Sphere { radius };
            return cast_shape(&ShapeSweep::ball(&ball, ray), shape, pose);
        }
        Shape::Compound(compound) => {
            return nearest_child_hit(compound, pose, ray, radius, |child, child_pose| {
                cast_sphere(radius, child, child_pose, ray)
            });
        }
    }?;
    if hit.distance > ray.max_distance {
        return None;
    }
    if hit.normal == Vec3::ZERO {
        return Some(ShapeHit {
            distance: 0.0,
            point: ray.origin,
            normal: -ray.direction,
        });
    }
    let normal = pose.transform_vector(hit.normal).normalize();
    Some(ShapeHit {
        distance: hit.distance,
        point: ray.at(hit.distance) - radius * normal,
        normal,
    })
}

/// The ray against the box grown by `radius` with rounded edges; see the module documentation.
fn rounded_box_hit(
    cuboid: &Cuboid,
    radius: f32,
    origin: Vec3,
    direction: Vec3,
) -> Option<LocalHit> {
    let half = cuboid.half_extents;
    let outside = (origin.abs() - half).max(Vec3::ZERO);
    if outside.length_squared() <= radius * radius {
        return Some(INSIDE);
    }
    let mut best: Option<LocalHit> = None;
    let mut keep = |hit: Option<LocalHit>| {
        if let Some(hit) = hit
            && best.is_none_or(|b| hit.distance < b.distance)
        {
            best = Some(hit);
        }
    };
    for axis in 0..3 {
        let mut grown = half;
        grown[axis] += radius;
        keep(ray_cuboid(
            &Cuboid {
                half_extents: grown,
            },
            origin,
            direction,
        ));
    }
    for axis in 0..3 {
        // The edges along `axis` sit at the four (±, ±) corners of the other two axes.
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for corner in 0..4 {
            let mut center = Vec3::ZERO;
            center[u] = if corner & 1 == 0 { -half[u] } else { half[u] };
            center[v] = if corner & 2 == 0 { -half[v] } else { half[v] };
            keep(edge_capsule_hit(
                axis,
                half[axis],
                radius,
                origin - center,
                direction,
            ));
        }
    }
    best
}

/// The ray against a capsule of `radius` centred on the origin along `axis`, with a straight
/// part of ±`half_length`: the Y capsule's test with `axis` and Y swapped, a reflection that
/// keeps distances (the capsule is symmetric, so a swapped frame holds the same capsule).
fn edge_capsule_hit(
    axis: usize,
    half_length: f32,
    radius: f32,
    origin: Vec3,
    direction: Vec3,
) -> Option<LocalHit> {
    let swap = |mut v: Vec3| {
        let a = v[axis];
        v[axis] = v[1];
        v[1] = a;
        v
    };
    let (origin, direction) = (swap(origin), swap(direction));
    let mut best = cylinder_side_hit(radius, half_length, origin, direction);
    for end in [-half_length, half_length] {
        let ball = super::sphere_hit(Vec3::new(0.0, end, 0.0), radius, origin, direction);
        if let Some(hit) = ball
            && best.is_none_or(|b| hit.distance < b.distance)
        {
            best = Some(hit);
        }
    }
    // The caller has ruled out a start inside, so every hit has a normal to swap back.
    best.map(|hit| LocalHit {
        distance: hit.distance,
        normal: swap(hit.normal),
    })
}
