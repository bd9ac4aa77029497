//! Joint rows built on the GPU (issue 7, `stages/constraints/joint_gpu.rs`): parity with the
//! CPU's `build_joint_constraints` on random joints of every kind, and worlds whose joint rows
//! are built on the device following the CPU world.

use crate::gpu_common;

use gpu_common::{Random, context};
use tumble::dynamics::body::{BodyMass, BodyPose};
use tumble::dynamics::joint::{Joint, JointKind, MAX_ANGULAR_ROWS, Motor};
use tumble::gpu::GpuVec;
use tumble::math::{Mat3, Quat, Vec3, tangent_basis};
use tumble::pipeline::config::Softness;
use tumble::pipeline::devices::{Executor, Stage, StageDevices};
use tumble::scene::builtin;
use tumble::stages::constraints::joint_gpu::{GpuJointInputs, GpuJointRows};
use tumble::stages::constraints::{
    Drag, JointConstraint, STATIC_BODY, build_joint_constraints, drag_constraint, joint_slots,
    world_inverse_inertia,
};
use tumble::stages::solver::SolverKind;
use tumble::{BodyHandle, JointDesc, JointHandle, JointKind as Kind, StepConfig, World};

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

/// `count` bodies: a fifth static (no mass, as a sleeping body has none), the rest with
/// inverse inertias spread over three decades so the inertia tolerance meets its scale.
fn bodies(random: &mut Random, count: usize) -> (Vec<BodyPose>, Vec<BodyMass>) {
    let mut poses = Vec::new();
    let mut masses = Vec::new();
    for _ in 0..count {
        let axis = vector(random, 1.0).normalize_or(Vec3::Y);
        let rotation = Quat::from_axis_angle(axis, uniform(random, 0.0, 6.3));
        poses.push(BodyPose::new(vector(random, 50.0), rotation));
        masses.push(if random.below(5) == 0 {
            BodyMass::default()
        } else {
            let scale = 10f32.powf(uniform(random, -1.5, 1.5));
            BodyMass {
                inverse_inertia: Vec3::new(
                    scale * uniform(random, 0.2, 3.0),
                    scale * uniform(random, 0.2, 3.0),
                    scale * uniform(random, 0.2, 3.0),
                ),
                inverse_mass: uniform(random, 0.05, 5.0),
            }
        });
    }
    (poses, masses)
}

/// `count` joint slots between random bodies: free slots, broken joints, and every kind with
/// every option (hinges with and without limits and motor, cone-twists, fixed, point), each
/// with random frames and warm-start impulses. Joints whose bodies both lack mass get no row.
fn joints(random: &mut Random, count: usize, body_count: u32) -> Vec<Option<Joint>> {
    (0..count)
        .map(|_| {
            let (a, b) = (random.below(body_count), random.below(body_count));
            if a == b || random.below(12) == 0 {
                return None;
            }
            let axis = vector(random, 1.0).normalize_or(Vec3::X);
            let limits = Some((uniform(random, -3.0, 0.0), uniform(random, 0.0, 3.0)));
            let motor = Some(Motor {
                target_speed: uniform(random, -5.0, 5.0),
                max_torque: uniform(random, 0.0, 100.0),
            });
            let kind = match random.below(7) {
                0 => JointKind::Hinge {
                    axis,
                    limits,
                    motor,
                },
                1 => JointKind::Hinge {
                    axis,
                    limits,
                    motor: None,
                },
                2 => JointKind::Hinge {
                    axis,
                    limits: None,
                    motor,
                },
                3 => JointKind::ConeTwist {
                    axis,
                    swing_limit: uniform(random, 0.0, 3.1),
                    twist_limits: (uniform(random, -3.0, 0.0), uniform(random, 0.0, 3.0)),
                },
                4 => JointKind::Fixed,
                _ => JointKind::Point,
            };
            let turn = |random: &mut Random| Quat::from_scaled_axis(vector(random, 2.0));
            let (rotation_a, rotation_b) = (turn(random), turn(random));
            let (reference, _) = tangent_basis(axis);
            let mut angular_impulse = [0.0; MAX_ANGULAR_ROWS];
            for impulse in &mut angular_impulse {
                *impulse = uniform(random, -1.0, 1.0);
            }
            Some(Joint {
                kind,
                body_a: a,
                body_b: b,
                local_anchor_a: vector(random, 1.0),
                local_anchor_b: vector(random, 1.0),
                local_axis_a: rotation_a * axis,
                local_axis_b: rotation_b * axis,
                local_reference_a: rotation_a * reference,
                local_reference_b: rotation_b * reference,
                relative_rotation: rotation_a.inverse() * rotation_b,
                break_impulse: (random.below(3) == 0).then_some(10.0),
                broken: random.below(10) == 0,
                point_impulse: vector(random, 2.0),
                angular_impulse,
            })
        })
        .collect()
}

