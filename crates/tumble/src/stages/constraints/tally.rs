//! What the step needs of the contact rows before it builds them, counted on the device
//! (`tally.wgsl`) in the collision's submission, when the contacts stay there: how many pairs
//! touch (what the rows' buffers are sized by), how many get a row and how many rows bounce
//! (what the batching and the solver are planned by), for the step's statistics the rows'
//! points and the deepest penetration, and for the pair cache the pairs kept from last step
//! (which give the added and the removed ones). On the host these are passes over every pair
//! (0.57 ms a step of a settled pile of 100k boxes on 16 cores for the rows, 0.13 for the
//! statistics, 0.46 for the pair diff, BENCHMARKS.md 2026-12-04). The device's counts, with the
//! wake test's candidates and the narrowphase's computed pairs copied beside them, come back in
//! one read-back, in the collision's submission.
//!
//! The rows depend on the masses, which an island that wakes after the collision changes: the
//! step then counts the rows on the host (`World::step_stages`). The touching pairs do not.

use crate::dynamics::body::{BODY_WGSL, BodyMass, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::fill::fill_dispatch;
use crate::stages::narrowphase::summary::PairSummary;

const WGSL: &str = include_str!("tally.wgsl");
/// Count, keys, summaries, masses, colliders, totals, old index.
const BINDINGS: [Binding; 7] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
];
/// Words of the totals: `tally.wgsl`'s six, then two counts copied in from other stages' lists
/// so that they come back in the same read-back: the wake test's candidates and the pairs the
/// narrowphase computed.
const TOTALS: usize = 8;
const WAKE_CANDIDATES_WORD: u64 = 6;
const COMPUTED_WORD: u64 = 7;

/// The counts of [`GpuRowTally`], as the masses stood at the collision.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairTally {
    /// Pairs whose manifold has points.
    pub touching: usize,
    /// Those with a moving body: the contact rows.
    pub rows: usize,
    /// Rows whose restitution is above zero.
    pub bouncing: usize,
    /// The rows' points.
    pub contacts: usize,
    /// The deepest penetration of any pair (m, >= 0; 0 without a touching pair).
    pub deepest: f32,
    /// Pairs that were last step's too.
    pub kept: usize,
    /// The wake test's candidates, when they were listed (else 0).
    pub wake_candidates: usize,
}

fn wgsl() -> Source {
    Source::new()
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("tally.wgsl", WGSL)
}

/// The buffers the dispatches bind (count, keys, summaries, masses, colliders, old index) and
/// the pair slots they cover.
type TallyKey = ([wgpu::Buffer; 6], usize);

/// The tally kernel, its totals and their read-back.
pub struct GpuRowTally {
    kernel: Kernel,
    totals: GpuVec<u32>,
    read: Vec<u32>,
    /// The zeroing of the totals, then the tally.
    cached: Option<(TallyKey, Vec<Dispatch>)>,
}

impl GpuRowTally {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            kernel: Kernel::new(context, "tally_rows", &wgsl(), "tally_rows", &BINDINGS),
            totals: GpuVec::from_slice(context, "row tally", &[0; TOTALS])?,
            read: Vec::new(),
            cached: None,
        })
    }

    /// Encodes the tally of the first `count[0]` of `keys` (padded up to `slots`), whose
    /// summaries are `summaries` and whose indices among last step's pairs are `old_index`.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        count: &GpuVec<u32>,
        (keys, summaries, old_index): (&GpuVec<u64>, &GpuVec<PairSummary>, &GpuVec<u32>),
        (masses, colliders): (&GpuVec<BodyMass>, &GpuVec<ColliderData>),
        slots: usize,
    ) -> Result<(), GpuError> {
        let key = (
            [
                count.buffer().clone(),
                keys.buffer().clone(),
                summaries.buffer().clone(),
                masses.buffer().clone(),
                colliders.buffer().clone(),
                old_index.buffer().clone(),
            ],
            slots,
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let mut dispatches = fill_dispatch(context, self.totals.buffer(), TOTALS, 0)?;
            let group = self.kernel.bind(
                context,
                &[
                    count.whole(),
                    keys.whole(),
                    summaries.whole(),
                    masses.whole(),
                    colliders.whole(),
                    self.totals.whole(),
                    old_index.whole(),
                ],
            );
            dispatches.push(
                self.kernel
                    .dispatch(group, workgroups_for(slots, WORKGROUP_SIZE)),
            );
            self.cached = Some((key, dispatches));
        }
        if let Some((_, dispatches)) = &self.cached {
            encode_all(pass, dispatches);
        }
        Ok(())
    }

    /// The totals' buffer (`tally.wgsl`'s words), for a kernel that reads them on the device.
    pub fn totals(&self) -> &GpuVec<u32> {
        &self.totals
    }

    /// Encodes the read-back of the totals, after [`Self::encode`]'s pass, with the wake
    /// test's candidate count (a one-word buffer) copied in first when it was encoded, and
    /// the first word of `computed`, the count of the pairs the narrowphase computed
    /// ([`Self::computed`]).
    pub fn encode_download(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        wake_candidates: Option<&GpuVec<u32>>,
        computed: &GpuVec<u32>,
    ) {
        let totals = self.totals.buffer();
        if let Some(total) = wake_candidates {
            let word = WAKE_CANDIDATES_WORD * 4;
            encoder.copy_buffer_to_buffer(total.buffer(), 0, totals, word, 4);
        }
        encoder.copy_buffer_to_buffer(computed.buffer(), 0, totals, COMPUTED_WORD * 4, 4);
        self.totals.encode_download(context, encoder);
    }

    /// After [`Self::read`]: the count [`Self::encode_download`] copied from `computed`.
    pub fn computed(&self) -> usize {
        self.read[COMPUTED_WORD as usize] as usize
    }

    /// After the submission of [`Self::encode_download`]: the counts.
    pub fn read(&mut self, context: &GpuContext) -> Result<PairTally, GpuError> {
        self.totals.read_download(context, &mut self.read)?;
        Ok(PairTally {
            touching: self.read[0] as usize,
            rows: self.read[1] as usize,
            bouncing: self.read[2] as usize,
            contacts: self.read[3] as usize,
            deepest: f32::from_bits(self.read[4]),
            kept: self.read[5] as usize,
            wake_candidates: self.read[6] as usize,
        })
    }
}
