use std::time::Instant;

use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider, ColliderData};
use crate::dynamics::island::Islands;
use crate::dynamics::island_gpu::{GpuIslandLinks, GpuLinkPairs};
use crate::dynamics::joint::Joint;
use crate::dynamics::rest_gpu::{GpuRestTimers, RestInputs, RestTally};
use crate::dynamics::wake::GpuWakeCandidates;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{Dispatch, encode_all};
use crate::gpu::prims::fill::copy_dispatch;
use crate::gpu::prims::scatter::GpuScatter;
use crate::gpu::profiler::{GpuProfiler, SpanPath, record_copy};
use crate::math::Aabb;
use crate::pipeline::config::Softness;
use crate::profile::{Profiler, SpanKind};
use crate::stages::aabb::gpu::GpuAabbs;
use crate::stages::batching::gpu::GpuBatching;
use crate::stages::batching::layout::{GpuBatchLayout, LAYOUT_BATCHES};
use crate::stages::batching::{Batcher, Coloring, MAX_ROUNDS};
use crate::stages::broadphase::gpu::GpuBroadphase;
use crate::stages::constraints::gpu::{GpuRowInputs, GpuRows};
use crate::stages::constraints::joint_gpu::{GpuJointInputs, GpuJointRows};
use crate::stages::constraints::lanes::{Word, lay_out, read_back};
use crate::stages::constraints::tally::{GpuRowTally, PairTally};
use crate::stages::constraints::{ContactConstraint, JointConstraint, RowInputs};
use crate::stages::integrate::gpu::{GpuFinalizeBodies, GpuPrepareBodies};
use crate::stages::narrowphase::gpu::{GpuNarrowphase, GpuNarrowphaseInputs, shape_kinds};
use crate::stages::narrowphase::summary::{GpuPairSummaries, PairSummary};
use crate::stages::narrowphase::{
    NarrowphaseInputs, PairContact, gpu_pair, pack_hulls, update_contacts_where,
};
use crate::stages::pairs::gpu::GpuPairDiff;
use crate::stages::solver::adjacency::{AdjacencyInputs, GpuBodyAdjacency};
use crate::stages::solver::batched::{BatchedImpulses, BatchedJointImpulses, GpuBatched};
use crate::stages::solver::gpu::{BatchSizes, DeviceBatched, GpuSolver, SMALL_BATCH};
use crate::stages::solver::jacobi_gpu::GpuJacobi;
use crate::stages::solver::{Batched, SolverBody, SolverKind, SolverSettings};

mod speculation;

pub(crate) use speculation::StepPlan;
use speculation::{Speculated, StepHold, unplanned};

/// Batching rounds a world encodes at first: falling-boxes at 3k bodies needs 24 to 31 (the
/// talk's batcher makes one batch a round), the colors batcher as many.
const FIRST_BATCHING_ROUNDS: usize = 32;
/// Rounds encoded past those the last batching needed: a pile's contact graph changes a little
/// from step to step, and the rounds past those encoded run in one workgroup.
const BATCHING_ROUND_SLACK: usize = 4;
/// The solver's plan for a world's first device layout, before any size is known: falling
/// boxes use 11 to 15 colors, the first ones large.
const FIRST_EXPECTED_BATCH_SIZES: [u32; LAYOUT_BATCHES] = {
    let mut sizes = [0; LAYOUT_BATCHES];
    let mut batch = 0;
    while batch < 12 {
        sizes[batch] = SMALL_BATCH;
        batch += 1;
    }
    sizes
};

/// Profile lines of one GPU stage: uploads, recording the kernels (host), the kernels (GPU
/// time), submitting and waiting on the host, downloads.
struct StageSpans {
    upload: SpanPath,
    encode: SpanPath,
    kernel: SpanPath,
    wait: SpanPath,
    download: SpanPath,
}

const AABB: StageSpans = StageSpans {
    upload: &["aabb", "copy to gpu"],
    encode: &["aabb", "encode"],
    kernel: &["aabb", "kernel"],
    wait: &["aabb", "submit and wait"],
    download: &["aabb", "copy to cpu"],
};
const BROADPHASE: StageSpans = StageSpans {
    upload: &["broadphase", "copy to gpu"],
    encode: &["broadphase", "encode"],
    kernel: &["broadphase", "kernels"],
    wait: &["broadphase", "submit and wait"],
    download: &["broadphase", "copy to cpu"],
};
const CONSTRAINTS: StageSpans = StageSpans {
    upload: &["constraints", "copy to gpu"],
    encode: &["constraints", "encode"],
    kernel: &["constraints", "kernels"],
    wait: &["constraints", "submit and wait"],
    download: &["constraints", "copy to cpu"],
};
/// The constraints' submission when the rows stay on the device: nothing to wait for.
const CONSTRAINTS_SUBMIT: SpanPath = &["constraints", "submit"];
/// The joint rows' kernel: its own pass in the constraints' submission, so the profile shows
/// it beside the contact rows' kernels.
const JOINT_ROWS_KERNEL: SpanPath = &["constraints", "joint kernel"];
/// The islands' links ([`GpuIslandLinks`]): a pass of their own in the rows' submission.
const ISLAND_LINKS_KERNEL: SpanPath = &["constraints", "kernels: island links"];
/// The pairs' summaries read back after the collision, when a step needs them after all.
const SUMMARIES_DOWNLOAD: SpanPath = &["pair summaries to cpu"];
/// The pairs' keys read back, when a step passes over the pairs on the host after all.
const PAIR_KEYS_DOWNLOAD: SpanPath = &["pair keys to cpu"];
/// Their roots' read-back, which the sleep waits for.
const ISLAND_LINKS_DOWNLOAD: SpanPath = &["sleep", "copy links to cpu"];
const REST_TIMERS_DOWNLOAD: SpanPath = &["sleep", "copy rest timers to cpu"];
const BATCHING: StageSpans = StageSpans {
    upload: &["batching", "copy to gpu"],
    encode: &["batching", "encode"],
    kernel: &["batching", "kernels"],
    wait: &["batching", "submit and wait"],
    download: &["batching", "copy to cpu"],
};
/// The batching's submission when its layout stays on the device: nothing to wait for.
const BATCHING_SUBMIT: SpanPath = &["batching", "submit"];
const SOLVER: StageSpans = StageSpans {
    upload: &["solver", "copy to gpu"],
    encode: &["solver", "encode"],
    kernel: &["solver", "kernels"],
    wait: &["solver", "submit and wait"],
    download: &["solver", "copy to cpu"],
};
/// The Jacobi solver's kernels get their own line, so the profile says which solver ran.
const JACOBI_SOLVER: StageSpans = StageSpans {
    kernel: &["solver", "jacobi kernels"],
    ..SOLVER
};
/// Stage 8 on the device after a solve elsewhere ([`GpuStages::integrate`]).
const INTEGRATE: StageSpans = StageSpans {
    upload: &["integrate", "copy to gpu"],
    encode: &["integrate", "encode"],
    kernel: &["integrate", "kernel"],
    wait: &["integrate", "submit and wait"],
    download: &["integrate", "copy to cpu"],
};
/// Stage 8 in the GPU solver's submission: its kernel and the bodies' read-back.
const SOLVER_INTEGRATE_KERNEL: SpanPath = &["solver", "integrate kernel"];
/// The chained solver's passes around its sweeps ([`SOLVER`]'s `kernel`): the rows gathered
/// into batch order (with the warm start's body adjacency), and their impulses read out.
const SOLVER_LAYOUT_KERNEL: SpanPath = &["solver", "kernels: rows in batch order"];
const SOLVER_IMPULSES_KERNEL: SpanPath = &["solver", "kernels: impulses out"];
const SOLVER_BODIES_DOWNLOAD: SpanPath = &["solver", "copy bodies to cpu"];
/// The batching's and the solver's commands recorded during the collision's wait
/// ([`SolveAhead`]).
const SOLVER_ENCODED_AHEAD: SpanPath =
    &["collision", "batching and solver encoded (during the wait)"];
/// The collision's first submission, the trees' pass (the rest follows it: `collision`,
/// `submit and wait`).
const COLLISION_TREES_SUBMIT: SpanPath = &["collision", "submit the trees"];
/// Stages 1–4 in one submission ([`GpuStages::collide`]).
const COLLISION: StageSpans = StageSpans {
    upload: &["collision", "copy bodies to gpu"],
    encode: &["collision", "encode"],
    kernel: &["collision", "kernels"],
    wait: &["collision", "submit and wait"],
    download: &["collision", "copy to cpu"],
};
/// The batching rounds the next step dispatches, from the last batching's: its `rounds` that
/// found a constraint left, and the first round that started with few enough left for
/// `rest_rounds` to list them (when one did), and a few more. The rounds after those run in
/// one workgroup, which takes about as long for one as a claim and a commit dispatch take;
/// a round started with more left than it lists would go over every constraint there.
fn next_batching_rounds(rounds: usize, listable_from: Option<usize>) -> usize {
    let dispatched = listable_from.map_or(rounds, |first| first.min(rounds));
    (dispatched + BATCHING_ROUND_SLACK).min(MAX_ROUNDS)
}

/// Pairs whose keys [`GpuStages::collide`] copies out of the broadphase's buffer, and whose
/// summaries it copies back, with its kernels, from the `last` step's count: an eighth more,
/// and at least 1024 more. At rest the pairs change by a few hundred a step (a settled pile of
/// 100k boxes: 588k pairs, ±30), so this copies about 10% more than the pairs rather than the
/// key buffers' whole capacity, up to twice the pairs; a step with more pairs copies them all
/// again in a second submission.
fn expected_pair_count(last: usize) -> usize {
    last + (last / 8).max(1024)
}

/// Copies the first `count` pair keys from the broadphase into `keys`, where the rows read
/// them and the host fetches them when it needs them ([`GpuStages::read_pair_keys`]), and
/// encodes the download of the first `count` summaries.
fn encode_summary_downloads(
    context: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    broadphase: &GpuBroadphase,
    keys: &GpuVec<u64>,
    summaries: Option<&mut GpuPairSummaries>,
    count: usize,
) {
    if count > 0 {
        let bytes = (count * size_of::<u64>()) as u64;
        encoder.copy_buffer_to_buffer(broadphase.keys().buffer(), 0, keys.buffer(), 0, bytes);
    }
    if let Some(summaries) = summaries {
        summaries
            .summaries
            .encode_download_prefix(context, encoder, count);
    }
}

/// [`GpuStages::collide`]'s kernels, timed as four passes: the AABBs and the trees' builds,
/// the trees' traversal and the sort of its pairs (the broadphase), each pair's lookup in last
/// step's, and the narrowphase with the pairs' summaries (the contacts).
const COLLISION_KERNELS: [SpanPath; 4] = [
    &["collision", "kernels: aabbs, trees"],
    &["collision", "kernels: pairs"],
    &["collision", "kernels: pair lookup"],
    &["collision", "kernels: contacts"],
];
/// With the contacts on the device, a fifth pass: what the host would pass over every pair
/// for (the pairs added and removed, the rows' tally, the wake test's candidates).
const COLLISION_COUNTS_KERNEL: SpanPath = &["collision", "kernels: counts for the host"];
/// [`GpuStages::collide`]'s other uploads: the trees' body lists (when bodies fell asleep or
/// woke), and the jointed pairs the narrowphase skips with, while bodies sleep, which do.
const COLLISION_TREE_BODIES: SpanPath = &["collision", "copy tree bodies to gpu"];
const COLLISION_PAIR_LISTS: SpanPath = &["collision", "copy pair lists to gpu"];
/// [`GpuStages::collide`]'s upload of the host's pair cache: its own line, shown only on the
/// steps that need it.
const PAIR_UPLOAD: SpanPath = &["collision", "copy pairs to gpu"];
const NARROWPHASE: StageSpans = StageSpans {
    upload: &["narrowphase", "copy to gpu"],
    encode: &["narrowphase", "encode"],
    kernel: &["narrowphase", "kernel"],
    wait: &["narrowphase", "submit and wait"],
    download: &["narrowphase", "copy to cpu"],
};

/// Where [`GpuStages::solve_batched`] finds the batches.
pub(crate) enum BatchLayout<'a> {
    /// Laid out on the host: `order[i]` is the contact row at batched place i,
    /// `joint_order[i]` the slot of the joint row there, `offsets` and `joint_offsets` the
    /// batch offsets; the last batch is the overflow batch when `has_overflow`.
    Host {
        order: &'a [u32],
        offsets: &'a [u32],
        joint_order: &'a [u32],
        joint_offsets: &'a [u32],
        has_overflow: bool,
    },
    /// Laid out on the device by this step's
    /// [`color_constraints_on_device`](GpuStages::color_constraints_on_device): the colors come
    /// back into `coloring` with the solve's results.
    Device { coloring: &'a mut Coloring },
}

/// The manifold slots the GPU rows read: pairs, then children.
pub(crate) enum RowSlots<'a> {
    /// Uploaded from the host.
    Host {
        keys: &'a [u64],
        contacts: &'a [PairContact],
    },
    /// This step's GPU narrowphase output, already on the device: every slot is a pair and the
    /// narrowphase computed all of them ([`GpuStages::narrowphase_output_is_pair_cache`]).
    Narrowphase,
}

/// Where [`GpuStages::build_constraints`] leaves the rows.
pub(crate) enum RowsTo<'a> {
    /// Back to the host: the contacts' rows, and the listed joints'.
    Host(&'a mut Vec<ContactConstraint>, &'a mut Vec<JointConstraint>),
    /// On the device, for [`GpuStages::solve_batched`]; there are `at_most` contact rows (the
    /// manifolds with points, counted on the host). The rows' buffers are sized by it rather
    /// than by the manifold slots: a settled pile has about 2.3 pairs for each manifold with
    /// points, and at 500k bodies one row per pair would not fit one storage binding.
    /// `link_islands`: the islands' links made in the same submission, where this step's
    /// collision left its pairs' summaries on the device ([`GpuStages::read_island_links`]).
    Device { at_most: usize, link_islands: bool },
}

/// What a batched solve's submission is recorded from besides the buffers it reads: two solves
/// with equal plans, and no buffer or binding made between them
/// ([`GpuContext::resources_made`]), record the same commands.
#[derive(Clone, Debug, PartialEq)]
struct SolvePlan {
    settings: SolverSettings,
    jacobi: bool,
    restitution: bool,
    /// Stage 8 in the same submission, the poses and velocities coming back.
    integrating: bool,
    /// The impulses come back to the host (rows whose contacts are there).
    impulses_back: bool,
    /// The impulses also go to the pairs' contacts on the device.
    scatter: bool,
    /// Joints among the batches.
    joints: bool,
    /// The warm start by body, its adjacency built first (a device layout's).
    by_body: bool,
    /// A device layout, planned with these batch sizes (the last layout's).
    expected: Option<[u32; LAYOUT_BATCHES]>,
    bodies: usize,
    /// The rest timers moved after the integration, and whether the sleep test runs with
    /// them (the islands linked on the device this step).
    rest: Option<bool>,
    /// The integrated poses and velocities come back to the host.
    bodies_back: bool,
}

/// A step's batched solve recorded during its collision's wait, from last step's plan. A 3k
/// boxes' solve is about 150 dispatches, 0.2–0.4 ms of recording on an H100 machine's host,
/// which the host spent after the collision's wait: on the step's path wherever the host
/// records more slowly than the device runs the rows and the batching (BENCHMARKS.md, session
/// 24). The step's solve submits these commands when its plan is the same and no buffer or
/// binding was made since (`resources`): then every buffer they read is the one it would
/// record now, and the counts that change from step to step reach the kernels through
/// buffers, not the commands.
struct SolveAhead {
    plan: SolvePlan,
    resources: u64,
    commands: wgpu::CommandBuffer,
}

impl SolvePlan {
    /// Whether a solve recorded from `self` records the same commands as one from `other`
    /// but for the batch sizes the dispatches were planned with, which change only which
    /// constraints of one batch share a dispatch (see
    /// [`device_stages`](crate::stages::solver::gpu::device_stages)), not the results.
    fn solves_as(&self, other: &SolvePlan) -> bool {
        let planned = |plan: &SolvePlan| SolvePlan {
            expected: plan.expected.map(|_| [0; LAYOUT_BATCHES]),
            ..plan.clone()
        };
        planned(self) == planned(other)
    }
}

/// What a device layout's batching is recorded from besides the buffers it reads (see
/// [`SolvePlan`]): whether there is a constraint, the bodies, the batcher and the rounds
/// dispatched on their own.
#[derive(Clone, Debug, PartialEq)]
struct BatchingPlan {
    any: bool,
    body_count: usize,
    batcher: Batcher,
    rounds: usize,
}

/// When a batched solve is recorded ([`GpuStages::encode_batched_solve`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Recording {
    /// Where it is submitted, after the rows and the batching.
    Now,
    /// During the collision's wait: for the step's solve to submit ([`SolveAhead`]), or
    /// submitted then with the rows and the batching, on a guess ([`speculation`]).
    Ahead,
    /// During the last step's wait for its solve, for this step's submitted on a guess: timed
    /// on a profiler of its own (the last step's spans are not collected yet), its impulses
    /// scattered into the contacts' buffer this step's collision will write (the two trade
    /// places from step to step).
    NextStep,
}

/// A step's batching recorded with its solve during the collision's wait ([`SolveAhead`]).
struct BatchingAhead {
    plan: BatchingPlan,
    resources: u64,
    commands: wgpu::CommandBuffer,
}

/// Last step's pairs, the host's pair cache, for [`GpuStages::collide`]: how many, their keys
/// (`None` while only the device has them, which then holds the cache), their contacts and
/// the cache's version.
pub(crate) struct OldPairs<'a> {
    pub count: usize,
    pub keys: Option<&'a [u64]>,
    pub contacts: &'a [PairContact],
    pub version: u64,
}

/// What [`GpuStages::collide`] reads back besides the keys.
pub(crate) enum CollideOutput<'a> {
    /// Every pair's contact, for the host's pair cache.
    Contacts(&'a mut Vec<PairContact>),
    /// Each pair's [`PairSummary`] only: the contacts stay on the device, where the rows read
    /// them and the solver writes their impulses, until the host asks for them
    /// ([`GpuStages::download_pair_contacts`]).
    Summaries(SummaryOutput<'a>),
}

/// What [`GpuStages::collide`] reads back when the contacts stay on the device.
pub(crate) struct SummaryOutput<'a> {
    /// Gets each pair's [`PairSummary`], or, when `None`, leaves them on the device for
    /// [`GpuStages::read_pair_summaries`] (where the step will likely not need them).
    pub summaries: Option<&'a mut Vec<PairSummary>>,
    /// Gets how many pairs were added and removed since last step's (the device's diff),
    /// what [`PairCache::adopt_key_count`](crate::stages::pairs::PairCache::adopt_key_count)
    /// takes. The keys stay on the device ([`GpuStages::read_pair_keys`]): `keys` is left as
    /// it was.
    pub changes: &'a mut (usize, usize),
    /// Gets the pairs that touch, the rows they make and those that bounce, as the masses
    /// stand at the collision.
    pub tally: &'a mut PairTally,
    /// The wake test's candidates, while bodies sleep.
    pub wake: Option<WakeQuery<'a>>,
}

/// The wake test's pass over the pairs, asked of [`GpuStages::collide`] while bodies sleep:
/// [`wake_candidates`](crate::dynamics::wake::wake_candidates) on the device.
pub(crate) struct WakeQuery<'a> {
    /// [`Islands::asleep_bits`](crate::dynamics::island::Islands::asleep_bits).
    pub asleep: (&'a [u32], u64),
    /// Gets the candidates' keys, in pair order, and `listed` whether it did (not when the
    /// tests ask for the host's pass).
    pub candidates: &'a mut Vec<u64>,
    pub listed: &'a mut bool,
}

/// The joint rows of a GPU stage 5 ([`GpuStages::build_constraints`]).
pub(crate) struct JointRowInputs<'a> {
    /// The world's joint array: the device keeps a copy, uploaded when the joints change.
    pub joints: &'a [Option<Joint>],
    /// The slots whose rows are solved this step, in row order: those of
    /// [`joint_slots`](crate::stages::constraints::joint_slots), then the drag's (the slot past
    /// the joints').
    pub slots: &'a [u32],
    /// The drag's row, built on the host.
    pub drag: Option<&'a JointConstraint>,
    pub softness: Softness,
}

/// A GPU step's poses where they are, on the device, for a renderer on the same device to draw
/// from without a readback: after a step that integrated on the GPU, `poses` holds each body
/// slot's [`BodyPose`] at the end of the step. Valid until the world is stepped or changed.
#[derive(Clone, Copy, Debug)]
pub struct DevicePoses<'a> {
    pub poses: &'a wgpu::Buffer,
    /// Body slots in the buffer.
    pub count: usize,
}

/// The step's body arrays, as the GPU stages read them, and the world's version of them
/// (bumped by every change on the host): the device keeps its copies while the version holds,
/// and takes only the bodies `changed` lists when it holds a version since which only they did.
pub(crate) struct BodyInputs<'a> {
    pub poses: &'a [BodyPose],
    pub velocities: &'a [BodyVelocity],
    pub masses: &'a [BodyMass],
    pub colliders: &'a [Collider],
    pub version: u64,
    pub changed: &'a BodyChanges,
}

/// The bodies whose masses and velocities alone changed on the host since the body version
/// `since` (islands that fell asleep or woke: their poses stay): a device that holds `since`
/// or a later version is brought up to date with theirs rather than with every body's (in a
/// settling pile of 100k boxes islands sleep and wake at most steps, and a whole upload took
/// 1.4 ms of them).
#[derive(Clone, Debug, Default)]
pub(crate) struct BodyChanges {
    pub since: u64,
    pub bodies: Vec<u32>,
}

impl BodyChanges {
    /// Every body changed at `version`: a device older than it takes them all.
    pub fn all(&mut self, version: u64) {
        self.since = version;
        self.bodies.clear();
    }
}

/// The body arrays that a GPU integration moves (stage 8 on the device): uploaded first when
/// the device's are not at `version`, then the step's new poses and velocities come back into
/// them.
pub(crate) struct BodyState<'a> {
    pub poses: &'a mut [BodyPose],
    pub velocities: &'a mut [BodyVelocity],
    pub masses: &'a [BodyMass],
    pub colliders: &'a [Collider],
    pub version: u64,
    pub changed: &'a BodyChanges,
}

impl BodyState<'_> {
    fn inputs(&self) -> BodyInputs<'_> {
        BodyInputs {
            poses: self.poses,
            velocities: self.velocities,
            masses: self.masses,
            colliders: self.colliders,
            version: self.version,
            changed: self.changed,
        }
    }
}

/// A partial upload's device side ([`upload_bodies`]): the changed bodies' indices, masses and
/// velocities, written in one go, and the kernels that scatter them into the body arrays.
struct BodyScatter {
    indices: GpuVec<u32>,
    masses: GpuVec<BodyMass>,
    velocities: GpuVec<BodyVelocity>,
    /// The changed bodies' masses and velocities gathered on the host, reused.
    host_masses: Vec<BodyMass>,
    host_velocities: Vec<BodyVelocity>,
    mass_kernel: GpuScatter,
    velocity_kernel: GpuScatter,
}

impl BodyScatter {
    fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            indices: GpuVec::with_capacity(context, "changed bodies", 0)?,
            masses: GpuVec::with_capacity(context, "changed masses", 0)?,
            velocities: GpuVec::with_capacity(context, "changed velocities", 0)?,
            host_masses: Vec::new(),
            host_velocities: Vec::new(),
            mass_kernel: GpuScatter::new(context),
            velocity_kernel: GpuScatter::new(context),
        })
    }
}

/// Device copies of the body arrays, shared by the GPU stages.
struct DeviceBodies {
    poses: GpuVec<BodyPose>,
    velocities: GpuVec<BodyVelocity>,
    masses: GpuVec<BodyMass>,
    colliders: GpuVec<ColliderData>,
    /// The colliders' hulls for the narrowphase ([`pack_hulls`]), uploaded with them.
    hulls: GpuVec<u32>,
    /// The partial uploads' changed bodies, scattered on the device.
    scatter: BodyScatter,
    /// The host's colliders changed since the last upload.
    colliders_stale: bool,
    /// The kinds of shape of the uploaded colliders ([`shape_kinds`]): the narrowphase's kernel.
    shape_kinds: u32,
    /// The world's body version ([`BodyInputs::version`]) that `poses`, `velocities` and
    /// `masses` hold: set by an upload, or by an integration here whose results the host took.
    synced: Option<u64>,
    /// A stage checked this step that the device holds the host's bodies.
    uploaded_this_step: bool,
    /// The device's poses and velocities are newer than the host's: an integration here left
    /// them, unread ([`GpuStages::bodies_left_on_device`]). The masses are still the host's.
    newer: bool,
    /// Uploads that took only the changed bodies ([`BodyChanges`]; the tests check them).
    partial_uploads: usize,
    /// Debug builds: the host's bodies as bytes when they were last synced, to catch a change
    /// that did not bump the version (the device would go on from stale bodies).
    #[cfg(debug_assertions)]
    shadow: Vec<u8>,
}