/// Largest difference allowed between an entry of a GPU inverse inertia and the CPU's, in
/// units of the body's largest inverse inertia d_max. Both compute R diag(d) Rᵀ from the same
/// quaternion in glam's order: each entry of R carries at most 3 roundings (|R_ij| ≤ 1), so
/// two executors' R differ by |ΔR| ≤ 6u per entry (u = 2⁻²⁴, FMA contraction on the GPU
/// rounds differently, not more); an entry Σ_k R_ik d_k R_jk then differs by at most
/// Σ_k (|ΔR_ik| |R_jk| + |R_ik| |ΔR_jk|) d_k ≤ 12u √3 d_max from R, plus the products' and sums'
/// own roundings, 4u · Σ_k |R_ik| d_k |R_jk| ≤ 4u d_max on each side: 29u d_max < 32u d_max.
const INERTIA_ULPS: f32 = 32.0;

/// The GPU rows against the CPU's, field by field: everything the kernel copies (frame,
/// bodies, ids, rotations, masses, impulses, softness, pads) bit for bit, the centre offset too
/// (one subtraction, correctly rounded on both), the inverse inertias within [`INERTIA_ULPS`].
/// Returns the worst inertia difference in units of u · d_max.
fn compare(gpu: &[JointConstraint], cpu: &[JointConstraint], masses: &[BodyMass]) -> f32 {
    assert_eq!(gpu.len(), cpu.len(), "row count");
    let u = f32::EPSILON / 2.0;
    let mut worst = 0.0f32;
    for (row, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        let without_inertia = |j: &JointConstraint| JointConstraint {
            inverse_inertia_a: Mat3::ZERO,
            inverse_inertia_b: Mat3::ZERO,
            ..*j
        };
        assert_eq!(
            bytemuck::bytes_of(&without_inertia(g)),
            bytemuck::bytes_of(&without_inertia(c)),
            "row {row} (joint {}): GPU {g:?}, CPU {c:?}",
            c.joint
        );
        for (body, gpu_inertia, cpu_inertia) in [
            (c.body_a, g.inverse_inertia_a, c.inverse_inertia_a),
            (c.body_b, g.inverse_inertia_b, c.inverse_inertia_b),
        ] {
            let pairs = gpu_inertia
                .to_cols_array()
                .into_iter()
                .zip(cpu_inertia.to_cols_array());
            if body == STATIC_BODY {
                // diag(0): zeros on both sides (their signs may differ).
                for (x, y) in pairs {
                    assert!(x == 0.0 && y == 0.0, "row {row}: a static side's inertia");
                }
                continue;
            }
            let d_max = masses[body as usize].inverse_inertia.max_element();
            for (x, y) in pairs {
                worst = worst.max((x - y).abs() / (u * d_max));
            }
        }
    }
    worst
}

/// Runs `count` random joint slots over `body_count` bodies through both executors, with a
/// drag in the slot past the joints', and compares the rows the step would solve.
fn check(seed: u64, count: usize, body_count: usize) -> f32 {
    let context = context();
    let mut random = Random::new(seed);
    let (poses, masses) = bodies(&mut random, body_count);
    let joints = joints(&mut random, count, body_count as u32);
    let h = 1.0 / 240.0;
    let softness = Softness::new(60.0, 5.0, h);
    let drag = (0..body_count)
        .find(|&b| masses[b].inverse_mass > 0.0)
        .map(|body| {
            let drag = Drag {
                body: body as u32,
                local_anchor: Vec3::new(0.1, 0.2, -0.1),
                target: poses[body].position + Vec3::Y,
                max_force: 20.0,
                impulse: Vec3::new(0.05, 0.1, 0.0),
            };
            drag_constraint(&drag, &poses, &masses, Softness::new(5.0, 0.7, h), h)
        });

    let mut inverse_inertia = Vec::new();
    world_inverse_inertia(&poses, &masses, &mut inverse_inertia);
    let mut cpu = Vec::new();
    build_joint_constraints(
        &joints,
        &poses,
        &masses,
        &inverse_inertia,
        softness,
        &mut cpu,
    );
    cpu.extend(drag);

    let mut slots: Vec<u32> = joint_slots(&joints, &masses)
        .map(|(slot, _)| slot)
        .collect();
    let device_poses = GpuVec::from_slice(&context, "poses", &poses).unwrap();
    let device_masses = GpuVec::from_slice(&context, "masses", &masses).unwrap();
    let mut rows = GpuJointRows::new(&context).unwrap();
    rows.sync(&context, &joints).unwrap();
    if let Some(drag) = &drag {
        slots.push(rows.extra_slot());
        rows.write_row(&context, rows.extra_slot(), drag);
    }
    let inputs = GpuJointInputs {
        poses: &device_poses,
        masses: &device_masses,
        softness,
    };
    context.submit_pass("joint rows", |pass| {
        rows.encode_build(&context, pass, &inputs);
    });
    let mut gpu = Vec::new();
    rows.read_back(&context, &slots, &mut gpu).unwrap();
    assert!(
        count < 100 || cpu.len() > count / 2,
        "most random joints get a row: {} of {count}",
        cpu.len()
    );
    compare(&gpu, &cpu, &masses)
}

