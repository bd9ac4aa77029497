//! Reduction (min, max, sum) of u32 or f32 to a single value, on the GPU and the CPU.
//!
//! Blocks of [`REDUCE_BLOCK`] values reduce to one, level after level, until one is left
//! (one dispatch per level: 2 for 1M values). The combination order is fixed and the CPU twin
//! follows it, so even float sums agree bitwise. An input past one storage binding
//! ([`GpuVec::windowed`]) is reduced a window of whole blocks at a time, each window's blocks
//! writing their slots of the next level: the same blocks, the same order.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::{GpuVec, Window, windows};
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};

const ITEMS_PER_THREAD: u32 = 4;
/// Values reduced by one workgroup.
pub const REDUCE_BLOCK: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;

const WGSL: &str = include_str!("reduce.wgsl");
const BINDINGS: [Binding; 3] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReduceOp {
    Min,
    Max,
    Sum,
}

/// A scalar the reduction handles, with its WGSL spelling.
pub trait ReduceScalar: Pod + PartialOrd {
    const WGSL_TYPE: &'static str;
    /// WGSL expression of the identity of `op`.
    fn wgsl_identity(op: ReduceOp) -> &'static str;
    fn identity(op: ReduceOp) -> Self;
    fn combine(op: ReduceOp, a: Self, b: Self) -> Self;
}

impl ReduceScalar for u32 {
    const WGSL_TYPE: &'static str = "u32";
    fn wgsl_identity(op: ReduceOp) -> &'static str {
        match op {
            ReduceOp::Min => "0xffffffffu",
            ReduceOp::Max | ReduceOp::Sum => "0u",
        }
    }
    fn identity(op: ReduceOp) -> Self {
        match op {
            ReduceOp::Min => u32::MAX,
            ReduceOp::Max | ReduceOp::Sum => 0,
        }
    }
    fn combine(op: ReduceOp, a: Self, b: Self) -> Self {
        match op {
            ReduceOp::Min => a.min(b),
            ReduceOp::Max => a.max(b),
            // WGSL's u32 addition wraps.
            ReduceOp::Sum => a.wrapping_add(b),
        }
    }
}

impl ReduceScalar for f32 {
    const WGSL_TYPE: &'static str = "f32";
    fn wgsl_identity(op: ReduceOp) -> &'static str {
        // WGSL has no infinity literal; the bit patterns of ±∞.
        match op {
            ReduceOp::Min => "bitcast<f32>(0x7f800000u)",
            ReduceOp::Max => "bitcast<f32>(0xff800000u)",
            ReduceOp::Sum => "0.0",
        }
    }
    fn identity(op: ReduceOp) -> Self {
        match op {
            ReduceOp::Min => f32::INFINITY,
            ReduceOp::Max => f32::NEG_INFINITY,
            ReduceOp::Sum => 0.0,
        }
    }
    fn combine(op: ReduceOp, a: Self, b: Self) -> Self {
        match op {
            ReduceOp::Min => a.min(b),
            ReduceOp::Max => a.max(b),
            ReduceOp::Sum => a + b,
        }
    }
}

/// Mirrors `ReduceParams` in `reduce.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ReduceParams {
    pub count: u32,
    pub first_block: u32,
    pub padding1: u32,
    pub padding2: u32,
}
const _: () = assert!(size_of::<ReduceParams>() == 16);

pub fn wgsl<T: ReduceScalar>(op: ReduceOp) -> Source {
    let combine = match op {
        ReduceOp::Min => "min(a, b)",
        ReduceOp::Max => "max(a, b)",
        ReduceOp::Sum => "a + b",
    };
    let operation = format!(
        "alias Scalar = {};\nfn identity() -> Scalar {{ return {}; }}\n\
         fn combine(a: Scalar, b: Scalar) -> Scalar {{ return {combine}; }}\n",
        T::WGSL_TYPE,
        T::wgsl_identity(op),
    );
    Source::new()
        .constant_u32("ITEMS_PER_THREAD", ITEMS_PER_THREAD)
        .snippet("reduce operation", &operation)
        .snippet("reduce.wgsl", WGSL)
}

