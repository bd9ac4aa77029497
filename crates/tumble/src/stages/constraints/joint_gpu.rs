//! GPU executor of the joint rows: [`build_joint_constraints`](super::build_joint_constraints)'s
//! rows built on the device (`joint_rows.wgsl`), so that a step whose rows, batching and solver
//! all run on the GPU sends no joint row down from the host.
//!
//! What lives on the device, by slot of the world's joint array (`World::joints`):
//! - [`JointSlot`]s: each joint's frames, kind, limits and bodies. Uploaded only when the
//!   joints change ([`GpuJointRows::joints_changed`]: added, removed, restored, broken).
//! - the warm-start impulses ([`BatchedJointImpulses`]): the solver writes each solved joint's
//!   impulses back to its slot, so they stay on the device from step to step; the host uploads
//!   them only when it solved (or changed) them itself ([`GpuJointRows::impulses_changed`]).
//! - the rows: [`GpuJointRows::encode_build`] builds one per live slot from the step's poses
//!   and masses, one dispatch; the slot past the last joint holds the drag's row, which the host
//!   builds (one row, a few numbers) and writes there ([`GpuJointRows::write_row`]).
//!
//! Which rows are solved this step, and in which order, is the host's list
//! ([`joint_slots`](super::joint_slots), the drag's slot appended): the host knows the masses
//! and needs the bodies for the batching anyway. [`GpuJointRows::read_back`] brings the listed
//! rows up for a solver elsewhere; [`GpuJointRows::encode_gather`] lays them out in batch order
//! on the device for the GPU solver.

use bytemuck::{Pod, Zeroable};

use super::{CONTACT_CONSTRAINT_WGSL, JOINT_CONSTRAINT_WGSL, JointConstraint, JointSlot};
use crate::dynamics::body::{BODY_WGSL, BodyMass, BodyPose};
use crate::dynamics::joint::Joint;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::pipeline::config::Softness;
use crate::stages::solver::batched::BatchedJointImpulses;