pub(crate) struct GpuStages {
    context: GpuContext,
    profiler: GpuProfiler,
    bodies: DeviceBodies,
    aabb: GpuAabbs,
    aabbs: GpuVec<Aabb>,
    broadphase: GpuBroadphase,
    narrowphase: GpuNarrowphase,
    rows: GpuRows,
    joint_rows: GpuJointRows,
    /// The rows' inputs on the device: every manifold slot's key and contact.
    row_keys: GpuVec<u64>,
    row_contacts: GpuVec<PairContact>,
    batching: GpuBatching,
    /// Batching rounds encoded as dispatches of their own (the rest run in one workgroup).
    batching_rounds: usize,
    /// The batch layout on the device ([`Self::color_constraints_on_device`]), and each of its
    /// batches' size at the last step that used it: the solver's plan for the next one.
    layout: GpuBatchLayout,
    expected_batch_sizes: [u32; LAYOUT_BATCHES],
    /// Each body's constraints in a device layout, for the warm start by body.
    adjacency: GpuBodyAdjacency,
    /// This step's batching left its layout on the device for [`Self::solve_batched`].
    laid_out_on_device: bool,
    /// Lay the batches out on the host even where the device could (for the tests that
    /// compare both), and how many steps laid them out on the device.
    host_layout: bool,
    device_layouts: usize,
    /// With a device layout, gather the warm start by body (the tests that compare layouts
    /// bit for bit turn it off: NVIDIA's compiler rounds the gather and the sweeps apart).
    warm_start_by_body: bool,
    host_layout_offsets: Vec<u32>,
    /// The wake test's candidates listed in the collision's submission while bodies sleep;
    /// the tests that compare it with the host's pass turn it off (`host_wake_candidates`),
    /// and count the steps that listed them on the device.
    wake: GpuWakeCandidates,
    host_wake_candidates: bool,
    /// The rows' counts, made with the pairs' summaries ([`SummaryOutput::tally`]).
    row_tally: GpuRowTally,
    wake_candidates_listed: usize,
    /// The islands' links, whether this step's rows' submission made them (its collision
    /// left the pairs' summaries on the device: `summarized`), and how many steps did; the
    /// tests that compare them with the host's turn them off (`host_island_links`).
    island_links: GpuIslandLinks,
    summarized: bool,
    islands_linked: bool,
    island_links_made: usize,
    host_island_links: bool,
    /// The rest timers and the sleep test, run where the batched solve integrates the
    /// bodies while the world sleeps its islands (`sleeping`); the host's timers version they
    /// started from ([`Islands::timers_version`]); this step's tally, once read; how many
    /// times the host read the timers. The tests that compare them with the host's turn them
    /// off (`host_rest_timers`).
    rest: GpuRestTimers,
    sleeping: bool,
    rest_version: Option<u64>,
    rest_tally: Option<RestTally>,
    rest_timer_reads: usize,
    host_rest_timers: bool,
    /// Whether this step's solve may leave the bodies it integrates on the device
    /// ([`Self::set_bodies_may_stay`]), and how many solves read them back (the tests count
    /// them).
    bodies_may_stay: bool,
    solves_reading_bodies: usize,
    /// Steps whose collision left the pairs' summaries on the device, and those read back
    /// after all ([`Self::read_pair_summaries`]).
    summaries_left: usize,
    summaries_fetched: usize,
    solver: GpuSolver,
    /// This step's solve, recorded during the collision's wait from `last_solve` (timed on
    /// `ahead_profiler`), how many steps submitted one, and whether to record them (the tests
    /// compare steps with and without).
    solve_ahead: Option<SolveAhead>,
    last_solve: Option<SolvePlan>,
    ahead_profiler: GpuProfiler,
    solves_encoded_ahead: usize,
    /// The next step's solve, recorded during this step's wait for its own, for the next
    /// step's rows, batching and solve submitted with its collision
    /// ([`Recording::NextStep`]): the contacts' buffer its impulses go to, checked when it
    /// is submitted; its profiler; how many steps submitted one.
    next_solve: Option<(SolveAhead, wgpu::Buffer)>,
    next_profiler: GpuProfiler,
    next_solves_submitted: usize,
    /// The same for the batching, recorded with the solve.
    batching_ahead: Option<BatchingAhead>,
    last_batching: Option<BatchingPlan>,
    ahead_batching_profiler: GpuProfiler,
    batchings_encoded_ahead: usize,
    encodes_ahead: bool,
    /// The step's plan for its rows, batching and solve to be submitted with its collision
    /// ([`Self::plan_step`]), then what they were submitted from and whether the step held
    /// ([`speculation`]); the check of the step's guesses on the device; whether steps are
    /// submitted so (the tests compare with steps that are not), and how many held or not.
    step_plan: Option<StepPlan>,
    speculated: Option<Speculated>,
    step_hold: StepHold,
    speculates: bool,
    steps_held: usize,
    steps_not_held: usize,
    /// Last step's rows, and whether one bounced: the guesses of the next step submitted
    /// with its collision, which has room for `row_margin` rows more at least
    /// ([`speculation::ROW_MARGIN`]; the tests make it 0, so that the rows outgrow it).
    last_rows: usize,
    last_bounced: bool,
    row_margin: usize,
    /// Built at the first Jacobi step.
    jacobi: Option<GpuJacobi>,
    /// The batches kept on the device when rows, batching and solver all run here.
    batched: GpuBatched,
    /// The solver's bodies, constraints in batch order and batch offsets (contacts, then
    /// joints) on the device; [`Self::solve_batched`] uses the offsets and the bodies.
    solver_bodies: GpuVec<SolverBody>,
    /// Makes `solver_bodies` from the velocities and masses on the device (batched solves).
    prepare_bodies: GpuPrepareBodies,
    /// Stage 8 on the device: the motion in `solver_bodies` into the poses and velocities.
    finalize_bodies: GpuFinalizeBodies,
    /// A host solve's contact constraints, in blocks of lanes
    /// ([`lanes`](crate::stages::constraints::lanes)).
    batched_contacts: GpuVec<Word>,
    batch_offsets: GpuVec<u32>,
    batched_joints: GpuVec<JointConstraint>,
    joint_batch_offsets: GpuVec<u32>,
    /// [`Self::collide`]: last step's pair keys (its contacts go in `old_contacts`) and their
    /// diff with this step's.
    old_keys: GpuVec<u64>,
    pair_diff: GpuPairDiff,
    /// The narrowphase's inputs and output on the device.
    keys: GpuVec<u64>,
    old_index: GpuVec<u32>,
    old_contacts: GpuVec<PairContact>,
    contacts: GpuVec<PairContact>,
    summaries: GpuPairSummaries,
    skipped: GpuVec<u64>,
    /// The narrowphase ran on the GPU this step and computed every pair there: its output
    /// (`contacts`, keyed by `keys`) equals the host's pair cache, so the rows can read it.
    pair_contacts_fresh: bool,
    /// This step integrated on the GPU and the host took the result: the device's poses are
    /// the step's end poses.
    integrated_this_step: bool,
    /// This step: stages 1–4 ran as [`Self::collide`]; the rows were built from its output
    /// ([`RowSlots::Narrowphase`]); the solver wrote their impulses into `contacts`.
    collided: bool,
    rows_from_narrowphase: bool,
    impulses_scattered: bool,
    /// The version of the host's pair cache ([`PairCache::version`]) that the broadphase's
    /// keys and `contacts` hold, impulses included: [`Self::collide`] then reads last step's
    /// pairs there instead of uploading them.
    ///
    /// [`PairCache::version`]: crate::stages::pairs::PairCache::version
    cached_pairs: Option<u64>,
    /// The device copy of last step's keys into `old_keys`, for the buffers and size it was
    /// built for.
    pair_copy: Option<(PairCopyKey, Vec<Dispatch>)>,
    /// [`Self::pairs_computed`].
    pairs_computed: usize,
    /// Host scratch, reused: the identity map, last step's keys padded, the packed colliders,
    /// downloaded contacts.
    identity: Vec<u32>,
    padded_keys: Vec<u64>,
    collider_data: Vec<ColliderData>,
    downloaded: Vec<PairContact>,
    downloaded_bodies: Vec<SolverBody>,
    /// `batched_contacts` on the host, on their way up and down.
    constraint_words: Vec<Word>,
    downloaded_joints: Vec<JointConstraint>,
}

