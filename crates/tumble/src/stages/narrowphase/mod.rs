//! Stage 4: contact manifolds for every candidate pair, persistent from step to step.
//!
//! Each step computes a fresh manifold per pair (one-shot, as Box2D does), unless the pair is
//! two polyhedra that have barely moved relative to each other since their manifold was
//! computed: then the old points move with the bodies ([`ManifoldCache`]). A fresh manifold's
//! points are matched with last step's; a matched point inherits the impulses the solver accumulated on it, which
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
//! [`GpuNarrowphase`] (`gpu.rs`; `move.wgsl` moves the cached manifolds, a thread per pair, and
//! `collide.wgsl` runs the `contact_*.wgsl` pair functions for the rest) is the same stage on the
//! GPU, with the same decisions, points, ids and impulses.

pub mod gpu;
pub mod summary;

pub use gpu::{
    GpuNarrowphase, GpuNarrowphaseInputs, NEW_PAIR, NarrowphaseParams, pack_hulls, shape_kinds,
};

mod children;

pub use children::{ChildCache, ChildKey, has_children, update_child_contacts};

use crate::collision::contact::collide;
use crate::collision::manifold::{ContactPoint, MAX_MANIFOLD_POINTS, Manifold};
use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider};
use crate::math::{Quat, Transform, Vec3};
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

/// What a pair keeps from one step to the next. 256 bytes, repr(C) + Pod with the WGSL
/// layout: the pair cache's values on the CPU and the GPU are the same array.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PairContact {
    /// The points, with their anchors in body A's frame for matching by position: where the
    /// points were when the pair function last ran (a rebuilt manifold keeps them).
    pub manifold: Manifold,
    /// Impulses of `manifold.points`, index for index.
    pub impulses: [PointImpulse; MAX_MANIFOLD_POINTS],
    /// How the manifold was computed, to move it with the bodies while they stay put.
    pub cache: ManifoldCache,
}
const _: () = assert!(size_of::<PairContact>() == 256);

impl PairContact {
    /// Zeroes the point slots past the manifold's count and their impulses, as the CPU keeps
    /// them. The GPU's narrowphase leaves them as its buffer had them (`move.wgsl`: no kernel
    /// reads them there), so the host clears them in what it reads back.
    pub fn clear_unused(&mut self) {
        let count = (self.manifold.count as usize).min(MAX_MANIFOLD_POINTS);
        self.manifold.points[count..].fill(ContactPoint::default());
        self.impulses[count..].fill(PointImpulse::default());
    }
}

/// The relative pose a pair's manifold was computed at, and what its points need to follow
/// the bodies from there (Jolt's body pair cache): while neither body's points have moved by
/// more than [`CACHE_TOLERANCE`] relative to the other since, the narrowphase moves the old
/// points instead of running the pair function again (see [`cache_holds`]). Each point's side
/// on body A stays fixed in A and its side on body B in B, so a vertex resting on a face keeps
/// its exact separation; what the shortcut cannot see is a feature that comes within reach,
/// and by then the bodies have moved more than the tolerance. In a settled pile most pairs
/// take it: their manifolds cost a few loads and a rotation instead of SAT and clipping.
/// 64 bytes, WGSL layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ManifoldCache {
    /// Body B's position in body A's frame then (m).
    pub position: Vec3,
    /// The speculative distance the pair function was given (m).
    pub margin: f32,
    /// Body B's rotation in body A's frame then.
    pub rotation: Quat,
    /// The manifold's normal in body A's frame.
    pub normal: Vec3,
    /// 1 when the rest holds; 0 for a pair never computed (a new pair, a loaded contact).
    pub valid: u32,
    /// Each point's separation then (m), index for index.
    pub separations: [f32; MAX_MANIFOLD_POINTS],
}
const _: () = assert!(size_of::<ManifoldCache>() == 64);

