//! Stream compaction: the values whose flag is 1, in input order, and their number, which
//! stays on the GPU (for an indirect dispatch or a later readback).
//!
//! Exclusive scan of the flags gives each kept value its slot; one more dispatch moves it
//! there. The output has room for every input (nothing can be dropped).

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::fill::fill_dispatch;
use crate::gpu::prims::scan::{ScanKind, scan_dispatches};

const WGSL: &str = include_str!("compact.wgsl");
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `CompactParams` in `compact.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CompactParams {
    pub count: u32,
    pub padding0: u32,
    pub padding1: u32,
    pub padding2: u32,
}
const _: () = assert!(size_of::<CompactParams>() == 16);

pub fn wgsl() -> Source {
    Source::new().snippet("compact.wgsl", WGSL)
}

/// CPU twin.
pub fn compact_cpu(values: &[u32], flags: &[u32]) -> Vec<u32> {
    values
        .iter()
        .zip(flags)
        .filter(|&(_, &flag)| flag != 0)
        .map(|(&value, _)| value)
        .collect()
}

type CompactKey = ([wgpu::Buffer; 4], usize);

/// Compaction of one set of buffers, built once.
#[derive(Debug, Default)]
pub struct Compact {
    cached: Option<(CompactKey, Vec<Dispatch>)>,
}

impl Compact {
    pub fn new() -> Self {
        Self::default()
    }

    /// Encodes `compacted[..total[0]]` = the `values` whose `flags` entry is 1 (flags are 0
    /// or 1). `compacted` is resized to `values.len()`, `total` to 1; only the first
    /// `total[0]` elements of `compacted` are meaningful.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        values: &GpuVec<u32>,
        flags: &GpuVec<u32>,
        compacted: &mut GpuVec<u32>,
        total: &mut GpuVec<u32>,
    ) -> Result<(), GpuError> {
        debug_assert_eq!(values.len(), flags.len(), "one flag per value");
        compacted.resize(context, values.len())?;
        total.resize(context, 1)?;
        let key = (
            [
                values.buffer().clone(),
                flags.buffer().clone(),
                compacted.buffer().clone(),
                total.buffer().clone(),
            ],
            values.len(),
        );
        let dispatches = match &mut self.cached {
            Some((cached_key, dispatches)) if *cached_key == key => dispatches,
            cached => {
                let dispatches = compact_dispatches(context, &key.0, key.1)?;
                &mut cached.insert((key, dispatches)).1
            }
        };
        encode_all(pass, dispatches);
        Ok(())
    }
}

/// `buffers` = [values, flags, compacted, total].
fn compact_dispatches(
    context: &GpuContext,
    buffers: &[wgpu::Buffer; 4],
    count: usize,
) -> Result<Vec<Dispatch>, GpuError> {
    if count == 0 {
        return Ok(vec![fill_dispatch(context, &buffers[3], 1, 0)?]);
    }
    let positions = GpuVec::<u32>::with_capacity(context, "compaction positions", count)?;
    let mut dispatches = scan_dispatches(
        context,
        &buffers[1],
        positions.buffer(),
        count,
        ScanKind::Exclusive,
    )?;
    let kernel = Kernel::new(context, "compact", &wgsl(), "scatter_kept", &BINDINGS);
    let slots = UniformSlots::new(
        context,
        "compact params",
        &[CompactParams {
            count: count as u32,
            padding0: 0,
            padding1: 0,
            padding2: 0,
        }],
    );
    let bind_group = kernel.bind(
        context,
        &[
            slots.binding(0),
            buffers[1].as_entire_buffer_binding(),
            positions.whole(),
            buffers[0].as_entire_buffer_binding(),
            buffers[2].as_entire_buffer_binding(),
            buffers[3].as_entire_buffer_binding(),
        ],
    );
    dispatches.push(kernel.dispatch(bind_group, workgroups_for(count, WORKGROUP_SIZE)));
    Ok(dispatches)
}
