//! GPU executor of the soft step: the kernels of `solver.wgsl` (contacts) and
//! `solver_joint.wgsl` (joints) over the same [`SolverBody`], [`ContactConstraint`] and
//! [`JointConstraint`] arrays the CPU solves (the contacts laid out in blocks of lanes,
//! [`lanes`]), in the CPU's order: a batch's contacts and joints are one dispatch, its threads
//! taking the contacts, then the joints. Stages without joints run contact-only kernels, those
//! with joints their `_mixed` twins (`solver.wgsl` says why).
//!
//! [`ContactConstraint`]: crate::stages::constraints::ContactConstraint
//! [`lanes`]: crate::stages::constraints::lanes
//!
//! One dispatch per batch and sweep (a dispatch is the GPU's barrier between batches), except
//! that each run of consecutive batches smaller than [`SMALL_BATCH`] is one dispatch of one
//! workgroup that walks them in order, its threads sharing each batch and meeting at a
//! barrier after it, and the overflow batch (whose constraints may share bodies) is one
//! dispatch whose first thread solves it in order. A step is
//!
//! ```text
//!   substeps · (2 + stages · (2 + iterations)) + stages (restitution, when any contact bounces)
//! ```
//!
//! dispatches, with `stages` the parallel batches plus the sequential runs: see
//! [`dispatch_count`]. With a body adjacency ([`DeviceBatched::adjacency`]) the warm start
//! gathers by body in the gravity step's dispatch, `substeps · stages` fewer.
//!
//! Guarantees: the same results as [`solve`](super::solve) up to float rounding (WGSL may
//! fuse multiply-adds); deterministic, since threads of a dispatch touch disjoint bodies and
//! constraints.

use bytemuck::{Pod, Zeroable};

use super::{Batched, SolverBody, SolverSettings};
use crate::dynamics::body::BODY_WGSL;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, encode_all, intern, workgroups_for,
};
use crate::gpu::profiler::DispatchTimer;
use crate::math::{Vec3, tangent_basis};
use crate::stages::batching::layout::{LAYOUT_BATCHES, USED_END};
use crate::stages::constraints::lanes::{Word, lay_out, read_back, with_lanes};
use crate::stages::constraints::{
    CONTACT_CONSTRAINT_WGSL, ContactConstraint, JOINT_CONSTRAINT_WGSL, JointConstraint, STATIC_BODY,
};
use crate::stages::integrate::MAX_ROTATION_PER_STEP;

pub(crate) const SOLVER_BODY_WGSL: &str = include_str!("solver_body.wgsl");
const SOLVER_WGSL: &str = include_str!("solver.wgsl");
const SOLVER_JOINT_WGSL: &str = include_str!("solver_joint.wgsl");
const WARM_START_BODIES_WGSL: &str = include_str!("warm_start_bodies.wgsl");
/// Parameters, bodies, contacts, contact offsets, joints, joint offsets.
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
];
/// [`BINDINGS`] and a body adjacency's starts and entries: `warm_start_bodies`.
const ADJACENCY_BINDINGS: [Binding; 8] = [
    BINDINGS[0],
    BINDINGS[1],
    BINDINGS[2],
    BINDINGS[3],
    BINDINGS[4],
    BINDINGS[5],
    Binding::StorageRead,
    Binding::StorageRead,
];

/// Batches with fewer constraints (contacts and joints) than this are walked in order by one
/// workgroup, together with their small neighbours: a dispatch costs microseconds, and so does
/// a round of a walk's threads over a batch (3.3 µs a round of [`WALK_WORKGROUP`] on an H100,
/// one constraint a thread). Measured there with walks of 256 threads (falling-boxes at 3k,
/// the solver's kernels; the results bitwise the same): 0.622 ms a step with 128, 0.707 with
/// 512 and 0.948 with 1024, against 0.705 when walks had 32 threads; on a settled pile of 100k
/// 2.510, 2.488 and 2.725 ms against 2.584 (BENCHMARKS.md, session 23).
pub const SMALL_BATCH: u32 = 128;

