//! Stages mixed between CPU and GPU (`World::set_stage_devices`): a world with a stage on the
//! GPU follows the all-CPU world within the stage parity tests' tolerances.

use crate::gpu_common;

use tumble::math::{Quat, Vec3};
use tumble::pipeline::devices::{Executor, Stage, StageDevices};
use tumble::{BodyDesc, BodyHandle, Shape, StepConfig, World};

/// Largest distance between the same body in two worlds (m).
fn max_distance(a: &World, b: &World, bodies: &[BodyHandle]) -> f32 {
    bodies
        .iter()
        .map(|&body| {
            let pa = a.pose(body).unwrap().position;
            let pb = b.pose(body).unwrap().position;
            pa.distance(pb)
        })
        .fold(0.0, f32::max)
}

/// Two towers of boxes, one turned, and a capsule and a ball resting against them: every
/// GPU pair function of the step meets work, small enough for a CPU driver.
/// A world that never sleeps (the tests compare every step's contacts and motion), with the
/// ground plane at y = 0 as its first body.
fn awake_on_ground() -> World {
    let mut world = World::new(StepConfig {
        sleeping: false,
        ..StepConfig::default()
    })
    .unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    world
}

fn world_on(stages: &[Stage]) -> World {
    let mut world = awake_on_ground();
    for level in 0..5 {
        let y = 0.5 + level as f32;
        let turn = Quat::from_rotation_y(0.3 * level as f32);
        for (x, rotation) in [(0.0, Quat::IDENTITY), (3.0, turn)] {
            world
                .add_body(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                        .position(Vec3::new(x, y, 0.0))
                        .rotation(rotation),
                )
                .unwrap();
        }
    }
    world
        .add_body(
            BodyDesc::dynamic(Shape::capsule(0.25, 0.5))
                .position(Vec3::new(1.5, 0.25, 0.0))
                .rotation(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2)),
        )
        .unwrap();
    world
        .add_body(BodyDesc::dynamic(Shape::sphere(0.3)).position(Vec3::new(0.0, 0.3, 1.0)))
        .unwrap();
    let mut devices = StageDevices::default();
    for &stage in stages {
        devices.set(stage, Executor::Gpu);
    }
    world.set_stage_devices(devices).unwrap();
    world
}

/// Runs a stack with `stages` on the GPU beside the all-CPU world.
fn follows_the_cpu(stages: &[Stage]) {
    // One test at a time on the device (see `gpu_common::context`).
    let _turn = gpu_common::context();
    let mut cpu = world_on(&[]);
    let mut gpu = world_on(stages);
    let bodies: Vec<BodyHandle> = cpu.bodies().collect();
    assert!(
        bodies.len() > 10,
        "a stack worth the name: {}",
        bodies.len()
    );
    cpu.step();
    gpu.try_step().unwrap();
    // From the same state, the same contacts (a GPU broadphase finds fewer candidate pairs
    // than the CPU's fat boxes, but every pair with a contact).
    assert_eq!(cpu.stats().contacts, gpu.stats().contacts, "{stages:?}");
    for _ in 1..120 {
        cpu.step();
        gpu.try_step().unwrap();
    }
    // Later the states differ by rounding, and a speculative point whose separation sits at
    // the contact margin (boxes of the walls stand that far apart) can be in one world and not
    // in the other: the counts agree within 2 % (measured: 1982 and 1995 after 120 steps).
    let (a, b) = (cpu.stats().contacts as f32, gpu.stats().contacts as f32);
    assert!(
        (a - b).abs() <= 0.02 * a,
        "contacts: {a} on the CPU, {b} on the GPU"
    );
    // Contacts agree within 1e-4 m (the narrowphase parity bound), AABBs within a few
    // roundings, impulses within 1e-5; resting stacks keep such differences from growing.
    let distance = max_distance(&cpu, &gpu, &bodies);
    assert!(
        distance < 1e-3,
        "{stages:?} on the GPU drifted {distance} m from the CPU"
    );
}

#[test]
fn each_collision_stage_on_the_gpu_follows_the_cpu() {
    follows_the_cpu(&[Stage::Aabb]);
    follows_the_cpu(&[Stage::Broadphase]);
    follows_the_cpu(&[Stage::Narrowphase]);
}

#[test]
fn the_solver_on_the_gpu_follows_the_cpu() {
    follows_the_cpu(&[Stage::Solver]);
}

#[test]
fn the_whole_step_on_the_gpu_follows_the_cpu() {
    follows_the_cpu(&Stage::ALL);
}

