//! A box resting on a plane stays: no sinking, no jitter, no drift.
use crate::common;
use common::*;
use tumble::math::Vec3;

#[test]
fn box_resting_on_a_plane_stays() {
    let mut world = world_with_ground(0.5, 0.0);
    let start = Vec3::new(0.3, 0.5, -0.2);
    let body = unit_box(&mut world, start);
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
fn sphere_falls_and_settles_on_the_ground() {
    let mut world = world_with_ground(0.5, 0.0);
    let ball = world
        .add_body(
            tumble::BodyDesc::dynamic(tumble::Shape::sphere(0.25))
                .position(Vec3::new(0.0, 3.0, 0.0)),
        )
        .unwrap();
    run(&mut world, 3.0);
    let y = world.pose(ball).unwrap().position.y;
    assert!((y - 0.25).abs() < 0.006, "ball rests at y = {y}");
    assert!(world.linear_velocity(ball).unwrap().length() < 1e-3);
}
