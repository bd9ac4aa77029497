//! GPU executor of the rigid particle bodies: one submission per step, six measured passes
//! (world particles; the particle demo's hash, sort and cell start; collide; bodies).

use std::time::Instant;

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::profiler::{GpuProfiler, SpanPath, record_copy};
use crate::particles::gpu::{COMMON_WGSL, GpuGrid, SEARCH_WGSL, begin_pass};
use crate::particles::rigid::{Flat, RigidBody};
use crate::particles::rigid_cpu::BODY_LANES;
use crate::particles::{EMPTY_CELL, Particle};
use crate::profile::Profiler;

const RIGID_COMMON_WGSL: &str = include_str!("rigid_common.wgsl");
const WORLD_WGSL: &str = include_str!("rigid_world.wgsl");
const COLLIDE_WGSL: &str = include_str!("rigid_collide.wgsl");
const BODIES_WGSL: &str = include_str!("rigid_bodies.wgsl");

const WORLD: SpanPath = &["world particles"];
const COLLIDE: SpanPath = &["collide"];
const BODIES: SpanPath = &["bodies"];
const DOWNLOAD: SpanPath = &["copy bodies to host"];

/// The rigid kernels' sources: the particle kernels' shared part, the rigid one, the kernel.
pub fn wgsl(kernel: &str) -> Source {
    let text = match kernel {
        "rigid_world" => WORLD_WGSL,
        "rigid_collide" => COLLIDE_WGSL,
        "rigid_bodies" => BODIES_WGSL,
        _ => unreachable!("no rigid particle kernel {kernel}"),
    };
    let source = Source::new()
        .constant_u32("EMPTY_CELL", EMPTY_CELL)
        .constant_u32("BODY_LANES", BODY_LANES as u32)
        .snippet("particles/common.wgsl", COMMON_WGSL)
        .snippet("particles/rigid_common.wgsl", RIGID_COMMON_WGSL);
    let source = match kernel {
        "rigid_collide" => source.snippet("particles/search.wgsl", SEARCH_WGSL),
        _ => source,
    };
    source.snippet(kernel, text)
}

#[derive(Debug)]
pub(super) struct GpuRigid {
    context: GpuContext,
    bodies: GpuVec<RigidBody>,
    grid: GpuGrid,
    world: Vec<Dispatch>,
    collide: Vec<Dispatch>,
    integrate: Vec<Dispatch>,
    profiler: GpuProfiler,
    timing: bool,
}

impl GpuRigid {
    pub fn new(flat: &Flat, context: GpuContext) -> Result<Self, GpuError> {
        // The buffers' sizes were checked against the device by RigidSystem::new.
        let config = &flat.particles;
        let count = config.count;
        let bodies = GpuVec::from_slice(&context, "rigid bodies", &flat.bodies)?;
        let infos = GpuVec::from_slice(&context, "rigid body constants", &flat.info)?;
        let offsets = GpuVec::from_slice(&context, "particle offsets", &flat.offsets)?;
        let mut particles = GpuVec::<Particle>::with_capacity(&context, "particles", count)?;
        particles.resize(&context, count)?;
        let mut forces = GpuVec::<[f32; 4]>::with_capacity(&context, "particle forces", count)?;
        forces.resize(&context, count)?;
        let grid = GpuGrid::new(config, &context, &particles)?;
        let rigid_params = UniformSlots::new(&context, "rigid params", &[flat.rigid_params()]);
        let particle_groups = workgroups_for(count, WORKGROUP_SIZE);
        // A workgroup per body.
        let body_groups = u32::try_from(flat.bodies.len()).expect("body count fits in u32");
        let kernel = |name: &str, bindings: &[Binding]| {
            Kernel::new(&context, name, &wgsl(name), name, bindings)
        };
        use Binding::{StorageRead as Read, StorageReadWrite as Write, Uniform};
        let params = || grid.params.binding(0);
        let world_kernel = kernel("rigid_world", &[Uniform, Read, Read, Write]);
        let world = vec![world_kernel.dispatch(
            world_kernel.bind(
                &context,
                &[params(), bodies.whole(), offsets.whole(), particles.whole()],
            ),
            particle_groups,
        )];
        let collide_kernel = kernel("rigid_collide", &[Uniform, Read, Read, Read, Read, Write]);
        let collide = vec![collide_kernel.dispatch(
            collide_kernel.bind(
                &context,
                &[
                    params(),
                    grid.sorted_particles.whole(),
                    grid.sorted_ids(),
                    grid.cell_start.whole(),
                    grid.cell_end.whole(),
                    forces.whole(),
                ],
            ),
            particle_groups,
        )];
        let bodies_kernel = kernel("rigid_bodies", &[Uniform, Uniform, Write, Read, Read, Read]);
        let integrate = vec![bodies_kernel.dispatch(
            bodies_kernel.bind(
                &context,
                &[
                    params(),
                    rigid_params.binding(0),
                    bodies.whole(),
                    infos.whole(),
                    offsets.whole(),
                    forces.whole(),
                ],
            ),
            body_groups,
        )];
        let profiler = GpuProfiler::new(&context, 6);
        Ok(Self {
            context,
            bodies,
            grid,
            world,
            collide,
            integrate,
            profiler,
            timing: false,
        })
    }

    pub fn context(&self) -> &GpuContext {
        &self.context
    }

    pub fn set_timing(&mut self, enabled: bool) {
        self.timing = enabled && self.profiler.is_active();
    }

    pub fn step(&mut self, profiler: &mut Profiler) -> Result<(), GpuError> {
        profiler.begin("encode and submit");
        let result = self.encode_and_submit();
        profiler.end();
        result?;
        if self.timing {
            self.profiler.collect(&self.context, profiler)?;
        }
        Ok(())
    }

    fn encode_and_submit(&mut self) -> Result<(), GpuError> {
        let context = &self.context;
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("rigid particles step"),
            });
        let timing = self.timing;
        encode_all(
            &mut begin_pass(&mut encoder, &mut self.profiler, timing, WORLD),
            &self.world,
        );
        self.grid
            .encode(context, &mut encoder, &mut self.profiler, timing)?;
        encode_all(
            &mut begin_pass(&mut encoder, &mut self.profiler, timing, COLLIDE),
            &self.collide,
        );
        encode_all(
            &mut begin_pass(&mut encoder, &mut self.profiler, timing, BODIES),
            &self.integrate,
        );
        if timing {
            self.profiler.resolve(&mut encoder);
        }
        context.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Downloads the bodies (waits for the GPU), timed as a copy.
    pub fn download_bodies(&mut self, profiler: &mut Profiler) -> Result<Vec<RigidBody>, GpuError> {
        let start = Instant::now();
        let bodies = self.bodies.download(&self.context)?;
        record_copy(profiler, DOWNLOAD, start.elapsed().as_secs_f64() * 1e3);
        Ok(bodies)
    }
}
