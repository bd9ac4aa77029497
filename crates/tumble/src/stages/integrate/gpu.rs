//! Stage 8's two halves on the GPU: [`prepare_bodies`](super::prepare_bodies) (`prepare.wgsl`)
//! makes the solver's bodies from the velocities and masses the step already has on the
//! device, and [`finalize_bodies`](super::finalize_bodies) (`finalize.wgsl`) moves the poses
//! and sets the velocities there, so the bodies stay on the device from step to step. The
//! preparation is bit for bit the CPU's (the same selects, no arithmetic); the finalization
//! writes glam's quaternion product and normalization in its order of operations, but a GPU
//! may fuse a multiply and an add, so it agrees with the CPU to rounding.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, BodyMass, BodyPose, BodyVelocity};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::CONTACT_CONSTRAINT_WGSL;
use crate::stages::integrate::MAX_ROTATION_PER_STEP;
use crate::stages::solver::SolverBody;
use crate::stages::solver::gpu::SOLVER_BODY_WGSL;

const PREPARE_WGSL: &str = include_str!("prepare.wgsl");
const FINALIZE_WGSL: &str = include_str!("finalize.wgsl");
const BODY_COUNT_WGSL: &str = include_str!("body_count.wgsl");

/// Mirrors `BodyCount` in `body_count.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BodyCount {
    pub count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// A body kernel's source: the body structs, `body_count.wgsl`, then the kernel file.
fn wgsl(file: &str, text: &str) -> Source {
    Source::new()
        .constant_f32("MAX_ROTATION_PER_STEP", MAX_ROTATION_PER_STEP)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("solver_body.wgsl", SOLVER_BODY_WGSL)
        .snippet("body_count.wgsl", BODY_COUNT_WGSL)
        .snippet(file, text)
}

/// `prepare.wgsl`'s source (its structs are checked against Rust's in the layout test).
pub fn prepare_wgsl() -> Source {
    wgsl("prepare.wgsl", PREPARE_WGSL)
}

/// `finalize.wgsl`'s source.
pub fn finalize_wgsl() -> Source {
    wgsl("finalize.wgsl", FINALIZE_WGSL)
}

/// A kernel of one thread a body over `N` buffers (after its count's block), with its dispatch
/// kept for the buffers and count it was built for (a step allocates nothing).
struct BodyKernel<const N: usize> {
    kernel: Kernel,
    cached: Option<(([wgpu::Buffer; N], usize), Dispatch)>,
}

impl<const N: usize> BodyKernel<N> {
    fn new(context: &GpuContext, source: &Source, entry: &str, bindings: &[Binding]) -> Self {
        debug_assert_eq!(bindings.len(), N + 1, "the count's block, then the buffers");
        Self {
            kernel: Kernel::new(context, entry, source, entry, bindings),
            cached: None,
        }
    }

    fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        buffers: [&wgpu::Buffer; N],
        count: usize,
    ) {
        let key = (buffers.map(Clone::clone), count);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let block = BodyCount {
                count: count as u32,
                _pad0: 0,
                _pad1: 0,
                _pad2: 0,
            };
            let slots = UniformSlots::new(context, "body count", &[block]);
            let bindings = std::iter::once(slots.binding(0))
                .chain(buffers.map(wgpu::Buffer::as_entire_buffer_binding))
                .collect::<Vec<_>>();
            let group = self.kernel.bind(context, &bindings);
            let dispatch = self
                .kernel
                .dispatch(group, workgroups_for(count, WORKGROUP_SIZE));
            self.cached = Some((key, dispatch));
        }
        if let Some((_, dispatch)) = &self.cached {
            encode_all(pass, std::slice::from_ref(dispatch));
        }
    }
}

pub struct GpuPrepareBodies(BodyKernel<3>);

impl GpuPrepareBodies {
    pub fn new(context: &GpuContext) -> Self {
        Self(BodyKernel::new(
            context,
            &prepare_wgsl(),
            "prepare_bodies",
            &[
                Binding::Uniform,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
            ],
        ))
    }

    /// Encodes `bodies[i]` = the solver body of velocity `i` and mass `i`, for `bodies.len()`
    /// bodies (velocities and masses hold at least as many).
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        velocities: &GpuVec<BodyVelocity>,
        masses: &GpuVec<BodyMass>,
        bodies: &GpuVec<SolverBody>,
    ) {
        let buffers = [velocities.buffer(), masses.buffer(), bodies.buffer()];
        self.0.encode(context, pass, buffers, bodies.len());
    }
}

pub struct GpuFinalizeBodies {
    kernel: BodyKernel<4>,
    /// One word: the kernel moves the bodies only where it is not 0. It is 1 but after a step
    /// whose rows and solve were submitted on a guess that was wrong: the check before the
    /// kernel then writes 0, and the host sets it back ([`Self::reset_held`]) once it has
    /// read it.
    held: GpuVec<u32>,
    /// The word read back, reused (a step allocates nothing).
    held_host: Vec<u32>,
}

impl GpuFinalizeBodies {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            kernel: BodyKernel::new(
                context,
                &finalize_wgsl(),
                "finalize_bodies",
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::StorageRead,
                ],
            ),
            held: GpuVec::from_slice(context, "step held", &[1])?,
            held_host: Vec::new(),
        })
    }

    /// Encodes the step's motion `bodies[i]` into pose `i` and velocity `i`, for `bodies.len()`
    /// bodies (poses and velocities hold at least as many), where the word [`Self::held`] is
    /// not 0 when the kernel runs.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        (bodies, poses, velocities): (
            &GpuVec<SolverBody>,
            &GpuVec<BodyPose>,
            &GpuVec<BodyVelocity>,
        ),
    ) {
        let buffers = [
            bodies.buffer(),
            poses.buffer(),
            velocities.buffer(),
            self.held.buffer(),
        ];
        self.kernel.encode(context, pass, buffers, bodies.len());
    }

    /// The word the kernel reads, for a kernel before it to write.
    pub fn held(&self) -> &GpuVec<u32> {
        &self.held
    }

    /// Sets the word back to 1 (landing before the next submission's commands run), after a
    /// step that wrote 0 into it finished.
    pub fn reset_held(&mut self, context: &GpuContext) -> Result<(), GpuError> {
        self.held.upload(context, &[1])
    }

    /// Encodes the word's read-back, after the kernel that writes it.
    pub fn encode_held_download(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        self.held.encode_download(context, encoder);
    }

    /// Whether the word read back ([`Self::encode_held_download`], after the wait) is not 0.
    pub fn read_held(&mut self, context: &GpuContext) -> Result<bool, GpuError> {
        self.held.read_download(context, &mut self.held_host)?;
        Ok(self.held_host.first().is_some_and(|&held| held != 0))
    }
}
