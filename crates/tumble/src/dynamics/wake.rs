//! The wake test's pass over the pairs: the touching pairs (a manifold with points) with a
//! sleeping body, in pair order. Only those can wake an island, at once or after another
//! island woke (the step walks them until no island wakes, `World::wake_touched`).
//!
//! On the host ([`wake_candidates`]) it is a pass over every pair each step while anything
//! sleeps: 0.6 ms a step of a settled pile of 100k boxes on 16 cores, 2.8 ms at 500k
//! (BENCHMARKS.md, 2026-12-04). When the contacts stay on the device, [`GpuWakeCandidates`]
//! makes the same list in the collision's submission (`wake.wgsl` flags the pairs, the
//! compaction lists them in order, `wake_keys.wgsl` gathers their keys), and the host reads
//! back that list, a few thousand pairs: it has no other key of the pairs then.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, BodyMass};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::compact::Compact;
use crate::pipeline::parallel::{FilterParts, filter_map_ordered};
use crate::stages::narrowphase::summary::PairSummary;
use crate::stages::pairs::pair_bodies;

const WGSL: &str = include_str!("wake.wgsl");
const KEYS_WGSL: &str = include_str!("wake_keys.wgsl");
/// The candidates' count, the pairs' keys, the candidates' indices, their keys.
const KEY_BINDINGS: [Binding; 4] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];
/// Count, keys, summaries, sleeping bits, flags, parameters, masses, the wakers' flag.
const BINDINGS: [Binding; 8] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Candidates read back with the collision's kernels, past last step's count: at rest the
/// list changes by a few pairs a step; a step with more copies the rest in a second
/// submission.
const CANDIDATE_SLACK: usize = 256;

/// The touching pairs of `keys` (`touching(pair)`) with a sleeping body (`asleep(body)`), as
/// body pairs in pair order: a pass over every pair, on every core.
pub(crate) fn wake_candidates(
    keys: &[u64],
    touching: impl Fn(usize) -> bool + Sync,
    asleep: impl Fn(u32) -> bool + Sync,
    parts: &mut FilterParts<(u32, u32)>,
    out: &mut Vec<(u32, u32)>,
) {
    let may_wake = |pair: usize| {
        // The point count first: read in order, and most pairs of a pile have no points.
        if !touching(pair) {
            return None;
        }
        let (a, b) = pair_bodies(keys[pair]);
        (asleep(a) || asleep(b)).then_some((a, b))
    };
    filter_map_ordered(keys.len(), may_wake, parts, out);
}

/// Mirrors `WakeParams` in `wake.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct WakeParams {
    slots: u32,
    _pad: [u32; 3],
}

fn wgsl() -> Source {
    Source::new()
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("wake.wgsl", WGSL)
}

/// The buffers the flag kernel binds (count, keys, summaries, sleeping bits, flags, masses)
/// and the pair slots it covers.
type FlagKey = ([wgpu::Buffer; 6], usize);
/// The buffers the key kernel binds (total, keys, candidates, their keys) and the slots.
type KeysKey = ([wgpu::Buffer; 4], usize);

/// [`wake_candidates`] on the device, over the broadphase's keys and the pairs' summaries.
pub struct GpuWakeCandidates {
    flag: Kernel,
    /// [`Islands::asleep_bits`](crate::dynamics::island::Islands::asleep_bits), and the version
    /// uploaded.
    asleep: GpuVec<u32>,
    asleep_version: Option<u64>,
    flags: GpuVec<u32>,
    /// 0, 1, 2, …: the values the compaction keeps, each pair's index.
    indices: GpuVec<u32>,
    compact: Compact,
    candidates: GpuVec<u32>,
    total: GpuVec<u32>,
    cached: Option<(FlagKey, Dispatch, UniformSlots)>,
    /// The candidates' keys, gathered by `keys_kernel`.
    keys_kernel: Kernel,
    keys: GpuVec<u64>,
    keys_cached: Option<(KeysKey, Dispatch)>,
    /// Last step's candidate count.
    last: usize,
    /// One word, not 0 where a candidate wakes an island at once: a body that moves touches
    /// a sleeping one (the first round of `World::wake_touched`).
    wakers: GpuVec<u32>,
}