/// Threads per workgroup of the kernels of `solver.wgsl`. A thread solves one constraint and
/// waits on memory most of the time, and a batch holds a few hundred to a few thousand
/// constraints: in workgroups of 64 a batch spreads over four times as many multiprocessors
/// as in workgroups of 256. Measured on an H200 (falling-boxes, the same results bitwise):
/// the solver's kernels took 1.25–1.86 ms a step at 3k bodies and 5.9–6.2 ms at 100k with 64,
/// 1.41–2.12 and 6.4–7.1 with 128, 1.88–2.50 and 9.4–10.0 with 256. On a settled pile of 100k
/// (two calls, `scripts/pile-on-device.sh`) they took 5.64 ms with 32 against 5.92 and 6.05 with
/// 64, and 1.009 against 1.014 ms at falling-boxes' 3k: one warp a workgroup.
pub const SOLVER_WORKGROUP: u32 = 32;

/// Threads of the workgroup that walks a run of small contact-only batches (`solve_walk` and
/// its twins in `solver.wgsl`). A walk is one workgroup on one multiprocessor, so its threads
/// are all it has: with [`SOLVER_WORKGROUP`]'s 32 a batch of a hundred constraints took four
/// rounds, each as long as a thread's chain of memory round trips. 256 is the most every
/// WebGPU device runs; on an H100 the solve kernel's registers (161) leave room for 384.
pub const WALK_WORKGROUP: u32 = 256;

/// Mirrors `SolverParams` in `solver.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SolverParams {
    pub gravity: Vec3,
    pub h: f32,
    pub first_batch: u32,
    pub end_batch: u32,
    pub sequential: u32,
    pub use_bias: u32,
    pub max_push_velocity: f32,
    pub restitution_threshold: f32,
    pub body_count: u32,
    /// The overflow batch, when a [`StageMode::Workgroup`] walk may hold it (a device layout's),
    /// else [`NO_BATCH`].
    pub overflow_batch: u32,
    /// [`SolverSettings::contact_softness`] and `static_softness` ([`Softness::words`]).
    pub softness: [f32; 4],
    pub static_softness: [f32; 4],
}
const _: () = assert!(size_of::<SolverParams>() == 80);

impl SolverParams {
    /// A solve sweep's parameters over every batch, for `settings` and `body_count` bodies;
    /// the stages set the batches and the sweep.
    pub fn new(settings: &SolverSettings, body_count: usize, overflow_batch: u32) -> Self {
        Self {
            gravity: settings.gravity,
            h: settings.dt / settings.substeps as f32,
            first_batch: 0,
            end_batch: 0,
            sequential: 0,
            use_bias: 1,
            max_push_velocity: settings.max_push_velocity,
            restitution_threshold: settings.restitution_threshold,
            body_count: u32::try_from(body_count).expect("body count fits in u32"),
            overflow_batch,
            softness: settings.contact_softness.words(),
            static_softness: settings.static_softness.words(),
        }
    }
}

/// [`SolverParams::overflow_batch`] when no walk holds the overflow batch.
pub const NO_BATCH: u32 = u32::MAX;

/// [`wgsl`] with the warm start by body (`warm_start_bodies`; the Jacobi solver's extra
/// bindings are others).
fn solver_wgsl() -> Source {
    wgsl().snippet("warm_start_bodies.wgsl", WARM_START_BODIES_WGSL)
}

/// The solver's WGSL: body and constraint structs, integration helpers, kernels.
pub fn wgsl() -> Source {
    with_lanes(Source::new())
        .constant_u32("SOLVER_WORKGROUP", SOLVER_WORKGROUP)
        .constant_u32("WALK_WORKGROUP", WALK_WORKGROUP)
        .constant_u32("NO_BATCH", NO_BATCH)
        .constant_u32("LAYOUT_USED_END", USED_END as u32)
        .constant_f32("MAX_ROTATION_PER_STEP", MAX_ROTATION_PER_STEP)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("joint_constraint.wgsl", JOINT_CONSTRAINT_WGSL)
        .snippet("solver_body.wgsl", SOLVER_BODY_WGSL)
        .snippet("solver.wgsl", SOLVER_WGSL)
        .snippet("solver_joint.wgsl", SOLVER_JOINT_WGSL)
}

