//! Rays, and exact ray casts, sphere casts ([`cast_sphere`]) and shape casts ([`cast_shape`])
//! against single shapes.
//!
//! A [`Ray`] is the half-line `origin + t · direction` for `0 <= t <= max_distance`, with a unit
//! `direction`, so `t` is a distance in metres. [`cast_ray`] intersects it with one shape at one
//! pose; the broadphase trees and [`World::cast_ray`](crate::World::cast_ray) choose which shapes
//! to ask.
//!
//! Conventions:
//! - Shapes are closed solids: touching the surface is a hit, and a ray that only grazes a
//!   sphere, a capsule or an edge of a box hits it at the grazing point.
//! - A ray whose origin is inside a shape (or on its surface) hits it at distance 0, at the
//!   origin, with the normal `-direction`: there is no entry surface to report, and a normal
//!   against the ray is what a character controller or a picking tool can use (Box2D v3 and
//!   Jolt report such rays as hits at 0 as well).
//! - Otherwise the hit is where the ray first enters the shape, with the outward surface normal
//!   there (unit length, world frame).
//!
//! Each shape has its own function in the shape's frame (the ray is moved into it, the hit moved
//! back); [`cast_ray`] dispatches on the shape in one `match`. A compound is the nearest hit
//! of its children.

mod shape_cast;
mod sphere_cast;

pub use shape_cast::{CastError, ShapeSweep, SweptParts, cast_shape};
pub use sphere_cast::cast_sphere;

use crate::math::{Transform, Vec3};
use crate::shape::compound::CHILD_QUERY_SLACK;
use crate::shape::{Capsule, Compound, ConvexHull, Cuboid, Plane, Shape, Sphere, TriMesh};

/// Why a ray could not be made.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum RayError {
    #[error("ray origin {0:?} is not finite")]
    OriginNotFinite(Vec3),
    #[error("ray direction {0:?} is not finite")]
    DirectionNotFinite(Vec3),
    #[error("ray direction has zero length: give a direction to cast along")]
    ZeroDirection,
    #[error("ray max_distance {0} must be >= 0 (use f32::INFINITY for an unbounded ray)")]
    BadMaxDistance(f32),
}

/// A half-line cut at `max_distance`. Fields are private so that a `Ray` is always valid: a
/// finite origin, a unit direction and a max distance in `[0, ∞]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    origin: Vec3,
    direction: Vec3,
    max_distance: f32,
}

impl Ray {
    /// A ray from `origin` (m) along `direction` (normalized here; any non-zero length), hitting
    /// nothing farther than `max_distance` (m; `f32::INFINITY` for no limit).
    pub fn new(origin: Vec3, direction: Vec3, max_distance: f32) -> Result<Self, RayError> {
        if !origin.is_finite() {
            return Err(RayError::OriginNotFinite(origin));
        }
        if !direction.is_finite() {
            return Err(RayError::DirectionNotFinite(direction));
        }
        // The squared length underflows to 0 for tiny directions that would normalize to junk.
        let length_squared = direction.length_squared();
        if length_squared == 0.0 || !length_squared.is_normal() {
            return Err(RayError::ZeroDirection);
        }
        if max_distance.is_nan() || max_distance < 0.0 {
            return Err(RayError::BadMaxDistance(max_distance));
        }
        Ok(Self {
            origin,
            direction: direction / length_squared.sqrt(),
            max_distance,
        })
    }

    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Unit length.
    pub fn direction(&self) -> Vec3 {
        self.direction
    }

    pub fn max_distance(&self) -> f32 {
        self.max_distance
    }

    /// The point `distance` metres along the ray.
    #[inline]
    pub fn at(&self, distance: f32) -> Vec3 {
        self.origin + distance * self.direction
    }

    /// The same ray, cut at `max_distance` instead (clamped to be >= 0; NaN keeps the old cut).
    pub fn with_max_distance(&self, max_distance: f32) -> Self {
        Self {
            max_distance: if max_distance.is_nan() {
                self.max_distance
            } else {
                max_distance.max(0.0)
            },
            ..*self
        }
    }
}

