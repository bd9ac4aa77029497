//! Stacks stand: a tower of 10 boxes, a pyramid with a base of 10 and the stacked-boxes scene
//! rest for 10 s with less than 1 cm of drift, on the CPU and with every stage on the GPU.
use crate::common;
use common::*;
use tumble::math::Vec3;
use tumble::scene::builtin;
use tumble::{BodyHandle, World};

/// Largest distance any body moved from where it started (m).
fn max_drift(world: &tumble::World, bodies: &[(BodyHandle, Vec3)]) -> f32 {
    bodies
        .iter()
        .map(|&(body, start)| (world.pose(body).unwrap().position - start).length())
        .fold(0.0, f32::max)
}

/// Runs `world` for 10 s, with every stage on the GPU when `gpu`.
fn run_ten_seconds(world: &mut World, gpu: bool) {
    let _turn = on_gpu(world, gpu);
    run(world, 10.0);
}

fn tower_of_ten_boxes_stands(gpu: bool) {
    let mut world = world_with_ground(0.5, 0.0);
    let bodies: Vec<_> = (0..10)
        .map(|level| {
            let start = Vec3::new(0.0, 0.5 + level as f32, 0.0);
            (unit_box(&mut world, start), start)
        })
        .collect();
    run_ten_seconds(&mut world, gpu);
    let drift = max_drift(&world, &bodies);
    assert!(drift < 0.01, "tower drifted {drift} m (GPU: {gpu})");
    assert!(
        world.kinetic_energy() < 1e-4,
        "tower still moving: {} J (GPU: {gpu})",
        world.kinetic_energy()
    );
}

#[test]
fn tower_of_ten_boxes_stands_on_the_cpu() {
    tower_of_ten_boxes_stands(false);
}

#[test]
fn tower_of_ten_boxes_stands_on_the_gpu() {
    tower_of_ten_boxes_stands(true);
}

fn pyramid_with_a_base_of_ten_stands(gpu: bool) {
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
    run_ten_seconds(&mut world, gpu);
    let drift = max_drift(&world, &bodies);
    assert!(drift < 0.01, "pyramid drifted {drift} m (GPU: {gpu})");
}

#[test]
fn pyramid_with_a_base_of_ten_stands_on_the_cpu() {
    pyramid_with_a_base_of_ten_stands(false);
}

#[test]
fn pyramid_with_a_base_of_ten_stands_on_the_gpu() {
    pyramid_with_a_base_of_ten_stands(true);
}

/// The stacked-boxes scene (a pyramid, a brick wall and a tower; a tenth of the talk's 1000
/// boxes), as `tumble run stacked-boxes` builds it: sleeping on, as a user runs it.
fn stacked_boxes_stand(gpu: bool) {
    let mut world = builtin("stacked-boxes", 0.1).unwrap().build().unwrap();
    let bodies: Vec<_> = world
        .bodies()
        .map(|body| (body, world.pose(body).unwrap().position))
        .collect();
    assert!(bodies.len() > 90, "{} bodies", bodies.len());
    run_ten_seconds(&mut world, gpu);
    let drift = max_drift(&world, &bodies);
    assert!(drift < 0.01, "stacked-boxes drifted {drift} m (GPU: {gpu})");
}

#[test]
fn stacked_boxes_stand_on_the_cpu() {
    stacked_boxes_stand(false);
}

#[test]
fn stacked_boxes_stand_on_the_gpu() {
    stacked_boxes_stand(true);
}