/// Batches `first..end` solved by one dispatch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Stage {
    pub first: u32,
    pub end: u32,
    pub mode: StageMode,
}

/// How a [`Stage`]'s dispatch goes through its batches; the value is `SolverParams::sequential`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StageMode {
    /// One batch, one thread per constraint, as many workgroups as it takes: the contacts'
    /// workgroups, then the joints'.
    Parallel = 0,
    /// One workgroup walks a run of small batches in order, a barrier after each.
    Workgroup = 1,
    /// The overflow batch: its first thread alone, in order.
    Alone = 2,
}

/// The dispatches of one sweep, from the batch offsets of the contacts and of the joints
/// (`offsets[b]..offsets[b + 1]` is batch b; the last batch is the overflow batch when
/// `has_overflow`).
pub fn stages(contact_offsets: &[u32], joint_offsets: &[u32], has_overflow: bool) -> Vec<Stage> {
    assert_eq!(
        contact_offsets.len(),
        joint_offsets.len(),
        "contacts and joints have the same batches"
    );
    let batch_count = contact_offsets.len().saturating_sub(1) as u32;
    let size = |batch| batch_size(contact_offsets, joint_offsets, batch as usize);
    plan(batch_count, size, has_overflow.then(|| batch_count - 1))
}

/// The dispatches of one sweep over a device layout's [`LAYOUT_BATCHES`] batches, the last the
/// overflow batch, from `expected[b]`, batch b's size in a recent step: the batches expected
/// to be large get dispatches of their own, the others are walked, the overflow batch by one
/// thread (see [`SolverParams::overflow_batch`]). Any plan gives the same results: it only
/// changes which constraints of one batch share a dispatch.
pub fn device_stages(expected: &[u32]) -> Vec<Stage> {
    assert_eq!(expected.len(), LAYOUT_BATCHES, "a size per layout batch");
    let overflow = LAYOUT_BATCHES as u32 - 1;
    let size = |batch| {
        if batch == overflow {
            0
        } else {
            expected[batch as usize]
        }
    };
    plan(LAYOUT_BATCHES as u32, size, None)
}

/// Stages over `batch_count` batches of `size`s: each batch of at least [`SMALL_BATCH`] a
/// parallel stage, each run of smaller ones a walk, and the batch `alone` (the overflow batch)
/// one thread's.
fn plan(batch_count: u32, size: impl Fn(u32) -> u32, alone: Option<u32>) -> Vec<Stage> {
    let mut stages = Vec::new();
    let mut small_from = 0;
    for batch in 0..batch_count {
        let overflow = alone == Some(batch);
        if size(batch) < SMALL_BATCH && !overflow {
            continue;
        }
        if small_from < batch {
            stages.push(Stage {
                first: small_from,
                end: batch,
                mode: StageMode::Workgroup,
            });
        }
        small_from = batch + 1;
        stages.push(Stage {
            first: batch,
            end: batch + 1,
            mode: if overflow {
                StageMode::Alone
            } else {
                StageMode::Parallel
            },
        });
    }
    if small_from < batch_count {
        stages.push(Stage {
            first: small_from,
            end: batch_count,
            mode: StageMode::Workgroup,
        });
    }
    stages
}

