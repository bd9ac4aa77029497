//! GPU executor of the Jacobi soft step: the kernels of `jacobi.wgsl` over the same arrays
//! [`jacobi::solve`](super::jacobi::solve) sweeps. A sweep is one dispatch over the contacts,
//! one over the joints when there are any, and one over the bodies, whatever the number of
//! batches (PGS has one or more per batch, see [`gpu`](super::gpu)): a step is
//!
//! ```text
//!   substeps · (2 + (2 + iterations) · sweep) + sweep (restitution, when any contact bounces),
//!   sweep = 2, or 3 with joints
//! ```
//!
//! dispatches ([`dispatch_count`]). The adjacency lists are built on the host (a counting sort
//! over the constraints' bodies, as the CPU does) and uploaded with the step.
//!
//! Guarantees: the CPU's results up to float rounding (WGSL may fuse multiply-adds);
//! deterministic, since each thread writes its own slots and each body sums its slots in a
//! fixed order.

use super::gpu::{DeviceBatched, HostArrays, NO_BATCH, SOLVER_WORKGROUP, SolverParams};
use super::jacobi::{Adjacency, VelocityDelta};
use super::{Batched, SolverBody, SolverSettings};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};

const JACOBI_WGSL: &str = include_str!("jacobi.wgsl");
/// The PGS solver's six (parameters, bodies, contacts, contact offsets, joints, joint
/// offsets), then counts, adjacency offsets, adjacency, deltas.
const BINDINGS: [Binding; 10] = [
    Binding::Uniform,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

fn wgsl() -> Source {
    super::gpu::wgsl().snippet("jacobi.wgsl", JACOBI_WGSL)
}

/// Dispatches of one step (see the module docs).
pub fn dispatch_count(settings: &SolverSettings, has_joints: bool, restitution: bool) -> usize {
    let sweep = if has_joints { 3 } else { 2 };
    let per_substep = 2 + (2 + settings.iterations as usize) * sweep;
    settings.substeps as usize * per_substep + if restitution { 2 } else { 0 }
}

/// Parameter slots: which sweep a dispatch runs (as in [`gpu`](super::gpu)).
#[derive(Clone, Copy)]
enum Variant {
    /// Solve with bias; also warm start, restitution and the body kernels.
    Solve = 0,
    /// Relax: no bias.
    Relax = 1,
}
const VARIANTS: usize = 2;

/// What the bind groups were built for; rebuilt when any of it changes.
type Key = ([wgpu::Buffer; 9], usize, [u32; 7]);

struct Bound {
    key: Key,
    groups: [wgpu::BindGroup; VARIANTS],
    /// Keeps the parameter blocks the bind groups point into alive.
    _slots: UniformSlots,
}

/// The joint kernels, built at the first step with joints (lavapipe takes long over them,
/// see [`gpu`](super::gpu)).
struct JointKernels {
    warm_start: Kernel,
    solve: Kernel,
}

/// The Jacobi solver on the GPU: its kernels and the step's adjacency and delta slots, and
/// its own arrays for [`run`](Self::run).
pub struct GpuJacobi {
    encoder: JacobiEncoder,
    arrays: HostArrays,
}

/// Kernels, adjacency, delta slots and bind groups: what encodes a step.
struct JacobiEncoder {
    context: GpuContext,
    warm_start: Kernel,
    solve: Kernel,
    restitution: Kernel,
    apply: Kernel,
    integrate_velocities: Kernel,
    integrate_positions: Kernel,
    joint_kernels: Option<JointKernels>,
    adjacency: Adjacency,
    /// Contacts, joints (two words).
    counts: GpuVec<u32>,
    adjacency_offsets: GpuVec<u32>,
    adjacency_entries: GpuVec<u32>,
    deltas: GpuVec<VelocityDelta>,
    /// The counts of the last [`Self::prepare`].
    contact_count: usize,
    joint_count: usize,
    bound: Option<Bound>,
    dispatches: Vec<Dispatch>,
}

impl GpuJacobi {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        let encoder = JacobiEncoder {
            context: context.clone(),
            warm_start: kernel("jacobi_warm_start_contacts"),
            solve: kernel("jacobi_solve_contacts"),
            restitution: kernel("jacobi_restitution_contacts"),
            apply: kernel("jacobi_apply"),
            integrate_velocities: kernel("integrate_velocities"),
            integrate_positions: kernel("integrate_positions"),
            joint_kernels: None,
            adjacency: Adjacency::default(),
            counts: GpuVec::from_slice(context, "jacobi counts", &[0, 0])?,
            adjacency_offsets: GpuVec::with_capacity(context, "jacobi adjacency offsets", 0)?,
            adjacency_entries: GpuVec::with_capacity(context, "jacobi adjacency", 0)?,
            deltas: GpuVec::with_capacity(context, "jacobi velocity deltas", 0)?,
            contact_count: 0,
            joint_count: 0,
            bound: None,
            dispatches: Vec::new(),
        };
        Ok(Self {
            encoder,
            arrays: HostArrays::new(context)?,
        })
    }

    /// Builds and uploads the step's adjacency lists: `bodies` as the solve starts,
    /// `contacts` and `joints` the bodies (A, B) of each constraint in the order the device
    /// holds them. Call before encoding the step, outside its pass.
    ///
    /// # Panics
    ///
    /// If a constraint names a body past `bodies` (other than
    /// [`STATIC_BODY`](crate::stages::constraints::STATIC_BODY)).
    pub fn prepare(
        &mut self,
        bodies: &[SolverBody],
        contacts: impl Iterator<Item = (u32, u32)> + Clone,
        joints: impl Iterator<Item = (u32, u32)> + Clone,
    ) -> Result<(), GpuError> {
        self.encoder.prepare(bodies, contacts, joints)
    }

    /// Encodes the whole soft step over `bodies` and the constraints of `batched` (whose
    /// batches are ignored) after [`Self::prepare`] for them. `restitution`: whether any
    /// contact bounces. Returns the number of dispatches encoded.
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

    /// The Jacobi soft step with [`jacobi::solve`](super::jacobi::solve)'s signature (less its
    /// scratch): uploads the bodies and constraints, solves on the GPU, downloads all three.
    pub fn run(
        &mut self,
        bodies: &mut [SolverBody],
        batched: &mut Batched,
        settings: SolverSettings,
    ) -> Result<(), GpuError> {
        let context = self.encoder.context.clone();
        self.encoder.prepare(
            bodies,
            batched.contacts.iter().map(|c| (c.body_a, c.body_b)),
            batched.joints.iter().map(|j| (j.body_a, j.body_b)),
        )?;
        let encoder = &mut self.encoder;
        self.arrays.run(
            &context,
            "jacobi solver",
            bodies,
            batched,
            &settings,
            |pass, bodies, device, restitution| {
                encoder.encode(pass, bodies, device, settings, restitution);
            },
        )
    }
}

