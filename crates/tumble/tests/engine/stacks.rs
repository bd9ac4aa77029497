//! Stacks stand: a tower of 10 boxes and a pyramid with a base of 10 rest for 10 s with less
//! than 1 cm of drift (a PGS solver with warm starting and 10 iterations must hold them).
use crate::common;
use common::*;
use tumble::BodyHandle;
use tumble::math::Vec3;

/// Largest distance any body moved from where it started (m).
fn max_drift(world: &tumble::World, bodies: &[(BodyHandle, Vec3)]) -> f32 {
    bodies
        .iter()
        .map(|&(body, start)| (world.pose(body).unwrap().position - start).length())
        .fold(0.0, f32::max)
}

#[test]
fn tower_of_ten_boxes_stands() {
    let mut world = world_with_ground(0.5, 0.0);
    let bodies: Vec<_> = (0..10)
        .map(|level| {
            let start = Vec3::new(0.0, 0.5 + level as f32, 0.0);
            (unit_box(&mut world, start), start)
        })
        .collect();
    run(&mut world, 10.0);
    let drift = max_drift(&world, &bodies);
    assert!(drift < 0.01, "tower drifted {drift} m");
    assert!(
        world.kinetic_energy() < 1e-4,
        "tower still moving: {} J",
        world.kinetic_energy()
    );
}

#[test]
fn pyramid_with_a_base_of_ten_stands() {
    let mut world = world_with_ground(0.5, 0.0);
    let mut bodies = Vec::new();
    for row in 0..10 {
        for i in 0..10 - row {
            // 1 m boxes, 5 cm apart so each rests on two below.
            let x = (i as f32 - (9 - row) as f32 * 0.5) * 1.05;
            let start = Vec3::new(x, 0.5 + row as f32, 0.0);
            bodies.push((unit_box(&mut world, start), start));
        }
    }
    assert_eq!(bodies.len(), 55);
    run(&mut world, 10.0);
    let drift = max_drift(&world, &bodies);
    assert!(drift < 0.01, "pyramid drifted {drift} m");
}
