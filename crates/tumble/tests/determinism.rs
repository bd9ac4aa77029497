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
    assert_eq!(one, run_in_pool(1, &scene, 120), "two 1-thread runs differ");
    assert_eq!(
        one,
        run_in_pool(2, &scene, 120),
        "1-thread and 2-thread runs differ"
    );
    assert_eq!(
        one,
        run_in_pool(4, &scene, 120),
        "1-thread and 4-thread runs differ"
    );
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

        assert_eq!(
            Scene::from_world(&straight).to_json(),
            Scene::from_world(&resumed).to_json(),
            "{name}: resumed run differs"
        );
    }
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
