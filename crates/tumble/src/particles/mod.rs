//! The uniform-grid particle system of the NVIDIA SDK particle demo, as in the talk's first
//! half: every step
//!
//! 1. **hash**: each particle's cell id (cells are one particle diameter wide, so every
//!    contact lies within the 27 cells around a particle's own);
//! 2. **sort** (cell id, particle id) pairs by cell: stable radix sort, or bitonic sort (the
//!    talk's alternative; it orders ties by particle id, which gives the same result);
//! 3. **cell start / end**: where each cell's run begins and ends in the sorted array, and
//!    the particles copied into sorted order (coherent reads in the next stage);
//! 4. **collide**: each particle searches the 27 neighbour cells and sums spring–damper (DEM)
//!    forces as it goes — no neighbour list is stored — then integrates (semi-implicit Euler).
//!    Jacobi: every interaction reads the state before the step, so the order in which
//!    particles are processed does not matter. The symmetric 14-cell search is the
//!    alternative: each pair is visited once and its force goes to both particles, summed in
//!    fixed point so that the total does not depend on the order of the additions (on the
//!    GPU they are atomic adds in whatever order threads run).
//!
//! The box is the grid: walls at its faces, the ground at its bottom, all spring–dampers.
//! Both executors run the same algorithm on the same `#[repr(C)]` data ([`Particle`],
//! [`ParticleParams`]); the GPU one encodes a whole step in one submission with no readback.

mod cpu;
pub mod explain;
mod gpu;
mod host_memory;
pub mod rigid;
mod rigid_cpu;
mod rigid_gpu;

pub use rigid::{
    BodyInfo, Ellipsoid, MAX_BODIES, RigidBody, RigidConfig, RigidParams, RigidSystem, Solid,
    VoxelShape, voxelize,
};

use bytemuck::{Pod, Zeroable};

use crate::gpu::{GpuContext, GpuError};
use crate::profile::Profiler;

/// One particle, as stored on both devices (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Particle {
    /// Centre (m); `w` is unused (0), there so the GPU reads one aligned `vec4`.
    pub position: [f32; 4],
    /// Velocity (m/s); `w` unused (0).
    pub velocity: [f32; 4],
}
const _: () = assert!(size_of::<Particle>() == 32);

/// How a particle finds the particles it touches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NeighbourSearch {
    /// Every particle searches its own and the 26 surrounding cells (both executors).
    Full27,
    /// Each pair is visited once: a particle searches its own cell (later particles only)
    /// and the 13 neighbour cells with a smaller index, and the force goes to both
    /// particles. Half the distance tests, but forces are summed in fixed point (see
    /// [`ParticleConfig::force_quantum`]) and the GPU needs atomics and one more dispatch.
    Symmetric14,
}

/// Which sort orders the particles by cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellSort {
    Radix,
    Bitonic,
}

/// Where the step runs.
#[derive(Clone, Debug)]
pub enum ParticleDevice {
    Cpu,
    Gpu(GpuContext),
}

/// Scene and material parameters. Units: SI.
#[derive(Clone, Debug)]
pub struct ParticleConfig {
    /// Number of particles.
    pub count: usize,
    /// Particle radius (m), > 0. Grid cells are 2·radius wide.
    pub radius: f32,
    /// Cells along x, y, z (each ≥ 1). The box spans the grid.
    pub grid: [u32; 3],
    /// Minimum corner of the box (m).
    pub origin: [f32; 3],
    /// Time step (s), > 0. Stable while dt·sqrt(spring / mass) stays well below 1.
    pub dt: f32,
    /// Gravity (m/s²). Default (0, −9.81, 0).
    pub gravity: [f32; 3],
    /// Mass of a particle (kg), > 0.
    pub mass: f32,
    /// Contact stiffness between particles (N/m).
    pub spring: f32,
    /// Damping of the normal relative velocity in a contact (N·s/m).
    pub damping: f32,
    /// Damping of the tangential relative velocity in a contact (N·s/m): a simple friction.
    pub shear: f32,
    /// Stiffness of the walls and the ground (N/m).
    pub wall_spring: f32,
    /// Damping of the velocity into a wall (N·s/m).
    pub wall_damping: f32,
    pub search: NeighbourSearch,
    pub sort: CellSort,
}

