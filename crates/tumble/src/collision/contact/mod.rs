//! Contact generation: the narrowphase's pair functions and the dispatcher [`collide`].
//!
//! # What a manifold holds
//!
//! - `normal` is unit length and points from body B to body A (DESIGN.md principle 7).
//! - Each point's `separation` is the signed distance of the two surfaces along `normal` (m),
//!   positive apart and negative overlapping. Points with `separation >= margin` are dropped; `margin` is the
//!   speculative distance that keeps a resting contact alive while the bodies hover a hair apart.
//! - Each point's `position` is the world point midway between the surfaces: the point on A's
//!   surface minus `normal * separation / 2`.
//! - At most four points; when a box face yields more they go through
//!   [`reduce`](crate::collision::manifold::reduce).
//!
//! # Feature ids
//!
//! `ContactPoint::id` names the pair of features that touch, so it stays the same from step to
//! step while they do, and the solver can carry last step's impulses over (warm starting). Ids
//! are unique within a manifold.
//!
//! | pair | ids |
//! |---|---|
//! | sphere–anything; capsule–capsule and capsule–box at one point | `0` |
//! | capsule–capsule (parallel), capsule–box (on a face) | `0` and `1`: the ends of the part of A's segment that lies along B, `0` at the end towards A's `-half_height` end |
//! | capsule–plane | `0` for the `-half_height` end, `1` for the `+half_height` end |
//! | box–plane | the box vertex index: bit 0, 1, 2 set when the vertex is on the + side of local x, y, z |
//! | box–box, face | clip feature (bits 0–5) · reference face `<< 6` · incident face `<< 9` · reference is A `<< 12` |
//! | box–box, edge | `1 << 13` · B's edge index · A's edge index `<< 4` |
//! | hull–plane | the hull vertex index |
//! | box–hull, hull–hull | see `hull.rs`: clip feature, reference and incident faces, edges |
//! | sphere, capsule, box, hull against a mesh triangle | see `triangle.rs` and `hull_triangle.rs`: 12 bits, the child cache adds the triangle above them |
//! | sphere–hull; capsule–hull at one point | `0` |
//! | capsule–hull along a face | `0` and `1` for the segment's `-half_height` and `+half_height` ends |
//!
//! `box_box.rs` details the box–box fields. A point surviving alone keeps its id (capsule end
//! `1`, box vertex `5`): ids name features, not positions in the manifold.
//!
//! # Frames
//!
//! Pairs with a box work in the box's frame, where it is axis aligned at the origin: clamps,
//! slabs and face planes become per-component comparisons. Nothing allocates: candidates live in
//! fixed arrays on the stack.

mod box_box;
mod capsule;
mod compound;
pub(crate) mod hull;
mod hull_triangle;
mod mesh;
mod plane;
mod segment;
mod sphere;
mod triangle;

pub use compound::{collide_compound, mix_child_ids};
pub use mesh::collide_mesh;

use crate::collision::manifold::{ContactPoint, Manifold};
use crate::gpu::kernel::Source;
use crate::math::{Transform, Vec3};
use crate::shape::Shape;

/// Squared distance (m²) under which two points count as one, so their difference gives no
/// direction and a fallback normal is used instead.
const COINCIDENT_DISTANCE_SQUARED: f32 = 1.0e-12;

/// Half height (m) under which a capsule is a sphere: its segment has no direction.
const POINT_SEGMENT_HALF_HEIGHT: f32 = 1.0e-6;

/// An edge axis of the separating-axis test is taken only when its separation clearly beats
/// the best face axis's (see [`clearly_greater`]): face contacts give whole manifolds, and
/// flipping between a face and an edge from one step to the next makes stacks jitter.
const EDGE_RELATIVE_TOLERANCE: f32 = 0.05;

/// Slack (m) added to the relative tolerances, so that when the separations are near zero the
/// preferred axis still wins ties that differ only by rounding.
const ABSOLUTE_TOLERANCE: f32 = 5.0e-4;

/// `sin²` of the angle under which an edge is parallel to another edge or to a face: their
/// cross product is then mostly rounding and is no axis to test.
const PARALLEL_SINE_SQUARED: f32 = 1.0e-6;