impl GpuStages {
    /// The GPU side on `context`'s device.
    pub fn new(context: GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            // Passes timed between two waits: at most the rows' two, the batching's and the
            // solver's four (the collision has five).
            profiler: GpuProfiler::new(&context, 16),
            bodies: DeviceBodies {
                poses: GpuVec::with_capacity(&context, "poses", 0)?,
                velocities: GpuVec::with_capacity(&context, "velocities", 0)?,
                masses: GpuVec::with_capacity(&context, "masses", 0)?,
                colliders: GpuVec::with_capacity(&context, "colliders", 0)?,
                hulls: GpuVec::with_capacity(&context, "hulls", 0)?,
                scatter: BodyScatter::new(&context)?,
                colliders_stale: true,
                shape_kinds: 0,
                synced: None,
                uploaded_this_step: false,
                newer: false,
                partial_uploads: 0,
                #[cfg(debug_assertions)]
                shadow: Vec::new(),
            },
            aabb: GpuAabbs::new(),
            aabbs: GpuVec::with_capacity(&context, "aabbs", 0)?,
            broadphase: GpuBroadphase::new(&context)?,
            narrowphase: GpuNarrowphase::new(),
            rows: GpuRows::new(&context)?,
            joint_rows: GpuJointRows::new(&context)?,
            row_keys: GpuVec::with_capacity(&context, "row keys", 0)?,
            row_contacts: GpuVec::with_capacity(&context, "row contacts", 0)?,
            batching: GpuBatching::new(&context)?,
            batching_rounds: FIRST_BATCHING_ROUNDS,
            layout: GpuBatchLayout::new(&context)?,
            expected_batch_sizes: FIRST_EXPECTED_BATCH_SIZES,
            adjacency: GpuBodyAdjacency::new(&context)?,
            laid_out_on_device: false,
            host_layout: false,
            device_layouts: 0,
            warm_start_by_body: true,
            host_layout_offsets: Vec::new(),
            wake: GpuWakeCandidates::new(&context)?,
            row_tally: GpuRowTally::new(&context)?,
            host_wake_candidates: false,
            wake_candidates_listed: 0,
            island_links: GpuIslandLinks::new(&context)?,
            summarized: false,
            islands_linked: false,
            island_links_made: 0,
            host_island_links: false,
            rest: GpuRestTimers::new(&context)?,
            sleeping: false,
            rest_version: None,
            rest_tally: None,
            rest_timer_reads: 0,
            host_rest_timers: false,
            bodies_may_stay: false,
            solves_reading_bodies: 0,
            summaries_left: 0,
            summaries_fetched: 0,
            solver: GpuSolver::new(&context)?,
            solve_ahead: None,
            last_solve: None,
            // The solver's four passes.
            ahead_profiler: GpuProfiler::new(&context, 4),
            solves_encoded_ahead: 0,
            next_solve: None,
            next_profiler: GpuProfiler::new(&context, 4),
            next_solves_submitted: 0,
            batching_ahead: None,
            last_batching: None,
            // The batching's pass, and the rows', the links' and the check's before it when
            // submitted with the collision.
            ahead_batching_profiler: GpuProfiler::new(&context, 4),
            batchings_encoded_ahead: 0,
            encodes_ahead: true,
            step_plan: None,
            speculated: None,
            step_hold: StepHold::new(&context)?,
            speculates: true,
            steps_held: 0,
            steps_not_held: 0,
            last_rows: 0,
            last_bounced: false,
            row_margin: speculation::ROW_MARGIN,
            jacobi: None,
            batched: GpuBatched::new(&context)?,
            solver_bodies: GpuVec::with_capacity(&context, "solver bodies", 0)?,
            prepare_bodies: GpuPrepareBodies::new(&context),
            finalize_bodies: GpuFinalizeBodies::new(&context)?,
            batched_contacts: GpuVec::with_capacity(&context, "batched contacts", 0)?,
            batch_offsets: GpuVec::with_capacity(&context, "batch offsets", 0)?,
            batched_joints: GpuVec::with_capacity(&context, "batched joints", 0)?,
            joint_batch_offsets: GpuVec::with_capacity(&context, "joint batch offsets", 0)?,
            old_keys: GpuVec::with_capacity(&context, "old pair keys", 0)?,
            pair_diff: GpuPairDiff::new(&context)?,
            keys: GpuVec::with_capacity(&context, "pair keys", 0)?,
            old_index: GpuVec::with_capacity(&context, "old pair index", 0)?,
            // One name for both: the two buffers trade places from step to step (`collide`).
            old_contacts: GpuVec::with_capacity(&context, "contacts", 0)?,
            contacts: GpuVec::with_capacity(&context, "contacts", 0)?,
            summaries: GpuPairSummaries::new(&context)?,
            skipped: GpuVec::with_capacity(&context, "jointed pairs", 0)?,
            pair_contacts_fresh: false,
            integrated_this_step: false,
            collided: false,
            rows_from_narrowphase: false,
            impulses_scattered: false,
            cached_pairs: None,
            pair_copy: None,
            pairs_computed: 0,
            identity: Vec::new(),
            padded_keys: Vec::new(),
            collider_data: Vec::new(),
            downloaded: Vec::new(),
            downloaded_bodies: Vec::new(),
            constraint_words: Vec::new(),
            downloaded_joints: Vec::new(),
            context,
        })
    }

    /// A one-line description of the adapter, for reports.
    pub fn describe(&self) -> String {
        self.context.describe()
    }

    /// Bodies were added or removed: upload the colliders again before the next GPU stage.
    pub fn colliders_changed(&mut self) {
        self.bodies.colliders_stale = true;
    }

    /// Joints were added, removed, restored or broke: the joint rows upload them again.
    pub fn joints_changed(&mut self) {
        self.joint_rows.joints_changed();
    }

    /// The host's joint impulses changed otherwise than through [`Self::solve_batched`] (a
    /// solve elsewhere): the joint rows upload them again.
    pub fn joint_impulses_changed(&mut self) {
        self.joint_rows.impulses_changed();
    }

    /// A new step: nothing of it is on the device yet.
    pub fn begin_step(&mut self) {
        // Recorded for a step that did not solve (a failed one, or one whose solve ran
        // elsewhere).
        (self.solve_ahead, self.batching_ahead) = (None, None);
        if self
            .speculated
            .take()
            .is_some_and(|speculated| speculated.held)
        {
            // A step that held and failed after its collision: the device integrated its
            // bodies, the host did not.
            self.bodies.synced = None;
        }
        self.step_plan = None;
        self.bodies.uploaded_this_step = false;
        self.pair_contacts_fresh = false;
        self.integrated_this_step = false;
        self.collided = false;
        self.rows_from_narrowphase = false;
        self.impulses_scattered = false;
        self.laid_out_on_device = false;
        self.summarized = false;
        self.islands_linked = false;
        self.rest_tally = None;
    }

    /// Gives the device the host's rest timers where they changed since it took them
    /// (`islands` must hold every timer: see [`Islands::timers_on_device`]), for the solves
    /// that integrate the bodies while the world is `sleeping` to move them there. Only where
    /// this step's solve may (`solved_here`: every stage from the rows on on the GPU): a
    /// step whose host moves the timers changes them every step.
    pub fn sync_rest_timers(
        &mut self,
        islands: &Islands,
        sleeping: bool,
        solved_here: bool,
    ) -> Result<(), GpuError> {
        let version = islands.timers_version();
        debug_assert!(
            islands.holds_timers() || self.rest_version == Some(version),
            "the host's timers are stale and the device's are not the newer"
        );
        self.sleeping = sleeping;
        if sleeping && solved_here && self.rest_version != Some(version) {
            self.rest_version = None;
            self.rest.upload(&self.context, &islands.timers())?;
            self.rest_version = Some(version);
        }
        Ok(())
    }

    /// Whether this step's solve may integrate the bodies without reading them back: nothing
    /// on the host needs them after it (every stage on the GPU, no drag). They stay only where
    /// the device moves the rest timers too, or the world sleeps no island.
    pub fn set_bodies_may_stay(&mut self, may: bool) {
        self.bodies_may_stay = may;
    }

    /// Whether the last integration left the poses and velocities on the device, newer than
    /// the host's ([`Self::read_bodies`]).
    pub fn bodies_left_on_device(&self) -> bool {
        self.bodies.newer
    }

    /// The poses and velocities on the device, read now.
    pub fn read_bodies(&self) -> Result<(Vec<BodyPose>, Vec<BodyVelocity>), GpuError> {
        Ok((
            self.bodies.poses.read(&self.context)?,
            self.bodies.velocities.read(&self.context)?,
        ))
    }

    /// The host took the device's poses and velocities ([`Self::read_bodies`]) into its
    /// bodies, still at the version the device holds (`bodies` only checks that in debug
    /// builds).
    #[cfg_attr(not(debug_assertions), allow(unused_variables))]
    pub fn bodies_read(&mut self, bodies: &BodyInputs) {
        self.bodies.newer = false;
        #[cfg(debug_assertions)]
        if self.bodies.synced == Some(bodies.version) {
            self.bodies.shadow = body_bytes(bodies);
        }
    }

    /// Whether a solve that integrates reads the bodies back: unless they may stay and the
    /// host needs no velocity for its rest timers (`rest`: they move on the device).
    fn reads_bodies_back(&self, rest: Option<bool>) -> bool {
        !(self.bodies_may_stay && (rest.is_some() || !self.sleeping))
    }

    /// The device's rest timers may differ from the host's, which hold them: the next step
    /// uploads the host's.
    pub fn rest_timers_stale(&mut self) {
        self.rest_version = None;
    }

    /// What this step's rest timers found, where the device moved them (the host's are then
    /// stale: [`Self::read_rest_timers`]).
    pub fn take_rest_tally(&mut self) -> Option<RestTally> {
        self.rest_tally.take()
    }

    /// Whether a solve that integrates `bodies` bodies moves their rest timers too: the world
    /// sleeps its islands and gave the device a timer a body.
    fn rests_bodies(&self, bodies: usize) -> bool {
        self.sleeping
            && !self.host_rest_timers
            && self.rest_version.is_some()
            && self.rest.bodies() == bodies
    }

    /// Every body's rest time as the device has it, read now.
    pub fn rest_timers(&self) -> Result<Vec<f32>, GpuError> {
        self.rest.read(&self.context)
    }

    /// [`Self::rest_timers`], its copy timed on `profiler`.
    pub fn read_rest_timers(&mut self, profiler: &mut Profiler) -> Result<Vec<f32>, GpuError> {
        self.rest_timer_reads += 1;
        let start = Instant::now();
        let timers = self.rest_timers()?;
        record_copy(profiler, REST_TIMERS_DOWNLOAD, elapsed_ms(start));
        Ok(timers)
    }

    /// The host stored this step's solved impulses in its pair cache, now at `version`: when
    /// the device did the same to its contacts, the two agree until the cache changes again.
    pub fn pair_cache_stored(&mut self, version: u64) {
        self.cached_pairs = self.impulses_scattered.then_some(version);
    }

    /// Whether the device holds the host's pair cache at `version` (see `cached_pairs`).
    pub fn holds_pair_cache(&self, version: u64) -> bool {
        self.cached_pairs == Some(version)
    }

    /// The host's pair cache, now at `version`, took its contacts from the device
    /// ([`Self::read_pair_contacts`]): the two agree.
    pub fn pair_cache_adopted(&mut self, version: u64) {
        self.cached_pairs = Some(version);
    }

    /// The colors of last step's contact rows, in row order, when its batch layout stayed on
    /// the device. Reads through a staging buffer of its own, for callers holding `&self`.
    pub fn read_row_colors(&self) -> Result<Vec<u32>, GpuError> {
        self.batching.colors.read(&self.context)
    }

    /// This step's pairs' summaries, which its [`Self::collide`] left on the device, into
    /// `out` (one per pair, `count` of them): a submission and a wait of their own.
    pub fn read_pair_summaries(
        &mut self,
        profiler: &mut Profiler,
        count: usize,
        out: &mut Vec<PairSummary>,
    ) -> Result<(), GpuError> {
        if !self.summarized || count > self.summaries.summaries.len() {
            return Err(GpuError::Readback {
                what: "pair summaries",
                reason: "no collision of this step left them on the device".to_owned(),
            });
        }
        let start = Instant::now();
        let context = &self.context;
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("pair summaries read-back"),
            });
        let summaries = &mut self.summaries.summaries;
        summaries.encode_download_prefix(context, &mut encoder, count);
        context.queue.submit([encoder.finish()]);
        summaries.read_download(context, out)?;
        record_copy(profiler, SUMMARIES_DOWNLOAD, elapsed_ms(start));
        self.summaries_fetched += 1;
        Ok(())
    }

    /// Whether the wake test's candidates are listed on the host (for the tests that compare
    /// them with the device's), which reads the pairs' summaries.
    pub fn lists_wake_candidates_on_host(&self) -> bool {
        self.host_wake_candidates
    }

    /// Whether this step's rows' submission linked the islands ([`Self::read_island_links`]).
    pub fn islands_linked(&self) -> bool {
        self.islands_linked
    }

    /// This step's islands as [`Self::build_constraints`] linked them on the device (each
    /// body's root, see [`GpuIslandLinks`]) into `out`; false, and nothing read, when it did
    /// not link them. Waits for that submission.
    pub fn read_island_links(
        &mut self,
        profiler: &mut Profiler,
        out: &mut Vec<u32>,
    ) -> Result<bool, GpuError> {
        if !self.islands_linked {
            return Ok(false);
        }
        let start = Instant::now();
        self.island_links.read(&self.context, out)?;
        record_copy(profiler, ISLAND_LINKS_DOWNLOAD, elapsed_ms(start));
        Ok(true)
    }

    /// The manifold slot of each contact row last built on the device, in row order (the
    /// order of [`Self::read_row_colors`]).
    pub fn read_row_slots(&self) -> Result<Vec<u32>, GpuError> {
        self.rows.read_slots(&self.context)
    }

    /// The contacts of last step's pairs as they are on the device, impulses included, in
    /// pair order: after a [`Self::collide`] that left them there
    /// ([`CollideOutput::Summaries`]). Reads through a staging buffer of its own, so that a
    /// caller holding only `&self` (the world's contact queries) can read them.
    pub fn read_pair_contacts(&self) -> Result<Vec<PairContact>, GpuError> {
        let mut contacts = self.contacts.read(&self.context)?;
        contacts.iter_mut().for_each(PairContact::clear_unused);
        Ok(contacts)
    }

    /// The keys of last step's pairs, sorted, as a [`Self::collide`] that left the contacts
    /// on the device left them there ([`CollideOutput::Summaries`]): the host's pair cache
    /// holds their count only ([`PairCache::adopt_key_count`]) until a reader on the host
    /// needs them. Reads like [`Self::read_pair_contacts`].
    ///
    /// [`PairCache::adopt_key_count`]: crate::stages::pairs::PairCache::adopt_key_count
    pub fn read_pair_keys(&self) -> Result<Vec<u64>, GpuError> {
        self.keys.read(&self.context)
    }

    /// [`Self::read_pair_keys`] for a step that needs them, timed in `profiler`.
    pub fn fetch_pair_keys(&self, profiler: &mut Profiler) -> Result<Vec<u64>, GpuError> {
        let start = Instant::now();
        let keys = self.read_pair_keys()?;
        record_copy(profiler, PAIR_KEYS_DOWNLOAD, elapsed_ms(start));
        Ok(keys)
    }

    /// This step's end poses on the device, when it integrated here ([`DevicePoses`]).
    pub fn device_poses(&self) -> Option<DevicePoses<'_>> {
        self.integrated_this_step.then(|| DevicePoses {
            poses: self.bodies.poses.buffer(),
            count: self.bodies.poses.len(),
        })
    }

    /// The host took this step's GPU integration into its bodies, which are now at `version`:
    /// the device's poses, velocities and masses are the host's until the next change.
    pub fn bodies_integrated(&mut self, bodies: &BodyInputs) {
        debug_assert!(self.integrated_this_step, "no GPU integration this step");
        self.bodies.synced = Some(bodies.version);
        #[cfg(debug_assertions)]
        {
            self.bodies.shadow = body_bytes(bodies);
        }
    }

    /// Whether this step's GPU narrowphase left every pair's contact on the device, so that
    /// [`RowSlots::Narrowphase`] can stand for the pair cache.
    pub fn narrowphase_output_is_pair_cache(&self) -> bool {
        self.pair_contacts_fresh
    }

    /// Stage 1 on the GPU: [`compute_aabbs`](crate::stages::aabb::compute_aabbs)'s contract.
    /// The AABBs stay on the device for a GPU broadphase; `download` brings them to the host
    /// for a CPU one.
    pub fn compute_aabbs(
        &mut self,
        profiler: &mut Profiler,
        bodies: &BodyInputs,
        margin: f32,
        dt: f32,
        download: Option<&mut Vec<Aabb>>,
    ) -> Result<(), GpuError> {
        let start = Instant::now();
        upload_bodies(
            &self.context,
            &mut self.bodies,
            &mut self.collider_data,
            bodies,
        )?;
        record_copy(profiler, AABB.upload, elapsed_ms(start));
        let (context, device) = (&self.context, &self.bodies);
        let (aabb, aabbs) = (&mut self.aabb, &mut self.aabbs);
        run_pass(context, &mut self.profiler, profiler, &AABB, |pass| {
            aabb.encode(
                context,
                pass,
                &device.poses,
                &device.velocities,
                &device.colliders,
                margin,
                dt,
                aabbs,
            )
        })?;
        if let Some(host) = download {
            let start = Instant::now();
            self.aabbs.download_into(context, host)?;
            record_copy(profiler, AABB.download, elapsed_ms(start));
        }
        Ok(())
    }

    /// Stage 2 on the GPU: the sorted keys of the pairs whose AABBs overlap, moving × moving
    /// and moving × static (`is_static` by body slot: static, asleep or removed). The AABBs
    /// come from `host_aabbs` when the AABB stage ran on the CPU, else from the device.
    /// Unlike the CPU broadphase's fat boxes, these are exact overlaps: fewer candidates, the
    /// same contacts.
    pub fn find_pairs(
        &mut self,
        profiler: &mut Profiler,
        host_aabbs: Option<&[Aabb]>,
        is_static: &[bool],
        keys: &mut Vec<u64>,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let start = Instant::now();
        if let Some(aabbs) = host_aabbs {
            self.aabbs.upload(context, aabbs)?;
        }
        self.broadphase.set_bodies(context, is_static)?;
        // The host merges the resting pairs into these.
        self.broadphase.set_extra_pairs(context, &[])?;
        record_copy(profiler, BROADPHASE.upload, elapsed_ms(start));
        let found = loop {
            let (broadphase, aabbs) = (&mut self.broadphase, &self.aabbs);
            let run = run_pass(context, &mut self.profiler, profiler, &BROADPHASE, |pass| {
                broadphase.encode(context, pass, aabbs)
            });
            // Reads the pair count back: more pairs than room means grow and run again.
            match run.and_then(|()| self.broadphase.check_capacity(context)) {
                Ok(true) => continue,
                other => break other,
            }
        };
        if found.is_err() {
            // Its submission may not have run: the trees' body lists are made again.
            self.broadphase.forget_bodies();
        }
        found?;
        let start = Instant::now();
        self.broadphase.download_keys_into(context, keys)?;
        record_copy(profiler, BROADPHASE.download, elapsed_ms(start));
        Ok(())
    }

    /// Stages 1 to 4 in one submission: AABBs, broadphase, the pair diff against last step's
    /// pairs (the talk's persistent pairs, [`GpuPairDiff`]) and the narrowphase, with nothing
    /// read back between them. `old` is the pair cache after last
    /// step (its contacts carry the solver's impulses, which live on the host); `keys` gets
    /// this step's sorted pair keys (unless the output is summaries: they stay here, see
    /// [`SummaryOutput::changes`]) and `contacts` their contacts,
    /// warm-started through the diff, as [`find_pairs`](Self::find_pairs) then
    /// [`update_contacts`](Self::update_contacts) would give them. Pairs the GPU narrowphase
    /// has no kernel for ([`gpu_pair`]) come back with last step's contact: the caller
    /// computes them. The pair count is read back once;
    /// when the pairs outgrew the broadphase's buffers, they grow and the submission runs
    /// again (from the same inputs). When the step fails (pairs past the adapter's limits),
    /// the pair buffers keep their size from before it, so that a smaller scene steps again.
    /// Last step's pairs of two bodies that `is_static` holds still (asleep on each other or
    /// on a static body, the host's resting pairs) are found by no tree: the broadphase adds
    /// them from last step's keys on the device ([`GpuBroadphase::set_resting_pairs_from`]),
    /// and they keep their contacts while they sleep. Every body slot must be live.
    #[allow(clippy::too_many_arguments)]
    pub fn collide(
        &mut self,
        profiler: &mut Profiler,
        bodies: &BodyInputs,
        is_static: &[bool],
        old: OldPairs,
        skipped: &[u64],
        margin_dt: (f32, f32),
        keys: &mut Vec<u64>,
        output: CollideOutput,
    ) -> Result<(), GpuError> {
        let capacity = self.broadphase.capacity();
        let collided = self.collide_growing(
            profiler, bodies, is_static, old, skipped, margin_dt, keys, output,
        );
        if collided.is_err() {
            // Its submission may not have run: the trees' body lists are made again.
            self.broadphase.forget_bodies();
            if self.speculated.take().is_some() {
                // The step submitted with it may have moved the device's bodies, or not (then
                // its word may be 0).
                self.bodies.synced = None;
                let _ = self.finalize_bodies.reset_held(&self.context);
            }
        }
        if collided.is_err() && self.broadphase.capacity() != capacity {
            // Smaller than what failed, and allocated before: the original error is the one
            // to report either way.
            let _ = self.broadphase.set_capacity(&self.context, capacity);
        }
        collided
    }

    /// [`Self::collide`], growing the pair buffers as the pairs need.
    #[allow(clippy::too_many_arguments)]
    fn collide_growing(
        &mut self,
        profiler: &mut Profiler,
        bodies: &BodyInputs,
        is_static: &[bool],
        old: OldPairs,
        skipped: &[u64],
        (margin, dt): (f32, f32),
        keys: &mut Vec<u64>,
        output: CollideOutput,
    ) -> Result<(), GpuError> {
        // A handle of its own (reference-counted), for the solve recorded during the wait to
        // borrow `self`.
        let context = &self.context.clone();
        let summarize = matches!(output, CollideOutput::Summaries(_));
        // Whether the pairs' summaries come back with the keys.
        let summaries_back = matches!(
            output,
            CollideOutput::Summaries(SummaryOutput {
                summaries: Some(_),
                ..
            })
        );
        let (old_count, old_contacts, old_version) = (old.count, old.contacts, old.version);
        let wake_asleep = match &output {
            CollideOutput::Summaries(SummaryOutput {
                wake: Some(query), ..
            }) if !self.host_wake_candidates => Some(query.asleep),
            _ => None,
        };
        let start = Instant::now();
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, bodies)?;
        record_copy(profiler, COLLISION.upload, elapsed_ms(start));
        let start = Instant::now();
        self.broadphase.set_bodies(context, is_static)?;
        record_copy(profiler, COLLISION_TREE_BODIES, elapsed_ms(start));
        let start = Instant::now();
        self.skipped.upload(context, skipped)?;
        if let Some(asleep) = wake_asleep {
            self.wake.set_asleep(context, asleep)?;
        }
        record_copy(profiler, COLLISION_PAIR_LISTS, elapsed_ms(start));
        // Padded with u64::MAX to the broadphase's capacity, so that the lookup's dispatch
        // keeps its size from step to step and is not built again.
        let padded = old_count.max(self.broadphase.capacity());
        // Last step's pairs are still on the device (the broadphase's keys, padded so, and
        // `contacts`) when the host's cache is the version they hold: the keys copied there,
        // in the first pass below, instead of uploaded, and the contacts' buffer made the old
        // one, the older taking this step's (copying them took 0.14 ms a step on an H100 at
        // 584k pairs).
        let on_device = self.cached_pairs.take() == Some(old_version)
            && padded == self.broadphase.capacity()
            && old_contacts.len() == self.contacts.len();
        // Whether the first pass copies them (`pair_copy`'s dispatches).
        let mut copy_keys = on_device;
        if on_device {
            self.old_keys.resize(context, padded)?;
            std::mem::swap(&mut self.contacts, &mut self.old_contacts);
            pair_copy(
                context,
                &mut self.pair_copy,
                self.broadphase.keys(),
                &self.old_keys,
            )?;
        } else {
            let Some(old_keys) = old.keys.filter(|keys| keys.len() == old_count) else {
                // The caller fetches the keys unless the device holds the cache
                // ([`Self::holds_pair_cache`]): a bug, reported rather than guessed at.
                return Err(GpuError::Readback {
                    what: "pair keys",
                    reason: "last step's pair keys are neither on the host nor here".into(),
                });
            };
            let start = Instant::now();
            self.padded_keys.clear();
            self.padded_keys.extend_from_slice(old_keys);
            self.padded_keys.resize(padded, u64::MAX);
            self.old_keys.upload(context, &self.padded_keys)?;
            self.old_contacts.upload(context, old_contacts)?;
            record_copy(profiler, PAIR_UPLOAD, elapsed_ms(start));
        }
        self.broadphase.set_resting_pairs_from(&self.old_keys);
        // The keys are copied out and the summaries come back with the kernels (one wait for
        // the stage), before the count is known: as many as last step had and some more (see
        // `expected_pair_count`), a second copy bringing the rest when there are more.
        let mut staged = 0;
        let mut wake_staged = 0;
        let mut recorded_ahead = false;
        loop {
            if summarize {
                self.keys.resize(context, self.broadphase.capacity())?;
                staged = expected_pair_count(self.broadphase.last_pair_count())
                    .min(self.broadphase.capacity());
            }
            let device = &self.bodies;
            let (aabb, aabbs) = (&mut self.aabb, &mut self.aabbs);
            let (broadphase, diff) = (&mut self.broadphase, &mut self.pair_diff);
            let (narrowphase, contacts) = (&mut self.narrowphase, &mut self.contacts);
            let (summaries, row_keys) = (&mut self.summaries, &mut self.keys);
            let wake = &mut self.wake;
            let row_tally = &mut self.row_tally;
            let (old_keys, old_contacts, skipped) =
                (&self.old_keys, &self.old_contacts, &self.skipped);
            // Only the first run copies: a run again after the broadphase grew reads the same
            // inputs, and its keys and `contacts` are this step's by then.
            let copies = std::mem::take(&mut copy_keys)
                .then_some(self.pair_copy.as_ref())
                .flatten()
                .map(|(_, dispatches)| dispatches);
            let [trees, pairs, lookup, contacts_kernels] = COLLISION_KERNELS;
            // The trees' pass goes first, on its own: the device is idle until the step's
            // first submission, and the host records the rest while the trees are built.
            submit_passes(
                context,
                &mut self.profiler,
                profiler,
                (&COLLISION, COLLISION_TREES_SUBMIT),
                |encoder, timer| {
                    encode_pass(encoder, timer, trees, |pass| {
                        if let Some(copies) = copies {
                            encode_all(pass, copies);
                        }
                        aabb.encode(
                            context,
                            pass,
                            &device.poses,
                            &device.velocities,
                            &device.colliders,
                            margin,
                            dt,
                            aabbs,
                        )?;
                        broadphase.encode_trees(context, pass, aabbs)
                    })
                },
            )?;
            let submit_ms = record_and_submit(
                context,
                &mut self.profiler,
                profiler,
                &COLLISION,
                |encoder, timer| {
                    encode_pass(encoder, timer, pairs, |pass| {
                        broadphase.encode_pairs(context, pass)
                    })?;
                    // The broadphase's keys are padded with u64::MAX past the count, which both
                    // the diff and the narrowphase pass over: the count stays on the device.
                    encode_pass(encoder, timer, lookup, |pass| {
                        diff.encode_lookup(context, pass, old_keys, broadphase.keys())
                    })?;
                    encode_pass(encoder, timer, contacts_kernels, |pass| {
                        let inputs = GpuNarrowphaseInputs {
                            keys: broadphase.keys(),
                            old_index: diff.old_index(),
                            old_contacts,
                            poses: &device.poses,
                            velocities: &device.velocities,
                            colliders: &device.colliders,
                            hulls: &device.hulls,
                            skipped,
                            margin,
                            dt,
                            shape_kinds: device.shape_kinds,
                        };
                        narrowphase.encode(context, pass, &inputs, contacts)?;
                        if summarize {
                            let capacity = broadphase.capacity();
                            summaries.encode(
                                context,
                                pass,
                                broadphase.count(),
                                contacts,
                                capacity,
                            )?;
                        }
                        Ok(())
                    })?;
                    if summarize {
                        encode_pass(encoder, timer, COLLISION_COUNTS_KERNEL, |pass| {
                            let capacity = broadphase.capacity();
                            let pairs = (broadphase.keys(), &summaries.summaries, diff.old_index());
                            row_tally.encode(
                                context,
                                pass,
                                broadphase.count(),
                                pairs,
                                (&device.masses, &device.colliders),
                                capacity,
                            )?;
                            if wake_asleep.is_some() {
                                wake.encode(
                                    context,
                                    pass,
                                    broadphase.count(),
                                    broadphase.keys(),
                                    &summaries.summaries,
                                    &device.masses,
                                    capacity,
                                )?;
                            }
                            Ok(())
                        })?;
                    }
                    broadphase.encode_count_download(context, encoder);
                    if summarize {
                        let summaries = summaries_back.then_some(&mut *summaries);
                        encode_summary_downloads(
                            context, encoder, broadphase, row_keys, summaries, staged,
                        );
                        let wake_total = wake_asleep.map(|_| wake.total());
                        // The computed pairs' count comes back with the tally's (one map).
                        let computed = narrowphase.computed_list(context)?;
                        row_tally.encode_download(context, encoder, wake_total, computed);
                    } else {
                        narrowphase.encode_computed_download(context, encoder)?;
                    }
                    if wake_asleep.is_some() {
                        wake_staged = wake.encode_download(context, encoder);
                    }
                    Ok(())
                },
            )?;
            let first = !recorded_ahead;
            if first {
                recorded_ahead = true;
                // The host would wait here: it submits this step's rows, batching and solve
                // meanwhile where the step planned them, else records the batching and the
                // solve. A failure there leaves them to record their commands themselves,
                // where it fails again.
                let submitted = match self.step_plan.take() {
                    Some(plan) if summarize => {
                        let wake_checked = wake_asleep.is_some();
                        self.submit_speculation(profiler, plan, (staged, wake_checked))
                    }
                    _ => self.encode_solve_ahead(profiler),
                };
                if submitted.is_err() {
                    (self.solve_ahead, self.batching_ahead) = (None, None);
                    self.speculated = None;
                }
            }
            wait_for_passes(context, &mut self.profiler, profiler, &COLLISION, submit_ms)?;
            if first {
                self.read_speculation()?;
            }
            let count = self.broadphase.read_encoded_count(context)?;
            if !self.broadphase.grow_for(context, count)? {
                break;
            }
        }
        let start = Instant::now();
        let count = self.broadphase.last_pair_count();
        match output {
            CollideOutput::Summaries(SummaryOutput {
                summaries: out,
                changes,
                tally,
                wake,
            }) => {
                if count > staged {
                    let mut encoder =
                        context
                            .device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("collision read-back"),
                            });
                    let (broadphase, summaries) = (&self.broadphase, &mut self.summaries);
                    encode_summary_downloads(
                        context,
                        &mut encoder,
                        broadphase,
                        &self.keys,
                        summaries_back.then_some(summaries),
                        count,
                    );
                    context.queue.submit([encoder.finish()]);
                }
                *tally = self.row_tally.read(context)?;
                self.last_bounced = tally.bouncing > 0;
                self.pairs_computed = self.row_tally.computed();
                // The pairs the lookup found among last step's are kept; the others were added,
                // and last step's that it did not find were removed. The keys stay here until
                // the host asks ([`Self::read_pair_keys`]): a settled pile's change by a few
                // pairs a step, and copying them all back took 1.7 ms a step at 500k bodies
                // (30 MB, H100 host).
                *changes = (count - tally.kept, old_count - tally.kept);
                if let Some(out) = out {
                    self.summaries.summaries.read_download(context, out)?;
                    out.truncate(count);
                }
                self.keys.resize(context, count)?;
                if let Some(query) = wake {
                    *query.listed = wake_asleep.is_some();
                    if *query.listed {
                        let listed = (wake_staged, tally.wake_candidates);
                        self.wake.read(context, listed, query.candidates)?;
                        self.wake_candidates_listed += 1;
                    }
                }
            }
            CollideOutput::Contacts(contacts) => {
                self.pairs_computed = self.narrowphase.read_computed(context)?;
                // Only the counted keys and contacts come back, in one submission; the rows
                // read them on the device, the keys copied there from the broadphase's.
                self.keys.resize(context, count)?;
                self.contacts.resize(context, count)?;
                let mut encoder =
                    context
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some("collision read-back"),
                        });
                if count > 0 {
                    let bytes = (count * size_of::<u64>()) as u64;
                    let from = self.broadphase.keys().buffer();
                    encoder.copy_buffer_to_buffer(from, 0, self.keys.buffer(), 0, bytes);
                }
                self.keys.encode_download(context, &mut encoder);
                self.contacts.encode_download(context, &mut encoder);
                context.queue.submit([encoder.finish()]);
                self.keys.read_download(context, keys)?;
                self.contacts.read_download(context, contacts)?;
                contacts.iter_mut().for_each(PairContact::clear_unused);
            }
        }
        self.contacts.resize(context, count)?;
        record_copy(profiler, COLLISION.download, elapsed_ms(start));
        self.pair_contacts_fresh = false;
        self.collided = true;
        self.summarized = summarize;
        self.summaries_left += usize::from(summarize && !summaries_back);
        Ok(())
    }

    /// How many pairs the last [`Self::collide`] found (their keys stay here:
    /// [`Self::read_pair_keys`]).
    pub fn pair_count(&self) -> usize {
        self.keys.len()
    }

    /// How many pairs the pair functions computed in the last [`Self::collide`] (the others
    /// moved their manifolds with the bodies, or have none).
    pub fn pairs_computed(&self) -> usize {
        self.pairs_computed
    }

    /// After [`Self::collide`]: the host's pair cache now holds exactly the keys and contacts
    /// it returned, every one computed on the GPU, so the rows may read them on the device.
    pub fn pair_cache_is_collide_output(&mut self) {
        self.pair_contacts_fresh = true;
    }

    /// Stage 4 on the GPU: [`update_contacts`](crate::stages::narrowphase::update_contacts)'s
    /// contract, the kernels of `stages/narrowphase/gpu.rs`.
    pub fn update_contacts(
        &mut self,
        profiler: &mut Profiler,
        keys: &[u64],
        contacts: &mut [PairContact],
        inputs: &NarrowphaseInputs,
        bodies: &BodyInputs,
    ) -> Result<usize, GpuError> {
        let context = &self.context;
        let start = Instant::now();
        self.keys.upload(context, keys)?;
        // `contacts[i]` is last step's contact of `keys[i]` (the CPU pair cache keeps them in
        // key order), so the map to last step's array is the identity.
        let count = u32::try_from(keys.len()).expect("pair count fits in u32");
        if self.identity.len() != keys.len() {
            self.identity.clear();
            self.identity.extend(0..count);
        }
        self.old_index.upload(context, &self.identity)?;
        self.old_contacts.upload(context, contacts)?;
        self.skipped.upload(context, inputs.skipped)?;
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, bodies)?;
        record_copy(profiler, NARROWPHASE.upload, elapsed_ms(start));

        let device_inputs = GpuNarrowphaseInputs {
            keys: &self.keys,
            old_index: &self.old_index,
            old_contacts: &self.old_contacts,
            poses: &self.bodies.poses,
            velocities: &self.bodies.velocities,
            colliders: &self.bodies.colliders,
            hulls: &self.bodies.hulls,
            skipped: &self.skipped,
            margin: inputs.margin,
            dt: inputs.dt,
            shape_kinds: self.bodies.shape_kinds,
        };
        let (narrowphase, output) = (&mut self.narrowphase, &mut self.contacts);
        run_pass(
            context,
            &mut self.profiler,
            profiler,
            &NARROWPHASE,
            |pass| narrowphase.encode(context, pass, &device_inputs, output),
        )?;

        let start = Instant::now();
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("narrowphase read-back"),
            });
        self.contacts.encode_download(context, &mut encoder);
        self.narrowphase
            .encode_computed_download(context, &mut encoder)?;
        context.queue.submit([encoder.finish()]);
        self.contacts.read_download(context, &mut self.downloaded)?;
        let mut computed = self.narrowphase.read_computed(context)?;
        // Pairs with a mesh or a compound (and of a hull whose faces are too large to clip)
        // have no kernel yet: they keep last step's contact (for its impulses) and the host
        // computes them, as the `cpu pairs` line shows.
        let colliders = inputs.colliders;
        let on_gpu = |key: u64| {
            let (a, b) = crate::stages::pairs::pair_bodies(key);
            gpu_pair(&colliders[a as usize].shape, &colliders[b as usize].shape)
        };
        let mut host_pairs = 0;
        for ((contact, downloaded), &key) in contacts.iter_mut().zip(&self.downloaded).zip(keys) {
            if on_gpu(key) {
                *contact = *downloaded;
                contact.clear_unused();
            } else {
                host_pairs += 1;
            }
        }
        self.pair_contacts_fresh = host_pairs == 0;
        record_copy(profiler, NARROWPHASE.download, elapsed_ms(start));
        computed += profiler.scope("cpu pairs", || {
            update_contacts_where(keys, contacts, inputs, |a, b| !gpu_pair(a, b))
        });
        Ok(computed)
    }
}

