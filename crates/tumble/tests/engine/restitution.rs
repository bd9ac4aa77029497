//! Restitution against closed forms: a ball rebounds to e² of its drop height; two equal balls
//! in a head-on elastic collision exchange velocities with momentum conserved; on the CPU and
//! with every stage on the GPU.
use crate::common;
use common::*;
use tumble::math::Vec3;
use tumble::{BodyDesc, Shape, StepConfig, World};

fn ball_rebounds_to_e_squared_of_its_height(gpu: bool) {
    let e: f32 = 0.8;
    let radius = 0.1;
    let mut world = world_with_ground(0.5, e);
    let ball = world
        .add_body(
            BodyDesc::dynamic(Shape::sphere(radius))
                .position(Vec3::new(0.0, 1.0 + radius, 0.0))
                .restitution(e),
        )
        .unwrap();
    let _turn = on_gpu(&mut world, gpu);
    // Fall (≈0.45 s), bounce, and track the highest point of the first rebound.
    let mut bounced = false;
    let mut apex: f32 = 0.0;
    for _ in 0..90 {
        world.step();
        let velocity = world.linear_velocity(ball).unwrap().y;
        let height = world.pose(ball).unwrap().position.y - radius;
        if velocity > 0.0 {
            bounced = true;
        }
        if bounced {
            apex = apex.max(height);
        }
    }
    assert!(bounced, "the ball never bounced");
    let expected = e * e;
    assert!(
        (apex - expected).abs() / expected < 0.1,
        "rebound to {apex} m, expected {expected} m"
    );
}

#[test]
fn ball_rebounds_to_e_squared_of_its_height_on_the_cpu() {
    ball_rebounds_to_e_squared_of_its_height(false);
}

#[test]
fn ball_rebounds_to_e_squared_of_its_height_on_the_gpu() {
    ball_rebounds_to_e_squared_of_its_height(true);
}

fn equal_balls_exchange_velocities_and_keep_momentum(gpu: bool) {
    let config = StepConfig {
        gravity: Vec3::ZERO,
        ..StepConfig::default()
    };
    let mut world = World::new(config).unwrap();
    let ball = |x: f32, v: f32| {
        BodyDesc::dynamic(Shape::sphere(0.5))
            .position(Vec3::new(x, 0.0, 0.0))
            .linear_velocity(Vec3::new(v, 0.0, 0.0))
            .restitution(1.0)
    };
    let a = world.add_body(ball(-2.0, 3.0)).unwrap();
    let b = world.add_body(ball(2.0, 0.0)).unwrap();
    let _turn = on_gpu(&mut world, gpu);
    let momentum =
        |world: &World| world.linear_velocity(a).unwrap() + world.linear_velocity(b).unwrap();
    let before = momentum(&world);
    run(&mut world, 2.0);
    let (va, vb) = (
        world.linear_velocity(a).unwrap(),
        world.linear_velocity(b).unwrap(),
    );
    assert!(
        (momentum(&world) - before).length() < 1e-5,
        "momentum {} → {}",
        before,
        momentum(&world)
    );
    assert!(va.length() < 1e-4, "a keeps {va}");
    assert!(
        (vb - Vec3::new(3.0, 0.0, 0.0)).length() < 1e-4,
        "b moves at {vb}"
    );
}

#[test]
fn equal_balls_exchange_velocities_and_keep_momentum_on_the_cpu() {
    equal_balls_exchange_velocities_and_keep_momentum(false);
}

#[test]
fn equal_balls_exchange_velocities_and_keep_momentum_on_the_gpu() {
    equal_balls_exchange_velocities_and_keep_momentum(true);
}
