//! [`prepare_bodies`](super::prepare_bodies) on the GPU (`prepare.wgsl`): the solver's bodies
//! from the velocities and masses the step already uploaded, bit for bit the CPU's (the same
//! selects, no arithmetic), so the solver's submission uploads no body.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, BodyMass, BodyVelocity};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::GpuContext;
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::CONTACT_CONSTRAINT_WGSL;
use crate::stages::integrate::MAX_ROTATION_PER_STEP;
use crate::stages::solver::SolverBody;
use crate::stages::solver::gpu::SOLVER_BODY_WGSL;

const WGSL: &str = include_str!("prepare.wgsl");
const BINDINGS: [Binding; 4] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `PrepareParams` in `prepare.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PrepareParams {
    pub count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

pub fn wgsl() -> Source {
    Source::new()
        .constant_f32("MAX_ROTATION_PER_STEP", MAX_ROTATION_PER_STEP)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("solver_body.wgsl", SOLVER_BODY_WGSL)
        .snippet("prepare.wgsl", WGSL)
}

/// The buffers and body count a dispatch was built for.
type Key = ([wgpu::Buffer; 3], usize);

pub struct GpuPrepareBodies {
    kernel: Kernel,
    cached: Option<(Key, Dispatch)>,
}

impl GpuPrepareBodies {
    pub fn new(context: &GpuContext) -> Self {
        Self {
            kernel: Kernel::new(
                context,
                "prepare_bodies",
                &wgsl(),
                "prepare_bodies",
                &BINDINGS,
            ),
            cached: None,
        }
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
        let count = bodies.len();
        let key = (
            [
                velocities.buffer().clone(),
                masses.buffer().clone(),
                bodies.buffer().clone(),
            ],
            count,
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let slots = UniformSlots::new(
                context,
                "prepare params",
                &[PrepareParams {
                    count: count as u32,
                    _pad0: 0,
                    _pad1: 0,
                    _pad2: 0,
                }],
            );
            let group = self.kernel.bind(
                context,
                &[
                    slots.binding(0),
                    velocities.whole(),
                    masses.whole(),
                    bodies.whole(),
                ],
            );
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
