//! Bitonic sort of u32 key-value pairs in place, for small arrays and as the particle
//! pipeline's alternative to radix sort (the talk names both).
//!
//! Pairs are ordered by key, then by value: the order is total, so the result does not
//! depend on the network's exchanges, and when values are the input positions (as for the
//! particles) equal keys keep their input order, as with the stable radix sort. For n
//! elements it takes about log²(n)/2 − 36 dispatches past 512 (77 for 2²⁰): radix sort is
//! the faster choice for large arrays.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};

/// Elements sorted in workgroup memory by one workgroup.
const LOCAL_BLOCK: u32 = 2 * WORKGROUP_SIZE;

const WGSL: &str = include_str!("bitonic_sort.wgsl");
const BINDINGS: [Binding; 3] = [
    Binding::Uniform,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `BitonicParams` in `bitonic_sort.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BitonicParams {
    pub count: u32,
    pub flip_block: u32,
    pub distance: u32,
    pub padding: u32,
}
const _: () = assert!(size_of::<BitonicParams>() == 16);

pub fn wgsl() -> Source {
    Source::new().snippet("bitonic_sort.wgsl", WGSL)
}

/// CPU twin: the same total order.
pub fn bitonic_sort_cpu(keys: &mut [u32], values: &mut [u32]) {
    let mut pairs: Vec<(u32, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.sort_unstable();
    for ((key, value), (sorted_key, sorted_value)) in keys.iter_mut().zip(values).zip(pairs) {
        *key = sorted_key;
        *value = sorted_value;
    }
}

/// The bitonic sort of one pair of buffers, built once and encoded every step.
#[derive(Debug, Default)]
pub struct BitonicSort {
    cached: Option<(BitonicKey, Vec<Dispatch>)>,
}

/// What the cached dispatches were built for: [keys, values] and the count.
type BitonicKey = ([wgpu::Buffer; 2], usize);

impl BitonicSort {
    pub fn new() -> Self {
        Self::default()
    }

    /// Encodes an in-place sort of the first `keys.len()` pairs.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        keys: &mut GpuVec<u32>,
        values: &mut GpuVec<u32>,
    ) -> Result<(), GpuError> {
        debug_assert_eq!(keys.len(), values.len(), "one value per key");
        let key = ([keys.buffer().clone(), values.buffer().clone()], keys.len());
        let dispatches = match &mut self.cached {
            Some((cached_key, dispatches)) if *cached_key == key => dispatches,
            cached => {
                let dispatches = bitonic_dispatches(context, &key.0, key.1);
                &mut cached.insert((key, dispatches)).1
            }
        };
        encode_all(pass, dispatches);
        Ok(())
    }
}

/// The steps for `count` pairs in `buffers` = [keys, values].
pub fn bitonic_dispatches(
    context: &GpuContext,
    buffers: &[wgpu::Buffer; 2],
    count: usize,
) -> Vec<Dispatch> {
    if count < 2 {
        return Vec::new();
    }
    let source = wgsl();
    let sort_local = Kernel::new(
        context,
        "bitonic sort local",
        &source,
        "sort_local",
        &BINDINGS,
    );
    let merge_local = Kernel::new(
        context,
        "bitonic merge local",
        &source,
        "merge_local",
        &BINDINGS,
    );
    let merge_global = Kernel::new(
        context,
        "bitonic merge global",
        &source,
        "merge_global",
        &BINDINGS,
    );
    let padded = count.next_power_of_two() as u32;
    let step = |flip_block: u32, distance: u32| BitonicParams {
        count: count as u32,
        flip_block,
        distance,
        padding: 0,
    };
    // (kernel, parameters) in order.
    let mut steps: Vec<(&Kernel, BitonicParams)> = vec![(&sort_local, step(0, 0))];
    let mut block = 2 * LOCAL_BLOCK;
    while block <= padded {
        steps.push((&merge_global, step(block, 0)));
        let mut distance = block / 4;
        while distance >= LOCAL_BLOCK {
            steps.push((&merge_global, step(0, distance)));
            distance /= 2;
        }
        steps.push((&merge_local, step(0, 0)));
        block *= 2;
    }
    let blocks: Vec<BitonicParams> = steps.iter().map(|&(_, params)| params).collect();
    let slots = UniformSlots::new(context, "bitonic params", &blocks);
    let local_groups = workgroups_for(count, LOCAL_BLOCK);
    let global_groups = workgroups_for(padded as usize / 2, WORKGROUP_SIZE);
    steps
        .iter()
        .enumerate()
        .map(|(slot, &(kernel, _))| {
            let bind_group = kernel.bind(
                context,
                &[
                    slots.binding(slot),
                    buffers[0].as_entire_buffer_binding(),
                    buffers[1].as_entire_buffer_binding(),
                ],
            );
            let groups = if std::ptr::eq(kernel, &merge_global) {
                global_groups
            } else {
                local_groups
            };
            kernel.dispatch(bind_group, groups)
        })
        .collect()
}
