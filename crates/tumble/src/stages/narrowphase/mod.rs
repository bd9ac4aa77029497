//! Stage 4: contact manifolds for every candidate pair, persistent from step to step.
//!
//! Each step computes a fresh manifold per pair (one-shot, as Box2D does) and matches its points
//! with last step's; a matched point inherits the impulses the solver accumulated on it, which
//! warm-starts the solver (Bullet's persistent manifolds, the talk's reason for persistent
//! pairs). Points match by feature id first; points left over match the nearest old point in
//! body A's frame within [`MATCH_DISTANCE`] (Bullet's contact breaking threshold). The second
//! rule matters: two equal boxes stacked square have their corners exactly on the clipping
//! planes, so rounding flips a point between "incident vertex" and "clipped edge" — and its id —
//! from step to step, and a stack warm-started by ids alone never converges.
//!
//! Guarantees: `contacts[i]` belongs to `keys[i]` = (a, b) with a < b, body A = a, normal from
//! b to a; the result depends only on the poses and last step's manifold, never on thread count.
//!
//! [`GpuNarrowphase`] (`gpu.rs`, `narrowphase.wgsl` and the `contact_*.wgsl` pair functions) is
//! the same stage on the GPU, one thread per pair, with the same points, ids and impulses.

pub mod gpu;
pub mod summary;

pub use gpu::{
    GpuNarrowphase, GpuNarrowphaseInputs, NEW_PAIR, NarrowphaseParams, pack_hulls, shape_kinds,
};

mod children;

pub use children::{ChildCache, ChildKey, has_children, update_child_contacts};

use crate::collision::contact::collide;
use crate::collision::manifold::{MAX_MANIFOLD_POINTS, Manifold};
use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider};
use crate::shape::{Shape, ShapeKind};
use crate::stages::pairs::pair_bodies;
use rayon::prelude::*;

/// Impulses the solver accumulated on one contact point (N·s), kept for warm starting.
/// 12 bytes, WGSL layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PointImpulse {
    pub normal: f32,
    /// Along the two friction directions of [`crate::math::tangent_basis`] of the normal.
    pub tangent: [f32; 2],
}

/// What a pair keeps from one step to the next. 192 bytes, repr(C) + Pod with the WGSL
/// layout: the pair cache's values on the CPU and the GPU are the same array.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PairContact {
    /// The points, with their anchors in body A's frame for matching by position.
    pub manifold: Manifold,
    /// Impulses of `manifold.points`, index for index.
    pub impulses: [PointImpulse; MAX_MANIFOLD_POINTS],
}
const _: () = assert!(size_of::<PairContact>() == 192);

/// WGSL twins of [`ContactPoint`](crate::collision::manifold::ContactPoint), [`Manifold`],
/// [`PointImpulse`] and [`PairContact`].
pub const PAIR_CONTACT_WGSL: &str = include_str!("pair_contact.wgsl");

/// Farthest a point may have moved on body A and still take over an old point's impulses (m).
pub const MATCH_DISTANCE: f32 = 0.02;

/// Pairs per rayon task.
const MIN_PAIRS_PER_TASK: usize = 64;

/// Per-step inputs of the narrowphase.
pub struct NarrowphaseInputs<'a> {
    pub poses: &'a [BodyPose],
    pub velocities: &'a [BodyVelocity],
    pub colliders: &'a [Collider],
    /// Speculative distance at rest (m).
    pub margin: f32,
    /// Step length (s): pairs that close fast get a margin as large as they can close in it.
    pub dt: f32,
    /// Sorted keys of pairs that get no contacts (bodies joined by a joint).
    pub skipped: &'a [u64],
    /// When set, the bodies' masses: a pair of two bodies with no inverse mass (asleep, or
    /// asleep on a static body) keeps its manifold, since neither moved.
    pub keep_resting: Option<&'a [BodyMass]>,
}