/// Whether `contacts` hold what the device's contact sweeps take from elsewhere instead of
/// loading it (`load_header` in `solver.wgsl`): each side's inverse mass is its body's (0 for a
/// static side), the tangents are `tangent_basis(normal)`, and the softness is `settings`' for
/// those masses. Every constraint the rows build with the step's softness does; a hand-made
/// one that does not would be solved differently on the two executors.
fn derived_fields_hold(
    bodies: &[SolverBody],
    contacts: &[ContactConstraint],
    settings: &SolverSettings,
) -> bool {
    let mass = |body: u32| match body {
        STATIC_BODY => Some(0.0),
        body => bodies.get(body as usize).map(|b| b.inverse_mass),
    };
    contacts.iter().all(|c| {
        let (tangent1, tangent2) = tangent_basis(c.normal);
        mass(c.body_a) == Some(c.inverse_mass_a)
            && mass(c.body_b) == Some(c.inverse_mass_b)
            && [tangent1, tangent2] == c.tangents()
            && c.softness == settings.contact_softness_of(c.inverse_mass_a, c.inverse_mass_b)
    })
}

/// Constraints of batch `batch`: its contacts and its joints.
fn batch_size(contact_offsets: &[u32], joint_offsets: &[u32], batch: usize) -> u32 {
    contact_offsets[batch + 1] - contact_offsets[batch] + joint_offsets[batch + 1]
        - joint_offsets[batch]
}

/// Dispatches of one step over `stage_count` stages (see the module docs); with `by_body`,
/// the warm start gathers by body in the gravity step's dispatch ([`DeviceBatched::adjacency`]).
pub fn dispatch_count(
    stage_count: usize,
    settings: &SolverSettings,
    restitution: bool,
    by_body: bool,
) -> usize {
    let warm_start = if by_body { 0 } else { stage_count };
    let per_substep = 2 + warm_start + stage_count * (1 + settings.iterations as usize);
    settings.substeps as usize * per_substep + if restitution { stage_count } else { 0 }
}

/// Parameter slots of a stage: which sweep it runs.
#[derive(Clone, Copy)]
enum Variant {
    /// Solve with bias; also warm start and restitution.
    Solve = 0,
    /// Relax: no bias.
    Relax = 1,
}
const VARIANTS: usize = 2;

/// What the bind groups were built for; rebuilt when any of it changes.
type Key = (
    [wgpu::Buffer; 5],
    Option<[wgpu::Buffer; 2]>,
    usize,
    Vec<(u32, u32, StageMode)>,
    [u32; 9],
);

/// Bind groups for the last key: one per (stage, variant), then one for the body kernels,
/// and one for `warm_start_bodies` when there is an adjacency.
struct Bound {
    key: Key,
    groups: Vec<wgpu::BindGroup>,
    by_body: Option<wgpu::BindGroup>,
    /// Keeps the parameter blocks the bind groups point into alive.
    _slots: UniformSlots,
}

/// The batched constraints on the device, as [`GpuSolver::encode`] sweeps them: the arrays of
/// [`Batched`], and what sizes the dispatches.
pub struct DeviceBatched<'a> {
    /// The contact constraints in blocks of lanes ([`lanes`](crate::stages::constraints::lanes)).
    pub contacts: &'a GpuVec<Word>,
    pub contact_offsets: &'a GpuVec<u32>,
    pub joints: &'a GpuVec<JointConstraint>,
    pub joint_offsets: &'a GpuVec<u32>,
    pub sizes: BatchSizes<'a>,
    /// Each body's constraints in batch order, as starts and entries
    /// ([`GpuBodyAdjacency`](super::adjacency::GpuBodyAdjacency)): the warm start then gathers
    /// by body, one dispatch with the gravity step instead of one per batch (the same
    /// velocities). Only without joints.
    pub adjacency: Option<(&'a GpuVec<u32>, &'a GpuVec<u32>)>,
}