#[test]
fn rows_on_the_gpu_follow_the_cpu() {
    follows_the_cpu(&[Stage::Constraints]);
}

/// The rows cover their buffers, not the live slots: after the pairs shrink (the towers' top
/// boxes removed), the slots past the live ones still hold last step's keys and contacts, and
/// no row is built from them. The rows, on the GPU alone, count as the CPU's every step.
#[test]
fn rows_on_the_gpu_skip_the_slots_past_the_live_ones() {
    let _turn = gpu_common::context();
    let mut cpu = world_on(&[]);
    let mut gpu = world_on(&[Stage::Constraints]);
    let bodies: Vec<BodyHandle> = cpu.bodies().collect();
    let mut shrank = false;
    for step in 0..40 {
        if step == 20 {
            let pairs = cpu.stats().pairs;
            // The top three levels of both towers (bodies 1 and 2 are the bottom level).
            for &body in &bodies[5..11] {
                cpu.remove_body(body).unwrap();
                gpu.remove_body(body).unwrap();
            }
            cpu.step();
            gpu.try_step().unwrap();
            shrank = cpu.stats().pairs < pairs;
        } else {
            cpu.step();
            gpu.try_step().unwrap();
        }
        let (a, b) = (cpu.stats(), gpu.stats());
        assert_eq!(
            (a.pairs, a.manifolds, a.contacts),
            (b.pairs, b.manifolds, b.contacts),
            "step {step}"
        );
    }
    assert!(shrank, "the pairs did not shrink");
}

/// Both batchers give the GPU the CPU's colors, so with only the batching on the GPU the two
/// worlds stay bitwise the same.
#[test]
fn batching_on_the_gpu_gives_the_cpu_step_exactly() {
    let _turn = gpu_common::context();
    for batcher in tumble::stages::batching::Batcher::ALL {
        let mut cpu = world_on(&[]);
        let mut gpu = world_on(&[Stage::Batching]);
        for world in [&mut cpu, &mut gpu] {
            let config = StepConfig {
                batcher,
                ..*world.config()
            };
            world.set_config(config).unwrap();
        }
        let bodies: Vec<BodyHandle> = cpu.bodies().collect();
        for _ in 0..60 {
            cpu.step();
            gpu.try_step().unwrap();
        }
        let (a, b) = (cpu.stats(), gpu.stats());
        assert_eq!(a.batch_histogram, b.batch_histogram);
        assert!(
            a.batch_histogram.len() > 1,
            "{batcher}: no batches to compare"
        );
        // The CPU's twin counts the rounds the device took.
        assert_eq!(a.batching_rounds, b.batching_rounds, "{batcher}");
        assert!(a.batching_rounds > 0, "{batcher}");
        for &body in &bodies {
            assert_eq!(cpu.pose(body), gpu.pose(body), "{batcher}");
        }
    }
}

/// Rows, batching and solver all on the GPU keep the contact rows on the device (gathered
/// there into batch order, only impulses read back): the same step, bit for bit, as the rows
/// and the solver on the GPU with the batching between them on the CPU, which gives the same
/// colors but sends the rows through the host. A bouncing ball takes the restitution sweep.
#[test]
fn rows_kept_on_the_gpu_give_the_step_through_the_host_exactly() {
    let _turn = gpu_common::context();
    let mut chained = world_on(&[Stage::Constraints, Stage::Batching, Stage::Solver]);
    let mut through_host = world_on(&[Stage::Constraints, Stage::Solver]);
    for world in [&mut chained, &mut through_host] {
        world
            .add_body(
                BodyDesc::dynamic(Shape::sphere(0.3))
                    .position(Vec3::new(-2.0, 1.0, 0.0))
                    .restitution(0.8),
            )
            .unwrap();
    }
    let bodies: Vec<BodyHandle> = chained.bodies().collect();
    let mut most_contacts = 0;
    for step in 0..90 {
        chained.try_step().unwrap();
        through_host.try_step().unwrap();
        let (a, b) = (chained.stats(), through_host.stats());
        assert_eq!(
            (a.manifolds, a.contacts, &a.batch_histogram),
            (b.manifolds, b.contacts, &b.batch_histogram),
            "step {step}"
        );
        // Colored on the device (its rounds read back with the solve) and on the host.
        assert_eq!(a.batching_rounds, b.batching_rounds, "step {step}");
        most_contacts = most_contacts.max(a.contacts);
        for &body in &bodies {
            assert_eq!(chained.pose(body), through_host.pose(body), "step {step}");
            assert_eq!(
                chained.angular_velocity(body),
                through_host.angular_velocity(body),
                "step {step}"
            );
        }
    }
    assert!(most_contacts > 10, "too few contacts to compare");
}

