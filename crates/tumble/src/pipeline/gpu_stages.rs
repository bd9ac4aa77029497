use std::time::Instant;

use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::profiler::{GpuProfiler, SpanPath, record_copy};
use crate::math::Aabb;
use crate::profile::{Profiler, SpanKind};
use crate::stages::aabb::gpu::GpuAabbs;
use crate::stages::batching::gpu::GpuBatching;
use crate::stages::batching::{Batcher, Coloring, MAX_ROUNDS};
use crate::stages::broadphase::gpu::GpuBroadphase;
use crate::stages::constraints::gpu::{GpuRowInputs, GpuRows};
use crate::stages::constraints::{ContactConstraint, JointConstraint, RowInputs};
use crate::stages::narrowphase::gpu::{GpuNarrowphase, GpuNarrowphaseInputs};
use crate::stages::narrowphase::{
    NarrowphaseInputs, PairContact, gpu_pair, pack_hulls, update_contacts_where,
};
use crate::stages::solver::batched::{BatchedImpulses, BatchedJointImpulses, GpuBatched};
use crate::stages::solver::gpu::{DeviceBatched, GpuSolver};
use crate::stages::solver::jacobi_gpu::GpuJacobi;
use crate::stages::solver::{Batched, SolverBody, SolverKind, SolverSettings};

/// Batching rounds a world encodes at first: falling-boxes at 3k bodies needs 24 to 31 (the
/// talk's batcher makes one batch a round), the colors batcher as many.
const FIRST_BATCHING_ROUNDS: usize = 32;

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
const BATCHING: StageSpans = StageSpans {
    upload: &["batching", "copy to gpu"],
    encode: &["batching", "encode"],
    kernel: &["batching", "kernels"],
    wait: &["batching", "submit and wait"],
    download: &["batching", "copy to cpu"],
};
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
const NARROWPHASE: StageSpans = StageSpans {
    upload: &["narrowphase", "copy to gpu"],
    encode: &["narrowphase", "encode"],
    kernel: &["narrowphase", "kernel"],
    wait: &["narrowphase", "submit and wait"],
    download: &["narrowphase", "copy to cpu"],
};

/// The manifold slots the GPU rows read: pairs, then children.
pub(crate) enum RowSlots<'a> {
    /// Uploaded from the host.
    Host {
        keys: &'a [u64],
        contacts: &'a [PairContact],
    },
    /// This step's GPU narrowphase output, already on the device: every slot is a pair and the
    /// narrowphase computed all of them ([`GpuStages::pair_contacts_on_device`]).
    Narrowphase,
}

/// A GPU step's poses where they are, on the device, for a renderer on the same device to draw
/// from without a readback. The integrator runs on the host, so no device buffer holds the
/// poses after the step; two buffers that the step leaves there give them: body slot `i`
/// ends the step at `start[i]` ([`BodyPose`], the pose the stages uploaded at the start of
/// the step) moved by `motion[i]` ([`SolverBody`]): position + delta_position, rotation
/// normalize(delta_rotation * rotation), unless inverse_mass is 0 (static or asleep: it stays),
/// as [`finalize_bodies`](crate::stages::integrate::finalize_bodies) computes on the host.
/// Valid until the world is stepped or changed.
#[derive(Clone, Copy, Debug)]
pub struct DevicePoses<'a> {
    pub start: &'a wgpu::Buffer,
    pub motion: &'a wgpu::Buffer,
    /// Body slots in both buffers.
    pub count: usize,
}

/// The step's body arrays, as the GPU stages read them.
pub(crate) struct BodyInputs<'a> {
    pub poses: &'a [BodyPose],
    pub velocities: &'a [BodyVelocity],
    pub colliders: &'a [Collider],
}