/// `source` with the tolerances of the pair functions as WGSL constants, for their GPU twins
/// (stages/narrowphase/*.wgsl): each is written once, here.
pub(crate) fn wgsl_constants(source: Source) -> Source {
    source
        .constant_f32("COINCIDENT_DISTANCE_SQUARED", COINCIDENT_DISTANCE_SQUARED)
        .constant_f32("POINT_SEGMENT_HALF_HEIGHT", POINT_SEGMENT_HALF_HEIGHT)
        .constant_f32("EDGE_RELATIVE_TOLERANCE", EDGE_RELATIVE_TOLERANCE)
        .constant_f32("ABSOLUTE_TOLERANCE", ABSOLUTE_TOLERANCE)
        .constant_f32("PARALLEL_SINE_SQUARED", PARALLEL_SINE_SQUARED)
        .constant_f32("FACE_RELATIVE_TOLERANCE", box_box::FACE_RELATIVE_TOLERANCE)
        .constant_f32(
            "PARALLEL_CAPSULES_SINE_SQUARED",
            capsule::PARALLEL_CAPSULES_SINE_SQUARED,
        )
        .constant_u32("REFERENCE_IS_A_BIT", box_box::REFERENCE_IS_A_BIT)
        .constant_u32("EDGE_CONTACT_BIT", box_box::EDGE_CONTACT_BIT)
        .constant_u32("HULL_REFERENCE_IS_A_BIT", hull::REFERENCE_IS_A_BIT)
        .constant_u32("HULL_EDGE_CONTACT_BIT", hull::EDGE_CONTACT_BIT)
        .constant_u32("HULL_CROSSING_BIT", hull::CROSSING_BIT)
        .constant_f32("MINIMUM_OVERLAP", capsule::MINIMUM_OVERLAP)
        .constant_f32(
            "DEGENERATE_LENGTH_SQUARED",
            segment::DEGENERATE_LENGTH_SQUARED,
        )
        .constant_f32(
            "SEGMENT_PARALLEL_SINE_SQUARED",
            segment::PARALLEL_SINE_SQUARED,
        )
}

/// Fills `out` with the contacts between shape `a` at `pose_a` and shape `b` at `pose_b` whose
/// separation is below `margin` (m, ≥ 0). The normal points from `b` to `a`. `out` is reset
/// first; it ends up empty when the shapes are farther apart than `margin`, and for two planes.
pub fn collide(
    a: &Shape,
    pose_a: &Transform,
    b: &Shape,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    *out = Manifold::default();
    // Each pair function exists once, for kind(a) <= kind(b); the other order is the same
    // contact seen from the other body: same points, opposite normal.
    if a.kind() <= b.kind() {
        collide_ordered(a, pose_a, b, pose_b, margin, out);
    } else {
        collide_ordered(b, pose_b, a, pose_a, margin, out);
        *out = out.flipped();
    }
}

