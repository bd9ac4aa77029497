//! Picking: a body dragged by a point follows a moving target, is limited by the drag's
//! largest force, and falls when let go.
use crate::common;
use common::*;
use tumble::math::Vec3;
use tumble::{BodyDesc, Shape, StepConfig, World};

/// Where the dragged point of `body` is now.
fn dragged_point(world: &World, body: tumble::BodyHandle, local_anchor: Vec3) -> Vec3 {
    world.pose(body).unwrap().transform_point(local_anchor)
}

#[test]
fn a_dragged_box_follows_the_target() {
    let mut world = world_with_ground(0.5, 0.0);
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    // A corner of the box, lifted to 2 m, then carried around a circle at 1 m/s.
    let corner = Vec3::splat(0.5);
    let max_force = 50.0 * G;
    let lift = Vec3::new(0.0, 2.0, 0.0);
    for _ in 0..120 {
        world
            .set_drag_target(body, corner, lift, max_force)
            .unwrap();
        world.step();
    }
    let lifted_error = (dragged_point(&world, body, corner) - lift).length();

    let dt = world.config().dt;
    let mut worst_error = 0.0f32;
    let mut target = lift;
    for step in 0..240 {
        let angle = step as f32 * dt;
        target = lift + Vec3::new(angle.sin(), 0.0, 1.0 - angle.cos());
        world
            .set_drag_target(body, corner, target, max_force)
            .unwrap();
        world.step();
        worst_error = worst_error.max((dragged_point(&world, body, corner) - target).length());
    }
    println!(
        "drag: {:.1} mm from the lift target after 2 s, worst {:.1} mm behind a target moving \
         at 1 m/s",
        lifted_error * 1e3,
        worst_error * 1e3
    );
    assert!(
        lifted_error < 0.005,
        "the corner hangs {lifted_error} m from the target"
    );
    assert!(worst_error < 0.08, "the corner fell {worst_error} m behind");

    // Let go: it falls back to the ground.
    world.clear_drag();
    run(&mut world, 2.0);
    let height = world.pose(body).unwrap().position.y;
    assert!(height < 0.6, "the box did not fall: y = {height}");
    assert!((world.pose(body).unwrap().position - target).length() > 1.0);
}

#[test]
fn a_drag_of_ten_weights_lifts_the_box_within_half_a_second() {
    // A drag keeps pulling through the relax sweeps (Box2D's mouse joint does): were it rigid
    // there, the point would stop at the end of every sub-step and creep after its target
    // (0.91 m short after 0.5 s).
    let mut world = world_with_ground(0.5, 0.0);
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    let top = Vec3::new(0.0, 0.5, 0.0);
    let target = Vec3::new(0.0, 2.0, 0.0);
    let mut distances = Vec::new();
    for _ in 0..30 {
        world.set_drag_target(body, top, target, 10.0 * G).unwrap();
        world.step();
        distances.push((dragged_point(&world, body, top) - target).length());
    }
    let last = distances[distances.len() - 1];
    assert!(
        last < 0.01,
        "the point is {last} m from the target after 0.5 s"
    );
    // Overdamped: the point closes in on the target without passing it.
    assert!(
        distances.windows(2).all(|pair| pair[1] <= pair[0] + 1e-4),
        "the drag overshot: {distances:?}"
    );
}

#[test]
fn a_drag_weaker_than_the_weight_cannot_lift_the_box() {
    let mut world = world_with_ground(0.5, 0.0);
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    // Pulling the centre straight up with half the box's weight.
    for _ in 0..120 {
        world
            .set_drag_target(body, Vec3::ZERO, Vec3::new(0.0, 3.0, 0.0), 0.5 * G)
            .unwrap();
        world.step();
    }
    let height = world.pose(body).unwrap().position.y;
    println!("weak drag: the box's centre at {height:.4} m");
    assert!(
        (height - 0.5).abs() < 0.01,
        "a weak drag lifted the box to {height}"
    );
}

#[test]
fn the_drag_anchors_are_the_dragged_point_and_the_target() {
    let mut world = world_with_ground(0.5, 0.0);
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    assert_eq!(world.drag_anchors(), None);
    let corner = Vec3::splat(0.5);
    let target = Vec3::new(1.0, 2.0, 0.0);
    world
        .set_drag_target(body, corner, target, 10.0 * G)
        .unwrap();
    assert_eq!(
        world.drag_anchors(),
        Some((Vec3::new(0.5, 1.0, 0.5), target))
    );
    // The point moves with the body; the target stays.
    for _ in 0..10 {
        world.step();
    }
    let (point, pulled_to) = world.drag_anchors().unwrap();
    assert_eq!(point, dragged_point(&world, body, corner));
    assert_eq!(pulled_to, target);
    world.clear_drag();
    assert_eq!(world.drag_anchors(), None);
    // Removing the dragged body ends its drag.
    world
        .set_drag_target(body, corner, target, 10.0 * G)
        .unwrap();
    world.remove_body(body).unwrap();
    assert_eq!(world.drag_anchors(), None);
}

#[test]
fn bad_drags_are_errors() {
    let mut world = world_with_ground(0.5, 0.0);
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    assert!(
        world
            .set_drag_target(body, Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), 1.0)
            .is_err()
    );
    assert!(
        world
            .set_drag_target(body, Vec3::ZERO, Vec3::ZERO, -1.0)
            .is_err()
    );
    world.remove_body(body).unwrap();
    assert!(
        world
            .set_drag_target(body, Vec3::ZERO, Vec3::ZERO, 1.0)
            .is_err()
    );
}

#[test]
fn a_rejected_drag_leaves_a_sleeping_body_asleep() {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
    for _ in 0..600 {
        if world.is_sleeping(body).unwrap() {
            break;
        }
        world.step();
    }
    assert!(
        world.is_sleeping(body).unwrap(),
        "the resting box never slept"
    );
    assert!(
        world
            .set_drag_target(body, Vec3::ZERO, Vec3::ZERO, -1.0)
            .is_err()
    );
    assert!(
        world.is_sleeping(body).unwrap(),
        "a rejected drag woke the box"
    );
    world
        .set_drag_target(body, Vec3::ZERO, Vec3::ZERO, 1.0)
        .unwrap();
    assert!(
        !world.is_sleeping(body).unwrap(),
        "an accepted drag left the box asleep"
    );
}
