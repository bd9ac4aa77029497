//! Joints solved on the GPU (issue 8): whole steps with the solver on the GPU, where joints
//! and the drag are solved in the same batches as the contacts instead of falling back to the
//! CPU solver; and worlds whose whole step runs on the GPU, with a drag and breakable joints.

use crate::common;
use crate::gpu_common;

use common::{G, unit_box, world_with_ground};
use tumble::math::Vec3;
use tumble::pipeline::devices::{Executor, Stage, StageDevices};
use tumble::scene::builtin;
use tumble::{BodyDesc, BodyHandle, JointDesc, JointHandle, JointKind, Shape, StepConfig, World};

fn solver_on_the_gpu(world: &mut World) {
    let mut devices = StageDevices::default();
    devices.set(Stage::Solver, Executor::Gpu);
    world.set_stage_devices(devices).unwrap();
}

/// Every stage of the step on the GPU.
fn all_on_the_gpu(world: &mut World) {
    world
        .set_stage_devices(StageDevices::all(Executor::Gpu))
        .unwrap();
}

/// Makes `world`'s gravity one ulp stronger: the yardstick of the parity
/// tests below (see `ragdolls_with_the_solver_on_the_gpu_follow_the_cpu`).
fn nudge_gravity(world: &mut World) {
    let config = *world.config();
    world
        .set_config(StepConfig {
            gravity: config
                .gravity
                .map(|g| if g < 0.0 { g.next_down() } else { g }),
            ..config
        })
        .unwrap();
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
/// yardstick of the tests/engine/gpu_solver.rs parity tests, the CPU's own response to one ulp of
/// input noise: at every step, the GPU world lies no further from the CPU world than eight
/// times as far as a CPU world whose gravity is one ulp stronger, or within 1e-5 m.
#[test]
fn ragdolls_with_the_solver_on_the_gpu_follow_the_cpu() {
    let turn = gpu_common::context();
    // The kernels' line below needs the passes timed; the shared context keeps whatever the
    // test before this one left (this test failed when run alone).
    turn.set_gpu_timing(true);
    let mut cpu = ragdolls(false);
    let mut gpu = ragdolls(true);
    let mut nudged = ragdolls(false);
    nudge_gravity(&mut nudged);
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
        !lines.contains(&"cpu") && (lines.contains(&"kernels") || !turn.has_timestamps()),
        "solver lines {lines:?}"
    );
}

