//! The batches kept on the device when the rows, the batching and the solver all run on the GPU
//! (`batched.wgsl`): the rows' constraints are gathered into batch order there, and after the
//! solve only their accumulated impulses come back ([`BatchedImpulses`], 48 bytes a
//! constraint), not the constraints (1 KB each, twice: down for the layout, up for the solve).
//!
//! The host still sends the order (a counting sort of the colors it read back, the same
//! [`group_by_batch`](crate::stages::batching::group_by_batch) the CPU step uses), so both
//! paths solve the same array bit for bit.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::{CONTACT_CONSTRAINT_WGSL, ContactConstraint};

const WGSL: &str = include_str!("batched.wgsl");
const BINDINGS: [Binding; 5] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `BatchedImpulses` in `batched.wgsl`: one batched constraint's accumulated impulses,
/// point k in lane k, 0 past its point count.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BatchedImpulses {
    pub normal: [f32; 4],
    pub tangent1: [f32; 4],
    pub tangent2: [f32; 4],
}

pub fn wgsl() -> Source {
    Source::new()
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("batched.wgsl", WGSL)
}

/// The buffers the cached dispatches bind, and the capacity they cover.
type Key = ([wgpu::Buffer; 5], usize);

pub struct GpuBatched {
    /// One word: the constraint count.
    count: GpuVec<u32>,
    order: GpuVec<u32>,
    /// The constraints in batch order: what the solver sweeps.
    pub constraints: GpuVec<ContactConstraint>,
    pub impulses: GpuVec<BatchedImpulses>,
    gather: Kernel,
    read_impulses: Kernel,
    cached: Option<(Key, [Dispatch; 2])>,
}

impl GpuBatched {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Ok(Self {
            count: GpuVec::from_slice(context, "batched count", &[0])?,
            order: GpuVec::with_capacity(context, "batch order", 0)?,
            constraints: GpuVec::with_capacity(context, "batched constraints", 0)?,
            impulses: GpuVec::with_capacity(context, "batched impulses", 0)?,
            gather: kernel("gather"),
            read_impulses: kernel("read_impulses"),
            cached: None,
        })
    }

    /// Sends the batch order (`order[i]` = the constraint at batched place i) and sizes the
    /// outputs for it.
    pub fn upload(&mut self, context: &GpuContext, order: &[u32]) -> Result<(), GpuError> {
        let count = u32::try_from(order.len()).expect("constraint count fits in u32");
        self.count.upload(context, &[count])?;
        self.order.upload(context, order)?;
        self.constraints.resize(context, order.len())?;
        self.impulses.resize(context, order.len())?;
        Ok(())
    }

    /// Encodes the gather of `rows` (the rows' constraints) into [`Self::constraints`].
    pub fn encode_gather(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        rows: &GpuVec<ContactConstraint>,
    ) {
        let key: Key = (
            [
                self.count.buffer().clone(),
                self.order.buffer().clone(),
                rows.buffer().clone(),
                self.constraints.buffer().clone(),
                self.impulses.buffer().clone(),
            ],
            self.order.capacity(),
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let group = self.gather.bind(
                context,
                &[
                    self.count.whole(),
                    self.order.whole(),
                    rows.whole(),
                    self.constraints.whole(),
                    self.impulses.whole(),
                ],
            );
            let groups = workgroups_for(key.1, WORKGROUP_SIZE);
            let dispatches = [
                self.gather.dispatch(group.clone(), groups),
                self.read_impulses.dispatch(group, groups),
            ];
            self.cached = Some((key, dispatches));
        }
        if let Some((_, [gather, _])) = &self.cached {
            encode_all(pass, std::slice::from_ref(gather));
        }
    }

    /// Encodes the copy of the solved impulses into [`Self::impulses`] (after
    /// [`Self::encode_gather`] and the solve, in the same pass).
    pub fn encode_read_impulses(&self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some((_, [_, read])) = &self.cached {
            encode_all(pass, std::slice::from_ref(read));
        }
    }
}
