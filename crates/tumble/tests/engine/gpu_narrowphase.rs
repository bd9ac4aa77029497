//! Parity of the GPU narrowphase with the CPU's `update_contacts`: random pairs of every
//! shape combination, near touching and overlapping, with last step's contacts reached
//! through an old-index map; plus the ties the CPU resolves by rule (boxes stacked square, a
//! box flat on a plane, parallel capsules), and two GPU runs compared bitwise.
//!
//! Counts, feature ids and carried impulses must be equal exactly. Positions, separations,
//! normals and anchors must agree within `TOLERANCE` = 1e-4 (m, or unit vector components):
//! both sides compute the same expressions in the same order, but WGSL lets the driver fuse a
//! multiply and an add and gives division, square root and the builtins a few ulps of slack.
//! Measured on lavapipe and llvmpipe over 100 000 random pairs, the largest difference was
//! 1e-6 m, one ulp of coordinates near 10 m; the bound leaves a hundred times that for
//! drivers that round differently and is still far below any geometric feature. One
//! exception, from the geometry rather than the code: the normal of a sphere or capsule is the
//! direction between two core points, and when the cores nearly meet (a deep overlap) an ulp
//! of their coordinates turns the direction by ulp / gap; see [`round_tolerances`].

use crate::gpu_common;

use gpu_common::{Random, context};
use tumble::Shape;
use tumble::collision::manifold::Manifold;
use tumble::dynamics::body::{BodyPose, BodyVelocity, Collider, ColliderData};
use tumble::gpu::{GpuContext, GpuVec};
use tumble::math::{Quat, Vec3, vec3};
use tumble::stages::narrowphase::{
    CACHE_TOLERANCE, GpuNarrowphase, GpuNarrowphaseInputs, ManifoldCache, NEW_PAIR,
    NarrowphaseInputs, PairContact, cache_motion, cache_radius, pack_hulls, relative_pose,
    shape_kinds, update_contacts,
};
use tumble::stages::pairs::{pair_bodies, pair_key};

const TOLERANCE: f32 = 1e-4;
const MARGIN: f32 = 0.02;
const DT: f32 = 1.0 / 60.0;

impl Random {
    fn unit(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 / (1u32 << 24) as f32
    }

    fn range(&mut self, low: f32, high: f32) -> f32 {
        low + (high - low) * self.unit()
    }

    fn direction(&mut self) -> Vec3 {
        loop {
            let v = vec3(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let length = v.length();
            if length > 0.1 && length <= 1.0 {
                return v / length;
            }
        }
    }

    fn rotation(&mut self) -> Quat {
        Quat::from_axis_angle(self.direction(), self.range(0.0, std::f32::consts::TAU))
    }

    /// One of the four shape kinds, of random size.
    fn shape(&mut self) -> Shape {
        match self.below(4) {
            0 => Shape::sphere(self.range(0.1, 1.0)),
            1 => Shape::capsule(self.range(0.1, 0.6), self.range(0.1, 1.0)),
            2 => Shape::cuboid(vec3(
                self.range(0.1, 1.0),
                self.range(0.1, 1.0),
                self.range(0.1, 1.0),
            )),
            _ => Shape::plane(self.direction(), self.range(-0.5, 0.5)),
        }
    }
}

/// Bodies, pairs and last step's contacts of a test.
#[derive(Clone)]
struct World {
    poses: Vec<BodyPose>,
    velocities: Vec<BodyVelocity>,
    colliders: Vec<Collider>,
    keys: Vec<u64>,
    skipped: Vec<u64>,
}

impl World {
    fn inputs(&self) -> NarrowphaseInputs<'_> {
        NarrowphaseInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            colliders: &self.colliders,
            margin: MARGIN,
            dt: DT,
            skipped: &self.skipped,
            keep_resting: None,
        }
    }
}

fn collider(shape: Shape) -> Collider {
    Collider {
        shape,
        friction: 0.5,
        restitution: 0.0,
    }
}

/// `pairs` pairs of two fresh bodies each, of random kinds (either index order), placed so
/// that about half touch: B at random, A at a random distance from it up to the sum of their
/// bounding radii (along a plane's normal, for a plane).
fn random_world(random: &mut Random, pairs: usize) -> World {
    random_world_with(random, pairs, |random| (random.shape(), random.shape()))
}

/// [`random_world`] with the pairs' shapes from `shapes`.
fn random_world_with(
    random: &mut Random,
    pairs: usize,
    mut shapes: impl FnMut(&mut Random) -> (Shape, Shape),
) -> World {
    let mut world = World {
        poses: Vec::new(),
        velocities: Vec::new(),
        colliders: Vec::new(),
        keys: Vec::new(),
        skipped: Vec::new(),
    };
    for pair in 0..pairs {
        let (shape_a, shape_b) = shapes(random);
        let pose_b = BodyPose::new(
            vec3(
                random.range(-10.0, 10.0),
                random.range(-10.0, 10.0),
                random.range(-10.0, 10.0),
            ),
            random.rotation(),
        );
        let reach = shape_a.bounding_radius() + shape_b.bounding_radius();
        let position_a = if let Shape::Plane(plane) = shape_b {
            let normal = pose_b.rotation * plane.normal;
            // The plane's surface point nearest the world origin.
            let surface = normal * (plane.offset + normal.dot(pose_b.position));
            surface + normal * random.range(-0.3, 1.0) * shape_a.bounding_radius().max(0.5)
        } else {
            pose_b.position + random.direction() * random.range(0.1, 1.05) * reach
        };
        let pose_a = BodyPose::new(position_a, random.rotation());
        let first = world.poses.len() as u32;
        // Either body may get the lower index (and so be body A of the pair).
        let swap = random.below(2) == 1;
        for (shape, pose) in if swap {
            [(shape_b, pose_b), (shape_a, pose_a)]
        } else {
            [(shape_a, pose_a), (shape_b, pose_b)]
        } {
            world.poses.push(pose);
            world.colliders.push(collider(shape));
            // Slow bodies mostly, some fast: the margin grows with the closing speed.
            let speed = if random.below(8) == 0 { 5.0 } else { 0.2 };
            world.velocities.push(BodyVelocity::new(
                random.direction() * random.range(0.0, speed),
                random.direction() * random.range(0.0, speed),
            ));
        }
        let key = pair_key(first, first + 1);
        world.keys.push(key);
        if pair % 17 == 5 {
            world.skipped.push(key);
        }
        if pair % 13 == 7 {
            // A jointed pair the broadphase did not report: must not match a neighbour.
            world.skipped.push(pair_key(first + 1, first + 2));
        }
    }
    world
}