/// No cache: all zeros, as the GPU writes it (not glam's identity rotation), so that the two
/// executors' pair contacts agree bit for bit.
impl Default for ManifoldCache {
    fn default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

/// Farthest a point of either body may have moved relative to the other since the pair's
/// manifold was computed for the narrowphase to move the old manifold instead of computing a
/// new one (m). Jolt's default position tolerance; its rotation tolerance (2°) we replace by
/// what the rotation moves the body's farthest point, which is tighter for bodies larger than
/// 3 cm. A rebuilt point's separation is exact while the same features touch; its position
/// may be off by half the tolerance, a thousandth of a metre-sized body (the scale the step's
/// defaults are for, as `StepConfig` says).
pub const CACHE_TOLERANCE: f32 = 1.0e-3;

/// WGSL twins of [`ContactPoint`](crate::collision::manifold::ContactPoint), [`Manifold`],
/// [`PointImpulse`], [`ManifoldCache`] and [`PairContact`].
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

impl NarrowphaseInputs<'_> {
    /// The speculative distance of bodies `a` and `b` (m): `margin` at rest, plus as far as
    /// they can close in a step ([`closing_speed_bound`]).
    pub fn pair_margin(&self, a: usize, b: usize) -> f32 {
        let (velocities, colliders) = (self.velocities, self.colliders);
        self.margin
            + self.dt
                * closing_speed_bound(&velocities[a], &velocities[b], &colliders[a], &colliders[b])
    }
}

/// CPU executor: refresh the manifold of every pair. Returns how many pairs the pair
/// functions computed (the others moved their last manifold with the bodies, or have none).
pub fn update_contacts(
    keys: &[u64],
    contacts: &mut [PairContact],
    inputs: &NarrowphaseInputs,
) -> usize {
    update_contacts_where(keys, contacts, inputs, |_, _| true)
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
) -> usize {
    let NarrowphaseInputs {
        poses,
        colliders,
        skipped,
        keep_resting,
        // The margin is `pair_margin`'s.
        velocities: _,
        margin: _,
        dt: _,
    } = *inputs;
    debug_assert_eq!(keys.len(), contacts.len());
    contacts
        .par_iter_mut()
        .zip(keys.par_iter())
        .with_min_len(MIN_PAIRS_PER_TASK)
        .map(|(contact, &key)| {
            let (a, b) = pair_bodies(key);
            let (a, b) = (a as usize, b as usize);
            if !select(&colliders[a].shape, &colliders[b].shape) {
                return 0;
            }
            if !skipped.is_empty() && skipped.binary_search(&key).is_ok() {
                *contact = PairContact::default();
                return 0;
            }
            if has_children(&colliders[a].shape, &colliders[b].shape) {
                // One manifold per triangle: they live in the child cache.
                *contact = PairContact::default();
                return 0;
            }
            if let Some(masses) = keep_resting
                && masses[a].inverse_mass == 0.0
                && masses[b].inverse_mass == 0.0
            {
                return 0;
            }
            let margin = inputs.pair_margin(a, b);
            let (pose_a, pose_b) = (poses[a].transform(), poses[b].transform());
            let relative = relative_pose(&pose_a, &pose_b);
            let radii = [cache_radius(&colliders[a]), cache_radius(&colliders[b])];
            let cacheable = cacheable(&colliders[a].shape, &colliders[b].shape);
            if cacheable && cache_holds(&contact.cache, &relative, margin, radii) {
                *contact = rebuild(contact, &pose_a, &relative);
                return 0;
            }
            let mut manifold = Manifold::default();
            collide(
                &colliders[a].shape,
                &pose_a,
                &colliders[b].shape,
                &pose_b,
                margin,
                &mut manifold,
            );
            let count = manifold.count as usize;
            for point in &mut manifold.points[..count] {
                point.anchor = pose_a.inverse_transform_point(point.position);
            }
            *contact = carry_impulses(manifold, contact);
            if cacheable {
                contact.cache = cache_of(&contact.manifold, &pose_a, &relative, margin);
            }
            1
        })
        .sum()
}