/// Device copies of the body arrays, shared by the GPU stages.
struct DeviceBodies {
    poses: GpuVec<BodyPose>,
    velocities: GpuVec<BodyVelocity>,
    colliders: GpuVec<ColliderData>,
    /// The colliders' hulls for the narrowphase ([`pack_hulls`]), uploaded with them.
    hulls: GpuVec<u32>,
    /// The host's colliders changed since the last upload.
    colliders_stale: bool,
    /// Poses and velocities were uploaded this step (they change only in the solver).
    uploaded_this_step: bool,
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
    /// The rows' inputs on the device: every manifold slot's key and contact, the masses.
    row_keys: GpuVec<u64>,
    row_contacts: GpuVec<PairContact>,
    masses: GpuVec<BodyMass>,
    batching: GpuBatching,
    /// Batching rounds encoded before the colors are first read back (grows when too few).
    batching_rounds: usize,
    solver: GpuSolver,
    /// Built at the first Jacobi step.
    jacobi: Option<GpuJacobi>,
    /// The batches kept on the device when rows, batching and solver all run here.
    batched: GpuBatched,
    /// The solver's bodies, constraints in batch order and batch offsets (contacts, then
    /// joints) on the device; [`Self::solve_batched`] uses the offsets and the bodies.
    solver_bodies: GpuVec<SolverBody>,
    batched_contacts: GpuVec<ContactConstraint>,
    batch_offsets: GpuVec<u32>,
    batched_joints: GpuVec<JointConstraint>,
    joint_batch_offsets: GpuVec<u32>,
    /// The narrowphase's inputs and output on the device.
    keys: GpuVec<u64>,
    old_index: GpuVec<u32>,
    old_contacts: GpuVec<PairContact>,
    contacts: GpuVec<PairContact>,
    skipped: GpuVec<u64>,
    /// The narrowphase ran on the GPU this step and computed every pair there: its output
    /// (`contacts`, keyed by `keys`) equals the host's pair cache, so the rows can read it.
    pair_contacts_fresh: bool,
    /// The solver ran on the GPU this step: `solver_bodies` holds the step's motion.
    solved_this_step: bool,
    /// Host scratch, reused: the identity map, the packed colliders, downloaded contacts.
    identity: Vec<u32>,
    collider_data: Vec<ColliderData>,
    downloaded: Vec<PairContact>,
    downloaded_bodies: Vec<SolverBody>,
    downloaded_constraints: Vec<ContactConstraint>,
    downloaded_joints: Vec<JointConstraint>,
    downloaded_joint_impulses: Vec<BatchedJointImpulses>,
}

impl GpuStages {
    /// The GPU side on `context`'s device.
    pub fn new(context: GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            profiler: GpuProfiler::new(&context, 8),
            bodies: DeviceBodies {
                poses: GpuVec::with_capacity(&context, "poses", 0)?,
                velocities: GpuVec::with_capacity(&context, "velocities", 0)?,
                colliders: GpuVec::with_capacity(&context, "colliders", 0)?,
                hulls: GpuVec::with_capacity(&context, "hulls", 0)?,
                colliders_stale: true,
                uploaded_this_step: false,
            },
            aabb: GpuAabbs::new(),
            aabbs: GpuVec::with_capacity(&context, "aabbs", 0)?,
            broadphase: GpuBroadphase::new(&context)?,
            narrowphase: GpuNarrowphase::new(&context),
            rows: GpuRows::new(&context)?,
            row_keys: GpuVec::with_capacity(&context, "row keys", 0)?,
            row_contacts: GpuVec::with_capacity(&context, "row contacts", 0)?,
            masses: GpuVec::with_capacity(&context, "masses", 0)?,
            batching: GpuBatching::new(&context)?,
            batching_rounds: FIRST_BATCHING_ROUNDS,
            solver: GpuSolver::new(&context)?,
            jacobi: None,
            batched: GpuBatched::new(&context)?,
            solver_bodies: GpuVec::with_capacity(&context, "solver bodies", 0)?,
            batched_contacts: GpuVec::with_capacity(&context, "batched contacts", 0)?,
            batch_offsets: GpuVec::with_capacity(&context, "batch offsets", 0)?,
            batched_joints: GpuVec::with_capacity(&context, "batched joints", 0)?,
            joint_batch_offsets: GpuVec::with_capacity(&context, "joint batch offsets", 0)?,
            keys: GpuVec::with_capacity(&context, "pair keys", 0)?,
            old_index: GpuVec::with_capacity(&context, "old pair index", 0)?,
            old_contacts: GpuVec::with_capacity(&context, "old contacts", 0)?,
            contacts: GpuVec::with_capacity(&context, "contacts", 0)?,
            skipped: GpuVec::with_capacity(&context, "jointed pairs", 0)?,
            pair_contacts_fresh: false,
            solved_this_step: false,
            identity: Vec::new(),
            collider_data: Vec::new(),
            downloaded: Vec::new(),
            downloaded_bodies: Vec::new(),
            downloaded_constraints: Vec::new(),
            downloaded_joints: Vec::new(),
            downloaded_joint_impulses: Vec::new(),
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

    /// A new step: the host's poses and velocities are newer than the device's.
    pub fn begin_step(&mut self) {
        self.bodies.uploaded_this_step = false;
        self.pair_contacts_fresh = false;
        self.solved_this_step = false;
    }

    /// This step's poses on the device, when a stage uploaded the poses this step and the
    /// solver ran here ([`DevicePoses`]).
    pub fn device_poses(&self) -> Option<DevicePoses<'_>> {
        (self.bodies.uploaded_this_step && self.solved_this_step).then(|| DevicePoses {
            start: self.bodies.poses.buffer(),
            motion: self.solver_bodies.buffer(),
            count: self.bodies.poses.len(),
        })
    }

