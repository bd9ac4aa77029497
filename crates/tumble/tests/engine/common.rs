//! Helpers shared by the scenario tests.
#![allow(dead_code)]

use crate::gpu_common;
use tumble::math::{Quat, Vec3};
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::{BodyDesc, BodyHandle, Shape, StepConfig, World};

pub const G: f32 = 9.81;

/// Every stage of `world` on the GPU when `gpu` (as `--device gpu`): the device's turn, which
/// the caller holds while the world steps (see `gpu_common::context`).
#[must_use]
pub fn on_gpu(world: &mut World, gpu: bool) -> Option<gpu_common::Gpu> {
    gpu.then(|| {
        let turn = gpu_common::context();
        world
            .set_stage_devices(StageDevices::all(Executor::Gpu))
            .expect("every stage on the GPU");
        turn
    })
}

/// The default settings without sleeping: the scenario tests measure the solver, and a
/// sleeping stack would hide a slow sag.
pub fn awake_config() -> StepConfig {
    StepConfig {
        sleeping: false,
        ..StepConfig::default()
    }
}

/// A world with a ground plane y <= 0 of the given friction and restitution (no sleeping).
pub fn world_with_ground(friction: f32, restitution: f32) -> World {
    let mut world = World::new(awake_config()).unwrap();
    world
        .add_body(
            BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))
                .friction(friction)
                .restitution(restitution),
        )
        .unwrap();
    world
}

pub fn unit_box(world: &mut World, position: Vec3) -> BodyHandle {
    world
        .add_body(BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position))
        .unwrap()
}

pub fn run(world: &mut World, seconds: f32) {
    let steps = (seconds / world.config().dt).round() as usize;
    for _ in 0..steps {
        world.step();
    }
}

/// Angle between two rotations (rad).
pub fn angle_between(a: Quat, b: Quat) -> f32 {
    (a.inverse() * b)
        .to_axis_angle()
        .1
        .min(std::f32::consts::TAU - (a.inverse() * b).to_axis_angle().1)
}
