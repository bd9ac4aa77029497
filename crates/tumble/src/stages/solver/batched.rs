//! The batches kept on the device when the rows, the batching and the solver all run on the GPU
//! (`batched.wgsl`): the rows' constraints are gathered into batch order there, and after the
//! solve only their accumulated impulses come back ([`BatchedImpulses`], 48 bytes a
//! constraint), not the constraints (432 bytes each on the device, twice: down for the
//! layout, up for the solve).
//!
//! The host still sends the order (a counting sort of the colors it read back, the same
//! [`group_by_batch`](crate::stages::batching::group_by_batch) the CPU step uses), so both
//! paths solve the same array bit for bit.
//!
//! Joint rows are built on the device too and gathered into batch order there
//! ([`GpuJointRows`](crate::stages::constraints::joint_gpu::GpuJointRows)); the solver sweeps
//! that array. After the solve only their impulses come back ([`BatchedJointImpulses`], 32
//! bytes a joint instead of 320), for the host's joints (break test, queries) and the drag, and
//! they are also written to each joint's slot on the device, the next step's warm start.
//!
//! The contacts' impulses can go to their pairs on the device as well
//! ([`GpuBatched::encode_scatter_pair_impulses`], `pair_impulses.wgsl`): with rows built from
//! the GPU narrowphase's output, the next step's collision then warm-starts from the device's
//! contacts and the host's pair cache is not uploaded again.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::joint::MAX_ANGULAR_ROWS;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, LastTwo, Source, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::math::Vec3;
use crate::stages::constraints::lanes::{Word, with_lanes, word_count};
use crate::stages::constraints::{CONTACT_CONSTRAINT_WGSL, JOINT_CONSTRAINT_WGSL, JointConstraint};
use crate::stages::narrowphase::{PAIR_CONTACT_WGSL, PairContact};

const WGSL: &str = include_str!("batched.wgsl");
const GATHER_ROWS_WGSL: &str = include_str!("gather_rows.wgsl");
const PAIR_IMPULSES_WGSL: &str = include_str!("pair_impulses.wgsl");
/// Counts, batched constraints, the pairs' contacts.
const PAIR_IMPULSES_BINDINGS: [Binding; 3] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];
/// Counts, order, rows, batched constraints, their impulses, batched joints, their impulses,
/// the joints' impulses by slot.
const BINDINGS: [Binding; 8] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `BatchedImpulses` in `batched.wgsl`: one batched constraint's accumulated impulses,
/// point k in lane k, 0 past its point count.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BatchedImpulses {
    pub normal: [f32; 4],
    pub tangent1: [f32; 4],
    pub tangent2: [f32; 4],
}

/// Mirrors `BatchedJointImpulses` in `joint_constraint.wgsl`: one joint's accumulated impulses.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BatchedJointImpulses {
    /// [`JointConstraint::point_impulse`] (N s).
    pub point: Vec3,
    /// [`JointConstraint::angular_impulse`] (N m s).
    pub angular: [f32; MAX_ANGULAR_ROWS],
}
const _: () = assert!(size_of::<BatchedJointImpulses>() == 32);

pub fn wgsl() -> Source {
    with_lanes(Source::new())
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("joint_constraint.wgsl", JOINT_CONSTRAINT_WGSL)
        .snippet("batched.wgsl", WGSL)
}

/// The gather of the rows into batch order, a word a thread, with the words only the
/// restitution sweep reads when `bouncing`.
fn gather_rows_wgsl(bouncing: bool) -> Source {
    with_lanes(Source::new())
        .constant_u32("BOUNCING", u32::from(bouncing))
        .snippet("gather_rows.wgsl", GATHER_ROWS_WGSL)
}

/// The scatter of the contacts' impulses to their pairs, for the layout test.
pub fn pair_impulses_wgsl() -> Source {
    with_lanes(Source::new())
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("pair_impulses.wgsl", PAIR_IMPULSES_WGSL)
}

/// The buffers the cached dispatches bind, and the capacities they cover (constraints, joints).
type Key = ([wgpu::Buffer; 8], usize, usize);

pub struct GpuBatched {
    /// Two words: the constraint count and the joint count.
    count: GpuVec<u32>,
    order: GpuVec<u32>,
    /// The constraints in batch order, in blocks of lanes
    /// ([`lanes`](crate::stages::constraints::lanes)): what the solver sweeps. Only the words
    /// a kernel reads are gathered (`gather_rows.wgsl`); the others hold whatever they held.
    pub constraints: GpuVec<Word>,
    pub impulses: GpuVec<BatchedImpulses>,
    /// The impulses of the joints in batch order, as the solver left them.
    pub joint_impulses: GpuVec<BatchedJointImpulses>,
    /// `gather_rows.wgsl`, on [`BINDINGS`]' first four: with the words only the restitution
    /// sweep reads, and without them.
    gather: Kernel,
    gather_still: Kernel,
    read_impulses: Kernel,
    read_joint_impulses: Kernel,
    cached: Option<(Key, [Dispatch; 4])>,
    scatter_pair_impulses: Kernel,
    /// For the contacts buffer and the constraint capacity it was built for.
    scattered: LastTwo<(wgpu::Buffer, wgpu::Buffer, usize), Dispatch>,
}

