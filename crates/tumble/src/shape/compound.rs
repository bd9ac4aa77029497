//! Compound shapes: several convex shapes (sphere, capsule, box, convex hull) rigidly joined,
//! each at its own pose in the compound's frame. A dumbbell is two spheres and a capsule; a
//! table is a top and four legs.
//!
//! # Frame
//!
//! As for a [`ConvexHull`]: the solver holds a diagonal inertia in the body frame, so the
//! children are stored in the compound's principal centroid frame and
//! [`Compound::local_frame`] is that frame in the frame the children were given in; a body built
//! from the compound at pose `P` sits at `P * local_frame`. Children already centred on their
//! principal axes (within [`RELATIVE_TOLERANCE`]) keep their poses bit for bit and the frame is
//! exactly the identity, so a dumped compound reads back as the same compound.
//!
//! # Mass
//!
//! Uniform density: each child weighs in by its volume. Children that overlap count twice
//! where they overlap (no boolean union), as in Bullet, Rapier and Jolt; give children that
//! touch, not overlap, for exact mass properties.
//!
//! # Collision
//!
//! A pair with a compound collides child by child (`collide_compound`; on a triangle mesh, each
//! child against the triangles); each touching child pair keeps its own manifold in the
//! narrowphase's child cache. Hull children meet no meshes, as hulls do not. Children are a flat list: every
//! child is tested, which suits the tens of children a compound built by hand has.

use std::sync::Arc;

use glam::{DMat3, DVec3};

use super::convex_hull::{RELATIVE_TOLERANCE, jacobi_eigenvectors, off_diagonal_ratio};
use super::{Shape, ShapeKind, capsule_inertia};
use crate::math::{Aabb, Quat, Transform};

/// Most children a compound may have: child manifolds are keyed by `child_a * children_b +
/// child_b` in a `u32`, which this keeps in range for two compounds of this size.
pub const MAX_COMPOUND_CHILDREN: usize = 1 << 15;

/// One convex part of a compound at `pose` in the compound's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct CompoundChild {
    pub shape: Shape,
    pub pose: Transform,
}

/// Why children make no compound.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CompoundError {
    #[error("a compound needs at least one child shape")]
    Empty,
    #[error("a compound holds at most {MAX_COMPOUND_CHILDREN} children, got {count}")]
    TooManyChildren { count: usize },
    #[error(
        "child {index} is a {kind:?}; children must be convex: sphere, capsule, box or \
         convex hull"
    )]
    UnsupportedChild { index: usize, kind: ShapeKind },
    #[error("child {index}: position must be finite (no NaN or infinity)")]
    PositionNotFinite { index: usize },
    #[error("child {index}: rotation must be finite (no NaN or infinity)")]
    RotationNotFinite { index: usize },
    #[error("child {index}: rotation is the zero quaternion; give a unit quaternion [x, y, z, w]")]
    ZeroRotation { index: usize },
    #[error(
        "child {index}: sizes must be finite and > 0 (a capsule's half_height may be 0), got \
         {shape:?}"
    )]
    BadChildSize { index: usize, shape: Shape },
}

/// Convex children at poses in the compound's principal centroid frame (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Compound {
    children: Vec<CompoundChild>,
    local_frame: Transform,
    /// Principal moments of inertia per kg of mass (m²).
    unit_inertia: glam::Vec3,
    bounding_radius: f32,
}