#[test]
fn gpu_joint_rows_match_the_cpu_on_random_joints() {
    let mut worst = 0.0f32;
    for (seed, (count, bodies)) in [(0, 4), (1, 2), (255, 64), (257, 300), (3001, 1000)]
        .into_iter()
        .enumerate()
    {
        let off = check(seed as u64, count, bodies);
        assert!(
            off <= INERTIA_ULPS,
            "{count} joints: an inverse inertia is {off} u·d_max from the CPU's"
        );
        worst = worst.max(off);
    }
    println!("worst inverse inertia difference: {worst} u·d_max (bound {INERTIA_ULPS})");
}

/// No joint at all, and joints whose rows are all skipped (free, broken or without a moving
/// body): nothing to build, nothing read back, no failure.
#[test]
fn no_joint_rows_build_nothing() {
    let context = context();
    let mut random = Random::new(9);
    let (poses, masses) = bodies(&mut random, 8);
    let asleep = BodyMass::default();
    let masses: Vec<BodyMass> = masses.iter().map(|_| asleep).collect();
    for joints in [Vec::new(), joints(&mut random, 40, 8)] {
        assert_eq!(joint_slots(&joints, &masses).count(), 0);
        let device_poses = GpuVec::from_slice(&context, "poses", &poses).unwrap();
        let device_masses = GpuVec::from_slice(&context, "masses", &masses).unwrap();
        let mut rows = GpuJointRows::new(&context).unwrap();
        rows.sync(&context, &joints).unwrap();
        let inputs = GpuJointInputs {
            poses: &device_poses,
            masses: &device_masses,
            softness: Softness::new(60.0, 5.0, 1.0 / 240.0),
        };
        context.submit_pass("joint rows", |pass| {
            rows.encode_build(&context, pass, &inputs);
        });
        let mut out = vec![bytemuck::Zeroable::zeroed()];
        rows.read_back(&context, &[], &mut out).unwrap();
        assert!(out.is_empty());
    }
}

/// The `ragdolls` scene at its smallest scale (6 ragdolls of 11 capsules joined by hinges and
/// cone-twists) with `stages` on the GPU.
fn ragdolls(stages: &[Stage]) -> World {
    let mut world = builtin("ragdolls", 0.05).unwrap().build().unwrap();
    let mut devices = StageDevices::default();
    for &stage in stages {
        devices.set(stage, Executor::Gpu);
    }
    world.set_stage_devices(devices).unwrap();
    world
}

fn positions(world: &World) -> Vec<Vec3> {
    let bodies: Vec<BodyHandle> = world.bodies().collect();
    bodies
        .iter()
        .map(|&body| world.pose(body).unwrap().position)
        .collect()
}

/// The stages of a step whose rows stay on the device from build to solve.
const CHAINED: [Stage; 3] = [Stage::Constraints, Stage::Batching, Stage::Solver];

/// The ragdolls with their joint rows built on the GPU follow the CPU world, by the yardstick
/// of tests/engine/gpu_joints.rs (the CPU's own response to one ulp of input noise: a CPU world with
/// gravity one ulp stronger), at every step of the fall and the pile: with the rows alone on
/// the GPU (read back for the CPU solver, so only the rows differ: their inertias by a few
/// roundings) and with the rows kept on the device for the GPU batching and solver.
#[test]
fn ragdolls_with_the_joint_rows_on_the_gpu_follow_the_cpu() {
    let _turn = context();
    for stages in [&[Stage::Constraints][..], &CHAINED] {
        let mut cpu = ragdolls(&[]);
        let mut gpu = ragdolls(stages);
        let mut nudged = ragdolls(&[]);
        let config = *nudged.config();
        let gravity = config
            .gravity
            .map(|g| if g < 0.0 { g.next_down() } else { g });
        nudged.set_config(StepConfig { gravity, ..config }).unwrap();
        let distance = |a: &World, b: &World| {
            positions(a)
                .iter()
                .zip(positions(b))
                .map(|(p, q)| p.distance(q))
                .fold(0.0, f32::max)
        };
        for step in 0..90 {
            cpu.step();
            gpu.try_step().unwrap();
            nudged.step();
            let (off, noise) = (distance(&cpu, &gpu), distance(&cpu, &nudged));
            assert!(
                off <= (8.0 * noise).max(1e-5),
                "{stages:?}, step {step}: the GPU world is {off} m from the CPU's, a CPU \
                 world with gravity one ulp stronger {noise} m"
            );
        }
        assert_eq!(gpu.stats().joints, cpu.stats().joints);
        assert!(gpu.stats().joints > 0, "the ragdolls' joints are solved");
    }
}

