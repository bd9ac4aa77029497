//! Nanoseconds per query of the convex-pair algorithms on two barrels (40-point hulls, the
//! `convex-hulls` scene's shape): GJK distance when apart, EPA and the sampled penetration
//! depth (42 and 162 directions) when overlapping.
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use tumble::collision::epa::epa;
use tumble::collision::gjk::{GjkResult, MinkowskiDifference, gjk};
use tumble::collision::penetration::{Sampling, sampled_penetration};
use tumble::math::{Quat, Transform, vec3};
use tumble::scene::barrel_points;
use tumble::shape::ConvexHull;

fn queries(c: &mut Criterion) {
    let barrel = ConvexHull::new(&barrel_points()).unwrap();
    let pose_a = Transform::IDENTITY;
    let tilted = Quat::from_euler(glam::EulerRot::XYZ, 0.4, 0.2, 0.9);
    let apart = Transform::new(vec3(0.4, 1.3, 0.2), tilted);
    let overlapping = Transform::new(vec3(0.3, 0.9, 0.1), tilted);

    c.bench_function("gjk distance (barrels apart)", |bench| {
        bench.iter(|| {
            let m = MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&apart));
            black_box(gjk(&m))
        })
    });
    c.bench_function("gjk + epa (barrels overlapping)", |bench| {
        bench.iter(|| {
            let m = MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&overlapping));
            match gjk(&m) {
                GjkResult::Overlapping { simplex } => black_box(epa(&m, &simplex)),
                GjkResult::Separated { .. } => unreachable!("the poses overlap"),
            }
        })
    });
    for (name, sampling) in [
        ("sampled penetration, 42 directions", Sampling::Directions42),
        (
            "sampled penetration, 162 directions",
            Sampling::Directions162,
        ),
    ] {
        c.bench_function(name, |bench| {
            bench.iter(|| {
                let m =
                    MinkowskiDifference::new(&barrel, &pose_a, &barrel, black_box(&overlapping));
                black_box(sampled_penetration(&m, sampling))
            })
        });
    }
}

criterion_group!(benches, queries);
criterion_main!(benches);