impl GpuStages {
    /// Stage 5 on the GPU:
    /// [`build_constraints`](crate::stages::constraints::build_constraints)'s contract over the
    /// manifold `slots`, and
    /// [`build_joint_constraints`](crate::stages::constraints::build_joint_constraints)'s for
    /// `joints` (the drag's row beside them), to the host or kept on the device ([`RowsTo`]).
    pub fn build_constraints(
        &mut self,
        profiler: &mut Profiler,
        slots: RowSlots,
        inputs: &RowInputs,
        (version, changed): (u64, &BodyChanges),
        joints: &JointRowInputs,
        to: RowsTo,
    ) -> Result<(), GpuError> {
        if let Some(held) = self.held_step() {
            // Built with the collision's submission, with the islands' links where planned.
            let link_islands = held.link_islands;
            let planned = matches!(slots, RowSlots::Narrowphase)
                && joints.slots.is_empty()
                && matches!(to, RowsTo::Device { link_islands: link, .. }
                    if (link && self.summarized && !self.host_island_links) == link_islands);
            if !planned {
                return Err(unplanned("the rows"));
            }
            self.rows_from_narrowphase = true;
            self.islands_linked = link_islands;
            self.island_links_made += usize::from(link_islands);
            return Ok(());
        }
        let context = &self.context;
        let start = Instant::now();
        let from_narrowphase = match slots {
            RowSlots::Host { keys, contacts } => {
                self.row_keys.upload(context, keys)?;
                self.row_contacts.upload(context, contacts)?;
                false
            }
            RowSlots::Narrowphase => {
                debug_assert!(
                    self.pair_contacts_fresh,
                    "no GPU narrowphase output this step"
                );
                true
            }
        };
        self.rows_from_narrowphase = from_narrowphase;
        let bodies = BodyInputs {
            poses: inputs.poses,
            velocities: inputs.velocities,
            masses: inputs.masses,
            colliders: inputs.colliders,
            version,
            changed,
        };
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, &bodies)?;
        // No joint row to solve (none, or all asleep): no joint kernel.
        let build_joints = !joints.slots.is_empty();
        if build_joints {
            self.joint_rows.sync(context, joints.joints)?;
            if let Some(drag) = joints.drag {
                self.joint_rows
                    .write_row(context, self.joint_rows.extra_slot(), drag);
            }
        }
        record_copy(profiler, CONSTRAINTS.upload, elapsed_ms(start));
        let (keys, contacts) = if from_narrowphase {
            (&self.keys, &self.contacts)
        } else {
            (&self.row_keys, &self.row_contacts)
        };
        let device_inputs = GpuRowInputs {
            keys,
            contacts,
            poses: &self.bodies.poses,
            velocities: &self.bodies.velocities,
            masses: &self.bodies.masses,
            colliders: &self.bodies.colliders,
            softness: inputs.softness,
            static_softness: inputs.static_softness,
        };
        let joint_inputs = GpuJointInputs {
            poses: &self.bodies.poses,
            masses: &self.bodies.masses,
            softness: joints.softness,
        };
        let (rows, joint_rows) = (&mut self.rows, &mut self.joint_rows);
        let (count, link_islands) = match to {
            RowsTo::Host(..) => (None, false),
            RowsTo::Device {
                at_most,
                link_islands,
            } => (Some(at_most), link_islands),
        };
        let link_islands = link_islands && self.summarized && !self.host_island_links;
        let link_pairs = link_pairs(&self.broadphase, &self.summaries);
        let island_links = &mut self.island_links;
        let encode = |encoder: &mut wgpu::CommandEncoder, timer: &mut GpuProfiler| {
            encode_pass(encoder, timer, CONSTRAINTS.kernel, |pass| {
                rows.encode(context, pass, &device_inputs, count, false)
            })?;
            if build_joints {
                encode_pass(encoder, timer, JOINT_ROWS_KERNEL, |pass| {
                    joint_rows.encode_build(context, pass, &joint_inputs);
                    Ok(())
                })?;
            }
            if link_islands {
                let masses = device_inputs.masses;
                encode_island_links(context, (encoder, timer), island_links, &link_pairs, masses)?;
            }
            Ok(())
        };
        if count.is_none() {
            run_passes(context, &mut self.profiler, profiler, &CONSTRAINTS, encode)?;
        } else {
            // The rows stay on the device for the batching and the solver, whose submissions
            // follow this one on the queue: no wait here.
            let spans = (&CONSTRAINTS, CONSTRAINTS_SUBMIT);
            submit_passes(context, &mut self.profiler, profiler, spans, encode)?;
        }
        self.islands_linked = link_islands;
        self.island_links_made += usize::from(link_islands);
        if let RowsTo::Host(contacts, joint_constraints) = to {
            let start = Instant::now();
            self.rows.read_back(context, contacts)?;
            self.joint_rows
                .read_back(context, joints.slots, joint_constraints)?;
            record_copy(profiler, CONSTRAINTS.download, elapsed_ms(start));
        }
        Ok(())
    }

    /// Stage 6 on the GPU: [`color_constraints`](crate::stages::batching::color_constraints)'s
    /// contract (the same colors); the host lays the constraints out by batch.
    pub fn color_constraints(
        &mut self,
        profiler: &mut Profiler,
        bodies: impl Iterator<Item = (u32, u32)>,
        body_count: usize,
        ordered: usize,
        batcher: Batcher,
        coloring: &mut Coloring,
    ) -> Result<(), GpuError> {
        if self.held_step().is_some() {
            return Err(unplanned("the batching"));
        }
        let context = &self.context;
        let start = Instant::now();
        self.batching.upload(context, bodies)?;
        record_copy(profiler, BATCHING.upload, elapsed_ms(start));
        // Most of the 64 rounds find nothing left: as many as the last step needed and a few
        // more get dispatches of their own, the rest one dispatch (`rest_rounds`).
        let rounds = self.batching_rounds;
        batching_pass(
            context,
            (&mut self.profiler, profiler),
            &mut self.batching,
            coloring,
            |batching, pass| batching.encode(context, pass, body_count, ordered, batcher, rounds),
        )?;
        self.batching_rounds = next_batching_rounds(coloring.rounds, self.batching.listable_from());
        Ok(())
    }

    /// Whether the batches may be laid out on the device
    /// ([`Self::color_constraints_on_device`]) where the step needs no host layout.
    pub fn lays_out_batches(&self) -> bool {
        !self.host_layout
    }

    /// Stage 6 on the GPU with the batch layout on the device too
    /// ([`GpuBatchLayout`]): the colors of the `count` contact rows that
    /// [`Self::build_constraints`] left on the device this step (no joint rows), with their
    /// order and offsets, stay there for [`Self::solve_batched`] with [`BatchLayout::Device`],
    /// which brings the colors back after the solve. Submitted, not waited for.
    pub fn color_constraints_on_device(
        &mut self,
        profiler: &mut Profiler,
        count: usize,
        body_count: usize,
        batcher: Batcher,
    ) -> Result<(), GpuError> {
        // A handle of its own (reference-counted), for the recording below to borrow `self`.
        let context = &self.context.clone();
        let start = Instant::now();
        self.batched.size_for(context, count, 0)?;
        let bodies = (&self.rows.bodies, count);
        let any = self
            .batching
            .prepare_device_bodies(context, bodies, body_count)?;
        let plan = BatchingPlan {
            any,
            body_count,
            batcher,
            rounds: self.batching_rounds,
        };
        self.last_rows = count;
        if let Some(held) = self.held_step() {
            // Colored and laid out with the collision's submission. The preparation above
            // gave the buffers this step's lengths (the colors' read-back, the solve's plan);
            // the counts it sent land before the next submission, which sends its own.
            if held.batching != plan {
                return Err(unplanned("the batching"));
            }
            profiler.record(BATCHING.encode, SpanKind::Cpu, elapsed_ms(start));
            self.last_batching = Some(plan);
            self.laid_out_on_device = true;
            self.device_layouts += 1;
            return Ok(());
        }
        // The commands recorded during the collision's wait, when they are this plan's and
        // nothing was made since (see `SolveAhead`).
        let resources = context.resources_made();
        let ahead = self
            .batching_ahead
            .take()
            .filter(|ahead| ahead.plan == plan && ahead.resources == resources);
        let commands = match ahead {
            Some(ahead) => {
                self.batchings_encoded_ahead += 1;
                ahead.commands
            }
            None => {
                self.ahead_batching_profiler.discard();
                let mut encoder =
                    context
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some(BATCHING.kernel[0]),
                        });
                self.record_batching(&mut encoder, &plan, false)?;
                encoder.finish()
            }
        };
        profiler.record(BATCHING.encode, SpanKind::Cpu, elapsed_ms(start));
        let start = Instant::now();
        context.queue.submit([commands]);
        profiler.record(BATCHING_SUBMIT, SpanKind::Cpu, elapsed_ms(start));
        self.last_batching = Some(plan);
        self.laid_out_on_device = true;
        self.device_layouts += 1;
        Ok(())
    }

    /// Records a device layout's batching (`plan`) into `encoder`, timed on the stages'
    /// profiler or, `ahead`, on the one of the batching recorded ahead (resolved here).
    fn record_batching(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        plan: &BatchingPlan,
        ahead: bool,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let (batching, layout) = (&mut self.batching, &mut self.layout);
        let (order, bodies) = (self.batched.order(), &self.rows.bodies);
        let timer = if ahead {
            &mut self.ahead_batching_profiler
        } else {
            &mut self.profiler
        };
        encode_pass(encoder, timer, BATCHING.kernel, |pass| {
            if plan.any {
                let (count, batcher, rounds) = (plan.body_count, plan.batcher, plan.rounds);
                batching.record_device_bodies(context, pass, bodies, count, batcher, rounds);
            }
            layout.encode(context, pass, batching.tally(), &batching.colors, order)
        })?;
        if ahead {
            timer.resolve(encoder);
        }
        Ok(())
    }

    /// Stage 7 on the GPU: [`solve`](crate::stages::solver::solve)'s contract, contacts and
    /// joints (the drag included) in the same batches; or, for [`SolverKind::Jacobi`],
    /// [`jacobi::solve`](crate::stages::solver::jacobi::solve)'s. With `integrate`, stage 8
    /// runs in the same submission ([`Self::integrate`]'s contract) and the solver's bodies
    /// stay on the device.
    pub fn solve(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: SolverSettings,
        integrate: Option<BodyState>,
    ) -> Result<(), GpuError> {
        let solved = self.solve_host_rows(profiler, kind, bodies, batched, settings, integrate);
        if solved.is_err() {
            // The integration may have moved the device's bodies.
            self.bodies.synced = None;
        }
        solved
    }

    fn solve_host_rows(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: SolverSettings,
        mut integrate: Option<BodyState>,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let start = Instant::now();
        if let Some(state) = &integrate {
            upload_bodies(
                context,
                &mut self.bodies,
                &mut self.collider_data,
                &state.inputs(),
            )?;
        }
        self.solver_bodies.upload(context, bodies)?;
        lay_out(batched.contacts, &mut self.constraint_words);
        self.batched_contacts
            .upload(context, &self.constraint_words)?;
        self.batch_offsets
            .upload(context, batched.contact_offsets)?;
        self.batched_joints.upload(context, batched.joints)?;
        self.joint_batch_offsets
            .upload(context, batched.joint_offsets)?;
        let jacobi = match kind {
            SolverKind::Pgs => None,
            SolverKind::Jacobi => {
                let jacobi = jacobi_solver(&mut self.jacobi, context)?;
                jacobi.prepare(
                    bodies,
                    batched.contacts.iter().map(|c| (c.body_a, c.body_b)),
                    batched.joints.iter().map(|j| (j.body_a, j.body_b)),
                )?;
                Some(jacobi)
            }
        };
        record_copy(profiler, SOLVER.upload, elapsed_ms(start));
        let restitution = batched.contacts.iter().any(|c| c.restitution > 0.0);
        let (solver, device_bodies) = (&mut self.solver, &self.solver_bodies);
        let device_batched = DeviceBatched {
            contacts: &self.batched_contacts,
            contact_offsets: &self.batch_offsets,
            joints: &self.batched_joints,
            joint_offsets: &self.joint_batch_offsets,
            sizes: BatchSizes::Host {
                contact_offsets: batched.contact_offsets,
                joint_offsets: batched.joint_offsets,
                has_overflow: batched.has_overflow,
            },
            adjacency: None,
        };
        let spans = if jacobi.is_some() {
            &JACOBI_SOLVER
        } else {
            &SOLVER
        };
        let (finalize, device) = (&mut self.finalize_bodies, &self.bodies);
        run_passes(
            context,
            &mut self.profiler,
            profiler,
            spans,
            |encoder, timer| {
                encode_pass(encoder, timer, spans.kernel, |pass| {
                    match jacobi {
                        Some(jacobi) => jacobi.encode(
                            pass,
                            device_bodies,
                            &device_batched,
                            settings,
                            restitution,
                        ),
                        None => solver.encode(
                            pass,
                            device_bodies,
                            &device_batched,
                            settings,
                            restitution,
                        ),
                    };
                    Ok(())
                })?;
                if integrate.is_some() {
                    encode_pass(encoder, timer, SOLVER_INTEGRATE_KERNEL, |pass| {
                        let motion = (device_bodies, &device.poses, &device.velocities);
                        finalize.encode(context, pass, motion);
                        Ok(())
                    })?;
                }
                Ok(())
            },
        )?;
        let start = Instant::now();
        match &mut integrate {
            Some(state) => {
                self.bodies.synced = None;
                download_bodies(context, &mut self.bodies, state)?;
                self.integrated_this_step = true;
                record_copy(profiler, SOLVER_BODIES_DOWNLOAD, elapsed_ms(start));
            }
            None => {
                self.solver_bodies
                    .download_into(context, &mut self.downloaded_bodies)?;
                bodies.copy_from_slice(&self.downloaded_bodies);
                record_copy(profiler, SOLVER.download, elapsed_ms(start));
            }
        }
        // Impulses come back for warm starting and, for joints, the host's break test.
        let start = Instant::now();
        self.batched_contacts
            .download_into(context, &mut self.constraint_words)?;
        read_back(&self.constraint_words, batched.contacts);
        self.batched_joints
            .download_into(context, &mut self.downloaded_joints)?;
        batched.joints.copy_from_slice(&self.downloaded_joints);
        record_copy(profiler, SOLVER.download, elapsed_ms(start));
        Ok(())
    }

    /// Stage 8 on the GPU after a solve elsewhere:
    /// [`finalize_bodies`](crate::stages::integrate::finalize_bodies)'s contract for the
    /// motion `bodies`, on the device's copies of `state` (uploaded first when stale), whose
    /// new poses and velocities come back into `state`. The device keeps them: the host
    /// says so with [`Self::bodies_integrated`] once it has taken them.
    pub fn integrate(
        &mut self,
        profiler: &mut Profiler,
        bodies: &[SolverBody],
        mut state: BodyState,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let start = Instant::now();
        upload_bodies(
            context,
            &mut self.bodies,
            &mut self.collider_data,
            &state.inputs(),
        )?;
        self.solver_bodies.upload(context, bodies)?;
        record_copy(profiler, INTEGRATE.upload, elapsed_ms(start));
        // The kernel moves the device's bodies: not the host's until they came back.
        self.bodies.synced = None;
        let (finalize, motion, device) = (
            &mut self.finalize_bodies,
            &self.solver_bodies,
            &mut self.bodies,
        );
        run_passes(
            context,
            &mut self.profiler,
            profiler,
            &INTEGRATE,
            |encoder, timer| {
                encode_pass(encoder, timer, INTEGRATE.kernel, |pass| {
                    let motion = (motion, &device.poses, &device.velocities);
                    finalize.encode(context, pass, motion);
                    Ok(())
                })?;
                encode_body_downloads(context, device, encoder);
                Ok(())
            },
        )?;
        let start = Instant::now();
        read_body_downloads(context, &self.bodies, &mut state)?;
        self.integrated_this_step = true;
        record_copy(profiler, INTEGRATE.download, elapsed_ms(start));
        Ok(())
    }
}

impl GpuStages {
    /// Stage 7 on the GPU after stages 5 and 6 ran there too: the contacts and joints that
    /// [`Self::build_constraints`] left on the device are gathered in batch order (`layout`),
    /// solved as [`Self::solve`] does, and only impulses come back, in batch order: the
    /// contacts' into `impulses` (when given: with the contacts on the device nobody on the
    /// host reads them), the joints' into `joint_impulses`. `contact_bodies` and
    /// `joint_bodies` are the bodies (A, B) of the gathered rows, in batch order: the Jacobi
    /// solver's adjacency (which needs a host layout).
    #[allow(clippy::too_many_arguments)]
    pub fn solve_batched(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        contact_bodies: impl Iterator<Item = (u32, u32)> + Clone,
        joint_bodies: impl Iterator<Item = (u32, u32)> + Clone,
        layout: BatchLayout,
        settings: SolverSettings,
        restitution: bool,
        impulses: Option<&mut Vec<BatchedImpulses>>,
        joint_impulses: &mut Vec<BatchedJointImpulses>,
        integrate: Option<BodyState>,
    ) -> Result<(), GpuError> {
        let on_device = self.laid_out_on_device;
        self.laid_out_on_device = false;
        debug_assert_eq!(
            on_device,
            matches!(layout, BatchLayout::Device { .. }),
            "a device layout exactly when the batching left one"
        );
        let solved = self.solve_batched_rows(
            profiler,
            kind,
            bodies,
            contact_bodies,
            joint_bodies,
            layout,
            settings,
            restitution,
            impulses,
            joint_impulses,
            integrate,
        );
        if solved.is_err() {
            // The solve may have written some joints' impulses to their slots, which the
            // host's joints never got, and the integration may have moved the device's bodies.
            self.joint_rows.impulses_changed();
            self.bodies.synced = None;
        }
        solved
    }

    #[allow(clippy::too_many_arguments)]
    fn solve_batched_rows(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        contact_bodies: impl Iterator<Item = (u32, u32)> + Clone,
        joint_bodies: impl Iterator<Item = (u32, u32)> + Clone,
        mut layout: BatchLayout,
        settings: SolverSettings,
        restitution: bool,
        impulses: Option<&mut Vec<BatchedImpulses>>,
        joint_impulses: &mut Vec<BatchedJointImpulses>,
        mut integrate: Option<BodyState>,
    ) -> Result<(), GpuError> {
        // A handle of its own (reference-counted), for the recording below to borrow `self`.
        let context = &self.context.clone();
        let start = Instant::now();
        // The rows ran here, so the velocities and masses on the device are this step's: the
        // solver's bodies are made from them there.
        debug_assert!(
            self.bodies.uploaded_this_step,
            "no bodies on the device this step"
        );
        if let Some(state) = &integrate {
            upload_bodies(
                context,
                &mut self.bodies,
                &mut self.collider_data,
                &state.inputs(),
            )?;
        }
        self.solver_bodies.resize(context, bodies.len())?;
        let (joint_order, host_sizes) = match &layout {
            BatchLayout::Host {
                order,
                offsets,
                joint_order,
                joint_offsets,
                has_overflow,
            } => {
                // The host's batches at a device layout's places, for the plan of the next
                // device layout: batch k is color k, the overflow batch the last.
                let expected = &mut self.expected_batch_sizes;
                expected.fill(0);
                let batches = offsets.len().saturating_sub(1);
                for batch in 0..batches {
                    let place = if *has_overflow && batch + 1 == batches {
                        LAYOUT_BATCHES - 1
                    } else {
                        batch
                    };
                    expected[place] = offsets[batch + 1] - offsets[batch];
                }
                self.batch_offsets.upload(context, offsets)?;
                self.joint_batch_offsets.upload(context, joint_offsets)?;
                self.batched.upload(context, order, joint_order.len())?;
                let sizes = BatchSizes::Host {
                    contact_offsets: offsets,
                    joint_offsets,
                    has_overflow: *has_overflow,
                };
                (*joint_order, Some(sizes))
            }
            BatchLayout::Device { .. } => {
                // Contacts only: every batch's joints are none.
                let zeros = [0; LAYOUT_BATCHES + 1];
                self.joint_batch_offsets.upload(context, &zeros)?;
                (&[][..], None)
            }
        };
        self.joint_rows.upload_order(context, joint_order)?;
        if kind == SolverKind::Jacobi {
            let jacobi = jacobi_solver(&mut self.jacobi, context)?;
            jacobi.prepare(bodies, contact_bodies, joint_bodies)?;
        }
        record_copy(profiler, SOLVER.upload, elapsed_ms(start));
        // The rest timers move after an integration here, with the sleep test where the
        // islands were linked on the device.
        let rest =
            (integrate.is_some() && self.rests_bodies(bodies.len())).then_some(self.islands_linked);
        let plan = SolvePlan {
            settings,
            jacobi: kind == SolverKind::Jacobi,
            restitution,
            integrating: integrate.is_some(),
            impulses_back: impulses.is_some(),
            // Rows from this step's one-submission collision: their impulses also go to the
            // pairs' contacts on the device, for the next step's collision
            // ([`Self::collide`]).
            scatter: self.collided && self.rows_from_narrowphase && self.pair_contacts_fresh,
            joints: !joint_order.is_empty(),
            // A device layout's warm start gathers by body: its adjacency first. None without
            // a constraint this step: the batching encoded nothing, so its masks are last
            // step's (or shorter than the bodies), and an adjacency built from them would hand
            // out last step's warm starts. (Found in review: through the API a contact ends
            // with zero impulses, so no test shows it.)
            by_body: host_sizes.is_none()
                && self.warm_start_by_body
                && !self.batched.order().is_empty(),
            expected: host_sizes.is_none().then_some(self.expected_batch_sizes),
            bodies: bodies.len(),
            rest,
            bodies_back: integrate.is_some() && self.reads_bodies_back(rest),
        };
        if plan.integrating {
            // The kernel moves the device's bodies: not the host's until they came back.
            self.bodies.synced = None;
        }
        // Solved with the collision's submission, where the step held.
        let held = self.speculated.take().filter(|speculated| speculated.held);
        if held.as_ref().is_some_and(|held| held.solve != plan) {
            return Err(unplanned("the solve"));
        }
        // The commands recorded during the collision's wait, when they are this plan's and
        // read the buffers this one would (none made since: see `SolveAhead`).
        let resources = context.resources_made();
        let ahead = self
            .solve_ahead
            .take()
            .filter(|ahead| ahead.plan == plan && ahead.resources == resources);
        if ahead.is_none() && held.is_none() {
            self.ahead_profiler.discard();
        }
        let start = Instant::now();
        // The solve's commands, and those that resolve the stages' timestamps when the solve
        // was recorded ahead (on a profiler of its own).
        let (commands, resolved) = match ahead {
            _ if held.is_some() => (None, None),
            Some(ahead) => {
                self.solves_encoded_ahead += 1;
                // The passes of the stages submitted since the last wait were timed on the
                // stages' profiler: resolved in a command buffer of their own.
                let resolved = self.profiler.is_active().then(|| {
                    let mut encoder = context.device.create_command_encoder(&Default::default());
                    self.profiler.resolve(&mut encoder);
                    encoder.finish()
                });
                (Some(ahead.commands), resolved)
            }
            None => {
                let mut encoder =
                    context
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                            label: Some(SOLVER.kernel[0]),
                        });
                self.encode_batched_solve(&mut encoder, &plan, host_sizes, Recording::Now)?;
                self.profiler.resolve(&mut encoder);
                (Some(encoder.finish()), None)
            }
        };
        profiler.record(SOLVER.encode, SpanKind::Cpu, elapsed_ms(start));
        if let Some(commands) = commands {
            let start = Instant::now();
            context
                .queue
                .submit(std::iter::once(commands).chain(resolved));
            let submit_ms = elapsed_ms(start);
            // The host would wait here: it records the next step's solve meanwhile.
            self.record_next_solve(profiler, &plan);
            let start = Instant::now();
            context.wait()?;
            profiler.record(SOLVER.wait, SpanKind::Cpu, submit_ms + elapsed_ms(start));
        }
        self.profiler.collect(context, profiler)?;
        self.ahead_profiler.collect(context, profiler)?;
        self.ahead_batching_profiler.collect(context, profiler)?;
        let start = Instant::now();
        if let Some(tested) = plan.rest {
            self.rest_tally = Some(self.rest.read_tally(context, tested)?);
        }
        match &mut integrate {
            Some(state) => {
                if plan.bodies_back {
                    read_body_downloads(context, &self.bodies, state)?;
                    self.solves_reading_bodies += 1;
                }
                self.bodies.newer = !plan.bodies_back;
                self.integrated_this_step = true;
                record_copy(profiler, SOLVER_BODIES_DOWNLOAD, elapsed_ms(start));
            }
            None => {
                self.solver_bodies
                    .read_download(context, &mut self.downloaded_bodies)?;
                bodies.copy_from_slice(&self.downloaded_bodies);
                record_copy(profiler, SOLVER.download, elapsed_ms(start));
            }
        }
        let start = Instant::now();
        if let Some(impulses) = impulses {
            self.batched.impulses.read_download(context, impulses)?;
        }
        self.batched
            .joint_impulses
            .read_download(context, joint_impulses)?;
        if let BatchLayout::Device { coloring } = &mut layout {
            let offsets = &mut self.host_layout_offsets;
            self.layout.offsets.read_download(context, offsets)?;
            for (batch, expected) in self.expected_batch_sizes.iter_mut().enumerate() {
                *expected = offsets[batch + 1] - offsets[batch];
            }
            // Batch k of the layout is color k, its last batch the overflow batch.
            coloring.colors.clear();
            coloring.set_batch_sizes(&self.expected_batch_sizes);
            coloring.rounds = self
                .batching
                .finish_read_tally(context, offsets[LAYOUT_BATCHES])?;
            self.batching_rounds =
                next_batching_rounds(coloring.rounds, self.batching.listable_from());
        }
        record_copy(profiler, SOLVER.download, elapsed_ms(start));
        self.impulses_scattered = plan.scatter;
        // The next step records its solve during its collision's wait from this one's plan,
        // where there is a device layout to plan from (PGS, contacts only, the bodies and
        // impulses staying on the device).
        let repeatable = plan.expected.is_some()
            && !plan.jacobi
            && !plan.impulses_back
            && !self.profiler.times_dispatches();
        self.last_solve = repeatable.then_some(plan);
        Ok(())
    }

    /// Records a batched solve (`plan`; `host_sizes`, the host's batch offsets, unless it has
    /// a device layout) into `encoder`: the rows into batch order (and the adjacency), the
    /// sweeps, the impulses out, the integration, then the read-backs, timed on the stages'
    /// profiler when recorded [`Recording::Now`], else on the one of the solve recorded ahead.
    fn encode_batched_solve(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        plan: &SolvePlan,
        host_sizes: Option<BatchSizes>,
        recording: Recording,
    ) -> Result<(), GpuError> {
        let ahead = recording != Recording::Now;
        let context = &self.context;
        let solver = &mut self.solver;
        let (batched, rows) = (&mut self.batched, &self.rows);
        let joint_rows = &mut self.joint_rows;
        let sizes = host_sizes.unwrap_or(BatchSizes::Device {
            expected: &self.expected_batch_sizes,
        });
        let host_offsets = host_sizes.map(|_| &self.batch_offsets);
        let device_joint_offsets = &self.joint_batch_offsets;
        let (batching, layout_offsets) = (&mut self.batching, &mut self.layout.offsets);
        let adjacency = &mut self.adjacency;
        let spans = if plan.jacobi { &JACOBI_SOLVER } else { &SOLVER };
        let jacobi = self.jacobi.as_mut().filter(|_| plan.jacobi);
        let solver_bodies = &mut self.solver_bodies;
        let (prepare, finalize) = (&mut self.prepare_bodies, &mut self.finalize_bodies);
        let (rest, roots) = (&mut self.rest, self.island_links.roots());
        let device = &mut self.bodies;
        let pair_contacts = if recording == Recording::NextStep {
            &self.old_contacts
        } else {
            &self.contacts
        };
        let timer = match recording {
            Recording::Now => &mut self.profiler,
            Recording::Ahead => &mut self.ahead_profiler,
            Recording::NextStep => &mut self.next_profiler,
        };
        // Three passes, timed apart: the rows into batch order (and the adjacency), the
        // sweeps, the impulses out.
        encode_pass(encoder, timer, SOLVER_LAYOUT_KERNEL, |pass| {
            prepare.encode(
                context,
                pass,
                &device.velocities,
                &device.masses,
                solver_bodies,
            );
            if plan.joints {
                joint_rows.encode_gather(context, pass);
            }
            batched.encode_gather(
                context,
                pass,
                &rows.constraints,
                (&joint_rows.batched, &joint_rows.impulses),
                plan.restitution,
            );
            if plan.by_body {
                let inputs = AdjacencyInputs {
                    masks: batching.masks(),
                    colors: &batching.colors,
                    order: batched.order(),
                    row_bodies: &rows.bodies,
                    offsets: layout_offsets,
                };
                let capacity = batched.order().capacity();
                let bodies = solver_bodies.len();
                adjacency.encode(context, pass, &inputs, bodies, capacity)?;
            }
            Ok(())
        })?;
        encode_pass(encoder, timer, spans.kernel, |pass| {
            let device_batched = DeviceBatched {
                contacts: &batched.constraints,
                contact_offsets: host_offsets.unwrap_or(layout_offsets),
                joints: &joint_rows.batched,
                joint_offsets: device_joint_offsets,
                sizes,
                adjacency: plan
                    .by_body
                    .then_some((&adjacency.starts, &adjacency.entries)),
            };
            let settings = plan.settings;
            match jacobi {
                Some(jacobi) => jacobi.encode(
                    pass,
                    solver_bodies,
                    &device_batched,
                    settings,
                    plan.restitution,
                ),
                None => solver.encode(
                    pass,
                    solver_bodies,
                    &device_batched,
                    settings,
                    plan.restitution,
                ),
            };
            Ok(())
        })?;
        encode_pass(encoder, timer, SOLVER_IMPULSES_KERNEL, |pass| {
            batched.encode_read_impulses(pass);
            if plan.scatter {
                batched.encode_scatter_pair_impulses(context, pass, pair_contacts);
            }
            Ok(())
        })?;
        if plan.integrating {
            if plan.rest.is_some() {
                rest.encode_clear(encoder);
            }
            encode_pass(encoder, timer, SOLVER_INTEGRATE_KERNEL, |pass| {
                let motion = (&*solver_bodies, &device.poses, &device.velocities);
                finalize.encode(context, pass, motion);
                if let Some(test) = plan.rest {
                    let inputs = RestInputs {
                        held: finalize.held(),
                        bodies: solver_bodies,
                        colliders: &device.colliders,
                        roots: test.then_some(roots),
                    };
                    rest.encode(context, pass, &inputs, plan.settings.dt);
                }
                Ok(())
            })?;
        }
        // The read-backs ride in the kernels' submission: one wait for the stage.
        if plan.bodies_back {
            encode_body_downloads(context, device, encoder);
        } else if !plan.integrating {
            solver_bodies.encode_download(context, encoder);
        }
        if plan.rest.is_some() {
            rest.encode_download(context, encoder);
        }
        if plan.impulses_back {
            batched.impulses.encode_download(context, encoder);
        }
        batched.joint_impulses.encode_download(context, encoder);
        if host_offsets.is_none() {
            // The offsets for the host's histogram and the next step's plan, the tally for its
            // rounds. The colors stay here until the viewer asks for them
            // ([`Self::read_row_colors`]).
            batching.encode_read_tally(context, encoder);
            layout_offsets.encode_download(context, encoder);
        }
        if ahead {
            timer.resolve(encoder);
        }
        Ok(())
    }

    /// Records this step's batching and solve during the collision's wait, from last step's
    /// plans (see [`SolveAhead`]), when last step's can be planned from.
    fn encode_solve_ahead(&mut self, profiler: &mut Profiler) -> Result<(), GpuError> {
        (self.solve_ahead, self.batching_ahead) = (None, None);
        self.ahead_profiler.discard();
        self.ahead_batching_profiler.discard();
        let (Some(mut plan), Some(mut batching)) =
            (self.last_solve.take(), self.last_batching.take())
        else {
            return Ok(());
        };
        // What changed since with last step's results: its rounds and batch sizes.
        batching.rounds = self.batching_rounds;
        if !self.encodes_ahead {
            return Ok(());
        }
        let start = Instant::now();
        let mut encoder =
            self.context
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("batching, recorded ahead"),
                });
        self.record_batching(&mut encoder, &batching, true)?;
        let batching_commands = encoder.finish();
        plan.expected = Some(self.expected_batch_sizes);
        self.solver_bodies.resize(&self.context, plan.bodies)?;
        let mut encoder =
            self.context
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("solver, recorded ahead"),
                });
        self.encode_batched_solve(&mut encoder, &plan, None, Recording::Ahead)?;
        let resources = self.context.resources_made();
        self.batching_ahead = Some(BatchingAhead {
            plan: batching,
            resources,
            commands: batching_commands,
        });
        self.solve_ahead = Some(SolveAhead {
            plan,
            resources,
            commands: encoder.finish(),
        });
        profiler.record(SOLVER_ENCODED_AHEAD, SpanKind::Cpu, elapsed_ms(start));
        Ok(())
    }
}

