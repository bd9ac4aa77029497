//! GPU executor of the batchers: the rounds of [`color_constraints`](super::color_constraints)
//! as kernels (`batching.wgsl`), giving the same colors as the CPU executor (the parity test
//! checks it bit for bit). A batching is one `start` dispatch, a number of rounds chosen by
//! the caller as a `claim` and a `commit` dispatch each, one `rest_rounds` dispatch that runs
//! the rounds left up to [`MAX_ROUNDS`] in one workgroup, and a `finish` dispatch. Rounds after
//! the last constraint is batched return at once, so the count encoded changes the time, never
//! the colors.

use bytemuck::{Pod, Zeroable};

use super::{Batcher, Coloring, LOCK_SLOTS, MAX_COLORS, MAX_ROUNDS};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::STATIC_BODY;

const WGSL: &str = include_str!("batching.wgsl");
/// The color of a constraint no round has batched yet.
const UNBATCHED: u32 = u32::MAX;

/// The most constraints `rest_rounds` lists to go over round after round in one workgroup
/// (more left, each of its rounds goes over all of them).
const REST_LIST: u32 = 1024;

const BINDINGS: [Binding; 7] = [
    // A block a round: one bind group a kernel for the 64 rounds, not one a round (194 bind
    // groups took 0.45 ms to make whenever a buffer grew).
    Binding::UniformAt,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `BatchParams` in `batching.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BatchParams {
    pub body_count: u32,
    pub round: u32,
    pub batcher: u32,
    pub ordered: u32,
}

pub fn wgsl() -> Source {
    let source = Source::new()
        .constant_u32("MAX_COLORS", MAX_COLORS as u32)
        .constant_u32("MAX_ROUNDS", MAX_ROUNDS as u32)
        .constant_u32("STATIC_BODY", STATIC_BODY)
        .constant_u32("UNBATCHED", UNBATCHED)
        .constant_u32("BATCHER_COLORS", Batcher::Colors as u32)
        .constant_u32("LOCK_SLOTS", LOCK_SLOTS as u32)
        .constant_u32("REST_LIST", REST_LIST)
        .snippet("batching.wgsl", WGSL);
    // SAFETY: every loop was read for it (session 29): counted ones, and strides over a count
    // that stop before they could wrap.
    unsafe { source.every_loop_ends() }
}

/// What the cached dispatches were built for: the buffers (bodies, colors, locks, masks,
/// tally, tentative colors), constraint capacity, body count, ordered count, batcher. Not the
/// constraint count, which changes every step: the kernels read it from the tally.
type BatchKey = ([wgpu::Buffer; 6], usize, usize, usize, Batcher);

/// A batching's dispatches for every number of rounds encoded on their own.
#[derive(Debug)]
struct Dispatches {
    /// The start, then each round's claim and commit.
    rounds: Vec<Dispatch>,
    /// `rest[r]`: rounds r to [`MAX_ROUNDS`] − 1 in one workgroup.
    rest: Vec<Dispatch>,
    finish: Dispatch,
}

/// The GPU batching of one world, its buffers reused from step to step.
#[derive(Debug)]
pub struct GpuBatching {
    /// Per constraint: its bodies.
    pub bodies: GpuVec<[u32; 2]>,
    /// Per constraint: its color (the output).
    pub colors: GpuVec<u32>,
    locks: GpuVec<u32>,
    masks: GpuVec<[u32; 2]>,
    /// Per constraint: the color its last claim took.
    tentative: GpuVec<u32>,
    /// How many constraints have a batch (the rounds' early exit), how many there are, how
    /// many rounds found one left to batch ([`Coloring::rounds`]), and the first round that
    /// started with few enough left for `rest_rounds` to list ([`Self::listable_from`]).
    tally: GpuVec<[u32; 4]>,
    cached: Option<(BatchKey, Dispatches)>,
    /// Host scratch: the bodies to upload, the colors and the tally read back.
    host_bodies: Vec<[u32; 2]>,
    host_colors: Vec<u32>,
    host_tally: Vec<[u32; 4]>,
}

impl GpuBatching {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            bodies: GpuVec::with_capacity(context, "batching bodies", 0)?,
            colors: GpuVec::with_capacity(context, "batching colors", 0)?,
            locks: GpuVec::with_capacity(context, "batching locks", 0)?,
            masks: GpuVec::with_capacity(context, "batching masks", 0)?,
            tentative: GpuVec::with_capacity(context, "batching tentative colors", 0)?,
            tally: GpuVec::from_slice(context, "batching tally", &[[0, 0, 0, u32::MAX]])?,
            cached: None,
            host_bodies: Vec::new(),
            host_colors: Vec::new(),
            host_tally: Vec::new(),
        })
    }

    /// Encodes the batching of the `bodies` buffer's constraints among `body_count` bodies,
    /// the first `ordered` ranked by index; the colors land in `colors`. `rounds` of the
    /// rounds are dispatches of their own, the rest one workgroup's: a caller that expects
    /// about as many rounds as the last step needed ([`Coloring::rounds`]) encodes those and a
    /// few more. The colors are the same for any `rounds`.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        rounds: usize,
    ) -> Result<(), GpuError> {
        let bodies = self.bodies.buffer().clone();
        let (count, capacity) = (self.bodies.len(), self.bodies.capacity());
        let input = (&bodies, count, capacity);
        self.encode_over(context, pass, input, body_count, ordered, batcher, rounds)
    }

    /// [`Self::encode`] of the first `count` constraints of `bodies` (the rows' bodies left on
    /// the device, [`GpuRows::bodies`](crate::stages::constraints::gpu::GpuRows::bodies))
    /// rather than of those uploaded, no joint among them: [`Self::prepare_device_bodies`],
    /// then, when there is a constraint, [`Self::record_device_bodies`].
    pub fn encode_device_bodies(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        (bodies, count): (&GpuVec<[u32; 2]>, usize),
        body_count: usize,
        batcher: Batcher,
        rounds: usize,
    ) -> Result<(), GpuError> {
        if self.prepare_device_bodies(context, (bodies, count), body_count)? {
            self.record_device_bodies(context, pass, bodies, body_count, batcher, rounds);
        }
        Ok(())
    }

    /// The host's part of [`Self::encode_device_bodies`]: the count to the device and the
    /// buffers sized for it. Whether there is a constraint to record a batching of.
    pub fn prepare_device_bodies(
        &mut self,
        context: &GpuContext,
        (bodies, count): (&GpuVec<[u32; 2]>, usize),
        body_count: usize,
    ) -> Result<bool, GpuError> {
        self.prepare(context, count, bodies.capacity(), body_count)
    }

    /// The commands of [`Self::encode_device_bodies`], after its
    /// [`Self::prepare_device_bodies`]: they read the count on the device, so a recording
    /// serves any count its preparation did not grow a buffer for.
    pub fn record_device_bodies(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        bodies: &GpuVec<[u32; 2]>,
        body_count: usize,
        batcher: Batcher,
        rounds: usize,
    ) {
        let input = (bodies.buffer(), bodies.capacity());
        self.record(context, pass, input, body_count, 0, batcher, rounds);
    }

    /// [`Self::encode`] over `(buffer, count, capacity)` of constraint bodies.
    #[allow(clippy::too_many_arguments)]
    fn encode_over(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        (bodies, count, capacity): (&wgpu::Buffer, usize, usize),
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        rounds: usize,
    ) -> Result<(), GpuError> {
        if self.prepare(context, count, capacity, body_count)? {
            let input = (bodies, capacity);
            self.record(context, pass, input, body_count, ordered, batcher, rounds);
        }
        Ok(())
    }

    /// The count to the device and the buffers sized for `count` of `capacity` constraints
    /// among `body_count` bodies: whether there is one.
    fn prepare(
        &mut self,
        context: &GpuContext,
        count: usize,
        capacity: usize,
        body_count: usize,
    ) -> Result<bool, GpuError> {
        // Lands before the next submission's commands run (the batch layout reads the count).
        self.tally
            .upload(context, &[[0, count as u32, 0, u32::MAX]])?;
        if count == 0 {
            self.colors.resize(context, 0)?;
            return Ok(false);
        }
        self.colors.resize(context, count)?;
        self.locks.resize(context, 2 * LOCK_SLOTS * body_count)?;
        self.masks.resize(context, body_count)?;
        self.tentative.resize(context, capacity)?;
        Ok(true)
    }

    /// The batching's dispatches over `(buffer, capacity)` of constraint bodies, after
    /// [`Self::prepare`].
    #[allow(clippy::too_many_arguments)]
    fn record(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        (bodies, capacity): (&wgpu::Buffer, usize),
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        rounds: usize,
    ) {
        let buffers = [
            bodies.clone(),
            self.colors.buffer().clone(),
            self.locks.buffer().clone(),
            self.masks.buffer().clone(),
            self.tally.buffer().clone(),
            self.tentative.buffer().clone(),
        ];
        let key = (buffers, capacity, body_count, ordered, batcher);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let dispatches =
                self.dispatches(context, bodies, capacity, body_count, ordered, batcher);
            self.cached = Some((key, dispatches));
        }
        if let Some((_, dispatches)) = &self.cached {
            // The start, the rounds, then the rest from round `rounds`, then the finish.
            let rounds = rounds.min(MAX_ROUNDS);
            encode_all(pass, &dispatches.rounds[..1 + 2 * rounds]);
            if rounds < MAX_ROUNDS {
                dispatches.rest[rounds].encode(pass);
            }
            dispatches.finish.encode(pass);
        }
    }

    fn dispatches(
        &self,
        context: &GpuContext,
        bodies: &wgpu::Buffer,
        capacity: usize,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
    ) -> Dispatches {
        let source = wgsl();
        let kernel = |entry: &str| {
            Kernel::new(
                context,
                &format!("batching {entry}"),
                &source,
                entry,
                &BINDINGS,
            )
        };
        let (start, claim, commit, rest, finish) = (
            kernel("start"),
            kernel("claim"),
            kernel("commit"),
            kernel("rest_rounds"),
            kernel("finish"),
        );
        let blocks: Vec<BatchParams> = (0..MAX_ROUNDS as u32)
            .map(|round| BatchParams {
                body_count: body_count as u32,
                round,
                batcher: batcher as u32,
                ordered: ordered as u32,
            })
            .collect();
        let slots = UniformSlots::new(context, "batching params", &blocks);
        let bind = |kernel: &Kernel| {
            kernel.bind(
                context,
                &[
                    slots.dynamic_binding(),
                    bodies.as_entire_buffer_binding(),
                    self.colors.whole(),
                    self.locks.whole(),
                    self.masks.whole(),
                    self.tally.whole(),
                    self.tentative.whole(),
                ],
            )
        };
        let [
            start_group,
            claim_group,
            commit_group,
            rest_group,
            finish_group,
        ] = [&start, &claim, &commit, &rest, &finish].map(bind);
        let at = |kernel: &Kernel, group: &wgpu::BindGroup, round: usize, workgroups: u32| {
            kernel.dispatch_at(group.clone(), workgroups, slots.offset(round))
        };
        let groups = workgroups_for(capacity, WORKGROUP_SIZE);
        let start_groups = workgroups_for(capacity.max(body_count), WORKGROUP_SIZE);
        let mut rounds = vec![at(&start, &start_group, 0, start_groups)];
        for round in 0..MAX_ROUNDS {
            // A thread a constraint and a body (the claims clear the bodies' next locks).
            rounds.push(at(&claim, &claim_group, round, start_groups));
            rounds.push(at(&commit, &commit_group, round, groups));
        }
        Dispatches {
            rounds,
            rest: (0..MAX_ROUNDS)
                .map(|round| at(&rest, &rest_group, round, 1))
                .collect(),
            finish: at(&finish, &finish_group, 0, groups),
        }
    }

    /// Upload, encode (`rounds` as in [`Self::encode`]), submit, read back: colors `bodies`
    /// into `coloring` as [`color_constraints`](super::color_constraints) does, for the parity
    /// tests.
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &mut self,
        context: &GpuContext,
        bodies: impl Iterator<Item = (u32, u32)>,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        rounds: usize,
        coloring: &mut Coloring,
    ) -> Result<(), GpuError> {
        self.upload(context, bodies)?;
        context.submit_pass("batching", |pass| {
            self.encode(context, pass, body_count, ordered, batcher, rounds)
        })?;
        self.read_back(context, coloring)
    }

    /// Per body, the colors its constraints got (two words, overflow aside): what the
    /// solver's warm start by body ranks a body's constraints by.
    pub fn masks(&self) -> &GpuVec<[u32; 2]> {
        &self.masks
    }

    /// How many constraints have a batch, how many there are, the rounds that found one left
    /// and the first listable round: what the batch layout reads the count from.
    pub fn tally(&self) -> &GpuVec<[u32; 4]> {
        &self.tally
    }

    /// Uploads the constraints' bodies.
    pub fn upload(
        &mut self,
        context: &GpuContext,
        bodies: impl Iterator<Item = (u32, u32)>,
    ) -> Result<(), GpuError> {
        self.host_bodies.clear();
        self.host_bodies.extend(bodies.map(|(a, b)| [a, b]));
        self.bodies.upload(context, &self.host_bodies)
    }

    /// Reads the colors of the last encoded batching into `coloring`.
    pub fn read_back(
        &mut self,
        context: &GpuContext,
        coloring: &mut Coloring,
    ) -> Result<(), GpuError> {
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("batching read-back"),
            });
        self.encode_read_back(context, &mut encoder);
        context.queue.submit([encoder.finish()]);
        self.finish_read_back(context, coloring)
    }

    /// The copies of [`Self::read_back`], recorded at the end of the batching's own encoder so
    /// that the kernels and the read-back are one submission; [`Self::finish_read_back`] then
    /// reads them.
    pub fn encode_read_back(&mut self, context: &GpuContext, encoder: &mut wgpu::CommandEncoder) {
        self.colors.encode_download(context, encoder);
        self.tally.encode_download(context, encoder);
    }

    /// Records the tally's copy for [`Self::finish_read_tally`] at the end of `encoder`.
    pub fn encode_read_tally(&mut self, context: &GpuContext, encoder: &mut wgpu::CommandEncoder) {
        self.tally.encode_download(context, encoder);
    }

    /// The rounds of the last encoded batching, over `constraints`, from the tally that
    /// [`Self::encode_read_tally`] recorded in its submission (the colors stay on the device).
    pub fn finish_read_tally(
        &mut self,
        context: &GpuContext,
        constraints: u32,
    ) -> Result<usize, GpuError> {
        if constraints == 0 {
            self.host_tally.clear();
            return Ok(0);
        }
        self.tally.read_download(context, &mut self.host_tally)?;
        Ok(self.host_tally[0][2] as usize)
    }

    /// The first round of the last batching read back that started with few enough
    /// constraints left for `rest_rounds` to list them (`None` when none did): from there one
    /// workgroup runs the rounds about as fast as dispatches of their own. `Some(0)` when
    /// there were no constraints.
    pub fn listable_from(&self) -> Option<usize> {
        match self.host_tally.first() {
            None => Some(0),
            Some(&[.., u32::MAX]) => None,
            Some(&[.., round]) => Some(round as usize),
        }
    }

    /// [`Self::read_back`] after [`Self::encode_read_back`]'s submission.
    pub fn finish_read_back(
        &mut self,
        context: &GpuContext,
        coloring: &mut Coloring,
    ) -> Result<(), GpuError> {
        self.colors.read_download(context, &mut self.host_colors)?;
        debug_assert!(
            !self.host_colors.contains(&UNBATCHED),
            "the rest and finish give every constraint a color"
        );
        coloring.rounds = if self.host_colors.is_empty() {
            self.host_tally.clear();
            0
        } else {
            self.tally.read_download(context, &mut self.host_tally)?;
            self.host_tally[0][2] as usize
        };
        coloring.colors.clear();
        coloring
            .colors
            .extend(self.host_colors.iter().map(|&color| color as u8));
        coloring.count_batches();
        Ok(())
    }
}