const WGSL: &str = include_str!("joint_rows.wgsl");
/// Parameters, slots, impulses, poses, masses, rows, count, order, batched rows.
const BINDINGS: [Binding; 9] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `JointRowParams` in `joint_rows.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct JointRowParams {
    /// The joints' softness as (bias rate, mass scale, impulse scale, unused).
    pub softness: [f32; 4],
    /// Slots of the world's joint array.
    pub slot_count: u32,
    /// [`JointConstraint::max_point_impulse`] of every joint: infinity.
    pub max_point_impulse: f32,
    pub _pad0: u32,
    pub _pad1: u32,
}

pub fn wgsl() -> Source {
    Source::new()
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("joint_constraint.wgsl", JOINT_CONSTRAINT_WGSL)
        .snippet("joint_rows.wgsl", WGSL)
}

/// The step's body arrays on the device, as the joint rows read them.
pub struct GpuJointInputs<'a> {
    pub poses: &'a GpuVec<BodyPose>,
    pub masses: &'a GpuVec<BodyMass>,
    pub softness: Softness,
}

/// What the cached dispatches were built for: the buffers bound, the slots, the parameters'
/// words, the capacity of the gather's order.
type Key = ([wgpu::Buffer; 8], u32, [u32; 8], usize);

#[derive(Debug)]
pub struct GpuJointRows {
    slots: GpuVec<JointSlot>,
    /// Warm-start impulses by slot; the solver writes them back (see the module docs).
    pub impulses: GpuVec<BatchedJointImpulses>,
    /// One row per slot, then the drag's.
    rows: GpuVec<JointConstraint>,
    count: GpuVec<u32>,
    order: GpuVec<u32>,
    /// The listed rows in batch order ([`Self::encode_gather`]): what the GPU solver sweeps.
    pub batched: GpuVec<JointConstraint>,
    slots_stale: bool,
    impulses_stale: bool,
    /// Host scratch for the uploads and the read-back.
    host_slots: Vec<JointSlot>,
    host_impulses: Vec<BatchedJointImpulses>,
    host_rows: Vec<JointConstraint>,
    /// The body buffers and parameters of the last build, which the gather's bind group (the
    /// same as the build's) binds too.
    built_with: Option<(wgpu::Buffer, wgpu::Buffer, JointRowParams)>,
    cached: Option<(Key, [Dispatch; 2])>,
}

impl GpuJointRows {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            slots: GpuVec::with_capacity(context, "joint slots", 0)?,
            impulses: GpuVec::with_capacity(context, "joint impulses", 0)?,
            rows: GpuVec::with_capacity(context, "joint rows", 0)?,
            count: GpuVec::from_slice(context, "joint count", &[0])?,
            order: GpuVec::with_capacity(context, "joint order", 0)?,
            batched: GpuVec::with_capacity(context, "batched joints", 0)?,
            slots_stale: true,
            impulses_stale: true,
            host_slots: Vec::new(),
            host_impulses: Vec::new(),
            host_rows: Vec::new(),
            built_with: None,
            cached: None,
        })
    }

    /// The joints were added, removed, restored or broke: upload them (and their impulses)
    /// before the next build.
    pub fn joints_changed(&mut self) {
        self.slots_stale = true;
        self.impulses_stale = true;
    }

    /// The host's joint impulses are newer than the device's (a solver other than the one
    /// writing back to [`Self::impulses`] ran): upload them before the next build.
    pub fn impulses_changed(&mut self) {
        self.impulses_stale = true;
    }

    /// Uploads what changed of `joints` since the last call: nothing in a step that follows a
    /// GPU solve of unchanged joints.
    pub fn sync(&mut self, context: &GpuContext, joints: &[Option<Joint>]) -> Result<(), GpuError> {
        if self.slots_stale || self.slots.len() != joints.len() {
            self.host_slots.clear();
            self.host_slots.extend(joints.iter().map(JointSlot::from));
            self.slots.upload(context, &self.host_slots)?;
            self.slots_stale = false;
            self.impulses_stale = true;
        }
        if self.impulses_stale {
            self.host_impulses.clear();
            self.host_impulses.extend(joints.iter().map(|joint| {
                joint.map_or_else(BatchedJointImpulses::default, |joint| {
                    BatchedJointImpulses {
                        point: joint.point_impulse,
                        angular: joint.angular_impulse,
                    }
                })
            }));
            self.impulses.upload(context, &self.host_impulses)?;
            self.impulses_stale = false;
        }
        // One row per slot and the drag's.
        self.rows.resize(context, joints.len() + 1)?;
        Ok(())
    }

    /// The slot of the row past the joints' (the drag's).
    pub fn extra_slot(&self) -> u32 {
        self.slots.len() as u32
    }

    /// Writes a row built on the host (the drag's) at `slot`, before the next submission.
    pub fn write_row(&self, context: &GpuContext, slot: u32, row: &JointConstraint) {
        debug_assert!((slot as usize) < self.rows.len(), "a slot of the rows");
        let offset = u64::from(slot) * size_of::<JointConstraint>() as u64;
        context
            .queue
            .write_buffer(self.rows.buffer(), offset, bytemuck::bytes_of(row));
    }

    /// Encodes the rows of every live slot (after [`Self::sync`]).
    pub fn encode_build(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        inputs: &GpuJointInputs,
    ) {
        let softness = inputs.softness;
        let params = JointRowParams {
            softness: [
                softness.bias_rate,
                softness.mass_scale,
                softness.impulse_scale,
                0.0,
            ],
            slot_count: self.slots.len() as u32,
            max_point_impulse: f32::INFINITY,
            _pad0: 0,
            _pad1: 0,
        };
        self.built_with = Some((
            inputs.poses.buffer().clone(),
            inputs.masses.buffer().clone(),
            params,
        ));
        if let Some([build, _]) = self.dispatches(context) {
            build.encode(pass);
        }
    }

    /// Sends the order in which the solver sweeps the rows (`order[i]`: the slot of the row at
    /// batched place i) and sizes [`Self::batched`] for it.
    pub fn upload_order(&mut self, context: &GpuContext, order: &[u32]) -> Result<(), GpuError> {
        let count = u32::try_from(order.len()).expect("joint count fits in u32");
        self.count.upload(context, &[count])?;
        self.order.upload(context, order)?;
        self.batched.resize(context, order.len())?;
        Ok(())
    }

    /// Encodes the gather of the rows into [`Self::batched`] (after [`Self::encode_build`] and
    /// [`Self::upload_order`]).
    pub fn encode_gather(&mut self, context: &GpuContext, pass: &mut wgpu::ComputePass<'_>) {
        debug_assert!(self.built_with.is_some(), "the rows are built first");
        if let Some([_, gather]) = self.dispatches(context) {
            gather.encode(pass);
        }
    }

    /// The dispatches for the buffers and parameters of now (those of the last build), built
    /// again when they changed; `None` before the first build.
    fn dispatches(&mut self, context: &GpuContext) -> Option<&[Dispatch; 2]> {
        let (poses, masses, params) = self.built_with.clone()?;
        let key: Key = (
            [
                self.slots.buffer().clone(),
                self.impulses.buffer().clone(),
                poses.clone(),
                masses.clone(),
                self.rows.buffer().clone(),
                self.count.buffer().clone(),
                self.order.buffer().clone(),
                self.batched.buffer().clone(),
            ],
            params.slot_count,
            bytemuck::cast(params),
            self.order.capacity(),
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let source = wgsl();
            let uniforms = UniformSlots::new(context, "joint row params", &[params]);
            let buffers = [
                uniforms.binding(0),
                self.slots.whole(),
                self.impulses.whole(),
                poses.as_entire_buffer_binding(),
                masses.as_entire_buffer_binding(),
                self.rows.whole(),
                self.count.whole(),
                self.order.whole(),
                self.batched.whole(),
            ];
            let dispatch = |entry: &str, threads: usize| {
                let label = format!("joint rows {entry}");
                let kernel = Kernel::new(context, &label, &source, entry, &BINDINGS);
                let group = kernel.bind(context, &buffers);
                kernel.dispatch(group, workgroups_for(threads, WORKGROUP_SIZE))
            };
            let dispatches = [
                dispatch("build", params.slot_count as usize),
                dispatch("gather", key.3),
            ];
            self.cached = Some((key, dispatches));
        }
        self.cached.as_ref().map(|(_, dispatches)| dispatches)
    }

    /// Reads the rows of `slots` back (after the encoded build ran), in that order, into `out`.
    pub fn read_back(
        &mut self,
        context: &GpuContext,
        slots: &[u32],
        out: &mut Vec<JointConstraint>,
    ) -> Result<(), GpuError> {
        out.clear();
        if slots.is_empty() {
            return Ok(());
        }
        self.rows.download_into(context, &mut self.host_rows)?;
        out.extend(slots.iter().map(|&slot| self.host_rows[slot as usize]));
        Ok(())
    }
}
