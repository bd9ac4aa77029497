//! Rigid bodies made of particles, the talk's second particle demo (Harada, "Real-Time Rigid
//! Body Simulation on GPUs", GPU Gems 3 ch. 29). A body is a set of particles fixed in its
//! frame (a voxelization of its shape). Every step
//!
//! 1. **world particles**: each particle's position and velocity from its body's pose and
//!    velocities;
//! 2. **hash, sort, cell start**: the particle demo's uniform grid, unchanged;
//! 3. **collide**: each particle sums the demo's spring–damper forces from the particles of
//!    *other* bodies in the 27 cells around it, and the walls' (with a tangential damping,
//!    the ground's friction);
//! 4. **bodies**: each body sums its particles' forces and their torques about its centre of
//!    mass — its particles are contiguous, so one pass in particle order, no float atomics,
//!    the same sums on every run — and integrates (semi-implicit Euler; the gyroscopic term
//!    is left out, as in Harada's).
//!
//! Both executors run the same arithmetic on the same `#[repr(C)]` data.

use std::collections::TryReserveError;

use bytemuck::{Pod, Zeroable};

use crate::particles::host_memory::{self, try_with_capacity};
use crate::particles::{MAX_PARTICLES, ParticleConfig, ParticleDevice, ParticleError};
use crate::profile::Profiler;

use super::{rigid_cpu, rigid_gpu};

/// Most bodies a system takes: a particle carries its body's index as an `f32`, exact below
/// 2²⁴.
pub const MAX_BODIES: usize = 1 << 24;

/// An ellipsoid of a [`Solid`] (m, in the solid's frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    pub centre: [f32; 3],
    pub radii: [f32; 3],
}

impl Ellipsoid {
    fn contains(&self, point: [f64; 3]) -> bool {
        (0..3)
            .map(|axis| {
                let scaled =
                    (point[axis] - f64::from(self.centre[axis])) / f64::from(self.radii[axis]);
                scaled * scaled
            })
            .sum::<f64>()
            <= 1.0
    }
}

/// A shape to voxelize.
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// A box centred on the origin.
    Box { half_extents: [f32; 3] },
    /// The union of ellipsoids.
    Ellipsoids(Vec<Ellipsoid>),
}

impl Solid {
    pub fn sphere(radius: f32) -> Self {
        Self::Ellipsoids(vec![Ellipsoid {
            centre: [0.0; 3],
            radii: [radius; 3],
        }])
    }

    /// A procedural bunny `length` long (nose to tail, along x), facing +x: body, head, two
    /// ears and a tail, all ellipsoids. Made here, so no mesh file (and no licence) is needed.
    pub fn bunny(length: f32) -> Self {
        let unit = length / 10.0;
        let ellipsoid = |centre: [f32; 3], radii: [f32; 3]| Ellipsoid {
            centre: centre.map(|c| c * unit),
            radii: radii.map(|r| r * unit),
        };
        Self::Ellipsoids(vec![
            ellipsoid([0.0, 0.0, 0.0], [3.4, 2.4, 2.4]),
            ellipsoid([3.0, 1.8, 0.0], [1.9, 1.7, 1.6]),
            ellipsoid([2.4, 4.4, 0.8], [0.7, 1.8, 0.5]),
            ellipsoid([2.4, 4.4, -0.8], [0.7, 1.8, 0.5]),
            ellipsoid([-3.7, 0.6, 0.0], [0.9, 0.9, 0.9]),
        ])
    }

    fn contains(&self, point: [f64; 3]) -> bool {
        match self {
            Self::Box { half_extents } => {
                (0..3).all(|axis| point[axis].abs() <= f64::from(half_extents[axis]))
            }
            Self::Ellipsoids(parts) => parts.iter().any(|part| part.contains(point)),
        }
    }

    /// Axis-aligned bounds (min, max), or None for an empty or non-finite solid.
    fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let (low, high) = match self {
            Self::Box { half_extents } => {
                let half = half_extents.map(f64::from);
                (half.map(|h| -h), half)
            }
            Self::Ellipsoids(parts) => {
                let mut low = [f64::INFINITY; 3];
                let mut high = [f64::NEG_INFINITY; 3];
                for part in parts {
                    for axis in 0..3 {
                        let (centre, radius) = (
                            f64::from(part.centre[axis]),
                            f64::from(part.radii[axis]).abs(),
                        );
                        low[axis] = low[axis].min(centre - radius);
                        high[axis] = high[axis].max(centre + radius);
                    }
                }
                (low, high)
            }
        };
        let finite = low.iter().chain(&high).all(|v| v.is_finite());
        (finite && (0..3).all(|axis| low[axis] <= high[axis])).then_some((low, high))
    }
}