/// Whether the narrowphase keeps a [`ManifoldCache`] for a pair of these shapes: two
/// polyhedra (boxes, hulls, planes), whose points lie on vertices, edges and faces that move
/// with their bodies. A sphere's or capsule's point slides over it as it rolls (moved with the
/// body, a rolling ball's point would turn away from the bottom and push it on), and their
/// pair functions cost little.
pub fn cacheable(a: &Shape, b: &Shape) -> bool {
    let polyhedron = |shape: &Shape| {
        matches!(
            shape.kind(),
            ShapeKind::Cuboid | ShapeKind::Plane | ShapeKind::ConvexHull
        )
    };
    polyhedron(a) && polyhedron(b)
}

/// Body B's pose in body A's frame.
pub fn relative_pose(pose_a: &Transform, pose_b: &Transform) -> Transform {
    let inverse = pose_a.rotation.conjugate();
    Transform::new(
        inverse * (pose_b.position - pose_a.position),
        inverse * pose_b.rotation,
    )
}

/// The radius [`cache_holds`] turns a body's points by: its bounding radius, or `None` for a
/// plane, whose points near the other body may lie anywhere from its origin.
pub fn cache_radius(collider: &Collider) -> Option<f32> {
    (collider.shape.kind() != ShapeKind::Plane).then(|| collider.shape.bounding_radius())
}

/// Whether the pair's old manifold may be moved to `relative` (B's pose in A's frame now) for
/// a speculative distance `margin`, given the bodies' [`cache_radius`]es: the cache is valid,
/// was computed for a margin no smaller by more than [`CACHE_TOLERANCE`], and no point of B
/// has moved by more than that in A's frame since — or no point of A in B's frame, whichever
/// bound is smaller. A point moves by its body's centre's move plus the turn's chord at its
/// radius, 2 sin(θ/2) r, and the turn's quaternion has |xyz| = sin(θ/2).
pub fn cache_holds(
    cache: &ManifoldCache,
    relative: &Transform,
    margin: f32,
    radii: [Option<f32>; 2],
) -> bool {
    cache.valid != 0
        && margin <= cache.margin + CACHE_TOLERANCE
        && cache_motion(cache, relative, radii) <= CACHE_TOLERANCE
}

/// The bound of [`cache_holds`] on how far a point of one body has moved relative to the
/// other since `cache` was made (m); `f32::MAX` when neither body has a radius.
pub fn cache_motion(cache: &ManifoldCache, relative: &Transform, radii: [Option<f32>; 2]) -> f32 {
    let turn = relative.rotation * cache.rotation.conjugate();
    let chord = 2.0 * Vec3::new(turn.x, turn.y, turn.z).length();
    let mut moved = f32::MAX;
    if let Some(radius_b) = radii[1] {
        moved = moved.min((relative.position - cache.position).length() + chord * radius_b);
    }
    if let Some(radius_a) = radii[0] {
        // A's centre in B's frame, now and then (both negated).
        let now = relative.rotation.conjugate() * relative.position;
        let then = cache.rotation.conjugate() * cache.position;
        moved = moved.min((then - now).length() + chord * radius_a);
    }
    moved
}

/// `old` moved to the bodies' poses (A's, and B's relative to it): each point's side on A
/// (its anchor plus half its separation along the normal, as it was computed) stays where it
/// is in A, its side on B where it was in B; the separation is theirs along the normal fixed
/// in A, the position their midpoint. Ids, anchors, impulses and the cache stay.
pub fn rebuild(old: &PairContact, pose_a: &Transform, relative: &Transform) -> PairContact {
    let cache = &old.cache;
    let normal = cache.normal;
    let mut contact = *old;
    contact.manifold.normal = pose_a.rotation * normal;
    let count = contact.manifold.count as usize;
    for (point, &separation) in contact.manifold.points[..count]
        .iter_mut()
        .zip(&cache.separations)
    {
        let half = normal * (0.5 * separation);
        let on_a = point.anchor + half;
        let on_b_in_b = cache.rotation.conjugate() * (point.anchor - half - cache.position);
        let on_b = relative.position + relative.rotation * on_b_in_b;
        point.separation = (on_a - on_b).dot(normal);
        point.position = pose_a.transform_point((on_a + on_b) * 0.5);
    }
    contact
}

