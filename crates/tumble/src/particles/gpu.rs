//! GPU executor of the particle step: one submission per step, four measured passes
//! (hash, sort, cell start, collide): 19 dispatches at 1M particles with radix sort (hash;
//! 3 passes of histogram, 3-dispatch scan and scatter; fill and cell bounds; collide) and the
//! 27-cell search, 2 more with the 14-cell one.
//! Buffers, pipelines and bind groups are built in [`GpuParticles::new`]; a step only encodes.

use std::time::Instant;

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::bitonic_sort::BitonicSort;
use crate::gpu::prims::fill::fill_dispatch;
use crate::gpu::prims::radix_sort::RadixSort;
use crate::gpu::profiler::{GpuProfiler, SpanPath, record_copy};
use crate::particles::{CellSort, EMPTY_CELL, NeighbourSearch, Particle, ParticleConfig};
use crate::profile::Profiler;

pub(super) const COMMON_WGSL: &str = include_str!("common.wgsl");
const HASH_WGSL: &str = include_str!("hash.wgsl");
const CELL_BOUNDS_WGSL: &str = include_str!("cell_bounds.wgsl");
pub(super) const SEARCH_WGSL: &str = include_str!("search.wgsl");
const COLLIDE_WGSL: &str = include_str!("collide.wgsl");
const COLLIDE_SYMMETRIC_WGSL: &str = include_str!("collide_symmetric.wgsl");

const HASH: SpanPath = &["hash"];
const SORT: SpanPath = &["sort"];
const CELL_START: SpanPath = &["cell start"];
const COLLIDE: SpanPath = &["collide"];
const UPLOAD: SpanPath = &["copy particles to gpu"];
const DOWNLOAD: SpanPath = &["copy particles to host"];

/// The particle kernels' sources: shared part, then the kernel (for the layout test too).
pub fn wgsl(kernel: &str) -> Source {
    let text = match kernel {
        "hash" => HASH_WGSL,
        "cell_bounds" => CELL_BOUNDS_WGSL,
        "collide" => COLLIDE_WGSL,
        "collide_symmetric" => COLLIDE_SYMMETRIC_WGSL,
        _ => unreachable!("no particle kernel {kernel}"),
    };
    let source = Source::new()
        .constant_u32("EMPTY_CELL", EMPTY_CELL)
        .snippet("particles/common.wgsl", COMMON_WGSL);
    let source = match kernel {
        "collide" => source.snippet("particles/search.wgsl", SEARCH_WGSL),
        _ => source,
    };
    source.snippet(kernel, text)
}

/// Whether the largest buffers fit the adapter's bindings, without allocating anything.
pub(super) fn check_capacity(
    config: &ParticleConfig,
    context: &GpuContext,
) -> Result<(), GpuError> {
    let limits = context.device.limits();
    let limit = limits
        .max_buffer_size
        .min(limits.max_storage_buffer_binding_size);
    let needs = [
        (
            "particles",
            config.count as u64 * size_of::<Particle>() as u64,
        ),
        ("cell start", config.cell_count() * 4),
    ];
    for (what, needed) in needs {
        if needed > limit {
            return Err(GpuError::BufferTooLarge {
                what,
                needed,
                limit,
            });
        }
    }
    Ok(())
}

/// Stages 1–3 on the GPU (hash, sort, cell start) over a particle buffer, shared by the
/// particle demo and the rigid particle bodies.
#[derive(Debug)]
pub(super) struct GpuGrid {
    keys: GpuVec<u32>,
    ids: GpuVec<u32>,
    sorted_keys: GpuVec<u32>,
    sorted_ids: GpuVec<u32>,
    /// The particles in sorted order, as the collide stage reads them.
    pub sorted_particles: GpuVec<Particle>,
    pub cell_start: GpuVec<u32>,
    pub cell_end: GpuVec<u32>,
    /// The [`ParticleParams`](crate::particles::ParticleParams) block, binding 0 of every
    /// particle kernel.
    pub params: UniformSlots,
    sort: CellSort,
    key_bits: u32,
    radix: RadixSort,
    bitonic: BitonicSort,
    hash: Vec<Dispatch>,
    cell_start_dispatches: Vec<Dispatch>,
}

