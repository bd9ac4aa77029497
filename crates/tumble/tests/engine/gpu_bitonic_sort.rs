//! Bitonic sort parity against the CPU twin (order by key, then value).

use crate::gpu_common;

use gpu_common::{LARGE, Random, SIZES, context};
use tumble::gpu::GpuVec;
use tumble::gpu::prims::bitonic_sort::{BitonicSort, bitonic_sort_cpu};

fn check(mut keys: Vec<u32>, mut values: Vec<u32>) {
    let context = context();
    let mut gpu_keys = GpuVec::from_slice(&context, "keys", &keys).expect("upload");
    let mut gpu_values = GpuVec::from_slice(&context, "values", &values).expect("upload");
    let mut sort = BitonicSort::new();
    context
        .submit_pass("bitonic sort", |pass| {
            sort.encode(&context, pass, &mut gpu_keys, &mut gpu_values)
        })
        .expect("encode");
    let sorted = (
        gpu_keys.download(&context).expect("download"),
        gpu_values.download(&context).expect("download"),
    );
    bitonic_sort_cpu(&mut keys, &mut values);
    assert_eq!(sorted, (keys, values), "{} pairs", sorted.0.len());
}

#[test]
fn bitonic_sort_matches_cpu() {
    for (seed, count) in SIZES.into_iter().chain([513, 1500, 4097]).enumerate() {
        let mut random = Random::new(200 + seed as u64);
        // Few distinct keys, so that ordering by value on ties is exercised.
        check(random.u32s_below(count, 100), random.u32s(count));
    }
}

#[test]
fn large_bitonic_sort_matches_cpu() {
    let mut random = Random::new(300);
    check(random.u32s(LARGE), (0..LARGE as u32).collect());
}