/// Moves every body a little (up to 5 mm, 0.01 rad): the next step, so that some contacts
/// keep their ids, some change them and are matched by anchor, some appear or vanish.
fn nudge(random: &mut Random, poses: &mut [BodyPose]) {
    for pose in poses {
        pose.position += random.direction() * random.range(0.0, 0.005);
        pose.rotation = (Quat::from_axis_angle(random.direction(), random.range(0.0, 0.01))
            * pose.rotation)
            .normalize();
    }
}

/// Impulses on every point of `contacts`, distinct per point, as a solver would leave them.
fn give_impulses(random: &mut Random, contacts: &mut [PairContact]) {
    for contact in contacts {
        for impulse in &mut contact.impulses[..contact.manifold.count as usize] {
            impulse.normal = random.range(0.0, 10.0);
            impulse.tangent = [random.range(-1.0, 1.0), random.range(-1.0, 1.0)];
        }
    }
}

fn assert_close(what: &str, pair: usize, cpu: Vec3, gpu: Vec3, tolerance: f32) {
    assert!(
        (cpu - gpu).abs().max_element() <= tolerance,
        "pair {pair}: {what} {cpu} (CPU) vs {gpu} (GPU), tolerance {tolerance}"
    );
}

/// Rounding of coordinates that a core point of a sphere or capsule carries, in ulps of the
/// largest coordinate: the pose's rotation and translation, the segment's closest point.
const CORE_ULPS: f32 = 4.0;
/// The largest coordinate of the random worlds (m): poses within 10 m, plus a reach.
const COORDINATE_SCALE: f32 = 16.0;

/// (normal, point) tolerances of a pair. Face normals come from the shapes' axes, and agree
/// within TOLERANCE. A sphere's or capsule's normal is the direction between two core points
/// `gap` apart, each known to `CORE_ULPS` ulps of the coordinates, so it is known only to
/// about that error over `gap`; its points lie a radius from the core along it. On the H100 a
/// capsule pair with a 2.2 mm gap differed by 2e-4 in the normal, within this bound (3.5e-3)
/// and beyond TOLERANCE; lavapipe rounds as the CPU does there.
fn round_tolerances(world: &World, key: u64, manifold: &Manifold) -> (f32, f32) {
    let radius = |body: u32| match world.colliders[body as usize].shape {
        Shape::Sphere(sphere) => sphere.radius,
        Shape::Capsule(capsule) => capsule.radius,
        _ => 0.0,
    };
    let (a, b) = pair_bodies(key);
    let rounding = radius(a) + radius(b);
    if rounding == 0.0 {
        return (TOLERANCE, TOLERANCE);
    }
    let deepest = manifold
        .points()
        .iter()
        .map(|point| point.separation)
        .fold(f32::INFINITY, f32::min);
    let gap = (deepest + rounding).max(f32::MIN_POSITIVE);
    let normal = TOLERANCE.max(CORE_ULPS * f32::EPSILON * COORDINATE_SCALE / gap);
    (normal, TOLERANCE.max(normal * rounding))
}

/// Same count, ids and impulses (exactly), the rest within TOLERANCE (or, for spheres and
/// capsules, [`round_tolerances`]).
fn assert_parity(world: &World, cpu: &[PairContact], gpu: &[PairContact]) {
    assert_eq!(cpu.len(), gpu.len());
    for (pair, (cpu, gpu)) in cpu.iter().zip(gpu).enumerate() {
        let (m_cpu, m_gpu): (&Manifold, &Manifold) = (&cpu.manifold, &gpu.manifold);
        assert_eq!(
            m_cpu.count, m_gpu.count,
            "pair {pair}: {m_cpu:?} vs {m_gpu:?}"
        );
        let (normal, point) = round_tolerances(world, world.keys[pair], m_cpu);
        assert_close("normal", pair, m_cpu.normal, m_gpu.normal, normal);
        for (p_cpu, p_gpu) in m_cpu.points().iter().zip(m_gpu.points()) {
            assert_eq!(p_cpu.id, p_gpu.id, "pair {pair}: {m_cpu:?} vs {m_gpu:?}");
            assert_close("position", pair, p_cpu.position, p_gpu.position, point);
            assert_close("anchor", pair, p_cpu.anchor, p_gpu.anchor, point);
            assert!(
                (p_cpu.separation - p_gpu.separation).abs() <= TOLERANCE,
                "pair {pair}: separation {} vs {}",
                p_cpu.separation,
                p_gpu.separation
            );
        }
        assert_eq!(cpu.impulses, gpu.impulses, "pair {pair}: impulses");
        // The cache each made (or kept): the same, within rounding.
        let (c_cpu, c_gpu) = (&cpu.cache, &gpu.cache);
        assert_eq!(
            c_cpu.valid, c_gpu.valid,
            "pair {pair}: {c_cpu:?} vs {c_gpu:?}"
        );
        if c_cpu.valid == 1 {
            assert_close(
                "cache position",
                pair,
                c_cpu.position,
                c_gpu.position,
                point,
            );
            assert_close("cache normal", pair, c_cpu.normal, c_gpu.normal, normal);
            let rotation = |q: Quat| Vec3::new(q.x, q.y, q.z) * q.w.signum();
            let (r_cpu, r_gpu) = (rotation(c_cpu.rotation), rotation(c_gpu.rotation));
            assert_close("cache rotation", pair, r_cpu, r_gpu, TOLERANCE);
            assert!((c_cpu.margin - c_gpu.margin).abs() <= TOLERANCE * c_cpu.margin);
            let separations = (c_cpu.separations.iter().zip(&c_gpu.separations))
                .all(|(s_cpu, s_gpu)| (s_cpu - s_gpu).abs() <= TOLERANCE);
            assert!(separations, "pair {pair}: {c_cpu:?} vs {c_gpu:?}");
        }
    }
}