/// The cache of a manifold just computed at `relative` for `margin`.
pub fn cache_of(
    manifold: &Manifold,
    pose_a: &Transform,
    relative: &Transform,
    margin: f32,
) -> ManifoldCache {
    let mut separations = [0.0; MAX_MANIFOLD_POINTS];
    for (separation, point) in separations.iter_mut().zip(manifold.points()) {
        *separation = point.separation;
    }
    ManifoldCache {
        position: relative.position,
        margin,
        rotation: relative.rotation,
        normal: pose_a.rotation.conjugate() * manifold.normal,
        valid: 1,
        separations,
    }
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
    PairContact {
        manifold,
        impulses,
        cache: ManifoldCache::default(),
    }
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

    /// A unit box (body `moving`) resting 1 mm into a wider box below it or a ground plane,
    /// tilted a little so that the separations differ.
    struct Pair {
        colliders: [Collider; 2],
        poses: [BodyPose; 2],
        /// The unit box.
        moving: usize,
    }

    impl Pair {
        fn boxes() -> Self {
            let collider = |shape| Collider {
                shape,
                friction: 0.5,
                restitution: 0.0,
            };
            Self {
                colliders: [
                    collider(Shape::cuboid(Vec3::splat(0.5))),
                    collider(Shape::cuboid(Vec3::new(2.0, 0.5, 2.0))),
                ],
                poses: [
                    BodyPose::new(
                        Vec3::new(0.1, 0.999, -0.2),
                        Quat::from_rotation_x(0.002) * Quat::from_rotation_y(0.3),
                    ),
                    BodyPose::new(Vec3::ZERO, Quat::IDENTITY),
                ],
                moving: 0,
            }
        }

        /// The box on a plane, body B: only the box gives a bound.
        fn on_plane() -> Self {
            let mut pair = Self::boxes();
            pair.colliders[1].shape = Shape::plane(Vec3::Y, 0.5);
            pair
        }

        /// The plane as body A.
        fn on_plane_a() -> Self {
            let mut pair = Self::on_plane();
            pair.colliders.swap(0, 1);
            pair.poses.swap(0, 1);
            pair.moving = 1;
            pair
        }

        fn all() -> [Self; 3] {
            [Self::boxes(), Self::on_plane(), Self::on_plane_a()]
        }

        fn box_pose(&mut self) -> &mut BodyPose {
            &mut self.poses[self.moving]
        }

        /// One narrowphase step from `old`.
        fn step(&self, old: &PairContact) -> PairContact {
            let mut contacts = [*old];
            let velocities = [BodyVelocity::default(); 2];
            let inputs = NarrowphaseInputs {
                poses: &self.poses,
                velocities: &velocities,
                colliders: &self.colliders,
                margin: 0.02,
                dt: 1.0 / 60.0,
                skipped: &[],
                keep_resting: None,
            };
            update_contacts(
                &[crate::stages::pairs::pair_key(0, 1)],
                &mut contacts,
                &inputs,
            );
            contacts[0]
        }

        /// The contact computed afresh at the current poses, with `old`'s impulses.
        fn fresh(&self, old: &PairContact) -> PairContact {
            self.step(&PairContact {
                cache: ManifoldCache::default(),
                ..*old
            })
        }

        /// Both bodies moved by `motion` (world): their relative pose stays.
        fn move_both(&mut self, motion: Transform) {
            for pose in &mut self.poses {
                pose.position = motion.transform_point(pose.position);
                pose.rotation = motion.rotation * pose.rotation;
            }
        }
    }

    /// The same points within `tolerance` (m) of position, `separation` of separation.
    fn assert_same_points(
        moved: &PairContact,
        fresh: &PairContact,
        tolerance: f32,
        separation: f32,
    ) {
        assert_eq!(moved.manifold.count, fresh.manifold.count);
        assert!(
            moved
                .manifold
                .normal
                .abs_diff_eq(fresh.manifold.normal, 1e-6)
        );
        assert_eq!(moved.impulses, fresh.impulses);
        for (m, f) in moved.manifold.points().iter().zip(fresh.manifold.points()) {
            assert_eq!(m.id, f.id);
            assert!(
                m.position.abs_diff_eq(f.position, tolerance),
                "{m:?} against {f:?}"
            );
            assert!(
                (m.separation - f.separation).abs() <= separation,
                "{m:?} against {f:?}"
            );
        }
    }

    #[test]
    fn a_pair_moved_as_one_moves_its_manifold() {
        for mut pair in Pair::all() {
            let mut first = pair.step(&PairContact::default());
            assert_eq!(first.manifold.count, 4, "a box face down: four corners");
            assert_eq!(first.cache.valid, 1);
            first.impulses[2].normal = 3.0;
            pair.move_both(Transform::new(
                Vec3::new(30.0, -2.0, 7.0),
                Quat::from_rotation_z(1.2) * Quat::from_rotation_x(-0.4),
            ));
            let moved = pair.step(&first);
            assert_eq!(moved.cache, first.cache, "the cache held: nothing computed");
            assert_eq!(
                moved.manifold.points()[0].anchor,
                first.manifold.points()[0].anchor
            );
            assert_same_points(&moved, &pair.fresh(&first), 1e-5, 1e-6);
        }
    }

    #[test]
    fn small_relative_motions_move_the_points_with_their_bodies() {
        for mut pair in Pair::all() {
            let first = pair.step(&PairContact::default());
            // 0.4 mm deeper: the box's corners, each on the other body's face, go 0.4 mm in.
            pair.box_pose().position.y -= 4.0e-4;
            let moved = pair.step(&first);
            assert_eq!(moved.cache, first.cache);
            for (m, f) in moved.manifold.points().iter().zip(first.manifold.points()) {
                assert!((m.separation - (f.separation - 4.0e-4)).abs() < 1e-6);
            }
            assert_same_points(&moved, &pair.fresh(&first), 1e-6, 1e-6);
            // A turn of the box that moves its corners 0.5 mm more: 0.9 mm from where the
            // manifold was computed, held as well.
            let pose = pair.box_pose();
            pose.rotation = Quat::from_rotation_y(5.0e-4 / 0.866) * pose.rotation;
            let turned = pair.step(&moved);
            assert_eq!(turned.cache, first.cache);
            // Each corner of the box turned 0.5 mm over the face below. A fresh manifold's
            // point below the corner slides with it, the moved one's stays on the face: the
            // midpoints differ by half the slide; the separations are the corners' alike.
            assert_same_points(&turned, &pair.fresh(&moved), 2.6e-4, 1e-6);
        }
    }

    #[test]
    fn motions_past_the_tolerance_compute_the_manifold_again() {
        for motion in [
            // Slid 1.1 mm.
            Transform::from_position(Vec3::new(1.1e-3, 0.0, 0.0)),
            // Turned in place by what moves a corner of the box 1.2 mm (its radius is 0.866).
            Transform::new(Vec3::ZERO, Quat::from_rotation_y(1.2e-3 / 0.866)),
        ] {
            for mut pair in Pair::all() {
                let first = pair.step(&PairContact::default());
                let pose = pair.box_pose();
                pose.position += motion.position;
                pose.rotation = motion.rotation * pose.rotation;
                let next = pair.step(&first);
                assert_ne!(next.cache, first.cache, "{motion:?}");
                assert_eq!(next.cache.valid, 1);
                assert_eq!(next, pair.fresh(&first), "computed afresh, {motion:?}");
            }
        }
    }

    #[test]
    fn a_larger_margin_computes_the_manifold_again() {
        let pair = Pair::boxes();
        let mut first = pair.step(&PairContact::default());
        // As if computed with a margin 1.5 mm smaller: points 1.5 mm apart may be missing.
        first.cache.margin -= 1.5e-3;
        assert_ne!(pair.step(&first).cache, first.cache);
        first.cache.margin += 1.0e-3;
        assert_eq!(
            pair.step(&first).cache,
            first.cache,
            "0.5 mm is within tolerance"
        );
    }
}