impl GpuBatched {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Ok(Self {
            count: GpuVec::from_slice(context, "batched counts", &[0, 0])?,
            order: GpuVec::with_capacity(context, "batch order", 0)?,
            constraints: GpuVec::with_capacity(context, "batched constraints", 0)?,
            impulses: GpuVec::with_capacity(context, "batched impulses", 0)?,
            joint_impulses: GpuVec::with_capacity(context, "batched joint impulses", 0)?,
            gather: Kernel::new(
                context,
                "gather_words",
                &gather_rows_wgsl(true),
                "gather_words",
                &BINDINGS[..4],
            ),
            gather_still: Kernel::new(
                context,
                "gather_words_still",
                &gather_rows_wgsl(false),
                "gather_words",
                &BINDINGS[..4],
            ),
            read_impulses: kernel("read_impulses"),
            read_joint_impulses: kernel("read_joint_impulses"),
            cached: None,
            scatter_pair_impulses: Kernel::new(
                context,
                "scatter_pair_impulses",
                &pair_impulses_wgsl(),
                "scatter_pair_impulses",
                &PAIR_IMPULSES_BINDINGS,
            ),
            scattered: LastTwo::default(),
        })
    }

    /// Sends the batch order (`order[i]` = the constraint at batched place i) and the number
    /// of joints in batch order, and sizes the outputs for them.
    pub fn upload(
        &mut self,
        context: &GpuContext,
        order: &[u32],
        joint_count: usize,
    ) -> Result<(), GpuError> {
        self.size_for(context, order.len(), joint_count)?;
        self.order.upload(context, order)
    }

    /// Sizes the order and the outputs for `count` constraints and `joint_count` joints, the
    /// order to be written on the device ([`Self::order`]).
    pub fn size_for(
        &mut self,
        context: &GpuContext,
        count: usize,
        joint_count: usize,
    ) -> Result<(), GpuError> {
        let constraints = u32::try_from(count).expect("constraint count fits in u32");
        let joints = u32::try_from(joint_count).expect("joint count fits in u32");
        self.count.upload(context, &[constraints, joints])?;
        self.order.resize(context, count)?;
        self.constraints.resize(context, word_count(count))?;
        self.impulses.resize(context, count)?;
        self.joint_impulses.resize(context, joint_count)?;
        Ok(())
    }

    /// The counts' buffer: word 0 the contact constraints, word 1 the joints.
    pub fn count(&self) -> &GpuVec<u32> {
        &self.count
    }

    /// The batch order the gather reads: `order[i]` = the constraint at batched place i.
    pub fn order(&self) -> &GpuVec<u32> {
        &self.order
    }

    /// Encodes the gather of `rows` (the rows' constraints) into [`Self::constraints`], with
    /// the words only the restitution sweep reads when the solve has one (`restitution`).
    /// `joints` are the joints in batch order that the solver will sweep, `slot_impulses` the
    /// joint rows' warm start by slot ([`Self::encode_read_impulses`] writes both).
    pub fn encode_gather(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        rows: &GpuVec<Word>,
        (joints, slot_impulses): (&GpuVec<JointConstraint>, &GpuVec<BatchedJointImpulses>),
        restitution: bool,
    ) {
        let key: Key = (
            [
                self.count.buffer().clone(),
                self.order.buffer().clone(),
                rows.buffer().clone(),
                self.constraints.buffer().clone(),
                self.impulses.buffer().clone(),
                joints.buffer().clone(),
                self.joint_impulses.buffer().clone(),
                slot_impulses.buffer().clone(),
            ],
            self.order.capacity(),
            joints.capacity(),
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let group = self.read_impulses.bind(
                context,
                &[
                    self.count.whole(),
                    self.order.whole(),
                    rows.whole(),
                    self.constraints.whole(),
                    self.impulses.whole(),
                    joints.whole(),
                    self.joint_impulses.whole(),
                    slot_impulses.whole(),
                ],
            );
            let gather_group = self.gather.bind(
                context,
                &[
                    self.count.whole(),
                    self.order.whole(),
                    rows.whole(),
                    self.constraints.whole(),
                ],
            );
            let groups = workgroups_for(key.1, WORKGROUP_SIZE);
            let words = workgroups_for(word_count(key.1), WORKGROUP_SIZE);
            let joint_groups = workgroups_for(key.2, WORKGROUP_SIZE);
            let dispatches = [
                self.gather.dispatch(gather_group.clone(), words),
                self.gather_still.dispatch(gather_group, words),
                self.read_impulses.dispatch(group.clone(), groups),
                self.read_joint_impulses.dispatch(group, joint_groups),
            ];
            self.cached = Some((key, dispatches));
        }
        if let Some((_, [gather, gather_still, ..])) = &self.cached {
            let gather = if restitution { gather } else { gather_still };
            encode_all(pass, std::slice::from_ref(gather));
        }
    }

    /// Encodes the copy of the solved impulses into [`Self::impulses`] and
    /// [`Self::joint_impulses`] (after [`Self::encode_gather`] and the solve, in the same
    /// pass).
    pub fn encode_read_impulses(&self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some((_, [_, _, read @ ..])) = &self.cached {
            encode_all(pass, read);
        }
    }

    /// Encodes the copy of each solved constraint's impulses into `contacts[pair]` (after the
    /// solve, in the same pass). Every constraint's `pair` must be a slot of `contacts`: rows
    /// built from the GPU narrowphase's output.
    pub fn encode_scatter_pair_impulses(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        contacts: &GpuVec<PairContact>,
    ) {
        let key = (
            contacts.buffer().clone(),
            self.constraints.buffer().clone(),
            self.order.capacity(),
        );
        let groups = workgroups_for(key.2, WORKGROUP_SIZE);
        let (kernel, count, constraints) =
            (&self.scatter_pair_impulses, &self.count, &self.constraints);
        let dispatch = self.scattered.get_or_insert(key, || {
            let buffers = [count.whole(), constraints.whole(), contacts.whole()];
            kernel.dispatch(kernel.bind(context, &buffers), groups)
        });
        dispatch.encode(pass);
    }
}