fn hull_words(world: &World) -> Vec<u32> {
    let mut words = Vec::new();
    pack_hulls(&world.colliders, &mut words);
    words
}

/// Runs the GPU stage through `encode`, on device buffers, with last step's contacts reached
/// through `old_index`.
fn gpu_step(
    context: &GpuContext,
    narrowphase: &mut GpuNarrowphase,
    world: &World,
    old_index: &[u32],
    old_contacts: &[PairContact],
) -> Vec<PairContact> {
    let colliders: Vec<ColliderData> = world.colliders.iter().map(|c| c.data()).collect();
    let keys = GpuVec::from_slice(context, "keys", &world.keys).unwrap();
    let old_index = GpuVec::from_slice(context, "old index", old_index).unwrap();
    let old_contacts = GpuVec::from_slice(context, "old contacts", old_contacts).unwrap();
    let poses = GpuVec::from_slice(context, "poses", &world.poses).unwrap();
    let velocities = GpuVec::from_slice(context, "velocities", &world.velocities).unwrap();
    let colliders = GpuVec::from_slice(context, "colliders", &colliders).unwrap();
    let hulls = GpuVec::from_slice(context, "hulls", &hull_words(world)).unwrap();
    let skipped = GpuVec::from_slice(context, "skipped", &world.skipped).unwrap();
    let mut contacts = GpuVec::with_capacity(context, "contacts", 0).unwrap();
    let mut encoder = context
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        let inputs = GpuNarrowphaseInputs {
            keys: &keys,
            old_index: &old_index,
            old_contacts: &old_contacts,
            poses: &poses,
            velocities: &velocities,
            colliders: &colliders,
            hulls: &hulls,
            skipped: &skipped,
            margin: MARGIN,
            dt: DT,
            shape_kinds: shape_kinds(&world.colliders),
        };
        narrowphase
            .encode(context, &mut pass, &inputs, &mut contacts)
            .unwrap();
    }
    context.queue.submit([encoder.finish()]);
    contacts.download(context).unwrap()
}

/// Random pairs of every combination, with a previous step whose pair list differs (pairs
/// dropped and pairs added), compared with the CPU on contacts carried by key.
#[test]
fn random_pairs_match_the_cpu() {
    let context = context();
    let mut narrowphase = GpuNarrowphase::new();
    for (seed, pairs) in [0usize, 1, 2, 100, 10_000].into_iter().enumerate() {
        let mut random = Random::new(seed as u64 + 1);
        let world = random_world(&mut random, pairs);
        let cpu = compare_with_cpu(&context, &mut narrowphase, &mut random, world);
        if pairs == 10_000 {
            // The test means something: contacts of every kind, and carried impulses.
            let touching = cpu.iter().filter(|c| c.manifold.count > 0).count();
            let carried = cpu.iter().filter(|c| c.impulses[0].normal > 0.0).count();
            assert!(touching > pairs / 4, "{touching} pairs touch");
            assert!(carried > pairs / 10, "{carried} pairs carry impulses");
        }
    }
}

/// Runs `world` as the second of two steps on both executors (last step: the pairs but every
/// fifth, at slightly different poses, with impulses set) and asserts parity; with 1000 pairs
/// or more, also that a second GPU run is bitwise the same. Returns the CPU's contacts.
fn compare_with_cpu(
    context: &GpuContext,
    narrowphase: &mut GpuNarrowphase,
    random: &mut Random,
    mut world: World,
) -> Vec<PairContact> {
    // Last step: the pairs but every fifth (new this step), in a sorted array of their own,
    // with contacts computed at slightly different poses and impulses set.
    let old_keys: Vec<u64> = world
        .keys
        .iter()
        .enumerate()
        .filter(|(index, _)| index % 5 != 3)
        .map(|(_, &key)| key)
        .collect();
    let mut old_contacts = vec![PairContact::default(); old_keys.len()];
    let old_world = World {
        keys: old_keys.clone(),
        skipped: Vec::new(),
        poses: world.poses.clone(),
        velocities: world.velocities.clone(),
        colliders: world.colliders.clone(),
    };
    update_contacts(&old_keys, &mut old_contacts, &old_world.inputs());
    give_impulses(random, &mut old_contacts);
    nudge(random, &mut world.poses);

    let old_index: Vec<u32> = world
        .keys
        .iter()
        .map(|key| {
            old_keys
                .binary_search(key)
                .map_or(NEW_PAIR, |index| index as u32)
        })
        .collect();
    let mut cpu: Vec<PairContact> = old_index
        .iter()
        .map(|&index| {
            if index == NEW_PAIR {
                PairContact::default()
            } else {
                old_contacts[index as usize]
            }
        })
        .collect();
    update_contacts(&world.keys, &mut cpu, &world.inputs());
    let gpu = gpu_step(context, narrowphase, &world, &old_index, &old_contacts);
    assert_parity(&world, &cpu, &gpu);
    if world.keys.len() >= 1000 {
        // Deterministic: a second run is bitwise the same.
        let again = gpu_step(context, narrowphase, &world, &old_index, &old_contacts);
        assert!(bytemuck::cast_slice::<_, u8>(&gpu) == bytemuck::cast_slice::<_, u8>(&again));
    }
    cpu
}

