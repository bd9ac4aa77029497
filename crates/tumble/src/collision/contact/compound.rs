//! Pairs with a compound: every child of one side against every child of the other (a shape
//! that is not a compound is its own single child), each touching child pair giving its own
//! manifold, as a mesh's triangles do (a dumbbell on the floor touches it with two spheres,
//! each with its own normal and its own persistent manifold in the narrowphase's child cache).
//!
//! A compound with a child BVH (`shape::compound`, module docs) offers only the children near
//! the other side as candidates; every candidate pair then takes the flat path's box test and
//! contact function, in the same ascending order, so the manifolds are the same bit for bit.

use super::collide;
use crate::collision::manifold::Manifold;
use crate::math::{Aabb, Transform};
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
    // A's children that may touch B at all: near a box around all of B's children's boxes, so
    // no child pair the box test below keeps is left out.
    let b_bounds = || match b {
        Shape::Compound(compound) => compound.bounds_superset(pose_b),
        _ => b.aabb(pose_b),
    };
    let (mut near_a, mut near_b) = (Vec::new(), Vec::new());
    parts_near(a, pose_a, || b_bounds().expanded(margin), &mut near_a);
    for &index_a in &near_a {
        let (part_a, part_pose_a) = part(a, pose_a, index_a);
        let bounds_a = part_a.aabb(&part_pose_a).expanded(margin);
        parts_near(b, pose_b, || bounds_a, &mut near_b);
        for &index_b in &near_b {
            let (part_b, part_pose_b) = part(b, pose_b, index_b);
            if !bounds_a.overlaps(&part_b.aabb(&part_pose_b)) {
                continue;
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
                continue;
            }
            let child = index_a * children_b + index_b;
            mix_child_ids(&mut manifold, child);
            found.push((child, manifold));
        }
    }
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

/// Sets `near` to the indices, ascending, of the children of `shape` at `pose` that
/// [`Compound::children_near`] offers for the box `query()` (built only for a compound with a
/// child BVH; without one, every child), or to `[0]` for a shape that is not a compound.
fn parts_near(shape: &Shape, pose: &Transform, query: impl FnOnce() -> Aabb, near: &mut Vec<u32>) {
    near.clear();
    match shape {
        Shape::Compound(compound) if compound.child_bvh().is_some() => {
            compound.children_near(pose, &query(), near);
        }
        _ => near.extend(0..part_count(shape)),
    }
}

/// Child `index` of `shape` (the shape itself, index 0, when it is not a compound) and its
/// world pose when `shape` is at `pose`.
fn part<'a>(shape: &'a Shape, pose: &Transform, index: u32) -> (&'a Shape, Transform) {
    match shape {
        Shape::Compound(compound) => {
            let child = &compound.children()[index as usize];
            (&child.shape, pose.mul_transform(&child.pose))
        }
        _ => (shape, *pose),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::dbvt::tests::TestRng;
    use crate::math::{Vec3, vec3};
    use crate::shape::compound::{random_children, random_rotation};
    use crate::shape::{Compound, CompoundChild};
    use std::sync::Arc;

    /// The compound of `children` with its child BVH and without.
    fn both_ways(children: Vec<CompoundChild>) -> [Shape; 2] {
        let compound = Compound::new(children).unwrap();
        [true, false].map(|bvh| Shape::Compound(Arc::new(compound.clone().with_child_bvh(bvh))))
    }

    /// The child BVH only narrows the candidates: against every kind of shape and another
    /// compound (with and without its own tree), in both argument orders, at random poses
    /// near the origin and 1 km out, the child pairs and their manifolds are the flat loop's
    /// bit for bit.
    #[test]
    fn child_bvh_finds_the_flat_loops_child_pairs_exactly() {
        let mut rng = TestRng::new(5);
        let [tree, flat] = both_ways(random_children(&mut rng, 64));
        let [other_tree, other_flat] = both_ways(random_children(&mut rng, 27));
        assert!(matches!(&tree, Shape::Compound(c) if c.child_bvh().is_some()));
        assert!(matches!(&flat, Shape::Compound(c) if c.child_bvh().is_none()));
        let others = [
            Shape::sphere(0.4),
            Shape::cuboid(vec3(0.6, 0.2, 0.3)),
            Shape::capsule(0.2, 0.5),
            Shape::convex_hull(&crate::scene::barrel_points()).unwrap(),
            Shape::plane(Vec3::Y, 0.0),
        ];
        let (mut pairs, mut touching) = (0, 0);
        for trial in 0..400 {
            let origin = if trial % 2 == 0 {
                Vec3::ZERO
            } else {
                vec3(1000.0, -20.0, 500.0)
            };
            let pose = Transform::new(origin + rng.vec3(-0.3, 0.3), random_rotation(&mut rng));
            let other_pose =
                Transform::new(origin + rng.vec3(-1.8, 1.8), random_rotation(&mut rng));
            let margin = [0.0, 0.02, 0.3][trial % 3];
            let mut check =
                |a: &Shape, pose_a, b: &Shape, pose_b, flat_a: &Shape, flat_b: &Shape| {
                    let (mut with_tree, mut without) = (Vec::new(), Vec::new());
                    collide_compound(a, pose_a, b, pose_b, margin, &mut with_tree);
                    collide_compound(flat_a, pose_a, flat_b, pose_b, margin, &mut without);
                    assert_eq!(
                        with_tree,
                        without,
                        "trial {trial}: {:?} {:?}",
                        a.kind(),
                        b.kind()
                    );
                    pairs += 1;
                    touching += usize::from(!without.is_empty());
                };
            for other in &others {
                check(&tree, &pose, other, &other_pose, &flat, other);
                check(other, &other_pose, &tree, &pose, other, &flat);
            }
            check(&tree, &pose, &other_tree, &other_pose, &flat, &other_flat);
            check(&other_tree, &other_pose, &tree, &pose, &other_flat, &flat);
            check(&tree, &pose, &other_flat, &other_pose, &flat, &other_flat);
        }
        // Most pairs touch through some children, and some do not at all: both sides tested.
        assert!(
            touching > pairs / 2 && touching < pairs,
            "{touching} of {pairs}"
        );
    }
}
