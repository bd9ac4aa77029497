//! Joints solved on the GPU (issue 8): whole steps with the solver on the GPU, where joints
//! and the drag are solved in the same batches as the contacts instead of falling back to the
//! CPU solver.

mod gpu_common;

use tumble::math::Vec3;
use tumble::pipeline::devices::{Executor, Stage, StageDevices};
use tumble::scene::builtin;
use tumble::{BodyDesc, BodyHandle, JointDesc, JointKind, Shape, StepConfig, World};

fn solver_on_the_gpu(world: &mut World) {
    let mut devices = StageDevices::default();
    devices.set(Stage::Solver, Executor::Gpu);
    world.set_stage_devices(devices).unwrap();
}

/// The `ragdolls` scene at the smallest scale (6 ragdolls of 11 capsules, hinges and
/// cone-twists), the solver on the GPU or not.
fn ragdolls(gpu: bool) -> World {
    let mut world = builtin("ragdolls", 0.05).unwrap().build().unwrap();
    if gpu {
        solver_on_the_gpu(&mut world);
    }
    world
}

fn positions(world: &World) -> Vec<Vec3> {
    let bodies: Vec<BodyHandle> = world.bodies().collect();
    bodies
        .iter()
        .map(|&body| world.pose(body).unwrap().position)
        .collect()
}

/// The ragdolls fall, hit the plane and pile up: a pile amplifies any rounding difference
/// until the two worlds part (contacts come and go), so the GPU world is held to the
/// yardstick of the tests/gpu_solver.rs parity tests, the CPU's own response to one ulp of
/// input noise: at every step, the GPU world lies no further from the CPU world than eight
/// times as far as a CPU world whose gravity is one ulp stronger, or within 1e-5 m.
#[test]
fn ragdolls_with_the_solver_on_the_gpu_follow_the_cpu() {
    let _turn = gpu_common::context();
    let mut cpu = ragdolls(false);
    let mut gpu = ragdolls(true);
    let mut nudged = ragdolls(false);
    let config = *nudged.config();
    nudged
        .set_config(StepConfig {
            gravity: config
                .gravity
                .map(|g| if g < 0.0 { g.next_down() } else { g }),
            ..config
        })
        .unwrap();
    let distance = |a: &World, b: &World| {
        positions(a)
            .iter()
            .zip(positions(b))
            .map(|(p, q)| p.distance(q))
            .fold(0.0, f32::max)
    };
    // Two seconds: the fall, the first hits (where the worlds part, 1e-4 m at step 40) and
    // the pile.
    for step in 0..120 {
        cpu.step();
        gpu.try_step().unwrap();
        nudged.step();
        let (off, noise) = (distance(&cpu, &gpu), distance(&cpu, &nudged));
        assert!(
            off <= (8.0 * noise).max(1e-5),
            "step {step}: the GPU world is {off} m from the CPU's, a CPU world with gravity \
             one ulp stronger {noise} m"
        );
    }
    assert!(gpu.stats().joints > 0, "the ragdolls' joints are solved");
    // The GPU solved them: the solver's profile has no `cpu` line (the fallback's).
    let report = gpu.profiler().report();
    let solver = report
        .root
        .children
        .iter()
        .find(|line| line.name == "solver")
        .expect("a solver line");
    let lines: Vec<&str> = solver.children.iter().map(|line| line.name).collect();
    assert!(
        !lines.contains(&"cpu") && lines.contains(&"kernels"),
        "solver lines {lines:?}"
    );
}

/// Same input, same device: bitwise the same ragdolls after 60 steps.
#[test]
fn two_runs_with_joints_on_the_gpu_are_bitwise_the_same() {
    let _turn = gpu_common::context();
    let (mut first, mut second) = (ragdolls(true), ragdolls(true));
    for _ in 0..60 {
        first.try_step().unwrap();
        second.try_step().unwrap();
    }
    let bodies: Vec<BodyHandle> = first.bodies().collect();
    for body in bodies {
        let (a, b) = (first.pose(body).unwrap(), second.pose(body).unwrap());
        assert_eq!(
            (
                a.position.to_array().map(f32::to_bits),
                a.rotation.to_array().map(f32::to_bits)
            ),
            (
                b.position.to_array().map(f32::to_bits),
                b.rotation.to_array().map(f32::to_bits)
            ),
            "{body:?}"
        );
    }
}

/// A bob on a 1 m rod (a point joint to a static anchor) swings from the horizontal for 5 s
/// with the solver on the GPU: the joint holds the rod's length.
#[test]
fn a_pendulum_on_the_gpu_keeps_its_length() {
    let _turn = gpu_common::context();
    let mut world = World::new(StepConfig {
        sleeping: false,
        ..StepConfig::default()
    })
    .unwrap();
    let pivot = Vec3::new(0.0, 3.0, 0.0);
    let anchor = world
        .add_body(BodyDesc::fixed(Shape::sphere(0.05)).position(pivot))
        .unwrap();
    let bob = world
        .add_body(BodyDesc::dynamic(Shape::sphere(0.1)).position(pivot + Vec3::X))
        .unwrap();
    world
        .add_joint(JointDesc::new(JointKind::Point, anchor, bob, pivot))
        .unwrap();
    solver_on_the_gpu(&mut world);
    let mut worst = 0.0f32;
    let mut lowest = f32::INFINITY;
    for _ in 0..300 {
        world.try_step().unwrap();
        let position = world.pose(bob).unwrap().position;
        worst = worst.max((position.distance(pivot) - 1.0).abs());
        lowest = lowest.min(position.y);
    }
    assert!(
        lowest < 2.01,
        "the bob swung through the bottom: lowest {lowest} m"
    );
    // The joint is soft (joint_hertz): it stretches while it carries the swing's pull, by
    // 0.4 mm at most here (measured).
    assert!(worst < 1e-3, "the rod changed length by {worst} m");
}