/// A hull of 4 to 40 random points in a box of random proportions (0.1 to 1 m a side):
/// lopsided, so its frame is turned and shifted from the points'.
fn random_hull(random: &mut Random) -> Shape {
    loop {
        let half = vec3(
            random.range(0.1, 1.0),
            random.range(0.1, 1.0),
            random.range(0.1, 1.0),
        );
        let count = 4 + random.below(37) as usize;
        let points: Vec<Vec3> = (0..count)
            .map(|_| {
                half * vec3(
                    random.range(-1.0, 1.0),
                    random.range(-1.0, 1.0),
                    random.range(-1.0, 1.0),
                )
            })
            .collect();
        // Thin draws (all points nearly coplanar) make no hull: draw again.
        if let Ok(hull) = tumble::shape::ConvexHull::new(&points) {
            return Shape::ConvexHull(std::sync::Arc::new(hull.in_own_frame()));
        }
    }
}

/// Hull pairs on the GPU: hull–hull, box–hull and hull–plane of the scene's barrel and of
/// random hulls, in both index orders, touching, overlapping and apart within the margin:
/// face contacts (with more than four clipped points to reduce), edge contacts and a hull's
/// many vertices on a plane. (Before hulls had a kernel, the GPU gave these pairs no
/// contact.)
#[test]
fn random_hull_pairs_match_the_cpu() {
    let context = context();
    let mut narrowphase = GpuNarrowphase::new();
    // One barrel shared by every pair that draws it, as the scene's bodies share it.
    let barrel = Shape::convex_hull(&tumble::scene::barrel_points()).unwrap();
    for (seed, pairs) in [0usize, 1, 257, 3000].into_iter().enumerate() {
        let mut random = Random::new(seed as u64 + 50);
        let world = random_world_with(&mut random, pairs, |random| {
            let hull = |random: &mut Random| {
                if random.below(2) == 0 {
                    barrel.clone()
                } else {
                    random_hull(random)
                }
            };
            let a = hull(random);
            let b = match random.below(3) {
                0 => hull(random),
                1 => Shape::cuboid(vec3(
                    random.range(0.1, 1.0),
                    random.range(0.1, 1.0),
                    random.range(0.1, 1.0),
                )),
                _ => Shape::plane(random.direction(), random.range(-0.5, 0.5)),
            };
            assert!(tumble::stages::narrowphase::gpu_pair(&a, &b));
            (a, b)
        });
        let cpu = compare_with_cpu(&context, &mut narrowphase, &mut random, world);
        if pairs == 3000 {
            let points = || cpu.iter().flat_map(|c| c.manifold.points());
            let touching = cpu.iter().filter(|c| c.manifold.count > 0).count();
            let edges = points().filter(|p| p.id & (1 << 31) != 0).count();
            let full = cpu.iter().filter(|c| c.manifold.count == 4).count();
            let carried = cpu.iter().filter(|c| c.impulses[0].normal > 0.0).count();
            assert!(touching > pairs / 4, "{touching} pairs touch");
            assert!(edges > 50, "{edges} edge contacts");
            assert!(full > pairs / 10, "{full} manifolds of four points");
            assert!(carried > pairs / 10, "{carried} pairs carry impulses");
        }
    }
}

/// A prism of `sides` sides (radius 1 m, 1 m tall) scaled by `scale`: two faces of `sides`
/// vertices, past the clip polygon of hull–hull pairs when `sides` > 16.
fn prism(sides: usize, scale: Vec3) -> Shape {
    let points: Vec<Vec3> = (0..2 * sides)
        .map(|k| {
            let angle = std::f32::consts::TAU * (k % sides) as f32 / sides as f32;
            scale * vec3(angle.cos(), if k < sides { -0.5 } else { 0.5 }, angle.sin())
        })
        .collect();
    Shape::convex_hull(&points).unwrap()
}

