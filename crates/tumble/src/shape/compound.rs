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
//! narrowphase's child cache. Hull children meet no meshes, as hulls do not.
//!
//! # Child BVH
//!
//! A compound of more than [`CHILD_BVH_THRESHOLD`] children keeps a [`Bvh`] over its children's
//! boxes in the compound frame, built once in [`Compound::new`]; pairs, rays and casts then test
//! only the children near the other shape or along the path instead of every child. The tree
//! only narrows the candidates: each candidate still goes through exactly the test the flat list
//! applies, in ascending child order, so both paths give the same contacts and hits bit for bit
//! ([`Compound::with_child_bvh`] switches the tree off or on to compare them).
//!
//! The tree lives in the compound frame while the pair test compares world boxes (each child's
//! box at its world pose). A node's box, turned by the compound's rotation, is bounded by the
//! world box of that turned box, which contains the world box of every child below it (a
//! child's world box is the tightest box around the turned child, which lies inside the turned
//! node box). So a node whose turned box misses the query holds no child the flat test keeps.
//! Rounding separates the two computations by a few ulps; [`CHILD_QUERY_SLACK`] covers that.

use std::sync::Arc;

use glam::{DMat3, DVec3};

use super::convex_hull::{RELATIVE_TOLERANCE, jacobi_eigenvectors, off_diagonal_ratio};
use super::{Shape, ShapeKind, capsule_inertia};
use crate::collision::bvh::{Bvh, BvhNode};
use crate::math::{Aabb, Mat3, Quat, Transform, Vec3};

/// Most children a compound may have: child manifolds are keyed by `child_a * children_b +
/// child_b` in a `u32`, which this keeps in range for two compounds of this size.
pub const MAX_COMPOUND_CHILDREN: usize = 1 << 15;

/// Most children a compound tests as a flat list; past this, [`Compound::new`] builds a child
/// BVH (module docs). Where the tree starts to pay, by `benches/compound.rs` (box children on a
/// grid, a box on one corner child, a ray onto it), tree time against flat time over two runs:
///
/// | children | 2 to 8 | 16 | 32 | 64 | 256 |
/// |---|---|---|---|---|---|
/// | pair | 0.7 to 1.25 | 0.65 to 1.07 | 0.5 to 0.85 | 0.5 | 0.1 to 0.2 |
/// | ray | 0.65 to 2.8 | 1.07 to 1.08 | 0.5 | 0.4 to 0.75 | 0.14 to 0.2 |
///
/// Below 16 the tree's walk costs as much as testing every child, and rays lose by up to 2.8
/// times; from 32 both win. Measured on a shared, loaded 2-core machine (dev profile, the crate
/// at opt-level 3), hence the spread: the crossing point, not the times, is what this keeps.
/// Compounds built by hand (a dumbbell, a table, a chair) stay under it.
pub const CHILD_BVH_THRESHOLD: usize = 16;