impl JacobiEncoder {
    /// [`GpuJacobi::prepare`].
    fn prepare(
        &mut self,
        bodies: &[SolverBody],
        contacts: impl Iterator<Item = (u32, u32)> + Clone,
        joints: impl Iterator<Item = (u32, u32)> + Clone,
    ) -> Result<(), GpuError> {
        let (contact_count, joint_count) = (contacts.clone().count(), joints.clone().count());
        self.adjacency.build(bodies, contacts.chain(joints));
        let context = &self.context;
        let word = |count: usize| u32::try_from(count).expect("constraint count fits in u32");
        self.counts
            .upload(context, &[word(contact_count), word(joint_count)])?;
        self.adjacency_offsets
            .upload(context, &self.adjacency.offsets)?;
        self.adjacency_entries
            .upload(context, &self.adjacency.entries)?;
        self.deltas
            .resize(context, 2 * (contact_count + joint_count))?;
        self.contact_count = contact_count;
        self.joint_count = joint_count;
        if joint_count > 0 && self.joint_kernels.is_none() {
            let source = wgsl();
            let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
            self.joint_kernels = Some(JointKernels {
                warm_start: kernel("jacobi_warm_start_joints"),
                solve: kernel("jacobi_solve_joints"),
            });
        }
        Ok(())
    }