impl ParticleConfig {
    /// The demo scene: `count` particles in a jittered block in the upper middle of a box
    /// about twice the block's width, falling and spreading over the ground.
    pub fn demo(count: usize) -> Self {
        let side = (count as f64).cbrt().ceil().max(1.0) as u32;
        Self {
            count,
            radius: 0.5,
            grid: [side * 3 / 2 + 2, side * 2 + 2, side * 3 / 2 + 2],
            origin: [0.0; 3],
            dt: 1.0 / 240.0,
            gravity: [0.0, -9.81, 0.0],
            mass: 1.0,
            spring: 2000.0,
            damping: 4.0,
            shear: 0.5,
            wall_spring: 4000.0,
            wall_damping: 4.0,
            search: NeighbourSearch::Full27,
            sort: CellSort::Radix,
        }
    }

    /// Side of a grid cell (m): one particle diameter.
    pub fn cell_size(&self) -> f32 {
        2.0 * self.radius
    }

    pub fn cell_count(&self) -> u64 {
        self.grid.iter().map(|&cells| u64::from(cells)).product()
    }

    /// Checks the parameters; every error names the field and what it must be.
    pub fn validate(&self) -> Result<(), ParticleError> {
        // First: a demo config for too many particles also has too many cells, and the count
        // is what the user asked for.
        if self.count > MAX_PARTICLES {
            return Err(ParticleError::TooManyParticles {
                count: self.count,
                max: MAX_PARTICLES,
            });
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(ParticleError::Radius(self.radius));
        }
        if self.grid.contains(&0) {
            return Err(ParticleError::EmptyGrid(self.grid));
        }
        if self.cell_count() >= u64::from(EMPTY_CELL) {
            return Err(ParticleError::GridTooLarge(self.grid));
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(ParticleError::TimeStep(self.dt));
        }
        if !(self.mass.is_finite() && self.mass > 0.0) {
            return Err(ParticleError::Mass(self.mass));
        }
        let coefficients = [
            ("spring", self.spring),
            ("damping", self.damping),
            ("shear", self.shear),
            ("wall_spring", self.wall_spring),
            ("wall_damping", self.wall_damping),
        ];
        for (name, value) in coefficients {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ParticleError::Coefficient { name, value });
            }
        }
        if self
            .origin
            .iter()
            .chain(&self.gravity)
            .any(|v| !v.is_finite())
        {
            return Err(ParticleError::NotFinite);
        }
        Ok(())
    }

    /// The block layout of [`demo`](Self::demo): particles on a lattice one diameter apart,
    /// jittered by up to 1 % of the radius (deterministically) so that stacks topple, in the
    /// upper middle of the box, at rest. An iterator, so that the caller chooses how to
    /// allocate (fallibly, for [`ParticleSystem::new`]).
    pub fn initial_particles(&self) -> impl ExactSizeIterator<Item = Particle> + '_ {
        let side = (self.count as f64).cbrt().ceil().max(1.0) as usize;
        let spacing = self.cell_size();
        let [cells_x, cells_y, cells_z] = self.grid.map(|cells| cells as f32 * spacing);
        let start = [
            self.origin[0] + 0.5 * (cells_x - side as f32 * spacing) + self.radius,
            self.origin[1] + cells_y - side as f32 * spacing - self.radius,
            self.origin[2] + 0.5 * (cells_z - side as f32 * spacing) + self.radius,
        ];
        (0..self.count).map(move |index| {
            let lattice = [index % side, (index / side) % side, index / (side * side)];
            let jitter = |axis: usize| {
                // A small integer hash of (index, axis): deterministic, no dependency.
                let mut bits = (index as u32).wrapping_mul(0x9E37_79B9) ^ (axis as u32 + 1);
                bits ^= bits >> 15;
                bits = bits.wrapping_mul(0x2C1B_3C6D);
                bits ^= bits >> 12;
                ((bits & 0xffff) as f32 / 65535.0 - 0.5) * 0.02 * self.radius
            };
            let position = [0, 1, 2].map(|axis| {
                let coordinate = start[axis] + lattice[axis] as f32 * spacing + jitter(axis);
                // Keep inside the box whatever the count.
                let low = self.origin[axis] + self.radius;
                let high = self.origin[axis] + self.grid[axis] as f32 * spacing - self.radius;
                coordinate.clamp(low, high.max(low))
            });
            Particle {
                position: [position[0], position[1], position[2], 0.0],
                velocity: [0.0; 4],
            }
        })
    }

    /// Resolution (N) of the fixed-point force sums of the symmetric search: a power of two
    /// about 2⁻²⁰ of the force of a full overlap. Each pair force is clamped to 2²⁶ quanta
    /// (64 full-overlap forces), so even 32 contacts cannot overflow the i32 sums.
    pub fn force_quantum(&self) -> f32 {
        let full_overlap = self.spring * self.cell_size()
            + self.mass * self.gravity.iter().map(|g| g.abs()).sum::<f32>();
        let exponent = full_overlap.max(1e-6).log2().ceil() as i32 - 20;
        2f32.powi(exponent)
    }

    /// The parameter block both executors read.
    pub fn params(&self) -> ParticleParams {
        ParticleParams {
            origin: self.origin,
            cell_size: self.cell_size(),
            grid: self.grid,
            count: self.count as u32,
            gravity: self.gravity,
            dt: self.dt,
            radius: self.radius,
            inverse_mass: 1.0 / self.mass,
            spring: self.spring,
            damping: self.damping,
            shear: self.shear,
            wall_spring: self.wall_spring,
            wall_damping: self.wall_damping,
            cell_count: self.cell_count() as u32,
            force_scale: 1.0 / self.force_quantum(),
            force_quantum: self.force_quantum(),
            padding0: 0,
            padding1: 0,
        }
    }
}