impl GpuGrid {
    pub fn new(
        config: &ParticleConfig,
        context: &GpuContext,
        particles: &GpuVec<Particle>,
    ) -> Result<Self, GpuError> {
        let count = config.count;
        let cells = config.cell_count() as usize;
        let sorted_particles =
            GpuVec::<Particle>::with_capacity(context, "sorted particles", count)?;
        let mut keys = GpuVec::<u32>::with_capacity(context, "cell keys", count)?;
        let mut ids = GpuVec::<u32>::with_capacity(context, "particle ids", count)?;
        keys.resize(context, count)?;
        ids.resize(context, count)?;
        let mut sorted_keys = GpuVec::<u32>::with_capacity(context, "sorted cell keys", count)?;
        let mut sorted_ids = GpuVec::<u32>::with_capacity(context, "sorted particle ids", count)?;
        sorted_keys.resize(context, count)?;
        sorted_ids.resize(context, count)?;
        let cell_start = GpuVec::<u32>::with_capacity(context, "cell start", cells)?;
        let cell_end = GpuVec::<u32>::with_capacity(context, "cell end", cells)?;
        let params = UniformSlots::new(context, "particle params", &[config.params()]);
        // Bitonic sorts in place: the later stages then read the hash output itself.
        let (sorted_keys_buffer, sorted_ids_buffer) = match config.sort {
            CellSort::Radix => (sorted_keys.buffer(), sorted_ids.buffer()),
            CellSort::Bitonic => (keys.buffer(), ids.buffer()),
        };
        let groups = workgroups_for(count, WORKGROUP_SIZE);
        let kernel = |name: &str, bindings: &[Binding]| {
            Kernel::new(context, name, &wgsl(name), name, bindings)
        };
        use Binding::{StorageRead as Read, StorageReadWrite as Write, Uniform};
        let hash_kernel = kernel("hash", &[Uniform, Read, Write, Write]);
        let hash = vec![hash_kernel.dispatch(
            hash_kernel.bind(
                context,
                &[
                    params.binding(0),
                    particles.whole(),
                    keys.whole(),
                    ids.whole(),
                ],
            ),
            groups,
        )];
        let bounds_kernel = kernel(
            "cell_bounds",
            &[Uniform, Read, Read, Read, Write, Write, Write],
        );
        let mut cell_start_dispatches =
            fill_dispatch(context, cell_start.buffer(), cells, EMPTY_CELL)?;
        cell_start_dispatches.push(bounds_kernel.dispatch(
            bounds_kernel.bind(
                context,
                &[
                    params.binding(0),
                    sorted_keys_buffer.as_entire_buffer_binding(),
                    sorted_ids_buffer.as_entire_buffer_binding(),
                    particles.whole(),
                    sorted_particles.whole(),
                    cell_start.whole(),
                    cell_end.whole(),
                ],
            ),
            groups,
        ));
        // Cell ids are below cell_count: only that many bits need sorting.
        let key_bits = u32::BITS - (config.cell_count().saturating_sub(1) as u32).leading_zeros();
        Ok(Self {
            keys,
            ids,
            sorted_keys,
            sorted_ids,
            sorted_particles,
            cell_start,
            cell_end,
            params,
            sort: config.sort,
            key_bits,
            radix: RadixSort::new(),
            bitonic: BitonicSort::new(),
            hash,
            cell_start_dispatches,
        })
    }

    /// Each sorted slot's particle id (where the sort left them).
    pub fn sorted_ids(&self) -> wgpu::BufferBinding<'_> {
        match self.sort {
            CellSort::Radix => self.sorted_ids.whole(),
            CellSort::Bitonic => self.ids.whole(),
        }
    }

    /// Encodes the three stages, one measured pass each.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        profiler: &mut GpuProfiler,
        timing: bool,
    ) -> Result<(), GpuError> {
        encode_all(&mut begin_pass(encoder, profiler, timing, HASH), &self.hash);
        {
            let mut sort_pass = begin_pass(encoder, profiler, timing, SORT);
            match self.sort {
                CellSort::Radix => self.radix.encode(
                    context,
                    &mut sort_pass,
                    (&self.keys, &self.ids),
                    (&mut self.sorted_keys, &mut self.sorted_ids),
                    self.key_bits,
                )?,
                CellSort::Bitonic => {
                    self.bitonic
                        .encode(context, &mut sort_pass, &mut self.keys, &mut self.ids)?
                }
            }
        }
        encode_all(
            &mut begin_pass(encoder, profiler, timing, CELL_START),
            &self.cell_start_dispatches,
        );
        Ok(())
    }
}