/// With the narrowphase on the GPU, a barrel rests on the plane (the hull–plane kernel) and a
/// ball and a barrel on a mesh (host work) as on the CPU. (The kernel once read a sphere–mesh
/// pair as capsule–capsule and gave hull pairs no contact.)
#[test]
fn hulls_and_meshes_beside_the_gpu_narrowphase_follow_the_cpu() {
    let _turn = gpu_common::context();
    let world = |stages: &[Stage]| {
        let mut world = awake_on_ground();
        // A 4 m square of two triangles at y = 1, facing up, beside the origin.
        let floor = tumble::shape::TriMesh::new(
            vec![
                Vec3::new(5.0, 1.0, -2.0),
                Vec3::new(5.0, 1.0, 2.0),
                Vec3::new(9.0, 1.0, -2.0),
                Vec3::new(9.0, 1.0, 2.0),
            ],
            vec![[0, 1, 2], [2, 1, 3]],
        )
        .unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::trimesh(floor)))
            .unwrap();
        let barrel = || Shape::convex_hull(&tumble::scene::barrel_points()).unwrap();
        let bodies = [
            world
                .add_body(BodyDesc::dynamic(barrel()).position(Vec3::new(0.0, 1.0, 0.0)))
                .unwrap(),
            world
                .add_body(BodyDesc::dynamic(barrel()).position(Vec3::new(6.0, 2.0, 0.0)))
                .unwrap(),
            world
                .add_body(BodyDesc::dynamic(Shape::sphere(0.3)).position(Vec3::new(8.0, 1.5, 0.0)))
                .unwrap(),
        ];
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        (world, bodies)
    };
    let (mut cpu, bodies) = world(&[]);
    let (mut gpu, _) = world(&[Stage::Narrowphase]);
    for _ in 0..120 {
        cpu.step();
        gpu.try_step().unwrap();
    }
    let [on_plane, on_mesh, ball] = bodies.map(|body| gpu.pose(body).unwrap().position.y);
    assert!(
        on_plane > 0.1,
        "the barrel fell through the plane to {on_plane}"
    );
    assert!(
        on_mesh > 1.1,
        "the barrel fell through the mesh to {on_mesh}"
    );
    assert!(
        (ball - 1.3).abs() < 0.01,
        "the ball rests at {ball}, not 1.3"
    );
    let distance = max_distance(&cpu, &gpu, &bodies);
    assert!(
        distance < 1e-3,
        "the GPU narrowphase world drifted {distance} m"
    );
}

/// The `convex-hulls` scene (barrels tipped onto their rims, landing on the plane and on each
/// other) with the narrowphase on the GPU, where every pair is hull–hull or hull–plane,
/// follows the all-CPU world for 60 steps; two GPU runs are bitwise the same.
#[test]
fn barrels_with_the_gpu_narrowphase_follow_the_cpu() {
    let _turn = gpu_common::context();
    let scene = tumble::scene::builtin("convex-hulls", 0.02).unwrap();
    let world = |stages: &[Stage]| {
        let mut world = scene.build().unwrap();
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        world
    };
    let mut cpu = world(&[]);
    let mut gpu = world(&[Stage::Narrowphase]);
    let mut again = world(&[Stage::Narrowphase]);
    let bodies: Vec<BodyHandle> = cpu.bodies().collect();
    assert!(bodies.len() > 10, "{} barrels", bodies.len());
    let mut most_contacts = 0;
    for _ in 0..60 {
        cpu.step();
        gpu.try_step().unwrap();
        again.try_step().unwrap();
        most_contacts = most_contacts.max(cpu.stats().contacts);
    }
    assert!(
        most_contacts > 20,
        "{most_contacts} contacts: the barrels never met"
    );
    let distance = max_distance(&cpu, &gpu, &bodies);
    assert!(
        distance < 1e-3,
        "the GPU narrowphase world drifted {distance} m"
    );
    for &body in &bodies {
        assert_eq!(gpu.pose(body), again.pose(body), "two GPU runs differ");
    }
}

