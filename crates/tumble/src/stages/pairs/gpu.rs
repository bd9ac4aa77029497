//! The pair cache's diff on the GPU (the talk's "persistent pairs"): given last step's and
//! this step's sorted pair keys, device-resident, it finds for every new key the index of the
//! same key last step (or [`NEW_PAIR`]) — which is how a kept pair's contact moves over for
//! warm starting — and the added and removed pairs, compacted, with their counts.
//!
//! Invariants (the CPU [`PairCache`](super::PairCache)'s, as the parity test checks):
//! - Inputs are sorted ascending and unique, except that either may end in `u64::MAX`
//!   padding (the GPU broadphase's key buffer past its count), which is never a pair.
//! - `old_index[i]` is the position of `new[i]` among the old keys, or [`NEW_PAIR`] when it is
//!   absent or padding.
//! - `added[..added_count]` are the ascending positions (in the new keys) of keys absent from
//!   the old keys; `removed[..removed_count]` the ascending positions (in the old keys) of
//!   keys absent from the new keys. Counts stay on the GPU.
//! - One lookup dispatch (binary search both ways, no atomics) and two compactions: the
//!   output is the same on every run.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::gpu::prims::compact::Compact;

const WGSL: &str = include_str!("pairs.wgsl");
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// `old_index` of a pair that was not in last step's keys.
pub const NEW_PAIR: u32 = u32::MAX;

/// Mirrors `DiffParams` in `pairs.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DiffParams {
    pub new_count: u32,
    pub old_count: u32,
    pub padding0: u32,
    pub padding1: u32,
}

pub fn wgsl() -> Source {
    Source::new().snippet("pairs.wgsl", WGSL)
}

/// A diff read back to the host: what [`GpuPairDiff::run`] returns.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PairDiff {
    /// Per new key: its index among the old keys, or [`NEW_PAIR`].
    pub old_index: Vec<u32>,
    /// Keys that are new, ascending.
    pub added: Vec<u64>,
    /// Keys that are gone, ascending.
    pub removed: Vec<u64>,
}

/// What the cached lookup dispatch was built for: [old keys, new keys], their lengths.
type DiffKey = ([wgpu::Buffer; 2], [usize; 2]);

/// The GPU pair diff, built once per buffer set and re-encoded every step.
#[derive(Debug)]
pub struct GpuPairDiff {
    old_index: GpuVec<u32>,
    added_flags: GpuVec<u32>,
    removed_flags: GpuVec<u32>,
    /// 0, 1, 2, …: the values the compactions keep, as long as the new and the old keys.
    new_positions: GpuVec<u32>,
    old_positions: GpuVec<u32>,
    added: GpuVec<u32>,
    added_count: GpuVec<u32>,
    removed: GpuVec<u32>,
    removed_count: GpuVec<u32>,
    compact_added: Compact,
    compact_removed: Compact,
    cached: Option<(DiffKey, Dispatch)>,
    /// [`Self::run`]'s device copies of the old and new keys, reused from call to call.
    host_keys: Option<(GpuVec<u64>, GpuVec<u64>)>,
}