/// Where the dispatches learn each batch's size.
#[derive(Clone, Copy)]
pub enum BatchSizes<'a> {
    /// The host's copy of the offsets, contacts' and joints' (the last batch is the overflow
    /// batch when `has_overflow`).
    Host {
        contact_offsets: &'a [u32],
        joint_offsets: &'a [u32],
        has_overflow: bool,
    },
    /// A device layout's ([`GpuBatchLayout`](crate::stages::batching::layout::GpuBatchLayout)):
    /// [`LAYOUT_BATCHES`] batches of contacts, no joints (`joint_offsets` all zero), the last
    /// the overflow batch. `expected[b]` is batch b's size in a recent step: it chooses the
    /// plan ([`device_stages`]) and sizes each parallel batch's dispatch (whose threads take
    /// more than one constraint each when the batch grew), never the results.
    Device { expected: &'a [u32] },
}

/// The GPU solver: its kernels with the bind groups for the arrays it last saw, and its own
/// arrays for [`run`](Self::run).
pub struct GpuSolver {
    encoder: SolverEncoder,
    arrays: HostArrays,
}

/// Device copies of a host solve's arrays, for the `run` of a GPU solver: upload, encode the
/// step, download.
pub(crate) struct HostArrays {
    bodies: GpuVec<SolverBody>,
    contacts: GpuVec<Word>,
    /// The host's constraints in blocks of lanes, on their way to and from `contacts`.
    words: Vec<Word>,
    contact_offsets: GpuVec<u32>,
    joints: GpuVec<JointConstraint>,
    joint_offsets: GpuVec<u32>,
}

impl HostArrays {
    pub(crate) fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            bodies: GpuVec::with_capacity(context, "solver bodies", 0)?,
            contacts: GpuVec::with_capacity(context, "solver contacts", 0)?,
            words: Vec::new(),
            contact_offsets: GpuVec::with_capacity(context, "solver contact batch offsets", 0)?,
            joints: GpuVec::with_capacity(context, "solver joints", 0)?,
            joint_offsets: GpuVec::with_capacity(context, "solver joint batch offsets", 0)?,
        })
    }

    /// Uploads `bodies` and `batched`, submits one pass of `encode` (the device arrays and
    /// whether any contact bounces) and downloads the bodies and impulses back into them.
    pub(crate) fn run(
        &mut self,
        context: &GpuContext,
        label: &str,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: &SolverSettings,
        encode: impl FnOnce(&mut wgpu::ComputePass<'_>, &GpuVec<SolverBody>, &DeviceBatched, bool),
    ) -> Result<(), GpuError> {
        debug_assert!(
            derived_fields_hold(bodies, batched.contacts, settings),
            "the device's contact sweeps take tangents, inverse masses and softness from elsewhere"
        );
        self.bodies.upload(context, bodies)?;
        lay_out(batched.contacts, &mut self.words);
        self.contacts.upload(context, &self.words)?;
        self.contact_offsets
            .upload(context, batched.contact_offsets)?;
        self.joints.upload(context, batched.joints)?;
        self.joint_offsets.upload(context, batched.joint_offsets)?;
        let restitution = batched.contacts.iter().any(|c| c.restitution > 0.0);
        let device = DeviceBatched {
            contacts: &self.contacts,
            contact_offsets: &self.contact_offsets,
            joints: &self.joints,
            joint_offsets: &self.joint_offsets,
            sizes: BatchSizes::Host {
                contact_offsets: batched.contact_offsets,
                joint_offsets: batched.joint_offsets,
                has_overflow: batched.has_overflow,
            },
            adjacency: None,
        };
        context.submit_pass(label, |pass| {
            encode(pass, &self.bodies, &device, restitution)
        });
        bodies.copy_from_slice(&self.bodies.download(context)?);
        self.contacts.download_into(context, &mut self.words)?;
        read_back(&self.words, batched.contacts);
        batched
            .joints
            .copy_from_slice(&self.joints.download(context)?);
        Ok(())
    }
}

