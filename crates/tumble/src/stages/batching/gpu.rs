//! GPU executor of the batchers: the rounds of [`color_constraints`](super::color_constraints)
//! as kernels (`batching.wgsl`), giving the same colors as the CPU executor (the parity test
//! checks it bit for bit). A batching is one `start` dispatch, [`MAX_ROUNDS`] rounds of a
//! `claim` and a `commit` dispatch, and a `finish` dispatch; rounds after the last constraint
//! is batched return at once.

use bytemuck::{Pod, Zeroable};

use super::{Batcher, Coloring, MAX_COLORS, MAX_ROUNDS};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::STATIC_BODY;

const WGSL: &str = include_str!("batching.wgsl");
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `BatchParams` in `batching.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BatchParams {
    pub count: u32,
    pub body_count: u32,
    pub round: u32,
    pub batcher: u32,
    pub ordered: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

pub fn wgsl() -> Source {
    Source::new()
        .constant_u32("MAX_COLORS", MAX_COLORS as u32)
        .constant_u32("STATIC_BODY", STATIC_BODY)
        .constant_u32("BATCHER_COLORS", Batcher::Colors as u32)
        .snippet("batching.wgsl", WGSL)
}

/// What the cached dispatches were built for: the buffers (bodies, colors, locks, masks,
/// batched count), constraint count, body count, ordered count, batcher.
type BatchKey = ([wgpu::Buffer; 5], usize, usize, usize, Batcher);

/// The GPU batching of one world, its buffers reused from step to step.
#[derive(Debug)]
pub struct GpuBatching {
    /// Per constraint: its bodies.
    pub bodies: GpuVec<[u32; 2]>,
    /// Per constraint: its color (the output).
    pub colors: GpuVec<u32>,
    locks: GpuVec<u32>,
    masks: GpuVec<[u32; 2]>,
    /// How many constraints have a batch (the rounds' early exit).
    batched: GpuVec<u32>,
    cached: Option<(BatchKey, Vec<Dispatch>)>,
    /// Host scratch: the bodies to upload, the colors read back.
    host_bodies: Vec<[u32; 2]>,
    host_colors: Vec<u32>,
}

impl GpuBatching {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            bodies: GpuVec::with_capacity(context, "batching bodies", 0)?,
            colors: GpuVec::with_capacity(context, "batching colors", 0)?,
            locks: GpuVec::with_capacity(context, "batching locks", 0)?,
            masks: GpuVec::with_capacity(context, "batching masks", 0)?,
            batched: GpuVec::from_slice(context, "batched count", &[0])?,
            cached: None,
            host_bodies: Vec::new(),
            host_colors: Vec::new(),
        })
    }

    /// Encodes the batching of the `bodies` buffer's constraints among `body_count` bodies,
    /// the first `ordered` ranked by index; the colors land in `colors`.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
    ) -> Result<(), GpuError> {
        let count = self.bodies.len();
        self.colors.resize(context, count)?;
        self.locks.resize(context, 2 * body_count)?;
        self.masks.resize(context, body_count)?;
        let buffers = [
            self.bodies.buffer().clone(),
            self.colors.buffer().clone(),
            self.locks.buffer().clone(),
            self.masks.buffer().clone(),
            self.batched.buffer().clone(),
        ];
        let key = (buffers, count, body_count, ordered, batcher);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let dispatches = self.dispatches(context, count, body_count, ordered, batcher);
            self.cached = Some((key, dispatches));
        }
        if let Some((_, dispatches)) = &self.cached {
            encode_all(pass, dispatches);
        }
        Ok(())
    }

    fn dispatches(
        &self,
        context: &GpuContext,
        count: usize,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
    ) -> Vec<Dispatch> {
        if count == 0 {
            return Vec::new();
        }
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
        let (start, claim, commit, finish) = (
            kernel("start"),
            kernel("claim"),
            kernel("commit"),
            kernel("finish"),
        );
        let blocks: Vec<BatchParams> = (0..MAX_ROUNDS as u32)
            .map(|round| BatchParams {
                count: count as u32,
                body_count: body_count as u32,
                round,
                batcher: batcher as u32,
                ordered: ordered as u32,
                _pad0: 0,
                _pad1: 0,
                _pad2: 0,
            })
            .collect();
        let slots = UniformSlots::new(context, "batching params", &blocks);
        let bind = |kernel: &Kernel, round: usize| {
            kernel.bind(
                context,
                &[
                    slots.binding(round),
                    self.bodies.whole(),
                    self.colors.whole(),
                    self.locks.whole(),
                    self.masks.whole(),
                    self.batched.whole(),
                ],
            )
        };
        let groups = workgroups_for(count, WORKGROUP_SIZE);
        let start_groups = workgroups_for(count.max(body_count).max(1), WORKGROUP_SIZE);
        let mut dispatches = vec![start.dispatch(bind(&start, 0), start_groups)];
        for round in 0..MAX_ROUNDS {
            dispatches.push(claim.dispatch(bind(&claim, round), groups));
            dispatches.push(commit.dispatch(bind(&commit, round), groups));
        }
        dispatches.push(finish.dispatch(bind(&finish, 0), groups));
        dispatches
    }

    /// Upload, encode, submit, read back: colors `bodies` into `coloring` as
    /// [`color_constraints`](super::color_constraints) does, for the step's mixed executor
    /// and the parity tests.
    pub fn run(
        &mut self,
        context: &GpuContext,
        bodies: impl Iterator<Item = (u32, u32)>,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        coloring: &mut Coloring,
    ) -> Result<(), GpuError> {
        self.upload(context, bodies)?;
        context.submit_pass("batching", |pass| {
            self.encode(context, pass, body_count, ordered, batcher)
        })?;
        self.read_back(context, coloring)
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
        self.colors.download_into(context, &mut self.host_colors)?;
        coloring.colors.clear();
        coloring
            .colors
            .extend(self.host_colors.iter().map(|&color| color as u8));
        coloring.count_batches();
        Ok(())
    }
}