impl GpuWakeCandidates {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            flag: Kernel::new(
                context,
                "flag_wake_candidates",
                &wgsl(),
                "flag_wake_candidates",
                &BINDINGS,
            ),
            asleep: GpuVec::with_capacity(context, "sleeping bodies", 0)?,
            asleep_version: None,
            flags: GpuVec::with_capacity(context, "wake candidate flags", 0)?,
            indices: GpuVec::with_capacity(context, "pair indices", 0)?,
            compact: Compact::new(),
            candidates: GpuVec::with_capacity(context, "wake candidates", 0)?,
            total: GpuVec::with_capacity(context, "wake candidate count", 0)?,
            cached: None,
            keys_kernel: Kernel::new(
                context,
                "wake_candidate_keys",
                &Source::new().snippet("wake_keys.wgsl", KEYS_WGSL),
                "wake_candidate_keys",
                &KEY_BINDINGS,
            ),
            keys: GpuVec::with_capacity(context, "wake candidate keys", 0)?,
            keys_cached: None,
            last: 0,
            wakers: GpuVec::from_slice(context, "wakers", &[0])?,
        })
    }

    /// Sends which bodies sleep
    /// ([`Islands::asleep_bits`](crate::dynamics::island::Islands::asleep_bits)), unless the device has this
    /// version already.
    pub fn set_asleep(
        &mut self,
        context: &GpuContext,
        (bits, version): (&[u32], u64),
    ) -> Result<(), GpuError> {
        if self.asleep_version != Some(version) || self.asleep.len() != bits.len() {
            self.asleep.upload(context, bits)?;
            self.asleep_version = Some(version);
        }
        Ok(())
    }

    /// Encodes the candidates among the first `count[0]` of `keys` (padded up to `slots`),
    /// whose summaries are `summaries`, into a list of their keys, in pair order, and whether
    /// one wakes an island at once ([`Self::wakers`]), by the bodies' `masses`; after
    /// [`Self::set_asleep`].
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        count: &GpuVec<u32>,
        keys: &GpuVec<u64>,
        summaries: &GpuVec<PairSummary>,
        masses: &GpuVec<BodyMass>,
        slots: usize,
    ) -> Result<(), GpuError> {
        // Lands before the submission's commands run.
        self.wakers.upload(context, &[0])?;
        self.flags.resize(context, slots)?;
        if self.indices.len() != slots {
            let indices: Vec<u32> = (0..slots as u32).collect();
            self.indices.upload(context, &indices)?;
        }
        let key = (
            [
                count.buffer().clone(),
                keys.buffer().clone(),
                summaries.buffer().clone(),
                self.asleep.buffer().clone(),
                self.flags.buffer().clone(),
                masses.buffer().clone(),
            ],
            slots,
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let params = WakeParams {
                slots: slots as u32,
                _pad: [0; 3],
            };
            let uniform = UniformSlots::new(context, "wake params", &[params]);
            let group = self.flag.bind(
                context,
                &[
                    count.whole(),
                    keys.whole(),
                    summaries.whole(),
                    self.asleep.whole(),
                    self.flags.whole(),
                    uniform.binding(0),
                    masses.whole(),
                    self.wakers.whole(),
                ],
            );
            let dispatch = self
                .flag
                .dispatch(group, workgroups_for(slots, WORKGROUP_SIZE));
            self.cached = Some((key, dispatch, uniform));
        }
        if let Some((_, dispatch, _)) = &self.cached {
            encode_all(pass, std::slice::from_ref(dispatch));
        }
        self.compact.encode(
            context,
            pass,
            &self.indices,
            &self.flags,
            &mut self.candidates,
            &mut self.total,
        )?;
        self.keys.resize(context, slots)?;
        let key = (
            [
                self.total.buffer().clone(),
                keys.buffer().clone(),
                self.candidates.buffer().clone(),
                self.keys.buffer().clone(),
            ],
            slots,
        );
        if self
            .keys_cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let group = self.keys_kernel.bind(
                context,
                &[
                    self.total.whole(),
                    keys.whole(),
                    self.candidates.whole(),
                    self.keys.whole(),
                ],
            );
            let dispatch =
                (self.keys_kernel).dispatch(group, workgroups_for(slots, WORKGROUP_SIZE));
            self.keys_cached = Some((key, dispatch));
        }
        if let Some((_, dispatch)) = &self.keys_cached {
            encode_all(pass, std::slice::from_ref(dispatch));
        }
        Ok(())
    }

    /// One word on the device: how many candidates [`Self::encode`] listed. The caller reads
    /// it back with its other counts (the rows' tally).
    pub fn total(&self) -> &GpuVec<u32> {
        &self.total
    }

    /// The word that the last [`Self::encode`] sets where a candidate wakes an island at once,
    /// for a kernel after it; 0 until then.
    pub fn wakers(&self) -> &GpuVec<u32> {
        &self.wakers
    }

    /// Encodes the read-back of as many candidates as last step had and some more, after
    /// [`Self::encode`]'s pass; returns how many it copies.
    pub fn encode_download(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
    ) -> usize {
        let staged = (self.last + CANDIDATE_SLACK).min(self.keys.len());
        self.keys.encode_download_prefix(context, encoder, staged);
        staged
    }

    /// After the submission of [`Self::encode_download`], which copied `staged` candidates,
    /// and given their `count` ([`Self::total`] read back): the candidates' keys, in pair
    /// order, into `out`. Copies the rest in a second submission when there were more.
    pub fn read(
        &mut self,
        context: &GpuContext,
        (staged, count): (usize, usize),
        out: &mut Vec<u64>,
    ) -> Result<(), GpuError> {
        if count > staged {
            let mut encoder =
                context
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("wake candidates read-back"),
                    });
            self.keys
                .encode_download_prefix(context, &mut encoder, count);
            context.queue.submit([encoder.finish()]);
        }
        self.keys.read_download(context, out)?;
        out.truncate(count);
        self.last = count;
        Ok(())
    }
}