#[derive(Debug)]
pub(super) struct GpuParticles {
    context: GpuContext,
    count: usize,
    particles: GpuVec<Particle>,
    grid: GpuGrid,
    collide: Vec<Dispatch>,
    profiler: GpuProfiler,
    timing: bool,
}

impl GpuParticles {
    /// Uploads `initial`, timed as a copy in `profiler` (the run's only host→device copy: a
    /// step reads and writes device memory alone).
    pub fn new(
        config: &ParticleConfig,
        context: GpuContext,
        initial: &[Particle],
        profiler: &mut Profiler,
    ) -> Result<Self, GpuError> {
        let count = config.count;
        let start = Instant::now();
        let particles = GpuVec::from_slice(&context, "particles", initial)?;
        record_copy(profiler, UPLOAD, start.elapsed().as_secs_f64() * 1e3);
        let grid = GpuGrid::new(config, &context, &particles)?;
        let params = grid.params.binding(0);
        let groups = workgroups_for(count, WORKGROUP_SIZE);
        use Binding::{StorageRead as Read, StorageReadWrite as Write, Uniform};
        let collide = match config.search {
            NeighbourSearch::Full27 => {
                let collide_kernel = Kernel::new(
                    &context,
                    "collide",
                    &wgsl("collide"),
                    "collide",
                    &[Uniform, Read, Read, Read, Read, Write],
                );
                let bindings = [
                    params,
                    grid.sorted_particles.whole(),
                    grid.sorted_ids(),
                    grid.cell_start.whole(),
                    grid.cell_end.whole(),
                    particles.whole(),
                ];
                vec![collide_kernel.dispatch(collide_kernel.bind(&context, &bindings), groups)]
            }
            NeighbourSearch::Symmetric14 => {
                let forces = GpuVec::<[i32; 3]>::with_capacity(&context, "pair forces", count)?;
                let layout = [Uniform, Read, Read, Read, Read, Write, Write];
                let source = wgsl("collide_symmetric");
                let pairs_kernel =
                    Kernel::new(&context, "collide pairs", &source, "collide_pairs", &layout);
                let integrate_kernel = Kernel::new(
                    &context,
                    "integrate forces",
                    &source,
                    "integrate_forces",
                    &layout,
                );
                let bindings = [
                    params,
                    grid.sorted_particles.whole(),
                    grid.sorted_ids(),
                    grid.cell_start.whole(),
                    grid.cell_end.whole(),
                    particles.whole(),
                    forces.whole(),
                ];
                let mut dispatches = fill_dispatch(&context, forces.buffer(), 3 * count, 0)?;
                dispatches.extend([
                    pairs_kernel.dispatch(pairs_kernel.bind(&context, &bindings), groups),
                    integrate_kernel.dispatch(integrate_kernel.bind(&context, &bindings), groups),
                ]);
                dispatches
            }
        };
        let profiler = GpuProfiler::new(&context, 4);
        Ok(Self {
            context,
            count,
            particles,
            grid,
            collide,
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
                label: Some("particles step"),
            });
        let timing = self.timing;
        self.grid
            .encode(context, &mut encoder, &mut self.profiler, timing)?;
        encode_all(
            &mut begin_pass(&mut encoder, &mut self.profiler, timing, COLLIDE),
            &self.collide,
        );
        if timing {
            self.profiler.resolve(&mut encoder);
        }
        context.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Downloads the particles (waits for the GPU), timed as a copy.
    pub fn download(&mut self, profiler: &mut Profiler) -> Result<Vec<Particle>, GpuError> {
        let start = Instant::now();
        let particles = self.particles.download(&self.context)?;
        record_copy(profiler, DOWNLOAD, start.elapsed().as_secs_f64() * 1e3);
        debug_assert_eq!(particles.len(), self.count);
        Ok(particles)
    }
}

/// A compute pass for one stage, measured when `timing`.
pub(super) fn begin_pass<'encoder>(
    encoder: &'encoder mut wgpu::CommandEncoder,
    profiler: &mut GpuProfiler,
    timing: bool,
    path: SpanPath,
) -> wgpu::ComputePass<'encoder> {
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(path[0]),
        timestamp_writes: if timing {
            profiler.pass_timestamps(path)
        } else {
            None
        },
    })
}