/// The composed WGSL of the particle kernels (hash, cell bounds, collide, collide symmetric),
/// then of the rigid particle kernels (world particles, collide, bodies), for tools and for
/// the layout test.
pub fn kernel_sources() -> [crate::gpu::kernel::Source; 7] {
    let [hash, cell_bounds, collide, collide_symmetric] =
        ["hash", "cell_bounds", "collide", "collide_symmetric"].map(gpu::wgsl);
    let [world, rigid_collide, bodies] =
        ["rigid_world", "rigid_collide", "rigid_bodies"].map(rigid_gpu::wgsl);
    [
        hash,
        cell_bounds,
        collide,
        collide_symmetric,
        world,
        rigid_collide,
        bodies,
    ]
}

/// Most particles a system takes: ids are u32 and sorted ids fit a u32 buffer index.
pub const MAX_PARTICLES: usize = (u32::MAX / 2) as usize;

/// `cell_start` of a cell with no particle.
pub const EMPTY_CELL: u32 = u32::MAX;

/// Mirrors `ParticleParams` in `particles.wgsl` (WGSL aligns `vec3` to 16 bytes, so each
/// 3-vector is followed by a scalar).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ParticleParams {
    pub origin: [f32; 3],
    pub cell_size: f32,
    pub grid: [u32; 3],
    pub count: u32,
    pub gravity: [f32; 3],
    pub dt: f32,
    pub radius: f32,
    pub inverse_mass: f32,
    pub spring: f32,
    pub damping: f32,
    pub shear: f32,
    pub wall_spring: f32,
    pub wall_damping: f32,
    pub cell_count: u32,
    /// Fixed-point quanta per newton (symmetric search), and its inverse.
    pub force_scale: f32,
    pub force_quantum: f32,
    pub padding0: u32,
    pub padding1: u32,
}
const _: () = assert!(size_of::<ParticleParams>() == 96);

