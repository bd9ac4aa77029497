//! What the host's step reads of each pair's contact when the contacts stay on the device
//! (`summary.wgsl`): its point count and deepest penetration, 8 bytes a pair instead of the
//! contact's 256. The row summaries, the islands and the step's statistics need no more.

use bytemuck::{Pod, Zeroable};

use super::{PAIR_CONTACT_WGSL, PairContact};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, LastTwo, Source, WORKGROUP_SIZE, workgroups_for,
};

const WGSL: &str = include_str!("summary.wgsl");
/// The pair count, the contacts, the summaries.
const BINDINGS: [Binding; 3] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// One pair's summary: its manifold's point count, and the deepest penetration of its points
/// (m, ≥ 0; 0 without points).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PairSummary {
    pub point_count: u32,
    pub depth: f32,
}

impl PairSummary {
    /// The summary of `contact`, as the kernel computes it.
    pub fn of(contact: &PairContact) -> Self {
        Self {
            point_count: contact.manifold.count,
            depth: contact
                .manifold
                .points()
                .iter()
                .map(|point| -point.separation)
                .fold(0.0, f32::max),
        }
    }
}

pub fn wgsl() -> Source {
    let source = Source::new()
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("summary.wgsl", WGSL);
    // SAFETY: its one loop counts up to a manifold's point count (read for it, session 29).
    unsafe { source.every_loop_ends() }
}

/// The summary kernel and its output.
pub struct GpuPairSummaries {
    kernel: Kernel,
    pub summaries: GpuVec<PairSummary>,
    /// For the count, contacts and summaries buffers, and the capacity.
    cached: LastTwo<([wgpu::Buffer; 3], usize), Dispatch>,
}

impl GpuPairSummaries {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            kernel: Kernel::new(context, "summarize", &wgsl(), "summarize", &BINDINGS),
            summaries: GpuVec::with_capacity(context, "pair summaries", 0)?,
            cached: LastTwo::default(),
        })
    }

    /// Encodes the summaries of the first `count[0]` of `contacts`, up to `capacity` pairs.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        count: &GpuVec<u32>,
        contacts: &GpuVec<PairContact>,
        capacity: usize,
    ) -> Result<(), GpuError> {
        self.summaries.resize(context, capacity)?;
        let key = (
            [
                count.buffer().clone(),
                contacts.buffer().clone(),
                self.summaries.buffer().clone(),
            ],
            capacity,
        );
        let (kernel, summaries) = (&self.kernel, &self.summaries);
        let dispatch = self.cached.get_or_insert(key, || {
            let group = kernel.bind(
                context,
                &[count.whole(), contacts.whole(), summaries.whole()],
            );
            kernel.dispatch(group, workgroups_for(capacity, WORKGROUP_SIZE))
        });
        dispatch.encode(pass);
        Ok(())
    }
}