/// CPU executor: refresh the manifold of every pair.
pub fn update_contacts(keys: &[u64], contacts: &mut [PairContact], inputs: &NarrowphaseInputs) {
    update_contacts_where(keys, contacts, inputs, |_, _| true);
}

/// Longest face loop of a hull whose pairs the GPU computes: the kernel clips the incident
/// face against the reference face's sides in a polygon of twice this many vertices.
pub const MAX_HULL_FACE_VERTICES: u32 = 16;

/// Whether the GPU narrowphase computes a pair of these shapes: spheres, capsules, boxes and
/// planes among themselves; hulls against spheres and capsules (SAT and nearest features, as
/// `hull.rs`, for any hull: no face is clipped); and hulls with faces of
/// at most [`MAX_HULL_FACE_VERTICES`] vertices against boxes, planes and such hulls, by SAT and
/// clipping. Meshes and compounds stay with [`update_contacts_where`] on the host.
pub fn gpu_pair(a: &Shape, b: &Shape) -> bool {
    gpu_pair_of(a, b)
}

/// Whether every pair of `shape` with any shape for which this holds is a [`gpu_pair`]:
/// spheres, capsules, boxes, planes and hulls whose faces the GPU kernels hold.
pub fn gpu_shape(shape: &Shape) -> bool {
    match shape {
        Shape::ConvexHull(hull) => hull.max_face_vertices() <= MAX_HULL_FACE_VERTICES,
        _ => shape.kind() <= ShapeKind::Plane,
    }
}

fn gpu_pair_of(a: &Shape, b: &Shape) -> bool {
    let polyhedral = |shape: &Shape| match shape {
        Shape::Cuboid(_) | Shape::Plane(_) => true,
        Shape::ConvexHull(hull) => hull.max_face_vertices() <= MAX_HULL_FACE_VERTICES,
        _ => false,
    };
    let round = |shape: &Shape| matches!(shape, Shape::Sphere(_) | Shape::Capsule(_));
    match (a, b) {
        (Shape::ConvexHull(_), other) | (other, Shape::ConvexHull(_)) if round(other) => true,
        _ => match (a.kind(), b.kind()) {
            (ShapeKind::ConvexHull, _) | (_, ShapeKind::ConvexHull) => {
                polyhedral(a) && polyhedral(b)
            }
            _ => a.kind() <= ShapeKind::Plane && b.kind() <= ShapeKind::Plane,
        },
    }
}

/// [`update_contacts`] for the pairs whose shapes `select` accepts; the others are left as
/// they are (a mixed step's GPU pairs).
pub fn update_contacts_where(
    keys: &[u64],
    contacts: &mut [PairContact],
    inputs: &NarrowphaseInputs,
    select: impl Fn(&Shape, &Shape) -> bool + Sync,
) {
    let NarrowphaseInputs {
        poses,
        velocities,
        colliders,
        margin,
        dt,
        skipped,
        keep_resting,
    } = *inputs;
    debug_assert_eq!(keys.len(), contacts.len());
    contacts
        .par_iter_mut()
        .zip(keys.par_iter())
        .with_min_len(MIN_PAIRS_PER_TASK)
        .for_each(|(contact, &key)| {
            let (a, b) = pair_bodies(key);
            let (a, b) = (a as usize, b as usize);
            if !select(&colliders[a].shape, &colliders[b].shape) {
                return;
            }
            if !skipped.is_empty() && skipped.binary_search(&key).is_ok() {
                *contact = PairContact::default();
                return;
            }
            if has_children(&colliders[a].shape, &colliders[b].shape) {
                // One manifold per triangle: they live in the child cache.
                *contact = PairContact::default();
                return;
            }
            if let Some(masses) = keep_resting
                && masses[a].inverse_mass == 0.0
                && masses[b].inverse_mass == 0.0
            {
                return;
            }
            let mut manifold = Manifold::default();
            collide(
                &colliders[a].shape,
                &poses[a].transform(),
                &colliders[b].shape,
                &poses[b].transform(),
                margin
                    + dt * closing_speed_bound(
                        &velocities[a],
                        &velocities[b],
                        &colliders[a],
                        &colliders[b],
                    ),
                &mut manifold,
            );
            let pose_a = poses[a].transform();
            let count = manifold.count as usize;
            for point in &mut manifold.points[..count] {
                point.anchor = pose_a.inverse_transform_point(point.position);
            }
            *contact = carry_impulses(manifold, contact);
        });
}

