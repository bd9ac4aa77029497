//! Bodies, split by how hot their data is (as Box2D v3 does): the pose and velocity arrays are
//! read and written every step by every stage; mass is read-only in the step; the collider
//! (shape and material) is read by the collision stages; the description is cold, kept for
//! dumps and queries.
//!
//! All arrays are indexed by the body's slot index. A removed body leaves a hole (its slot is
//! reused by the next body added), so indices — and the broadphase pair keys built from them —
//! stay valid while other bodies come and go.

use crate::math::{Quat, Transform, Vec3, Vec4};
use crate::shape::Shape;

/// Names a body in a [`World`](crate::World). Carries the slot's generation, so a handle to a
/// removed body is caught instead of silently naming the body that reuses its slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BodyHandle {
    pub(crate) index: u32,
    pub(crate) generation: u32,
}

impl BodyHandle {
    /// The slot index: dense over the world's bodies, used by the stages' arrays.
    pub fn index(self) -> u32 {
        self.index
    }
}

/// Position and orientation of a body frame. 32 bytes; repr(C) + Pod because the GPU stages
/// read the same array (the `_pad` keeps `rotation` 16-byte aligned as in WGSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BodyPose {
    pub position: Vec3,
    pub _pad: f32,
    pub rotation: Quat,
}
const _: () = assert!(size_of::<BodyPose>() == 32);

impl BodyPose {
    pub fn new(position: Vec3, rotation: Quat) -> Self {
        Self {
            position,
            _pad: 0.0,
            rotation,
        }
    }

    pub fn transform(&self) -> crate::math::Transform {
        crate::math::Transform::new(self.position, self.rotation)
    }
}

/// Linear (m/s) and angular (rad/s, world frame) velocity. 32 bytes, WGSL-aligned.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BodyVelocity {
    pub linear: Vec3,
    pub _pad0: f32,
    pub angular: Vec3,
    pub _pad1: f32,
}
const _: () = assert!(size_of::<BodyVelocity>() == 32);

impl BodyVelocity {
    pub fn new(linear: Vec3, angular: Vec3) -> Self {
        Self {
            linear,
            _pad0: 0.0,
            angular,
            _pad1: 0.0,
        }
    }
}

/// Inverse mass and inverse principal inertia (body axes). Zero for static bodies. 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BodyMass {
    /// 1/(kg m²) about each body axis.
    pub inverse_inertia: Vec3,
    /// 1/kg.
    pub inverse_mass: f32,
}
const _: () = assert!(size_of::<BodyMass>() == 16);

/// What a body collides as.
#[derive(Clone, Debug, PartialEq)]
pub struct Collider {
    pub shape: Shape,
    /// Coulomb friction coefficient (≥ 0); pairs combine as sqrt(a·b).
    pub friction: f32,
    /// Bounciness in [0, 1]; pairs combine as max(a, b), applied above 1 m/s of approach.
    pub restitution: f32,
}

impl Collider {
    /// The collider as the GPU stages read it.
    pub fn data(&self) -> ColliderData {
        let params = match &self.shape {
            Shape::Sphere(s) => Vec4::new(s.radius, 0.0, 0.0, 0.0),
            Shape::Capsule(c) => Vec4::new(c.radius, c.half_height, 0.0, 0.0),
            Shape::Cuboid(c) => c.half_extents.extend(0.0),
            Shape::Plane(p) => p.normal.extend(p.offset),
            // The GPU narrowphase reads a hull from its own table (`narrowphase::gpu::
            // pack_hulls`) and leaves meshes and compounds to the host; the AABB kernel bounds
            // all three as a box of these half extents about the body origin, which holds the
            // shape's local box.
            Shape::ConvexHull(_) | Shape::TriMesh(_) | Shape::Compound(_) => {
                let local = self.shape.aabb(&Transform::IDENTITY);
                local.min.abs().max(local.max.abs()).extend(0.0)
            }
        };
        ColliderData {
            kind: self.shape.kind() as u32,
            friction: self.friction,
            restitution: self.restitution,
            bounding_radius: self.shape.bounding_radius(),
            params,
        }
    }
}

/// A [`Collider`] packed for the GPU: the shape as its [`ShapeKind`](crate::shape::ShapeKind)
/// and up to four parameters, and the material. 32 bytes, repr(C) + Pod with the layout of
/// `ColliderData` in `body.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ColliderData {
    /// `ShapeKind as u32`.
    pub kind: u32,
    pub friction: f32,
    pub restitution: f32,
    /// [`Shape::bounding_radius`] (m), for the narrowphase's closing-speed bound.
    pub bounding_radius: f32,
    /// Sphere: (radius, 0, 0, 0); capsule: (radius, half_height, 0, 0); cuboid: (half
    /// extents, 0); plane: (unit normal, offset); convex hull, triangle mesh and compound: (half
    /// extents of a box centred on the body origin that holds the shape, 0), for the AABB
    /// kernel.
    pub params: Vec4,
}
const _: () = assert!(size_of::<ColliderData>() == 32);

