//! Radix sort parity (u32 and u64 keys) against the CPU twin, and stability.

use crate::gpu_common;

use gpu_common::{LARGE, Random, SIZES, context};
use tumble::gpu::GpuVec;
use tumble::gpu::prims::radix_sort::{RadixKey, RadixSort, SortPath, radix_sort_cpu};

/// The paths this adapter runs: every sort below is checked on each.
fn paths() -> Vec<SortPath> {
    let context = context();
    [SortPath::Baseline, SortPath::Subgroups]
        .into_iter()
        .filter(|path| path.runs_on(&context))
        .collect()
}

/// The sort on every path this adapter runs; panics unless all paths agree.
fn sort_on_gpu<K: RadixKey>(keys: &[K], values: &[u32], key_bits: u32) -> (Vec<K>, Vec<u32>) {
    let mut results = paths()
        .into_iter()
        .map(|path| (path, sort_on_gpu_path(path, keys, values, key_bits)));
    let (_, first) = results.next().expect("the baseline path runs everywhere");
    for (path, result) in results {
        assert!(result == first, "{path:?} differs from the baseline");
    }
    first
}

fn sort_on_gpu_path<K: RadixKey>(
    path: SortPath,
    keys: &[K],
    values: &[u32],
    key_bits: u32,
) -> (Vec<K>, Vec<u32>) {
    let context = context();
    let keys_in = GpuVec::from_slice(&context, "keys", keys).expect("upload");
    let values_in = GpuVec::from_slice(&context, "values", values).expect("upload");
    let mut keys_out = GpuVec::with_capacity(&context, "sorted keys", 0).expect("alloc");
    let mut values_out = GpuVec::with_capacity(&context, "sorted values", 0).expect("alloc");
    let mut sort = RadixSort::on(path);
    context
        .submit_pass("radix sort", |pass| {
            sort.encode(
                &context,
                pass,
                (&keys_in, &values_in),
                (&mut keys_out, &mut values_out),
                key_bits,
            )
        })
        .expect("encode");
    (
        keys_out.download(&context).expect("download"),
        values_out.download(&context).expect("download"),
    )
}

fn indices(count: usize) -> Vec<u32> {
    (0..count as u32).collect()
}

#[test]
fn u32_keys_match_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        let keys = Random::new(seed as u64).u32s(count);
        let values = indices(count);
        assert_eq!(
            sort_on_gpu(&keys, &values, 32),
            radix_sort_cpu(&keys, &values),
            "{count} keys"
        );
    }
}

#[test]
fn u64_pair_keys_match_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        let mut random = Random::new(50 + seed as u64);
        let keys: Vec<u64> = (0..count).map(|_| random.next_u64()).collect();
        let values = indices(count);
        assert_eq!(
            sort_on_gpu(&keys, &values, 64),
            radix_sort_cpu(&keys, &values),
            "{count} keys"
        );
    }
}

#[test]
fn large_u32_sort_matches_cpu() {
    let keys = Random::new(9).u32s(LARGE);
    let values = Random::new(10).u32s(LARGE);
    assert_eq!(
        sort_on_gpu(&keys, &values, 32),
        radix_sort_cpu(&keys, &values)
    );
}

#[test]
fn large_u64_sort_matches_cpu() {
    // Pair keys as the broadphase makes them: (smaller body index << 32) | larger index.
    let mut random = Random::new(11);
    let keys: Vec<u64> = (0..LARGE)
        .map(|_| {
            let a = random.below(100_000);
            let b = random.below(100_000);
            (u64::from(a.min(b)) << 32) | u64::from(a.max(b))
        })
        .collect();
    let values = indices(LARGE);
    assert_eq!(
        sort_on_gpu(&keys, &values, 64),
        radix_sort_cpu(&keys, &values)
    );
}

/// Equal keys keep their input order: with values = input positions, each run of equal keys
/// has increasing values. An odd number of passes (18 key bits: 3) is covered too.
#[test]
fn radix_sort_is_stable() {
    let count = 70_001;
    let keys = Random::new(12).u32s_below(count, 5);
    let (sorted_keys, sorted_values) = sort_on_gpu(&keys, &indices(count), 18);
    for pair in sorted_keys
        .iter()
        .zip(&sorted_values)
        .collect::<Vec<_>>()
        .windows(2)
    {
        let ((key_a, value_a), (key_b, value_b)) = (pair[0], pair[1]);
        assert!(key_a < key_b || (key_a == key_b && value_a < value_b));
    }
    assert_eq!(
        (sorted_keys, sorted_values),
        radix_sort_cpu(&keys, &indices(count))
    );
}

#[test]
fn key_bits_limit_the_passes() {
    // Keys below 2^10 sorted with 10 key bits (2 passes) and with 0 (a copy).
    let keys = Random::new(13).u32s_below(3000, 1 << 10);
    let values = indices(3000);
    assert_eq!(
        sort_on_gpu(&keys, &values, 10),
        radix_sort_cpu(&keys, &values)
    );
    assert_eq!(sort_on_gpu(&keys, &values, 0), (keys.clone(), values));
}
