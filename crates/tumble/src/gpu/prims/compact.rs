//! Stream compaction: the values whose flag is 1, in input order, and their number, which
//! stays on the GPU (for an indirect dispatch or a later readback).
//!
//! Exclusive scan of the flags gives each kept value its slot; one more dispatch moves it
//! there. The output has room for every input (nothing can be dropped).
//!
//! Past one storage binding ([`GpuVec::windowed`] buffers) the scan runs by windows, and the
//! move runs once per window of the input and window of the output at or before it (a value's
//! slot is never after its index): each run writes the values whose slot lies in its output
//! window.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::{GpuVec, windows};
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
    pub destination_first: u32,
    pub destination_count: u32,
    pub writes_total: u32,
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
        return fill_dispatch(context, &buffers[3], 1, 0);
    }
    let positions = GpuVec::<u32>::windowed(context, "compaction positions", count)?;
    let mut dispatches = scan_dispatches(
        context,
        &buffers[1],
        positions.buffer(),
        count,
        ScanKind::Exclusive,
    )?;
    let kernel = Kernel::new(context, "compact", &wgsl(), "scatter_kept", &BINDINGS);
    let windows = windows(context, count, 4, WORKGROUP_SIZE as usize)?;
    let last = windows.len() - 1;
    // (input window, output window), each output window at or before the input's.
    let runs: Vec<(usize, usize)> = (0..windows.len())
        .flat_map(|input| (0..=input).map(move |output| (input, output)))
        .collect();
    let blocks: Vec<CompactParams> = runs
        .iter()
        .map(|&(input, output)| CompactParams {
            count: windows[input].len as u32,
            destination_first: windows[output].first as u32,
            destination_count: windows[output].len as u32,
            writes_total: u32::from(input == last && output == 0),
        })
        .collect();
    let slots = UniformSlots::new(context, "compact params", &blocks);
    for (slot, &(input, output)) in runs.iter().enumerate() {
        let (input, output) = (windows[input], windows[output]);
        let bind_group = kernel.bind(
            context,
            &[
                slots.binding(slot),
                input.binding(&buffers[1], 4),
                input.binding(positions.buffer(), 4),
                input.binding(&buffers[0], 4),
                output.binding(&buffers[2], 4),
                buffers[3].as_entire_buffer_binding(),
            ],
        );
        dispatches.push(kernel.dispatch(bind_group, workgroups_for(input.len, WORKGROUP_SIZE)));
    }
    Ok(dispatches)
}
