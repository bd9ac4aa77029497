//! Nanoseconds per query of the convex-pair algorithms: GJK distance when apart, EPA and the
//! sampled penetration depth (42 and 162 directions) when overlapping. On two barrels (40-point
//! hulls, the `convex-hulls` scene's shape) at one pose, and averaged over 256 random
//! overlapping pairs of hulls of 6–20 points (the oracle test's generator), since the sampled
//! depth's cost depends on how many faces its descents cross.
//!
//! `cargo bench -p tumble --bench penetration`
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use tumble::collision::epa::epa;
use tumble::collision::gjk::{GjkResult, MinkowskiDifference, gjk};
use tumble::collision::penetration::{Sampling, sampled_penetration};
use tumble::math::{Quat, Transform, Vec3, vec3};
use tumble::scene::barrel_points;
use tumble::shape::ConvexHull;

const SAMPLINGS: [(&str, Sampling); 2] = [
    ("42 directions", Sampling::Directions42),
    ("162 directions", Sampling::Directions162),
];

fn barrels(c: &mut Criterion) {
    let barrel = ConvexHull::new(&barrel_points()).unwrap();
    let pose_a = Transform::IDENTITY;
    let tilted = Quat::from_euler(glam::EulerRot::XYZ, 0.4, 0.2, 0.9);
    let apart = Transform::new(vec3(0.4, 1.3, 0.2), tilted);
    let overlapping = Transform::new(vec3(0.3, 0.9, 0.1), tilted);

    c.bench_function("barrels: gjk distance (apart)", |bench| {
        bench.iter(|| {
            let m = MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&apart));
            black_box(gjk(&m))
        })
    });
    c.bench_function("barrels: gjk + epa (overlapping)", |bench| {
        bench.iter(|| {
            let m = MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&overlapping));
            match gjk(&m) {
                GjkResult::Overlapping { simplex } => black_box(epa(&m, &simplex)),
                GjkResult::Separated { .. } => unreachable!("the poses overlap"),
            }
        })
    });
    for (name, sampling) in SAMPLINGS {
        c.bench_function(&format!("barrels: sampled penetration, {name}"), |bench| {
            bench.iter(|| {
                let m =
                    MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&overlapping));
                black_box(sampled_penetration(&m, sampling))
            })
        });
    }
}

/// A small deterministic generator (numerical recipes' LCG), the oracle test's.
struct Lcg(u32);

impl Lcg {
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        lo + (hi - lo) * ((self.0 >> 8) as f32 / (1u32 << 24) as f32)
    }

    fn vec3(&mut self, half: Vec3) -> Vec3 {
        half * vec3(
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
            self.range(-1.0, 1.0),
        )
    }

    fn hull(&mut self) -> ConvexHull {
        let scale = vec3(
            self.range(0.2, 1.0),
            self.range(0.2, 1.0),
            self.range(0.2, 1.0),
        );
        let count = 6 + self.range(0.0, 15.0) as usize;
        loop {
            let points: Vec<Vec3> = (0..count).map(|_| self.vec3(scale)).collect();
            if let Ok(hull) = ConvexHull::new(&points) {
                return hull;
            }
        }
    }

    fn pose(&mut self, reach: f32) -> Transform {
        let position = self.vec3(Vec3::splat(reach));
        let q = self.vec3(Vec3::ONE);
        let rotation = Quat::from_xyzw(q.x, q.y, q.z, self.range(-1.0, 1.0)).normalize();
        Transform::new(position, rotation)
    }
}

type Pair = (ConvexHull, ConvexHull, Transform);

/// A routine that queries the next pair on each call: criterion's mean is then per query over
/// the set.
fn cycle<'a>(
    pairs: &'a [Pair],
    query: impl Fn(&MinkowskiDifference<ConvexHull, ConvexHull>) + 'a,
) -> impl FnMut() + 'a {
    let mut next = 0;
    move || {
        let (a, b, pose_b) = &pairs[next % pairs.len()];
        next += 1;
        query(&MinkowskiDifference::new(
            a,
            &Transform::IDENTITY,
            b,
            black_box(pose_b),
        ));
    }
}

fn random_hulls(c: &mut Criterion) {
    let mut rng = Lcg(7);
    let (mut apart, mut overlapping): (Vec<Pair>, Vec<Pair>) = (Vec::new(), Vec::new());
    while apart.len() < 256 || overlapping.len() < 256 {
        let (a, b, pose_b) = (rng.hull(), rng.hull(), rng.pose(1.2));
        let m = MinkowskiDifference::new(&a, &Transform::IDENTITY, &b, &pose_b);
        let list = match gjk(&m) {
            GjkResult::Separated { .. } => &mut apart,
            GjkResult::Overlapping { .. } => &mut overlapping,
        };
        if list.len() < 256 {
            list.push((a, b, pose_b));
        }
    }
    c.bench_function("random hulls: gjk distance (apart)", |bench| {
        let mut query = cycle(&apart, |m| {
            black_box(gjk(m));
        });
        bench.iter(&mut query)
    });
    c.bench_function("random hulls: gjk + epa (overlapping)", |bench| {
        let mut query = cycle(&overlapping, |m| {
            if let GjkResult::Overlapping { simplex } = gjk(m) {
                black_box(epa(m, &simplex));
            }
        });
        bench.iter(&mut query)
    });
    for (name, sampling) in SAMPLINGS {
        c.bench_function(
            &format!("random hulls: sampled penetration, {name}"),
            |bench| {
                let mut query = cycle(&overlapping, |m| {
                    black_box(sampled_penetration(m, sampling));
                });
                bench.iter(&mut query)
            },
        );
    }
}

criterion_group!(benches, barrels, random_hulls);
criterion_main!(benches);
