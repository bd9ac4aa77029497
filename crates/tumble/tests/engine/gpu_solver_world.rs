//! The step with the GPU solver (`solver=gpu`, the other stages on the CPU):
//! closed-form rest and friction, and a stack that follows the all-CPU run.

use crate::common;
use crate::gpu_common;

use common::*;
use tumble::math::{Quat, Vec3};
use tumble::{BodyDesc, BodyHandle, Shape, StepConfig, World};

/// Puts `world`'s solver on the shared GPU; the returned turn must be held while the world
/// steps (see `gpu_common::context`: tests take turns on the device).
#[must_use]
fn gpu_world(world: &mut World) -> gpu_common::Gpu {
    let turn = gpu_common::context();
    let devices = "solver=gpu".parse().unwrap();
    world.set_stage_devices(devices).expect("GPU solver");
    turn
}

/// A stack of five unit boxes on the ground after `steps` steps.
fn stack(gpu: bool, steps: usize) -> Vec<Vec3> {
    let mut world = world_with_ground(0.5, 0.0);
    let _turn = gpu.then(|| gpu_world(&mut world));
    let boxes: Vec<BodyHandle> = (0..5)
        .map(|level| unit_box(&mut world, Vec3::new(0.0, 0.5 + level as f32, 0.0)))
        .collect();
    for _ in 0..steps {
        world.step();
    }
    boxes
        .iter()
        .map(|&body| world.pose(body).unwrap().position)
        .collect()
}

#[test]
fn five_box_stack_follows_the_cpu_run_within_a_millimetre() {
    let (cpu, gpu) = (stack(false, 300), stack(true, 300));
    for (level, (c, g)) in cpu.iter().zip(&gpu).enumerate() {
        let distance = (*c - *g).length();
        assert!(
            distance < 1e-3,
            "box {level}: GPU {g}, CPU {c} ({distance} m apart)"
        );
        // And it stands: each box within 1 cm of where it started.
        let start = Vec3::new(0.0, 0.5 + level as f32, 0.0);
        assert!((*g - start).length() < 1e-2, "box {level} moved to {g}");
    }
}

#[test]
fn box_resting_on_a_plane_stays_with_the_gpu_solver() {
    let mut world = world_with_ground(0.5, 0.0);
    let _turn = gpu_world(&mut world);
    let start = Vec3::new(0.0, 0.5, 0.0);
    let body = unit_box(&mut world, start);
    run(&mut world, 2.0);
    let pose = world.pose(body).unwrap();
    assert!(
        (pose.position - start).length() < 5e-3,
        "moved to {}",
        pose.position
    );
    assert!(angle_between(pose.rotation, Quat::IDENTITY) < 1e-3);
}

/// Distance a box travels down a 20° incline of friction `friction` in `seconds`.
fn incline(friction: f32, seconds: f32) -> f32 {
    let tilt = Quat::from_rotation_z(20f32.to_radians());
    let mut world = World::new(StepConfig::default()).unwrap();
    let _turn = gpu_world(&mut world);
    world
        .add_body(
            BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))
                .rotation(tilt)
                .friction(friction),
        )
        .unwrap();
    let start = tilt * Vec3::Y * 0.5;
    let body = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                .position(start)
                .rotation(tilt)
                .friction(friction),
        )
        .unwrap();
    run(&mut world, seconds);
    (world.pose(body).unwrap().position - start).length()
}

#[test]
fn box_on_incline_sticks_with_high_friction_with_the_gpu_solver() {
    // tan 20° = 0.364 < 0.6: static friction holds.
    let travelled = incline(0.6, 3.0);
    assert!(travelled < 5e-3, "slid {travelled} m");
}

#[test]
fn box_on_incline_slides_at_the_closed_form_rate_with_the_gpu_solver() {
    let angle = 20f32.to_radians();
    let expected = G * (angle.sin() - 0.1 * angle.cos());
    let seconds = 2.0;
    let acceleration = 2.0 * incline(0.1, seconds) / (seconds * seconds);
    let error = (acceleration - expected).abs() / expected;
    assert!(
        error < 0.05,
        "a = {acceleration}, expected {expected} (error {:.1}%)",
        100.0 * error
    );
}