/// The Jacobi solver, built at its first use.
fn jacobi_solver<'a>(
    jacobi: &'a mut Option<GpuJacobi>,
    context: &GpuContext,
) -> Result<&'a mut GpuJacobi, GpuError> {
    if jacobi.is_none() {
        *jacobi = Some(GpuJacobi::new(context)?);
    }
    Ok(jacobi.as_mut().expect("built just above"))
}

/// Encodes one stage's kernels into a measured pass, submits and waits: the host's encoding
/// and its wait are CPU lines, the kernels' time a GPU line when the adapter has timestamps.
fn run_pass(
    context: &GpuContext,
    gpu_profiler: &mut GpuProfiler,
    profiler: &mut Profiler,
    spans: &StageSpans,
    encode: impl FnOnce(&mut wgpu::ComputePass<'_>) -> Result<(), GpuError>,
) -> Result<(), GpuError> {
    run_passes(context, gpu_profiler, profiler, spans, |encoder, timer| {
        encode_pass(encoder, timer, spans.kernel, encode)
    })
}

/// The touching pairs the islands' links pass over: this step's collision's, on the device.
fn link_pairs<'a>(
    broadphase: &'a GpuBroadphase,
    summaries: &'a GpuPairSummaries,
) -> GpuLinkPairs<'a> {
    GpuLinkPairs {
        count: broadphase.count(),
        keys: broadphase.keys(),
        summaries: &summaries.summaries,
        slots: broadphase.capacity(),
    }
}

/// Encodes the islands' links over `pairs` as a pass of their own (the device's sleep test
/// reads them after the solve, the host only where an island may fall asleep).
fn encode_island_links(
    context: &GpuContext,
    (encoder, timer): (&mut wgpu::CommandEncoder, &mut GpuProfiler),
    island_links: &mut GpuIslandLinks,
    pairs: &GpuLinkPairs,
    masses: &GpuVec<BodyMass>,
) -> Result<(), GpuError> {
    encode_pass(encoder, timer, ISLAND_LINKS_KERNEL, |pass| {
        island_links.encode(context, pass, pairs, masses)
    })
}

/// Encodes one measured pass (its GPU time recorded at `kernel`) into `encoder`.
fn encode_pass(
    encoder: &mut wgpu::CommandEncoder,
    gpu_profiler: &mut GpuProfiler,
    kernel: SpanPath,
    encode: impl FnOnce(&mut wgpu::ComputePass<'_>) -> Result<(), GpuError>,
) -> Result<(), GpuError> {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(kernel[0]),
        timestamp_writes: gpu_profiler.pass_timestamps(kernel),
    });
    gpu_profiler.timing_dispatches(|| encode(&mut pass))
}

/// [`run_pass`] for a stage whose kernels are timed on several lines: `encode` encodes its
/// passes ([`encode_pass`]) into one submission.
fn run_passes(
    context: &GpuContext,
    gpu_profiler: &mut GpuProfiler,
    profiler: &mut Profiler,
    spans: &StageSpans,
    encode: impl FnOnce(&mut wgpu::CommandEncoder, &mut GpuProfiler) -> Result<(), GpuError>,
) -> Result<(), GpuError> {
    let submit_ms = record_and_submit(context, gpu_profiler, profiler, spans, encode)?;
    wait_for_passes(context, gpu_profiler, profiler, spans, submit_ms)
}

/// [`run_passes`]' first half: records the passes and submits them, without waiting; returns
/// how long the submission took (ms), for [`wait_for_passes`].
fn record_and_submit(
    context: &GpuContext,
    gpu_profiler: &mut GpuProfiler,
    profiler: &mut Profiler,
    spans: &StageSpans,
    encode: impl FnOnce(&mut wgpu::CommandEncoder, &mut GpuProfiler) -> Result<(), GpuError>,
) -> Result<f64, GpuError> {
    let start = Instant::now();
    let mut encoder = context
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some(spans.kernel[0]),
        });
    encode(&mut encoder, gpu_profiler)?;
    gpu_profiler.resolve(&mut encoder);
    let commands = encoder.finish();
    profiler.record(spans.encode, SpanKind::Cpu, elapsed_ms(start));
    let start = Instant::now();
    context.queue.submit([commands]);
    Ok(elapsed_ms(start))
}

/// [`run_passes`]' second half: waits for the submission, records it and the wait as one line
/// (`submit_ms` the submission's part), and the kernels' GPU times.
fn wait_for_passes(
    context: &GpuContext,
    gpu_profiler: &mut GpuProfiler,
    profiler: &mut Profiler,
    spans: &StageSpans,
    submit_ms: f64,
) -> Result<(), GpuError> {
    let start = Instant::now();
    context.wait()?;
    profiler.record(spans.wait, SpanKind::Cpu, submit_ms + elapsed_ms(start));
    gpu_profiler.collect(context, profiler)
}

/// [`run_passes`] for a stage whose results stay on the device: submitted (timed at `submit`),
/// not waited for. Its kernels' GPU times are collected with the next stage that waits (the
/// profiler's queries accumulate until then).
fn submit_passes(
    context: &GpuContext,
    gpu_profiler: &mut GpuProfiler,
    profiler: &mut Profiler,
    (spans, submit): (&StageSpans, SpanPath),
    encode: impl FnOnce(&mut wgpu::CommandEncoder, &mut GpuProfiler) -> Result<(), GpuError>,
) -> Result<(), GpuError> {
    let start = Instant::now();
    let mut encoder = context
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some(spans.kernel[0]),
        });
    encode(&mut encoder, gpu_profiler)?;
    let commands = encoder.finish();
    profiler.record(spans.encode, SpanKind::Cpu, elapsed_ms(start));
    let start = Instant::now();
    context.queue.submit([commands]);
    profiler.record(submit, SpanKind::Cpu, elapsed_ms(start));
    Ok(())
}

/// One submission of batching kernels (`encode`) with the colors' read-back.
fn batching_pass(
    context: &GpuContext,
    (gpu_profiler, profiler): (&mut GpuProfiler, &mut Profiler),
    batching: &mut GpuBatching,
    coloring: &mut Coloring,
    encode: impl FnOnce(&mut GpuBatching, &mut wgpu::ComputePass<'_>) -> Result<(), GpuError>,
) -> Result<(), GpuError> {
    run_passes(
        context,
        gpu_profiler,
        profiler,
        &BATCHING,
        |encoder, timer| {
            encode_pass(encoder, timer, BATCHING.kernel, |pass| {
                encode(batching, pass)
            })?;
            batching.encode_read_back(context, encoder);
            Ok(())
        },
    )?;
    let start = Instant::now();
    batching.finish_read_back(context, coloring)?;
    record_copy(profiler, BATCHING.download, elapsed_ms(start));
    Ok(())
}

/// What [`pair_copy`] was built for: the source and destination buffers of the keys, and
/// their words.
type PairCopyKey = (wgpu::Buffer, wgpu::Buffer, usize);

/// The dispatches that copy last step's pair keys (`from`, the broadphase's) into `to`,
/// built again when the buffers or sizes changed.
fn pair_copy<'c>(
    context: &GpuContext,
    cache: &'c mut Option<(PairCopyKey, Vec<Dispatch>)>,
    from: &GpuVec<u64>,
    to: &GpuVec<u64>,
) -> Result<&'c Vec<Dispatch>, GpuError> {
    let words = to.len() * size_of::<u64>() / 4;
    let key: PairCopyKey = (from.buffer().clone(), to.buffer().clone(), words);
    if cache.as_ref().is_none_or(|(cached, _)| *cached != key) {
        let dispatches = copy_dispatch(context, &key.0, &key.1, words)?;
        *cache = Some((key, dispatches));
    }
    Ok(&cache.as_ref().expect("built above").1)
}

/// A device behind the host by at most one body in this many (or this few bodies) takes only
/// the changed bodies ([`BodyChanges`]): 52 bytes each (index, mass, velocity) and a scatter
/// kernel, where a whole upload writes 80 bytes a body (pose, mass, velocity).
const PARTIAL_UPLOAD_SHARE: usize = 4;
const PARTIAL_UPLOAD_MIN: usize = 64;

/// Uploads poses, velocities and masses when the device's are not at the host's version (only
/// the changed bodies' masses and velocities when [`BodyChanges`] allows), and the colliders
/// when they changed.
fn upload_bodies(
    context: &GpuContext,
    bodies: &mut DeviceBodies,
    collider_data: &mut Vec<ColliderData>,
    inputs: &BodyInputs,
) -> Result<(), GpuError> {
    let changed = &inputs.changed.bodies;
    if bodies.synced == Some(inputs.version) {
        #[cfg(debug_assertions)]
        debug_assert!(
            bodies.shadow == body_bytes(inputs),
            "the host's bodies changed without a new version: the device's are stale"
        );
    } else if bodies
        .synced
        .is_some_and(|synced| synced >= inputs.changed.since)
        && (bodies.newer
            || changed.len()
                <= (inputs.masses.len() / PARTIAL_UPLOAD_SHARE).max(PARTIAL_UPLOAD_MIN))
    {
        // Only some bodies' masses and velocities changed since: theirs, with their indices,
        // scattered on the device by a submission of their own (the stage's comes after it).
        // Where the device's bodies are the newer, however many: only the changed bodies'
        // velocities are the host's (set, or zero by a sleep or a wake).
        let scatter = &mut bodies.scatter;
        scatter.host_masses.clear();
        scatter
            .host_masses
            .extend(changed.iter().map(|&i| inputs.masses[i as usize]));
        scatter.host_velocities.clear();
        scatter
            .host_velocities
            .extend(changed.iter().map(|&i| inputs.velocities[i as usize]));
        bodies.synced = None;
        scatter.indices.upload(context, changed)?;
        scatter.masses.upload(context, &scatter.host_masses)?;
        scatter
            .velocities
            .upload(context, &scatter.host_velocities)?;
        let (masses, velocities) = (&bodies.masses, &bodies.velocities);
        // A new version with no body changed (an empty wake) submits nothing.
        if !changed.is_empty() {
            context.submit_pass("body scatter", |pass| {
                let (indices, kernel) = (&scatter.indices, &mut scatter.mass_kernel);
                kernel.encode(context, pass, indices, &scatter.masses, masses);
                let kernel = &mut scatter.velocity_kernel;
                kernel.encode(context, pass, indices, &scatter.velocities, velocities);
            });
        }
        bodies.synced = Some(inputs.version);
        bodies.partial_uploads += 1;
        #[cfg(debug_assertions)]
        {
            bodies.shadow = body_bytes(inputs);
        }
    } else if bodies.newer {
        return Err(GpuError::StaleBodies);
    } else {
        // Not synced while the copies are under way: a failed one leaves them mixed.
        bodies.synced = None;
        bodies.poses.upload(context, inputs.poses)?;
        bodies.velocities.upload(context, inputs.velocities)?;
        bodies.masses.upload(context, inputs.masses)?;
        bodies.synced = Some(inputs.version);
        #[cfg(debug_assertions)]
        {
            bodies.shadow = body_bytes(inputs);
        }
    }
    bodies.uploaded_this_step = true;
    if bodies.colliders_stale || bodies.colliders.len() != inputs.colliders.len() {
        collider_data.clear();
        collider_data.extend(inputs.colliders.iter().map(Collider::data));
        bodies.colliders.upload(context, collider_data)?;
        bodies.shape_kinds = shape_kinds(inputs.colliders);
        let mut hull_words = Vec::new();
        pack_hulls(inputs.colliders, &mut hull_words);
        bodies.hulls.upload(context, &hull_words)?;
        bodies.colliders_stale = false;
    }
    Ok(())
}

/// The device's poses and velocities into `state`, in a submission after the one that
/// integrated them.
fn download_bodies(
    context: &GpuContext,
    bodies: &mut DeviceBodies,
    state: &mut BodyState,
) -> Result<(), GpuError> {
    let mut encoder = context
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("bodies read-back"),
        });
    encode_body_downloads(context, bodies, &mut encoder);
    context.queue.submit([encoder.finish()]);
    read_body_downloads(context, bodies, state)
}

/// Records the copies of the device's poses and velocities for [`read_body_downloads`].
fn encode_body_downloads(
    context: &GpuContext,
    bodies: &mut DeviceBodies,
    encoder: &mut wgpu::CommandEncoder,
) {
    bodies.poses.encode_download(context, encoder);
    bodies.velocities.encode_download(context, encoder);
}

/// The poses and velocities that [`encode_body_downloads`] copied, into `state`, once their
/// submission is done.
fn read_body_downloads(
    context: &GpuContext,
    bodies: &DeviceBodies,
    state: &mut BodyState,
) -> Result<(), GpuError> {
    bodies.poses.read_download_to(context, state.poses)?;
    bodies
        .velocities
        .read_download_to(context, state.velocities)
}

/// The poses, velocities and masses as bytes, for the debug check in [`upload_bodies`].
#[cfg(debug_assertions)]
fn body_bytes(inputs: &BodyInputs) -> Vec<u8> {
    let mut bytes = Vec::new();
    bytes.extend_from_slice(bytemuck::cast_slice(inputs.poses));
    bytes.extend_from_slice(bytemuck::cast_slice(inputs.velocities));
    bytes.extend_from_slice(bytemuck::cast_slice(inputs.masses));
    bytes
}