/// Sphere– and capsule–hull pairs on the GPU (GJK, and the sampled penetration depth where the
/// cores overlap), in both index orders: apart within the margin, touching, overlapping and
/// deep (a core inside the hull), against the barrel, random hulls and prisms of 3 to 40 sides
/// (faces of every size, larger than hull–hull pairs take), flat or tall. Capsules lying along
/// a face get two points. (Before this kernel the GPU gave these pairs no contact.)
#[test]
fn random_round_hull_pairs_match_the_cpu() {
    let context = context();
    let mut narrowphase = GpuNarrowphase::new();
    let barrel = Shape::convex_hull(&tumble::scene::barrel_points()).unwrap();
    for (seed, pairs) in [0usize, 1, 257, 3000].into_iter().enumerate() {
        let mut random = Random::new(seed as u64 + 70);
        let world = random_world_with(&mut random, pairs, |random| {
            let round = if random.below(2) == 0 {
                Shape::sphere(random.range(0.05, 0.6))
            } else {
                Shape::capsule(random.range(0.05, 0.5), random.range(0.05, 1.0))
            };
            let hull = match random.below(3) {
                0 => barrel.clone(),
                1 => random_hull(random),
                _ => prism(
                    3 + random.below(38) as usize,
                    vec3(
                        random.range(0.2, 2.0),
                        random.range(0.1, 2.0),
                        random.range(0.2, 2.0),
                    ),
                ),
            };
            assert!(tumble::stages::narrowphase::gpu_pair(&round, &hull));
            (round, hull)
        });
        let cpu = compare_with_cpu(&context, &mut narrowphase, &mut random, world.clone());
        if pairs == 3000 {
            let touching = cpu.iter().filter(|c| c.manifold.count > 0).count();
            let two_points = cpu.iter().filter(|c| c.manifold.count == 2).count();
            // A core inside the hull: deeper than the round shape's radius.
            let cores_overlap = cpu
                .iter()
                .zip(&world.keys)
                .filter(|(contact, key)| {
                    let (a, b) = tumble::stages::pairs::pair_bodies(**key);
                    let radius = [a, b]
                        .iter()
                        .find_map(|&body| match &world.colliders[body as usize].shape {
                            Shape::Sphere(sphere) => Some(sphere.radius),
                            Shape::Capsule(capsule) => Some(capsule.radius),
                            _ => None,
                        })
                        .unwrap();
                    contact
                        .manifold
                        .points()
                        .iter()
                        .any(|p| p.separation < -radius)
                })
                .count();
            let carried = cpu.iter().filter(|c| c.impulses[0].normal > 0.0).count();
            assert!(touching > pairs / 4, "{touching} pairs touch");
            assert!(two_points > 20, "{two_points} capsules along a face");
            assert!(cores_overlap > pairs / 20, "{cores_overlap} cores overlap");
            assert!(carried > pairs / 10, "{carried} pairs carry impulses");
        }
    }
}