/// A voxelized body: its particles, relative to its centre of mass, and its mass properties.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelShape {
    /// Particle centres in the body frame (m), relative to the centre of mass.
    pub offsets: Vec<[f32; 3]>,
    /// Σ particle masses (kg).
    pub mass: f64,
    /// Inertia about the centre of mass in the body frame (kg·m²): the particles as point
    /// masses plus each one's own inertia as a solid cube one diameter wide (the voxel it
    /// stands for), so that a box filled exactly by voxels gets the box's inertia.
    pub inertia: [[f64; 3]; 3],
}

/// Most lattice points a voxelization visits (its bounds over the diameter, cubed).
pub const MAX_VOXELS: usize = 100_000_000;

/// Fills `solid` with particles of `radius` on a cubic lattice one diameter apart (a voxel
/// per particle, kept where its centre is inside), each of `particle_mass`.
pub fn voxelize(
    solid: &Solid,
    radius: f32,
    particle_mass: f32,
) -> Result<VoxelShape, ParticleError> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(ParticleError::Radius(radius));
    }
    if !(particle_mass.is_finite() && particle_mass > 0.0) {
        return Err(ParticleError::Mass(particle_mass));
    }
    let (low, high) = solid.bounds().ok_or(ParticleError::EmptyBody)?;
    let spacing = 2.0 * f64::from(radius);
    // The lattice is centred on the bounds, as many voxels across as fit best: a box k
    // diameters wide gets exactly k, any box's side is off by at most half a voxel, and the
    // next lattice point out lies outside the bounds (nothing inside is missed).
    let counts: [usize; 3] =
        [0, 1, 2].map(|axis| ((high[axis] - low[axis]) / spacing).round().max(1.0) as usize);
    let lattice = counts.iter().fold(1usize, |all, &c| all.saturating_mul(c));
    if lattice > MAX_VOXELS {
        return Err(ParticleError::VoxelLattice {
            points: lattice,
            max: MAX_VOXELS,
        });
    }
    let mut points = Vec::new();
    for z in 0..counts[2] {
        for y in 0..counts[1] {
            for x in 0..counts[0] {
                let index = [x, y, z];
                let point = [0, 1, 2].map(|axis| {
                    0.5 * (low[axis] + high[axis])
                        + (index[axis] as f64 + 0.5 - 0.5 * counts[axis] as f64) * spacing
                });
                if solid.contains(point) {
                    points.push(point);
                }
            }
        }
    }
    if points.is_empty() {
        return Err(ParticleError::EmptyBody);
    }
    let count = points.len() as f64;
    let centre = [0, 1, 2].map(|axis| points.iter().map(|p| p[axis]).sum::<f64>() / count);
    let mass = f64::from(particle_mass);
    let own = mass * spacing * spacing / 6.0;
    let mut inertia = [[0.0; 3]; 3];
    for point in &points {
        let r = [0, 1, 2].map(|axis| point[axis] - centre[axis]);
        let squared = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        for row in 0..3 {
            for column in 0..3 {
                let diagonal = if row == column {
                    squared + own / mass
                } else {
                    0.0
                };
                inertia[row][column] += mass * (diagonal - r[row] * r[column]);
            }
        }
    }
    Ok(VoxelShape {
        offsets: points
            .iter()
            .map(|p| [0, 1, 2].map(|axis| (p[axis] - centre[axis]) as f32))
            .collect(),
        mass: mass * count,
        inertia,
    })
}

/// A body's state, as stored on both devices (64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RigidBody {
    /// Centre of mass (m); `w` unused (0).
    pub position: [f32; 4],
    /// Unit quaternion (x, y, z, w), body to world.
    pub orientation: [f32; 4],
    /// Velocity of the centre of mass (m/s); `w` unused.
    pub linear_velocity: [f32; 4],
    /// World angular velocity (rad/s); `w` unused.
    pub angular_velocity: [f32; 4],
}
const _: () = assert!(size_of::<RigidBody>() == 64);