/// CPU twin, in the GPU's order of combination.
pub fn reduce_cpu<T: ReduceScalar>(input: &[T], op: ReduceOp) -> T {
    let block = REDUCE_BLOCK as usize;
    let threads = WORKGROUP_SIZE as usize;
    let mut level = input.to_vec();
    loop {
        let blocks = level.len().div_ceil(block).max(1);
        let next: Vec<T> = (0..blocks)
            .map(|index| {
                let mut partial: Vec<T> = (0..threads)
                    .map(|thread| {
                        (0..ITEMS_PER_THREAD as usize)
                            .filter_map(|item| level.get(index * block + item * threads + thread))
                            .fold(T::identity(op), |a, &b| T::combine(op, a, b))
                    })
                    .collect();
                let mut stride = threads / 2;
                while stride > 0 {
                    for thread in 0..stride {
                        partial[thread] = T::combine(op, partial[thread], partial[thread + stride]);
                    }
                    stride /= 2;
                }
                partial[0]
            })
            .collect();
        if blocks == 1 {
            return next[0];
        }
        level = next;
    }
}

/// A reduction of one input buffer into a one-element output, built once.
#[derive(Debug, Default)]
pub struct Reduce {
    cached: Option<(ReduceKey, Vec<Dispatch>)>,
}

/// What the cached dispatches were built for: input, output, count, operation.
type ReduceKey = (wgpu::Buffer, wgpu::Buffer, usize, ReduceOp);

impl Reduce {
    pub fn new() -> Self {
        Self::default()
    }

    /// Encodes `output[0] = op(input)` (the identity for an empty input); `output` gets
    /// length 1.
    pub fn encode<T: ReduceScalar>(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        input: &GpuVec<T>,
        output: &mut GpuVec<T>,
        op: ReduceOp,
    ) -> Result<(), GpuError> {
        output.resize(context, 1)?;
        let key = (
            input.buffer().clone(),
            output.buffer().clone(),
            input.len(),
            op,
        );
        let dispatches = match &mut self.cached {
            Some((cached_key, dispatches)) if *cached_key == key => dispatches,
            cached => {
                let dispatches = reduce_dispatches::<T>(context, &key.0, &key.1, key.2, op)?;
                &mut cached.insert((key, dispatches)).1
            }
        };
        encode_all(pass, dispatches);
        Ok(())
    }
}

fn reduce_dispatches<T: ReduceScalar>(
    context: &GpuContext,
    input: &wgpu::Buffer,
    output: &wgpu::Buffer,
    count: usize,
    op: ReduceOp,
) -> Result<Vec<Dispatch>, GpuError> {
    let kernel = Kernel::new(context, "reduce", &wgsl::<T>(op), "reduce", &BINDINGS);
    // Counts of the inputs of each level; the last level has one block.
    let mut counts = vec![count];
    while counts[counts.len() - 1] > REDUCE_BLOCK as usize {
        let below = counts[counts.len() - 1];
        counts.push(below.div_ceil(REDUCE_BLOCK as usize));
    }
    // Each level's windows; an empty input is one empty window, whose block writes the
    // identity.
    let level_windows: Vec<Vec<Window>> = counts
        .iter()
        .map(|&level_count| {
            if level_count == 0 {
                Ok(vec![Window { first: 0, len: 0 }])
            } else {
                windows(context, level_count, size_of::<T>(), REDUCE_BLOCK as usize)
            }
        })
        .collect::<Result<_, _>>()?;
    let blocks: Vec<ReduceParams> = level_windows
        .iter()
        .flatten()
        .map(|window| ReduceParams {
            count: window.len as u32,
            first_block: (window.first / REDUCE_BLOCK as usize) as u32,
            padding1: 0,
            padding2: 0,
        })
        .collect();
    let slots = UniformSlots::new(context, "reduce params", &blocks);
    let scratch: Vec<GpuVec<T>> = counts[1..]
        .iter()
        .map(|&level_count| GpuVec::with_capacity(context, "reduce partial", level_count))
        .collect::<Result<_, _>>()?;
    let levels = counts.len();
    let element = size_of::<T>();
    let mut dispatches = Vec::new();
    for (level, windows) in level_windows.iter().enumerate() {
        let source = if level == 0 {
            input
        } else {
            scratch[level - 1].buffer()
        };
        let destination = if level + 1 == levels {
            output
        } else {
            scratch[level].buffer()
        };
        for window in windows {
            let bind_group = kernel.bind(
                context,
                &[
                    slots.binding(dispatches.len()),
                    window.binding(source, element),
                    destination.as_entire_buffer_binding(),
                ],
            );
            dispatches
                .push(kernel.dispatch(bind_group, workgroups_for(window.len, REDUCE_BLOCK).max(1)));
        }
    }
    Ok(dispatches)
}
