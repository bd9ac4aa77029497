//! Stage 8 on the GPU (`stages/integrate/finalize.wgsl`): parity with the CPU's
//! `finalize_bodies` on random motions, and worlds that integrate on the device following the
//! CPU's integration.

use crate::gpu_common;

use gpu_common::{Random, SIZES, context};
use tumble::dynamics::body::{BodyPose, BodyVelocity};
use tumble::gpu::GpuVec;
use tumble::math::{Quat, Vec3};
use tumble::pipeline::devices::{Executor, Stage, StageDevices};
use tumble::scene::builtin;
use tumble::stages::integrate::finalize_bodies;
use tumble::stages::integrate::gpu::GpuFinalizeBodies;
use tumble::stages::solver::SolverBody;

fn uniform(random: &mut Random, low: f32, high: f32) -> f32 {
    low + (high - low) * (random.next_u32() as f32 / u32::MAX as f32)
}

fn vector(random: &mut Random, extent: f32) -> Vec3 {
    Vec3::new(
        uniform(random, -extent, extent),
        uniform(random, -extent, extent),
        uniform(random, -extent, extent),
    )
}

fn rotation(random: &mut Random, angle: f32) -> Quat {
    let axis = vector(random, 1.0).try_normalize().unwrap_or(Vec3::Y);
    Quat::from_axis_angle(axis, uniform(random, -angle, angle))
}

/// `count` random bodies: poses, velocities, and the step's motion, one in four static.
fn random_bodies(seed: u32, count: usize) -> (Vec<BodyPose>, Vec<BodyVelocity>, Vec<SolverBody>) {
    let mut random = Random::new(seed.into());
    let mut poses = Vec::new();
    let mut velocities = Vec::new();
    let mut motion = Vec::new();
    for i in 0..count {
        poses.push(BodyPose::new(
            vector(&mut random, 100.0),
            rotation(&mut random, 3.1),
        ));
        velocities.push(BodyVelocity::new(
            vector(&mut random, 5.0),
            vector(&mut random, 5.0),
        ));
        motion.push(SolverBody {
            linear_velocity: vector(&mut random, 5.0),
            inverse_mass: if i % 4 == 3 {
                0.0
            } else {
                uniform(&mut random, 0.1, 2.0)
            },
            angular_velocity: vector(&mut random, 5.0),
            delta_position: vector(&mut random, 0.1),
            delta_rotation: rotation(&mut random, 0.2),
            ..SolverBody::STATIC
        });
    }
    (poses, velocities, motion)
}

/// The GPU's finalization of random motions equals the CPU's: positions and velocities
/// bitwise (one add, copies), rotations to a few units in the last place (the quaternion
/// product and the normalization may fuse on a GPU), static bodies untouched.
#[test]
fn gpu_integration_matches_the_cpu_on_random_bodies() {
    let context = context();
    let mut finalize = GpuFinalizeBodies::new(&context).unwrap();
    for (seed, count) in SIZES.into_iter().enumerate() {
        let (poses, velocities, motion) = random_bodies(seed as u32, count);
        let (mut cpu_poses, mut cpu_velocities) = (poses.clone(), velocities.clone());
        finalize_bodies(&motion, &mut cpu_poses, &mut cpu_velocities);

        let device_motion = GpuVec::from_slice(&context, "motion", &motion).unwrap();
        let mut device_poses = GpuVec::from_slice(&context, "poses", &poses).unwrap();
        let mut device_velocities =
            GpuVec::from_slice(&context, "velocities", &velocities).unwrap();
        let buffers = (&device_motion, &device_poses, &device_velocities);
        context.submit_pass("finalize", |pass| finalize.encode(&context, pass, buffers));
        let gpu_poses = device_poses.download(&context).unwrap();
        let gpu_velocities = device_velocities.download(&context).unwrap();
        assert_eq!(gpu_poses.len(), count);
        for i in 0..count {
            let (gpu, cpu) = (gpu_poses[i], cpu_poses[i]);
            assert_eq!(gpu.position, cpu.position, "body {i} of {count}: position");
            assert!(
                gpu_velocities[i] == cpu_velocities[i],
                "body {i} of {count}: velocity"
            );
            if motion[i].inverse_mass == 0.0 {
                assert!(gpu == poses[i], "static body {i} of {count} moved");
            }
            let error = (gpu.rotation - cpu.rotation).length();
            assert!(
                error < 4.0 * f32::EPSILON,
                "body {i} of {count}: rotation off by {error}"
            );
            assert!((gpu.rotation.length() - 1.0).abs() < 4.0 * f32::EPSILON);
        }
    }
}

