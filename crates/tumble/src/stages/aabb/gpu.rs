//! Stage 1 on the GPU: world AABBs from the device-resident body arrays, one thread per body
//! slot, with the CPU executor's formula ([`compute_aabbs`](super::compute_aabbs)): the shape's
//! box at the pose, grown by the margin, unioned with itself moved by `linear_velocity · dt`.
//!
//! The kernel repeats glam's arithmetic term by term; results agree with the CPU to a few f32
//! roundings (a GPU may fuse a multiply-add), not bitwise; for hulls, meshes and compounds it
//! turns a box that holds the shape (see [`super`]), so theirs hold the CPU's. Output is
//! [`Aabb`] (24 bytes), the same array the CPU stage writes.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, BodyPose, BodyVelocity, Collider, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::math::Aabb;
use crate::shape::PLANE_AABB_EXTENT;

const WGSL: &str = include_str!("aabb.wgsl");
const BINDINGS: [Binding; 5] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `AabbParams` in `aabb.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct AabbParams {
    pub count: u32,
    pub margin: f32,
    pub dt: f32,
    pub padding: u32,
}
const _: () = assert!(size_of::<AabbParams>() == 16);

pub fn wgsl() -> Source {
    Source::new()
        .snippet("body.wgsl", BODY_WGSL)
        // `{:?}` writes 1e15, a WGSL float literal.
        .snippet(
            "plane extent",
            &format!("const PLANE_AABB_EXTENT: f32 = {PLANE_AABB_EXTENT:?};"),
        )
        .snippet("aabb.wgsl", WGSL)
}

/// What the cached dispatch was built for: [poses, velocities, colliders, aabbs], count,
/// margin and dt as bits.
type AabbKey = ([wgpu::Buffer; 4], usize, u32, u32);

/// The AABB stage of one set of buffers, built once and re-encoded every step.
#[derive(Debug, Default)]
pub struct GpuAabbs {
    cached: Option<(AabbKey, Dispatch)>,
    /// [`Self::run`]'s device copies, kept so that a step mixing executors allocates nothing.
    host_path: Option<HostPath>,
}

#[derive(Debug)]
struct HostPath {
    poses: GpuVec<BodyPose>,
    velocities: GpuVec<BodyVelocity>,
    colliders: GpuVec<ColliderData>,
    aabbs: GpuVec<Aabb>,
    /// Reused host buffer of packed colliders.
    data: Vec<ColliderData>,
}

impl GpuAabbs {
    pub fn new() -> Self {
        Self::default()
    }

    /// Encodes `aabbs[i]` for every body slot `i < poses.len()`; `aabbs` is resized to that
    /// length. One dispatch.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        poses: &GpuVec<BodyPose>,
        velocities: &GpuVec<BodyVelocity>,
        colliders: &GpuVec<ColliderData>,
        margin: f32,
        dt: f32,
        aabbs: &mut GpuVec<Aabb>,
    ) -> Result<(), GpuError> {
        let count = poses.len();
        debug_assert!(
            velocities.len() == count && colliders.len() == count,
            "one velocity and one collider per pose"
        );
        aabbs.resize(context, count)?;
        let key = (
            [
                poses.buffer().clone(),
                velocities.buffer().clone(),
                colliders.buffer().clone(),
                aabbs.buffer().clone(),
            ],
            count,
            margin.to_bits(),
            dt.to_bits(),
        );
        let dispatch = match &mut self.cached {
            Some((cached_key, dispatch)) if *cached_key == key => dispatch,
            cached => {
                let dispatch = build(context, &key.0, count, margin, dt);
                &mut cached.insert((key, dispatch)).1
            }
        };
        dispatch.encode(pass);
        Ok(())
    }

    /// Upload, encode, submit, download: the CPU executor's signature, for parity tests and
    /// for a step that runs this stage alone on the GPU.
    #[allow(clippy::too_many_arguments)] // the CPU executor's arguments and the context
    pub fn run(
        &mut self,
        context: &GpuContext,
        poses: &[BodyPose],
        velocities: &[BodyVelocity],
        colliders: &[Collider],
        margin: f32,
        dt: f32,
        aabbs: &mut Vec<Aabb>,
    ) -> Result<(), GpuError> {
        let mut host = match self.host_path.take() {
            Some(host) => host,
            None => HostPath {
                poses: GpuVec::with_capacity(context, "poses", poses.len())?,
                velocities: GpuVec::with_capacity(context, "velocities", poses.len())?,
                colliders: GpuVec::with_capacity(context, "colliders", poses.len())?,
                aabbs: GpuVec::with_capacity(context, "aabbs", poses.len())?,
                data: Vec::new(),
            },
        };
        host.data.clear();
        host.data.extend(colliders.iter().map(Collider::data));
        let result = (|| {
            host.poses.upload(context, poses)?;
            host.velocities.upload(context, velocities)?;
            host.colliders.upload(context, &host.data)?;
            context.submit_pass("aabbs", |pass| {
                self.encode(
                    context,
                    pass,
                    &host.poses,
                    &host.velocities,
                    &host.colliders,
                    margin,
                    dt,
                    &mut host.aabbs,
                )
            })?;
            host.aabbs.download_into(context, aabbs)
        })();
        self.host_path = Some(host);
        result
    }
}

fn build(
    context: &GpuContext,
    buffers: &[wgpu::Buffer; 4],
    count: usize,
    margin: f32,
    dt: f32,
) -> Dispatch {
    let kernel = Kernel::new(context, "world aabbs", &wgsl(), "world_aabbs", &BINDINGS);
    let slots = UniformSlots::new(
        context,
        "aabb params",
        &[AabbParams {
            count: count as u32,
            margin,
            dt,
            padding: 0,
        }],
    );
    let bind_group = kernel.bind(
        context,
        &[
            slots.binding(0),
            buffers[0].as_entire_buffer_binding(),
            buffers[1].as_entire_buffer_binding(),
            buffers[2].as_entire_buffer_binding(),
            buffers[3].as_entire_buffer_binding(),
        ],
    );
    kernel.dispatch(bind_group, workgroups_for(count, WORKGROUP_SIZE))
}