/// Where a ray meets a shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeHit {
    /// Along the ray from its origin (m), in `[0, max_distance]`; 0 when the origin is inside.
    pub distance: f32,
    /// The hit point, world frame (m).
    pub point: Vec3,
    /// Outward unit surface normal at the hit, world frame; `-direction` when the origin is
    /// inside the shape.
    pub normal: Vec3,
}

/// A hit in the shape's frame: the distance along the ray and the outward normal there.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LocalHit {
    distance: f32,
    normal: Vec3,
}

/// The first point where `ray` meets `shape` at `pose`, within the ray's max distance; `None`
/// when it misses. See the module documentation for rays that start inside.
pub fn cast_ray(shape: &Shape, pose: &Transform, ray: &Ray) -> Option<ShapeHit> {
    // Rotation keeps lengths, so distances in the shape's frame are world distances.
    let origin = pose.inverse_transform_point(ray.origin);
    let direction = pose.inverse_transform_vector(ray.direction);
    let hit = match shape {
        Shape::Sphere(sphere) => ray_sphere(sphere, origin, direction),
        Shape::Cuboid(cuboid) => ray_cuboid(cuboid, origin, direction),
        Shape::Capsule(capsule) => ray_capsule(capsule, origin, direction),
        Shape::Plane(plane) => ray_plane(plane, origin, direction),
        Shape::ConvexHull(hull) => ray_hull(hull, origin, direction),
        Shape::TriMesh(mesh) => ray_mesh(mesh, origin, direction, ray.max_distance),
        Shape::Compound(compound) => {
            return nearest_child_hit(compound, pose, ray, 0.0, |child, child_pose| {
                cast_ray(child, child_pose, ray)
            });
        }
    }?;
    if hit.distance > ray.max_distance {
        return None;
    }
    if hit.normal == Vec3::ZERO {
        // Inside: the exact origin and the exact reversed direction, untouched by the round
        // trip through the shape's frame.
        return Some(ShapeHit {
            distance: 0.0,
            point: ray.origin,
            normal: -ray.direction,
        });
    }
    Some(ShapeHit {
        distance: hit.distance,
        point: ray.at(hit.distance),
        normal: pose.transform_vector(hit.normal).normalize(),
    })
}

/// Inside: distance 0 and no normal, a marker [`cast_ray`] replaces with `-direction` (a real
/// hit always has a unit normal).
const INSIDE: LocalHit = LocalHit {
    distance: 0.0,
    normal: Vec3::ZERO,
};

/// Ray against a ball of `radius` around the origin. Solves |o + t d|² = r² for the smaller t,
/// with the discriminant taken as r² minus the squared distance from the centre to the line,
/// which keeps its precision when the origin is far away (Haines et al., "Precision
/// Improvements for Ray/Sphere Intersection", Ray Tracing Gems, 2019).
fn ray_sphere(sphere: &Sphere, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    sphere_hit(Vec3::ZERO, sphere.radius, origin, direction)
}

fn sphere_hit(center: Vec3, radius: f32, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let to_origin = origin - center;
    if to_origin.length_squared() <= radius * radius {
        return Some(INSIDE);
    }
    // Distance along the ray to the point closest to the centre; behind the origin, the ray
    // moves away from the ball and, starting outside, cannot meet it.
    let closest = -to_origin.dot(direction);
    if closest < 0.0 {
        return None;
    }
    let off_line = (to_origin + closest * direction).length_squared();
    let discriminant = radius * radius - off_line;
    if discriminant < 0.0 {
        return None;
    }
    let distance = (closest - discriminant.sqrt()).max(0.0);
    let normal = (to_origin + distance * direction) / radius;
    Some(LocalHit {
        distance,
        normal: normal.normalize_or(-direction),
    })
}