impl Compound {
    /// The compound of `children` (poses in the compound's input frame, rotations normalized
    /// here); `Err` names the first bad child.
    pub fn new(children: Vec<CompoundChild>) -> Result<Self, CompoundError> {
        if children.is_empty() {
            return Err(CompoundError::Empty);
        }
        if children.len() > MAX_COMPOUND_CHILDREN {
            return Err(CompoundError::TooManyChildren {
                count: children.len(),
            });
        }
        let mut checked = Vec::with_capacity(children.len());
        for (index, child) in children.into_iter().enumerate() {
            checked.push(check_child(index, child)?);
        }
        let (volume, centroid, inertia) = mass_moments(&checked);
        let extent = checked
            .iter()
            .map(|child| {
                child.pose.position.as_dvec3().length() + f64::from(child.shape.bounding_radius())
            })
            .fold(0.0, f64::max);
        let already_principal = centroid.length() <= RELATIVE_TOLERANCE * extent
            && off_diagonal_ratio(&inertia) <= RELATIVE_TOLERANCE;
        let (children, local_frame, principal_inertia) = if already_principal {
            (checked, Transform::IDENTITY, diagonal(&inertia))
        } else {
            let mut axes = jacobi_eigenvectors(inertia);
            if axes.determinant() < 0.0 {
                axes.z_axis = -axes.z_axis;
            }
            let rotation = Quat::from_mat3(&axes.as_mat3()).normalize();
            let frame = Transform::new(centroid.as_vec3(), rotation);
            let frame_inverse = frame.inverse();
            let children = checked
                .into_iter()
                .map(|child| CompoundChild {
                    pose: frame_inverse.mul_transform(&child.pose),
                    ..child
                })
                .collect();
            // The tensor in the frame actually stored (f32 rotation), so the moments match it.
            let stored_axes = DMat3::from_quat(rotation.as_dquat());
            let principal = stored_axes.transpose() * inertia * stored_axes;
            (children, frame, diagonal(&principal))
        };
        let bounding_radius = children
            .iter()
            .map(|child| child.pose.position.length() + child.shape.bounding_radius())
            .fold(0.0, f32::max);
        Ok(Self {
            children,
            local_frame,
            unit_inertia: (principal_inertia / volume).as_vec3(),
            bounding_radius,
        })
    }

    /// The children, poses in the compound frame.
    pub fn children(&self) -> &[CompoundChild] {
        &self.children
    }

    /// The compound frame (centroid, principal axes) in the frame the children were given in.
    pub fn local_frame(&self) -> Transform {
        self.local_frame
    }

    /// The same compound with its frame taken as the input frame: what a body built from it
    /// stores, its pose having absorbed [`local_frame`](Self::local_frame).
    pub fn in_own_frame(&self) -> Self {
        Self {
            local_frame: Transform::IDENTITY,
            ..self.clone()
        }
    }

    /// Principal moments of inertia for a mass of 1 kg (kg m²).
    pub fn unit_inertia(&self) -> glam::Vec3 {
        self.unit_inertia
    }

    /// Distance from the compound frame's origin to its farthest point, bounded above (m).
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// World bounding box at `pose`: the union of the children's.
    pub fn aabb(&self, pose: &Transform) -> Aabb {
        let mut children = self
            .children
            .iter()
            .map(|child| child.shape.aabb(&pose.mul_transform(&child.pose)));
        let first = children
            .next()
            .expect("a compound has a child (checked in new)");
        children.fold(first, |all, aabb| all.union(&aabb))
    }
}

/// `child` with a unit rotation and, for a hull, the hull's own frame folded into the pose (so
/// every child is centred on its centroid); `Err` when it cannot be a child.
fn check_child(index: usize, child: CompoundChild) -> Result<CompoundChild, CompoundError> {
    let CompoundChild { shape, pose } = child;
    if !pose.position.is_finite() {
        return Err(CompoundError::PositionNotFinite { index });
    }
    if !pose.rotation.is_finite() {
        return Err(CompoundError::RotationNotFinite { index });
    }
    let length_squared = pose.rotation.length_squared();
    if length_squared == 0.0 || !length_squared.is_normal() {
        return Err(CompoundError::ZeroRotation { index });
    }
    let pose = Transform::new(pose.position, pose.rotation / length_squared.sqrt());
    let positive = |x: f32| x.is_finite() && x > 0.0;
    let sized = match &shape {
        Shape::Sphere(s) => positive(s.radius),
        Shape::Capsule(c) => {
            positive(c.radius) && c.half_height.is_finite() && c.half_height >= 0.0
        }
        Shape::Cuboid(c) => c.half_extents.to_array().into_iter().all(positive),
        // Checked for volume when it was built.
        Shape::ConvexHull(_) => true,
        Shape::Plane(_) | Shape::TriMesh(_) | Shape::Compound(_) => {
            return Err(CompoundError::UnsupportedChild {
                index,
                kind: shape.kind(),
            });
        }
    };
    if !sized {
        return Err(CompoundError::BadChildSize { index, shape });
    }
    Ok(match shape {
        Shape::ConvexHull(hull) if hull.local_frame() != Transform::IDENTITY => CompoundChild {
            pose: pose.mul_transform(&hull.local_frame()),
            shape: Shape::ConvexHull(Arc::new(hull.in_own_frame())),
        },
        shape => CompoundChild { shape, pose },
    })
}

