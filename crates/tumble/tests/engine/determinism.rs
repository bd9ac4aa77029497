//! Same scene, same build → bitwise the same state, whatever the thread count; and a dumped
//! state loads and continues the run bitwise.
use tumble::math::{Quat, Vec3};
use tumble::scene::format::SceneJoint;
use tumble::scene::{Scene, builtin};
use tumble::{BodyDesc, JointKind, Motor, Shape, StepConfig, World};

fn run_in_pool(threads: usize, scene: &Scene, steps: usize) -> String {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut world = scene.build().unwrap();
        for _ in 0..steps {
            world.step();
        }
        Scene::from_world(&world).to_json()
    })
}

/// At 1.5k boxes the solver's widest stages hold several blocks, so several workers share
/// its steps (a smaller world's solve runs on one thread whatever the pool's size).
#[test]
fn falling_boxes_are_bitwise_identical_across_runs_and_thread_counts() {
    let scene = builtin("falling-boxes", 0.5).unwrap();
    let one = run_in_pool(1, &scene, 120);
    for threads in [1, 2, 4] {
        assert_same_dump(
            &format!("1 thread vs {threads}"),
            &one,
            &run_in_pool(threads, &scene, 120),
        );
    }
}

/// Compound pairs go through the child cache, built per pair in parallel: the thread count
/// must not show in the result.
#[test]
fn compounds_are_bitwise_identical_across_thread_counts() {
    let scene = builtin("compounds", 0.05).unwrap();
    let one = run_in_pool(1, &scene, 120);
    for threads in [2, 4] {
        assert_same_dump(
            &format!("1 thread vs {threads}"),
            &one,
            &run_in_pool(threads, &scene, 120),
        );
    }
}

fn run(world: &mut World, steps: usize) {
    for _ in 0..steps {
        world.step();
    }
}

#[test]
fn dump_at_step_50_then_load_and_run_50_equals_100_steps() {
    for (name, scale) in [
        ("falling-boxes", 0.05),
        ("stacked-boxes", 0.05),
        ("ragdolls", 0.05),
        ("convex-hulls", 0.05),
        ("convex-trimesh", 0.02),
        ("compounds", 0.05),
    ] {
        let scene = builtin(name, scale).unwrap();
        let mut straight = scene.build().unwrap();
        run(&mut straight, 100);

        let mut first_half = scene.build().unwrap();
        run(&mut first_half, 50);
        let dump = Scene::from_world(&first_half).to_json();
        let loaded = Scene::from_json(&dump).unwrap();
        // Compounds keep theirs per child pair, in the child contacts.
        assert!(
            !loaded.contacts.is_empty() || !loaded.child_contacts.is_empty(),
            "{name}: the dump carries the warm-start contacts"
        );
        let mut resumed = loaded.build().unwrap();
        run(&mut resumed, 50);

        assert_same_state(name, &straight, &resumed);
    }
}

/// Every joint kind at once: a hinged, motorized and limited arm hanging from a post, a
/// cone-twist link below it, a welded pair and a breakable joint that lets go, all landing on
/// the ground, so that joints and contacts are solved together.
fn jointed_scene() -> Scene {
    let mut scene = Scene::new(StepConfig::default());
    let body = |shape, position: Vec3| BodyDesc::dynamic(shape).position(position);
    let bar = Shape::cuboid(Vec3::new(0.4, 0.05, 0.05));
    scene.bodies = vec![
        BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)).name("ground"),
        BodyDesc::fixed(Shape::sphere(0.05)).position(Vec3::new(0.0, 2.0, 0.0)),
        body(bar, Vec3::new(0.4, 2.0, 0.0)),
        body(Shape::capsule(0.05, 0.3), Vec3::new(0.8, 1.65, 0.0)),
        body(Shape::cuboid(Vec3::splat(0.2)), Vec3::new(-1.0, 1.0, 0.0))
            .rotation(Quat::from_rotation_z(0.3)),
        body(Shape::sphere(0.15), Vec3::new(-1.0, 1.35, 0.0)),
        body(Shape::sphere(0.2), Vec3::new(1.5, 1.0, 0.5)).mass(5.0),
    ];
    let hinge = JointKind::Hinge {
        axis: Vec3::Z,
        limits: Some((-1.0, 0.2)),
        motor: Some(Motor {
            target_speed: -0.5,
            max_torque: 2.0,
        }),
    };
    let cone = JointKind::ConeTwist {
        axis: -Vec3::Y,
        swing_limit: 0.6,
        twist_limits: (-0.3, 0.3),
    };
    let mut breakable = SceneJoint::new(JointKind::Point, 1, 6, Vec3::new(1.5, 2.0, 0.5));
    breakable.break_impulse = Some(0.05);
    scene.joints = vec![
        SceneJoint::new(hinge, 1, 2, Vec3::new(0.0, 2.0, 0.0)),
        SceneJoint::new(cone, 2, 3, Vec3::new(0.8, 2.0, 0.0)),
        SceneJoint::new(JointKind::Fixed, 4, 5, Vec3::new(-1.0, 1.2, 0.0)),
        breakable,
    ];
    scene
}

