//! Where a compound's child BVH starts to pay: nanoseconds per pair (`collide_compound`, a box
//! resting on one corner child) and per ray (`cast_ray`, onto that child) for compounds of 2 to
//! 256 box children on a cubic grid, through the child BVH and through the flat loop. The
//! crossing point sets `shape::compound::CHILD_BVH_THRESHOLD`.
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use tumble::collision::contact::collide_compound;
use tumble::collision::ray::{Ray, cast_ray};
use tumble::math::{Quat, Transform, Vec3, vec3};
use tumble::shape::{Compound, CompoundChild, Shape};

const COUNTS: [usize; 7] = [2, 4, 8, 16, 32, 64, 256];

/// `count` boxes of half extent 0.2 m on a 0.5 m grid, filled x first, then z, then y.
fn grid(count: usize) -> Compound {
    let side = (count as f32).cbrt().ceil() as usize;
    let children = (0..count)
        .map(|i| CompoundChild {
            shape: Shape::cuboid(Vec3::splat(0.2)),
            pose: Transform::from_position(
                0.5 * vec3(
                    (i % side) as f32,
                    (i / (side * side)) as f32,
                    (i / side % side) as f32,
                ),
            ),
        })
        .collect();
    Compound::new(children).unwrap()
}

/// The compound with and without its tree, its pose (turned a little) and the world centre of
/// child 0, a bottom corner of the grid.
fn setups(count: usize) -> ([(&'static str, Shape); 2], Transform, Vec3) {
    let compound = grid(count);
    let pose = Transform::new(Vec3::ZERO, Quat::from_rotation_y(0.1));
    let corner = pose.transform_point(compound.children()[0].pose.position);
    let shapes = [("bvh", true), ("flat", false)].map(|(name, bvh)| {
        (
            name,
            Shape::Compound(Arc::new(compound.clone().with_child_bvh(bvh))),
        )
    });
    (shapes, pose, corner)
}

fn compounds(c: &mut Criterion) {
    let mut pairs = c.benchmark_group("compound-box pair");
    for count in COUNTS {
        let (shapes, pose, corner) = setups(count);
        // Under child 0, its top face 5 cm into the child's bottom face.
        let box_shape = Shape::cuboid(vec3(0.3, 0.25, 0.3));
        let resting = Transform::from_position(corner + vec3(0.0, -0.4, 0.0));
        for (name, shape) in &shapes {
            let mut found = Vec::new();
            pairs.bench_with_input(BenchmarkId::new(*name, count), shape, |bench, shape| {
                bench.iter(|| {
                    collide_compound(
                        shape,
                        &pose,
                        &box_shape,
                        black_box(&resting),
                        0.02,
                        &mut found,
                    );
                    black_box(found.len())
                })
            });
        }
    }
    pairs.finish();
    let mut rays = c.benchmark_group("compound ray");
    for count in COUNTS {
        let (shapes, pose, corner) = setups(count);
        // Up from 3 m below child 0: it hits that child, the column above is behind it.
        let ray = Ray::new(corner - vec3(0.0, 3.0, 0.0), Vec3::Y, f32::INFINITY).unwrap();
        for (name, shape) in &shapes {
            rays.bench_with_input(BenchmarkId::new(*name, count), shape, |bench, shape| {
                bench.iter(|| black_box(cast_ray(shape, &pose, black_box(&ray))))
            });
        }
    }
    rays.finish();
}

criterion_group!(benches, compounds);
criterion_main!(benches);
