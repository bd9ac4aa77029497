//! Collision shapes. Primitives are centred on their body frame; a plane and a triangle mesh
//! are static only; a convex hull and a compound are stored in their principal centroid frames
//! (see [`convex_hull`], [`compound`]). Hulls and meshes are shared behind an `Arc`, so `Shape` is `Clone` but
//! not `Copy`.

pub mod compound;
pub mod convex_hull;
pub mod trimesh;

use std::sync::Arc;

use crate::math::{Aabb, Transform, Vec3};
pub use compound::{Compound, CompoundChild, CompoundError, MAX_COMPOUND_CHILDREN};
pub use convex_hull::{ConvexHull, HullError};
pub use trimesh::{TriMesh, TriMeshError};

/// Half-size of the box that stands for "everywhere" in an infinite plane's AABB (m). Large
/// enough for any scene, small enough that surface areas stay finite in f32 (SAH costs).
pub const PLANE_AABB_EXTENT: f32 = 1.0e15;

/// A collision shape, in its body's frame. Clone is cheap: a hull is shared through an `Arc`.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    Sphere(Sphere),
    Cuboid(Cuboid),
    Capsule(Capsule),
    Plane(Plane),
    ConvexHull(Arc<ConvexHull>),
    /// A static triangle mesh, in the body frame.
    TriMesh(Arc<TriMesh>),
    /// Convex shapes at poses in the body frame.
    Compound(Arc<Compound>),
}

/// A ball of `radius` (m) centred on the body origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub radius: f32,
}

/// A box with `half_extents` (m) along the body's axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    pub half_extents: Vec3,
}

/// A capsule along the body's Y axis: the segment from `-half_height` to `+half_height` (m),
/// swept by a ball of `radius` (m). Total height is `2 * half_height + 2 * radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    pub radius: f32,
    pub half_height: f32,
}

/// The solid half-space `normal · x <= offset` in the body frame. `normal` is unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: Vec3,
    pub offset: f32,
}

/// The kind of a shape, as a small integer: the order pair functions are dispatched in.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ShapeKind {
    Sphere = 0,
    Capsule = 1,
    Cuboid = 2,
    Plane = 3,
    ConvexHull = 4,
    TriMesh = 5,
    Compound = 6,
}

/// Mass and rotational inertia of a body about its centre of mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// 1 / mass (1/kg); 0 for a static body.
    pub inverse_mass: f32,
    /// Inverse of the principal moments of inertia along the body axes (1/(kg m²)).
    pub inverse_inertia: Vec3,
}

impl MassProperties {
    pub const STATIC: Self = Self {
        inverse_mass: 0.0,
        inverse_inertia: Vec3::ZERO,
    };
}

impl Shape {
    pub fn sphere(radius: f32) -> Self {
        Shape::Sphere(Sphere { radius })
    }

    pub fn cuboid(half_extents: Vec3) -> Self {
        Shape::Cuboid(Cuboid { half_extents })
    }

    pub fn capsule(radius: f32, half_height: f32) -> Self {
        Shape::Capsule(Capsule {
            radius,
            half_height,
        })
    }

    pub fn trimesh(mesh: TriMesh) -> Self {
        Shape::TriMesh(Arc::new(mesh))
    }

    /// A plane `normal · x <= offset`; `normal` is normalized here.
    pub fn plane(normal: Vec3, offset: f32) -> Self {
        Shape::Plane(Plane {
            normal: normal.normalize_or_zero(),
            offset,
        })
    }

    /// The compound of `children` (convex shapes at poses in the body frame); `Err` names the
    /// first child that cannot be one.
    pub fn compound(children: Vec<CompoundChild>) -> Result<Self, CompoundError> {
        Ok(Shape::Compound(Arc::new(Compound::new(children)?)))
    }

    /// The convex hull of `points` (m); `Err` when they enclose no volume.
    pub fn convex_hull(points: &[Vec3]) -> Result<Self, HullError> {
        Ok(Shape::ConvexHull(Arc::new(ConvexHull::new(points)?)))
    }

    pub fn kind(&self) -> ShapeKind {
        match self {
            Shape::Sphere(_) => ShapeKind::Sphere,
            Shape::Capsule(_) => ShapeKind::Capsule,
            Shape::Cuboid(_) => ShapeKind::Cuboid,
            Shape::Plane(_) => ShapeKind::Plane,
            Shape::TriMesh(_) => ShapeKind::TriMesh,
            Shape::ConvexHull(_) => ShapeKind::ConvexHull,
            Shape::Compound(_) => ShapeKind::Compound,
        }
    }

