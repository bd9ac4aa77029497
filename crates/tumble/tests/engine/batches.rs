//! The batches the solver used, as the viewer shows them: each manifold's batch agrees with the
//! histogram, and no batch (but the overflow one) holds two constraints on one dynamic body.
use std::collections::HashSet;
use tumble::scene::builtin;

#[test]
fn contact_batches_match_the_histogram_and_share_no_dynamic_body() {
    let mut world = builtin("stacked-boxes", 0.1).unwrap().build().unwrap();
    for _ in 0..3 {
        world.step();
    }
    let histogram = world.stats().batch_histogram.clone();
    assert!(histogram.len() > 1, "a resting stack needs several batches");
    let mut counts = vec![0u32; histogram.len()];
    let mut bodies_in_batch = vec![HashSet::new(); histogram.len()];
    for (a, b, batch) in world.contact_batches() {
        counts[batch as usize] += 1;
        for body in [a, b] {
            if world.is_dynamic(body).unwrap() {
                assert!(
                    bodies_in_batch[batch as usize].insert(body),
                    "{body:?} twice in batch {batch}"
                );
            }
        }
    }
    assert_eq!(counts, histogram);
    assert_eq!(world.contact_batches().count(), world.contacts().count());
}
