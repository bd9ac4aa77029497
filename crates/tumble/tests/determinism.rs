//! Same scene, same build → bitwise the same state, whatever the thread count; and a dumped
//! state loads and continues the run bitwise.
use tumble::World;
use tumble::scene::{Scene, builtin};

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

#[test]
fn falling_boxes_are_bitwise_identical_across_runs_and_thread_counts() {
    let scene = builtin("falling-boxes", 0.05).unwrap();
    let one = run_in_pool(1, &scene, 120);
    for threads in [1, 2, 4] {
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
    for (name, scale) in [("falling-boxes", 0.05), ("stacked-boxes", 0.05)] {
        let scene = builtin(name, scale).unwrap();
        let mut straight = scene.build().unwrap();
        run(&mut straight, 100);

        let mut first_half = scene.build().unwrap();
        run(&mut first_half, 50);
        let dump = Scene::from_world(&first_half).to_json();
        let loaded = Scene::from_json(&dump).unwrap();
        assert!(
            !loaded.contacts.is_empty(),
            "{name}: the dump carries the warm-start contacts"
        );
        let mut resumed = loaded.build().unwrap();
        run(&mut resumed, 50);

        assert_same_state(name, &straight, &resumed);
    }
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