impl RigidBody {
    /// At rest at `position`, rotated by `orientation` (normalized here).
    pub fn at(position: [f32; 3], orientation: [f32; 4]) -> Self {
        let length = orientation.iter().map(|c| c * c).sum::<f32>().sqrt();
        Self {
            position: [position[0], position[1], position[2], 0.0],
            orientation: orientation.map(|c| c / length),
            linear_velocity: [0.0; 4],
            angular_velocity: [0.0; 4],
        }
    }

    pub fn with_velocity(mut self, linear: [f32; 3], angular: [f32; 3]) -> Self {
        self.linear_velocity = [linear[0], linear[1], linear[2], 0.0];
        self.angular_velocity = [angular[0], angular[1], angular[2], 0.0];
        self
    }
}

/// A body's constants, as stored on both devices (64 bytes; WGSL's `mat3x3` columns are
/// 16 bytes apart).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BodyInfo {
    /// Index of its first particle: a body's particles are contiguous.
    pub first_particle: u32,
    pub particle_count: u32,
    pub inverse_mass: f32,
    pub padding: u32,
    /// Inverse inertia in the body frame, by columns (`w` unused).
    pub inverse_inertia: [[f32; 4]; 3],
}
const _: () = assert!(size_of::<BodyInfo>() == 64);

/// Mirrors `RigidParams` in `rigid_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RigidParams {
    pub body_count: u32,
    pub padding0: u32,
    pub padding1: u32,
    pub padding2: u32,
}

/// A scene of rigid particle bodies: the particle parameters (their `count` is set from the
/// bodies), the shapes and, for each body, its shape and start state.
#[derive(Clone, Debug)]
pub struct RigidConfig {
    /// Radius, mass per particle, grid, box, time step, gravity, contact coefficients and
    /// the sort. `shear` also damps a particle's tangential velocity against a wall
    /// (friction); `count` is set from the bodies; `search` is not read: bodies always search
    /// the 27 cells (the forces of a particle's pairs are summed where it is, in order).
    pub particles: ParticleConfig,
    pub shapes: Vec<VoxelShape>,
    /// (shape index, start state) per body.
    pub bodies: Vec<(usize, RigidBody)>,
}

/// Particle radius of the `bunnies` scene (m).
pub const BUNNY_PARTICLE_RADIUS: f32 = 0.05;
/// Bunny length of the `bunnies` scene (m): 13 particle diameters, about 200 particles.
pub const BUNNY_LENGTH: f32 = 1.3;