/// The finalization moves nothing where its word is 0 (a step whose guess was wrong wrote it),
/// and moves the bodies again once the word is set back.
#[test]
fn the_integration_moves_nothing_where_the_step_did_not_hold() {
    let context = context();
    let mut finalize = GpuFinalizeBodies::new(&context).unwrap();
    let (poses, velocities, motion) = random_bodies(7, 300);
    let device_motion = GpuVec::from_slice(&context, "motion", &motion).unwrap();
    let device_poses = GpuVec::from_slice(&context, "poses", &poses).unwrap();
    let device_velocities = GpuVec::from_slice(&context, "velocities", &velocities).unwrap();
    let zero = GpuVec::from_slice(&context, "zero", &[0u32]).unwrap();
    let buffers = (&device_motion, &device_poses, &device_velocities);
    let run = |finalize: &mut GpuFinalizeBodies, held: bool| {
        let mut encoder = context.device.create_command_encoder(&Default::default());
        if !held {
            // What the check of a step whose guess was wrong writes before the kernel.
            let word = finalize.held().buffer();
            encoder.copy_buffer_to_buffer(zero.buffer(), 0, word, 0, 4);
        }
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            finalize.encode(&context, &mut pass, buffers);
        }
        context.queue.submit([encoder.finish()]);
    };
    run(&mut finalize, false);
    assert!(device_poses.read(&context).unwrap() == poses, "poses moved");
    assert!(device_velocities.read(&context).unwrap() == velocities);
    finalize.reset_held(&context).unwrap();
    run(&mut finalize, true);
    let moved = device_poses.read(&context).unwrap();
    let dynamic = (0..motion.len()).filter(|&i| motion[i].inverse_mass > 0.0);
    let moved_count = dynamic.filter(|&i| moved[i] != poses[i]).count();
    assert!(moved_count > 100, "only {moved_count} bodies moved");
}

/// A pile of boxes integrated on the device follows the one integrated on the host, every
/// other stage on the GPU in both: the stages' inputs differ only by the integration's
/// rounding.
#[test]
fn a_pile_integrated_on_the_gpu_follows_the_host_integration() {
    let _turn = context();
    let run = |integrate: Executor| {
        let mut world = builtin("stacked-boxes", 0.1).unwrap().build().unwrap();
        let mut devices = StageDevices::all(Executor::Gpu);
        devices.set(Stage::Integrate, integrate);
        world.set_stage_devices(devices).unwrap();
        for _ in 0..60 {
            world.try_step().unwrap();
        }
        world
            .bodies()
            .map(|body| world.pose(body).unwrap().position)
            .collect::<Vec<_>>()
    };
    let on_gpu = run(Executor::Gpu);
    let on_cpu = run(Executor::Cpu);
    let worst = on_gpu
        .iter()
        .zip(&on_cpu)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(on_gpu.len() > 10);
    assert!(worst < 1e-4, "the piles are {worst} m apart");
}

/// A step whose GPU integration fails (here its motion is past the device's binding limit)
/// leaves the world as it was, and fails the same way again: the integration runs before the
/// solved impulses are stored. Stepped on the host afterwards, the world is bitwise the one
/// that never failed.
#[test]
fn a_failed_gpu_integration_leaves_the_world_as_it_was() {
    let _turn = context();
    let small = tumble::gpu::GpuContext::with_limits(|limits| {
        limits.max_storage_buffer_binding_size = 64 << 10;
    })
    .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
    // 1100 balls dropping onto a plane, at different heights: 35 KB of poses fit a binding,
    // 70 KB of the solver's motion do not. A step on the host first, so contacts carry
    // impulses.
    let build = || {
        let mut world = tumble::World::new(tumble::StepConfig::default()).unwrap();
        world
            .add_body(tumble::BodyDesc::fixed(tumble::Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        let bodies: Vec<_> = (0..1100)
            .map(|i| {
                let height = 0.5 + 0.002 * (i % 7) as f32;
                let position = Vec3::new(2.0 * (i % 40) as f32, height, 2.0 * (i / 40) as f32);
                let desc = tumble::BodyDesc::dynamic(tumble::Shape::sphere(0.5))
                    .position(position)
                    .linear_velocity(Vec3::new(0.1, -0.5, 0.0));
                world.add_body(desc).unwrap()
            })
            .collect();
        world.try_step().unwrap();
        (world, bodies)
    };
    let state = |world: &tumble::World, bodies: &[tumble::BodyHandle]| {
        let bodies: Vec<(Vec3, Quat, Vec3)> = bodies
            .iter()
            .map(|&body| {
                let pose = world.pose(body).unwrap();
                let velocity = world.linear_velocity(body).unwrap();
                (pose.position, pose.rotation, velocity)
            })
            .collect();
        let impulses: Vec<[f32; 3]> = world
            .contacts()
            .flat_map(|(_, _, contact)| {
                let impulses = contact.impulses;
                impulses.map(|i| [i.normal, i.tangent[0], i.tangent[1]])
            })
            .collect();
        (bodies, impulses)
    };
    let (mut world, bodies) = build();
    world.set_gpu_context(small).unwrap();
    let mut devices = StageDevices::all(Executor::Cpu);
    devices.set(Stage::Integrate, Executor::Gpu);
    world.set_stage_devices(devices).unwrap();
    let before = state(&world, &bodies);
    assert!(before.1.iter().filter(|impulse| impulse[0] > 0.0).count() >= 100);
    let error = world.try_step().unwrap_err();
    assert!(
        matches!(
            error,
            tumble::gpu::GpuError::BufferTooLarge {
                what: "solver bodies",
                ..
            }
        ),
        "{error}"
    );
    assert!(
        state(&world, &bodies) == before,
        "the failed step changed the world"
    );
    assert!(world.try_step().is_err());
    assert!(
        state(&world, &bodies) == before,
        "the failed step changed the world"
    );

    world
        .set_stage_devices(StageDevices::all(Executor::Cpu))
        .unwrap();
    world.try_step().unwrap();
    let (mut never_failed, _) = build();
    never_failed.try_step().unwrap();
    let after = state(&world, &bodies);
    assert!(
        after.0 != before.0 && after.1 != before.1,
        "the world did not move"
    );
    assert!(
        after == state(&never_failed, &bodies),
        "the failures left a trace"
    );
}