/// [`collide`] for `a.kind() <= b.kind()`.
fn collide_ordered(
    a: &Shape,
    pose_a: &Transform,
    b: &Shape,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    match (a, b) {
        (Shape::Sphere(a), Shape::Sphere(b)) => {
            sphere::sphere_sphere(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Sphere(a), Shape::Capsule(b)) => {
            sphere::sphere_capsule(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Sphere(a), Shape::Cuboid(b)) => {
            sphere::sphere_box(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Sphere(a), Shape::Plane(b)) => {
            plane::sphere_plane(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Capsule(a), Shape::Capsule(b)) => {
            capsule::capsule_capsule(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Capsule(a), Shape::Cuboid(b)) => {
            capsule::capsule_box(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Capsule(a), Shape::Plane(b)) => {
            plane::capsule_plane(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Cuboid(a), Shape::Cuboid(b)) => box_box::box_box(a, pose_a, b, pose_b, margin, out),
        (Shape::Cuboid(a), Shape::Plane(b)) => plane::box_plane(a, pose_a, b, pose_b, margin, out),
        (Shape::Sphere(a), Shape::ConvexHull(b)) => {
            hull::sphere_hull(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Capsule(a), Shape::ConvexHull(b)) => {
            hull::capsule_hull(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Cuboid(a), Shape::ConvexHull(b)) => {
            hull::box_hull(a, pose_a, b, pose_b, margin, out)
        }
        (Shape::Plane(a), Shape::ConvexHull(b)) => {
            // The hull–plane function has the plane as B: swap, then flip the normal back.
            hull::hull_plane(b, pose_b, a, pose_a, margin, out);
            *out = out.flipped();
        }
        (Shape::ConvexHull(a), Shape::ConvexHull(b)) => {
            hull::hull_hull(a, pose_a, b, pose_b, margin, out)
        }
        // Plane–plane: two static half-spaces never need a contact. Meshes make one manifold
        // per triangle and go through `collide_mesh` instead, compounds one per child pair
        // through `collide_compound`; mesh–plane and mesh–mesh are static–static. Every other combination reaches this function ordered by kind, so it
        // is one of the arms above.
        _ => {}
    }
}

/// Appends the point whose surface point on A is `surface_a` (world, m); the surface of B lies
/// `separation` (m) behind it along `normal`, so the midpoint is half that back.
#[inline]
fn push_contact(out: &mut Manifold, surface_a: Vec3, normal: Vec3, separation: f32, id: u32) {
    out.push(ContactPoint::new(
        surface_a - normal * (0.5 * separation),
        separation,
        id,
    ));
}

/// A face of an axis-aligned box (in its own frame): its outward normal is
/// `sign * Vec3::AXES[axis]`, `sign` being 1 or -1.
#[derive(Clone, Copy, Debug)]
struct Face {
    axis: usize,
    sign: f32,
}

impl Face {
    /// `2 * axis + (1 if the normal is along -axis)`: 0..=5, 3 bits of a feature id.
    #[inline]
    fn index(self) -> u32 {
        2 * self.axis as u32 + u32::from(self.sign < 0.0)
    }
}

/// True when separation `candidate` (m) beats separation `preferred` (m) by more than the
/// fraction `relative_tolerance` of its size plus [`ABSOLUTE_TOLERANCE`]. The slack grows
/// with `|preferred|`, so it holds both for overlaps (< 0) and speculative gaps (> 0); ties
/// and rounding go to `preferred`.
#[inline]
fn clearly_greater(candidate: f32, preferred: f32, relative_tolerance: f32) -> bool {
    candidate > preferred + relative_tolerance * preferred.abs() + ABSOLUTE_TOLERANCE
}

/// `1` for `x >= 0` (zero included, so that a centred body still picks a side), else `-1`.
#[inline]
fn sign_or_positive(x: f32) -> f32 {
    if x >= 0.0 { 1.0 } else { -1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};

    /// Every pair, both argument orders: the same points and ids, the normal flipped.
    #[test]
    fn swapped_arguments_flip_the_normal_only() {
        let shapes = [
            Shape::sphere(0.5),
            Shape::capsule(0.3, 0.6),
            Shape::cuboid(vec3(0.6, 0.4, 0.5)),
            Shape::plane(Vec3::Y, 0.0),
            Shape::convex_hull(&crate::scene::barrel_points()).unwrap(),
        ];
        let pose_a = Transform::new(vec3(0.1, 0.55, -0.2), Quat::from_rotation_z(1.2));
        let pose_b = Transform::new(vec3(0.0, 0.0, 0.1), Quat::from_rotation_x(0.1));
        let mut produced = 0;
        for a in &shapes {
            for b in &shapes {
                let mut forward = Manifold::default();
                let mut backward = Manifold::default();
                collide(a, &pose_a, b, &pose_b, 0.02, &mut forward);
                collide(b, &pose_b, a, &pose_a, 0.02, &mut backward);
                assert_eq!(forward.count, backward.count, "{a:?} {b:?}");
                if forward.count == 0 {
                    continue;
                }
                produced += 1;
                assert!((forward.normal.length() - 1.0).abs() < 1e-5);
                if a.kind() != b.kind() {
                    // Different kinds are swapped by the dispatcher: exactly the same contact.
                    assert_eq!(forward.normal, -backward.normal);
                    assert_eq!(forward.points(), backward.points());
                } else {
                    // Same kind: the pair function itself runs the other way round.
                    assert!((forward.normal + backward.normal).length() < 1e-4);
                    let mut backward_points = backward.points().to_vec();
                    for point in forward.points() {
                        let nearest = backward_points
                            .iter()
                            .position(|other| {
                                (other.position - point.position).length() < 1e-4
                                    && (other.separation - point.separation).abs() < 1e-4
                            })
                            .unwrap_or_else(|| panic!("{a:?} {b:?}: {point:?} not matched"));
                        backward_points.swap_remove(nearest);
                    }
                }
            }
        }
        // All pairs but plane–plane touch in this pose.
        assert_eq!(produced, 24);
    }

    #[test]
    fn plane_plane_gives_nothing() {
        let plane = Shape::plane(Vec3::Y, 0.0);
        let mut out = Manifold {
            count: 3,
            ..Manifold::default()
        };
        collide(
            &plane,
            &Transform::IDENTITY,
            &plane,
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 0);
    }
}
