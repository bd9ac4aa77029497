//! Reduce parity: min, max and sum of u32 and f32, bitwise equal to the CPU twin (which
//! follows the GPU's order of combination).

use crate::gpu_common;

use gpu_common::{LARGE, Random, SIZES, context};
use tumble::gpu::GpuVec;
use tumble::gpu::prims::reduce::{Reduce, ReduceOp, ReduceScalar, reduce_cpu};

const OPS: [ReduceOp; 3] = [ReduceOp::Min, ReduceOp::Max, ReduceOp::Sum];

fn reduce_on_gpu<T: ReduceScalar>(input: &[T], op: ReduceOp) -> T {
    let context = context();
    let source = GpuVec::from_slice(&context, "reduce input", input).expect("upload");
    let mut output = GpuVec::with_capacity(&context, "reduce output", 1).expect("alloc");
    let mut reduce = Reduce::new();
    context
        .submit_pass("reduce", |pass| {
            reduce.encode(&context, pass, &source, &mut output, op)
        })
        .expect("encode");
    output.download(&context).expect("download")[0]
}

/// Floats in [-1000, 1000) on a 2⁻¹⁰ grid: sums stay exact enough to be interesting and
/// never produce subnormals (which a GPU may flush to zero).
fn floats(random: &mut Random, count: usize) -> Vec<f32> {
    (0..count)
        .map(|_| (random.below(2_048_000) as f32 - 1_024_000.0) / 1024.0)
        .collect()
}

#[test]
fn u32_reductions_match_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        let input = Random::new(400 + seed as u64).u32s(count);
        for op in OPS {
            assert_eq!(
                reduce_on_gpu(&input, op),
                reduce_cpu(&input, op),
                "{op:?} of {count}"
            );
        }
    }
}

#[test]
fn f32_reductions_match_cpu_bitwise() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        let input = floats(&mut Random::new(500 + seed as u64), count);
        for op in OPS {
            let (gpu, cpu) = (reduce_on_gpu(&input, op), reduce_cpu(&input, op));
            assert_eq!(
                gpu.to_bits(),
                cpu.to_bits(),
                "{op:?} of {count}: {gpu} vs {cpu}"
            );
        }
    }
}

#[test]
fn large_reductions_match_cpu() {
    let integers = Random::new(600).u32s(LARGE);
    let input = floats(&mut Random::new(601), LARGE);
    for op in OPS {
        assert_eq!(reduce_on_gpu(&integers, op), reduce_cpu(&integers, op));
        assert_eq!(
            reduce_on_gpu(&input, op).to_bits(),
            reduce_cpu(&input, op).to_bits()
        );
    }
}