impl RigidConfig {
    /// The `bunnies` scene: `count` bunnies (at least one) on a lattice, each turned its own
    /// way (deterministically), above the floor of a box about as wide as the lattice, falling
    /// into a pile. Particles of 5 cm and 1 kg (water's density), contacts stiff enough that
    /// a bunny rests on its particles sunk by about a tenth of their radius.
    pub fn bunny_pile(count: usize) -> Result<Self, ParticleError> {
        let radius = BUNNY_PARTICLE_RADIUS;
        let shape = voxelize(&Solid::bunny(BUNNY_LENGTH), radius, 1.0)?;
        let count = count.max(1);
        // Checked before anything is allocated for them: the counts, then the host memory of
        // the list of bodies (the system's arrays are checked when it is built).
        if count > MAX_BODIES {
            return Err(ParticleError::TooManyBodies {
                count,
                max: MAX_BODIES,
            });
        }
        let particles = count.saturating_mul(shape.offsets.len());
        if particles > MAX_PARTICLES {
            return Err(ParticleError::TooManyParticles {
                count: particles,
                max: MAX_PARTICLES,
            });
        }
        let bytes = count as u64 * size_of::<(usize, RigidBody)>() as u64;
        check_host_memory(count, particles, bytes)?;
        let mut bodies =
            try_with_capacity(count).map_err(|_| ParticleError::BodyHostAllocation {
                bodies: count,
                particles,
                bytes,
            })?;
        // Any turn of a bunny fits in a cube this wide: its farthest particle, both ways.
        let reach = shape
            .offsets
            .iter()
            .map(|o| (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt())
            .fold(0.0f32, f32::max)
            + radius;
        let spacing = 2.0 * reach;
        let columns = ((count as f64 / 4.0).sqrt().ceil() as usize).max(1);
        let layers = count.div_ceil(columns * columns);
        let cell = 2.0 * radius;
        let side = (columns as f32 * spacing / cell).ceil() as u32 + 2;
        let height = (layers as f32 * spacing / cell).ceil() as u32 + 4;
        bodies.extend((0..count).map(|index| {
            let (x, z, y) = (
                index % columns,
                (index / columns) % columns,
                index / (columns * columns),
            );
            let centre = [
                cell + (x as f32 + 0.5) * spacing,
                4.0 * cell + (y as f32 + 0.5) * spacing,
                cell + (z as f32 + 0.5) * spacing,
            ];
            (0, RigidBody::at(centre, turn(index)))
        }));
        Ok(Self {
            particles: ParticleConfig {
                count: 0,
                radius,
                grid: [side, height, side],
                origin: [0.0; 3],
                dt: 1.0 / 240.0,
                gravity: [0.0, -9.81, 0.0],
                mass: 1.0,
                spring: 1.0e5,
                damping: 200.0,
                shear: 20.0,
                wall_spring: 1.0e5,
                wall_damping: 200.0,
                search: super::NeighbourSearch::Full27,
                sort: super::CellSort::Radix,
            },
            shapes: vec![shape],
            bodies,
        })
    }

    /// The particle config with the count of the bodies' particles, checked, before anything
    /// is allocated for them (so that a scene too large is refused first).
    fn sized(&self) -> Result<ParticleConfig, ParticleError> {
        if self.bodies.len() > MAX_BODIES {
            return Err(ParticleError::TooManyBodies {
                count: self.bodies.len(),
                max: MAX_BODIES,
            });
        }
        let total = self.bodies.iter().fold(0usize, |total, &(shape, _)| {
            let particles = self.shapes.get(shape).map_or(0, |s| s.offsets.len());
            total.saturating_add(particles)
        });
        if total > MAX_PARTICLES {
            return Err(ParticleError::TooManyParticles {
                count: total,
                max: MAX_PARTICLES,
            });
        }
        let particles = ParticleConfig {
            count: total,
            ..self.particles.clone()
        };
        particles.validate()?;
        Ok(particles)
    }

    /// Checks the bodies and flattens the scene, sized by [`sized`](Self::sized): each
    /// particle's body-frame offset with its body's index in `w`, and each body's constants.
    /// `refused` is the error when the allocator refuses an array.
    fn flatten(
        &self,
        particles: ParticleConfig,
        refused: impl Fn(TryReserveError) -> ParticleError,
    ) -> Result<Flat, ParticleError> {
        let mut offsets = try_with_capacity(particles.count).map_err(&refused)?;
        let mut info = try_with_capacity(self.bodies.len()).map_err(&refused)?;
        let mut bodies = try_with_capacity(self.bodies.len()).map_err(&refused)?;
        for (index, (shape, body)) in self.bodies.iter().enumerate() {
            let shape = self.shapes.get(*shape).ok_or(ParticleError::ShapeIndex {
                body: index,
                shape: *shape,
                shapes: self.shapes.len(),
            })?;
            if shape.offsets.is_empty() || !(shape.mass.is_finite() && shape.mass > 0.0) {
                return Err(ParticleError::EmptyBody);
            }
            let state = [
                body.position,
                body.orientation,
                body.linear_velocity,
                body.angular_velocity,
            ];
            let length_squared: f32 = body.orientation.iter().map(|c| c * c).sum();
            if state.iter().flatten().any(|v| !v.is_finite()) || (length_squared - 1.0).abs() > 1e-3
            {
                return Err(ParticleError::BodyState(index));
            }
            let inverse = invert(&shape.inertia).ok_or(ParticleError::EmptyBody)?;
            info.push(BodyInfo {
                first_particle: offsets.len() as u32,
                particle_count: shape.offsets.len() as u32,
                inverse_mass: (1.0 / shape.mass) as f32,
                padding: 0,
                inverse_inertia: [0, 1, 2].map(|column| {
                    [
                        inverse[0][column] as f32,
                        inverse[1][column] as f32,
                        inverse[2][column] as f32,
                        0.0,
                    ]
                }),
            });
            offsets.extend(
                shape
                    .offsets
                    .iter()
                    .map(|o| [o[0], o[1], o[2], index as f32]),
            );
        }
        bodies.extend(self.bodies.iter().map(|(_, body)| *body));
        Ok(Flat {
            particles,
            offsets,
            info,
            bodies,
        })
    }
}

/// Refuses `bytes` of host memory for `bodies` bodies of `particles` particles in all when
/// more than the host has available (see [`host_memory`]).
fn check_host_memory(bodies: usize, particles: usize, bytes: u64) -> Result<(), ParticleError> {
    match host_memory::shortfall(bytes, host_memory::available()) {
        Some(available) => Err(ParticleError::BodyHostMemory {
            bodies,
            particles,
            bytes,
            available,
        }),
        None => Ok(()),
    }
}

/// A scene as both executors take it.
pub(super) struct Flat {
    pub particles: ParticleConfig,
    pub offsets: Vec<[f32; 4]>,
    pub info: Vec<BodyInfo>,
    pub bodies: Vec<RigidBody>,
}

impl Flat {
    /// Host memory [`RigidConfig::flatten`] allocates for `bodies` bodies of `particles`
    /// particles in all (bytes): an offset per particle, the constants and state per body.
    fn bytes(bodies: usize, particles: usize) -> u64 {
        let per_body = size_of::<BodyInfo>() + size_of::<RigidBody>();
        bodies as u64 * per_body as u64 + particles as u64 * size_of::<[f32; 4]>() as u64
    }