/// Volume (m³), centroid (m) and inertia tensor about the centroid per unit density (m⁵) of
/// the children (centred on their centroids, see [`check_child`]): each child's own tensor
/// rotated into the compound frame, moved to the centroid by the parallel-axis theorem
/// `I + V (|d|² E − d dᵀ)`. In f64, as for hulls.
fn mass_moments(children: &[CompoundChild]) -> (f64, DVec3, DMat3) {
    let parts: Vec<(f64, DVec3, DMat3)> = children
        .iter()
        .map(|child| {
            let (volume, unit_inertia) = volume_and_unit_inertia(&child.shape);
            let rotation = DMat3::from_quat(child.pose.rotation.as_dquat());
            let own = rotation * DMat3::from_diagonal(unit_inertia * volume) * rotation.transpose();
            (volume, child.pose.position.as_dvec3(), own)
        })
        .collect();
    let volume: f64 = parts.iter().map(|part| part.0).sum();
    let centroid = parts
        .iter()
        .map(|&(v, position, _)| v * position)
        .sum::<DVec3>()
        / volume;
    let inertia = parts.iter().fold(DMat3::ZERO, |sum, &(v, position, own)| {
        let d = position - centroid;
        let shift = DMat3::from_diagonal(DVec3::splat(d.length_squared()))
            - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        sum + own + shift * v
    });
    (volume, centroid, inertia)
}

/// Volume (m³) and principal moments per unit mass (m²) of a convex child about its centre,
/// along its axes.
fn volume_and_unit_inertia(shape: &Shape) -> (f64, DVec3) {
    use std::f64::consts::PI;
    match shape {
        Shape::Sphere(s) => {
            let r = f64::from(s.radius);
            (4.0 / 3.0 * PI * r * r * r, DVec3::splat(0.4 * r * r))
        }
        Shape::Cuboid(c) => {
            let d2 = (2.0 * c.half_extents.as_dvec3()).powf(2.0);
            let volume = 8.0 * c.half_extents.as_dvec3().element_product();
            (
                volume,
                DVec3::new(d2.y + d2.z, d2.x + d2.z, d2.x + d2.y) / 12.0,
            )
        }
        Shape::Capsule(c) => {
            let (r, h) = (f64::from(c.radius), f64::from(c.half_height));
            let volume = PI * r * r * 2.0 * h + 4.0 / 3.0 * PI * r * r * r;
            (
                volume,
                capsule_inertia(1.0, c.radius, c.half_height).as_dvec3(),
            )
        }
        Shape::ConvexHull(hull) => (f64::from(hull.volume()), hull.unit_inertia().as_dvec3()),
        // Refused by `check_child`.
        Shape::Plane(_) | Shape::TriMesh(_) | Shape::Compound(_) => (0.0, DVec3::ZERO),
    }
}