/// Ray against a box centred on the origin: the slab method (Kay and Kajiya 1986). The ray is
/// inside the box for t in [max of the slab entries, min of the slab exits]; the entering slab
/// gives the normal. An axis the ray is parallel to is skipped, or rejects the ray when the
/// origin lies outside that slab; this avoids the 0 / 0 = NaN of the branch-free version.
fn ray_cuboid(cuboid: &Cuboid, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let half = cuboid.half_extents;
    if origin.abs().cmple(half).all() {
        return Some(INSIDE);
    }
    let mut enter = 0.0f32;
    let mut exit = f32::INFINITY;
    let mut normal = Vec3::ZERO;
    for axis in 0..3 {
        let (o, d, h) = (origin[axis], direction[axis], half[axis]);
        if d == 0.0 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (near, far, sign) = if d > 0.0 {
            ((-h - o) / d, (h - o) / d, -1.0)
        } else {
            ((h - o) / d, (-h - o) / d, 1.0)
        };
        if near > enter {
            enter = near;
            normal = Vec3::ZERO;
            normal[axis] = sign;
        }
        exit = exit.min(far);
        if enter > exit {
            return None;
        }
    }
    // The origin is outside, so some slab was entered at t > 0 and set the normal.
    (normal != Vec3::ZERO).then_some(LocalHit {
        distance: enter,
        normal,
    })
}

