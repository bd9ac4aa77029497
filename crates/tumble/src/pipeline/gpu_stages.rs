//! The world's GPU side: the adapter, the GPU executors of the stages that
//! [`StageDevices`](crate::pipeline::devices::StageDevices) puts there, and device copies of
//! the arrays they read and write.
//!
//! A GPU stage here runs between CPU stages: it uploads the inputs the host changed, runs its
//! kernels, waits, and downloads its outputs, so the host arrays stay the world's state. Each
//! transfer is a copy line in the profile under the stage (`copy to gpu`, `copy to cpu`), as in
//! the talk's profiles; the kernels' own time is a `gpu` line when the adapter has timestamps.
//! Bodies' colliders and masses change only when bodies come and go: they are uploaded again
//! only then.

use std::time::Instant;

use crate::dynamics::body::{BodyPose, BodyVelocity, Collider, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::profiler::{GpuProfiler, SpanPath, record_copy};
use crate::pipeline::devices::Stage;
use crate::profile::Profiler;
use crate::stages::narrowphase::gpu::{GpuNarrowphase, GpuNarrowphaseInputs};
use crate::stages::narrowphase::{NarrowphaseInputs, PairContact};

const NARROWPHASE_UPLOAD: SpanPath = &["narrowphase", "copy to gpu"];
const NARROWPHASE_KERNEL: SpanPath = &["narrowphase", "kernel"];
const NARROWPHASE_DOWNLOAD: SpanPath = &["narrowphase", "copy to cpu"];

/// Device copies of the body arrays, shared by the GPU stages.
struct DeviceBodies {
    poses: GpuVec<BodyPose>,
    velocities: GpuVec<BodyVelocity>,
    colliders: GpuVec<ColliderData>,
    /// The host's colliders changed since the last upload.
    colliders_stale: bool,
}

pub(crate) struct GpuStages {
    context: GpuContext,
    profiler: GpuProfiler,
    bodies: DeviceBodies,
    narrowphase: GpuNarrowphase,
    /// The narrowphase's inputs and output on the device.
    keys: GpuVec<u64>,
    old_index: GpuVec<u32>,
    old_contacts: GpuVec<PairContact>,
    contacts: GpuVec<PairContact>,
    skipped: GpuVec<u64>,
    /// Host scratch, reused: the identity map, the packed colliders, downloaded contacts.
    identity: Vec<u32>,
    collider_data: Vec<ColliderData>,
    downloaded: Vec<PairContact>,
}

impl GpuStages {
    /// The GPU side on the process's shared adapter (`GpuContext::shared`).
    pub fn new() -> Result<Self, GpuError> {
        let context = GpuContext::shared()?;
        Ok(Self {
            profiler: GpuProfiler::new(&context, 8),
            bodies: DeviceBodies {
                poses: GpuVec::with_capacity(&context, "poses", 0)?,
                velocities: GpuVec::with_capacity(&context, "velocities", 0)?,
                colliders: GpuVec::with_capacity(&context, "colliders", 0)?,
                colliders_stale: true,
            },
            narrowphase: GpuNarrowphase::new(&context),
            keys: GpuVec::with_capacity(&context, "pair keys", 0)?,
            old_index: GpuVec::with_capacity(&context, "old pair index", 0)?,
            old_contacts: GpuVec::with_capacity(&context, "old contacts", 0)?,
            contacts: GpuVec::with_capacity(&context, "contacts", 0)?,
            skipped: GpuVec::with_capacity(&context, "jointed pairs", 0)?,
            identity: Vec::new(),
            collider_data: Vec::new(),
            downloaded: Vec::new(),
            context,
        })
    }

    /// Whether `stage` has a GPU executor.
    pub fn runs(stage: Stage) -> bool {
        matches!(stage, Stage::Narrowphase)
    }

    /// A one-line description of the adapter, for reports.
    pub fn describe(&self) -> String {
        self.context.describe()
    }

    /// Bodies were added or removed: upload the colliders again before the next GPU stage.
    pub fn colliders_changed(&mut self) {
        self.bodies.colliders_stale = true;
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
        upload_bodies(context, &mut self.bodies, &mut self.collider_data, inputs)?;
        record_copy(profiler, NARROWPHASE_UPLOAD, elapsed_ms(start));

        let start = Instant::now();
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("narrowphase"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("narrowphase"),
                timestamp_writes: self.profiler.pass_timestamps(NARROWPHASE_KERNEL),
            });
            let device_inputs = GpuNarrowphaseInputs {
                keys: &self.keys,
                old_index: &self.old_index,
                old_contacts: &self.old_contacts,
                poses: &self.bodies.poses,
                velocities: &self.bodies.velocities,
                colliders: &self.bodies.colliders,
                skipped: &self.skipped,
                margin: inputs.margin,
                dt: inputs.dt,
            };
            self.narrowphase
                .encode(context, &mut pass, &device_inputs, &mut self.contacts)?;
        }
        self.profiler.resolve(&mut encoder);
        context.queue.submit([encoder.finish()]);
        context.wait()?;
        profiler.record(
            &["narrowphase", "encode, submit and wait"],
            crate::profile::SpanKind::Cpu,
            elapsed_ms(start),
        );
        self.profiler.collect(context, profiler)?;

        let start = Instant::now();
        self.contacts.download_into(context, &mut self.downloaded)?;
        contacts.copy_from_slice(&self.downloaded);
        record_copy(profiler, NARROWPHASE_DOWNLOAD, elapsed_ms(start));
        Ok(())
    }
}

/// Uploads poses and velocities, and the colliders when they changed.
fn upload_bodies(
    context: &GpuContext,
    bodies: &mut DeviceBodies,
    collider_data: &mut Vec<ColliderData>,
    inputs: &NarrowphaseInputs,
) -> Result<(), GpuError> {
    bodies.poses.upload(context, inputs.poses)?;
    bodies.velocities.upload(context, inputs.velocities)?;
    if bodies.colliders_stale || bodies.colliders.len() != inputs.colliders.len() {
        collider_data.clear();
        collider_data.extend(inputs.colliders.iter().map(Collider::data));
        bodies.colliders.upload(context, collider_data)?;
        bodies.colliders_stale = false;
    }
    Ok(())
}

fn elapsed_ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
