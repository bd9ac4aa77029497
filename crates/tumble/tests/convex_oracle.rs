//! GJK distance, EPA and sampled penetration depth against parry3d (rapier's geometry crate,
//! code no one here wrote) on thousands of random convex hull pairs, seeded.
use parry3d::math::{Pose as ParryPose, Rotation as ParryRotation, Vector as ParryVector};
use parry3d::shape::ConvexPolyhedron;
use tumble::collision::epa::epa;
use tumble::collision::gjk::{GjkResult, MinkowskiDifference, gjk};
use tumble::collision::penetration::{Sampling, sampled_penetration};
use tumble::math::{Quat, Transform, Vec3, vec3};
use tumble::shape::ConvexHull;

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

    fn hull(&mut self) -> ConvexHull {
        let scale = vec3(
            self.range(0.2, 1.0),
            self.range(0.2, 1.0),
            self.range(0.2, 1.0),
        );
        let count = 6 + (self.uniform() * 15.0) as usize;
        loop {
            let points: Vec<Vec3> = (0..count)
                .map(|_| {
                    scale
                        * vec3(
                            self.range(-1.0, 1.0),
                            self.range(-1.0, 1.0),
                            self.range(-1.0, 1.0),
                        )
                })
                .collect();
            if let Ok(hull) = ConvexHull::new(&points) {
                return hull;
            }
        }
    }

    fn pose(&mut self, reach: f32) -> Transform {
        let position = vec3(
            self.range(-reach, reach),
            self.range(-reach, reach),
            self.range(-reach, reach),
        );
        let rotation = Quat::from_xyzw(
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
        )
        .normalize();
        Transform::new(position, rotation)
    }
}

fn parry_shape(hull: &ConvexHull) -> ConvexPolyhedron {
    let points: Vec<ParryVector> = hull
        .vertices()
        .iter()
        .map(|v| ParryVector::from_array(v.to_array()))
        .collect();
    ConvexPolyhedron::from_convex_hull(&points).expect("parry hulls our hull's vertices")
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

const PAIRS: usize = 3000;

#[test]
fn gjk_epa_and_sampling_agree_with_parry() {
    let mut rng = Lcg(2024);
    let (mut separated, mut overlapping, mut ambiguous) = (0, 0, 0);
    let mut sampled_excess: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
    for pair in 0..PAIRS {
        let (a, b) = (rng.hull(), rng.hull());
        let (pose_a, pose_b) = (rng.pose(0.2), rng.pose(1.2));
        let (pa, pb) = (parry_shape(&a), parry_shape(&b));
        let (ppa, ppb) = (parry_pose(&pose_a), parry_pose(&pose_b));
        let m = MinkowskiDifference::new(&a, &pose_a, &b, &pose_b);
        let oracle = parry3d::query::contact(&ppa, &pa, &ppb, &pb, 10.0)
            .unwrap()
            .expect("within the prediction distance");
        match gjk(&m) {
            GjkResult::Separated {
                distance, normal, ..
            } => {
                // A certificate: the plane normal to the closest points' offset separates the
                // shapes by at least `lower` (exact supports), and GJK's `distance` is the length
                // of a point of the Minkowski difference, at least the true distance. So the
                // true distance lies in [lower, distance].
                let lower = m.separation_along(normal);
                assert!(
                    distance - lower < 1e-4 && lower <= distance + 1e-6,
                    "pair {pair}: distance {distance}, certified only from {lower}"
                );
                // Parry's GJK stops once its bounds are within sqrt(10 f32::EPSILON) ≈ 1.1e-3
                // of the distance (parry3d 0.31 `query::gjk::closest_points`), so it vouches
                // for [0.9989 d, d] only; ours must fall in that bracket (f32 rounding aside).
                let expected = parry3d::query::distance(&ppa, &pa, &ppb, &pb)
                    .unwrap()
                    .distance;
                let parry_slack = (10.0 * f32::EPSILON).sqrt() * expected;
                assert!(
                    distance <= expected + 1e-5 && distance >= expected - parry_slack - 1e-5,
                    "pair {pair}: distance {distance}, parry {expected}"
                );
                separated += 1;
            }
            GjkResult::Overlapping { simplex } => {
                let depth = -oracle.dist;
                // Shallower than GJK's touching distance: parry and GJK may disagree on
                // whether that is overlap; nothing to compare.
                if depth <= 1e-4 {
                    continue;
                }
                overlapping += 1;
                // Parry's normal1 points from A to B; ours from B to A, in A's frame.
                let expected_normal = -pose_a.inverse_transform_vector(to_vec3(oracle.normal1));
                let tolerance = 1e-3 * depth + 1e-5;
                let penetration = epa(&m, &simplex).expect("full-dimensional hulls");
                assert!(
                    (penetration.depth - depth).abs() <= tolerance,
                    "pair {pair}: EPA depth {}, parry {depth}",
                    penetration.depth
                );
                // Two faces of the Minkowski difference can be (nearly) equally near: then
                // either normal is a right answer, and the check is that ours separates as
                // much as parry's does.
                if penetration
                    .normal
                    .angle_between(expected_normal)
                    .to_degrees()
                    > 1.0
                {
                    let along_ours = -m.separation_along(penetration.normal);
                    let along_parry = -m.separation_along(expected_normal);
                    assert!(
                        (along_ours - along_parry).abs() <= tolerance,
                        "pair {pair}: EPA normal {:?}, parry {expected_normal:?}",
                        penetration.normal
                    );
                    ambiguous += 1;
                }
                for (k, sampling) in [Sampling::Directions42, Sampling::Directions162]
                    .into_iter()
                    .enumerate()
                {
                    let sampled = sampled_penetration(&m, sampling);
                    // Sampling finds a local best: never deeper than the true depth, and
                    // measured against it.
                    assert!(
                        sampled.depth >= depth - tolerance,
                        "pair {pair}: sampled deeper"
                    );
                    sampled_excess[k].push((sampled.depth - depth) / depth);
                }
            }
        }
    }
    println!(
        "{separated} separated, {overlapping} overlapping ({ambiguous} with two equally near faces)"
    );
    for (k, name) in ["42", "162"].iter().enumerate() {
        let excess = &mut sampled_excess[k];
        excess.sort_by(f32::total_cmp);
        let within = |limit: f32| {
            excess.iter().filter(|&&e| e <= limit).count() as f32 / excess.len() as f32
        };
        println!(
            "sampled ({name}): depth within 0.1 % of EPA for {:.1} % of pairs, within 1 % for {:.1} %, within 10 % for {:.1} %; median excess {:e}, worst {}",
            100.0 * within(1e-3),
            100.0 * within(1e-2),
            100.0 * within(1e-1),
            excess[excess.len() / 2],
            excess[excess.len() - 1]
        );
        // Sampling is a heuristic (a local search from the best samples); these are its
        // measured rates on this seed (92.1 % / 93.7 % within 0.1 %, 98.1 % / 99.5 % within
        // 10 %), kept as a floor so a regression shows.
        let (within_tenth_percent, within_ten_percent) = [(0.92, 0.98), (0.93, 0.99)][k];
        assert!(
            within(1e-3) >= within_tenth_percent,
            "{name} directions got worse"
        );
        assert!(
            within(1e-1) >= within_ten_percent,
            "{name} directions got worse"
        );
    }
    assert!(separated > PAIRS / 5 && overlapping > PAIRS / 5);
    assert!(
        ambiguous * 100 < overlapping,
        "ambiguous normals should be rare"
    );
}