    /// Whether this step's GPU narrowphase left every pair's contact on the device, so that
    /// [`RowSlots::Narrowphase`] can stand for the pair cache.
    pub fn pair_contacts_on_device(&self) -> bool {
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
        record_copy(profiler, BROADPHASE.upload, elapsed_ms(start));
        loop {
            let (broadphase, aabbs) = (&mut self.broadphase, &self.aabbs);
            run_pass(context, &mut self.profiler, profiler, &BROADPHASE, |pass| {
                broadphase.encode(context, pass, aabbs)
            })?;
            // Reads the pair count back: more pairs than room means grow and run again.
            if !self.broadphase.check_capacity(context)? {
                break;
            }
        }
        let start = Instant::now();
        self.broadphase.download_keys_into(context, keys)?;
        record_copy(profiler, BROADPHASE.download, elapsed_ms(start));
        Ok(())
    }

    /// Stage 4 on the GPU: [`update_contacts`](crate::stages::narrowphase::update_contacts)'s
    /// contract, the kernels of `stages/narrowphase/gpu.rs`.
    pub fn update_contacts(
        &mut self,
        profiler: &mut Profiler,
        keys: &[u64],
        contacts: &mut [PairContact],
        inputs: &NarrowphaseInputs,
    ) -> Result<(), GpuError> {
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
        let bodies = BodyInputs {
            poses: inputs.poses,
            velocities: inputs.velocities,
            colliders: inputs.colliders,
        };
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, &bodies)?;
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
        self.contacts.download_into(context, &mut self.downloaded)?;
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
            } else {
                host_pairs += 1;
            }
        }
        self.pair_contacts_fresh = host_pairs == 0;
        record_copy(profiler, NARROWPHASE.download, elapsed_ms(start));
        profiler.scope("cpu pairs", || {
            update_contacts_where(keys, contacts, inputs, |a, b| !gpu_pair(a, b))
        });
        Ok(())
    }
}