/// With the rows kept on the device, the profile shows the joint rows as a GPU kernel line of
/// the constraints (where the adapter has timestamps), beside the contact rows' kernels.
#[test]
fn the_profile_shows_the_joint_rows_kernel() {
    let turn = context();
    turn.set_gpu_timing(true);
    let mut world = ragdolls(&Stage::ALL);
    for _ in 0..3 {
        world.try_step().unwrap();
    }
    let report = world.profiler().report();
    let constraints = report
        .root
        .children
        .iter()
        .find(|line| line.name == "constraints")
        .expect("a constraints line");
    let lines: Vec<&str> = constraints.children.iter().map(|l| l.name).collect();
    assert_eq!(
        lines.contains(&"joint kernel"),
        turn.has_timestamps(),
        "constraints lines {lines:?}"
    );
}

/// The device's copy of the joints follows every change, so a world that keeps its rows on
/// the device steps bit for bit as one whose rows go through the host: joints removed (their
/// slot freed) and added (reusing it, between other bodies), and steps whose batching, and so
/// the solve, ran through the host (the device's warm starts are then the host's). World
/// `chained` keeps the rows on the device at every step; `switching` sends them through the
/// host at every third step (the batching on the CPU: the GPU solver then solves the rows
/// uploaded from the host and writes no impulse back to the device's joints). Both solvers:
/// the Jacobi one reads the gathered joints too.
#[test]
fn device_joints_follow_changes_and_devices_bitwise() {
    let _turn = context();
    for solver in [SolverKind::Pgs, SolverKind::Jacobi] {
        follow_changes_and_devices(solver);
    }
}

fn follow_changes_and_devices(solver: SolverKind) {
    let mut chained = ragdolls(&CHAINED);
    let mut switching = ragdolls(&CHAINED);
    for world in [&mut chained, &mut switching] {
        let config = StepConfig {
            solver,
            ..*world.config()
        };
        world.set_config(config).unwrap();
    }
    let bodies: Vec<BodyHandle> = chained.bodies().collect();
    let joints: Vec<JointHandle> = chained.joints().map(|(joint, _)| joint).collect();
    let through_host = {
        let mut devices = StageDevices::default();
        devices.set(Stage::Constraints, Executor::Gpu);
        devices.set(Stage::Solver, Executor::Gpu);
        devices
    };
    let all_chained = {
        let mut devices = StageDevices::default();
        for stage in CHAINED {
            devices.set(stage, Executor::Gpu);
        }
        devices
    };
    for step in 0..45 {
        match step {
            // A knee (or elbow) goes: its slot is freed.
            10 => {
                for world in [&mut chained, &mut switching] {
                    world.remove_joint(joints[3]).unwrap();
                }
            }
            // A point joint between two other ragdolls takes the freed slot.
            20 => {
                for world in [&mut chained, &mut switching] {
                    let (a, b) = (bodies[1], bodies[bodies.len() - 1]);
                    let anchor = world.pose(a).unwrap().position;
                    world
                        .add_joint(JointDesc::new(Kind::Point, a, b, anchor))
                        .unwrap();
                }
            }
            _ => {}
        }
        let devices = if step % 3 == 2 {
            through_host
        } else {
            all_chained
        };
        switching.set_stage_devices(devices).unwrap();
        chained.try_step().unwrap();
        switching.try_step().unwrap();
        for &body in &bodies {
            assert_eq!(
                chained.pose(body).unwrap(),
                switching.pose(body).unwrap(),
                "{solver:?}, step {step}: {body:?}"
            );
        }
        let impulses = |world: &World| {
            let joints = world.joints().map(|(_, joint)| joint);
            joints
                .flat_map(|joint| {
                    joint
                        .point_impulse
                        .to_array()
                        .into_iter()
                        .chain(joint.angular_impulse)
                })
                .map(f32::to_bits)
                .collect::<Vec<u32>>()
        };
        assert_eq!(
            impulses(&chained),
            impulses(&switching),
            "{solver:?}, step {step}"
        );
    }
    assert_eq!(
        chained.joints().count(),
        joints.len(),
        "one joint removed, one added"
    );
}