    pub fn rigid_params(&self) -> RigidParams {
        RigidParams {
            body_count: self.bodies.len() as u32,
            ..RigidParams::default()
        }
    }
}

/// A deterministic orientation for body `index` (a unit quaternion from a small integer hash;
/// not uniform over rotations, varied enough for a pile).
fn turn(index: usize) -> [f32; 4] {
    let component = |salt: u32| {
        let mut bits = (index as u32).wrapping_mul(0x9E37_79B9) ^ salt.wrapping_mul(0x85EB_CA6B);
        bits ^= bits >> 15;
        bits = bits.wrapping_mul(0x2C1B_3C6D);
        bits ^= bits >> 12;
        (bits & 0xffff) as f32 / 65535.0 - 0.5
    };
    let q = [component(1), component(2), component(3), component(4) + 1.0];
    let length = q.iter().map(|c| c * c).sum::<f32>().sqrt();
    q.map(|c| c / length)
}

/// The inverse of a symmetric 3×3 matrix, None if singular.
fn invert(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let cofactor =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adjugate = [
        [
            cofactor(1, 2, 1, 2),
            -cofactor(0, 2, 1, 2),
            cofactor(0, 1, 1, 2),
        ],
        [
            -cofactor(1, 2, 0, 2),
            cofactor(0, 2, 0, 2),
            -cofactor(0, 1, 0, 2),
        ],
        [
            cofactor(1, 2, 0, 1),
            -cofactor(0, 2, 0, 1),
            cofactor(0, 1, 0, 1),
        ],
    ];
    let determinant: f64 = (0..3).map(|c| m[0][c] * adjugate[c][0]).sum();
    if !(determinant.is_finite() && determinant.abs() > 0.0) {
        return None;
    }
    Some(adjugate.map(|row| row.map(|v| v / determinant)))
}

/// The rigid particle bodies on one device.
#[derive(Debug)]
pub struct RigidSystem {
    config: ParticleConfig,
    /// Body-frame offsets with the body's index in `w` (for [`positions`](Self::positions)).
    offsets: Vec<[f32; 4]>,
    /// Each body's mass and body-frame inertia (for [`kinetic_energy`](Self::kinetic_energy)).
    masses: Vec<(f64, [[f64; 3]; 3])>,
    executor: Executor,
    profiler: Profiler,
}

#[derive(Debug)]
enum Executor {
    Cpu(Box<rigid_cpu::CpuRigid>),
    Gpu(Box<rigid_gpu::GpuRigid>),
}

impl RigidSystem {
    pub fn new(config: &RigidConfig, device: ParticleDevice) -> Result<Self, ParticleError> {
        let sized = config.sized()?;
        let (bodies, particles) = (config.bodies.len(), sized.count);
        // Before building possibly huge host arrays: does the host have room for all of them?
        // The flattened scene and the bodies' masses on either device, and on the CPU the
        // executor's arrays too; on the GPU, first whether its buffers fit the device.
        let executor_bytes = match &device {
            ParticleDevice::Cpu => {
                rigid_cpu::CpuRigid::bytes(bodies, particles, sized.cell_count())
            }
            ParticleDevice::Gpu(context) => {
                super::gpu::check_capacity(&sized, context)?;
                0
            }
        };
        let bytes = Flat::bytes(bodies, particles)
            + bodies as u64 * size_of::<(f64, [[f64; 3]; 3])>() as u64
            + executor_bytes;
        check_host_memory(bodies, particles, bytes)?;
        let refused = |_| ParticleError::BodyHostAllocation {
            bodies,
            particles,
            bytes,
        };
        let flat = config.flatten(sized, refused)?;
        let mut masses = try_with_capacity(bodies).map_err(refused)?;
        masses.extend(
            config
                .bodies
                .iter()
                .map(|&(shape, _)| (config.shapes[shape].mass, config.shapes[shape].inertia)),
        );
        let executor = match device {
            ParticleDevice::Cpu => {
                let cpu = rigid_cpu::CpuRigid::new(&flat).map_err(refused)?;
                Executor::Cpu(Box::new(cpu))
            }
            ParticleDevice::Gpu(context) => {
                Executor::Gpu(Box::new(rigid_gpu::GpuRigid::new(&flat, context)?))
            }
        };
        Ok(Self {
            config: flat.particles,
            offsets: flat.offsets,
            masses,
            executor,
            profiler: Profiler::new("rigid particles step"),
        })
    }