/// Compounds beside GPU stages: their pairs are host work (`narrowphase::gpu_pair` is false
/// for them), and the GPU AABB kernel bounds them by a turned box that holds the CPU's. A
/// dumbbell on the plane, a table with a box on its top, and a compound of a hull cube and a
/// ball on a mesh rest as on the CPU, with the collision stages or the whole step on the GPU.
/// (Before the kernel bounded them, a compound's box was the plane's ±1e15 and it paired with
/// every body.)
#[test]
fn compounds_beside_gpu_stages_follow_the_cpu() {
    use tumble::math::Transform;
    use tumble::shape::{Compound, CompoundChild, TriMesh};
    let _turn = gpu_common::context();
    let child = |shape: Shape, position: Vec3| CompoundChild {
        shape,
        pose: Transform::from_position(position),
    };
    let dumbbell = Shape::compound(vec![
        child(Shape::sphere(0.25), Vec3::new(-0.5, 0.0, 0.0)),
        CompoundChild {
            shape: Shape::capsule(0.05, 0.4),
            pose: Transform::new(
                Vec3::ZERO,
                Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
            ),
        },
        child(Shape::sphere(0.25), Vec3::new(0.5, 0.0, 0.0)),
    ])
    .unwrap();
    // Legs 0.7 m tall under a 0.1 m top, given from the floor under the table's middle.
    let mut table = vec![child(
        Shape::cuboid(Vec3::new(0.6, 0.05, 0.4)),
        Vec3::new(0.0, 0.75, 0.0),
    )];
    for (x, z) in [(-0.5, -0.3), (0.5, -0.3), (-0.5, 0.3), (0.5, 0.3)] {
        table.push(child(
            Shape::cuboid(Vec3::new(0.05, 0.35, 0.05)),
            Vec3::new(x, 0.35, z),
        ));
    }
    let table_centroid = Compound::new(table.clone())
        .unwrap()
        .local_frame()
        .position
        .y;
    let table = Shape::compound(table).unwrap();
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            0.2 * Vec3::new(
                [-1.0, 1.0][i & 1],
                [-1.0, 1.0][(i >> 1) & 1],
                [-1.0, 1.0][i >> 2],
            )
        })
        .collect();
    let cube_and_ball = Shape::compound(vec![
        child(Shape::convex_hull(&corners).unwrap(), Vec3::ZERO),
        child(Shape::sphere(0.2), Vec3::X),
    ])
    .unwrap();
    let world = |stages: &[Stage]| {
        let mut world = awake_on_ground();
        // A 4 m square of two triangles at y = 1, facing up, beside the origin.
        let floor = TriMesh::new(
            vec![
                Vec3::new(5.0, 1.0, -2.0),
                Vec3::new(5.0, 1.0, 2.0),
                Vec3::new(9.0, 1.0, -2.0),
                Vec3::new(9.0, 1.0, 2.0),
            ],
            vec![[0, 1, 2], [2, 1, 3]],
        )
        .unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::trimesh(floor)))
            .unwrap();
        let bodies = [
            world
                .add_body(BodyDesc::dynamic(dumbbell.clone()).position(Vec3::new(0.0, 0.5, -2.0)))
                .unwrap(),
            world
                .add_body(BodyDesc::dynamic(table.clone()).position(Vec3::new(0.0, 0.1, 1.0)))
                .unwrap(),
            world
                .add_body(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.1)))
                        .position(Vec3::new(0.2, 1.0, 1.0)),
                )
                .unwrap(),
            world
                .add_body(
                    BodyDesc::dynamic(cube_and_ball.clone()).position(Vec3::new(6.5, 1.4, 0.0)),
                )
                .unwrap(),
        ];
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        (world, bodies)
    };
    let stage_sets: [&[Stage]; 3] = [
        &[Stage::Narrowphase],
        &[Stage::Aabb, Stage::Broadphase, Stage::Narrowphase],
        &Stage::ALL,
    ];
    for stages in stage_sets {
        let (mut cpu, bodies) = world(&[]);
        let (mut gpu, _) = world(stages);
        for _ in 0..120 {
            cpu.step();
            gpu.try_step().unwrap();
        }
        let heights = bodies.map(|body| gpu.pose(body).unwrap().position.y);
        let expected = [0.25, table_centroid, 0.9, 1.2];
        for (name, (y, rest)) in ["dumbbell", "table", "box", "cube and ball"]
            .iter()
            .zip(heights.into_iter().zip(expected))
        {
            assert!(
                (y - rest).abs() < 2e-3,
                "{stages:?}: the {name} rests at y = {y}, not {rest}"
            );
        }
        let distance = max_distance(&cpu, &gpu, &bodies);
        assert!(
            distance < 1e-3,
            "{stages:?}: the GPU world drifted {distance} m"
        );
    }
}