/// Ray against a capsule along Y. The capsule is the union of the finite cylinder |y| <= h and
/// the two end balls; from outside, the first entry into a union is the first entry into any
/// part. A ray entering the cylinder through a flat end enters the end ball (which contains
/// that disc) no later, so only the cylinder's side needs testing, with its hit height checked.
fn ray_capsule(capsule: &Capsule, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let (radius, half_height) = (capsule.radius, capsule.half_height);
    let on_axis = Vec3::new(0.0, origin.y.clamp(-half_height, half_height), 0.0);
    if (origin - on_axis).length_squared() <= radius * radius {
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
    keep(cylinder_side_hit(radius, half_height, origin, direction));
    keep(sphere_hit(
        Vec3::new(0.0, half_height, 0.0),
        radius,
        origin,
        direction,
    ));
    keep(sphere_hit(
        Vec3::new(0.0, -half_height, 0.0),
        radius,
        origin,
        direction,
    ));
    best
}

/// Entry through the side of the cylinder of `radius` around Y, |y| <= `half_height`, for an
/// origin outside the capsule. In the XZ plane this is the circle case of [`sphere_hit`].
fn cylinder_side_hit(
    radius: f32,
    half_height: f32,
    origin: Vec3,
    direction: Vec3,
) -> Option<LocalHit> {
    let flat_direction = Vec3::new(direction.x, 0.0, direction.z);
    let flat_length = flat_direction.length();
    // Parallel to the axis (or nearly: the division below would blow up): only the end balls
    // can be hit, and they are tested by the caller.
    if flat_length < 1e-12 {
        return None;
    }
    let flat_origin = Vec3::new(origin.x, 0.0, origin.z);
    let unit = flat_direction / flat_length;
    let closest = -flat_origin.dot(unit);
    if closest < 0.0 {
        return None;
    }
    let off_line = (flat_origin + closest * unit).length_squared();
    let discriminant = radius * radius - off_line;
    if discriminant < 0.0 {
        return None;
    }
    // Distances in the XZ plane shrink by `flat_length` against distances along the ray.
    let distance = ((closest - discriminant.sqrt()) / flat_length).max(0.0);
    let point = origin + distance * direction;
    if point.y.abs() > half_height {
        return None;
    }
    let normal = Vec3::new(point.x, 0.0, point.z) / radius;
    Some(LocalHit {
        distance,
        normal: normal.normalize_or(-direction),
    })
}

/// The nearest of `cast(child shape, child pose)` over the compound's children at `pose`; on
/// a tie the lowest child, so the answer does not depend on float noise in the order.
///
/// `path` is what `cast` follows and `radius` (m) bounds how far from the path the cast
/// shape reaches (0 for a ray). With a child BVH, only the children whose boxes (compound
/// frame) the path enters, grown by `radius` and the compound's query slack, are cast: a
/// child the cast touches at distance `t` has a point within `radius` of the path's point at
/// `t`, inside that grown box. Each is cast exactly as the flat loop casts it, and the nearest
/// is taken by (distance, child index), so the hit is the flat loop's bit for bit.
fn nearest_child_hit(
    compound: &Compound,
    pose: &Transform,
    path: &Ray,
    radius: f32,
    mut cast: impl FnMut(&Shape, &Transform) -> Option<ShapeHit>,
) -> Option<ShapeHit> {
    let children = compound.children();
    let mut nearest: Option<(ShapeHit, u32)> = None;
    let mut try_child = |index: u32| {
        let child = &children[index as usize];
        if let Some(hit) = cast(&child.shape, &pose.mul_transform(&child.pose))
            && nearest.is_none_or(|(best, best_index)| {
                (hit.distance, index) < (best.distance, best_index)
            })
        {
            nearest = Some((hit, index));
        }
    };
    let Some(bvh) = compound.child_bvh() else {
        (0..children.len() as u32).for_each(try_child);
        return nearest.map(|(hit, _)| hit);
    };
    let origin = pose.inverse_transform_point(path.origin);
    let direction = pose.inverse_transform_vector(path.direction);
    // Slack at the scale of the path's start as well as of the compound: rounding in moving
    // the path into the compound frame grows with both.
    let slack =
        compound.query_slack(pose) + CHILD_QUERY_SLACK * (origin.abs().max_element() + radius);
    // Not pruned behind the nearest hit found so far: a cast's distance is exact only up to
    // its own tolerance, and every child the path passes is cast, as the flat loop does.
    bvh.sweep(
        origin,
        Vec3::splat(radius + slack),
        direction,
        path.max_distance + slack,
        |index, max_t| {
            try_child(index);
            max_t
        },
    );
    nearest.map(|(hit, _)| hit)
}

/// Ray against the solid half-space n·x <= offset: from outside, only a ray heading into the
/// plane (n·d < 0) meets it, at t = (offset − n·o) / (n·d).
fn ray_plane(plane: &Plane, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let height = plane.normal.dot(origin) - plane.offset;
    if height <= 0.0 {
        return Some(INSIDE);
    }
    let approach = plane.normal.dot(direction);
    if approach >= 0.0 {
        return None;
    }
    Some(LocalHit {
        distance: height / -approach,
        normal: plane.normal,
    })
}

/// The hull as the intersection of its faces' half-spaces (Cyrus–Beck clipping): the ray
/// enters at the last entering face and must do so before it leaves through the first exit.
fn ray_hull(hull: &ConvexHull, origin: Vec3, direction: Vec3) -> Option<LocalHit> {
    let mut enter = LocalHit {
        distance: 0.0,
        normal: Vec3::ZERO,
    };
    let mut exit = f32::INFINITY;
    for face in hull.faces() {
        // > 0: the origin is inside this face's half-space.
        let height = face.offset - face.normal.dot(origin);
        let approach = face.normal.dot(direction);
        if approach == 0.0 {
            if height < 0.0 {
                return None;
            }
            continue;
        }
        // Where the ray crosses the face's plane: moving against the outward normal it enters
        // the half-space there, moving along it it leaves.
        let t = height / approach;
        if approach > 0.0 {
            exit = exit.min(t);
        } else if t > enter.distance {
            enter = LocalHit {
                distance: t,
                normal: face.normal,
            };
        }
    }
    // An origin inside every face keeps the zero normal: the INSIDE convention.
    (enter.distance <= exit).then_some(enter)
}

/// The nearest triangle the ray crosses (Möller–Trumbore through the mesh's BVH). A mesh is a
/// two-sided surface: the normal faces the ray, and there is no inside.
fn ray_mesh(mesh: &TriMesh, origin: Vec3, direction: Vec3, max_distance: f32) -> Option<LocalHit> {
    let mut best: Option<LocalHit> = None;
    mesh.bvh()
        .ray(origin, direction, max_distance, |index, max_t| {
            let triangle = mesh.triangle(index);
            let [a, b, c] = triangle.vertices;
            let (edge1, edge2) = (b - a, c - a);
            let p = direction.cross(edge2);
            let determinant = edge1.dot(p);
            if determinant == 0.0 {
                return max_t;
            }
            let inverse = 1.0 / determinant;
            let s = origin - a;
            let u = s.dot(p) * inverse;
            let q = s.cross(edge1);
            let v = direction.dot(q) * inverse;
            let t = edge2.dot(q) * inverse;
            if u < 0.0 || v < 0.0 || u + v > 1.0 || t < 0.0 || t > max_t {
                return max_t;
            }
            let normal = if triangle.normal.dot(direction) > 0.0 {
                -triangle.normal
            } else {
                triangle.normal
            };
            best = Some(LocalHit {
                distance: t,
                normal,
            });
            t
        });
    best
}

#[cfg(test)]
mod tests;
