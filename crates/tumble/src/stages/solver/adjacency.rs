//! Each body's constraints on the device, in batch order (`adjacency.wgsl`), for the warm start
//! that gathers by body: one dispatch per sub-step with the gravity step, instead of one per
//! batch. A body receives its constraints' warm-start impulses in the order the batch sweeps
//! would give them (batch after batch), so the velocities are the sweeps' bit for bit.
//!
//! Built from a device batch layout ([`GpuBatchLayout`](crate::stages::batching::layout::GpuBatchLayout))
//! and the batching's per-body color masks, with no read-back.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::gpu::prims::scan::{Scan, ScanKind};
use crate::stages::batching::MAX_COLORS;
use crate::stages::constraints::STATIC_BODY;

const WGSL: &str = include_str!("adjacency.wgsl");

/// Parameters, masks, colors, order, row bodies, offsets, overflow counts, side ranks, counts,
/// starts, entries.
const BINDINGS: [Binding; 11] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `AdjacencyParams` in `adjacency.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct AdjacencyParams {
    pub body_count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

pub fn wgsl() -> Source {
    Source::new()
        .constant_u32("MAX_COLORS", MAX_COLORS as u32)
        .constant_u32("STATIC_BODY", STATIC_BODY)
        .snippet("adjacency.wgsl", WGSL)
}

/// What a body adjacency is built from: the batching's masks and colors, the layout's order
/// and offsets, the rows' bodies.
pub struct AdjacencyInputs<'a> {
    pub masks: &'a GpuVec<[u32; 2]>,
    pub colors: &'a GpuVec<u32>,
    pub order: &'a GpuVec<u32>,
    pub row_bodies: &'a GpuVec<[u32; 2]>,
    pub offsets: &'a GpuVec<u32>,
}

/// The buffers and sizes the cached dispatches were built for.
type Key = ([wgpu::Buffer; 5], usize, usize);

/// Each body's constraints: body b's entries are `entries[starts[b]..starts[b + 1]]`.
pub struct GpuBodyAdjacency {
    pub starts: GpuVec<u32>,
    pub entries: GpuVec<u32>,
    counts: GpuVec<u32>,
    overflow_counts: GpuVec<u32>,
    side_ranks: GpuVec<[u32; 2]>,
    scan: Scan,
    overflow_ranks: Kernel,
    count_bodies: Kernel,
    fill: Kernel,
    cached: Option<(Key, [Dispatch; 3], UniformSlots)>,
}

impl GpuBodyAdjacency {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry: &str| {
            Kernel::new(
                context,
                &format!("adjacency {entry}"),
                &source,
                entry,
                &BINDINGS,
            )
        };
        Ok(Self {
            starts: GpuVec::with_capacity(context, "adjacency starts", 0)?,
            entries: GpuVec::with_capacity(context, "adjacency entries", 0)?,
            counts: GpuVec::with_capacity(context, "adjacency counts", 0)?,
            overflow_counts: GpuVec::with_capacity(context, "adjacency overflow counts", 0)?,
            side_ranks: GpuVec::with_capacity(context, "adjacency side ranks", 0)?,
            scan: Scan::new(),
            overflow_ranks: kernel("overflow_ranks"),
            count_bodies: kernel("count_bodies"),
            fill: kernel("fill"),
            cached: None,
        })
    }

    /// Encodes the adjacency of `body_count` bodies and the layout's constraints (at most
    /// `constraint_capacity`, the dispatches' size).
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        inputs: &AdjacencyInputs,
        body_count: usize,
        constraint_capacity: usize,
    ) -> Result<(), GpuError> {
        // Zero between steps: grown buffers start zeroed, and `count_bodies` clears what
        // `overflow_ranks` counted.
        self.overflow_counts.resize(context, body_count)?;
        self.side_ranks.resize(context, constraint_capacity)?;
        self.counts.resize(context, body_count + 1)?;
        self.starts.resize(context, body_count + 1)?;
        self.entries.resize(context, 2 * constraint_capacity)?;
        let key: Key = (
            [
                inputs.masks.buffer().clone(),
                inputs.colors.buffer().clone(),
                inputs.order.buffer().clone(),
                inputs.row_bodies.buffer().clone(),
                inputs.offsets.buffer().clone(),
            ],
            body_count,
            constraint_capacity,
        );
        let stale = self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key);
        if stale {
            let params = AdjacencyParams {
                body_count: body_count as u32,
                ..AdjacencyParams::zeroed()
            };
            let slots = UniformSlots::new(context, "adjacency params", &[params]);
            let group = |kernel: &Kernel| {
                kernel.bind(
                    context,
                    &[
                        slots.binding(0),
                        inputs.masks.whole(),
                        inputs.colors.whole(),
                        inputs.order.whole(),
                        inputs.row_bodies.whole(),
                        inputs.offsets.whole(),
                        self.overflow_counts.whole(),
                        self.side_ranks.whole(),
                        self.counts.whole(),
                        self.starts.whole(),
                        self.entries.whole(),
                    ],
                )
            };
            let dispatches = [
                self.overflow_ranks.dispatch(group(&self.overflow_ranks), 1),
                self.count_bodies.dispatch(
                    group(&self.count_bodies),
                    workgroups_for(body_count + 1, WORKGROUP_SIZE),
                ),
                self.fill.dispatch(
                    group(&self.fill),
                    workgroups_for(constraint_capacity, WORKGROUP_SIZE),
                ),
            ];
            self.cached = Some((key, dispatches, slots));
        }
        let Some((_, [overflow_ranks, count_bodies, fill], _)) = &self.cached else {
            unreachable!("cached just above")
        };
        overflow_ranks.encode(pass);
        count_bodies.encode(pass);
        self.scan.encode(
            context,
            pass,
            &self.counts,
            &mut self.starts,
            ScanKind::Exclusive,
        )?;
        fill.encode(pass);
        Ok(())
    }
}
