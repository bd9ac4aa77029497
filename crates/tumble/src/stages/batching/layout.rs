//! GPU executor of the batch layout ([`batch_order`](super::batch_order)'s contract, kernels
//! in `layout.wgsl`): from the colors a [`GpuBatching`](super::gpu::GpuBatching) left on the
//! device, the order that gathers the constraints batch after batch and each batch's offsets.
//! Nothing comes back to the host, so the batching and the solve can share a submission.
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
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::gpu::prims::scan::{Scan, ScanKind};

const WGSL: &str = include_str!("layout.wgsl");

/// Batches of the device layout: the colors, then the overflow batch.
pub const LAYOUT_BATCHES: usize = MAX_COLORS + 1;

/// Parameters, tally, colors, block counts, block starts, order, offsets.
const BINDINGS: [Binding; 7] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Where [`GpuBatchLayout::offsets`] holds the end of the batches that hold a constraint (one
/// past the last of them; 0 with no constraint).
pub const USED_END: usize = LAYOUT_BATCHES + 1;

/// Mirrors `LayoutParams` in `layout.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LayoutParams {
    pub blocks: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

pub fn wgsl() -> Source {
    let source = Source::new()
        .constant_u32("LAYOUT_BATCHES", LAYOUT_BATCHES as u32)
        .snippet("layout.wgsl", WGSL);
    // SAFETY: every loop was read for it (session 29): counted ones over constant bounds, and
    // a count down to zero.
    unsafe { source.every_loop_ends() }
}

/// What the cached dispatches were built for: tally, colors, order, and the blocks covered.
type LayoutKey = ([wgpu::Buffer; 3], usize);

/// The device's batch layout, its buffers reused from step to step.
pub struct GpuBatchLayout {
    /// Batch k is `order[offsets[k]..offsets[k + 1]]`, then [`USED_END`].
    pub offsets: GpuVec<u32>,
    block_counts: GpuVec<u32>,
    starts: GpuVec<u32>,
    scan: Scan,
    count_blocks: Kernel,
    scatter: Kernel,
    batch_offsets: Kernel,
    cached: Option<(LayoutKey, [Dispatch; 3], UniformSlots)>,
}

impl GpuBatchLayout {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry: &str| {
            Kernel::new(
                context,
                &format!("layout {entry}"),
                &source,
                entry,
                &BINDINGS,
            )
        };
        let mut offsets = GpuVec::with_capacity(context, "layout offsets", USED_END + 1)?;
        offsets.resize(context, USED_END + 1)?;
        Ok(Self {
            offsets,
            block_counts: GpuVec::with_capacity(context, "layout block counts", 0)?,
            starts: GpuVec::with_capacity(context, "layout block starts", 0)?,
            scan: Scan::new(),
            count_blocks: kernel("count_blocks"),
            scatter: kernel("scatter"),
            batch_offsets: kernel("batch_offsets"),
            cached: None,
        })
    }

    /// Encodes the layout of the `tally`'s count of `colors` (a batching's outputs) into
    /// `order` (sized for that count by the caller) and [`Self::offsets`].
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        tally: &GpuVec<[u32; 4]>,
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
                    ],
                )
            };
            let dispatches = [
                self.count_blocks
                    .dispatch(group(&self.count_blocks), blocks),
                self.scatter.dispatch(group(&self.scatter), blocks),
                self.batch_offsets.dispatch(group(&self.batch_offsets), 1),
            ];
            self.cached = Some((key, dispatches, slots));
        }
        let Some((_, [count, scatter, offsets], _)) = &self.cached else {
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
        offsets.encode(pass);
        Ok(())
    }
}