fn diagonal(m: &DMat3) -> DVec3 {
    DVec3::new(m.x_axis.x, m.y_axis.y, m.z_axis.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Vec3, vec3};
    use std::f32::consts::PI;

    fn child(shape: Shape, position: Vec3) -> CompoundChild {
        CompoundChild {
            shape,
            pose: Transform::from_position(position),
        }
    }

    /// Two balls of radius r at ±L along an axis: I = 2·(m/2)·(2r²/5) about the axis and
    /// 2·(m/2)·(2r²/5 + L²) across it (parallel axis), about their midpoint. Placed off the
    /// origin and turned, the frame must find the midpoint and the axis.
    #[test]
    fn two_balls_on_a_rod_have_the_closed_form_inertia_and_frame() {
        let (r, l) = (0.2f32, 0.7f32);
        let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.8, 0.5);
        let centre = vec3(1.0, -2.0, 0.5);
        let axis = turn * Vec3::X;
        let compound = Compound::new(vec![
            child(Shape::sphere(r), centre + l * axis),
            child(Shape::sphere(r), centre - l * axis),
        ])
        .unwrap();
        let frame = compound.local_frame();
        assert!((frame.position - centre).length() < 1e-5, "{frame:?}");
        let along = 0.4 * r * r;
        let across = 0.4 * r * r + l * l;
        let inertia = compound.unit_inertia();
        // The axis with the small moment is the rod.
        let (rod_axis, rod_moment) = (0..3)
            .map(|i| (frame.rotation * Vec3::AXES[i], inertia[i]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert!((rod_moment - along).abs() < 1e-6 * across, "{inertia}");
        assert!(
            rod_axis.dot(axis).abs() > 1.0 - 1e-6,
            "{rod_axis} vs {axis}"
        );
        let sum = inertia.x + inertia.y + inertia.z;
        assert!(
            (sum - (along + 2.0 * across)).abs() < 1e-5 * across,
            "{inertia}"
        );
        // The children sit at ±L on the rod axis of the stored frame.
        for stored in compound.children() {
            let offset = stored.pose.position;
            assert!((offset.length() - l).abs() < 1e-5);
            assert!(
                offset
                    .normalize()
                    .dot(frame.rotation.inverse() * axis)
                    .abs()
                    > 1.0 - 1e-6
            );
        }
    }

    /// Two unit cubes side by side are one 2 × 1 × 1 box: the same centre and moments, moved
    /// from each cube's centre by the parallel-axis theorem.
    #[test]
    fn two_cubes_side_by_side_weigh_as_one_box() {
        let cube = Shape::cuboid(Vec3::splat(0.5));
        let compound =
            Compound::new(vec![child(cube.clone(), Vec3::ZERO), child(cube, Vec3::X)]).unwrap();
        assert!((compound.local_frame().position - vec3(0.5, 0.0, 0.0)).length() < 1e-6);
        let expected = 1.0 / 12.0 * vec3(1.0 + 1.0, 4.0 + 1.0, 4.0 + 1.0);
        // The frame may permute the axes; the moments as a set must match.
        let mut got = compound.unit_inertia().to_array();
        let mut want = expected.to_array();
        got.sort_by(f32::total_cmp);
        want.sort_by(f32::total_cmp);
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{got:?} vs {want:?}");
        }
        let box_shape = Shape::cuboid(vec3(1.0, 0.5, 0.5));
        let mass = 3.0;
        let sum = |v: Vec3| v.x + v.y + v.z;
        assert!(
            (sum(Shape::Compound(Arc::new(compound))
                .mass_properties(mass)
                .inverse_inertia
                .recip())
                - sum(box_shape.mass_properties(mass).inverse_inertia.recip()))
            .abs()
                < 1e-5
        );
    }

    /// A capsule along Y and a ball on its end: mass splits by volume, so the centroid is the
    /// volume-weighted mean of the parts' centres.
    #[test]
    fn centroid_weighs_children_by_volume() {
        let (r, h) = (0.1f32, 0.5f32);
        let ball = 0.3f32;
        let compound = Compound::new(vec![
            child(Shape::capsule(r, h), Vec3::ZERO),
            child(Shape::sphere(ball), vec3(0.0, 1.0, 0.0)),
        ])
        .unwrap();
        let capsule_volume = PI * r * r * 2.0 * h + 4.0 / 3.0 * PI * r * r * r;
        let ball_volume = 4.0 / 3.0 * PI * ball * ball * ball;
        let y = ball_volume / (capsule_volume + ball_volume);
        assert!((compound.local_frame().position - vec3(0.0, y, 0.0)).length() < 1e-6);
    }

    /// Children given about their principal frame keep their poses bit for bit, so a dumped
    /// compound loads back as itself.
    #[test]
    fn centred_children_keep_their_poses_and_the_identity_frame() {
        let children = vec![
            child(Shape::sphere(0.25), vec3(-0.7, 0.0, 0.0)),
            child(Shape::capsule(0.05, 0.3), Vec3::ZERO),
            child(Shape::sphere(0.25), vec3(0.7, 0.0, 0.0)),
        ];
        let compound = Compound::new(children.clone()).unwrap();
        assert_eq!(compound.local_frame(), Transform::IDENTITY);
        assert_eq!(compound.children(), &children[..]);
        assert_eq!(compound.bounding_radius(), 0.95);
    }

    /// A hull child whose points sit off their centroid: its own frame folds into the child's
    /// pose, so the compound of one such hull is centred where the hull is.
    #[test]
    fn hull_child_frame_folds_into_its_pose() {
        let corners: Vec<Vec3> = (0..8)
            .map(|i| {
                vec3(5.0, 0.0, 0.0)
                    + 0.5
                        * vec3(
                            [-1.0, 1.0][i & 1],
                            [-1.0, 1.0][(i >> 1) & 1],
                            [-1.0, 1.0][i >> 2],
                        )
            })
            .collect();
        let hull = Shape::convex_hull(&corners).unwrap();
        let compound = Compound::new(vec![child(hull, vec3(0.0, 1.0, 0.0))]).unwrap();
        assert!((compound.local_frame().position - vec3(5.0, 1.0, 0.0)).length() < 1e-5);
        let aabb = compound.aabb(&compound.local_frame());
        assert!(
            (aabb.min - vec3(4.5, 0.5, -0.5)).length() < 1e-5,
            "{aabb:?}"
        );
        assert!((aabb.max - vec3(5.5, 1.5, 0.5)).length() < 1e-5, "{aabb:?}");
    }

    #[test]
    fn bad_children_are_refused_by_index() {
        let ball = || child(Shape::sphere(0.1), Vec3::ZERO);
        assert_eq!(Compound::new(vec![]), Err(CompoundError::Empty));
        assert_eq!(
            Compound::new(vec![ball(), child(Shape::plane(Vec3::Y, 0.0), Vec3::ZERO)]),
            Err(CompoundError::UnsupportedChild {
                index: 1,
                kind: ShapeKind::Plane
            })
        );
        let inner = Shape::compound(vec![ball()]).unwrap();
        assert_eq!(
            Compound::new(vec![child(inner, Vec3::ZERO)]),
            Err(CompoundError::UnsupportedChild {
                index: 0,
                kind: ShapeKind::Compound
            })
        );
        assert_eq!(
            Compound::new(vec![ball(), child(Shape::sphere(0.1), Vec3::NAN)]),
            Err(CompoundError::PositionNotFinite { index: 1 })
        );
        let turned = |rotation| CompoundChild {
            shape: Shape::sphere(0.1),
            pose: Transform::new(Vec3::ZERO, rotation),
        };
        assert_eq!(
            Compound::new(vec![turned(Quat::from_xyzw(0.0, 0.0, 0.0, f32::INFINITY))]),
            Err(CompoundError::RotationNotFinite { index: 0 })
        );
        assert_eq!(
            Compound::new(vec![turned(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0))]),
            Err(CompoundError::ZeroRotation { index: 0 })
        );
        for shape in [
            Shape::sphere(0.0),
            Shape::capsule(0.1, -1.0),
            Shape::cuboid(vec3(1.0, f32::INFINITY, 1.0)),
        ] {
            assert_eq!(
                Compound::new(vec![ball(), child(shape.clone(), Vec3::ZERO)]),
                Err(CompoundError::BadChildSize { index: 1, shape })
            );
        }
    }
}
