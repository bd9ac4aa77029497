//! Shape casts against parry3d's `cast_shapes` (code no one here wrote) on thousands of random
//! convex pairs (spheres, capsules, boxes, hulls, each against each), seeded. Where parry is
//! off by more than its tolerance allows, ours must prove itself from exact support functions
//! (see the comments at each such case); the counts are printed.
use parry3d::math::{Pose as ParryPose, Rotation as ParryRotation, Vector as ParryVector};
use parry3d::query::{ShapeCastOptions, ShapeCastStatus};
use parry3d::shape::{Ball, Capsule, ConvexPolyhedron, Cuboid, SharedShape};
use tumble::Shape;
use tumble::collision::gjk::{GjkResult, MinkowskiDifference, OVERLAP_DISTANCE, SupportMap, gjk};
use tumble::collision::ray::{ShapeSweep, cast_shape};
use tumble::math::{Quat, Transform, Vec3, vec3};

/// A small deterministic generator (numerical recipes' LCG), so the pairs are the same in
/// every run.
struct Lcg(u32);

impl Lcg {
    fn uniform(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.uniform()
    }

    fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        vec3(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    /// A random convex shape of kind `kind % 4` and its parry twin.
    fn shape(&mut self, kind: usize) -> (Shape, SharedShape) {
        match kind % 4 {
            0 => {
                let radius = self.range(0.1, 1.0);
                (Shape::sphere(radius), SharedShape::new(Ball::new(radius)))
            }
            1 => {
                let (radius, half_height) = (self.range(0.1, 0.6), self.range(0.0, 1.0));
                (
                    Shape::capsule(radius, half_height),
                    SharedShape::new(Capsule::new_y(half_height, radius)),
                )
            }
            2 => {
                let half = self.vec3(0.1, 1.0);
                (
                    Shape::cuboid(half),
                    SharedShape::new(Cuboid::new(ParryVector::from_array(half.to_array()))),
                )
            }
            _ => {
                let scale = self.vec3(0.2, 1.0);
                let count = 6 + (self.uniform() * 15.0) as usize;
                loop {
                    let points: Vec<Vec3> =
                        (0..count).map(|_| scale * self.vec3(-1.0, 1.0)).collect();
                    if let Ok(shape) = Shape::convex_hull(&points) {
                        let Shape::ConvexHull(hull) = &shape else {
                            unreachable!("convex_hull makes a hull")
                        };
                        let vertices: Vec<ParryVector> = hull
                            .vertices()
                            .iter()
                            .map(|v| ParryVector::from_array(v.to_array()))
                            .collect();
                        let parry = ConvexPolyhedron::from_convex_hull(&vertices)
                            .expect("parry hulls our hull's vertices");
                        return (shape, SharedShape::new(parry));
                    }
                }
            }
        }
    }

    fn rotation(&mut self) -> Quat {
        Quat::from_xyzw(
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
        )
        .normalize()
    }
}

fn parry_pose(pose: &Transform) -> ParryPose {
    ParryPose::from_parts(
        ParryVector::from_array(pose.position.to_array()),
        ParryRotation::from_array(pose.rotation.to_array()),
    )
}

fn to_vec3(v: ParryVector) -> Vec3 {
    Vec3::from_array(v.to_array())
}

const PAIRS: usize = 4000;

/// Bounds on the distance between two convex shapes (m; < 0 overlapping): the separation
/// along GJK's normal, from exact support points, is a lower bound, and GJK's distance, the
/// length of a point of the Minkowski difference, an upper bound. Cores GJK calls overlapping
/// are within `OVERLAP_DISTANCE` of each other.
fn gap_bounds(a: &Shape, pose_a: &Transform, b: &Shape, pose_b: &Transform) -> (f32, f32) {
    let (a, b) = (support_map(a), support_map(b));
    let radii = a.radius() + b.radius();
    let m = MinkowskiDifference::new(a, pose_a, b, pose_b);
    match gjk(&m) {
        GjkResult::Separated {
            distance, normal, ..
        } => (m.separation_along(normal) - radii, distance - radii),
        GjkResult::Overlapping { .. } => (f32::NEG_INFINITY, OVERLAP_DISTANCE - radii),
    }
}

/// A lower bound on the distance (m): the larger of GJK's and the separation along the world
/// `normal` (from b to a), both from exact supports.
fn separation(a: &Shape, pose_a: &Transform, b: &Shape, pose_b: &Transform, normal: Vec3) -> f32 {
    let (lower, _) = gap_bounds(a, pose_a, b, pose_b);
    let (a, b) = (support_map(a), support_map(b));
    let m = MinkowskiDifference::new(a, pose_a, b, pose_b);
    let along =
        m.separation_along(pose_a.inverse_transform_vector(normal)) - a.radius() - b.radius();
    lower.max(along)
}

fn support_map(shape: &Shape) -> &dyn SupportMap {
    match shape {
        Shape::Sphere(s) => s,
        Shape::Capsule(c) => c,
        Shape::Cuboid(c) => c,
        Shape::ConvexHull(hull) => &**hull,
        _ => unreachable!("the test makes convex shapes only"),
    }
}

#[test]
fn shape_casts_agree_with_parry() {
    let mut rng = Lcg(77);
    let (mut hits, mut misses, mut starts, mut grazing) = (0, 0, 0, 0);
    let (mut parry_off, mut normals_certified, mut normals_ambiguous) = (0, 0, 0);
    let (mut worst_distance, mut worst_parry) = (0.0f32, 0.0f32);
    let mut worst_angle = 0.0f32;
    for pair in 0..PAIRS {
        let (moving, parry_moving) = rng.shape(pair);
        let (target, parry_target) = rng.shape(pair / 4);
        let start = Transform::new(rng.vec3(-4.0, 4.0), rng.rotation());
        let target_pose = Transform::new(rng.vec3(-1.0, 1.0), rng.rotation());
        // Aim near the target's centre: most paths hit, some graze, some miss.
        let direction = (target_pose.position + rng.vec3(-1.5, 1.5) - start.position).normalize();
        let max_distance = 10.0;
        let sweep = ShapeSweep::new(&moving, &start, direction, max_distance).unwrap();
        let hit = cast_shape(&sweep, &target, &target_pose);
        let oracle = parry3d::query::cast_shapes(
            &parry_pose(&start),
            ParryVector::from_array(direction.to_array()),
            parry_moving.as_ref(),
            &parry_pose(&target_pose),
            ParryVector::ZERO,
            parry_target.as_ref(),
            ShapeCastOptions::with_max_time_of_impact(max_distance),
        )
        .unwrap();
        match (hit, oracle) {
            (Some(hit), Some(oracle)) => {
                if oracle.status == ShapeCastStatus::PenetratingOrWithinTargetDist {
                    assert_eq!(hit.distance, 0.0, "pair {pair}: {hit:?}");
                    starts += 1;
                    continue;
                }
                hits += 1;
                let error = (hit.distance - oracle.time_of_impact).abs();
                if error >= 1e-4 {
                    // Parry's cast and distance stop once their bounds meet parry's tolerance
                    // (about 1e-3 relative, `query::gjk`), and now and then its time of impact
                    // is off by more than 1e-4 m: seen 2.5e-4 m short and 2.6e-3 m late, with
                    // its distance along the path jumping by 2e-4 m from one 1e-4 m step to
                    // the next. There ours must carry its own certificate, from exact support
                    // functions: apart 1e-4 m before our time (some direction separates), and
                    // 1e-4 m after it no farther apart than GJK's resolution (1e-5 m).
                    let moved =
                        |t: f32| Transform::new(start.position + t * direction, start.rotation);
                    let before = separation(
                        &moving,
                        &moved(hit.distance - 1e-4),
                        &target,
                        &target_pose,
                        hit.normal,
                    );
                    let (_, after) =
                        gap_bounds(&moving, &moved(hit.distance + 1e-4), &target, &target_pose);
                    assert!(
                        before > 0.0 && after <= OVERLAP_DISTANCE,
                        "pair {pair}: time of impact {} vs parry's {} (gap {before} before, \
                         {after} after)",
                        hit.distance,
                        oracle.time_of_impact
                    );
                    parry_off += 1;
                    worst_parry = worst_parry.max(error);
                    continue;
                }
                worst_distance = worst_distance.max(error);
                // Parry's normal2 is the target's outward normal in the target's frame.
                let expected = target_pose.transform_vector(to_vec3(oracle.normal2));
                let angle = hit
                    .normal
                    .dot(expected)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                if angle >= 1.0 {
                    let contact =
                        Transform::new(start.position + hit.distance * direction, start.rotation);
                    let (a, b) = (support_map(&moving), support_map(&target));
                    let m = MinkowskiDifference::new(a, &contact, b, &target_pose);
                    // Separation of the cores along a world normal, from exact supports.
                    let along =
                        |normal: Vec3| m.separation_along(contact.inverse_transform_vector(normal));
                    match gjk(&m) {
                        GjkResult::Separated { distance, .. } if distance > 1e-3 => {
                            // Rounded shapes. Parry's normal comes from its GJK at its
                            // tolerance, about 1e-3 relative: for cores `d` apart that leaves
                            // sqrt(2e-3) rad, 2.6°, of play. Ours proves itself: the separation
                            // along it falls short of `d` by some `e`, and a normal θ off the
                            // best one loses at least d (1 - cos θ), so θ <= acos(1 - e / d).
                            let shortfall = (distance - along(hit.normal)).max(0.0);
                            let bound = (1.0 - shortfall / distance).clamp(-1.0, 1.0).acos();
                            assert!(
                                bound.to_degrees() < 0.5,
                                "pair {pair}: normal {} vs parry's {expected} ({angle}°), ours \
                                 within {}°",
                                hit.normal,
                                bound.to_degrees()
                            );
                            normals_certified += 1;
                        }
                        _ => {
                            // Polytopes touching at a vertex or an edge against an edge: a
                            // range of normals is right, and each engine picks one. Both must
                            // separate the shapes at their contact (a support plane through
                            // it); parry's contact is this much earlier along the path.
                            let earlier = hit.distance - oracle.time_of_impact;
                            let parry_along = along(expected) - earlier * direction.dot(expected);
                            assert!(
                                along(hit.normal) > -1e-5 && parry_along > -1e-5,
                                "pair {pair}: normal {} vs parry's {expected} ({angle}°): \
                                 separations {} and {}",
                                hit.normal,
                                along(hit.normal),
                                parry_along
                            );
                            normals_ambiguous += 1;
                        }
                    }
                    continue;
                }
                worst_angle = worst_angle.max(angle);
            }
            (None, None) => misses += 1,
            // Parry's cast stops at its tolerance (see above) and then and again calls a near
            // miss a hit (seen: 2.7e-3 m of gap left at its time of impact); a path that only
            // grazes the target may also touch it by one account and miss it by the other.
            // Otherwise the one that differs from parry must prove itself.
            (hit, oracle) => {
                let moved = |t: f32| Transform::new(start.position + t * direction, start.rotation);
                let certified = match (hit, oracle) {
                    (Some(hit), _) => {
                        let before = separation(
                            &moving,
                            &moved(hit.distance - 1e-4),
                            &target,
                            &target_pose,
                            hit.normal,
                        );
                        let (_, after) =
                            gap_bounds(&moving, &moved(hit.distance + 1e-4), &target, &target_pose);
                        before > 0.0 && after <= OVERLAP_DISTANCE
                    }
                    (_, Some(oracle)) => {
                        let (apart, _) = gap_bounds(
                            &moving,
                            &moved(oracle.time_of_impact),
                            &target,
                            &target_pose,
                        );
                        apart > 0.0
                    }
                    _ => unreachable!("one of them hit"),
                };
                let closing = match (hit, oracle) {
                    (Some(hit), _) => -hit.normal.dot(direction),
                    (_, Some(oracle)) => -target_pose
                        .transform_vector(to_vec3(oracle.normal2))
                        .dot(direction),
                    _ => unreachable!("one of them hit"),
                };
                assert!(
                    certified || closing < 1e-2,
                    "pair {pair}: ours {hit:?}, parry's {oracle:?}"
                );
                if certified {
                    parry_off += 1;
                } else {
                    grazing += 1;
                }
            }
        }
    }
    println!(
        "{hits} hits ({parry_off} off parry's by more than 1e-4 m, certified, up to {worst_parry} m), {starts} starting in contact, \
         {misses} misses, {grazing} grazing; worst time of impact difference {worst_distance:e} \
         m, worst normal {worst_angle}° ({normals_certified} normals off parry's by 1° or more, \
         certified; {normals_ambiguous} contacts with a range of normals)"
    );
    assert!(
        hits > PAIRS / 3 && misses > PAIRS / 20 && starts > 0,
        "cover every case"
    );
    assert!(grazing < PAIRS / 100, "{grazing} grazing disagreements");
    // Measured: 165 of 2141 hits, 7.7%; the bound is there to catch a change, not to excuse one.
    assert!(parry_off < hits / 10, "parry's cast off {parry_off} times");
    assert!(
        normals_certified < PAIRS / 50,
        "parry's normal off {normals_certified} times"
    );
}