#[test]
fn a_jointed_scene_dumps_and_continues_bitwise() {
    let scene = jointed_scene();
    let mut straight = scene.build().unwrap();
    run(&mut straight, 100);

    let mut first_half = scene.build().unwrap();
    run(&mut first_half, 50);
    let dump = Scene::from_world(&first_half).to_json();
    let loaded = Scene::from_json(&dump).unwrap();
    assert_eq!(loaded.joints.len(), 4);
    assert!(
        loaded.joints.iter().all(|joint| joint.state.is_some()),
        "the dump carries the joints' frames and impulses"
    );
    assert!(
        loaded.joints[3].state.is_some_and(|state| state.broken),
        "the breakable joint broke and the dump says so"
    );
    assert!(
        !loaded.contacts.is_empty(),
        "the welded pair rests on the ground"
    );
    let mut resumed = loaded.build().unwrap();
    run(&mut resumed, 50);

    assert_same_state("jointed scene", &straight, &resumed);
}

/// Boxes, capsules and spheres tumbling on a small landscape mesh: child manifolds (per
/// triangle) in the step.
fn landscape_scene() -> Scene {
    let landscape = tumble::scene::landscape::Landscape::with_cells(12);
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies = vec![BodyDesc::fixed(Shape::trimesh(landscape.mesh().unwrap()))];
    let shapes = [
        Shape::cuboid(Vec3::new(0.4, 0.3, 0.35)),
        Shape::capsule(0.2, 0.4),
        Shape::sphere(0.3),
    ];
    for i in 0..9 {
        let (x, z) = (-3.0 + 3.0 * (i % 3) as f32, -3.0 + 3.0 * (i / 3) as f32);
        let ground = landscape.height_at(x, z).unwrap();
        scene.bodies.push(
            BodyDesc::dynamic(shapes[i % 3].clone())
                .position(Vec3::new(x, ground + 0.8, z))
                .rotation(Quat::from_rotation_x(0.4 * i as f32)),
        );
    }
    scene
}

#[test]
fn a_landscape_scene_is_bitwise_identical_across_thread_counts_and_resumes_from_a_dump() {
    let scene = landscape_scene();
    let one = run_in_pool(1, &scene, 100);
    assert_same_dump(
        "landscape, 1 thread vs 4",
        &one,
        &run_in_pool(4, &scene, 100),
    );

    let mut straight = scene.build().unwrap();
    run(&mut straight, 100);
    let mut first_half = scene.build().unwrap();
    run(&mut first_half, 50);
    let dump = Scene::from_world(&first_half).to_json();
    let loaded = Scene::from_json(&dump).unwrap();
    assert!(
        !loaded.child_contacts.is_empty(),
        "the dump carries the per-triangle warm-start contacts"
    );
    let mut resumed = loaded.build().unwrap();
    run(&mut resumed, 50);
    assert_same_state("landscape", &straight, &resumed);
}

/// Fails with the first line where the two worlds' dumps differ.
fn assert_same_state(name: &str, expected: &World, actual: &World) {
    assert_same_dump(
        name,
        &Scene::from_world(expected).to_json(),
        &Scene::from_world(actual).to_json(),
    );
}

fn assert_same_dump(name: &str, expected: &str, actual: &str) {
    if let Some((line, (e, a))) = expected
        .lines()
        .zip(actual.lines())
        .enumerate()
        .find(|(_, (e, a))| e != a)
    {
        panic!("{name}: resumed run differs at dump line {line}: expected {e:?}, got {a:?}");
    }
    assert_eq!(
        expected.len(),
        actual.len(),
        "{name}: dumps differ in length"
    );
}

#[test]
fn json_keeps_every_f32_bit() {
    // Shortest round-trip printing and correctly rounded parsing (serde_json float_roundtrip).
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let values: Vec<f32> = (0..100_000)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            f32::from_bits(state as u32)
        })
        .filter(|v| v.is_finite())
        .collect();
    let text = serde_json::to_string(&values).unwrap();
    let back: Vec<f32> = serde_json::from_str(&text).unwrap();
    assert!(
        values
            .iter()
            .zip(&back)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
}