/// An upper bound on how fast any two points of the bodies approach (m/s): relative speed of
/// the centres plus each spin times the shape's radius. Contacts up to this speed times dt
/// apart are kept as speculative contacts, so that a fast body is stopped at the surface
/// instead of deep inside it.
fn closing_speed_bound(
    velocity_a: &BodyVelocity,
    velocity_b: &BodyVelocity,
    a: &Collider,
    b: &Collider,
) -> f32 {
    (velocity_a.linear - velocity_b.linear).length()
        + velocity_a.angular.length() * a.shape.bounding_radius()
        + velocity_b.angular.length() * b.shape.bounding_radius()
}

/// The new manifold (its points' anchors set) with the impulses of last step's points:
/// same feature id first, then the nearest unclaimed old point within [`MATCH_DISTANCE`].
pub fn carry_impulses(manifold: Manifold, old: &PairContact) -> PairContact {
    let mut impulses = [PointImpulse::default(); MAX_MANIFOLD_POINTS];
    let count = manifold.count as usize;
    let old_count = old.manifold.count as usize;
    let mut claimed = [false; MAX_MANIFOLD_POINTS];
    let mut matched = [false; MAX_MANIFOLD_POINTS];
    for i in 0..count {
        let id = manifold.points[i].id;
        if let Some(j) = (0..old_count).find(|&j| !claimed[j] && old.manifold.points[j].id == id) {
            impulses[i] = old.impulses[j];
            claimed[j] = true;
            matched[i] = true;
        }
    }
    for i in 0..count {
        if matched[i] {
            continue;
        }
        let nearest = (0..old_count)
            .filter(|&j| !claimed[j])
            .map(|j| {
                let anchor = manifold.points[i].anchor;
                (j, anchor.distance_squared(old.manifold.points[j].anchor))
            })
            .filter(|&(_, distance_squared)| distance_squared < MATCH_DISTANCE * MATCH_DISTANCE)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((j, _)) = nearest {
            impulses[i] = old.impulses[j];
            claimed[j] = true;
        }
    }
    PairContact { manifold, impulses }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::manifold::ContactPoint;
    use crate::math::Vec3;

    #[test]
    fn impulses_follow_feature_ids_then_nearest_anchors() {
        let point = |id, anchor| ContactPoint {
            anchor,
            ..ContactPoint::new(Vec3::ZERO, 0.0, id)
        };
        let mut old = PairContact::default();
        old.manifold.push(point(7, Vec3::new(0.0, 0.0, 0.0)));
        old.manifold.push(point(3, Vec3::new(1.0, 0.0, 0.0)));
        old.impulses[0].normal = 1.0;
        old.impulses[1].normal = 2.0;
        let mut new = Manifold::default();
        // A renamed point 1 cm from old id 7: takes its impulse.
        new.push(point(9, Vec3::new(0.01, 0.0, 0.0)));
        // Same id, though far.
        new.push(point(3, Vec3::new(5.0, 0.0, 0.0)));
        // New and far from every old point.
        new.push(point(11, Vec3::new(0.5, 0.0, 0.0)));
        let carried = carry_impulses(new, &old);
        let normals: Vec<f32> = carried.impulses[..3].iter().map(|i| i.normal).collect();
        assert_eq!(normals, [1.0, 2.0, 0.0]);
        assert_eq!(carried.manifold, new);
    }
}