#[derive(Clone, Debug, thiserror::Error)]
pub enum ParticleError {
    #[error("particle radius must be a finite number > 0 (got {0})")]
    Radius(f32),
    #[error("the grid must have at least one cell along each axis (got {0:?})")]
    EmptyGrid([u32; 3]),
    #[error("the grid {0:?} has too many cells: at most 2³² − 2 in all")]
    GridTooLarge([u32; 3]),
    #[error("the time step dt must be a finite number > 0 (got {0})")]
    TimeStep(f32),
    #[error("the particle mass must be a finite number > 0 (got {0})")]
    Mass(f32),
    #[error("{name} must be a finite number ≥ 0 (got {value})")]
    Coefficient { name: &'static str, value: f32 },
    #[error("origin and gravity must be finite")]
    NotFinite,
    #[error("{count} particles is more than the {max} a system can hold")]
    TooManyParticles { count: usize, max: usize },
    #[error(
        "{count} particles need {bytes} bytes ({needed_gb:.1} GB) of host memory, but \
         {available} bytes ({available_gb:.1} GB) are available (free memory, reclaimable \
         cache and swap); use fewer particles",
        needed_gb = gigabytes(.bytes),
        available_gb = gigabytes(.available)
    )]
    HostMemory {
        count: usize,
        bytes: u64,
        available: u64,
    },
    #[error(
        "the host refused to allocate the {bytes} bytes ({gb:.1} GB) that {count} particles \
         need; use fewer particles",
        gb = gigabytes(.bytes)
    )]
    HostAllocation { count: usize, bytes: u64 },
    #[error(
        "{bodies} bodies of {particles} particles in all need {bytes} bytes ({needed_gb:.1} GB) \
         of host memory, but {available} bytes ({available_gb:.1} GB) are available (free \
         memory, reclaimable cache and swap); use fewer bodies",
        needed_gb = gigabytes(.bytes),
        available_gb = gigabytes(.available)
    )]
    BodyHostMemory {
        bodies: usize,
        particles: usize,
        bytes: u64,
        available: u64,
    },
    #[error(
        "the host refused to allocate the {bytes} bytes ({gb:.1} GB) that {bodies} bodies of \
         {particles} particles in all need; use fewer bodies",
        gb = gigabytes(.bytes)
    )]
    BodyHostAllocation {
        bodies: usize,
        particles: usize,
        bytes: u64,
    },
    #[error("{given} initial particles were given for a system of {expected}")]
    ParticleCount { given: usize, expected: usize },
    #[error("a body must have at least one particle (its shape is empty at this radius)")]
    EmptyBody,
    #[error("body {body} names shape {shape}, but there are {shapes} shapes")]
    ShapeIndex {
        body: usize,
        shape: usize,
        shapes: usize,
    },
    #[error("body {0}'s state must be finite with a unit orientation quaternion")]
    BodyState(usize),
    #[error("voxelizing this shape at this radius visits {points} lattice points, more than {max}")]
    VoxelLattice { points: usize, max: usize },
    #[error("{count} bodies is more than the {max} a system can hold")]
    TooManyBodies { count: usize, max: usize },
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// For messages: 1 GB = 10⁹ bytes.
fn gigabytes(bytes: &u64) -> f64 {
    *bytes as f64 / 1e9
}

/// The particle system on one device.
#[derive(Debug)]
pub struct ParticleSystem {
    config: ParticleConfig,
    executor: Executor,
    profiler: Profiler,
}

#[derive(Debug)]
enum Executor {
    Cpu(Box<cpu::CpuParticles>),
    Gpu(Box<gpu::GpuParticles>),
}

impl ParticleSystem {
    /// A system with the config's [`initial_particles`](ParticleConfig::initial_particles).
    pub fn new(config: ParticleConfig, device: ParticleDevice) -> Result<Self, ParticleError> {
        config.validate()?;
        // Before building a possibly huge host array: does the device have room? The host
        // holds the initial particles, and on the CPU the executor's arrays too.
        let executor_bytes = match &device {
            ParticleDevice::Gpu(context) => {
                gpu::check_capacity(&config, context)?;
                0
            }
            ParticleDevice::Cpu => cpu::CpuParticles::bytes(&config),
        };
        let bytes = config.count as u64 * size_of::<Particle>() as u64 + executor_bytes;
        host_memory::check(config.count, bytes, host_memory::available())?;
        let refused = |_| ParticleError::HostAllocation {
            count: config.count,
            bytes,
        };
        let mut particles = host_memory::try_with_capacity(config.count).map_err(refused)?;
        particles.extend(config.initial_particles());
        Self::with_particles(config, device, &particles)
    }