    /// [`GpuJacobi::encode`].
    fn encode(
        &mut self,
        pass: &mut wgpu::ComputePass<'_>,
        bodies: &GpuVec<SolverBody>,
        batched: &DeviceBatched,
        settings: SolverSettings,
        restitution: bool,
    ) -> usize {
        let key: Key = (
            [
                bodies.buffer().clone(),
                batched.contacts.buffer().clone(),
                batched.contact_offsets.buffer().clone(),
                batched.joints.buffer().clone(),
                batched.joint_offsets.buffer().clone(),
                self.counts.buffer().clone(),
                self.adjacency_offsets.buffer().clone(),
                self.adjacency_entries.buffer().clone(),
                self.deltas.buffer().clone(),
            ],
            bodies.len(),
            [
                settings.dt.to_bits(),
                settings.substeps,
                settings.gravity.x.to_bits(),
                settings.gravity.y.to_bits(),
                settings.gravity.z.to_bits(),
                settings.max_push_velocity.to_bits(),
                settings.restitution_threshold.to_bits(),
            ],
        );
        if self.bound.as_ref().is_none_or(|bound| bound.key != key) {
            self.bound = Some(self.bind(key, bodies, batched, settings));
        }
        let Some(bound) = &self.bound else {
            unreachable!("bound just above")
        };
        let body_groups = workgroups_for(bodies.len(), SOLVER_WORKGROUP);
        let contact_groups = workgroups_for(self.contact_count, WORKGROUP_SIZE);
        let joint_groups = workgroups_for(self.joint_count, WORKGROUP_SIZE);
        let joints = self.joint_kernels.as_ref().filter(|_| self.joint_count > 0);
        let dispatches = &mut self.dispatches;
        dispatches.clear();
        let apply = &self.apply;
        let sweep = |dispatches: &mut Vec<Dispatch>,
                     (contacts, contact_groups): (&Kernel, u32),
                     joint: Option<&Kernel>,
                     variant: Variant| {
            let group = &bound.groups[variant as usize];
            dispatches.push(contacts.dispatch(group.clone(), contact_groups));
            if let Some(joint) = joint {
                dispatches.push(joint.dispatch(group.clone(), joint_groups));
            }
            dispatches.push(apply.dispatch(group.clone(), body_groups));
        };
        let body_group = &bound.groups[Variant::Solve as usize];
        for _ in 0..settings.substeps {
            dispatches.push(
                self.integrate_velocities
                    .dispatch(body_group.clone(), body_groups),
            );
            sweep(
                dispatches,
                (&self.warm_start, contact_groups),
                joints.map(|j| &j.warm_start),
                Variant::Solve,
            );
            for _ in 0..settings.iterations {
                sweep(
                    dispatches,
                    (&self.solve, contact_groups),
                    joints.map(|j| &j.solve),
                    Variant::Solve,
                );
            }
            dispatches.push(
                self.integrate_positions
                    .dispatch(body_group.clone(), body_groups),
            );
            sweep(
                dispatches,
                (&self.solve, contact_groups),
                joints.map(|j| &j.solve),
                Variant::Relax,
            );
        }
        if restitution {
            // Joints do not bounce; the restitution kernel clears their slots, so it runs
            // a thread for each contact and for each joint.
            let groups = contact_groups.max(joint_groups);
            sweep(
                dispatches,
                (&self.restitution, groups),
                None,
                Variant::Solve,
            );
        }
        encode_all(pass, dispatches);
        debug_assert_eq!(
            dispatches.len(),
            dispatch_count(&settings, joints.is_some(), restitution)
        );
        dispatches.len()
    }

    fn bind(
        &self,
        key: Key,
        bodies: &GpuVec<SolverBody>,
        batched: &DeviceBatched,
        settings: SolverSettings,
    ) -> Bound {
        let solve = SolverParams::new(&settings, bodies.len(), NO_BATCH);
        // In the order of `Variant`.
        let blocks = [
            solve,
            SolverParams {
                use_bias: 0,
                ..solve
            },
        ];
        let slots = UniformSlots::new(&self.context, "jacobi params", &blocks);
        let groups = std::array::from_fn(|slot| {
            self.apply.bind(
                &self.context,
                &[
                    slots.binding(slot),
                    bodies.whole(),
                    batched.contacts.whole(),
                    batched.contact_offsets.whole(),
                    batched.joints.whole(),
                    batched.joint_offsets.whole(),
                    self.counts.whole(),
                    self.adjacency_offsets.whole(),
                    self.adjacency_entries.whole(),
                    self.deltas.whole(),
                ],
            )
        });
        Bound {
            key,
            groups,
            _slots: slots,
        }
    }
}