/// Same input, same device: bitwise the same ragdolls after 60 steps, with the solver or the
/// whole step on the GPU (where the contact rows stay on the device beside the joint rows).
#[test]
fn two_runs_with_joints_on_the_gpu_are_bitwise_the_same() {
    let _turn = gpu_common::context();
    for put_on_the_gpu in [solver_on_the_gpu as fn(&mut World), all_on_the_gpu] {
        let mut runs = [ragdolls(false), ragdolls(false)];
        for world in &mut runs {
            put_on_the_gpu(world);
            for _ in 0..60 {
                world.try_step().unwrap();
            }
        }
        let [first, second] = &runs;
        for body in first.bodies() {
            assert_eq!(body_bits(first, body), body_bits(second, body), "{body:?}");
        }
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

/// Where `world`'s dragged point is, for the drag test: the corner (0.5, 0.5, 0.5) of `body`.
fn corner(world: &World, body: BodyHandle) -> Vec3 {
    world.pose(body).unwrap().transform_point(Vec3::splat(0.5))
}

/// The drag of tests/engine/drag.rs (a box's corner lifted off the ground to 2 m, then carried round
/// a circle at 1 m/s) in a world whose whole step runs on the GPU: the box follows the target
/// as on the CPU, and the GPU world keeps to the CPU world by the yardstick of the ragdoll
/// test above, the CPU's own response to one ulp of input noise, at every step and over the
/// run. The drag is a critically damped spring: it damps differences instead of amplifying
/// them, so both worlds stay within rounding of the CPU's (measured: 1.1e-6 m for the GPU,
/// about ten ulps of the corner's coordinates; 3.9e-7 m for the nudged world, which for the
/// first 50 steps is bitwise the CPU's), and at each step the 1e-5 m floor governs; over the
/// run, the eightfold bound does (2.9 times, measured).
#[test]
fn a_drag_on_the_gpu_world_follows_the_target_as_on_the_cpu() {
    let _turn = gpu_common::context();
    let world = |gpu: bool| {
        let mut world = world_with_ground(0.5, 0.0);
        let body = unit_box(&mut world, Vec3::new(0.0, 0.5, 0.0));
        if gpu {
            all_on_the_gpu(&mut world);
        }
        (world, body)
    };
    let (mut cpu, body) = world(false);
    let (mut gpu, _) = world(true);
    let (mut nudged, _) = world(false);
    nudge_gravity(&mut nudged);
    let max_force = 50.0 * G;
    let lift = Vec3::new(0.0, 2.0, 0.0);
    let dt = cpu.config().dt;
    let (mut worst_off, mut worst_noise, mut worst_behind) = (0.0f32, 0.0f32, 0.0f32);
    let mut lifted_error = f32::INFINITY;
    for step in 0..360 {
        // Two seconds at the lift target, then four round the circle.
        let target = if step < 120 {
            lift
        } else {
            let angle = (step - 120) as f32 * dt;
            lift + Vec3::new(angle.sin(), 0.0, 1.0 - angle.cos())
        };
        for world in [&mut cpu, &mut gpu, &mut nudged] {
            world
                .set_drag_target(body, Vec3::splat(0.5), target, max_force)
                .unwrap();
            world.try_step().unwrap();
        }
        let off = corner(&cpu, body).distance(corner(&gpu, body));
        let noise = corner(&cpu, body).distance(corner(&nudged, body));
        assert!(
            off <= (8.0 * noise).max(1e-5),
            "step {step}: the GPU world's box is {off} m from the CPU's, a CPU world with \
             gravity one ulp stronger {noise} m"
        );
        (worst_off, worst_noise) = (worst_off.max(off), worst_noise.max(noise));
        let behind = corner(&gpu, body).distance(target);
        if step == 119 {
            lifted_error = behind;
        } else if step >= 120 {
            worst_behind = worst_behind.max(behind);
        }
    }
    println!(
        "drag on the GPU: {:.1} mm from the lift target after 2 s, worst {:.1} mm behind the \
         moving target; {worst_off:e} m from the CPU world at most, the nudged CPU world \
         {worst_noise:e} m",
        lifted_error * 1e3,
        worst_behind * 1e3
    );
    assert!(
        worst_off <= 8.0 * worst_noise,
        "the GPU world strayed {worst_off} m from the CPU's, the nudged CPU world {worst_noise} m"
    );
    // tests/engine/drag.rs's bounds: it lifted, and it kept up.
    assert!(
        lifted_error < 0.005,
        "the corner hangs {lifted_error} m from the target"
    );
    assert!(
        worst_behind < 0.08,
        "the corner fell {worst_behind} m behind"
    );
    assert!(gpu.stats().joints == 1, "the drag is solved as a joint");
}

/// Two cantilevers: unit cubes held out from a static wall by fixed joints, each with a 1 kg
/// block falling onto its free half. The first joint breaks above 1.5 times the impulse per
/// sub-step that holds its beam with the block at rest on it (which the block's impact
/// exceeds), the second cannot break. Returns the world, the beams and the joints.
fn cantilevers(devices: StageDevices) -> (World, [BodyHandle; 2], [JointHandle; 2]) {
    let mut world = World::new(StepConfig {
        sleeping: false,
        ..StepConfig::default()
    })
    .unwrap();
    let config = *world.config();
    let h = config.dt / config.substeps as f32;
    // Beam and block, 1 kg each, their centres 0.5 m and 0.7 m out from the wall: a point
    // impulse of 2 kg · g · h and angular impulses of g · h · (0.5 + 0.7) kg m.
    let holding = G * h * (2.0 + 0.5 + 0.7);
    let wall = world
        .add_body(
            BodyDesc::fixed(Shape::cuboid(Vec3::new(0.5, 0.5, 3.0)))
                .position(Vec3::new(0.0, 4.0, 0.0)),
        )
        .unwrap();
    let mut beams = Vec::new();
    let mut joints = Vec::new();
    for (z, break_impulse) in [(-1.5, Some(1.5 * holding)), (1.5, None)] {
        let beam = world
            .add_body(
                BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(1.0, 4.0, z)),
            )
            .unwrap();
        let mut joint = JointDesc::new(JointKind::Fixed, wall, beam, Vec3::new(0.5, 4.0, z));
        if let Some(impulse) = break_impulse {
            joint = joint.break_impulse(impulse);
        }
        joints.push(world.add_joint(joint).unwrap());
        world
            .add_body(
                BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.2))).position(Vec3::new(1.2, 6.0, z)),
            )
            .unwrap();
        beams.push(beam);
    }
    world.set_stage_devices(devices).unwrap();
    (world, [beams[0], beams[1]], [joints[0], joints[1]])
}