/// A GPU stage that fails partway through a step leaves the bodies as they were before it,
/// and says why: here the contact rows outgrow the storage bindings of a device whose limit
/// is lowered to 256 KiB (the pairs' contacts still fit: 80 boxes make 630 pairs, a row each
/// on the first step, 432 bytes a row), after the collision ran.
#[test]
fn a_failed_gpu_step_leaves_the_bodies_as_they_were() {
    let _turn = gpu_common::context();
    let small = tumble::gpu::GpuContext::with_limits(|limits| {
        limits.max_storage_buffer_binding_size = 256 << 10;
    })
    .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
    let mut world = World::new(StepConfig {
        sleeping: false,
        ..StepConfig::default()
    })
    .unwrap();
    world.set_gpu_context(small).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let mut bodies = Vec::new();
    for index in 0..80 {
        let (x, y, z) = (index % 5, index / 20, (index / 5) % 4);
        let position = Vec3::new(x as f32, 0.5 + y as f32, z as f32);
        let desc = BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
            .position(position)
            .linear_velocity(Vec3::new(0.1, 0.0, 0.0));
        bodies.push(world.add_body(desc).unwrap());
    }
    world
        .set_stage_devices(StageDevices::all(Executor::Gpu))
        .unwrap();
    let state = |world: &World| -> Vec<(Vec3, Quat, Vec3)> {
        bodies
            .iter()
            .map(|&body| {
                let pose = world.pose(body).unwrap();
                (
                    pose.position,
                    pose.rotation,
                    world.linear_velocity(body).unwrap(),
                )
            })
            .collect()
    };
    let before = state(&world);
    let error = world.try_step().unwrap_err();
    assert!(
        matches!(
            error,
            tumble::gpu::GpuError::BufferTooLarge {
                what: "contact constraints",
                ..
            }
        ),
        "{error}"
    );
    assert_eq!(state(&world), before);
    // And again: the world is as it was, so the same step fails the same way.
    assert!(world.try_step().is_err());
    assert_eq!(state(&world), before);
}

/// The GPU narrowphase's kernel holds the pair functions of the shapes the world has
/// (`narrowphase::gpu::shape_kinds`): a world of boxes that gains a ball, then a capsule, builds
/// the kernel again, and each new body comes to rest on the plane as on the CPU, where a
/// kernel left without their pair functions lets them fall through it.
#[test]
fn a_world_that_gains_a_kind_of_shape_collides_it_on_the_gpu() {
    let _turn = gpu_common::context();
    let run = |stages: &[Stage]| {
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        let block =
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0));
        world.add_body(block).unwrap();
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        let mut added = Vec::new();
        let lying = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let arrivals = [
            (10, Shape::sphere(0.3), Quat::IDENTITY),
            (20, Shape::capsule(0.25, 0.5), lying),
        ];
        for (step, shape, rotation) in arrivals {
            while world.steps() < step {
                world.try_step().unwrap();
            }
            let position = Vec3::new(0.3 * step as f32, 1.0, 0.0);
            let body = BodyDesc::dynamic(shape)
                .position(position)
                .rotation(rotation);
            added.push(world.add_body(body).unwrap());
        }
        for _ in 0..90 {
            world.try_step().unwrap();
        }
        added
            .iter()
            .map(|&body| world.pose(body).unwrap().position.y)
            .collect::<Vec<f32>>()
    };
    let cpu = run(&[]);
    let gpu = run(&Stage::ALL);
    // Resting on the plane: the ball's centre at its radius, the capsule lying on its side.
    assert!(
        (cpu[0] - 0.3).abs() < 0.02 && (cpu[1] - 0.25).abs() < 0.02,
        "{cpu:?}"
    );
    for (cpu, gpu) in cpu.iter().zip(&gpu) {
        assert!((cpu - gpu).abs() < 1e-3, "CPU {cpu} m, GPU {gpu} m");
    }
}