    /// A system starting from `particles` (one per `config.count`).
    pub fn with_particles(
        config: ParticleConfig,
        device: ParticleDevice,
        particles: &[Particle],
    ) -> Result<Self, ParticleError> {
        config.validate()?;
        if particles.len() != config.count {
            return Err(ParticleError::ParticleCount {
                given: particles.len(),
                expected: config.count,
            });
        }
        let mut profiler = Profiler::new("particles step");
        let executor = match device {
            ParticleDevice::Cpu => {
                let bytes = cpu::CpuParticles::bytes(&config);
                host_memory::check(config.count, bytes, host_memory::available())?;
                let cpu = cpu::CpuParticles::new(&config, particles).map_err(|_| {
                    ParticleError::HostAllocation {
                        count: config.count,
                        bytes,
                    }
                })?;
                Executor::Cpu(Box::new(cpu))
            }
            ParticleDevice::Gpu(context) => Executor::Gpu(Box::new(gpu::GpuParticles::new(
                &config,
                context,
                particles,
                &mut profiler,
            )?)),
        };
        Ok(Self {
            config,
            executor,
            profiler,
        })
    }

    pub fn config(&self) -> &ParticleConfig {
        &self.config
    }

    /// "cpu (N threads)" or the GPU adapter's description.
    pub fn device_name(&self) -> String {
        match &self.executor {
            Executor::Cpu(_) => format!("cpu ({} threads)", rayon::current_num_threads()),
            Executor::Gpu(gpu) => gpu.context().describe(),
        }
    }

    /// Measures GPU stages with timestamp queries (when the adapter has them). Reading them
    /// back waits for each step, so leave it off when timing steps per second.
    pub fn set_gpu_timing(&mut self, enabled: bool) {
        if let Executor::Gpu(gpu) = &mut self.executor {
            gpu.set_timing(enabled);
        }
    }

    /// Advances one time step. On the GPU this encodes and submits the step without waiting.
    pub fn step(&mut self) -> Result<(), ParticleError> {
        self.profiler.begin_frame();
        let result = match &mut self.executor {
            Executor::Cpu(cpu) => {
                cpu.step(&mut self.profiler);
                Ok(())
            }
            Executor::Gpu(gpu) => gpu.step(&mut self.profiler).map_err(ParticleError::from),
        };
        self.profiler.end_frame();
        result
    }

    /// Blocks until the device has finished every submitted step (a no-op on the CPU).
    pub fn finish(&mut self) -> Result<(), ParticleError> {
        if let Executor::Gpu(gpu) = &self.executor {
            gpu.context().wait()?;
        }
        Ok(())
    }

    /// The particles, in their original order (downloaded from the GPU, recorded as a copy
    /// in the profile).
    pub fn particles(&mut self) -> Result<Vec<Particle>, ParticleError> {
        match &mut self.executor {
            Executor::Cpu(cpu) => Ok(cpu.particles().to_vec()),
            Executor::Gpu(gpu) => Ok(gpu.download(&mut self.profiler)?),
        }
    }

    /// Particle centres (m), in their original order.
    pub fn positions(&mut self) -> Result<Vec<[f32; 3]>, ParticleError> {
        Ok(self
            .particles()?
            .iter()
            .map(|particle| {
                let [x, y, z, _] = particle.position;
                [x, y, z]
            })
            .collect())
    }

    /// Σ ½ m v² (J).
    pub fn kinetic_energy(&mut self) -> Result<f64, ParticleError> {
        let mass = f64::from(self.config.mass);
        Ok(self
            .particles()?
            .iter()
            .map(|particle| {
                let [x, y, z, _] = particle.velocity.map(f64::from);
                0.5 * mass * (x * x + y * y + z * z)
            })
            .sum())
    }

    /// Timings of the steps so far: CPU stages, GPU stages and copies in one tree.
    pub fn profiler(&self) -> &Profiler {
        &self.profiler
    }

    pub fn profiler_mut(&mut self) -> &mut Profiler {
        &mut self.profiler
    }
}
