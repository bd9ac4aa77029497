//! Pairs with a compound: every child of one side against every child of the other (a shape
//! that is not a compound is its own single child), each touching child pair giving its own
//! manifold, as a mesh's triangles do (a dumbbell on the floor touches it with two spheres,
//! each with its own normal and its own persistent manifold in the narrowphase's child cache).

use super::collide;
use crate::collision::manifold::Manifold;
use crate::math::Transform;
use crate::shape::Shape;

/// Mixes a child pair's index into its points' feature ids, so that equal ids of different
/// children (two spheres both report id 0) stay apart when the child cache carries impulses
/// across the children of a pair. Odd, so `child * MIX` is a bijection on u32: two children
/// never share a mask. Ids already use all 32 bits (hull edges), so this cannot be a shift.
const CHILD_ID_MIX: u32 = 0x9E37_79B9;

/// Fills `found` with `(child, manifold)` for each child pair of `a` (at
/// `pose_a`) and `b` (at `pose_b`) with contacts closer than `margin` (m), in ascending child
/// order. `child = child_a * children_b + child_b`, where a shape that is not a compound has
/// one child, index 0. Manifolds are in world space with the normal from B to A.
pub fn collide_compound(
    a: &Shape,
    pose_a: &Transform,
    b: &Shape,
    pose_b: &Transform,
    margin: f32,
    found: &mut Vec<(u32, Manifold)>,
) {
    found.clear();
    let children_b = part_count(b);
    for_each_part(a, pose_a, |index_a, part_a, part_pose_a| {
        let bounds_a = part_a.aabb(&part_pose_a).expanded(margin);
        for_each_part(b, pose_b, |index_b, part_b, part_pose_b| {
            if !bounds_a.overlaps(&part_b.aabb(&part_pose_b)) {
                return;
            }
            let mut manifold = Manifold::default();
            collide(
                part_a,
                &part_pose_a,
                part_b,
                &part_pose_b,
                margin,
                &mut manifold,
            );
            if manifold.count == 0 {
                return;
            }
            let child = index_a * children_b + index_b;
            mix_child_ids(&mut manifold, child);
            found.push((child, manifold));
        });
    });
}

/// Makes the feature ids of `manifold`, found for child (pair) `child`, differ from those of
/// every other child (see [`CHILD_ID_MIX`]).
pub fn mix_child_ids(manifold: &mut Manifold, child: u32) {
    let mask = child.wrapping_mul(CHILD_ID_MIX);
    let count = manifold.count as usize;
    for point in &mut manifold.points[..count] {
        point.id ^= mask;
    }
}

/// Children of `shape`: its compound children, or the shape itself.
fn part_count(shape: &Shape) -> u32 {
    match shape {
        // At most MAX_COMPOUND_CHILDREN (checked in `Compound::new`), well inside u32.
        Shape::Compound(compound) => compound.children().len() as u32,
        _ => 1,
    }
}

/// Calls `visit(index, part, world pose)` for each child of `shape` at `pose`, in order.
fn for_each_part(shape: &Shape, pose: &Transform, mut visit: impl FnMut(u32, &Shape, Transform)) {
    match shape {
        Shape::Compound(compound) => {
            for (index, child) in compound.children().iter().enumerate() {
                visit(index as u32, &child.shape, pose.mul_transform(&child.pose));
            }
        }
        _ => visit(0, shape, *pose),
    }
}