/// Kernels and bind groups: what encodes a step.
struct SolverEncoder {
    context: GpuContext,
    warm_start: Kernel,
    solve: Kernel,
    restitution: Kernel,
    /// Their twins for walks ([`WALK_WORKGROUP`]).
    warm_start_walk: Kernel,
    solve_walk: Kernel,
    restitution_walk: Kernel,
    /// Warm start and solve for stages whose batches hold joints (see `sweep_mixed`), built
    /// at the first step with joints: with a cold Mesa shader cache, lavapipe's LLVM took
    /// more than 6 minutes over them (seconds once cached), which a world without joints
    /// need not wait for.
    mixed: Option<MixedKernels>,
    integrate_velocities: Kernel,
    integrate_positions: Kernel,
    /// Gravity and the warm start gathered by body ([`DeviceBatched::adjacency`]).
    warm_start_bodies: Kernel,
    bound: Option<Bound>,
    dispatches: Vec<Dispatch>,
}

/// The kernels of one sweep: contact-only for a parallel batch or the overflow batch alone,
/// contact-only for a walk, and the `_mixed` twin for stages whose batches hold joints.
#[derive(Clone, Copy)]
struct SweepKernels<'a> {
    batch: &'a Kernel,
    walk: &'a Kernel,
    mixed: Option<&'a Kernel>,
}

/// The `_mixed` kernels of `solver.wgsl`.
struct MixedKernels {
    warm_start: Kernel,
    solve: Kernel,
}

impl MixedKernels {
    fn new(context: &GpuContext) -> Self {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Self {
            warm_start: kernel("warm_start_mixed"),
            solve: kernel("solve_mixed"),
        }
    }
}

impl GpuSolver {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Ok(Self {
            encoder: SolverEncoder {
                context: context.clone(),
                warm_start: kernel("warm_start"),
                solve: kernel("solve"),
                restitution: kernel("restitution"),
                warm_start_walk: kernel("warm_start_walk"),
                solve_walk: kernel("solve_walk"),
                restitution_walk: kernel("restitution_walk"),
                mixed: None,
                integrate_velocities: kernel("integrate_velocities"),
                integrate_positions: kernel("integrate_positions"),
                warm_start_bodies: Kernel::new(
                    context,
                    "warm_start_bodies",
                    &solver_wgsl(),
                    "warm_start_bodies",
                    &ADJACENCY_BINDINGS,
                ),
                bound: None,
                dispatches: Vec::new(),
            },
            arrays: HostArrays::new(context)?,
        })
    }

    /// Encodes the whole soft step over device-resident arrays: `bodies` (all of them) and
    /// the `batched` constraints, as the rows build them (see [`Self::run`]). `restitution`:
    /// whether any contact bounces (false skips the restitution sweep, which would change
    /// nothing). Returns the number of dispatches encoded.
    pub fn encode(
        &mut self,
        pass: &mut wgpu::ComputePass<'_>,
        bodies: &GpuVec<SolverBody>,
        batched: &DeviceBatched,
        settings: SolverSettings,
        restitution: bool,
    ) -> usize {
        self.encoder
            .encode(pass, bodies, batched, settings, restitution)
    }

    /// The soft step with [`solve`](super::solve)'s signature: uploads the bodies and the
    /// batched contacts and joints, solves on the GPU, downloads all three. The contacts must
    /// be as the rows build them: each side's inverse mass its body's, the tangents
    /// `tangent_basis(normal)`, the softness `settings`' (the sweeps take them from there;
    /// checked in debug builds).
    pub fn run(
        &mut self,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: SolverSettings,
    ) -> Result<(), GpuError> {
        let context = self.encoder.context.clone();
        let encoder = &mut self.encoder;
        self.arrays.run(
            &context,
            "solver",
            bodies,
            batched,
            &settings,
            |pass, bodies, device, restitution| {
                encoder.encode(pass, bodies, device, settings, restitution);
            },
        )
    }
}