/// The breakable cantilever of [`cantilevers`] breaks on the GPU worlds at the same step as on
/// the CPU world, when the block lands and not before, and the beam then falls away from the
/// wall; the unbreakable one holds the same load. Joint impulses come back from the GPU each
/// step for the host's break test: with the whole step on the GPU (the rows kept there,
/// `GpuStages::solve_batched`) and with the solver alone (`GpuStages::solve`).
#[test]
fn a_joint_breaks_on_the_gpu_world_at_the_cpu_step() {
    let _turn = gpu_common::context();
    let mut solver_only = StageDevices::default();
    solver_only.set(Stage::Solver, Executor::Gpu);
    let names = ["CPU", "GPU (whole step)", "GPU (solver)"];
    let mut worlds = [
        StageDevices::default(),
        StageDevices::all(Executor::Gpu),
        solver_only,
    ]
    .map(cantilevers);
    let (beams, joints) = (worlds[0].1, worlds[0].2);
    let dt = worlds[0].0.config().dt;
    // The block's 1.3 m fall to the beam's top face (from 5.8 m to 4.5 m).
    let landing = ((2.0 * 1.3 / G).sqrt() / dt).floor() as usize;
    let mut broke = [None; 3];
    for step in 0..landing + 60 {
        for ((world, _, _), broke) in worlds.iter_mut().zip(&mut broke) {
            world.try_step().unwrap();
            if broke.is_none() && world.is_joint_broken(joints[0]).unwrap() {
                *broke = Some(step);
            }
        }
    }
    println!("the joint broke at step {broke:?} ({names:?}), the block lands at step {landing}");
    let Some(on_cpu) = broke[0] else {
        panic!("the breakable joint held on the CPU");
    };
    assert!(
        on_cpu >= landing,
        "it broke at step {on_cpu}, before the impact"
    );
    assert_eq!(
        broke,
        [Some(on_cpu); 3],
        "a GPU world broke at another step"
    );
    for (name, (world, _, _)) in names.iter().zip(&worlds) {
        // About a second after the impact: fallen well clear of the wall.
        let (a, b) = world.joint_anchors(joints[0]).unwrap();
        assert!(
            a.distance(b) > 0.5,
            "{name}: the broken beam stays {} m from the wall",
            a.distance(b)
        );
        assert!(!world.is_joint_broken(joints[1]).unwrap(), "{name}");
        let sag = world
            .pose(beams[1])
            .unwrap()
            .position
            .distance(Vec3::new(1.0, 4.0, 1.5));
        println!(
            "{name}: the unbreakable beam sags {:.2} mm under the block",
            sag * 1e3
        );
        assert!(sag < 0.01, "{name}: the unbreakable beam sagged {sag} m");
    }
}

/// Bit patterns of a body's pose and angular velocity, for bitwise comparisons.
fn body_bits(world: &World, body: BodyHandle) -> [u32; 10] {
    let pose = world.pose(body).unwrap();
    let spin = world.angular_velocity(body).unwrap();
    let mut bits = [0; 10];
    for (bit, value) in bits.iter_mut().zip(
        pose.position
            .to_array()
            .into_iter()
            .chain(pose.rotation.to_array())
            .chain(spin.to_array()),
    ) {
        *bit = value.to_bits();
    }
    bits
}

/// Rows, batching and solver all on the GPU keep the contact and joint rows on the device
/// (the joints' warm starts too), solved in the same batched dispatches, with only impulses
/// read back: the same step, bit for bit, as with the batching on the CPU, where every row
/// goes through the host. Six ragdolls fall into a pile, the top one dragged
/// by its pelvis, so contacts, joints and the drag share batches and carry their impulses
/// from step to step.
#[test]
fn joints_beside_rows_kept_on_the_gpu_give_the_step_through_the_host_exactly() {
    let _turn = gpu_common::context();
    let world = |stages: &[Stage]| {
        let mut world = ragdolls(false);
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        world
    };
    let mut chained = world(&[Stage::Constraints, Stage::Batching, Stage::Solver]);
    let mut through_host = world(&[Stage::Constraints, Stage::Solver]);
    let bodies: Vec<BodyHandle> = chained.bodies().collect();
    let joints: Vec<JointHandle> = chained.joints().map(|(joint, _)| joint).collect();
    // The top ragdoll's first capsule, its pelvis, pulled up and aside.
    let dragged = bodies[bodies.len() - 11];
    let target = chained.pose(dragged).unwrap().position + Vec3::new(0.5, 0.5, 0.0);
    let mut most_contacts = 0;
    for step in 0..90 {
        for world in [&mut chained, &mut through_host] {
            world
                .set_drag_target(dragged, Vec3::ZERO, target, 200.0)
                .unwrap();
            world.try_step().unwrap();
        }
        let (a, b) = (chained.stats(), through_host.stats());
        assert_eq!(
            (a.manifolds, a.contacts, a.joints, &a.batch_histogram),
            (b.manifolds, b.contacts, b.joints, &b.batch_histogram),
            "step {step}"
        );
        most_contacts = most_contacts.max(a.contacts);
        for &body in &bodies {
            assert_eq!(
                body_bits(&chained, body),
                body_bits(&through_host, body),
                "step {step}: {body:?}"
            );
        }
        // The joints' impulses, read back for the warm start and the break test.
        let impulse_bits = |world: &World, joint: JointHandle| {
            let joint = world.joint(joint).unwrap();
            let impulses = joint.point_impulse.to_array().into_iter();
            let impulses = impulses.chain(joint.angular_impulse);
            impulses.map(f32::to_bits).collect::<Vec<u32>>()
        };
        for &joint in &joints {
            assert_eq!(
                impulse_bits(&chained, joint),
                impulse_bits(&through_host, joint),
                "step {step}: {joint:?}"
            );
        }
    }
    assert!(most_contacts > 10, "too few contacts to compare");
    // The rows stayed on the device: no copy of them to the host in the chained world.
    let copies_rows_back = |world: &World| {
        let report = world.profiler().report();
        let constraints = report
            .root
            .children
            .iter()
            .find(|line| line.name == "constraints")
            .expect("a constraints line");
        constraints
            .children
            .iter()
            .any(|line| line.name == "copy to cpu")
    };
    assert!(!copies_rows_back(&chained) && copies_rows_back(&through_host));
}