/// WGSL twins of [`BodyPose`], [`BodyVelocity`], [`BodyMass`] and [`ColliderData`], with the
/// shape kinds: the snippet every rigid-body kernel includes.
pub const BODY_WGSL: &str = include_str!("body.wgsl");

/// Everything needed to create a body. Build one with [`BodyDesc::dynamic`] or
/// [`BodyDesc::fixed`] and the builder methods; [`World::add_body`](crate::World::add_body)
/// validates it.
#[must_use]
#[derive(Clone, Debug, PartialEq)]
pub struct BodyDesc {
    pub shape: Shape,
    /// Body frame origin (m). Default: the world origin.
    pub position: Vec3,
    /// Body frame orientation; a non-unit quaternion is normalized. Default: identity.
    pub rotation: Quat,
    /// kg; 0 makes the body static. Default: 1 for [`dynamic`](Self::dynamic).
    pub mass: f32,
    /// m/s. Default: zero.
    pub linear_velocity: Vec3,
    /// rad/s in the world frame. Default: zero.
    pub angular_velocity: Vec3,
    /// Default: 0.5.
    pub friction: f32,
    /// Default: 0.
    pub restitution: f32,
    /// Optional unique name, kept in dumped scenes. Default: none.
    pub name: Option<String>,
}

impl BodyDesc {
    /// A dynamic body of mass 1 kg.
    pub fn dynamic(shape: Shape) -> Self {
        Self {
            shape,
            position: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            mass: 1.0,
            linear_velocity: Vec3::ZERO,
            angular_velocity: Vec3::ZERO,
            friction: 0.5,
            restitution: 0.0,
            name: None,
        }
    }

    /// A static body: it never moves and has infinite mass.
    pub fn fixed(shape: Shape) -> Self {
        Self {
            mass: 0.0,
            ..Self::dynamic(shape)
        }
    }

    pub fn position(mut self, position: Vec3) -> Self {
        self.position = position;
        self
    }

    pub fn rotation(mut self, rotation: Quat) -> Self {
        self.rotation = rotation;
        self
    }

    pub fn mass(mut self, mass: f32) -> Self {
        self.mass = mass;
        self
    }

    pub fn linear_velocity(mut self, velocity: Vec3) -> Self {
        self.linear_velocity = velocity;
        self
    }

    pub fn angular_velocity(mut self, velocity: Vec3) -> Self {
        self.angular_velocity = velocity;
        self
    }

    pub fn friction(mut self, friction: f32) -> Self {
        self.friction = friction;
        self
    }

    pub fn restitution(mut self, restitution: f32) -> Self {
        self.restitution = restitution;
        self
    }

    pub fn name(mut self, name: impl Into<String>) -> Self {
        self.name = Some(name.into());
        self
    }

    /// The rotation as the body will get it: normalized when visibly off unit length, else
    /// kept bit for bit (so a dumped state loads back exactly).
    pub fn unit_rotation(&self) -> Quat {
        let length_squared = self.rotation.length_squared();
        if (length_squared - 1.0).abs() > 1e-5 {
            self.rotation / length_squared.sqrt()
        } else {
            self.rotation
        }
    }

    pub fn is_static(&self) -> bool {
        self.mass == 0.0
    }

    /// Checks the description; `Err` names the offending field.
    pub fn validate(&self) -> Result<(), BodyError> {
        let finite = |field: &'static str, values: &[f32]| {
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err(BodyError::NotFinite { field })
            }
        };
        finite("position", &self.position.to_array())?;
        finite("rotation", &self.rotation.to_array())?;
        finite("mass", &[self.mass])?;
        finite("linear_velocity", &self.linear_velocity.to_array())?;
        finite("angular_velocity", &self.angular_velocity.to_array())?;
        finite("friction", &[self.friction])?;
        finite("restitution", &[self.restitution])?;
        if self.rotation.length_squared() == 0.0 {
            return Err(BodyError::ZeroRotation);
        }
        if self.mass < 0.0 {
            return Err(BodyError::Negative {
                field: "mass",
                value: self.mass,
            });
        }
        if self.friction < 0.0 {
            return Err(BodyError::Negative {
                field: "friction",
                value: self.friction,
            });
        }
        if !(0.0..=1.0).contains(&self.restitution) {
            return Err(BodyError::RestitutionOutOfRange(self.restitution));
        }
        validate_shape(&self.shape)?;
        if matches!(self.shape, Shape::Plane(_)) && !self.is_static() {
            return Err(BodyError::DynamicPlane);
        }
        if matches!(self.shape, Shape::TriMesh(_)) && !self.is_static() {
            return Err(BodyError::DynamicTriMesh);
        }
        Ok(())
    }
}