    /// World-space bounding box of the shape at `pose`.
    pub fn aabb(&self, pose: &Transform) -> Aabb {
        match self {
            Shape::Sphere(s) => {
                Aabb::from_center_half_extents(pose.position, Vec3::splat(s.radius))
            }
            Shape::Cuboid(c) => {
                let m = glam::Mat3::from_quat(pose.rotation);
                // Extent along each world axis = sum of |rotated axis| * half extent.
                let e = m.x_axis.abs() * c.half_extents.x
                    + m.y_axis.abs() * c.half_extents.y
                    + m.z_axis.abs() * c.half_extents.z;
                Aabb::from_center_half_extents(pose.position, e)
            }
            Shape::Capsule(c) => {
                let axis = pose.rotation * Vec3::new(0.0, c.half_height, 0.0);
                Aabb::from_center_half_extents(pose.position, axis.abs() + Vec3::splat(c.radius))
            }
            Shape::Plane(p) => {
                let n = pose.rotation * p.normal;
                let point_on_plane = pose.position + n * p.offset;
                let mut aabb =
                    Aabb::from_center_half_extents(Vec3::ZERO, Vec3::splat(PLANE_AABB_EXTENT));
                // An axis-aligned plane bounds its half-space on that axis.
                for axis in 0..3 {
                    if (n[axis].abs() - 1.0).abs() <= 1e-6 {
                        let level = point_on_plane[axis];
                        if n[axis] > 0.0 {
                            aabb.max[axis] = level;
                        } else {
                            aabb.min[axis] = level;
                        }
                    }
                }
                aabb
            }
            Shape::TriMesh(mesh) => {
                let local = mesh.local_aabb();
                let m = glam::Mat3::from_quat(pose.rotation);
                let e = local.half_extents();
                let e = m.x_axis.abs() * e.x + m.y_axis.abs() * e.y + m.z_axis.abs() * e.z;
                Aabb::from_center_half_extents(pose.transform_point(local.center()), e)
            }
            Shape::ConvexHull(hull) => {
                // The extreme vertex along each world axis, found in the hull frame.
                let mut min = Vec3::ZERO;
                let mut max = Vec3::ZERO;
                for axis in 0..3 {
                    let direction = pose.inverse_transform_vector(Vec3::AXES[axis]);
                    max[axis] = pose.transform_point(hull.support(direction))[axis];
                    min[axis] = pose.transform_point(hull.support(-direction))[axis];
                }
                Aabb::new(min, max)
            }
            Shape::Compound(compound) => compound.aabb(pose),
        }
    }

    /// Distance from the body origin to the farthest point of the shape (m); 0 for a plane,
    /// which never moves.
    pub fn bounding_radius(&self) -> f32 {
        match self {
            Shape::Sphere(s) => s.radius,
            Shape::Cuboid(c) => c.half_extents.length(),
            Shape::Capsule(c) => c.half_height + c.radius,
            Shape::Plane(_) => 0.0,
            Shape::TriMesh(mesh) => mesh.bounding_radius(),
            Shape::ConvexHull(hull) => hull.bounding_radius(),
            Shape::Compound(compound) => compound.bounding_radius(),
        }
    }

    /// Mass properties for a body of `mass` (kg) with uniform density. `mass == 0` → static.
    pub fn mass_properties(&self, mass: f32) -> MassProperties {
        if mass <= 0.0 {
            return MassProperties::STATIC;
        }
        let inertia = match self {
            Shape::Sphere(s) => Vec3::splat(0.4 * mass * s.radius * s.radius),
            Shape::Cuboid(c) => {
                let d = 2.0 * c.half_extents;
                let d2 = d * d;
                mass / 12.0 * Vec3::new(d2.y + d2.z, d2.x + d2.z, d2.x + d2.y)
            }
            Shape::Capsule(c) => capsule_inertia(mass, c.radius, c.half_height),
            Shape::Plane(_) | Shape::TriMesh(_) => return MassProperties::STATIC,
            Shape::ConvexHull(hull) => mass * hull.unit_inertia(),
            Shape::Compound(compound) => mass * compound.unit_inertia(),
        };
        MassProperties {
            inverse_mass: 1.0 / mass,
            inverse_inertia: inertia.recip(),
        }
    }
}

/// Inertia of a solid capsule (axis Y) about its centre: a cylinder plus two hemispheres with
/// the mass split by volume, the hemispheres moved out by the parallel-axis theorem.
pub(super) fn capsule_inertia(mass: f32, r: f32, half_height: f32) -> Vec3 {
    use std::f32::consts::PI;
    let h = 2.0 * half_height;
    let cylinder_volume = PI * r * r * h;
    let sphere_volume = 4.0 / 3.0 * PI * r * r * r;
    let density = mass / (cylinder_volume + sphere_volume);
    let mc = density * cylinder_volume;
    let ms = density * sphere_volume; // both hemispheres together
    let axial = mc * r * r / 2.0 + ms * 2.0 / 5.0 * r * r;
    // Hemisphere centroid sits 3r/8 from its flat face; the face is h/2 from the centre.
    let transverse = mc * (3.0 * r * r + h * h) / 12.0
        + ms * (2.0 / 5.0 * r * r + h * h / 4.0 + 3.0 * h * r / 8.0);
    Vec3::new(transverse, axial, transverse)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Quat;

    #[test]
    fn rotated_box_aabb_encloses_corners() {
        let shape = Shape::cuboid(Vec3::new(1.0, 0.5, 0.25));
        let pose = Transform::new(
            Vec3::new(1.0, 2.0, 3.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.9, -0.4),
        );
        let aabb = shape.aabb(&pose);
        for i in 0..8 {
            let s = Vec3::new(
                [-1.0, 1.0][i & 1],
                [-1.0, 1.0][(i >> 1) & 1],
                [-1.0, 1.0][i >> 2],
            );
            let corner = pose.transform_point(s * Vec3::new(1.0, 0.5, 0.25));
            assert!(aabb.expanded(1e-5).contains(&Aabb::new(corner, corner)));
        }
    }

    #[test]
    fn capsule_inertia_tends_to_sphere_and_rod() {
        // No straight part: a solid sphere.
        let i = capsule_inertia(2.0, 0.5, 0.0);
        assert!((i - Vec3::splat(0.4 * 2.0 * 0.25)).abs().max_element() < 1e-6);
        // Very thin: a rod of length h about its middle, m h² / 12.
        let i = capsule_inertia(3.0, 1e-4, 1.0);
        assert!((i.x - 3.0 * 4.0 / 12.0).abs() < 1e-3);
    }

    #[test]
    fn ground_plane_aabb_is_a_half_space() {
        let aabb = Shape::plane(Vec3::Y, 0.5).aabb(&Transform::IDENTITY);
        assert_eq!(aabb.max.y, 0.5);
        assert!(aabb.min.y < -1e14 && aabb.max.x > 1e14);
    }
}
