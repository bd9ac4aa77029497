//! Stream compaction, fill and scatter parity against their CPU twins.

use crate::gpu_common;

use gpu_common::{LARGE, Random, SIZES, context};
use tumble::gpu::GpuVec;
use tumble::gpu::kernel::encode_all;
use tumble::gpu::prims::compact::{Compact, compact_cpu};
use tumble::gpu::prims::fill::{fill_cpu, fill_vec_dispatch};
use tumble::gpu::prims::scatter::{GpuScatter, scatter_cpu};

fn check_compaction(count: usize, seed: u64) {
    let context = context();
    let mut random = Random::new(seed);
    let values = random.u32s(count);
    let flags = random.u32s_below(count, 2);
    let values_gpu = GpuVec::from_slice(&context, "values", &values).expect("upload");
    let flags_gpu = GpuVec::from_slice(&context, "flags", &flags).expect("upload");
    // A stale total proves the empty case writes 0.
    let mut total = GpuVec::from_slice(&context, "total", &[12345u32]).expect("upload");
    let mut compacted = GpuVec::with_capacity(&context, "compacted", 0).expect("alloc");
    let mut compact = Compact::new();
    context
        .submit_pass("compact", |pass| {
            compact.encode(
                &context,
                pass,
                &values_gpu,
                &flags_gpu,
                &mut compacted,
                &mut total,
            )
        })
        .expect("encode");
    let expected = compact_cpu(&values, &flags);
    let kept = total.download(&context).expect("download")[0] as usize;
    assert_eq!(kept, expected.len(), "count of {count}");
    let output = compacted.download(&context).expect("download");
    assert_eq!(&output[..kept], &expected[..], "compaction of {count}");
}

#[test]
fn compaction_matches_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        check_compaction(count, 700 + seed as u64);
    }
}

#[test]
fn large_compaction_matches_cpu() {
    check_compaction(LARGE, 710);
}

#[test]
fn fill_matches_cpu() {
    let context = context();
    for count in SIZES.into_iter().chain([LARGE]) {
        let mut expected = vec![0.0f32; count];
        let mut vector = GpuVec::from_slice(&context, "fill", &expected).expect("upload");
        let dispatches = fill_vec_dispatch(&context, &vector, -1.5f32).expect("fill");
        context.submit_pass("fill", |pass| encode_all(pass, &dispatches));
        fill_cpu(&mut expected, -1.5);
        assert_eq!(vector.download(&context).expect("download"), expected);
    }
}

/// 65 536 × 256 + 1 words need 65 537 workgroups: more than one dispatch dimension holds,
/// so the grid is split over x and y and every word must still be written exactly once.
#[test]
fn fill_splits_dispatches_past_65535_workgroups() {
    let context = context();
    let count = 65_536 * 256 + 1;
    let mut vector = GpuVec::from_slice(&context, "fill", &vec![0u32; count]).expect("upload");
    let dispatches = fill_vec_dispatch(&context, &vector, 7u32).expect("fill");
    context.submit_pass("fill", |pass| encode_all(pass, &dispatches));
    let filled = vector.download(&context).expect("download");
    assert_eq!(filled.len(), count);
    assert!(filled.iter().all(|&word| word == 7));
}

/// Records of 1, 4 and 12 words to distinct random places of a larger array, the rest kept.
#[test]
fn scatter_matches_cpu() {
    fn check<T: bytemuck::Pod + PartialEq + std::fmt::Debug>(
        make: impl Fn(&mut Random) -> T,
        count: usize,
        seed: u64,
    ) {
        let context = context();
        let mut random = Random::new(seed);
        let length = 2 * count + 3;
        let mut expected: Vec<T> = (0..length).map(|_| make(&mut random)).collect();
        // Distinct indices: a random subset of 0..length, in random order.
        let mut places: Vec<u32> = (0..length as u32).collect();
        for i in (1..places.len()).rev() {
            places.swap(i, random.below(i as u32 + 1) as usize);
        }
        places.truncate(count);
        let values: Vec<T> = (0..count).map(|_| make(&mut random)).collect();
        let mut destination = GpuVec::from_slice(&context, "destination", &expected).unwrap();
        let indices = GpuVec::from_slice(&context, "indices", &places).unwrap();
        let values_gpu = GpuVec::from_slice(&context, "values", &values).unwrap();
        let mut scatter = GpuScatter::new(&context);
        context.submit_pass("scatter", |pass| {
            scatter.encode(&context, pass, &indices, &values_gpu, &destination)
        });
        scatter_cpu(&places, &values, &mut expected);
        assert_eq!(
            destination.download(&context).unwrap(),
            expected,
            "{count} records"
        );
    }
    for (seed, count) in SIZES.into_iter().enumerate() {
        let seed = 900 + seed as u64;
        check(|random| random.next_u32(), count, seed);
        check(
            |random| [random.next_u32(); 4].map(|w| w ^ random.next_u32()),
            count,
            seed,
        );
        check(|random| [0u32; 12].map(|_| random.next_u32()), count, seed);
    }
}