fn validate_shape(shape: &Shape) -> Result<(), BodyError> {
    let positive = |field: &'static str, value: f32| {
        if !value.is_finite() {
            Err(BodyError::NotFinite { field })
        } else if value <= 0.0 {
            Err(BodyError::NotPositive { field, value })
        } else {
            Ok(())
        }
    };
    match shape {
        Shape::Sphere(s) => positive("radius", s.radius),
        Shape::Cuboid(c) => c
            .half_extents
            .to_array()
            .iter()
            .try_for_each(|&e| positive("half_extents", e)),
        Shape::Capsule(c) => {
            positive("radius", c.radius)?;
            if !c.half_height.is_finite() {
                return Err(BodyError::NotFinite {
                    field: "half_height",
                });
            }
            if c.half_height < 0.0 {
                return Err(BodyError::Negative {
                    field: "half_height",
                    value: c.half_height,
                });
            }
            Ok(())
        }
        Shape::Plane(p) => {
            if !p.normal.is_finite() || !p.offset.is_finite() {
                return Err(BodyError::NotFinite { field: "plane" });
            }
            if (p.normal.length() - 1.0).abs() > 1e-4 {
                return Err(BodyError::ZeroNormal);
            }
            Ok(())
        }
        // Checked when the mesh was built (TriMesh::new).
        Shape::TriMesh(_) => Ok(()),
        // Hulls and compounds are checked when they are built (`ConvexHull::new`,
        // `Compound::new`).
        Shape::ConvexHull(_) | Shape::Compound(_) => Ok(()),
    }
}

/// Why a body could not be added or named.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BodyError {
    #[error("{field} must be finite (no NaN or infinity)")]
    NotFinite { field: &'static str },
    #[error("{field} must be > 0, got {value}")]
    NotPositive { field: &'static str, value: f32 },
    #[error("{field} must be >= 0, got {value}")]
    Negative { field: &'static str, value: f32 },
    #[error("restitution must be in [0, 1], got {0}")]
    RestitutionOutOfRange(f32),
    #[error("rotation is the zero quaternion; give a unit quaternion [x, y, z, w]")]
    ZeroRotation,
    #[error("plane normal must be non-zero")]
    ZeroNormal,
    #[error("a plane is infinite and must be static (mass 0)")]
    DynamicPlane,
    #[error("a triangle mesh is static only (mass 0); use a convex shape for moving bodies")]
    DynamicTriMesh,
    #[error(
        "a compound of {children} children on a mesh of {triangles} triangles needs more than \
         2^32 child manifold keys; split the mesh or the compound"
    )]
    CompoundMeshKeys { children: usize, triangles: usize },
    #[error("the body handle is stale: that body was removed")]
    StaleHandle,
    #[error("reading the contacts back from the GPU failed: {0}")]
    ContactsReadback(String),
    #[error("reading the bodies back from the GPU failed: {0}")]
    BodiesReadback(String),
    #[error("body name {0:?} is used twice")]
    DuplicateName(String),
}

impl BodyError {
    /// A failed read-back of the bodies the device holds.
    pub(crate) fn readback(error: crate::gpu::context::GpuError) -> Self {
        BodyError::BodiesReadback(error.to_string())
    }

    /// The problem without the field's name, for callers that name the field themselves
    /// (the scene loader writes `bodies[3].mass: must be >= 0, got -1`).
    pub fn requirement(&self) -> String {
        match self {
            BodyError::NotFinite { .. } => "must be finite (no NaN or infinity)".into(),
            BodyError::NotPositive { value, .. } => format!("must be > 0, got {value}"),
            BodyError::Negative { value, .. } => format!("must be >= 0, got {value}"),
            other => other.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_descriptions_name_the_problem() {
        let unit_box = || BodyDesc::dynamic(Shape::cuboid(Vec3::ONE));
        assert_eq!(
            unit_box()
                .position(Vec3::new(f32::NAN, 0.0, 0.0))
                .validate(),
            Err(BodyError::NotFinite { field: "position" })
        );
        assert_eq!(
            unit_box().mass(-1.0).validate(),
            Err(BodyError::Negative {
                field: "mass",
                value: -1.0
            })
        );
        assert_eq!(
            BodyDesc::dynamic(Shape::cuboid(Vec3::new(1.0, 0.0, 1.0))).validate(),
            Err(BodyError::NotPositive {
                field: "half_extents",
                value: 0.0
            })
        );
        assert_eq!(
            BodyDesc::dynamic(Shape::sphere(-1.0)).validate(),
            Err(BodyError::NotPositive {
                field: "radius",
                value: -1.0
            })
        );
        assert_eq!(
            BodyDesc::dynamic(Shape::plane(Vec3::Y, 0.0)).validate(),
            Err(BodyError::DynamicPlane)
        );
        assert_eq!(
            BodyDesc::fixed(Shape::plane(Vec3::ZERO, 0.0)).validate(),
            Err(BodyError::ZeroNormal)
        );
        assert_eq!(
            unit_box()
                .rotation(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0))
                .validate(),
            Err(BodyError::ZeroRotation)
        );
        assert!(unit_box().validate().is_ok());
    }
}