/// Spheres and capsules at set distances from hull faces, edges and vertices, over steps that
/// slide them along: resting exactly on a face (separation 0), within the margin, just inside,
/// a capsule flat on a face (two points) and tilted past 2° (one), a core exactly on the
/// surface and one at the hull's centre.
#[test]
fn round_shapes_on_hulls_match() {
    let context = context();
    let barrel = &Shape::convex_hull(&tumble::scene::barrel_points()).unwrap();
    let box_hull = &prism(4, vec3(1.0, 1.0, 1.0));
    let sphere = &Shape::sphere(0.25);
    let capsule = &Shape::capsule(0.1, 0.3);
    let lying = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    let tilted = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2 - 0.05);
    let frames: Vec<World> = (0..4)
        .map(|step| {
            let slide = vec3(step as f32 * 0.05, 0.0, step as f32 * 0.02);
            pairs_world(&[
                // The barrel's top face is at y = 0.5.
                [
                    (sphere, vec3(0.0, 0.75, 0.0) + slide, Quat::IDENTITY),
                    (barrel, Vec3::ZERO, Quat::IDENTITY),
                ],
                [
                    (barrel, vec3(5.0, 0.0, 0.0), Quat::IDENTITY),
                    (sphere, vec3(5.0, 0.76, 0.0) + slide, Quat::IDENTITY),
                ],
                [
                    (sphere, vec3(10.0, 0.7, 0.0) + slide, Quat::IDENTITY),
                    (barrel, vec3(10.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                [
                    (capsule, vec3(15.0, 0.6, 0.0) + slide, lying),
                    (barrel, vec3(15.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                [
                    (capsule, vec3(20.0, 0.61, 0.0) + slide, tilted),
                    (barrel, vec3(20.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                // The core on the prism's top face, and at its centre.
                [
                    (sphere, vec3(25.0, 0.5, 0.0) + slide, Quat::IDENTITY),
                    (box_hull, vec3(25.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                [
                    (capsule, vec3(30.0, 0.0, 0.0) + 0.1 * slide, lying),
                    (box_hull, vec3(30.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                // Over the prism's vertical edge at x = 1, beyond its corner.
                [
                    (sphere, vec3(36.2, 0.0, 0.0) + slide, Quat::IDENTITY),
                    (box_hull, vec3(35.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                [
                    (sphere, vec3(41.0, 0.7, 0.1) + slide, Quat::IDENTITY),
                    (box_hull, vec3(40.0, 0.0, 0.0), Quat::IDENTITY),
                ],
            ])
        })
        .collect();
    let steps = run_steps(&context, &frames);
    let counts: Vec<u32> = steps[0].iter().map(|c| c.manifold.count).collect();
    assert_eq!(counts, [1, 1, 1, 2, 1, 1, 2, 1, 1]);
}

/// Pairs of a hull with a face of more than `MAX_HULL_FACE_VERTICES` vertices and a box, plane
/// or hull are host work (the kernel's clip polygon holds twice that many); spheres and
/// capsules take any hull.
#[test]
fn large_faces_stay_on_the_host() {
    use tumble::stages::narrowphase::gpu_pair;
    let hull = Shape::convex_hull(&tumble::scene::barrel_points()).unwrap();
    let (fits, too_large) = (prism(16, Vec3::ONE), prism(17, Vec3::ONE));
    for round in [Shape::sphere(0.5), Shape::capsule(0.3, 0.5)] {
        for any in [&hull, &fits, &too_large] {
            assert!(gpu_pair(&round, any) && gpu_pair(any, &round));
        }
    }
    for polyhedral in [
        hull.clone(),
        Shape::cuboid(Vec3::ONE),
        Shape::plane(Vec3::Y, 0.0),
    ] {
        assert!(gpu_pair(&polyhedral, &hull) && gpu_pair(&hull, &polyhedral));
    }
    assert!(gpu_pair(&fits, &hull) && gpu_pair(&fits, &Shape::cuboid(Vec3::ONE)));
    assert!(!gpu_pair(&too_large, &hull) && !gpu_pair(&Shape::cuboid(Vec3::ONE), &too_large));
}

/// Runs `frames` (the same pairs at successive poses) as successive steps on both executors,
/// each carrying its own contacts from step to step, with the same impulses written into both
/// after each step as a solver would; compares every step. Returns the CPU's contacts of each
/// step, before the impulses were written. The frames move by micrometres, which the
/// narrowphase's cache would take as no motion: each step computes the manifolds afresh, as
/// after a motion past the cache's tolerance, so that the pair functions are compared.
fn run_steps(context: &GpuContext, frames: &[World]) -> Vec<Vec<PairContact>> {
    let mut narrowphase = GpuNarrowphase::new();
    let pairs = frames[0].keys.len();
    let mut cpu = vec![PairContact::default(); pairs];
    let mut gpu = vec![PairContact::default(); pairs];
    let mut steps = Vec::new();
    for (step, world) in frames.iter().enumerate() {
        for contact in cpu.iter_mut().chain(&mut gpu) {
            contact.cache = ManifoldCache::default();
        }
        update_contacts(&world.keys, &mut cpu, &world.inputs());
        narrowphase
            .update_contacts(context, &world.keys, &mut gpu, &world.inputs())
            .unwrap();
        assert_parity(world, &cpu, &gpu);
        steps.push(cpu.clone());
        for contacts in [&mut cpu, &mut gpu] {
            for (pair, contact) in contacts.iter_mut().enumerate() {
                for (point, impulse) in contact.impulses.iter_mut().enumerate() {
                    impulse.normal = (1 + step * 100 + pair * 10 + point) as f32;
                }
            }
        }
    }
    steps
}

/// One pair of two bodies per entry of `bodies`, body 2i and 2i + 1.
fn pairs_world(bodies: &[[(&Shape, Vec3, Quat); 2]]) -> World {
    let mut world = World {
        poses: Vec::new(),
        velocities: Vec::new(),
        colliders: Vec::new(),
        keys: Vec::new(),
        skipped: Vec::new(),
    };
    for pair in bodies {
        let first = world.poses.len() as u32;
        for &(shape, position, rotation) in pair {
            let shape = shape.clone();
            world.poses.push(BodyPose::new(position, rotation));
            world.velocities.push(BodyVelocity::default());
            world.colliders.push(collider(shape));
        }
        world.keys.push(pair_key(first, first + 1));
    }
    world
}

/// Equal boxes stacked square put the upper box's corners exactly on the lower face's side
/// planes, where rounding decides between "incident vertex" and "clipped edge" and the CPU's
/// ids flip from step to step (mod.rs): the GPU must make the same choice each time, and then
/// match the renamed points by anchor the same way.
#[test]
fn stacked_boxes_flip_ids_alike() {
    let context = context();
    let cube = &Shape::cuboid(Vec3::splat(0.5));
    let slab = &Shape::cuboid(vec3(0.5, 0.25, 0.5));
    let offsets = [
        vec3(0.0, 0.0, 0.0),
        vec3(1e-7, -1e-6, 0.0),
        vec3(-1e-7, 1e-6, 2e-7),
        vec3(0.0, -2e-6, -1e-7),
        vec3(3e-7, 0.0, 0.0),
        vec3(0.0, 0.0, 0.0),
    ];
    let frames: Vec<World> = offsets
        .iter()
        .enumerate()
        .map(|(step, &offset)| {
            let yaw = Quat::from_rotation_y(step as f32 * 1e-6);
            pairs_world(&[
                // Upper box has the lower index: A on top.
                [
                    (cube, vec3(0.0, 1.0, 0.0) + offset, Quat::IDENTITY),
                    (cube, Vec3::ZERO, Quat::IDENTITY),
                ],
                // Lower box A: the normal points down.
                [
                    (cube, Vec3::ZERO, Quat::IDENTITY),
                    (cube, vec3(0.0, 0.999, 0.0) + offset, yaw),
                ],
                // Different heights, faces of equal size: the reference goes to the larger face
                // or, equal, to B.
                [
                    (slab, vec3(5.0, 0.75, 0.0) + offset, yaw),
                    (cube, vec3(5.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                // Half a box over the edge: edges exactly on side planes.
                [
                    (cube, vec3(10.5, 1.0, 0.0) + offset, Quat::IDENTITY),
                    (cube, vec3(10.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                // Edge down at 45°: the two faces at the edge are equally anti-parallel to the
                // lower face, and the incident one is chosen on a tie.
                [
                    (
                        cube,
                        vec3(20.0, 0.5 + std::f32::consts::FRAC_1_SQRT_2 - 0.001, 0.0) + offset,
                        Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
                    ),
                    (cube, vec3(20.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                // A quarter turn about y: the same square, vertices renumbered.
                [
                    (
                        cube,
                        vec3(15.0, 0.99, 0.0) + offset,
                        Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
                    ),
                    (cube, vec3(15.0, 0.0, 0.0), Quat::IDENTITY),
                ],
            ])
        })
        .collect();
    let steps = run_steps(&context, &frames);
    for contacts in &steps {
        let counts: Vec<u32> = contacts
            .iter()
            .map(|contact| contact.manifold.count)
            .collect();
        assert_eq!(counts, [4, 4, 4, 4, 2, 4]);
    }
    // The premise: some point changed its id from one step to the next yet kept its impulse
    // (matched by anchor).
    let ids = |contact: &PairContact| {
        contact
            .manifold
            .points()
            .iter()
            .map(|p| p.id)
            .collect::<Vec<_>>()
    };
    let renamed_and_carried = steps.windows(2).any(|pair| {
        pair[0].iter().zip(&pair[1]).any(|(before, after)| {
            after
                .manifold
                .points()
                .iter()
                .zip(&after.impulses)
                .any(|(point, impulse)| !ids(before).contains(&point.id) && impulse.normal > 0.0)
        })
    });
    assert!(renamed_and_carried);
}

/// A box flat on a plane has four vertices exactly at zero separation, and a thin one within
/// the margin has all eight, which `reduce` cuts to four on ties of equal distances and areas:
/// ties must go to the same (lower) index on both sides.
#[test]
fn box_on_plane_matches_on_ties() {
    let context = context();
    let cube = &Shape::cuboid(Vec3::splat(0.5));
    let thin = &Shape::cuboid(vec3(0.5, 0.005, 0.5));
    let ground = &Shape::plane(Vec3::Y, 0.0);
    let frames: Vec<World> = (0..4)
        .map(|step| {
            let lift = vec3(0.0, step as f32 * 1e-4, 0.0);
            let yaw = Quat::from_rotation_y(step as f32 * 0.3);
            pairs_world(&[
                [
                    (cube, vec3(0.0, 0.5, 0.0) + lift, Quat::IDENTITY),
                    (ground, Vec3::ZERO, Quat::IDENTITY),
                ],
                [
                    (ground, Vec3::ZERO, Quat::IDENTITY),
                    (cube, vec3(3.0, 0.5, 0.0) + lift, yaw),
                ],
                [
                    (thin, vec3(6.0, 0.005, 0.0) + lift, Quat::IDENTITY),
                    (ground, Vec3::ZERO, Quat::IDENTITY),
                ],
                [
                    (thin, vec3(9.0, 0.005, 0.0) + lift, yaw),
                    (ground, Vec3::ZERO, Quat::IDENTITY),
                ],
                // Edge down, and a plane turned and moved with its body.
                [
                    (
                        cube,
                        vec3(12.0, std::f32::consts::FRAC_1_SQRT_2, 0.0),
                        Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
                    ),
                    (ground, Vec3::ZERO, Quat::IDENTITY),
                ],
                [
                    (cube, vec3(15.0, 1.749, 0.0), Quat::IDENTITY),
                    (
                        &Shape::plane(Vec3::X, 0.25),
                        vec3(15.0, 1.0, 0.0),
                        Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
                    ),
                ],
            ])
        })
        .collect();
    let steps = run_steps(&context, &frames);
    let last = steps.last().unwrap();
    let counts: Vec<u32> = last.iter().map(|contact| contact.manifold.count).collect();
    assert_eq!(counts, [4, 4, 4, 4, 2, 4]);
}

/// Parallel capsules, side by side and end to end, touch along a segment: two points at the
/// ends of the overlap; a capsule lying on a box face or a plane likewise.
#[test]
fn parallel_capsules_match() {
    let context = context();
    let capsule = &Shape::capsule(0.25, 0.5);
    let long = &Shape::capsule(0.25, 1.0);
    let lying = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    let frames: Vec<World> = (0..3)
        .map(|step| {
            let slide = vec3(step as f32 * 0.1, 0.0, 0.0);
            pairs_world(&[
                [
                    (capsule, vec3(0.0, 0.49, 0.0) + slide, lying),
                    (long, Vec3::ZERO, lying),
                ],
                [
                    (long, vec3(5.0, 0.0, 0.0), lying),
                    (capsule, vec3(5.3, 0.5, 0.0) + slide, lying),
                ],
                // Coincident parallel axes: the fallback normal.
                [
                    (capsule, vec3(10.0, 0.0, 0.0) + slide, Quat::IDENTITY),
                    (long, vec3(10.0, 0.0, 0.0), Quat::IDENTITY),
                ],
                [
                    (capsule, vec3(15.0, 0.74, 0.0) + slide, lying),
                    (
                        &Shape::cuboid(Vec3::splat(0.5)),
                        vec3(15.0, 0.0, 0.0),
                        Quat::IDENTITY,
                    ),
                ],
                [
                    (long, vec3(20.0, 0.25, 0.0) + slide, lying),
                    (&Shape::plane(Vec3::Y, 0.0), Vec3::ZERO, Quat::IDENTITY),
                ],
                // Crossing at right angles, touching: one point.
                [
                    (capsule, vec3(25.0, 0.5, 0.0), lying),
                    (
                        capsule,
                        vec3(25.0, 0.0, 0.0) + slide,
                        Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
                    ),
                ],
            ])
        })
        .collect();
    let steps = run_steps(&context, &frames);
    let last = steps.last().unwrap();
    let counts: Vec<u32> = last.iter().map(|contact| contact.manifold.count).collect();
    assert_eq!(counts, [2, 2, 2, 2, 2, 1]);
}

/// The stage as a GPU step uses it: contacts stay on the device, this step's output is next
/// step's input (two arrays in turn), only the poses are uploaded; each step agrees with the
/// CPU carrying its contacts in place.
#[test]
fn device_resident_steps_match_the_cpu() {
    let context = context();
    let mut narrowphase = GpuNarrowphase::new();
    let mut random = Random::new(99);
    let mut world = random_world(&mut random, 1000);
    let mut cpu = vec![PairContact::default(); world.keys.len()];
    update_contacts(&world.keys, &mut cpu, &world.inputs());
    give_impulses(&mut random, &mut cpu);

    let identity: Vec<u32> = (0..world.keys.len() as u32).collect();
    let colliders: Vec<ColliderData> = world.colliders.iter().map(|c| c.data()).collect();
    let keys = GpuVec::from_slice(&context, "keys", &world.keys).unwrap();
    let old_index = GpuVec::from_slice(&context, "old index", &identity).unwrap();
    let mut poses = GpuVec::from_slice(&context, "poses", &world.poses).unwrap();
    let velocities = GpuVec::from_slice(&context, "velocities", &world.velocities).unwrap();
    let colliders = GpuVec::from_slice(&context, "colliders", &colliders).unwrap();
    let hulls = GpuVec::from_slice(&context, "hulls", &hull_words(&world)).unwrap();
    let skipped = GpuVec::from_slice(&context, "skipped", &world.skipped).unwrap();
    let mut contacts = [
        GpuVec::from_slice(&context, "contacts 0", &cpu).unwrap(),
        GpuVec::with_capacity(&context, "contacts 1", 0).unwrap(),
    ];
    for step in 0..4 {
        nudge(&mut random, &mut world.poses);
        update_contacts(&world.keys, &mut cpu, &world.inputs());
        poses.upload(&context, &world.poses).unwrap();
        let (old, new) = if step % 2 == 0 {
            let [old, new] = &mut contacts;
            (&*old, new)
        } else {
            let [new, old] = &mut contacts;
            (&*old, new)
        };
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            let inputs = GpuNarrowphaseInputs {
                keys: &keys,
                old_index: &old_index,
                old_contacts: old,
                poses: &poses,
                velocities: &velocities,
                colliders: &colliders,
                hulls: &hulls,
                skipped: &skipped,
                margin: MARGIN,
                dt: DT,
                shape_kinds: shape_kinds(&world.colliders),
            };
            narrowphase
                .encode(&context, &mut pass, &inputs, new)
                .unwrap();
        }
        context.queue.submit([encoder.finish()]);
        assert_parity(&world, &cpu, &new.download(&context).unwrap());
    }
    // Impulses made it through four steps of matching.
    assert!(cpu.iter().filter(|c| c.impulses[0].normal > 0.0).count() > 100);
}

/// Motions within the narrowphase's cache tolerance (`CACHE_TOLERANCE`, 1 mm): some pairs move
/// their old manifolds with the bodies, the others compute theirs again. The GPU decides pair
/// for pair as the CPU does, and the moved manifolds agree.
#[test]
fn small_motions_move_the_cached_manifolds_as_the_cpu_does() {
    let context = context();
    let mut narrowphase = GpuNarrowphase::new();
    let mut random = Random::new(7);
    let world = random_world(&mut random, 3000);
    move_slightly_on_both(&context, &mut narrowphase, &mut random, world);
    // Hulls against hulls, boxes and planes: the pairs that clip the most.
    let world = random_world_with(&mut random, 1000, |random| {
        let b = match random.below(3) {
            0 => random_hull(random),
            1 => Shape::cuboid(vec3(0.5, 0.3, 0.7)),
            _ => Shape::plane(random.direction(), 0.0),
        };
        (random_hull(random), b)
    });
    move_slightly_on_both(&context, &mut narrowphase, &mut random, world);
}

/// One step of `world`'s pairs from contacts computed where they are to poses moved by up to
/// 0.6 mm and 4e-4 rad a body, on both executors: see the test above.
fn move_slightly_on_both(
    context: &GpuContext,
    narrowphase: &mut GpuNarrowphase,
    random: &mut Random,
    mut world: World,
) {
    let mut old = vec![PairContact::default(); world.keys.len()];
    update_contacts(&world.keys, &mut old, &world.inputs());
    give_impulses(random, &mut old);
    // Up to 0.6 mm and 4e-4 rad a body: a pair's points move by up to about 2 mm.
    for pose in &mut world.poses {
        pose.position += random.direction() * random.range(0.0, 6.0e-4);
        pose.rotation = (Quat::from_axis_angle(random.direction(), random.range(0.0, 4.0e-4))
            * pose.rotation)
            .normalize();
    }
    let mut cpu = old.clone();
    update_contacts(&world.keys, &mut cpu, &world.inputs());
    let identity: Vec<u32> = (0..world.keys.len() as u32).collect();
    let mut gpu = gpu_step(context, narrowphase, &world, &identity, &old);
    // A pair that moved its manifold kept its cache, bit for bit.
    let held = |contacts: &[PairContact]| -> Vec<bool> {
        (contacts.iter().zip(&old))
            .map(|(new, old)| old.cache.valid == 1 && new.cache == old.cache)
            .collect()
    };
    let (held_cpu, held_gpu) = (held(&cpu), held(&gpu));
    // The decision compares a bound computed from world coordinates (up to 16 m here, an ulp
    // of 1e-6 m) with the tolerance: where the bound is that close to it, the executors'
    // rounding may decide either way (one pair in about 3000 on lavapipe).
    for pair in (0..held_cpu.len()).filter(|&pair| held_cpu[pair] != held_gpu[pair]) {
        let (a, b) = pair_bodies(world.keys[pair]);
        let (a, b) = (a as usize, b as usize);
        let relative = relative_pose(&world.poses[a].transform(), &world.poses[b].transform());
        let radii = [
            cache_radius(&world.colliders[a]),
            cache_radius(&world.colliders[b]),
        ];
        let motion = cache_motion(&old[pair].cache, &relative, radii);
        assert!(
            (motion - CACHE_TOLERANCE).abs() < 1e-5,
            "pair {pair} moved its manifold on one executor only, {motion} m from where it was"
        );
        gpu[pair] = cpu[pair];
    }
    assert_parity(&world, &cpu, &gpu);
    let touching: Vec<bool> = old.iter().map(|c| c.manifold.count > 0).collect();
    let count = |want: bool| {
        (held_cpu.iter().zip(&touching))
            .filter(|&(&held, &touching)| touching && held == want)
            .count()
    };
    let (moved, computed) = (count(true), count(false));
    assert!(
        moved > 100 && computed > 100,
        "both paths taken: {moved} touching pairs moved, {computed} computed"
    );
}
