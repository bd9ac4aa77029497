//! Shape casts: a convex shape (sphere, capsule, box, convex hull) swept without turning along a
//! straight path, against one shape.
//!
//! # Method: conservative advancement on the GJK distance
//!
//! Let `d(t)` be the distance between the two cores (see `collision::gjk`) once the moving shape
//! has travelled `t` along the unit direction, and `r` the sum of the radii swept around them.
//! The shapes touch when `d(t) = r`. Translating one convex set along a line makes `d` a convex
//! function of `t`, and GJK gives both `d` and its slope: `d'(t) = n · direction`, `n` the unit
//! normal from the target to the moving core. Each step is Newton's step towards
//! `d(t) = r + SKIN`,
//!
//! ```text
//!   t ← t + (d(t) − r − SKIN) / closing,    closing = −n · direction
//! ```
//!
//! which, on a convex decreasing function, never passes the root (no tunnelling: the shape never
//! moves past a surface it would have touched) and converges quadratically near it. A slope of
//! zero or more means the distance never shrinks again: a miss. The iteration aims [`SKIN`]
//! short of contact because at contact the cores of two polytopes touch, and GJK's normal is
//! then undefined; the last `SKIN` is crossed in one linear step along the last normal, which is
//! exact for a flat contact (a vertex or an edge onto a face, two edges) and off by a term in
//! `SKIN²` for a curved one.
//!
//! A shape that already touches or overlaps the target hits it at distance 0, with the sphere
//! cast's convention: the point is the path's origin, the normal `-direction`.
//!
//! Against a plane the cast is closed form (the moving shape's lowest point); against a
//! triangle mesh the moving shape's box is swept through the mesh's BVH, nearer nodes first,
//! and each triangle met is a convex target of its own.

use super::{Ray, RayError, ShapeHit, nearest_child_hit};
use crate::collision::gjk::{GjkResult, MinkowskiDifference, SupportMap, gjk};
use crate::math::{Aabb, Quat, Transform, Vec3};
use crate::shape::{Plane, Shape, ShapeKind, TriMesh};

/// How far short of contact (m) the advancement aims: well above GJK's overlap threshold
/// (`gjk::OVERLAP_DISTANCE`, 1e-5 m) and its f32 noise, so that the last normal is a real one.
const SKIN: f32 = 1.0e-4;

/// The advancement stops once the gap left above [`SKIN`] is under this (m).
const CONVERGED: f32 = 1.0e-6;

/// Newton's steps before the advancement gives up and extrapolates from where it is: it needs
/// a handful, except for paths that graze the target, where the slope tends to zero.
const MAX_ITERATIONS: usize = 64;

/// Why a shape cast could not be made.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum CastError {
    #[error(
        "only convex shapes (sphere, capsule, box, convex hull) and compounds of them can be \
         swept, not a {0:?}"
    )]
    NotConvex(ShapeKind),
    #[error(
        "the swept {0:?} is flat or degenerate: radii, half extents and half heights must be \
         finite, and > 0 except a capsule's half height (>= 0)"
    )]
    DegenerateShape(ShapeKind),
    #[error("the swept shape's rotation {0:?} is not finite")]
    RotationNotFinite(Quat),
    #[error("the swept shape's rotation is the zero quaternion: give a unit quaternion")]
    ZeroRotation,
    /// The start (the pose's position), the direction or the maximum distance is bad.
    #[error("bad sweep path: {0}")]
    Path(#[from] RayError),
}

/// A convex shape at a pose, swept along a direction up to a maximum distance. Fields are
/// private so that a sweep is always valid (see [`ShapeSweep::new`]).
#[derive(Clone, Copy)]
pub struct ShapeSweep<'a> {
    shape: &'a dyn SupportMap,
    kind: ShapeKind,
    rotation: Quat,
    /// From the pose's position along the unit direction.
    path: Ray,
    bounding_radius: f32,
}

impl std::fmt::Debug for ShapeSweep<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShapeSweep")
            .field("kind", &self.kind)
            .field("rotation", &self.rotation)
            .field("path", &self.path)
            .finish()
    }
}