impl SolverEncoder {
    /// [`GpuSolver::encode`].
    fn encode(
        &mut self,
        pass: &mut wgpu::ComputePass<'_>,
        bodies: &GpuVec<SolverBody>,
        batched: &DeviceBatched,
        settings: SolverSettings,
        restitution: bool,
    ) -> usize {
        let (stages, overflow_batch) = match batched.sizes {
            BatchSizes::Host {
                contact_offsets,
                joint_offsets,
                has_overflow,
            } => (
                stages(contact_offsets, joint_offsets, has_overflow),
                NO_BATCH,
            ),
            BatchSizes::Device { expected, .. } => {
                (device_stages(expected), LAYOUT_BATCHES as u32 - 1)
            }
        };
        let key: Key = (
            [
                bodies.buffer().clone(),
                batched.contacts.buffer().clone(),
                batched.contact_offsets.buffer().clone(),
                batched.joints.buffer().clone(),
                batched.joint_offsets.buffer().clone(),
            ],
            batched
                .adjacency
                .map(|(starts, entries)| [starts.buffer().clone(), entries.buffer().clone()]),
            bodies.len(),
            stages.iter().map(|s| (s.first, s.end, s.mode)).collect(),
            [
                settings.dt.to_bits(),
                settings.substeps,
                settings.iterations,
                settings.gravity.x.to_bits(),
                settings.gravity.y.to_bits(),
                settings.gravity.z.to_bits(),
                settings.max_push_velocity.to_bits(),
                settings.restitution_threshold.to_bits(),
                overflow_batch,
            ],
        );
        if self.bound.as_ref().is_none_or(|bound| bound.key != key) {
            let bound = self.bind(key, &stages, bodies, batched, settings, overflow_batch);
            self.bound = Some(bound);
        }
        let Some(bound) = &self.bound else {
            unreachable!("bound just above")
        };
        let body_groups = workgroups_for(bodies.len(), SOLVER_WORKGROUP);
        // Per stage: its workgroups, and whether its batches hold joints.
        let stage_sizes: Vec<(u32, bool)> = stages
            .iter()
            .map(|stage| match batched.sizes {
                _ if stage.mode != StageMode::Parallel => {
                    (1, stage_has_joints(batched.sizes, stage))
                }
                BatchSizes::Host {
                    contact_offsets,
                    joint_offsets,
                    ..
                } => {
                    let size = batch_size(contact_offsets, joint_offsets, stage.first as usize);
                    let groups = workgroups_for(size as usize, SOLVER_WORKGROUP);
                    (groups, stage_has_joints(batched.sizes, stage))
                }
                BatchSizes::Device { expected } => {
                    // Room for the batch to grow by an eighth before threads take two each.
                    let size = expected[stage.first as usize] as usize;
                    let groups = workgroups_for(size + size / 8, SOLVER_WORKGROUP);
                    (groups.max(1), false)
                }
            })
            .collect();
        let group = |stage: usize, variant: Variant| {
            bound.groups[stage * VARIANTS + variant as usize].clone()
        };
        let body_group = bound.groups[stages.len() * VARIANTS].clone();
        let dispatches = &mut self.dispatches;
        dispatches.clear();
        // Where each dispatch is timed, a parallel batch's line names its batch: how a
        // batch's time grows with its size tells launches from bytes.
        let by_batch = DispatchTimer::is_active();
        // A stage with joints runs the mixed twin of the contact-only kernel, a walk without
        // joints the walk's.
        let sweep = |dispatches: &mut Vec<Dispatch>, kernels: SweepKernels, variant: Variant| {
            for (stage, &(groups, joints)) in stage_sizes.iter().enumerate() {
                let kernel = match (joints, stages[stage].mode) {
                    (true, _) => kernels
                        .mixed
                        .expect("the mixed kernels are built before a stage with joints"),
                    (false, StageMode::Workgroup) => kernels.walk,
                    (false, _) => kernels.batch,
                };
                let mut dispatch = kernel.dispatch(group(stage, variant), groups);
                if by_batch && stages[stage].mode == StageMode::Parallel {
                    let name = format!("{} / batch {:02}", kernel.name, stages[stage].first);
                    dispatch = dispatch.named(intern(name));
                }
                dispatches.push(dispatch);
            }
        };
        if stage_sizes.iter().any(|&(_, joints)| joints) && self.mixed.is_none() {
            self.mixed = Some(MixedKernels::new(&self.context));
        }
        let mixed = self.mixed.as_ref();
        let warm_start = SweepKernels {
            batch: &self.warm_start,
            walk: &self.warm_start_walk,
            mixed: mixed.map(|m| &m.warm_start),
        };
        let solve = SweepKernels {
            batch: &self.solve,
            walk: &self.solve_walk,
            mixed: mixed.map(|m| &m.solve),
        };
        // The warm start by body needs contacts alone in every stage.
        let by_body = bound
            .by_body
            .as_ref()
            .filter(|_| stage_sizes.iter().all(|&(_, joints)| !joints));
        for _ in 0..settings.substeps {
            match by_body {
                Some(group) => {
                    dispatches.push(self.warm_start_bodies.dispatch(group.clone(), body_groups))
                }
                None => {
                    dispatches.push(
                        self.integrate_velocities
                            .dispatch(body_group.clone(), body_groups),
                    );
                    sweep(dispatches, warm_start, Variant::Solve);
                }
            }
            for _ in 0..settings.iterations {
                sweep(dispatches, solve, Variant::Solve);
            }
            dispatches.push(
                self.integrate_positions
                    .dispatch(body_group.clone(), body_groups),
            );
            sweep(dispatches, solve, Variant::Relax);
        }
        if restitution {
            // Joints do not bounce: the contact-only kernels everywhere.
            let restitution = SweepKernels {
                batch: &self.restitution,
                walk: &self.restitution_walk,
                mixed: Some(&self.restitution),
            };
            sweep(dispatches, restitution, Variant::Solve);
        }
        encode_all(pass, dispatches);
        debug_assert_eq!(
            dispatches.len(),
            dispatch_count(stages.len(), &settings, restitution, by_body.is_some())
        );
        dispatches.len()
    }