    /// The particle parameters, `count` being the number of particles of all bodies.
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

    /// Measures GPU stages with timestamp queries (when the adapter has them).
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

    /// The bodies' states (downloaded from the GPU).
    pub fn bodies(&mut self) -> Result<Vec<RigidBody>, ParticleError> {
        match &mut self.executor {
            Executor::Cpu(cpu) => Ok(cpu.bodies().to_vec()),
            Executor::Gpu(gpu) => Ok(gpu.download_bodies(&mut self.profiler)?),
        }
    }

    /// Every particle's centre (m), in body order, from the bodies' current poses.
    pub fn positions(&mut self) -> Result<Vec<[f32; 3]>, ParticleError> {
        let bodies = self.bodies()?;
        Ok(self
            .offsets
            .iter()
            .map(|offset| {
                let body = &bodies[offset[3] as usize];
                let arm = rotate(body.orientation, [offset[0], offset[1], offset[2]]);
                [0, 1, 2].map(|axis| body.position[axis] + arm[axis])
            })
            .collect())
    }

    /// Each particle's body index, in body order (as [`positions`](Self::positions)).
    pub fn particle_bodies(&self) -> Vec<u32> {
        self.offsets.iter().map(|offset| offset[3] as u32).collect()
    }

    pub fn body_count(&self) -> usize {
        self.masses.len()
    }

    /// Σ ½ m v² + ½ ωᵀ I ω (J), I the inertia turned into the world.
    pub fn kinetic_energy(&mut self) -> Result<f64, ParticleError> {
        let bodies = self.bodies()?;
        Ok(bodies
            .iter()
            .zip(&self.masses)
            .map(|(body, (mass, inertia))| {
                let velocity = body.linear_velocity.map(f64::from);
                let q = body.orientation;
                let angular = [
                    body.angular_velocity[0],
                    body.angular_velocity[1],
                    body.angular_velocity[2],
                ];
                // ω in the body frame, where the inertia is known.
                let local = rotate([-q[0], -q[1], -q[2], q[3]], angular).map(f64::from);
                let spin: f64 = (0..3)
                    .map(|row| local[row] * (0..3).map(|c| inertia[row][c] * local[c]).sum::<f64>())
                    .sum();
                0.5 * mass
                    * (0..3)
                        .map(|axis| velocity[axis] * velocity[axis])
                        .sum::<f64>()
                    + 0.5 * spin
            })
            .sum())
    }

    /// Timings of the steps so far.
    pub fn profiler(&self) -> &Profiler {
        &self.profiler
    }

    pub fn profiler_mut(&mut self) -> &mut Profiler {
        &mut self.profiler
    }
}

/// `v` rotated by the unit quaternion `q` (the same operations as `rotate` in WGSL).
pub(super) fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let axis = [q[0], q[1], q[2]];
    let t = cross(axis, v).map(|c| 2.0 * c);
    let u = cross(axis, t);
    [0, 1, 2].map(|i| v[i] + q[3] * t[i] + u[i])
}

pub(super) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