/// Fraction of the query's scale (m per m: the compound's distance from the origin plus its
/// bounding radius) by which the child BVH's node tests are widened, so that rounding never lets
/// them drop a child the flat test keeps: 1e-5 is about 80 ulps of f32, where the two
/// computations (a node's turned box, a child's box at its composed pose) differ by a few. A
/// wider test only costs a few extra candidates, each then tested exactly.
pub const CHILD_QUERY_SLACK: f32 = 1.0e-5;

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
    /// Each child's box in the compound frame, what the child BVH is built from.
    child_aabbs: Vec<Aabb>,
    /// Over `child_aabbs`, when there are more than [`CHILD_BVH_THRESHOLD`] children.
    child_bvh: Option<Bvh>,
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
        let child_aabbs: Vec<Aabb> = children
            .iter()
            .map(|child| child.shape.aabb(&child.pose))
            .collect();
        let child_bvh = (children.len() > CHILD_BVH_THRESHOLD).then(|| Bvh::build(&child_aabbs));
        Ok(Self {
            children,
            child_aabbs,
            child_bvh,
            local_frame,
            unit_inertia: (principal_inertia / volume).as_vec3(),
            bounding_radius,
        })
    }

    /// The children, poses in the compound frame.
    pub fn children(&self) -> &[CompoundChild] {
        &self.children
    }

    /// The BVH over the children's boxes in the compound frame, if the compound has one
    /// (module docs); its primitives are child indices.
    pub fn child_bvh(&self) -> Option<&Bvh> {
        self.child_bvh.as_ref()
    }

    /// The same compound with its child BVH built (`true`) or dropped (`false`), whatever its
    /// number of children. Contacts and hits are the same bit for bit either way, only the time
    /// differs: for tests and benchmarks that compare the two paths.
    #[must_use]
    pub fn with_child_bvh(mut self, enabled: bool) -> Self {
        self.child_bvh = enabled.then(|| Bvh::build(&self.child_aabbs));
        self
    }

    /// Appends to `near`, in ascending order, the index of every child whose world box at
    /// `pose` (`child.shape.aabb(&pose.mul_transform(&child.pose))`) overlaps `aabb`, and, with a
    /// child BVH, possibly a few more whose boxes come close: callers test each candidate
    /// exactly. Without a BVH that is every child.
    pub fn children_near(&self, pose: &Transform, aabb: &Aabb, near: &mut Vec<u32>) {
        let start = near.len();
        let Some(bvh) = &self.child_bvh else {
            // At most MAX_COMPOUND_CHILDREN (checked in `new`), well inside u32.
            near.extend(0..self.children.len() as u32);
            return;
        };
        let turned = TurnedNodes::new(pose, self.query_slack(pose));
        bvh.query(
            |node| turned.world_box(node).overlaps(aabb),
            |child| near.push(child),
        );
        // The walk's order is deterministic but not ascending; the flat list is.
        near[start..].sort_unstable();
    }

    /// A box (world frame, m) around every child's world box at `pose`: the child BVH's root
    /// turned (and widened by the slack) when there is a tree, else the exact union.
    pub fn bounds_superset(&self, pose: &Transform) -> Aabb {
        match self.child_bvh.as_ref().and_then(|bvh| bvh.nodes().first()) {
            Some(root) => TurnedNodes::new(pose, self.query_slack(pose)).world_box(root),
            None => self.aabb(pose),
        }
    }

    /// [`CHILD_QUERY_SLACK`] at the scale of this compound at `pose` (m).
    pub fn query_slack(&self, pose: &Transform) -> f32 {
        CHILD_QUERY_SLACK * (pose.position.abs().max_element() + self.bounding_radius)
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

/// World boxes of child-BVH nodes for a compound at one pose (module docs).
struct TurnedNodes {
    pose: Transform,
    /// `|R|`: the world half extents of a turned box are `|R| · half_extents`.
    abs_rotation: Mat3,
    slack: f32,
}

impl TurnedNodes {
    fn new(pose: &Transform, slack: f32) -> Self {
        let rotation = Mat3::from_quat(pose.rotation);
        Self {
            pose: *pose,
            abs_rotation: Mat3::from_cols(
                rotation.x_axis.abs(),
                rotation.y_axis.abs(),
                rotation.z_axis.abs(),
            ),
            slack,
        }
    }

    /// The world box of `node`'s box turned by the pose, widened by the slack.
    fn world_box(&self, node: &BvhNode) -> Aabb {
        let local = node.aabb();
        let half_extents: Vec3 = self.abs_rotation * local.half_extents() + Vec3::splat(self.slack);
        Aabb::from_center_half_extents(self.pose.transform_point(local.center()), half_extents)
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

/// Test scenery: `count` children (spheres, boxes, capsules and barrel hulls, 0.1 to 0.3 m)
/// at random turns on a jittered grid of 0.5 m cells, so that neighbours sometimes overlap.
#[cfg(test)]
pub(crate) fn random_children(
    rng: &mut crate::collision::dbvt::tests::TestRng,
    count: usize,
) -> Vec<CompoundChild> {
    let side = (count as f32).cbrt().ceil() as usize;
    let hull = Shape::convex_hull(
        &crate::scene::barrel_points()
            .iter()
            .map(|point| 0.4 * *point)
            .collect::<Vec<_>>(),
    )
    .expect("the barrel is a hull");
    (0..count)
        .map(|index| {
            let cell = Vec3::new(
                (index % side) as f32,
                (index / side % side) as f32,
                (index / (side * side)) as f32,
            );
            let position =
                0.5 * (cell - Vec3::splat(0.5 * (side - 1) as f32)) + rng.vec3(-0.1, 0.1);
            let size = rng.range(0.1, 0.3);
            let shape = match rng.below(4) {
                0 => Shape::sphere(size),
                1 => Shape::cuboid(rng.vec3(0.05, size)),
                2 => Shape::capsule(0.5 * size, size),
                _ => hull.clone(),
            };
            CompoundChild {
                shape,
                pose: Transform::new(position, random_rotation(rng)),
            }
        })
        .collect()
}

/// A random unit quaternion (test scenery).
#[cfg(test)]
pub(crate) fn random_rotation(rng: &mut crate::collision::dbvt::tests::TestRng) -> Quat {
    let q = rng.vec3(-1.0, 1.0).extend(rng.range(-1.0, 1.0));
    Quat::from_vec4(q).normalize()
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

    /// The tree comes past [`CHILD_BVH_THRESHOLD`] children, and `with_child_bvh` adds or drops
    /// it whatever the count; without one, `children_near` offers every child.
    #[test]
    fn child_bvh_comes_past_the_threshold() {
        let mut rng = crate::collision::dbvt::tests::TestRng::new(8);
        let at = Compound::new(random_children(&mut rng, CHILD_BVH_THRESHOLD)).unwrap();
        let past = Compound::new(random_children(&mut rng, CHILD_BVH_THRESHOLD + 1)).unwrap();
        assert!(at.child_bvh().is_none());
        assert!(past.child_bvh().is_some());
        assert!(at.clone().with_child_bvh(true).child_bvh().is_some());
        assert!(past.with_child_bvh(false).child_bvh().is_none());
        let mut near = vec![99];
        let nowhere = Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0));
        at.children_near(&Transform::IDENTITY, &nowhere, &mut near);
        let every: Vec<u32> = (0..CHILD_BVH_THRESHOLD as u32).collect();
        assert_eq!(near[1..], every[..], "appended after what was there");
    }

    /// `children_near` offers every child whose world box overlaps the query, including one
    /// that only touches it at a corner: the case where rounding in the turned node boxes would
    /// drop a child without [`CHILD_QUERY_SLACK`]. Near the origin and 1 km out.
    #[test]
    fn children_near_offers_every_child_whose_box_touches_the_query() {
        let mut rng = crate::collision::dbvt::tests::TestRng::new(3);
        let compound = Compound::new(random_children(&mut rng, 64)).unwrap();
        assert!(compound.child_bvh().is_some());
        let mut near = Vec::new();
        for trial in 0..2000 {
            let centre = [Vec3::ZERO, vec3(1000.0, -20.0, 500.0)][trial % 2];
            // Square turns keep node boxes tight, where rounding decides a touch.
            let rotation = match trial % 3 {
                0 => Quat::IDENTITY,
                1 => Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
                _ => random_rotation(&mut rng),
            };
            let pose = Transform::new(centre + rng.vec3(-1.0, 1.0), rotation);
            let index = rng.below(64);
            let child = &compound.children()[index];
            let world = child.shape.aabb(&pose.mul_transform(&child.pose));
            // A unit box touching the child's world box at its max or min corner.
            let query = if trial % 4 < 2 {
                Aabb::new(world.max, world.max + Vec3::ONE)
            } else {
                Aabb::new(world.min - Vec3::ONE, world.min)
            };
            near.clear();
            compound.children_near(&pose, &query, &mut near);
            assert!(
                near.contains(&(index as u32)),
                "trial {trial}: child {index}"
            );
            assert!(near.is_sorted());
        }
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
