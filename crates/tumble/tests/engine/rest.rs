//! A box resting on a plane stays: no sinking, no jitter, no drift; on the CPU and with every
//! stage on the GPU.
use crate::common;
use common::*;
use tumble::math::Vec3;

fn box_resting_on_a_plane_stays(gpu: bool) {
    let mut world = world_with_ground(0.5, 0.0);
    let start = Vec3::new(0.3, 0.5, -0.2);
    let body = unit_box(&mut world, start);
    let _turn = on_gpu(&mut world, gpu);
    let start_rotation = world.pose(body).unwrap().rotation;
    for step in 0..600 {
        world.step();
        let pose = world.pose(body).unwrap();
        // No sinking beyond the penetration slop, no hopping.
        assert!(
            (pose.position.y - 0.5).abs() < 0.006,
            "step {step}: y = {}",
            pose.position.y
        );
    }
    let pose = world.pose(body).unwrap();
    let drift = (pose.position - start).length();
    assert!(drift < 1e-3, "drifted {drift} m");
    assert!(angle_between(pose.rotation, start_rotation) < 1e-3);
    let speed = world.linear_velocity(body).unwrap().length();
    assert!(speed < 1e-3, "still moving at {speed} m/s (jitter)");
    assert_eq!(
        world.stats().contacts,
        4,
        "a resting box touches with its 4 bottom corners"
    );
}

#[test]
fn box_resting_on_a_plane_stays_on_the_cpu() {
    box_resting_on_a_plane_stays(false);
}

#[test]
fn box_resting_on_a_plane_stays_on_the_gpu() {
    box_resting_on_a_plane_stays(true);
}

fn sphere_falls_and_settles_on_the_ground(gpu: bool) {
    let mut world = world_with_ground(0.5, 0.0);
    let ball = world
        .add_body(
            tumble::BodyDesc::dynamic(tumble::Shape::sphere(0.25))
                .position(Vec3::new(0.0, 3.0, 0.0)),
        )
        .unwrap();
    let _turn = on_gpu(&mut world, gpu);
    run(&mut world, 3.0);
    let y = world.pose(ball).unwrap().position.y;
    assert!((y - 0.25).abs() < 0.006, "ball rests at y = {y}");
    assert!(world.linear_velocity(ball).unwrap().length() < 1e-3);
}

#[test]
fn sphere_falls_and_settles_on_the_ground_on_the_cpu() {
    sphere_falls_and_settles_on_the_ground(false);
}

#[test]
fn sphere_falls_and_settles_on_the_ground_on_the_gpu() {
    sphere_falls_and_settles_on_the_ground(true);
}