impl<'a> ShapeSweep<'a> {
    /// `shape` at `pose`, moving along `direction` (normalized here; any non-zero length) for
    /// at most `max_distance` (m, >= 0; `f32::INFINITY` for no limit). The rotation is
    /// normalized; a flat shape (a zero radius or half extent) has no volume to sweep and is an
    /// error, as is any non-convex shape.
    pub fn new(
        shape: &'a Shape,
        pose: &Transform,
        direction: Vec3,
        max_distance: f32,
    ) -> Result<Self, CastError> {
        let kind = shape.kind();
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let support: &dyn SupportMap = match shape {
            Shape::Sphere(s) if positive(s.radius) => s,
            Shape::Capsule(c)
                if positive(c.radius) && c.half_height.is_finite() && c.half_height >= 0.0 =>
            {
                c
            }
            Shape::Cuboid(c)
                if c.half_extents.is_finite() && c.half_extents.cmpgt(Vec3::ZERO).all() =>
            {
                c
            }
            // A hull is checked for volume when it is built.
            Shape::ConvexHull(hull) => &**hull,
            Shape::Sphere(_) | Shape::Capsule(_) | Shape::Cuboid(_) => {
                return Err(CastError::DegenerateShape(kind));
            }
            Shape::Plane(_) | Shape::TriMesh(_) | Shape::Compound(_) => {
                return Err(CastError::NotConvex(kind));
            }
        };
        if !pose.rotation.is_finite() {
            return Err(CastError::RotationNotFinite(pose.rotation));
        }
        let length_squared = pose.rotation.length_squared();
        if length_squared == 0.0 || !length_squared.is_normal() {
            return Err(CastError::ZeroRotation);
        }
        Ok(Self {
            shape: support,
            kind,
            rotation: pose.rotation / length_squared.sqrt(),
            path: Ray::new(pose.position, direction, max_distance)?,
            bounding_radius: shape.bounding_radius(),
        })
    }

    /// A ball of `radius` (m, >= 0, unchecked: 0 is a point) whose centre follows `path`.
    pub(super) fn ball(ball: &'a crate::shape::Sphere, path: &Ray) -> Self {
        Self {
            shape: ball,
            kind: ShapeKind::Sphere,
            rotation: Quat::IDENTITY,
            path: *path,
            bounding_radius: ball.radius,
        }
    }

    /// The path of the shape's origin: from the pose's position, unit direction.
    pub fn path(&self) -> &Ray {
        &self.path
    }

    /// The same sweep cut at `max_distance` (clamped to be >= 0).
    pub fn with_max_distance(&self, max_distance: f32) -> Self {
        Self {
            path: self.path.with_max_distance(max_distance),
            ..*self
        }
    }

    /// Distance from the path to the farthest point of the shape (m): the swept shape stays
    /// inside the path's tube of this radius.
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// What is swept.
    pub fn kind(&self) -> ShapeKind {
        self.kind
    }

    /// The pose after travelling `distance` (m).
    fn pose_at(&self, distance: f32) -> Transform {
        Transform::new(self.path.at(distance), self.rotation)
    }

    /// A hit at the start: see the module documentation.
    fn start_hit(&self) -> ShapeHit {
        ShapeHit {
            distance: 0.0,
            point: self.path.origin(),
            normal: -self.path.direction(),
        }
    }
}

/// A convex shape or a compound swept without turning: one [`ShapeSweep`] per convex part (a
/// convex shape is its own one part; a compound's children each start from their own pose),
/// all travelling the same direction and distance together. What
/// [`World::cast_shape`](crate::World::cast_shape) sweeps.
#[derive(Clone, Debug)]
pub struct SweptParts<'a> {
    parts: Vec<ShapeSweep<'a>>,
    /// From the shape's pose along the unit direction.
    path: Ray,
    bounding_radius: f32,
}