fn elapsed_ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, Transform, Vec3};
    use crate::pipeline::config::{Softness, StepConfig};
    use crate::pipeline::devices::Executor;
    use crate::stages::constraints::world_inverse_inertia;
    use crate::{BodyDesc, BodyHandle, Shape, World};

    /// The world's current poses and velocities as bytes (read from the device where they
    /// stayed there), for bitwise comparisons.
    fn state_bytes(world: &World) -> (Vec<u8>, Vec<u8>) {
        let (poses, velocities) = world.current_bodies().unwrap();
        (
            bytemuck::cast_slice(poses).to_vec(),
            bytemuck::cast_slice(velocities).to_vec(),
        )
    }

    /// One GPU test of this module at a time, as in tests/engine/gpu_common.rs: wgpu's GL
    /// backend locks its context around every call and panics after a second, which a long
    /// dispatch on llvmpipe in a parallel test thread exceeds (seen on a machine with no
    /// Vulkan driver: seven of these tests failed so).
    pub(super) fn turn() -> std::sync::MutexGuard<'static, ()> {
        static TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());
        TURN.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The batching stage dispatches rounds up to the first the last batching started with few
    /// enough constraints left for one workgroup to list, and a few more: whatever it
    /// dispatched, the colors are the CPU's, and it finds the same first round.
    #[test]
    fn batching_rounds_follow_what_the_last_batching_needed() {
        let _turn = turn();
        let mut gpu = GpuStages::new(
            GpuContext::shared()
                .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}")),
        )
        .unwrap();
        let mut profiler = Profiler::default();
        // A chain of bodies, ranked by index (all "ordered"): each round batches one link.
        let links = 12u32;
        let chain = || (0..links).map(|i| (i, i + 1));
        // 6000 constraints on 2000 bodies, more than one workgroup lists.
        let mut state = 0x5eedu64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32 % 2000
        };
        let graph: Vec<(u32, u32)> = (0..6000).map(|_| (next(), next())).collect();
        // (constraints, bodies, ordered, batcher)
        type Case = (Vec<(u32, u32)>, usize, usize, Batcher);
        let cases: [Case; 2] = [
            (
                chain().collect(),
                links as usize + 1,
                links as usize,
                Batcher::Rounds,
            ),
            (graph, 2000, 0, Batcher::Colors),
        ];
        for (constraints, bodies, ordered, batcher) in cases {
            let mut cpu = Coloring::default();
            let iter = || constraints.iter().copied();
            crate::stages::batching::color_constraints(iter(), bodies, ordered, batcher, &mut cpu);
            let mut color = |gpu: &mut GpuStages, first_rounds| {
                gpu.batching_rounds = first_rounds;
                let mut colored = Coloring::default();
                gpu.color_constraints(
                    &mut profiler,
                    iter(),
                    bodies,
                    ordered,
                    batcher,
                    &mut colored,
                )
                .unwrap();
                assert_eq!(colored.colors, cpu.colors, "from {first_rounds} rounds");
                assert_eq!(colored.rounds, cpu.rounds, "from {first_rounds} rounds");
                (gpu.batching_rounds, gpu.batching.listable_from())
            };
            // Every round dispatched: the first listable round is known.
            let (planned, listable) = color(&mut gpu, MAX_ROUNDS);
            let first = listable.expect("a round started with few enough left");
            assert_eq!(planned, first.min(cpu.rounds) + BATCHING_ROUND_SLACK);
            // From the plan, the same plan again.
            assert_eq!(color(&mut gpu, planned), (planned, listable));
            if constraints.len() <= 1024 {
                assert_eq!(first, 0, "a chain of {links} is listable from the start");
            } else {
                assert!(
                    first > 0 && first < cpu.rounds,
                    "{first} of {} rounds",
                    cpu.rounds
                );
                // One round dispatched, the others left to one workgroup going over every
                // constraint (too many to list): its rounds find the same first one.
                assert_eq!(color(&mut gpu, 1), (planned, listable));
            }
        }
    }

    /// An awake world (the tests compare every step's contacts and motion) with a ground plane.
    fn awake_world_on_a_plane() -> World {
        let mut world = World::new(StepConfig {
            sleeping: false,
            ..StepConfig::default()
        })
        .unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        world
    }

    /// Body `index` of a block four wide and four deep, layers of 16 a little apart, each
    /// turned a little more than the last.
    /// [`awake_world_on_a_plane`] with every stage on `context`'s GPU.
    fn awake_gpu_world_on_a_plane(context: &GpuContext) -> World {
        let mut world = awake_world_on_a_plane();
        world.set_gpu_context(context.clone()).unwrap();
        world
            .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
            .unwrap();
        world
    }

    /// `count` bodies of [`block_member`], every fourth a ball, the others boxes.
    fn add_block(world: &mut World, count: usize) {
        for index in 0..count {
            let shape = if index % 4 == 0 {
                Shape::sphere(0.5)
            } else {
                Shape::cuboid(Vec3::splat(0.5))
            };
            world.add_body(block_member(index, shape)).unwrap();
        }
    }

    fn block_member(index: usize, shape: Shape) -> BodyDesc {
        let (x, y, z) = (index % 4, index / 16, (index / 4) % 4);
        BodyDesc::dynamic(shape)
            .position(Vec3::new(x as f32, 0.5 + 1.1 * y as f32, z as f32 * 1.02))
            .rotation(Quat::from_rotation_y(0.3 * index as f32))
    }

    /// The rows read from the GPU narrowphase's output are the rows read from the host's copy
    /// of it, bit for bit: the shortcut skips a copy, it changes nothing.
    #[test]
    fn rows_from_the_narrowphase_output_equal_rows_from_the_host() {
        let _turn = turn();
        let mut gpu = GpuStages::new(
            GpuContext::shared()
                .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}")),
        )
        .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_world_on_a_plane();
        for level in 0..6 {
            let turn = Quat::from_rotation_y(0.4 * level as f32);
            world
                .add_body(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                        .position(Vec3::new(0.1 * level as f32, 0.5 + level as f32, 0.0))
                        .rotation(turn),
                )
                .unwrap();
        }
        for _ in 0..40 {
            world.step();
        }
        world.sync_bodies().unwrap();
        let config = *world.config();
        let mut profiler = Profiler::new("test");
        let keys = world.pairs.keys().to_vec();
        let mut contacts = world.pairs.values().to_vec();
        let inputs = NarrowphaseInputs {
            poses: &world.poses,
            velocities: &world.velocities,
            colliders: &world.colliders,
            margin: config.contact_margin,
            dt: config.dt,
            skipped: &world.jointed_pairs,
            keep_resting: None,
        };
        let bodies = BodyInputs {
            poses: &world.poses,
            velocities: &world.velocities,
            masses: &world.masses,
            colliders: &world.colliders,
            version: world.bodies_version,
            changed: &world.body_changes,
        };
        gpu.begin_step();
        gpu.update_contacts(&mut profiler, &keys, &mut contacts, &inputs, &bodies)
            .unwrap();
        assert!(
            gpu.narrowphase_output_is_pair_cache(),
            "every pair is a GPU pair here"
        );
        assert!(contacts.iter().any(|c| c.manifold.count > 0), "no contact");
        let mut inertia = Vec::new();
        world_inverse_inertia(&world.poses, &world.masses, &mut inertia);
        let row_inputs = RowInputs {
            poses: &world.poses,
            velocities: &world.velocities,
            masses: &world.masses,
            colliders: &world.colliders,
            inverse_inertia: &inertia,
            softness: Softness::new(30.0, 10.0, 1.0 / 480.0),
            static_softness: Softness::new(60.0, 10.0, 1.0 / 480.0),
        };
        let (mut from_device, mut from_host) = (Vec::new(), Vec::new());
        let no_joints = JointRowInputs {
            joints: &[],
            slots: &[],
            drag: None,
            softness: row_inputs.softness,
        };
        gpu.build_constraints(
            &mut profiler,
            RowSlots::Narrowphase,
            &row_inputs,
            (world.bodies_version, &world.body_changes),
            &no_joints,
            RowsTo::Host(&mut from_device, &mut Vec::new()),
        )
        .unwrap();
        let slots = RowSlots::Host {
            keys: &keys,
            contacts: &contacts,
        };
        gpu.build_constraints(
            &mut profiler,
            slots,
            &row_inputs,
            (world.bodies_version, &world.body_changes),
            &no_joints,
            RowsTo::Host(&mut from_host, &mut Vec::new()),
        )
        .unwrap();
        assert!(!from_host.is_empty());
        let bytes = |rows: &[ContactConstraint]| bytemuck::cast_slice::<_, u8>(rows).to_vec();
        assert_eq!(bytes(&from_device), bytes(&from_host));
    }

    /// With every stage on the GPU the pair cache stays on the device from step to step: the
    /// solver writes its impulses into the narrowphase's contacts there, and the next
    /// collision reads them instead of an upload. The run is bitwise the run that uploads the
    /// host's cache every step (a change to the host's cache, here a write through
    /// `values_mut` after each step, sends it up again).
    #[test]
    fn the_pair_cache_kept_on_the_device_steps_as_the_uploaded_one() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let steps = 40;
        let run = |upload_every_step: bool| {
            let mut world = awake_gpu_world_on_a_plane(&context);
            for index in 0..40 {
                let shape = if index % 3 == 0 {
                    Shape::sphere(0.5)
                } else {
                    Shape::cuboid(Vec3::splat(0.5))
                };
                world.add_body(block_member(index, shape)).unwrap();
            }
            for _ in 0..steps {
                world.step();
                if upload_every_step {
                    world.sync_contacts().unwrap();
                    world.pairs.values_mut();
                }
            }
            world.sync_contacts().unwrap();
            let report = world.profiler().report();
            let uploads = report
                .root
                .children
                .iter()
                .filter(|line| line.name == "collision")
                .flat_map(|line| &line.children)
                .filter(|line| line.name == "copy pairs to gpu")
                .map(|line| line.calls_per_frame * report.frames as f64)
                .sum::<f64>()
                .round() as usize;
            let poses = state_bytes(&world).0;
            let impulses: Vec<f32> = world
                .pairs
                .values()
                .iter()
                .flat_map(|c| c.impulses.iter().map(|i| i.normal))
                .collect();
            (poses, impulses, uploads)
        };
        let (kept, kept_impulses, kept_uploads) = run(false);
        let (uploaded, uploaded_impulses, uploads) = run(true);
        assert_eq!(uploads, steps);
        // The first step has no cache on the device yet.
        assert_eq!(kept_uploads, 1);
        assert!(kept_impulses.iter().any(|&impulse| impulse > 0.0));
        assert_eq!(kept_impulses, uploaded_impulses);
        assert_eq!(kept, uploaded);
    }

    /// With every stage on the GPU the bodies stay on the device from step to step: after each
    /// step the device holds the host's bodies at the world's version, so the next step
    /// uploads none. The host's changes between steps (a velocity set, a body added, one
    /// removed) reach the device, and the run is bitwise the one that uploads the bodies
    /// every step. (Debug builds also check, at every skipped upload, that the host's bodies
    /// are the ones the device holds.)
    #[test]
    fn bodies_kept_on_the_device_step_as_bodies_uploaded() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let steps = 40;
        let run = |upload_every_step: bool| {
            let mut world = awake_gpu_world_on_a_plane(&context);
            let blocks: Vec<_> = (0..24)
                .map(|index| {
                    let body = block_member(index, Shape::cuboid(Vec3::splat(0.5)));
                    world.add_body(body).unwrap()
                })
                .collect();
            let mut kept = 0;
            for step in 0..steps {
                match step {
                    10 => world
                        .set_velocity(blocks[5], Vec3::new(0.0, 3.0, 1.0), Vec3::X)
                        .unwrap(),
                    20 => {
                        let ball = BodyDesc::dynamic(Shape::sphere(0.4))
                            .position(Vec3::new(1.5, 6.0, 1.5));
                        world.add_body(ball).unwrap();
                    }
                    30 => world.remove_body(blocks[0]).unwrap(),
                    _ => {}
                }
                world.step();
                let gpu = world.gpu.as_ref().unwrap();
                kept += usize::from(gpu.bodies.synced == Some(world.bodies_version));
                if upload_every_step {
                    world.sync_bodies().unwrap();
                    world.bodies_changed();
                }
            }
            let (poses, velocities) = state_bytes(&world);
            (poses, velocities, kept)
        };
        let (kept_poses, kept_velocities, kept) = run(false);
        let (uploaded_poses, uploaded_velocities, _) = run(true);
        assert_eq!(kept, steps);
        assert!(
            kept_velocities == uploaded_velocities,
            "the velocities differ"
        );
        assert!(kept_poses == uploaded_poses, "the poses differ");
    }

    /// With every stage on the GPU the integrated bodies stay on the device, and the getters
    /// read them there: the run, and what the getters return between steps, are bitwise the
    /// one that reads the bodies back every step. Between steps the host sets a velocity
    /// (read before and after),
    /// adds and removes bodies, drags one (its row is built on the host: the bodies come back
    /// for those steps), runs the solver on the CPU for a step, and dumps the world; boxes
    /// fall asleep and a ball wakes them.
    #[test]
    fn bodies_left_on_the_device_step_as_bodies_read_back() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let steps = 160;
        let run = |may_stay: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            let gpu_stages = crate::pipeline::devices::StageDevices::all(Executor::Gpu);
            world.set_stage_devices(gpu_stages).unwrap();
            world.bodies_may_stay_on_device = may_stay;
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            let blocks: Vec<_> = (0..12)
                .map(|index| {
                    let position =
                        Vec3::new(1.5 * (index % 6) as f32, 0.5, 2.0 * (index / 6) as f32);
                    let block =
                        BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position);
                    world.add_body(block).unwrap()
                })
                .collect();
            let (mut seen, mut on_device) = (Vec::new(), 0);
            for step in 0..steps {
                match step {
                    10 => {
                        // Read before the change, so that a read kept from the step must
                        // take it.
                        let before = world.linear_velocity(blocks[3]).unwrap();
                        world
                            .set_velocity(blocks[3], Vec3::new(0.0, 2.0, 0.5), Vec3::Y)
                            .unwrap();
                        let after = world.linear_velocity(blocks[3]).unwrap();
                        seen.push((Transform::IDENTITY, before, after, 0));
                    }
                    20..25 => world
                        .set_drag_target(blocks[7], Vec3::ZERO, Vec3::new(4.5, 2.0, 2.0), 200.0)
                        .unwrap(),
                    25 => world.clear_drag(),
                    40 => {
                        let mut devices = gpu_stages;
                        devices.set(crate::pipeline::devices::Stage::Solver, Executor::Cpu);
                        world.set_stage_devices(devices).unwrap();
                    }
                    41 => world.set_stage_devices(gpu_stages).unwrap(),
                    60 => world.remove_body(blocks[0]).unwrap(),
                    110 => {
                        let ball = BodyDesc::dynamic(Shape::sphere(0.3))
                            .position(Vec3::new(4.5, 3.0, 0.0));
                        world.add_body(ball).unwrap();
                    }
                    _ => {}
                }
                world.step();
                on_device += usize::from(world.bodies_on_device());
                // What a caller sees between steps.
                let body = blocks[5];
                seen.push((
                    world.pose(body).unwrap(),
                    world.linear_velocity(body).unwrap(),
                    world.angular_velocity(body).unwrap(),
                    world.stats().sleeping,
                ));
                if step % 40 == 30 {
                    seen.push((
                        Transform::IDENTITY,
                        Vec3::splat(world.kinetic_energy() as f32),
                        Vec3::ZERO,
                        crate::scene::Scene::from_world(&world).to_json().len(),
                    ));
                }
            }
            let gpu = world.gpu.as_ref().unwrap();
            let (reads, next) = (gpu.solves_reading_bodies, gpu.next_solves_submitted);
            world.sync_bodies().unwrap();
            let poses = bytemuck::cast_slice::<_, u8>(&world.poses).to_vec();
            let velocities = bytemuck::cast_slice::<_, u8>(&world.velocities).to_vec();
            (poses, velocities, seen, on_device, reads, next)
        };
        let (poses, velocities, seen, on_device, reads, next) = run(true);
        let back = run(false);
        // The bodies stayed but where the drag or the CPU solver needed them, and while a
        // removed body's slot was free (the one-submission collision needs every slot live).
        assert!(on_device >= steps - 60, "{on_device} of {steps} steps");
        assert!(
            reads <= steps - on_device,
            "{reads} solves read the bodies back"
        );
        // The getters' reads between steps keep the solves recorded a step ahead.
        assert!(
            next > steps / 2,
            "{next} solves recorded a step ahead submitted"
        );
        // Every GPU solve of the other run read them (one step solved on the CPU).
        assert_eq!((back.3, back.4), (0, steps - 1));
        let sleeping = seen.iter().map(|s| s.3);
        assert!(sleeping.clone().any(|n| n >= 11), "the boxes never slept");
        assert!(seen == back.2, "what the getters returned differs");
        assert!(velocities == back.1, "the velocities differ");
        assert!(poses == back.0, "the poses differ");
    }

    /// A full upload of the host's bodies over the device's newer ones is refused with a typed
    /// error, never made: here a test marks every body changed while the bodies are on the
    /// device, which the world's own changes never do. The failed step moved nothing and
    /// brings the device's bodies over, and the next steps go on from them.
    #[test]
    fn a_full_upload_over_the_devices_newer_bodies_is_refused() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_gpu_world_on_a_plane(&context);
        add_block(&mut world, 8);
        for _ in 0..10 {
            world.step();
        }
        assert!(world.bodies_on_device());
        let state = |world: &World| {
            let (poses, velocities) = world.current_bodies().unwrap();
            let mut bytes = bytemuck::cast_slice::<_, u8>(poses).to_vec();
            bytes.extend_from_slice(bytemuck::cast_slice(velocities));
            bytes
        };
        let before = state(&world);
        world.bodies_changed();
        let failed = world.try_step();
        assert!(matches!(failed, Err(GpuError::StaleBodies)), "{failed:?}");
        assert!(
            !world.bodies_on_device(),
            "the failed step brought them over"
        );
        assert!(state(&world) == before, "the failed step moved the bodies");
        for _ in 0..10 {
            world.try_step().unwrap();
        }
        assert!(state(&world) != before, "the bodies stopped");
    }

    /// Islands that fall asleep or wake change only their bodies' masses and velocities: the
    /// next step writes only theirs to the device, and the run is bitwise the one that uploads
    /// every body. Six boxes rest apart on a plane and fall asleep one island each; a ball
    /// dropped on one of them wakes its island, which falls asleep again.
    #[test]
    fn bodies_that_sleep_or_wake_reach_the_device_alone() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let run = |upload_every_step: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            for index in 0..6 {
                let position = Vec3::new(3.0 * index as f32, 0.5, 0.0);
                let block = BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position);
                world.add_body(block).unwrap();
            }
            let mut asleep = Vec::new();
            for step in 0..200 {
                if step == 50 {
                    let ball =
                        BodyDesc::dynamic(Shape::sphere(0.3)).position(Vec3::new(0.0, 3.0, 0.0));
                    world.add_body(ball).unwrap();
                }
                world.step();
                asleep.push(world.stats().sleeping);
                if upload_every_step {
                    world.sync_bodies().unwrap();
                    world.bodies_changed();
                }
            }
            let (poses, velocities) = state_bytes(&world);
            let partial = world.gpu.as_ref().unwrap().bodies.partial_uploads;
            (poses, velocities, asleep, partial)
        };
        let (poses, velocities, asleep, partial) = run(false);
        let uploaded = run(true);
        // Asleep, woken by the ball, asleep again with it.
        let woke = asleep.windows(2).any(|w| w[1] < w[0]);
        assert!(woke && asleep.last() == Some(&7), "{asleep:?}");
        // (A wake within a step reaches the rows' upload alone in both runs.)
        assert!(
            partial >= uploaded.3 + 2,
            "{partial} against {}",
            uploaded.3
        );
        assert_eq!(asleep, uploaded.2);
        assert!(velocities == uploaded.1, "the velocities differ");
        assert!(poses == uploaded.0, "the poses differ");
    }

    /// The wake test's candidates listed on the device are the host pass's, in pair order, on
    /// random sorted keys padded past their count as the broadphase's are, random point counts
    /// and random sleeping bodies, at 0, 1, about 250 and about 10 000 pairs; and the device
    /// finds that one wakes an island at once exactly where the host's first round does (a
    /// body that moves touches a sleeping one), with bodies that move and with none. The
    /// read-back stages last call's count and 256 more, so the large case takes the second
    /// copy.
    #[test]
    fn wake_candidates_on_the_device_are_the_hosts() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut wake = GpuWakeCandidates::new(&context).unwrap();
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move |bound: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % bound
        };
        let mut sizes_seen = Vec::new();
        let mut wakes_seen = Vec::new();
        let cases = [
            (0, 10, true),
            (1, 3, true),
            (260, 60, true),
            (10_000, 3_000, true),
            (2_000, 500, false),
        ];
        for (version, (pairs, bodies, movers)) in cases.into_iter().enumerate() {
            let mut keys: Vec<u64> = (0..pairs)
                .map(|_| {
                    let (a, b) = (next(bodies), next(bodies));
                    (a.min(b) << 32) | a.max(b)
                })
                .collect();
            keys.sort_unstable();
            keys.dedup();
            let count = keys.len();
            let summaries: Vec<PairSummary> = (0..count)
                .map(|_| PairSummary {
                    point_count: next(2) as u32 * (1 + next(4) as u32),
                    depth: 0.0,
                })
                .collect();
            let mut bits = vec![0u32; (bodies as usize).div_ceil(32)];
            for body in 0..bodies as usize {
                if next(10) < 3 {
                    bits[body / 32] |= 1 << (body % 32);
                }
            }
            let asleep = |body: u32| bits[body as usize / 32] & (1 << (body % 32)) != 0;
            // Sleeping bodies have no mass; of the others, some are static.
            let masses: Vec<BodyMass> = (0..bodies as u32)
                .map(|body| BodyMass {
                    inverse_mass: if asleep(body) || !movers || next(10) < 3 {
                        0.0
                    } else {
                        1.0
                    },
                    ..BodyMass::default()
                })
                .collect();
            let slots = count + count / 3 + 5;
            let mut padded = keys.clone();
            padded.resize(slots, u64::MAX);
            let mut padded_summaries = summaries.clone();
            padded_summaries.resize(slots, PairSummary::default());
            let count_buffer = GpuVec::from_slice(&context, "count", &[count as u32]).unwrap();
            let keys_buffer = GpuVec::from_slice(&context, "keys", &padded).unwrap();
            let summaries_buffer =
                GpuVec::from_slice(&context, "summaries", &padded_summaries).unwrap();
            let masses_buffer = GpuVec::from_slice(&context, "masses", &masses).unwrap();
            wake.set_asleep(&context, (&bits, version as u64)).unwrap();
            let mut encoder = context.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                wake.encode(
                    &context,
                    &mut pass,
                    &count_buffer,
                    &keys_buffer,
                    &summaries_buffer,
                    &masses_buffer,
                    slots,
                )
                .unwrap();
            }
            let staged = wake.encode_download(&context, &mut encoder);
            context.queue.submit([encoder.finish()]);
            let total = wake.total().read(&context).unwrap()[0] as usize;
            let mut listed = Vec::new();
            wake.read(&context, (staged, total), &mut listed).unwrap();
            let device: Vec<(u32, u32)> = listed
                .iter()
                .map(|&key| crate::stages::pairs::pair_bodies(key))
                .collect();
            let touching = |pair: usize| summaries[pair].point_count > 0;
            let (mut parts, mut host) = (Default::default(), Vec::new());
            crate::dynamics::wake::wake_candidates(&keys, touching, asleep, &mut parts, &mut host);
            assert_eq!(device, host, "{count} pairs");
            sizes_seen.push((host.len(), staged));
            let moves = |body: u32| masses[body as usize].inverse_mass > 0.0;
            let wakes = host
                .iter()
                .any(|&(a, b)| moves(a) && asleep(b) || moves(b) && asleep(a));
            let device_wakes = wake.wakers().read(&context).unwrap()[0] != 0;
            assert_eq!(device_wakes, wakes, "{count} pairs: an island wakes");
            wakes_seen.push(wakes);
        }
        assert!(wakes_seen.contains(&true) && wakes_seen.contains(&false));
        // Some candidates past what was staged: the second copy brought them.
        assert!(
            sizes_seen.iter().any(|&(listed, staged)| listed > staged),
            "{sizes_seen:?}"
        );
    }

    /// The islands' links made on the device give each body the root the host's union-find
    /// gives it (its island's lowest body), on random pairs at 0, 1, about 250 and 10 000
    /// pairs with random point counts and static or sleeping bodies, on a long chain linked
    /// from its far end, and on bodies with no pair at all; the keys padded past the count.
    #[test]
    fn island_links_on_the_device_are_the_hosts() {
        use crate::dynamics::body::BodyMass;
        use crate::dynamics::island::Islands;
        use crate::dynamics::island_gpu::{GpuIslandLinks, GpuLinkPairs};
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut links = GpuIslandLinks::new(&context).unwrap();
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move |bound: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % bound
        };
        let chain: Vec<(u64, u64)> = (0..4000u64).rev().map(|i| (i, i + 1)).collect();
        let mut random = |pairs: usize, bodies: u64| -> Vec<(u64, u64)> {
            (0..pairs)
                .map(|_| (next(bodies), next(bodies)))
                .filter(|(a, b)| a != b)
                .collect()
        };
        let cases = [
            (random(0, 10), 10),
            (random(1, 3), 3),
            (random(260, 200), 200),
            (random(10_000, 6_000), 6_000),
            (chain, 4001),
            (Vec::new(), 0),
        ];
        let mut largest = 0;
        for (edges, bodies) in cases {
            let mut keys: Vec<u64> = (edges.iter())
                .map(|&(a, b)| (a.min(b) << 32) | a.max(b))
                .collect();
            keys.sort_unstable();
            keys.dedup();
            let count = keys.len();
            let summaries: Vec<PairSummary> = (0..count)
                .map(|_| PairSummary {
                    point_count: (next(4) as u32).min(2),
                    depth: 0.0,
                })
                .collect();
            // One body in five static or asleep: it joins nothing.
            let masses: Vec<BodyMass> = (0..bodies)
                .map(|_| BodyMass {
                    inverse_mass: if next(5) == 0 { 0.0 } else { 0.5 },
                    ..Default::default()
                })
                .collect();
            let slots = count + count / 3 + 5;
            let mut padded = keys.clone();
            padded.resize(slots, u64::MAX);
            let mut padded_summaries = summaries.clone();
            padded_summaries.resize(slots, PairSummary::default());
            let count_buffer = GpuVec::from_slice(&context, "count", &[count as u32]).unwrap();
            let pairs = GpuLinkPairs {
                count: &count_buffer,
                keys: &GpuVec::from_slice(&context, "keys", &padded).unwrap(),
                summaries: &GpuVec::from_slice(&context, "summaries", &padded_summaries).unwrap(),
                slots,
            };
            let masses_buffer = GpuVec::from_slice(&context, "masses", &masses).unwrap();
            let mut encoder = context.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                links
                    .encode(&context, &mut pass, &pairs, &masses_buffer)
                    .unwrap();
            }
            context.queue.submit([encoder.finish()]);
            let mut device = Vec::new();
            links.read(&context, &mut device).unwrap();
            let mut islands = Islands::default();
            islands.resize(bodies as usize);
            let edges: Vec<(u32, u32)> = (keys.iter().zip(&summaries))
                .filter(|(_, summary)| summary.point_count > 0)
                .map(|(&key, _)| crate::stages::pairs::pair_bodies(key))
                .collect();
            islands.unlink_all();
            islands.link(&edges, &masses);
            assert_eq!(device, islands.roots(), "{count} pairs, {bodies} bodies");
            // The oracle links too: the largest island's size.
            let mut sizes = vec![0; bodies as usize];
            for &root in &device {
                sizes[root as usize] += 1;
            }
            largest = largest.max(sizes.into_iter().max().unwrap_or(0));
        }
        assert!(largest > 1000, "the largest island has {largest} bodies");
    }

    /// The rest kernels give each body the host's timer bit for bit
    /// ([`Islands::update_timers`]), the largest rest time and the rested count, and count at
    /// least as many sleepers as [`Islands::fall_asleep`] puts to sleep, 0 exactly where it
    /// puts none; a step that did not hold moves nothing. Random bodies at 0, 1, 257, 600 and
    /// 20 000: most one in five static or asleep, speeds about the threshold, rest times about
    /// the time to sleep, random islands.
    #[test]
    fn rest_timers_and_the_sleep_test_on_the_device_are_the_hosts() {
        use crate::dynamics::body::{BodyMass, BodyVelocity};
        use crate::dynamics::island::{Islands, SLEEP_SPEED, TIME_TO_SLEEP};
        use crate::dynamics::rest_gpu::{GpuRestTimers, RestInputs};
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut rest = GpuRestTimers::new(&context).unwrap();
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let dt = 1.0 / 60.0;
        let (mut slept_some, mut held_all) = (false, false);
        // Bodies, the share that moves, how far below the time to sleep timers start (in
        // steps), the islands' blocks and the share of static (or sleeping) bodies: the 257
        // rest long enough for most islands to sleep, the 600 are one island held awake. The
        // last case is a step that did not hold.
        let cases = [
            (0usize, 0.1, 4.0, 30, 0.2),
            (1, 0.1, 4.0, 30, 0.2),
            (257, 0.01, 0.5, 30, 0.2),
            (600, 0.1, 4.0, 600, 0.0),
            (20_000, 0.1, 4.0, 30, 0.2),
            (20_000, 0.1, 4.0, 30, 0.2),
        ];
        for (case, (bodies, moving, below, block, statics)) in cases.into_iter().enumerate() {
            let held = case != 5;
            let masses: Vec<BodyMass> = (0..bodies)
                .map(|_| BodyMass {
                    inverse_mass: if next() < statics { 0.0 } else { 0.5 },
                    ..Default::default()
                })
                .collect();
            // Most bodies rest; a few move, some about the threshold but not within a
            // thousandth of it, where a GPU's square root or fused multiply-add may round to
            // the other side.
            // (linear, angular) speeds. Resting bodies' fastest points stay below 0.042 m/s
            // (radii up to 1.1 m); those about the threshold turn not at all, and are not
            // within a thousandth of it, where a GPU's square root or fused multiply-add may
            // round to the other side; moving ones are at least twice as fast.
            let speeds = |next: &mut dyn FnMut() -> f32| match next() {
                x if x < 1.0 - moving => (next() * 0.02, next() * 0.02),
                x if x < 1.0 - moving / 2.0 => {
                    let off = 0.001 + 0.099 * next();
                    let factor = if next() < 0.5 { 1.0 - off } else { 1.0 + off };
                    (SLEEP_SPEED * factor, 0.0)
                }
                _ => (SLEEP_SPEED * (2.0 + 40.0 * next()), next() * 2.0),
            };
            let direction = |next: &mut dyn FnMut() -> f32| {
                Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::X)
            };
            let velocities: Vec<BodyVelocity> = (0..bodies)
                .map(|_| {
                    let (linear, angular) = speeds(&mut next);
                    let linear = direction(&mut next) * linear;
                    BodyVelocity::new(linear, direction(&mut next) * angular)
                })
                .collect();
            let radii: Vec<f32> = (0..bodies).map(|_| 0.1 + next()).collect();
            let timers: Vec<f32> = (0..bodies)
                .map(|_| (TIME_TO_SLEEP - below * dt) + next() * 8.0 * dt)
                .collect();
            // Islands within blocks of bodies, by random edges, and a chain through each block.
            let random_edges = (0..bodies * 2).map(|_| {
                let a = (next() * bodies as f32) as u32 % bodies.max(1) as u32;
                let b = (a / block * block + (next() * block as f32) as u32) % bodies.max(1) as u32;
                (a, b)
            });
            let chains = (1..bodies as u32)
                .filter(|&b| b % block != 0)
                .map(|b| (b - 1, b));
            let edges: Vec<(u32, u32)> = random_edges.chain(chains).collect();
            let mut islands = Islands::default();
            islands.resize(bodies);
            for (body, &timer) in timers.iter().enumerate() {
                islands.set_timer(body as u32, timer);
            }
            islands.unlink_all();
            islands.link(&edges, &masses);
            let roots = islands.roots();
            let rested = if held {
                islands.update_timers(&velocities, &masses, |i| radii[i], dt);
                (0..bodies)
                    .filter(|&i| {
                        masses[i].inverse_mass > 0.0
                            && islands.state(i as u32).timer >= TIME_TO_SLEEP
                    })
                    .count() as u32
            } else {
                0
            };
            let expected: Vec<f32> = islands.timers();
            let max_timer = (0..bodies)
                .filter(|&i| held && masses[i].inverse_mass > 0.0)
                .map(|i| expected[i])
                .fold(0.0f32, f32::max);
            let mut velocities_left = velocities.clone();
            let mut masses_left = masses.clone();
            let mut asleep = Vec::new();
            if held {
                islands.fall_asleep(&mut masses_left, &mut velocities_left, None, &mut asleep);
            }

            let solver_bodies: Vec<SolverBody> = (0..bodies)
                .map(|i| SolverBody {
                    linear_velocity: velocities[i].linear,
                    inverse_mass: masses[i].inverse_mass,
                    angular_velocity: velocities[i].angular,
                    ..SolverBody::STATIC
                })
                .collect();
            let colliders: Vec<ColliderData> = radii
                .iter()
                .map(|&bounding_radius| ColliderData {
                    bounding_radius,
                    ..bytemuck::Zeroable::zeroed()
                })
                .collect();
            let held_word = GpuVec::from_slice(&context, "held", &[u32::from(held)]).unwrap();
            let solver_bodies = GpuVec::from_slice(&context, "bodies", &solver_bodies).unwrap();
            let colliders = GpuVec::from_slice(&context, "colliders", &colliders).unwrap();
            let roots = GpuVec::from_slice(&context, "roots", &roots).unwrap();
            rest.upload(&context, &timers).unwrap();
            let inputs = RestInputs {
                held: &held_word,
                bodies: &solver_bodies,
                colliders: &colliders,
                roots: Some(&roots),
            };
            let mut encoder = context.device.create_command_encoder(&Default::default());
            rest.encode_clear(&mut encoder);
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                rest.encode(&context, &mut pass, &inputs, dt);
            }
            rest.encode_download(&context, &mut encoder);
            context.queue.submit([encoder.finish()]);
            let tally = rest.read_tally(&context, true).unwrap();
            let device = rest.read(&context).unwrap();
            let case = format!("{bodies} bodies, held {held}");
            let differing = (0..bodies).filter(|&i| device[i].to_bits() != expected[i].to_bits());
            assert_eq!(differing.count(), 0, "timers differ: {case}");
            assert_eq!(tally.max_timer.to_bits(), max_timer.to_bits(), "{case}");
            assert_eq!(tally.rested, rested, "{case}");
            let sleepers = tally.sleepers.unwrap();
            assert!(
                sleepers as usize >= asleep.len(),
                "{case}: {sleepers}, {asleep:?}"
            );
            assert_eq!(sleepers == 0, asleep.is_empty(), "{case}: {sleepers}");
            slept_some |= !asleep.is_empty();
            held_all |= held && rested > 0 && asleep.is_empty();
        }
        // Both outcomes were tried: islands put to sleep, and rested bodies all held awake.
        assert!(slept_some && held_all);
    }

    /// Bouncing rows counted with the collision on the device plan the restitution sweep:
    /// balls of restitution 0.8 dropped 2 m onto the plane beside a resting box, with every
    /// stage on the GPU and the batches laid out there, come back up above 1 m (without the
    /// sweep they would not leave the plane). In debug builds the step also checks the
    /// device's counts against the host's pass every step.
    #[test]
    fn bouncing_rows_counted_on_the_device_bounce() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_gpu_world_on_a_plane(&context);
        let boxed = BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::Y * 0.5);
        world.add_body(boxed).unwrap();
        let balls: Vec<BodyHandle> = (0..3)
            .map(|i| {
                let ball = BodyDesc::dynamic(Shape::sphere(0.25))
                    .position(Vec3::new(2.0 + i as f32, 2.25, 0.0))
                    .restitution(0.8);
                world.add_body(ball).unwrap()
            })
            .collect();
        let mut landed = false;
        let mut apex: f32 = 0.0;
        for _ in 0..90 {
            world.step();
            let height = world.pose(balls[0]).unwrap().position.y - 0.25;
            landed |= height < 0.05;
            if landed {
                apex = apex.max(height);
            }
        }
        assert!(world.gpu.as_ref().unwrap().device_layouts > 0);
        assert!(landed && apex > 1.0, "landed {landed}, rose to {apex} m");
    }

    /// The rows' tally on the device is the host's passes: on random sorted keys padded past
    /// their count, random point counts and depths (−0 among them), bodies static or not,
    /// bouncing or not, and random lookups into last step's pairs, at 0, 1, about 250 and
    /// about 10 000 pairs: the touching pairs, the rows (`has_constraint`), the bouncing rows,
    /// their points, the deepest penetration and the pairs kept, and the wake count copied in.
    #[test]
    fn the_rows_tally_on_the_device_is_the_hosts() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut tally = GpuRowTally::new(&context).unwrap();
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move |bound: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % bound
        };
        for (pairs, bodies) in [(0, 10), (1, 3), (260, 60), (10_000, 3_000)] {
            let mut keys: Vec<u64> = (0..pairs)
                .map(|_| {
                    let a = next(bodies) as u32;
                    crate::stages::pairs::pair_key(a, a + 1 + next(4) as u32)
                })
                .collect();
            keys.sort_unstable();
            keys.dedup();
            let count = keys.len();
            let summaries: Vec<PairSummary> = (0..count)
                .map(|_| match next(3) {
                    0 => PairSummary::default(),
                    1 => PairSummary {
                        point_count: 1 + next(4) as u32,
                        depth: -0.0,
                    },
                    _ => PairSummary {
                        point_count: 1 + next(4) as u32,
                        depth: next(1000) as f32 * 1e-4,
                    },
                })
                .collect();
            let masses: Vec<BodyMass> = (0..bodies + 5)
                .map(|_| BodyMass {
                    inverse_inertia: Vec3::ONE,
                    inverse_mass: if next(3) == 0 { 0.0 } else { 1.0 },
                })
                .collect();
            let colliders: Vec<ColliderData> = (0..bodies + 5)
                .map(|_| ColliderData {
                    restitution: if next(8) == 0 { 0.5 } else { 0.0 },
                    ..bytemuck::Zeroable::zeroed()
                })
                .collect();
            let old_index: Vec<u32> = (0..count)
                .map(|i| if next(4) == 0 { u32::MAX } else { i as u32 })
                .collect();
            let slots = count + count / 3 + 5;
            fn padded<T: Copy>(values: &[T], slots: usize, pad: T) -> Vec<T> {
                let mut padded = values.to_vec();
                padded.resize(slots, pad);
                padded
            }
            let keys_buffer = padded(&keys, slots, u64::MAX);
            let summaries_buffer = padded(&summaries, slots, PairSummary::default());
            let old_index_buffer = padded(&old_index, slots, u32::MAX);
            let count_buffer = GpuVec::from_slice(&context, "count", &[count as u32]).unwrap();
            let keys_buffer = GpuVec::from_slice(&context, "keys", &keys_buffer).unwrap();
            let summaries_buffer =
                GpuVec::from_slice(&context, "summaries", &summaries_buffer).unwrap();
            let old_index_buffer =
                GpuVec::from_slice(&context, "old index", &old_index_buffer).unwrap();
            let masses_buffer = GpuVec::from_slice(&context, "masses", &masses).unwrap();
            let colliders_buffer = GpuVec::from_slice(&context, "colliders", &colliders).unwrap();
            let wake_total = GpuVec::from_slice(&context, "wake total", &[count as u32 / 2]);
            let wake_total = wake_total.unwrap();
            let mut encoder = context.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                let pairs = (&keys_buffer, &summaries_buffer, &old_index_buffer);
                let bodies = (&masses_buffer, &colliders_buffer);
                tally
                    .encode(&context, &mut pass, &count_buffer, pairs, bodies, slots)
                    .unwrap();
            }
            // The narrowphase's list of computed pairs, its count first, comes back with them.
            let computed = GpuVec::from_slice(&context, "computed", &[count as u32 / 3, 7, 7]);
            let computed = computed.unwrap();
            tally.encode_download(&context, &mut encoder, Some(&wake_total), &computed);
            context.queue.submit([encoder.finish()]);
            let device = tally.read(&context).unwrap();
            assert_eq!(tally.computed(), count / 3, "{count} pairs");

            let touching: Vec<usize> = (0..count)
                .filter(|&i| summaries[i].point_count > 0)
                .collect();
            let rows: Vec<usize> = (touching.iter().copied())
                .filter(|&i| {
                    let point_count = summaries[i].point_count;
                    crate::stages::constraints::has_constraint(keys[i], point_count, &masses)
                })
                .collect();
            let bounces = |i: usize| {
                let (a, b) = crate::stages::pairs::pair_bodies(keys[i]);
                colliders[a as usize]
                    .restitution
                    .max(colliders[b as usize].restitution)
                    > 0.0
            };
            let host = PairTally {
                touching: touching.len(),
                rows: rows.len(),
                bouncing: rows.iter().filter(|&&i| bounces(i)).count(),
                contacts: rows
                    .iter()
                    .map(|&i| summaries[i].point_count as usize)
                    .sum(),
                deepest: summaries.iter().map(|s| s.depth).fold(0.0f32, f32::max) + 0.0,
                kept: old_index.iter().filter(|&&i| i != u32::MAX).count(),
                wake_candidates: count / 2,
            };
            assert_eq!(device, host, "{count} pairs");
            assert_eq!(
                device.deepest.to_bits(),
                host.deepest.to_bits(),
                "{count} pairs"
            );
        }
    }

    /// While bodies sleep, the collision lists the wake test's candidates on the device: the
    /// run is bitwise the one whose host walks every pair (and whose steps are not submitted
    /// with their collisions while bodies sleep). Towers of two boxes stand apart on
    /// a plane and fall asleep an island each (so the lists hold pairs of two sleeping bodies
    /// and of a sleeping body and the plane); a ball dropped on one wakes its island through
    /// the list, and the towers beside it sleep on.
    #[test]
    fn the_wake_test_on_the_device_wakes_as_the_hosts() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let run = |host_wake_candidates: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            world.gpu.as_mut().unwrap().host_wake_candidates = host_wake_candidates;
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            for index in 0..4 {
                for level in 0..2 {
                    let position = Vec3::new(3.0 * index as f32, 0.5 + level as f32, 0.0);
                    let block =
                        BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position);
                    world.add_body(block).unwrap();
                }
            }
            let (mut asleep, mut listed) = (Vec::new(), Vec::new());
            let mut towers = Vec::new();
            for step in 0..300 {
                match step {
                    0 => towers = (1..9).map(|index| world.handle_of(index)).collect(),
                    60 => {
                        let ball = BodyDesc::dynamic(Shape::sphere(0.3))
                            .position(Vec3::new(0.0, 3.5, 0.0));
                        world.add_body(ball).unwrap();
                    }
                    // A free slot: the steps after run the stages one by one, which list the
                    // candidates on the host, while three towers sleep; a ball wakes one.
                    200 => world.remove_body(towers[7]).unwrap(),
                    220 => {
                        let ball = BodyDesc::dynamic(Shape::sphere(0.3))
                            .position(Vec3::new(3.0, 3.5, 0.0));
                        world.add_body(ball).unwrap();
                    }
                    _ => {}
                }
                world.step();
                asleep.push(world.stats().sleeping);
                let scratch = &world.scratch;
                listed.push(scratch.wake_listed.then_some(scratch.wake_pair_keys.len()));
            }
            let (poses, velocities) = state_bytes(&world);
            let gpu = world.gpu.as_ref().unwrap();
            let steps_listed = gpu.wake_candidates_listed;
            let held = [gpu.steps_held, gpu.steps_not_held];
            (poses, velocities, asleep, listed, steps_listed, held)
        };
        let (poses, velocities, asleep, listed, steps_listed, held) = run(false);
        let host = run(true);
        // The steps submitted with their collision held while towers slept, but for those
        // where a ball woke one (the device's wake test said so).
        let [held, not_held] = held;
        assert!(held > 60 && not_held > 0, "{held} held, {not_held} not");
        // All asleep, the hit tower woken by the ball, all asleep again with it; the second
        // ball wakes its tower, whose free slot it took, after the removal.
        let woke = asleep[..200].windows(2).any(|w| w[1] < w[0]);
        assert!(woke && asleep[199] == 9, "{asleep:?}");
        assert!(asleep[225..].windows(2).any(|w| w[1] < w[0]), "{asleep:?}");
        // The steps with bodies asleep listed their candidates on the device, but for those
        // with a free slot: 4 towers asleep, 2 touching pairs each (box on box, box on plane);
        // 3 of them while the hit one is awake; with the ball, 9.
        assert_eq!(steps_listed, listed.iter().flatten().count());
        assert!(listed[200..220].iter().all(Option::is_none));
        for step in 1..listed.len() {
            // The wake test sees the bodies that the step before put to sleep.
            let free_slot = (200..220).contains(&step);
            let expected = asleep[step - 1] > 0 && !free_slot;
            assert_eq!(listed[step].is_some(), expected, "step {step}");
        }
        for count in [8, 6, 9] {
            assert!(listed.contains(&Some(count)), "{listed:?}");
        }
        assert_eq!((host.3.iter().flatten().count(), host.4), (0, 0));
        assert_eq!(asleep, host.2);
        assert!(velocities == host.1, "the velocities differ");
        assert!(poses == host.0, "the poses differ");
    }

    /// Where the batched solve integrates the bodies, it moves their rest timers and tests for
    /// an island to put to sleep on the device: the run is bitwise the one whose host moves
    /// them from the velocities it reads back. Towers of two boxes fall asleep; one is pushed
    /// while the timers are on the device (the host sets its timer), a ball added later wakes
    /// another (a body the device has no timer for; woken bodies keep their rest times), and
    /// the dumps made between steps read the device's timers.
    #[test]
    fn rest_timers_on_the_device_sleep_as_the_hosts() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let run = |host_rest_timers: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            world.gpu.as_mut().unwrap().host_rest_timers = host_rest_timers;
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            let mut blocks = Vec::new();
            for index in 0..4 {
                for level in 0..2 {
                    let position = Vec3::new(3.0 * index as f32, 0.5 + level as f32, 0.0);
                    let block =
                        BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position);
                    blocks.push(world.add_body(block).unwrap());
                }
            }
            let (mut asleep, mut dumps) = (Vec::new(), Vec::new());
            for step in 0..200 {
                if step == 20 {
                    // Resting, not yet asleep: its timer starts again on the host.
                    let (linear, angular) = (Vec3::new(0.0, 0.0, 0.3), Vec3::ZERO);
                    world.set_velocity(blocks[1], linear, angular).unwrap();
                }
                if step == 110 {
                    let ball = BodyDesc::dynamic(Shape::sphere(0.25))
                        .position(Vec3::new(6.0, 3.0, 0.0))
                        .linear_velocity(Vec3::new(0.0, -2.0, 0.0));
                    world.add_body(ball).unwrap();
                }
                if step % 50 == 25 {
                    dumps.push(crate::scene::Scene::from_world(&world).to_json());
                }
                world.step();
                asleep.push(world.stats().sleeping);
            }
            let (poses, velocities) = state_bytes(&world);
            let reads = world.gpu.as_ref().unwrap().rest_timer_reads;
            (poses, velocities, asleep, dumps, reads)
        };
        let (poses, velocities, asleep, dumps, reads) = run(false);
        let host = run(true);
        // Every tower fell asleep, the ball woke one, and it slept again with the ball.
        assert_eq!(asleep[100], 8, "{asleep:?}");
        assert!(asleep[110..].contains(&6), "{asleep:?}");
        assert_eq!(asleep.last(), Some(&9), "{asleep:?}");
        // The device's timers came to the host where an island fell asleep and where the host
        // set some, not every step.
        assert!((1..20).contains(&reads), "{reads} reads of the timers");
        assert_eq!(host.4, 0);
        assert_eq!(asleep, host.2);
        assert!(dumps == host.3, "the dumps differ");
        assert!(velocities == host.1, "the velocities differ");
        assert!(poses == host.0, "the poses differ");
    }

    /// Where the contacts stay on the device, the rows' submission links the islands there:
    /// the run is bitwise the one whose host links them. A light ball rolls across a heavy
    /// table, which rests under it but stays awake with it (the links make them one island),
    /// while towers of two boxes apart sleep an island each.
    #[test]
    fn the_islands_linked_on_the_device_sleep_as_the_hosts() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let run = |host_island_links: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            world.gpu.as_mut().unwrap().host_island_links = host_island_links;
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            let table = BodyDesc::dynamic(Shape::cuboid(Vec3::new(3.0, 0.25, 3.0)))
                .position(Vec3::new(0.0, 0.25, 0.0));
            let table = world.add_body(table).unwrap();
            let (radius, speed) = (0.3, 1.5);
            let ball = BodyDesc::dynamic(Shape::sphere(radius))
                .position(Vec3::new(-2.7, 0.5 + radius, 0.0))
                .linear_velocity(Vec3::new(speed, 0.0, 0.0))
                .angular_velocity(Vec3::new(0.0, 0.0, -speed / radius));
            world.add_body(ball).unwrap();
            for index in 0..3 {
                for level in 0..2 {
                    let position = Vec3::new(3.0 * index as f32, 0.5 + level as f32, 6.0);
                    let block =
                        BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(position);
                    world.add_body(block).unwrap();
                }
            }
            let (mut asleep, mut table_asleep) = (Vec::new(), Vec::new());
            for _ in 0..150 {
                world.step();
                asleep.push(world.stats().sleeping);
                table_asleep.push(world.is_sleeping(table).unwrap());
            }
            let rested = world.sleep_state(table.index()).timer;
            assert!(
                rested >= crate::dynamics::island::TIME_TO_SLEEP,
                "the table rested {rested} s"
            );
            let (poses, velocities) = state_bytes(&world);
            let gpu = world.gpu.as_ref().unwrap();
            // No joints, the PGS solver: the pairs' summaries stay on the device, unless the
            // host links the islands, which reads them.
            let (left, fetched) = (gpu.summaries_left, gpu.summaries_fetched);
            if host_island_links {
                assert!(fetched > 100, "{fetched} steps read the summaries back");
            } else {
                assert!(
                    left > 140 && fetched == 0,
                    "{left} left, {fetched} read back"
                );
            }
            (
                poses,
                velocities,
                asleep,
                table_asleep,
                gpu.island_links_made,
            )
        };
        let (poses, velocities, asleep, table_asleep, made) = run(false);
        let host = run(true);
        // The towers sleep; the table stays awake under the rolling ball.
        assert_eq!(asleep.last(), Some(&6), "{asleep:?}");
        assert!(table_asleep.iter().all(|&asleep| !asleep));
        // From the first step whose bodies may have rested, every step linked on the device.
        assert!(made > 100, "{made} steps linked on the device");
        assert_eq!(host.4, 0);
        assert_eq!(asleep, host.2);
        assert!(velocities == host.1, "the velocities differ");
        assert!(poses == host.0, "the poses differ");
    }

    /// A world of boxes and balls with every stage on the GPU, `steps` steps, with the contacts
    /// left on the device between steps or not, the pair buffers starting too small: (poses,
    /// the contact queries' answer, the step statistics' deepest penetration, the steps that
    /// left them there, bodies asleep, each step's pairs with those added and removed, its
    /// manifolds and its contact points).
    #[allow(clippy::type_complexity)]
    fn steps_on_the_gpu(
        contacts_may_stay_on_device: bool,
        sleeping: bool,
        steps: usize,
    ) -> (Vec<u8>, Vec<u8>, f32, usize, usize, Vec<[usize; 5]>) {
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = World::new(StepConfig {
            sleeping,
            ..StepConfig::default()
        })
        .unwrap();
        world.contacts_may_stay_on_device = contacts_may_stay_on_device;
        world.set_gpu_context(context.clone()).unwrap();
        world
            .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
            .unwrap();
        // Room for 4 pairs: the pair buffers grow, and the collision runs again, as the pile
        // forms.
        let gpu = world.gpu.as_mut().unwrap();
        gpu.broadphase.set_capacity(&context, 4).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        add_block(&mut world, 24);
        // A chain of three capsules on point joints falls onto the block: joint rows, and
        // jointed pairs the narrowphase skips.
        let link =
            |x: f32| BodyDesc::dynamic(Shape::capsule(0.3, 0.2)).position(Vec3::new(x, 6.0, 1.5));
        let links: Vec<_> = (0..3)
            .map(|i| world.add_body(link(i as f32)).unwrap())
            .collect();
        for pair in links.windows(2) {
            let anchor = Vec3::new(0.5 + world.pose(pair[0]).unwrap().position.x, 6.0, 1.5);
            let joint = crate::JointDesc::new(crate::JointKind::Point, pair[0], pair[1], anchor);
            world.add_joint(joint).unwrap();
        }
        let (mut left_on_device, mut pairs) = (0, Vec::new());
        for _ in 0..steps {
            world.step();
            left_on_device += usize::from(world.contacts_on_device);
            let stats = world.stats();
            let counts = [stats.pairs, stats.pairs_added, stats.pairs_removed];
            pairs.push([
                counts[0],
                counts[1],
                counts[2],
                stats.manifolds,
                stats.contacts,
            ]);
        }
        let contacts: Vec<PairContact> = world.contacts().map(|(_, _, c)| *c).collect();
        (
            state_bytes(&world).0,
            bytemuck::cast_slice::<_, u8>(&contacts).to_vec(),
            world.stats().max_penetration,
            left_on_device,
            world.stats().sleeping,
            pairs,
        )
    }

    /// The bodies of `add_bodies` on a plane with every stage on the GPU, sleeping, `steps`
    /// steps, the batches laid out on the host or (where it can) on the device, the warm start
    /// by body there or not: (poses, the contact batches, each step's batch histogram, bodies
    /// asleep, steps laid out on the device).
    fn pile_on_the_gpu(
        (host_layout, by_body): (bool, bool),
        steps: usize,
        add_bodies: impl Fn(&mut World),
    ) -> (Vec<u8>, Vec<u32>, Vec<u32>, usize, usize) {
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = World::new(StepConfig::default()).unwrap();
        world.set_gpu_context(context).unwrap();
        world
            .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
            .unwrap();
        let gpu = world.gpu.as_mut().unwrap();
        (gpu.host_layout, gpu.warm_start_by_body) = (host_layout, by_body);
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        add_bodies(&mut world);
        let mut histograms = Vec::new();
        for _ in 0..steps {
            world.step();
            histograms.extend_from_slice(&world.stats().batch_histogram);
            histograms.push(u32::MAX);
        }
        let batches = world.contact_batches().map(|(_, _, batch)| batch).collect();
        let gpu = world.gpu.as_ref().unwrap();
        (
            state_bytes(&world).0,
            batches,
            histograms,
            world.stats().sleeping,
            gpu.device_layouts,
        )
    }

    /// Where the step needs no host layout of the batches, the device lays them out and the
    /// solver reads its sizes there: bitwise the run laid out on the host (both warm-starting
    /// batch by batch), poses, each step's batch histogram, the contacts' batches, sleep.
    #[test]
    fn batches_laid_out_on_the_device_step_as_on_the_host() {
        let _turn = turn();
        let block = |world: &mut World| {
            add_block(world, 48);
        };
        let device = pile_on_the_gpu((false, false), 120, block);
        let host = pile_on_the_gpu((true, false), 120, block);
        assert_eq!(host.4, 0);
        // The first step brings the contacts to the device; every later one lays out there
        // until the pile sleeps.
        assert!(device.4 > 60, "{} steps laid out on the device", device.4);
        assert!(
            device.3 > 0 && device.3 == host.3,
            "asleep: {} {}",
            device.3,
            host.3
        );
        assert_eq!(device.2, host.2, "the batch histograms");
        assert_eq!(device.1, host.1, "the contacts' batches");
        assert!(device.0 == host.0, "the poses differ");
    }

    /// 48 boxes and balls falling onto a plane with every stage on the GPU, the pair buffers
    /// starting too small and a bouncing ball added at step 40, each step's solve and batching
    /// recorded during its collision's wait or not, its rows, batching and solve submitted
    /// with its collision or not: (the poses and velocities, the steps that submitted a solve
    /// and a batching recorded ahead, those laid out on the device, the steps submitted with
    /// their collision that held and that did not).
    fn block_with_solves_ahead(
        (ahead, speculates): (bool, bool),
        steps: usize,
    ) -> (Vec<u8>, [usize; 2], usize, [usize; 3]) {
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = World::new(StepConfig::default()).unwrap();
        world.set_gpu_context(context.clone()).unwrap();
        world
            .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
            .unwrap();
        let gpu = world.gpu.as_mut().unwrap();
        (gpu.encodes_ahead, gpu.speculates, gpu.row_margin) = (ahead, speculates, 0);
        gpu.broadphase.set_capacity(&context, 4).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        add_block(&mut world, 48);
        for step in 0..steps {
            if step == 40 {
                // Bouncing: its steps' solves have a restitution sweep, the others' not. It
                // lands before the block sleeps.
                let ball = BodyDesc::dynamic(Shape::sphere(0.5))
                    .position(Vec3::new(0.2, 5.0, 0.3))
                    .linear_velocity(Vec3::new(0.0, -8.0, 0.0))
                    .restitution(0.8);
                world.add_body(ball).unwrap();
            }
            world.step();
        }
        let (poses, velocities) = state_bytes(&world);
        let state = [poses, velocities].concat();
        let gpu = world.gpu.as_ref().unwrap();
        let ahead = [gpu.solves_encoded_ahead, gpu.batchings_encoded_ahead];
        let held = [
            gpu.steps_held,
            gpu.steps_not_held,
            gpu.next_solves_submitted,
        ];
        (state, ahead, gpu.device_layouts, held)
    }

    /// A solve and a batching recorded during the collision's wait, from last step's plans,
    /// step bitwise as those recorded after it, through the pairs' buffers growing, the rows'
    /// growing as the pile forms and a bouncing body added; and most steps of a settling pile
    /// submit them.
    #[test]
    fn a_solve_recorded_during_the_collision_steps_as_one_recorded_after() {
        let _turn = turn();
        let ahead = block_with_solves_ahead((true, false), 120);
        let after = block_with_solves_ahead((false, false), 120);
        assert_eq!(after.1, [0, 0]);
        for (recorded, what) in ahead.1.into_iter().zip(["solve", "batching"]) {
            assert!(
                recorded > ahead.2 / 2 && recorded < ahead.2,
                "{recorded} of {} steps laid out on the device submitted a {what} recorded ahead",
                ahead.2
            );
        }
        assert!(ahead.0 == after.0, "the poses or velocities differ");
    }

    /// A step whose rows, batching and solve were submitted with its collision, on a guess of
    /// its counts, steps bitwise as one that records them after the collision's wait, through
    /// the guesses failing (the pairs' buffers and the rows' growing, the bounce of a ball
    /// added); and most steps before the pile sleeps hold.
    #[test]
    fn a_step_submitted_with_its_collision_steps_as_one_submitted_after() {
        let _turn = turn();
        let with = block_with_solves_ahead((true, true), 120);
        let after = block_with_solves_ahead((false, false), 120);
        assert_eq!(after.3, [0, 0, 0]);
        let [held, not_held, recorded] = with.3;
        assert!(
            held > with.2 / 2 && not_held > 0,
            "{held} of {} steps laid out on the device held, {not_held} did not",
            with.2
        );
        // Most of them submitted a solve recorded during the last step's wait.
        assert!(
            recorded > held / 2,
            "{recorded} of {held} submitted a solve recorded a step ahead"
        );
        assert!(with.0 == after.0, "the poses or velocities differ");
    }

    /// Steps submitted with their collisions step as those that are not while the world
    /// changes between steps: the solver and the batching moved to the CPU and back, the
    /// sub-steps and gravity changed, a body added, a velocity set. The plans and the solve recorded a step
    /// ahead must follow each change.
    #[test]
    fn steps_submitted_with_their_collisions_follow_the_worlds_changes() {
        use crate::pipeline::devices::{Stage, StageDevices};
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let run = |speculates: bool| {
            let mut world = World::new(StepConfig::default()).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(StageDevices::all(Executor::Gpu))
                .unwrap();
            world.gpu.as_mut().unwrap().speculates = speculates;
            world
                .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
                .unwrap();
            add_block(&mut world, 32);
            for step in 0..90 {
                match step {
                    20 => {
                        let mut devices = StageDevices::all(Executor::Gpu);
                        devices.set(Stage::Batching, Executor::Cpu);
                        devices.set(Stage::Solver, Executor::Cpu);
                        world.set_stage_devices(devices).unwrap();
                    }
                    30 => world
                        .set_stage_devices(StageDevices::all(Executor::Gpu))
                        .unwrap(),
                    45 | 50 => {
                        // The sub-steps change the rows' softness too, gravity the solve alone.
                        let config = *world.config();
                        let config = if step == 45 {
                            StepConfig {
                                substeps: 4,
                                ..config
                            }
                        } else {
                            StepConfig {
                                gravity: Vec3::new(0.5, -12.0, 0.0),
                                ..config
                            }
                        };
                        world.set_config(config).unwrap();
                    }
                    60 => {
                        let ball = BodyDesc::dynamic(Shape::sphere(0.5))
                            .position(Vec3::new(0.3, 6.0, 0.2));
                        world.add_body(ball).unwrap();
                    }
                    70 => {
                        let body = world.handle_of(5);
                        world
                            .set_velocity(body, Vec3::new(0.0, 3.0, 0.0), Vec3::ZERO)
                            .unwrap();
                    }
                    _ => {}
                }
                world.step();
            }
            let (poses, velocities) = state_bytes(&world);
            let state = [poses, velocities].concat();
            let gpu = world.gpu.as_ref().unwrap();
            (state, gpu.steps_held, gpu.next_solves_submitted)
        };
        let with = run(true);
        let without = run(false);
        assert_eq!((without.1, without.2), (0, 0));
        assert!(
            with.1 > 40 && with.2 > 30,
            "{} held, {} recorded ahead",
            with.1,
            with.2
        );
        assert!(with.0 == without.0, "the poses or velocities differ");
    }

    /// 81 balls on one dynamic slab: more constraints on the slab than there are colors.
    fn balls_on_a_slab(world: &mut World) {
        let slab = BodyDesc::dynamic(Shape::cuboid(Vec3::new(5.0, 0.25, 5.0)))
            .position(Vec3::new(0.0, 0.25, 0.0));
        world.add_body(slab).unwrap();
        for i in 0..81 {
            let (x, z) = ((i % 9) as f32 - 4.0, (i / 9) as f32 - 4.0);
            let ball = BodyDesc::dynamic(Shape::sphere(0.4)).position(Vec3::new(x, 0.9, z));
            world.add_body(ball).unwrap();
        }
    }

    /// The same with an overflow batch: 81 balls on one dynamic slab give it more constraints
    /// than there are colors, so the batches the device lays out, and the warm start gathered
    /// by body, hold overflow constraints sharing the slab.
    #[test]
    fn overflow_batches_laid_out_on_the_device_step_as_on_the_host() {
        let _turn = turn();
        let device = pile_on_the_gpu((false, false), 40, balls_on_a_slab);
        let host = pile_on_the_gpu((true, false), 40, balls_on_a_slab);
        assert!(device.4 > 30, "{} steps laid out on the device", device.4);
        // The slab's 81 ball contacts overflow its 64 colors.
        let overflowing = host.2.split(|&h| h == u32::MAX).filter(|h| h.len() == 65);
        assert!(overflowing.count() > 30, "histograms {:?}", &host.2[..80]);
        assert_eq!(device.2, host.2, "the batch histograms");
        assert_eq!(device.1, host.1, "the contacts' batches");
        assert!(device.0 == host.0, "the poses differ");
    }

    /// The warm start gathered by body gives the batch sweeps' velocities up to rounding (the
    /// same operations on each body in the same order; lavapipe rounds them alike, NVIDIA's
    /// compiler fuses them differently): over 4 steps of the overflowing slab and of the
    /// block, the poses stay within 10 µm and 20 µrad. The horizon is short because rounding
    /// differences grow in a pile: on the H200 the slab's balls were 18 µm apart after 10
    /// steps. (A gather that gave a body the other side's impulses moved them by metres, one
    /// that ranked the slab's overflow constraints wrongly by 1.4 mm in 4 steps.)
    #[test]
    fn the_warm_start_by_body_follows_the_batch_sweeps() {
        let _turn = turn();
        let block = |world: &mut World| {
            for index in 0..48 {
                world
                    .add_body(block_member(index, Shape::cuboid(Vec3::splat(0.5))))
                    .unwrap();
            }
        };
        let scenes: [&dyn Fn(&mut World); 2] = [&block, &balls_on_a_slab];
        for (scene, add_bodies) in scenes.into_iter().enumerate() {
            let by_body = pile_on_the_gpu((false, true), 4, add_bodies);
            let sweeps = pile_on_the_gpu((false, false), 4, add_bodies);
            assert!(by_body.4 >= 3, "{} steps laid out on the device", by_body.4);
            let poses = |bytes: &[u8]| bytemuck::cast_slice::<_, BodyPose>(bytes).to_vec();
            for (i, (a, b)) in poses(&by_body.0).iter().zip(&poses(&sweeps.0)).enumerate() {
                let moved = (a.position - b.position).length();
                // Twice the sine of half the turn between them, in radians for small turns.
                let turned = 2.0 * (a.rotation.inverse() * b.rotation).xyz().length();
                assert!(
                    moved < 1e-5 && turned < 2e-5,
                    "scene {scene}, body {i}: {moved} m, {turned} rad"
                );
            }
        }
    }

    /// With every stage on the GPU and only pairs it computes, the contacts stay on the device
    /// (only their point counts and depths come back), and the run is bitwise the one that
    /// brings every contact back each step: poses, the contact queries' answer (read back when
    /// asked) and the statistics.
    #[test]
    fn contacts_left_on_the_device_step_as_contacts_brought_back() {
        let _turn = turn();
        let kept = steps_on_the_gpu(true, false, 30);
        let brought = steps_on_the_gpu(false, false, 30);
        assert_eq!((kept.3, brought.3), (30, 0));
        assert!(!kept.1.is_empty() && kept.2 > 0.0);
        assert_eq!(kept.2.to_bits(), brought.2.to_bits());
        assert!(kept.1 == brought.1, "the contacts differ");
        assert!(kept.0 == brought.0, "the poses differ");
        // The pairs added and removed as the device's diff counted them, and the contact
        // points as its tally did, the host's.
        assert_eq!(kept.5, brought.5);
    }

    /// The device leaves the point slots past a moved manifold's count as its buffer had them
    /// (`move.wgsl`); the contacts the host reads back have them zero, as the CPU keeps them.
    /// Here a box flies off the ground, so the pairs sorted after its ground pair each move
    /// down a slot, and the pair of two boxes an edge apart (two points, moved by its cache)
    /// lands where a box's four points on the ground were written before.
    #[test]
    fn unused_point_slots_come_back_zero() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_gpu_world_on_a_plane(&context);
        let cube = || BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)));
        let flying = cube()
            .position(Vec3::new(-3.0, 0.5, 0.0))
            .linear_velocity(Vec3::new(0.0, 4.0, 0.0));
        world.add_body(flying).unwrap();
        world
            .add_body(cube().position(Vec3::new(0.0, 0.5, 0.0)))
            .unwrap();
        // Turned a quarter about the vertical, 5 mm from the other box: its edge, two points.
        let edge = cube()
            .position(Vec3::new(0.505 + 0.5 * std::f32::consts::SQRT_2, 0.5, 0.0))
            .rotation(Quat::from_rotation_y(std::f32::consts::FRAC_PI_4));
        world.add_body(edge).unwrap();
        let (mut most_pairs, mut fewest_pairs) = (0, usize::MAX);
        let mut keys_left = 0;
        for _ in 0..30 {
            world.step();
            assert!(world.contacts_on_device);
            // No joint, nothing asleep: nothing on the host passes over the pairs, so the keys
            // stay on the device once the pairs change, and the queries read them there.
            keys_left += usize::from(!world.pairs.has_keys());
            most_pairs = most_pairs.max(world.pairs.len());
            fewest_pairs = fewest_pairs.min(world.pairs.len());
            for contact in world.pair_values() {
                let count = contact.manifold.count as usize;
                let zero_points = contact.manifold.points[count..]
                    .iter()
                    .all(|p| *p == Default::default());
                let zero_impulses = contact.impulses[count..]
                    .iter()
                    .all(|i| *i == Default::default());
                assert!(
                    zero_points && zero_impulses,
                    "unused point slots in {contact:?}"
                );
            }
        }
        // The flying box's ground pair went, the edge's pair stayed.
        assert_eq!((most_pairs, fewest_pairs), (4, 3));
        assert!(
            keys_left > 0 && !world.pairs.has_keys(),
            "{keys_left} steps"
        );
        let points: Vec<u32> = world.contacts().map(|(_, _, c)| c.manifold.count).collect();
        assert_eq!(points, [4, 4, 2]);
    }

    /// Keys left on the device come back where the host needs them: the contact queries read
    /// them, removing a body and switching the stages to the CPU fetch them, and the CPU's
    /// steps then go on from the same pairs, impulses included.
    #[test]
    fn keys_left_on_the_device_come_back_when_the_host_needs_them() {
        let _turn = turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_gpu_world_on_a_plane(&context);
        let cube = |x: f32| {
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(x, 1.5, 0.0))
        };
        let handles: Vec<_> = (0..4)
            .map(|i| world.add_body(cube(1.5 * i as f32)).unwrap())
            .collect();
        let mut steps = 0;
        while world.pairs.has_keys() {
            world.step();
            steps += 1;
            assert!(steps < 60, "the keys never stayed on the device");
        }
        let queried: Vec<_> = world.contacts().map(|(a, b, c)| (a, b, *c)).collect();
        assert_eq!(queried.len(), 4, "each cube on the plane");
        world.remove_body(handles[3]).unwrap();
        assert!(world.pairs.has_keys(), "the removal read the pairs");
        world
            .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Cpu))
            .unwrap();
        // The removed body's pair (the last by key) goes at the next step, its cache at once.
        let kept: Vec<_> = world.contacts().map(|(a, b, c)| (a, b, *c)).collect();
        assert_eq!((kept.len(), &kept[..3]), (4, &queried[..3]));
        assert_eq!(
            kept[3].2.cache,
            crate::stages::narrowphase::ManifoldCache::default()
        );
        for _ in 0..5 {
            world.step();
        }
        let after: Vec<_> = world.contacts().map(|(a, b, _)| (a, b)).collect();
        assert_eq!(after.len(), 3);
        assert!(
            after
                .iter()
                .all(|&(a, b)| a != handles[3] && b != handles[3])
        );
    }

    /// Bodies falling asleep keep the step on the one-submission path, their resting pairs
    /// going down with the bodies: the contacts stay on the device, and the run stays bitwise
    /// the one that brings them back every step.
    #[test]
    fn contacts_stay_on_the_device_while_bodies_sleep() {
        let _turn = turn();
        let kept = steps_on_the_gpu(true, true, 150);
        let brought = steps_on_the_gpu(false, true, 150);
        assert_eq!(kept.3, 150, "steps that left them there");
        assert!(kept.4 > 0 && kept.4 == brought.4, "asleep: {}", kept.4);
        assert!(kept.1 == brought.1, "the contacts differ");
        assert!(kept.0 == brought.0, "the poses differ");
        assert_eq!(kept.5, brought.5);
        let changed = |column: usize| kept.5.iter().filter(|step| step[column] > 0).count();
        assert!(changed(1) > 5 && changed(2) > 5, "{:?}", kept.5);
    }

    /// A collision that fails while the contacts are on the device (here the pairs outgrow the
    /// bindings of a device whose limit is lowered to 64 KiB, when the contact margin jumps)
    /// starts the pair cache afresh instead of from half-overwritten contacts: the step fails,
    /// and the steps after it run, with the contacts a world that never failed has.
    #[test]
    fn a_collision_that_fails_with_the_contacts_on_the_device_starts_the_pairs_afresh() {
        let _turn = turn();
        let small = GpuContext::with_limits(|limits| {
            limits.max_storage_buffer_binding_size = 64 << 10;
        })
        .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let config = StepConfig {
            sleeping: false,
            gravity: Vec3::ZERO,
            ..StepConfig::default()
        };
        let balls = |context: &GpuContext| {
            let mut world = World::new(config).unwrap();
            world.set_gpu_context(context.clone()).unwrap();
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            world
                .gpu
                .as_mut()
                .unwrap()
                .broadphase
                .set_capacity(context, 4)
                .unwrap();
            // Balls 2 m apart, still, and 8 more each touching two of them: 16 pairs at the
            // default margin, hundreds at 1.5 m.
            for index in 0..80 {
                let (x, y, z) = (index % 5, (index / 5) % 4, index / 20);
                let position = 2.0 * Vec3::new(x as f32, y as f32, z as f32);
                world
                    .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(position))
                    .unwrap();
            }
            for index in 0..8 {
                let position = Vec3::new(
                    1.0 + 2.0 * (index % 2) as f32,
                    2.0 * (index / 2) as f32,
                    0.0,
                );
                world
                    .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(position))
                    .unwrap();
            }
            world
        };
        let mut world = balls(&small);
        let mut reference = balls(&small);
        for _ in 0..3 {
            world.try_step().unwrap();
            reference.try_step().unwrap();
        }
        assert!(world.contacts_on_device);
        assert_eq!(world.contacts().count(), 16);
        let wide = StepConfig {
            contact_margin: 1.5,
            ..config
        };
        world.set_config(wide).unwrap();
        let error = world.try_step().unwrap_err();
        assert!(
            matches!(
                error,
                GpuError::BufferTooLarge {
                    what: "contacts",
                    ..
                }
            ),
            "{error}"
        );
        assert!(!world.contacts_on_device && world.pairs.is_empty());
        world.set_config(config).unwrap();
        for _ in 0..3 {
            world.try_step().unwrap();
            reference.try_step().unwrap();
        }
        assert!(world.contacts_on_device);
        let touching = |world: &World| -> Vec<(BodyHandle, BodyHandle, u32)> {
            world
                .contacts()
                .map(|(a, b, contact)| (a, b, contact.manifold.count))
                .collect()
        };
        assert_eq!(touching(&world), touching(&reference));
    }

    /// Rows kept on the device take a buffer sized by the manifolds with points, not by the
    /// pairs: on a device whose bindings hold 606 rows (and 1024 pairs' contacts), 80 still
    /// balls whose boxes overlap (610 pairs without points) and 8 balls that touch them step as
    /// on the default device.
    /// A row per pair would not fit (it did not for a settled pile of 500k boxes on an H200).
    #[test]
    fn rows_on_the_device_are_sized_by_the_manifolds_not_the_pairs() {
        const SMALL_BINDING: u64 = 256 << 10;
        let _turn = turn();
        let small = GpuContext::with_limits(|limits| {
            limits.max_storage_buffer_binding_size = SMALL_BINDING;
        })
        .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let config = StepConfig {
            sleeping: false,
            gravity: Vec3::ZERO,
            ..StepConfig::default()
        };
        let balls = |context: Option<&GpuContext>| {
            let mut world = World::new(config).unwrap();
            if let Some(context) = context {
                world.set_gpu_context(context.clone()).unwrap();
            }
            world
                .set_stage_devices(crate::pipeline::devices::StageDevices::all(Executor::Gpu))
                .unwrap();
            // 1.03 m apart: each ball's box (grown by the contact margin, 0.02 m) overlaps its
            // 26 neighbours', and the gaps are past the margin.
            for index in 0..80 {
                let (x, y, z) = (index % 5, (index / 5) % 4, index / 20);
                let position = 1.03 * Vec3::new(x as f32, y as f32, z as f32);
                world
                    .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(position))
                    .unwrap();
            }
            // Under half the bottom layer, 5 mm into it.
            for index in 0..8 {
                let position =
                    Vec3::new(1.03 * (index % 4) as f32, 1.03 * (index / 4) as f32, -0.995);
                world
                    .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(position))
                    .unwrap();
            }
            world
        };
        let mut world = balls(Some(&small));
        let mut reference = balls(None);
        for _ in 0..5 {
            world.try_step().unwrap();
            reference.try_step().unwrap();
        }
        assert!(world.contacts_on_device);
        let (pairs, rows) = (world.stats().pairs, world.stats().manifolds);
        // A constraint's bytes on the device, its impulse sums included.
        let row_bytes = crate::stages::constraints::lanes::WORDS * size_of::<Word>();
        let limit = SMALL_BINDING as usize;
        assert!(pairs * row_bytes > limit, "{pairs} pairs");
        assert!(rows > 0 && rows * row_bytes <= limit, "{rows}");
        assert_eq!(pairs, reference.stats().pairs);
        let poses = |world: &World| state_bytes(world).0;
        assert!(poses(&world) == poses(&reference), "the poses differ");
    }

    /// Stages 1 to 4 in one submission give the pairs and contacts that the stages one by one
    /// give, bit for bit, warm starts included (through the GPU pair diff rather than the
    /// host's cache), and lose no pair when the broadphase's buffers start too small.
    #[test]
    fn one_submission_collision_equals_the_stages_one_by_one() {
        let _turn = turn();
        one_submission_against_the_stages(false);
    }

    /// The same with the bottom layer of the pile held still, as sleeping bodies are: their
    /// pairs with the plane and each other are in no tree, and the one submission gets them
    /// on the device from last step's pairs, where the stages one by one merge the host's list
    /// of them.
    #[test]
    fn one_submission_collision_keeps_resting_pairs() {
        let _turn = turn();
        one_submission_against_the_stages(true);
    }

    fn one_submission_against_the_stages(bottom_asleep: bool) {
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = awake_world_on_a_plane();
        for index in 0..48 {
            let cube = Shape::cuboid(Vec3::splat(0.5));
            world.add_body(block_member(index, cube)).unwrap();
        }
        for _ in 0..30 {
            world.step();
        }
        // Last step's pair cache, with the solver's impulses; the bodies have moved since.
        let (old_keys, old_contacts) = (world.pairs.keys().to_vec(), world.pairs.values().to_vec());
        assert!(old_contacts.iter().any(|c| c.impulses[0].normal > 0.0));
        let config = *world.config();
        // Bodies 1 to 16 are the bottom layer (`block_member`).
        let held = |body: usize| bottom_asleep && (1..=16).contains(&body);
        let is_static: Vec<bool> = (world.masses.iter().enumerate())
            .map(|(body, m)| m.inverse_mass == 0.0 || held(body))
            .collect();
        let resting: Vec<u64> = (old_keys.iter().copied())
            .filter(|&key| {
                let (a, b) = crate::stages::pairs::pair_bodies(key);
                is_static[a as usize] && is_static[b as usize]
            })
            .collect();
        assert_eq!(
            resting.len() > 16,
            bottom_asleep,
            "{} resting pairs",
            resting.len()
        );
        let bodies = BodyInputs {
            poses: &world.poses,
            velocities: &world.velocities,
            masses: &world.masses,
            colliders: &world.colliders,
            version: world.bodies_version,
            changed: &world.body_changes,
        };
        let mut profiler = Profiler::new("test");

        let mut one = GpuStages::new(context.clone()).unwrap();
        one.broadphase.set_capacity(&context, 4).unwrap();
        one.begin_step();
        let (mut keys, mut contacts) = (Vec::new(), Vec::new());
        one.collide(
            &mut profiler,
            &bodies,
            &is_static,
            OldPairs {
                count: old_keys.len(),
                keys: Some(&old_keys),
                contacts: &old_contacts,
                version: world.pairs.version(),
            },
            &world.jointed_pairs,
            (config.contact_margin, config.dt),
            &mut keys,
            CollideOutput::Contacts(&mut contacts),
        )
        .unwrap();
        assert!(one.broadphase.capacity() >= keys.len() && keys.len() > 48);

        let mut stages = GpuStages::new(context).unwrap();
        stages.begin_step();
        stages
            .compute_aabbs(
                &mut profiler,
                &bodies,
                config.contact_margin,
                config.dt,
                None,
            )
            .unwrap();
        let mut stage_keys = Vec::new();
        stages
            .find_pairs(&mut profiler, None, &is_static, &mut stage_keys)
            .unwrap();
        assert!(
            resting
                .iter()
                .all(|key| stage_keys.binary_search(key).is_err())
        );
        super::super::step::merge_sorted(&mut stage_keys, &resting);
        let mut cache = world.pairs.clone();
        cache.update(&stage_keys);
        let inputs = NarrowphaseInputs {
            poses: &world.poses,
            velocities: &world.velocities,
            colliders: &world.colliders,
            margin: config.contact_margin,
            dt: config.dt,
            skipped: &world.jointed_pairs,
            keep_resting: None,
        };
        let (cache_keys, cache_contacts) = cache.keys_and_values_mut();
        stages
            .update_contacts(&mut profiler, cache_keys, cache_contacts, &inputs, &bodies)
            .unwrap();

        assert_eq!(keys, stage_keys);
        assert_ne!(keys, old_keys, "the pairs changed since last step");
        let bytes = |contacts: &[PairContact]| bytemuck::cast_slice::<_, u8>(contacts).to_vec();
        assert_eq!(bytes(&contacts), bytes(cache.values()));
        assert!(
            contacts.iter().any(|c| c.impulses[0].normal > 0.0),
            "warm started"
        );
    }
}
