//! What the host's step reads of each pair's contact when the contacts stay on the device
//! (`summary.wgsl`): its point count and deepest penetration, 8 bytes a pair instead of the
//! contact's 256. The row summaries, the islands and the step's statistics need no more.

use bytemuck::{Pod, Zeroable};

use super::{PAIR_CONTACT_WGSL, PairContact};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, WORKGROUP_SIZE, encode_all, workgroups_for,
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
    Source::new()
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("summary.wgsl", WGSL)
}

/// The summary kernel and its output.
pub struct GpuPairSummaries {
    kernel: Kernel,
    pub summaries: GpuVec<PairSummary>,
    /// For the count, contacts and summaries buffers, and the capacity.
    cached: Option<(([wgpu::Buffer; 3], usize), Dispatch)>,
}

impl GpuPairSummaries {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            kernel: Kernel::new(context, "summarize", &wgsl(), "summarize", &BINDINGS),
            summaries: GpuVec::with_capacity(context, "pair summaries", 0)?,
            cached: None,
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
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let group = self.kernel.bind(
                context,
                &[count.whole(), contacts.whole(), self.summaries.whole()],
            );
            let dispatch = self
                .kernel
                .dispatch(group, workgroups_for(capacity, WORKGROUP_SIZE));
            self.cached = Some((key, dispatch));
        }
        if let Some((_, dispatch)) = &self.cached {
            encode_all(pass, std::slice::from_ref(dispatch));
        }
        Ok(())
    }
}