impl GpuStages {
    /// Stage 5 on the GPU for contacts:
    /// [`build_constraints`](crate::stages::constraints::build_constraints)'s contract over the
    /// manifold `slots`. With no `out` the constraints stay on the device for
    /// [`Self::solve_batched`].
    pub fn build_constraints(
        &mut self,
        profiler: &mut Profiler,
        slots: RowSlots,
        inputs: &RowInputs,
        out: Option<&mut Vec<ContactConstraint>>,
    ) -> Result<(), GpuError> {
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
        self.masses.upload(context, inputs.masses)?;
        let bodies = BodyInputs {
            poses: inputs.poses,
            velocities: inputs.velocities,
            colliders: inputs.colliders,
        };
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, &bodies)?;
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
            masses: &self.masses,
            colliders: &self.bodies.colliders,
            softness: inputs.softness,
            static_softness: inputs.static_softness,
        };
        let rows = &mut self.rows;
        run_pass(
            context,
            &mut self.profiler,
            profiler,
            &CONSTRAINTS,
            |pass| rows.encode(context, pass, &device_inputs),
        )?;
        if let Some(out) = out {
            let start = Instant::now();
            self.rows.read_back(context, out)?;
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
        let context = &self.context;
        let start = Instant::now();
        self.batching.upload(context, bodies)?;
        record_copy(profiler, BATCHING.upload, elapsed_ms(start));
        // Most of the 64 rounds find nothing left: encode as many as the last steps needed,
        // and the rest only when some constraint is still unbatched after them.
        let rounds = self.batching_rounds;
        let batching = &mut self.batching;
        run_pass(context, &mut self.profiler, profiler, &BATCHING, |pass| {
            batching.encode_rounds(context, pass, body_count, ordered, batcher, rounds)
        })?;
        let start = Instant::now();
        let complete = self.batching.read_back(context, coloring)?;
        record_copy(profiler, BATCHING.download, elapsed_ms(start));
        if !complete {
            let batching = &self.batching;
            run_pass(context, &mut self.profiler, profiler, &BATCHING, |pass| {
                batching.encode_rest(pass, rounds);
                Ok(())
            })?;
            let start = Instant::now();
            let complete = self.batching.read_back(context, coloring)?;
            debug_assert!(complete, "every round and the finish ran");
            record_copy(profiler, BATCHING.download, elapsed_ms(start));
            self.batching_rounds = (2 * rounds).min(MAX_ROUNDS);
        }
        Ok(())
    }

    /// Stage 7 on the GPU: [`solve`](crate::stages::solver::solve)'s contract, contacts and
    /// joints (the drag included) in the same batches; or, for [`SolverKind::Jacobi`],
    /// [`jacobi::solve`](crate::stages::solver::jacobi::solve)'s.
    pub fn solve(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: SolverSettings,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let start = Instant::now();
        self.solver_bodies.upload(context, bodies)?;
        self.batched_contacts.upload(context, batched.contacts)?;
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
            host_contact_offsets: batched.contact_offsets,
            host_joint_offsets: batched.joint_offsets,
            has_overflow: batched.has_overflow,
        };
        let spans = if jacobi.is_some() {
            &JACOBI_SOLVER
        } else {
            &SOLVER
        };
        run_pass(context, &mut self.profiler, profiler, spans, |pass| {
            match jacobi {
                Some(jacobi) => {
                    jacobi.encode(pass, device_bodies, &device_batched, settings, restitution)
                }
                None => solver.encode(pass, device_bodies, &device_batched, settings, restitution),
            };
            Ok(())
        })?;
        // Impulses come back for warm starting and, for joints, the host's break test.
        let start = Instant::now();
        self.solver_bodies
            .download_into(context, &mut self.downloaded_bodies)?;
        bodies.copy_from_slice(&self.downloaded_bodies);
        self.batched_contacts
            .download_into(context, &mut self.downloaded_constraints)?;
        batched
            .contacts
            .copy_from_slice(&self.downloaded_constraints);
        self.batched_joints
            .download_into(context, &mut self.downloaded_joints)?;
        batched.joints.copy_from_slice(&self.downloaded_joints);
        record_copy(profiler, SOLVER.download, elapsed_ms(start));
        self.solved_this_step = true;
        Ok(())
    }
}

impl GpuStages {
    /// Stage 7 on the GPU after stages 5 and 6 ran there too: the contacts that
    /// [`Self::build_constraints`] left on the device are gathered in batch order (`order[i]`
    /// is the constraint at batched place i; `offsets` the batch offsets), solved as
    /// [`Self::solve`] does together with the host's `joints` (in batch order, batch b at
    /// `joint_offsets[b]..joint_offsets[b + 1]`), and only impulses come back: the contacts'
    /// into `impulses`, in batch order, the joints' into `joints`. `contact_bodies` are the
    /// bodies (A, B) of the gathered contacts, in batch order: the Jacobi solver's adjacency.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_batched(
        &mut self,
        profiler: &mut Profiler,
        kind: SolverKind,
        bodies: &mut [SolverBody],
        contact_bodies: impl Iterator<Item = (u32, u32)> + Clone,
        order: &[u32],
        offsets: &[u32],
        joints: &mut [JointConstraint],
        joint_offsets: &[u32],
        has_overflow: bool,
        settings: SolverSettings,
        restitution: bool,
        impulses: &mut Vec<BatchedImpulses>,
    ) -> Result<(), GpuError> {
        let context = &self.context;
        let start = Instant::now();
        self.solver_bodies.upload(context, bodies)?;
        self.batch_offsets.upload(context, offsets)?;
        self.joint_batch_offsets.upload(context, joint_offsets)?;
        self.batched.upload(context, order, joints)?;
        let jacobi = match kind {
            SolverKind::Pgs => None,
            SolverKind::Jacobi => {
                let jacobi = jacobi_solver(&mut self.jacobi, context)?;
                let joint_bodies = joints.iter().map(|j| (j.body_a, j.body_b));
                jacobi.prepare(bodies, contact_bodies, joint_bodies)?;
                Some(jacobi)
            }
        };
        record_copy(profiler, SOLVER.upload, elapsed_ms(start));
        let (solver, device_bodies) = (&mut self.solver, &self.solver_bodies);
        let (batched, rows) = (&mut self.batched, &self.rows);
        let (device_offsets, device_joint_offsets) =
            (&self.batch_offsets, &self.joint_batch_offsets);
        let spans = if jacobi.is_some() {
            &JACOBI_SOLVER
        } else {
            &SOLVER
        };
        run_pass(context, &mut self.profiler, profiler, spans, |pass| {
            batched.encode_gather(context, pass, &rows.constraints);
            let device_batched = DeviceBatched {
                contacts: &batched.constraints,
                contact_offsets: device_offsets,
                joints: &batched.joints,
                joint_offsets: device_joint_offsets,
                host_contact_offsets: offsets,
                host_joint_offsets: joint_offsets,
                has_overflow,
            };
            match jacobi {
                Some(jacobi) => {
                    jacobi.encode(pass, device_bodies, &device_batched, settings, restitution)
                }
                None => solver.encode(pass, device_bodies, &device_batched, settings, restitution),
            };
            batched.encode_read_impulses(pass);
            Ok(())
        })?;
        let start = Instant::now();
        self.solver_bodies
            .download_into(context, &mut self.downloaded_bodies)?;
        bodies.copy_from_slice(&self.downloaded_bodies);
        self.batched.impulses.download_into(context, impulses)?;
        if !joints.is_empty() {
            self.batched
                .joint_impulses
                .download_into(context, &mut self.downloaded_joint_impulses)?;
            for (joint, solved) in joints.iter_mut().zip(&self.downloaded_joint_impulses) {
                solved.store(joint);
            }
        }
        record_copy(profiler, SOLVER.download, elapsed_ms(start));
        self.solved_this_step = true;
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
    let start = Instant::now();
    let mut encoder = context
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some(spans.kernel[0]),
        });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(spans.kernel[0]),
            timestamp_writes: gpu_profiler.pass_timestamps(spans.kernel),
        });
        encode(&mut pass)?;
    }
    gpu_profiler.resolve(&mut encoder);
    let commands = encoder.finish();
    profiler.record(spans.encode, SpanKind::Cpu, elapsed_ms(start));
    let start = Instant::now();
    context.queue.submit([commands]);
    context.wait()?;
    profiler.record(spans.wait, SpanKind::Cpu, elapsed_ms(start));
    gpu_profiler.collect(context, profiler)
}

