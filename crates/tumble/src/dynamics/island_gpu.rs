//! The islands' links on the device: [`Islands::link`](super::island::Islands::link) over the
//! touching pairs between awake dynamic bodies, where the contacts stay on the device.
//!
//! On the host this is a pass over every pair and a union-find on every core, each step that
//! an island may fall asleep: 2.5 ms a step of a settled pile of 100k boxes on 16 cores
//! (BENCHMARKS.md, 2026-12-05), hidden behind the solver's wait until the solver is faster,
//! and it needs the pairs' keys and summaries on the host. Here it is three dispatches in the
//! rows' submission (`island.wgsl`: unlink, link, flatten), and the host reads a root a
//! body ([`Islands::adopt_links`](super::island::Islands::adopt_links)). Both link the higher
//! root under the lower, so both give each body its island's lowest body: the same roots.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, BodyMass};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::narrowphase::summary::PairSummary;

const WGSL: &str = include_str!("island.wgsl");
/// Parameters, count, keys, summaries, masses, parents.
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `IslandParams` in `island.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct IslandParams {
    bodies: u32,
    slots: u32,
    _pad: [u32; 2],
}

fn wgsl() -> Source {
    Source::new()
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("island.wgsl", WGSL)
}

/// The device's pairs that the links read: the count (word 0), the keys and the summaries,
/// padded up to `slots`.
pub struct GpuLinkPairs<'a> {
    pub count: &'a GpuVec<u32>,
    pub keys: &'a GpuVec<u64>,
    pub summaries: &'a GpuVec<PairSummary>,
    pub slots: usize,
}

/// The buffers bound (count, keys, summaries, masses, parents), the bodies and the pair slots.
type Key = ([wgpu::Buffer; 5], usize, usize);

/// [`Islands::link`](super::island::Islands::link) of the touching pairs on the device.
pub struct GpuIslandLinks {
    kernels: [Kernel; 3],
    /// Each body's root once the links ran.
    parent: GpuVec<u32>,
    cached: Option<(Key, [Dispatch; 3], UniformSlots)>,
}

impl GpuIslandLinks {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Ok(Self {
            kernels: [kernel("unlink"), kernel("link"), kernel("flatten")],
            parent: GpuVec::with_capacity(context, "island parents", 0)?,
            cached: None,
        })
    }

    /// Encodes this step's links of `pairs` between bodies awake by `masses` (one per body),
    /// and the read-back of the roots after them ([`Self::read`]).
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        pairs: &GpuLinkPairs,
        masses: &GpuVec<BodyMass>,
    ) -> Result<(), GpuError> {
        let bodies = masses.len();
        self.parent.resize(context, bodies)?;
        let buffers = [
            pairs.count.buffer().clone(),
            pairs.keys.buffer().clone(),
            pairs.summaries.buffer().clone(),
            masses.buffer().clone(),
            self.parent.buffer().clone(),
        ];
        let key = (buffers, bodies, pairs.slots);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let params = IslandParams {
                bodies: bodies as u32,
                slots: pairs.slots as u32,
                _pad: [0; 2],
            };
            let uniform = UniformSlots::new(context, "island params", &[params]);
            let bindings = [
                uniform.binding(0),
                pairs.count.whole(),
                pairs.keys.whole(),
                pairs.summaries.whole(),
                masses.whole(),
                self.parent.whole(),
            ];
            let [unlink, link, flatten] = &self.kernels;
            let dispatch = |kernel: &Kernel, items: usize| {
                let group = kernel.bind(context, &bindings);
                kernel.dispatch(group, workgroups_for(items, WORKGROUP_SIZE))
            };
            let dispatches = [
                dispatch(unlink, bodies),
                dispatch(link, pairs.slots),
                dispatch(flatten, bodies),
            ];
            self.cached = Some((key, dispatches, uniform));
        }
        if let Some((_, dispatches, _)) = &self.cached {
            encode_all(pass, dispatches);
        }
        Ok(())
    }

    /// Each body's root once [`Self::encode`]'s pass ran, for the device's sleep test
    /// ([`GpuRestTimers`](super::rest_gpu::GpuRestTimers)).
    pub fn roots(&self) -> &GpuVec<u32> {
        &self.parent
    }

    /// Once [`Self::encode`]'s submission ran: each body's root, the lowest body of its
    /// island, read now into `out`. Only a step that may put an island to sleep reads them.
    pub fn read(&self, context: &GpuContext, out: &mut Vec<u32>) -> Result<(), GpuError> {
        *out = self.parent.read(context)?;
        Ok(())
    }
}