impl<'a> SweptParts<'a> {
    /// `shape` at `pose` moving along `direction` (any non-zero length) for at most
    /// `max_distance` (m); errors as [`ShapeSweep::new`], which checks each part, and
    /// [`CastError::NotConvex`] for a plane or a mesh.
    pub fn new(
        shape: &'a Shape,
        pose: &Transform,
        direction: Vec3,
        max_distance: f32,
    ) -> Result<Self, CastError> {
        let Shape::Compound(compound) = shape else {
            let sweep = ShapeSweep::new(shape, pose, direction, max_distance)?;
            return Ok(Self {
                parts: vec![sweep],
                path: sweep.path,
                bounding_radius: sweep.bounding_radius,
            });
        };
        if !pose.rotation.is_finite() {
            return Err(CastError::RotationNotFinite(pose.rotation));
        }
        let length_squared = pose.rotation.length_squared();
        if length_squared == 0.0 || !length_squared.is_normal() {
            return Err(CastError::ZeroRotation);
        }
        // Normalized before it places the children: a scaled rotation would move them.
        let pose = Transform::new(pose.position, pose.rotation / length_squared.sqrt());
        let path = Ray::new(pose.position, direction, max_distance)?;
        let parts = compound
            .children()
            .iter()
            .map(|child| {
                ShapeSweep::new(
                    &child.shape,
                    &pose.mul_transform(&child.pose),
                    direction,
                    max_distance,
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            parts,
            path,
            bounding_radius: compound.bounding_radius(),
        })
    }

    /// The path of the shape's origin: from the pose's position, unit direction.
    pub fn path(&self) -> &Ray {
        &self.path
    }

    /// Distance from the path to the farthest point of the shape (m).
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// The first contact of any part with `target` at `pose` within `max_distance` (m, at
    /// most the sweep's own): the smallest distance, ties to the lowest part. A part that
    /// touches the target at the start makes the whole shape's start hit: distance 0, at the
    /// path's origin, normal `-direction`.
    pub fn cast(&self, target: &Shape, pose: &Transform, max_distance: f32) -> Option<ShapeHit> {
        let mut first: Option<ShapeHit> = None;
        for part in &self.parts {
            if let Some(hit) = cast_shape(&part.with_max_distance(max_distance), target, pose)
                && first.is_none_or(|best| hit.distance < best.distance)
            {
                first = Some(hit);
            }
        }
        first.map(|hit| match hit.distance {
            0.0 => ShapeHit {
                distance: 0.0,
                point: self.path.origin(),
                normal: -self.path.direction(),
            },
            _ => hit,
        })
    }
}

/// The first contact of the swept shape with `target` at `pose`, within the sweep's maximum
/// distance: `distance` is how far the shape travelled, `point` the contact point, `normal` the
/// target's outward normal there (world frame). `None` for a miss. See the module docs.
pub fn cast_shape(sweep: &ShapeSweep, target: &Shape, pose: &Transform) -> Option<ShapeHit> {
    match target {
        Shape::Sphere(s) => sweep_convex(sweep, s, pose),
        Shape::Capsule(c) => sweep_convex(sweep, c, pose),
        Shape::Cuboid(c) => sweep_convex(sweep, c, pose),
        Shape::ConvexHull(hull) => sweep_convex(sweep, &**hull, pose),
        Shape::Plane(plane) => sweep_plane(sweep, plane, pose),
        Shape::TriMesh(mesh) => sweep_mesh(sweep, mesh, pose),
        Shape::Compound(compound) => nearest_child_hit(
            compound,
            pose,
            &sweep.path,
            sweep.bounding_radius,
            |child, child_pose| cast_shape(sweep, child, child_pose),
        ),
    }
}

/// Conservative advancement against a convex target (module docs).
fn sweep_convex(sweep: &ShapeSweep, target: &dyn SupportMap, pose: &Transform) -> Option<ShapeHit> {
    let radius = sweep.shape.radius() + target.radius();
    let direction = sweep.path.direction();
    let mut travelled = 0.0f32;
    let mut iterations = 0;
    loop {
        let moving_pose = sweep.pose_at(travelled);
        let m = MinkowskiDifference::new(sweep.shape, &moving_pose, target, pose);
        let GjkResult::Separated {
            distance,
            normal,
            point_a,
            ..
        } = gjk(&m)
        else {
            // The cores overlap. Later steps stop SKIN short of contact, so this is the start,
            // or f32 noise at SKIN from a touching polytope: a hit where the shape stands.
            return Some(if travelled == 0.0 {
                sweep.start_hit()
            } else {
                ShapeHit {
                    distance: travelled,
                    point: moving_pose.position,
                    normal: -direction,
                }
            });
        };
        let gap = distance - radius;
        if travelled == 0.0 && gap <= 0.0 {
            return Some(sweep.start_hit());
        }
        let normal = moving_pose.transform_vector(normal);
        let closing = -direction.dot(normal);
        if closing <= 0.0 {
            // d'(t) >= 0 and d is convex: the shapes only draw apart from here.
            return None;
        }
        iterations += 1;
        if gap - SKIN <= CONVERGED || iterations == MAX_ITERATIONS {
            // The last stretch, along the last normal (module docs).
            let remaining = gap / closing;
            let hit_distance = travelled + remaining;
            if hit_distance > sweep.path.max_distance() {
                return None;
            }
            // The moving core's closest point, carried over the last stretch onto the surface.
            let mut point = moving_pose.transform_point(point_a) + remaining * direction
                - sweep.shape.radius() * normal;
            let mut normal = normal;
            // Rounded pairs: at contact the cores are still `radius` apart, where GJK's normal
            // is sharp, so measure there rather than keep the normal from SKIN before, which
            // a curved surface has turned away from (by SKIN / its radius).
            if radius >= SKIN {
                let contact_pose = sweep.pose_at(hit_distance);
                let m = MinkowskiDifference::new(sweep.shape, &contact_pose, target, pose);
                if let GjkResult::Separated {
                    normal: contact_normal,
                    point_a,
                    ..
                } = gjk(&m)
                {
                    normal = contact_pose.transform_vector(contact_normal);
                    point = contact_pose.transform_point(point_a) - sweep.shape.radius() * normal;
                }
            }
            return Some(ShapeHit {
                distance: hit_distance,
                point,
                normal,
            });
        }
        travelled += (gap - SKIN) / closing;
        if travelled > sweep.path.max_distance() {
            return None;
        }
    }
}

/// Against the half-space `n · x <= offset`: the moving shape's deepest point along `-n`
/// reaches the plane first, after its height over the plane divided by the closing speed.
fn sweep_plane(sweep: &ShapeSweep, plane: &Plane, pose: &Transform) -> Option<ShapeHit> {
    let normal = pose.transform_vector(plane.normal);
    let level = normal.dot(pose.position) + plane.offset;
    let start = sweep.pose_at(0.0);
    let lowest = start
        .transform_point(sweep.shape.support(start.inverse_transform_vector(-normal)))
        - sweep.shape.radius() * normal;
    let height = normal.dot(lowest) - level;
    if height <= 0.0 {
        return Some(sweep.start_hit());
    }
    let direction = sweep.path.direction();
    let closing = -direction.dot(normal);
    if closing <= 0.0 {
        return None;
    }
    let distance = height / closing;
    (distance <= sweep.path.max_distance()).then(|| ShapeHit {
        distance,
        point: lowest + distance * direction,
        normal,
    })
}

/// A triangle as a convex core (no radius).
struct TriangleCore([Vec3; 3]);

impl SupportMap for TriangleCore {
    fn support(&self, direction: Vec3) -> Vec3 {
        let [a, b, c] = self.0;
        // Ties go to the lower vertex, so the result is deterministic.
        let (da, db, dc) = (a.dot(direction), b.dot(direction), c.dot(direction));
        if da >= db && da >= dc {
            a
        } else if db >= dc {
            b
        } else {
            c
        }
    }
}

/// The nearest triangle hit, through the mesh's BVH (module docs). Ties go to the lower
/// triangle index. Everything runs in the mesh frame, where the triangles are stored.
fn sweep_mesh(sweep: &ShapeSweep, mesh: &TriMesh, pose: &Transform) -> Option<ShapeHit> {
    let local = ShapeSweep {
        rotation: pose.rotation.inverse() * sweep.rotation,
        // Rotating keeps the direction unit up to rounding, all the sweep needs.
        path: Ray {
            origin: pose.inverse_transform_point(sweep.path.origin),
            direction: pose.inverse_transform_vector(sweep.path.direction),
            max_distance: sweep.path.max_distance,
        },
        ..*sweep
    };
    // The box is swept from its own centre, which is off the path for an off-centre hull.
    let bounds = support_aabb(local.shape, &local.pose_at(0.0));
    let mut best: Option<(ShapeHit, u32)> = None;
    mesh.bvh().sweep(
        bounds.center(),
        bounds.half_extents(),
        local.path.direction(),
        local.path.max_distance(),
        |triangle, max_t| {
            let core = TriangleCore(mesh.triangle(triangle).vertices);
            let Some(hit) =
                sweep_convex(&local.with_max_distance(max_t), &core, &Transform::IDENTITY)
            else {
                return max_t;
            };
            if best.is_none_or(|(b, index)| (hit.distance, triangle) < (b.distance, index)) {
                best = Some((hit, triangle));
            }
            hit.distance
        },
    );
    best.map(|(hit, _)| match hit.distance {
        0.0 => sweep.start_hit(),
        _ => ShapeHit {
            distance: hit.distance,
            point: pose.transform_point(hit.point),
            normal: pose.transform_vector(hit.normal),
        },
    })
}

/// Bounds of a support map at `pose` (6 support queries).
fn support_aabb(shape: &dyn SupportMap, pose: &Transform) -> Aabb {
    let mut min = Vec3::ZERO;
    let mut max = Vec3::ZERO;
    for axis in 0..3 {
        let direction = pose.inverse_transform_vector(Vec3::AXES[axis]);
        max[axis] = pose.transform_point(shape.support(direction))[axis];
        min[axis] = pose.transform_point(shape.support(-direction))[axis];
    }
    Aabb::new(min, max).expanded(shape.radius())
}