/// Uploads poses and velocities once a step, and the colliders when they changed.
fn upload_bodies(
    context: &GpuContext,
    bodies: &mut DeviceBodies,
    collider_data: &mut Vec<ColliderData>,
    inputs: &BodyInputs,
) -> Result<(), GpuError> {
    if !bodies.uploaded_this_step {
        bodies.poses.upload(context, inputs.poses)?;
        bodies.velocities.upload(context, inputs.velocities)?;
        bodies.uploaded_this_step = true;
    }
    if bodies.colliders_stale || bodies.colliders.len() != inputs.colliders.len() {
        collider_data.clear();
        collider_data.extend(inputs.colliders.iter().map(Collider::data));
        bodies.colliders.upload(context, collider_data)?;
        let mut hull_words = Vec::new();
        pack_hulls(inputs.colliders, &mut hull_words);
        bodies.hulls.upload(context, &hull_words)?;
        bodies.colliders_stale = false;
    }
    Ok(())
}

fn elapsed_ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, Vec3};
    use crate::pipeline::config::{Softness, StepConfig};
    use crate::stages::constraints::world_inverse_inertia;
    use crate::{BodyDesc, Shape, World};

    /// The rows read from the GPU narrowphase's output are the rows read from the host's copy
    /// of it, bit for bit: the shortcut skips a copy, it changes nothing.
    #[test]
    fn rows_from_the_narrowphase_output_equal_rows_from_the_host() {
        let mut gpu = GpuStages::new(
            GpuContext::shared()
                .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}")),
        )
        .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut world = World::new(StepConfig {
            sleeping: false,
            ..StepConfig::default()
        })
        .unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
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
        gpu.begin_step();
        gpu.update_contacts(&mut profiler, &keys, &mut contacts, &inputs)
            .unwrap();
        assert!(
            gpu.pair_contacts_on_device(),
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
        gpu.build_constraints(
            &mut profiler,
            RowSlots::Narrowphase,
            &row_inputs,
            Some(&mut from_device),
        )
        .unwrap();
        let slots = RowSlots::Host {
            keys: &keys,
            contacts: &contacts,
        };
        gpu.build_constraints(&mut profiler, slots, &row_inputs, Some(&mut from_host))
            .unwrap();
        assert!(!from_host.is_empty());
        let bytes = |rows: &[ContactConstraint]| bytemuck::cast_slice::<_, u8>(rows).to_vec();
        assert_eq!(bytes(&from_device), bytes(&from_host));
    }
}
