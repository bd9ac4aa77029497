//! Math types shared by every stage: glam re-exports, rigid [`Transform`] and [`Aabb`].
//!
//! Conventions (DESIGN.md): SI units, Y up, right-handed, quaternions `[x, y, z, w]`.

pub use glam::{Mat3, Quat, Vec3, Vec4, vec3};

/// A rigid transform: rotate, then translate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Origin of the frame in world space (m).
    pub position: Vec3,
    /// Orientation of the frame (unit quaternion).
    pub rotation: Quat,
}

impl Default for Transform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Transform {
    pub const IDENTITY: Self = Self {
        position: Vec3::ZERO,
        rotation: Quat::IDENTITY,
    };

    pub fn new(position: Vec3, rotation: Quat) -> Self {
        Self { position, rotation }
    }

    pub fn from_position(position: Vec3) -> Self {
        Self {
            position,
            rotation: Quat::IDENTITY,
        }
    }

    /// Local point → world point.
    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.position + self.rotation * p
    }

    /// Local direction → world direction.
    #[inline]
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation * v
    }

    /// World point → local point.
    #[inline]
    pub fn inverse_transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation.inverse() * (p - self.position)
    }

    /// World direction → local direction.
    #[inline]
    pub fn inverse_transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation.inverse() * v
    }

    /// `self * other`: the frame `other` (given in `self`'s frame) expressed in world space.
    #[inline]
    pub fn mul_transform(&self, other: &Transform) -> Transform {
        Transform {
            position: self.transform_point(other.position),
            rotation: self.rotation * other.rotation,
        }
    }

    /// The transform that maps world space into this frame.
    #[inline]
    pub fn inverse(&self) -> Transform {
        let rotation = self.rotation.inverse();
        Transform {
            position: rotation * -self.position,
            rotation,
        }
    }
}

/// Axis-aligned bounding box. `min <= max` on every axis for a valid box.
///
/// repr(C) + Pod: AABBs are uploaded as flat arrays; 24 bytes, no padding.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}
const _: () = assert!(size_of::<Aabb>() == 24);

impl Aabb {
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    pub fn from_center_half_extents(center: Vec3, half_extents: Vec3) -> Self {
        Self {
            min: center - half_extents,
            max: center + half_extents,
        }
    }

    /// The box grown by `margin` on every side.
    #[inline]
    pub fn expanded(&self, margin: f32) -> Self {
        Self {
            min: self.min - Vec3::splat(margin),
            max: self.max + Vec3::splat(margin),
        }
    }

    #[inline]
    pub fn union(&self, other: &Aabb) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// True when the boxes overlap or touch.
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        self.min.cmple(other.max).all() && other.min.cmple(self.max).all()
    }

    /// True when `other` lies inside `self` (touching counts as inside).
    #[inline]
    pub fn contains(&self, other: &Aabb) -> bool {
        self.min.cmple(other.min).all() && other.max.cmple(self.max).all()
    }

    #[inline]
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    #[inline]
    pub fn half_extents(&self) -> Vec3 {
        0.5 * (self.max - self.min)
    }

    /// Surface area, the cost measure of the surface area heuristic (m²).
    #[inline]
    pub fn surface_area(&self) -> f32 {
        let d = self.max - self.min;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
}

/// An orthonormal basis `(t1, t2)` perpendicular to the unit vector `n`, right-handed
/// (`t1 × t2 = n`). Continuous in `n` except across `n.z = -1`, so friction directions stay
/// steady from step to step and warm starting works (Duff et al. 2017, "Building an
/// orthonormal basis, revisited").
#[inline]
pub fn tangent_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t1 = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let t2 = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    (t1, t2)
}

/// A symmetric 3×3 matrix by its six distinct entries: a body's world-frame inverse inertia
/// in 24 bytes instead of [`Mat3`]'s 36. The contact rows keep both bodies' (see
/// `stages::constraints::contact`), and WGSL's twin is `array<vec3<f32>, 2>` (`lanes.wgsl`),
/// multiplied in the same order.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SymmetricMat3 {
    /// xx, yy, zz.
    pub diagonal: Vec3,
    /// xy, xz, yz.
    pub off_diagonal: Vec3,
}

impl SymmetricMat3 {
    pub const ZERO: Self = Self {
        diagonal: Vec3::ZERO,
        off_diagonal: Vec3::ZERO,
    };

    /// The upper triangle of `m`, which is symmetric up to rounding (R D Rᵀ computed in
    /// floats is not exactly).
    pub fn from_upper(m: Mat3) -> Self {
        Self {
            diagonal: Vec3::new(m.x_axis.x, m.y_axis.y, m.z_axis.z),
            off_diagonal: Vec3::new(m.y_axis.x, m.z_axis.x, m.z_axis.y),
        }
    }

    #[inline]
    pub fn mul_vec3(&self, v: Vec3) -> Vec3 {
        let (d, o) = (self.diagonal, self.off_diagonal);
        Vec3::new(
            d.x * v.x + o.x * v.y + o.y * v.z,
            o.x * v.x + d.y * v.y + o.z * v.z,
            o.y * v.x + o.z * v.y + d.z * v.z,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform_round_trip() {
        let t = Transform::new(vec3(1.0, 2.0, 3.0), Quat::from_rotation_y(0.7));
        let p = vec3(-0.3, 0.5, 4.0);
        assert!((t.inverse_transform_point(t.transform_point(p)) - p).length() < 1e-5);
        assert!((t.inverse().transform_point(t.transform_point(p)) - p).length() < 1e-5);
    }

    #[test]
    fn tangent_basis_is_orthonormal_and_right_handed() {
        for n in [
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            vec3(0.3, -0.8, 0.52).normalize(),
        ] {
            let (t1, t2) = tangent_basis(n);
            assert!(t1.dot(n).abs() < 1e-6 && t2.dot(n).abs() < 1e-6 && t1.dot(t2).abs() < 1e-6);
            assert!((t1.length() - 1.0).abs() < 1e-6 && (t2.length() - 1.0).abs() < 1e-6);
            assert!((t1.cross(t2) - n).length() < 1e-5);
        }
    }

    #[test]
    fn a_symmetric_matrix_multiplies_as_the_full_one() {
        let r = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.1));
        let m = r * Mat3::from_diagonal(vec3(0.5, 2.0, 7.0)) * r.transpose();
        let v = vec3(0.7, -1.3, 2.2);
        let full = m * v;
        assert!((SymmetricMat3::from_upper(m).mul_vec3(v) - full).length() < 1e-5 * full.length());
        assert_eq!(SymmetricMat3::ZERO.mul_vec3(v), Vec3::ZERO);
    }
}