    fn bind(
        &self,
        key: Key,
        stages: &[Stage],
        bodies: &GpuVec<SolverBody>,
        batched: &DeviceBatched,
        settings: SolverSettings,
        overflow_batch: u32,
    ) -> Bound {
        let base = SolverParams::new(&settings, bodies.len(), overflow_batch);
        let mut blocks = Vec::with_capacity(stages.len() * VARIANTS + 1);
        for stage in stages {
            let params = SolverParams {
                first_batch: stage.first,
                end_batch: stage.end,
                sequential: stage.mode as u32,
                ..base
            };
            // In the order of `Variant`.
            blocks.push(params);
            blocks.push(SolverParams {
                use_bias: 0,
                ..params
            });
        }
        blocks.push(base);
        let slots = UniformSlots::new(&self.context, "solver params", &blocks);
        // Every kernel of the file shares one layout.
        let groups = (0..blocks.len())
            .map(|slot| {
                self.solve.bind(
                    &self.context,
                    &[
                        slots.binding(slot),
                        bodies.whole(),
                        batched.contacts.whole(),
                        batched.contact_offsets.whole(),
                        batched.joints.whole(),
                        batched.joint_offsets.whole(),
                    ],
                )
            })
            .collect();
        let by_body = batched.adjacency.map(|(starts, entries)| {
            self.warm_start_bodies.bind(
                &self.context,
                &[
                    slots.binding(blocks.len() - 1),
                    bodies.whole(),
                    batched.contacts.whole(),
                    batched.contact_offsets.whole(),
                    batched.joints.whole(),
                    batched.joint_offsets.whole(),
                    starts.whole(),
                    entries.whole(),
                ],
            )
        });
        Bound {
            key,
            groups,
            by_body,
            _slots: slots,
        }
    }
}

/// Whether `stage`'s batches hold joints (never a device layout's).
fn stage_has_joints(sizes: BatchSizes, stage: &Stage) -> bool {
    match sizes {
        BatchSizes::Host { joint_offsets, .. } => {
            joint_offsets[stage.end as usize] > joint_offsets[stage.first as usize]
        }
        BatchSizes::Device { .. } => false,
    }
}