/// The collision's keys and summaries come back with its kernels, as many as last step's
/// pairs and some more (`expected_pair_count`), up to the broadphase's capacity: a step with
/// more pairs than that copies them all again. A block of 512 boxes face to face (about 5000
/// pairs) grows the capacity and goes; after three steps of a lone box on the plane (one pair)
/// it comes back, and that step's pairs and contacts are the CPU's. Without the second copy
/// the host sees only the first 1025 pairs.
#[test]
fn a_step_with_many_more_pairs_than_the_last_reads_them_all_back() {
    let _turn = gpu_common::context();
    let add_block = |world: &mut World| -> Vec<BodyHandle> {
        let mut block = Vec::new();
        for i in 0..8 {
            for j in 0..8 {
                for k in 0..8 {
                    let position = Vec3::new(i as f32, 0.5 + j as f32, k as f32);
                    let desc = BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)));
                    block.push(world.add_body(desc.position(position)).unwrap());
                }
            }
        }
        block
    };
    let run = |stages: &[Stage]| {
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        let lone =
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(-20.0, 0.5, 0.0));
        world.add_body(lone).unwrap();
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        let block = add_block(&mut world);
        world.try_step().unwrap();
        for body in block {
            world.remove_body(body).unwrap();
        }
        for _ in 0..3 {
            world.try_step().unwrap();
        }
        assert_eq!(world.stats().pairs, 1, "the lone box on the plane");
        add_block(&mut world);
        world.try_step().unwrap();
        let mut pairs: Vec<(u32, u32)> = world
            .contacts()
            .map(|(a, b, _)| (a.index(), b.index()))
            .collect();
        pairs.sort();
        (world.stats().pairs, pairs)
    };
    let (cpu_pairs, cpu_contacts) = run(&[]);
    let (gpu_pairs, gpu_contacts) = run(&Stage::ALL);
    assert!(
        cpu_pairs > 4000,
        "{cpu_pairs} pairs: the block's neighbours"
    );
    assert_eq!(gpu_pairs, cpu_pairs, "pairs");
    assert_eq!(gpu_contacts, cpu_contacts, "pairs with points");
}

/// A body removed and another added in its slot before the next step: the pairs of the slot
/// keep their keys, and the narrowphase must not move the old body's manifolds as the new
/// one's. A box rests on the ground; a taller one takes its slot at the same pose and is pushed
/// out to rest on its own base, on the CPU and with every stage on the GPU.
#[test]
fn a_body_added_in_a_removed_bodys_slot_gets_its_own_contacts() {
    let _turn = gpu_common::context();
    for executor in [Executor::Cpu, Executor::Gpu] {
        let mut world = awake_on_ground();
        let cube = BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::Y * 0.5);
        let first = world.add_body(cube).unwrap();
        world
            .set_stage_devices(StageDevices::all(executor))
            .unwrap();
        for _ in 0..60 {
            world.step();
        }
        let pose = world.pose(first).unwrap();
        world.remove_body(first).unwrap();
        let tall = BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.6, 0.5)))
            .position(pose.position)
            .rotation(pose.rotation);
        let second = world.add_body(tall).unwrap();
        assert_eq!(second.index(), first.index(), "the slot is reused");
        for _ in 0..60 {
            world.step();
        }
        let height = world.pose(second).unwrap().position.y;
        assert!(
            (height - 0.6).abs() < 5e-3,
            "{executor:?}: the tall box rests at y = {height}, not 0.6"
        );
    }
}

/// `StepStats::pairs_computed` counts the pairs whose pair functions ran, on either executor:
/// a box at rest moves its first manifold with it from then on (the manifold cache), a ball at
/// rest computes its own every step (spheres keep no cache), and a box in the air has no pair
/// until it lands.
#[test]
fn the_pairs_computed_are_those_the_manifold_cache_does_not_move() {
    let _turn = gpu_common::context();
    let executors: [&[Stage]; 3] = [&[], &[Stage::Narrowphase], &Stage::ALL];
    for stages in executors {
        let mut world = awake_on_ground();
        let cube = Shape::cuboid(Vec3::splat(0.5));
        world
            .add_body(BodyDesc::dynamic(cube.clone()).position(Vec3::new(0.0, 0.5, 0.0)))
            .unwrap();
        world
            .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(Vec3::new(3.0, 0.5, 0.0)))
            .unwrap();
        world
            .add_body(BodyDesc::dynamic(cube).position(Vec3::new(-3.0, 20.0, 0.0)))
            .unwrap();
        let mut devices = StageDevices::default();
        for &stage in stages {
            devices.set(stage, Executor::Gpu);
        }
        world.set_stage_devices(devices).unwrap();
        let computed: Vec<usize> = (0..20)
            .map(|_| {
                world.step();
                world.stats().pairs_computed
            })
            .collect();
        let mut expected = vec![1; 20];
        expected[0] = 2;
        assert_eq!(computed, expected, "{stages:?} on the GPU");
    }
}
