//! Exclusive and inclusive prefix sums of u32 (wrapping), on the GPU and the CPU.
//!
//! Reduce-then-scan: each level sums blocks of [`SCAN_BLOCK`] elements into the level above
//! until one block is left; that block is scanned, and each level below is scanned block by
//! block starting from the scanned sum of its block. 2·levels − 1 dispatches (3 for 1M
//! elements, 5 for 64M); no workgroup ever waits for another, so any adapter runs it.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};

/// Elements each thread scans.
const ITEMS_PER_THREAD: u32 = 4;
/// Elements per workgroup (one block).
pub const SCAN_BLOCK: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;

const WGSL: &str = include_str!("scan.wgsl");
const BINDINGS: [Binding; 4] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
];

/// Whether element i's own value is part of output i.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ScanKind {
    /// out[i] = in[0] + … + in[i − 1]; out[0] = 0.
    Exclusive,
    /// out[i] = in[0] + … + in[i].
    Inclusive,
}

/// Mirrors `ScanParams` in `scan.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ScanParams {
    pub count: u32,
    pub inclusive: u32,
    pub has_parent: u32,
    pub padding: u32,
}
const _: () = assert!(size_of::<ScanParams>() == 16);

/// The scan's WGSL, for the layout test and for kernels that embed it.
pub fn wgsl() -> Source {
    Source::new()
        .constant_u32("ITEMS_PER_THREAD", ITEMS_PER_THREAD)
        .snippet("scan.wgsl", WGSL)
}

/// CPU twin: the same sums, sequentially.
pub fn scan_cpu(input: &[u32], kind: ScanKind) -> Vec<u32> {
    let mut running = 0u32;
    input
        .iter()
        .map(|&value| {
            let before = running;
            running = running.wrapping_add(value);
            match kind {
                ScanKind::Exclusive => before,
                ScanKind::Inclusive => running,
            }
        })
        .collect()
}

/// The dispatches that scan `count` u32 of `source` into `destination` (distinct buffers).
/// Scratch for the block sums is allocated here and kept alive by the bind groups, so the
/// list is self-contained: build it once, encode it every step.
pub fn scan_dispatches(
    context: &GpuContext,
    source: &wgpu::Buffer,
    destination: &wgpu::Buffer,
    count: usize,
    kind: ScanKind,
) -> Result<Vec<Dispatch>, GpuError> {
    if count == 0 {
        return Ok(Vec::new());
    }
    let wgsl = wgsl();
    let reduce = Kernel::new(context, "scan reduce", &wgsl, "reduce_blocks", &BINDINGS);
    let scan = Kernel::new(context, "scan blocks", &wgsl, "scan_blocks", &BINDINGS);
    // Level k's input buffer and count; level 0 is the caller's.
    let mut counts = vec![count];
    while *counts.last().unwrap_or(&1) > SCAN_BLOCK as usize {
        let below = counts[counts.len() - 1];
        counts.push(below.div_ceil(SCAN_BLOCK as usize));
    }
    let levels = counts.len();
    // reduced[k] holds level k's input for k ≥ 1 (the block sums of level k − 1),
    // scanned[k] its exclusive scan.
    let mut reduced = Vec::with_capacity(levels);
    let mut scanned = Vec::with_capacity(levels);
    for &level_count in &counts[1..] {
        reduced.push(GpuVec::<u32>::with_capacity(
            context,
            "scan block sums",
            level_count,
        )?);
        scanned.push(GpuVec::<u32>::with_capacity(
            context,
            "scan block offsets",
            level_count,
        )?);
    }
    let dummy = GpuVec::<u32>::with_capacity(context, "scan no parent", 1)?;
    // Slots: reduce of levels 0..levels-1, then scans from the top level down to 0.
    let mut blocks = Vec::new();
    for &level_count in &counts[..levels - 1] {
        blocks.push(params(level_count, false, false));
    }
    for level in (0..levels).rev() {
        let inclusive = level == 0 && kind == ScanKind::Inclusive;
        blocks.push(params(counts[level], inclusive, level + 1 < levels));
    }
    let slots = UniformSlots::new(context, "scan params", &blocks);
    let input = |level: usize| -> &wgpu::Buffer {
        if level == 0 {
            source
        } else {
            reduced[level - 1].buffer()
        }
    };
    let output = |level: usize| -> &wgpu::Buffer {
        if level == 0 {
            destination
        } else {
            scanned[level - 1].buffer()
        }
    };
    let mut dispatches = Vec::with_capacity(2 * levels - 1);
    for level in 0..levels - 1 {
        let bind_group = reduce.bind(
            context,
            &[
                slots.binding(level),
                input(level).as_entire_buffer_binding(),
                reduced[level].whole(),
                dummy.whole(),
            ],
        );
        dispatches.push(reduce.dispatch(bind_group, workgroups_for(counts[level], SCAN_BLOCK)));
    }
    for (slot, level) in (levels - 1..levels * 2 - 1).zip((0..levels).rev()) {
        let parent = if level + 1 < levels {
            scanned[level].whole()
        } else {
            dummy.whole()
        };
        let bind_group = scan.bind(
            context,
            &[
                slots.binding(slot),
                input(level).as_entire_buffer_binding(),
                output(level).as_entire_buffer_binding(),
                parent,
            ],
        );
        dispatches.push(scan.dispatch(bind_group, workgroups_for(counts[level], SCAN_BLOCK)));
    }
    Ok(dispatches)
}

fn params(count: usize, inclusive: bool, has_parent: bool) -> ScanParams {
    ScanParams {
        count: count as u32,
        inclusive: u32::from(inclusive),
        has_parent: u32::from(has_parent),
        padding: 0,
    }
}

/// A scan with its dispatches cached for the last (source, destination, count, kind).
#[derive(Debug, Default)]
pub struct Scan {
    cached: Option<(ScanKey, Vec<Dispatch>)>,
}

type ScanKey = (wgpu::Buffer, wgpu::Buffer, usize, ScanKind);

impl Scan {
    pub fn new() -> Self {
        Self::default()
    }

    /// Encodes `destination = scan(source)` into `pass`; `destination` is resized to
    /// `source.len()` first (call outside the hot loop when sizes change, as it may grow).
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        source: &GpuVec<u32>,
        destination: &mut GpuVec<u32>,
        kind: ScanKind,
    ) -> Result<(), GpuError> {
        destination.resize(context, source.len())?;
        let key = (
            source.buffer().clone(),
            destination.buffer().clone(),
            source.len(),
            kind,
        );
        let dispatches = match &mut self.cached {
            Some((cached_key, dispatches)) if *cached_key == key => dispatches,
            cached => {
                let dispatches =
                    scan_dispatches(context, source.buffer(), destination.buffer(), key.2, kind)?;
                &mut cached.insert((key, dispatches)).1
            }
        };
        crate::gpu::kernel::encode_all(pass, dispatches);
        Ok(())
    }
}
