//! GPU executor of the batch layout ([`batch_order`](super::batch_order)'s contract, kernels
//! in `layout.wgsl`): from the colors a [`GpuBatching`](super::gpu::GpuBatching) left on the
//! device, the order that gathers the constraints batch after batch, each batch's offsets, and
//! the solver's workgroup counts per batch as indirect dispatch arguments. Nothing comes back
//! to the host, so the batching and the solve can share a submission.
//!
//! The device's batches are the colors themselves: batch k is color k for k < [`MAX_COLORS`],
//! and batch [`MAX_COLORS`] is the overflow batch, so there are always [`LAYOUT_BATCHES`],
//! most of them empty. Solved in index order they are the host's batches in its order (the
//! host numbers only the used colors), and within a batch the constraints keep their input
//! order, as [`batch_order`](super::batch_order)'s do: the parity test checks the order and
//! offsets bit for bit.

use bytemuck::{Pod, Zeroable};

use super::MAX_COLORS;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, MAX_GROUPS_PER_DIMENSION, Source, UniformSlots, WORKGROUP_SIZE,
    workgroups_for,
};
use crate::gpu::prims::scan::{Scan, ScanKind};

const WGSL: &str = include_str!("layout.wgsl");

/// Batches of the device layout: the colors, then the overflow batch.
pub const LAYOUT_BATCHES: usize = MAX_COLORS + 1;

/// Parameters, tally, colors, block counts, block starts, order, offsets, dispatch arguments.
const BINDINGS: [Binding; 8] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `LayoutParams` in `layout.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LayoutParams {
    pub blocks: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// The layout's WGSL, for workgroups of `solver_workgroup` threads in the solver.
pub fn wgsl(solver_workgroup: u32) -> Source {
    Source::new()
        .constant_u32("LAYOUT_BATCHES", LAYOUT_BATCHES as u32)
        .constant_u32("SOLVER_WORKGROUP", solver_workgroup)
        .constant_u32("MAX_GROUPS_PER_DIMENSION", MAX_GROUPS_PER_DIMENSION)
        .snippet("layout.wgsl", WGSL)
}

/// What the cached dispatches were built for: tally, colors, order, and the blocks covered.
type LayoutKey = ([wgpu::Buffer; 3], usize);

/// The device's batch layout, its buffers reused from step to step.
pub struct GpuBatchLayout {
    /// `LAYOUT_BATCHES + 1` words: batch k is `order[offsets[k]..offsets[k + 1]]`.
    pub offsets: GpuVec<u32>,
    /// Three words per batch: the solver's (x, y, 1) workgroups for it.
    arguments: wgpu::Buffer,
    block_counts: GpuVec<u32>,
    starts: GpuVec<u32>,
    scan: Scan,
    count_blocks: Kernel,
    scatter: Kernel,
    batch_args: Kernel,
    cached: Option<(LayoutKey, [Dispatch; 3], UniformSlots)>,
}

impl GpuBatchLayout {
    /// A layout whose dispatch arguments size dispatches of `solver_workgroup` threads.
    pub fn new(context: &GpuContext, solver_workgroup: u32) -> Result<Self, GpuError> {
        let source = wgsl(solver_workgroup);
        let kernel = |entry: &str| {
            Kernel::new(
                context,
                &format!("layout {entry}"),
                &source,
                entry,
                &BINDINGS,
            )
        };
        let arguments = context.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("batch dispatch arguments"),
            size: (3 * LAYOUT_BATCHES * size_of::<u32>()) as u64,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::INDIRECT
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let mut offsets = GpuVec::with_capacity(context, "layout offsets", LAYOUT_BATCHES + 1)?;
        offsets.resize(context, LAYOUT_BATCHES + 1)?;
        Ok(Self {
            offsets,
            arguments,
            block_counts: GpuVec::with_capacity(context, "layout block counts", 0)?,
            starts: GpuVec::with_capacity(context, "layout block starts", 0)?,
            scan: Scan::new(),
            count_blocks: kernel("count_blocks"),
            scatter: kernel("scatter"),
            batch_args: kernel("batch_args"),
            cached: None,
        })
    }

    /// The solver's workgroup counts: batch k's at byte offset `12 k`.
    pub fn arguments(&self) -> &wgpu::Buffer {
        &self.arguments
    }

    /// Encodes the layout of the `tally`'s count of `colors` (a batching's outputs) into
    /// `order` (sized for that count by the caller), [`Self::offsets`] and
    /// [`Self::arguments`].
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        tally: &GpuVec<[u32; 3]>,
        colors: &GpuVec<u32>,
        order: &GpuVec<u32>,
    ) -> Result<(), GpuError> {
        // Blocks for the colors' capacity: the dispatches serve every step until it grows.
        let blocks = workgroups_for(colors.capacity(), WORKGROUP_SIZE);
        self.block_counts
            .resize(context, LAYOUT_BATCHES * blocks as usize)?;
        self.starts.resize(context, self.block_counts.len())?;
        let key: LayoutKey = (
            [
                tally.buffer().clone(),
                colors.buffer().clone(),
                order.buffer().clone(),
            ],
            blocks as usize,
        );
        let stale = self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key);
        if stale {
            let params = LayoutParams {
                blocks,
                ..LayoutParams::zeroed()
            };
            let slots = UniformSlots::new(context, "layout params", &[params]);
            let group = |kernel: &Kernel| {
                kernel.bind(
                    context,
                    &[
                        slots.binding(0),
                        tally.whole(),
                        colors.whole(),
                        self.block_counts.whole(),
                        self.starts.whole(),
                        order.whole(),
                        self.offsets.whole(),
                        self.arguments.as_entire_buffer_binding(),
                    ],
                )
            };
            let dispatches = [
                self.count_blocks
                    .dispatch(group(&self.count_blocks), blocks),
                self.scatter.dispatch(group(&self.scatter), blocks),
                self.batch_args.dispatch(group(&self.batch_args), 1),
            ];
            self.cached = Some((key, dispatches, slots));
        }
        let Some((_, [count, scatter, args], _)) = &self.cached else {
            unreachable!("cached just above")
        };
        count.encode(pass);
        self.scan.encode(
            context,
            pass,
            &self.block_counts,
            &mut self.starts,
            ScanKind::Exclusive,
        )?;
        scatter.encode(pass);
        args.encode(pass);
        Ok(())
    }
}