impl GpuPairDiff {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let empty = |label| GpuVec::<u32>::with_capacity(context, label, 0);
        Ok(Self {
            old_index: empty("old pair index")?,
            added_flags: empty("added pair flags")?,
            removed_flags: empty("removed pair flags")?,
            new_positions: empty("new pair positions")?,
            old_positions: empty("old pair positions")?,
            added: empty("added pairs")?,
            added_count: empty("added pair count")?,
            removed: empty("removed pairs")?,
            removed_count: empty("removed pair count")?,
            compact_added: Compact::new(),
            compact_removed: Compact::new(),
            cached: None,
            host_keys: None,
        })
    }

    /// Encodes the diff of `old_keys` → `new_keys` (whole vectors, padding allowed). Three
    /// dispatch groups: lookup, then the two compactions.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        old_keys: &GpuVec<u64>,
        new_keys: &GpuVec<u64>,
    ) -> Result<(), GpuError> {
        self.encode_lookup(context, pass, old_keys, new_keys)?;
        self.compact_added.encode(
            context,
            pass,
            &self.new_positions,
            &self.added_flags,
            &mut self.added,
            &mut self.added_count,
        )?;
        self.compact_removed.encode(
            context,
            pass,
            &self.old_positions,
            &self.removed_flags,
            &mut self.removed,
            &mut self.removed_count,
        )
    }

    /// Encodes the lookup alone: [`Self::old_index`] (and the flags) but not the compacted
    /// lists, for a step that needs only how kept pairs map to last step's. Its dispatch is
    /// built again whenever a vector's buffer or length changes: keep both lengths fixed
    /// (padding) to encode it for free from step to step.
    pub fn encode_lookup(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        old_keys: &GpuVec<u64>,
        new_keys: &GpuVec<u64>,
    ) -> Result<(), GpuError> {
        let (new_count, old_count) = (new_keys.len(), old_keys.len());
        let key = (
            [old_keys.buffer().clone(), new_keys.buffer().clone()],
            [old_count, new_count],
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            self.old_index.resize(context, new_count)?;
            self.added_flags.resize(context, new_count)?;
            self.removed_flags.resize(context, old_count)?;
            for (positions, count) in [
                (&mut self.new_positions, new_count),
                (&mut self.old_positions, old_count),
            ] {
                if positions.len() != count {
                    let iota: Vec<u32> = (0..count as u32).collect();
                    positions.upload(context, &iota)?;
                }
            }
            let dispatch = self.lookup_dispatch(context, &key.0, new_count, old_count);
            self.cached = Some((key, dispatch));
        }
        if let Some((_, dispatch)) = &self.cached {
            dispatch.encode(pass);
        }
        Ok(())
    }

    fn lookup_dispatch(
        &self,
        context: &GpuContext,
        keys: &[wgpu::Buffer; 2],
        new_count: usize,
        old_count: usize,
    ) -> Dispatch {
        let kernel = Kernel::new(context, "pair diff", &wgsl(), "diff_keys", &BINDINGS);
        let slots = UniformSlots::new(
            context,
            "pair diff params",
            &[DiffParams {
                new_count: new_count as u32,
                old_count: old_count as u32,
                padding0: 0,
                padding1: 0,
            }],
        );
        let bind_group = kernel.bind(
            context,
            &[
                slots.binding(0),
                keys[0].as_entire_buffer_binding(),
                keys[1].as_entire_buffer_binding(),
                self.old_index.whole(),
                self.added_flags.whole(),
                self.removed_flags.whole(),
            ],
        );
        kernel.dispatch(
            bind_group,
            workgroups_for(new_count.max(old_count), WORKGROUP_SIZE),
        )
    }

    /// Per new key: its index among the old keys, or [`NEW_PAIR`].
    pub fn old_index(&self) -> &GpuVec<u32> {
        &self.old_index
    }

    /// Positions in the new keys of the added pairs (the first `count[0]` are meaningful),
    /// and that count.
    pub fn added(&self) -> (&GpuVec<u32>, &GpuVec<u32>) {
        (&self.added, &self.added_count)
    }

    /// Positions in the old keys of the removed pairs, and their count.
    pub fn removed(&self) -> (&GpuVec<u32>, &GpuVec<u32>) {
        (&self.removed, &self.removed_count)
    }

    /// Upload, encode, submit, read back: the diff of two sorted key lists, for parity tests
    /// and for a step that keeps its pair cache on the host.
    pub fn run(
        &mut self,
        context: &GpuContext,
        old_keys: &[u64],
        new_keys: &[u64],
    ) -> Result<PairDiff, GpuError> {
        let (mut old, mut new) = match self.host_keys.take() {
            Some(keys) => keys,
            None => (
                GpuVec::with_capacity(context, "old pair keys", old_keys.len())?,
                GpuVec::with_capacity(context, "new pair keys", new_keys.len())?,
            ),
        };
        let result = (|| {
            old.upload(context, old_keys)?;
            new.upload(context, new_keys)?;
            context.submit_pass("pair diff", |pass| self.encode(context, pass, &old, &new))?;
            self.read_back(context, old_keys, new_keys)
        })();
        self.host_keys = Some((old, new));
        result
    }

    /// Reads the last encoded diff back, turning positions into keys with the host copies of
    /// the key lists (`old_keys`, `new_keys`: the real keys, without padding, which sorts last).
    /// `old_index` is as long as the new key buffer was.
    pub fn read_back(
        &mut self,
        context: &GpuContext,
        old_keys: &[u64],
        new_keys: &[u64],
    ) -> Result<PairDiff, GpuError> {
        let gather = |positions: &mut GpuVec<u32>,
                      count: &mut GpuVec<u32>,
                      keys: &[u64]|
         -> Result<Vec<u64>, GpuError> {
            let count = count.download(context)?[0] as usize;
            let positions = positions.download(context)?;
            Ok(positions[..count]
                .iter()
                .map(|&position| keys[position as usize])
                .collect())
        };
        Ok(PairDiff {
            old_index: self.old_index.download(context)?,
            added: gather(&mut self.added, &mut self.added_count, new_keys)?,
            removed: gather(&mut self.removed, &mut self.removed_count, old_keys)?,
        })
    }
}
