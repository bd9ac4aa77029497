//! CPU executor of the particle step (rayon), the twin of `gpu.rs`: same stages, same
//! arithmetic in the same order as the WGSL (`common.wgsl`, `collide.wgsl`).

use std::collections::TryReserveError;

use rayon::prelude::*;

use crate::particles::host_memory::{try_filled, try_to_vec, try_with_capacity};
use crate::particles::{EMPTY_CELL, NeighbourSearch, Particle, ParticleConfig, ParticleParams};
use crate::profile::Profiler;

pub(super) type Vector = [f32; 3];

pub(super) fn add(a: Vector, b: Vector) -> Vector {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(super) fn sub(a: Vector, b: Vector) -> Vector {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(super) fn scale(a: Vector, s: f32) -> Vector {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(super) fn dot(a: Vector, b: Vector) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(super) fn xyz(v: [f32; 4]) -> Vector {
    [v[0], v[1], v[2]]
}

/// The cell holding `position`, clamped into the grid (a particle outside the box is
/// pushed back by the walls; meanwhile it lives in the border cell).
pub(crate) fn cell_of(params: &ParticleParams, position: Vector) -> [u32; 3] {
    [0, 1, 2].map(|axis| {
        let scaled = ((position[axis] - params.origin[axis]) / params.cell_size).floor();
        scaled.clamp(0.0, (params.grid[axis] - 1) as f32) as u32
    })
}

/// Linear cell id: x fastest, then y, then z (the talk's 4×4 example numbers y·4 + x).
pub(crate) fn cell_index(params: &ParticleParams, cell: [u32; 3]) -> u32 {
    (cell[2] * params.grid[1] + cell[1]) * params.grid[0] + cell[0]
}

/// The neighbour cell at `offset` from `cell`, if inside the grid.
pub(super) fn neighbour(params: &ParticleParams, cell: [u32; 3], offset: [i32; 3]) -> Option<u32> {
    let mut coordinates = [0u32; 3];
    for axis in 0..3 {
        let value = cell[axis] as i64 + i64::from(offset[axis]);
        if value < 0 || value >= i64::from(params.grid[axis]) {
            return None;
        }
        coordinates[axis] = value as u32;
    }
    Some(cell_index(params, coordinates))
}

/// The pair forces on sorted particle `index` from the particles of the 27 cells around it,
/// summed in stencil order as they are found (`search.wgsl`'s `neighbour_force`). With
/// `skip_own_body`, particles with the same `position[3]` (a rigid body's index) are left out.
pub(super) fn neighbour_force(
    params: &ParticleParams,
    grid: &Grid,
    sorted: &[Particle],
    index: usize,
    skip_own_body: bool,
) -> Vector {
    let me = sorted[index];
    let (position, velocity) = (xyz(me.position), xyz(me.velocity));
    let cell = cell_of(params, position);
    let mut force = [0.0; 3];
    for offset in FULL_STENCIL {
        let Some(neighbour) = neighbour(params, cell, offset) else {
            continue;
        };
        for other in grid.run(neighbour) {
            let them = sorted[other];
            let own_body = skip_own_body && them.position[3] == me.position[3];
            if other != index && !own_body {
                let pair = pair_force(
                    params,
                    position,
                    velocity,
                    xyz(them.position),
                    xyz(them.velocity),
                );
                force = add(force, pair);
            }
        }
    }
    force
}

/// All 27 offsets, in increasing cell index order (z, then y, then x).
pub(super) const FULL_STENCIL: [[i32; 3]; 27] = {
    let mut offsets = [[0; 3]; 27];
    let mut index = 0;
    while index < 27 {
        offsets[index] = [
            index as i32 % 3 - 1,
            (index as i32 / 3) % 3 - 1,
            index as i32 / 9 - 1,
        ];
        index += 1;
    }
    offsets
};

/// The 13 neighbours with a smaller cell index (the first half of [`FULL_STENCIL`]): with
/// the own cell's later particles, each pair is met exactly once.
const HALF_STENCIL: [[i32; 3]; 13] = {
    let mut offsets = [[0; 3]; 13];
    let mut index = 0;
    while index < 13 {
        offsets[index] = FULL_STENCIL[index];
        index += 1;
    }
    offsets
};

/// Force on a particle at (`position`, `velocity`) from one at (`other_position`,
/// `other_velocity`) (N): spring on the overlap, damping on the normal relative velocity,
/// shear damping on the tangential one. Zero when apart (or coincident: no normal).
/// Antisymmetric bit for bit: swapping the two negates the result exactly.
pub(super) fn pair_force(
    params: &ParticleParams,
    position: Vector,
    velocity: Vector,
    other_position: Vector,
    other_velocity: Vector,
) -> Vector {
    let offset = sub(other_position, position);
    let distance_squared = dot(offset, offset);
    let contact = 2.0 * params.radius;
    if distance_squared >= contact * contact || distance_squared == 0.0 {
        return [0.0; 3];
    }
    let distance = distance_squared.sqrt();
    let normal = scale(offset, 1.0 / distance);
    let relative = sub(other_velocity, velocity);
    let normal_speed = dot(relative, normal);
    let tangential = sub(relative, scale(normal, normal_speed));
    add(
        scale(
            normal,
            params.damping * normal_speed - params.spring * (contact - distance),
        ),
        scale(tangential, params.shear),
    )
}

/// Largest pair force in fixed point (quanta): 32 of them cannot overflow an i32 sum.
const MAX_PAIR_QUANTA: f32 = 67_108_864.0;

/// A pair force in fixed point (rounded half to even, as WGSL's `round`): integer sums do
/// not depend on the order of the additions.
fn quantize(params: &ParticleParams, force: Vector) -> [i32; 3] {
    force.map(|component| {
        (component * params.force_scale)
            .round_ties_even()
            .clamp(-MAX_PAIR_QUANTA, MAX_PAIR_QUANTA) as i32
    })
}

/// Spring–damper force of the six walls (the ground is the lower y wall) (N).
pub(super) fn wall_force(params: &ParticleParams, position: Vector, velocity: Vector) -> Vector {
    let mut force = [0.0; 3];
    for axis in 0..3 {
        let low = params.origin[axis] + params.radius;
        let high =
            params.origin[axis] + params.grid[axis] as f32 * params.cell_size - params.radius;
        let below = low - position[axis];
        if below > 0.0 {
            force[axis] += params.wall_spring * below - params.wall_damping * velocity[axis];
        }
        let above = position[axis] - high;
        if above > 0.0 {
            force[axis] -= params.wall_spring * above + params.wall_damping * velocity[axis];
        }
    }
    force
}

/// Semi-implicit Euler: velocity first, then position with the new velocity.
fn integrate(
    params: &ParticleParams,
    position: Vector,
    velocity: Vector,
    force: Vector,
) -> Particle {
    let acceleration = add(scale(force, params.inverse_mass), params.gravity);
    let velocity = add(velocity, scale(acceleration, params.dt));
    let position = add(position, scale(velocity, params.dt));
    Particle {
        position: [position[0], position[1], position[2], 0.0],
        velocity: [velocity[0], velocity[1], velocity[2], 0.0],
    }
}

/// The sorted grid: (cell, particle) pairs by cell and where each cell's run lies.
#[derive(Debug, Default)]
pub(crate) struct Grid {
    /// (cell id, particle id), sorted by cell then particle id (= stable by cell).
    pub pairs: Vec<(u32, u32)>,
    /// First sorted index of each cell, [`EMPTY_CELL`] when it has none.
    pub cell_start: Vec<u32>,
    /// One past the last sorted index of each cell (meaningful where start is not empty).
    pub cell_end: Vec<u32>,
}

impl Grid {
    /// A grid with room for `count` particles in `cells` cells: its stages then allocate
    /// nothing.
    pub(crate) fn with_capacity(count: usize, cells: usize) -> Result<Self, TryReserveError> {
        Ok(Self {
            pairs: try_with_capacity(count)?,
            cell_start: try_with_capacity(cells)?,
            cell_end: try_with_capacity(cells)?,
        })
    }

    /// Stage 1: hash every particle to its cell.
    pub fn hash(&mut self, params: &ParticleParams, particles: &[Particle]) {
        self.pairs.clear();
        self.pairs
            .par_extend(particles.par_iter().enumerate().map(|(index, particle)| {
                let cell = cell_index(params, cell_of(params, xyz(particle.position)));
                (cell, index as u32)
            }));
    }

    /// Stage 2: sort by cell. Ordering by (cell, particle id) is the stable order by cell,
    /// the same as the GPU's radix sort and bitonic sort produce.
    pub fn sort(&mut self) {
        self.pairs.par_sort_unstable();
    }

    /// Stage 3: where each cell's run starts and ends.
    pub fn find_cell_bounds(&mut self, params: &ParticleParams) {
        let cells = params.cell_count as usize;
        self.cell_start.clear();
        self.cell_start.resize(cells, EMPTY_CELL);
        self.cell_end.resize(cells, 0);
        let count = self.pairs.len();
        for index in 0..count {
            let cell = self.pairs[index].0;
            if index == 0 || self.pairs[index - 1].0 != cell {
                self.cell_start[cell as usize] = index as u32;
            }
            if index + 1 == count || self.pairs[index + 1].0 != cell {
                self.cell_end[cell as usize] = index as u32 + 1;
            }
        }
    }

    /// Sorted indices of the particles in `cell`.
    pub(super) fn run(&self, cell: u32) -> std::ops::Range<usize> {
        match self.cell_start[cell as usize] {
            EMPTY_CELL => 0..0,
            start => start as usize..self.cell_end[cell as usize] as usize,
        }
    }

    /// Calls `visit(i, j)` once for each pair of sorted indices in neighbouring cells, in the
    /// 14-cell order: for each i, later particles of its own cell, then the 13 neighbour
    /// cells with smaller ids, in increasing id order.
    pub fn for_each_symmetric_pair(
        &self,
        params: &ParticleParams,
        mut visit: impl FnMut(usize, usize),
    ) {
        for (index, &(cell, _)) in self.pairs.iter().enumerate() {
            for other in index + 1..self.run(cell).end {
                visit(index, other);
            }
            let coordinates = cell_coordinates(params, cell);
            for offset in HALF_STENCIL {
                if let Some(neighbour) = neighbour(params, coordinates, offset) {
                    for other in self.run(neighbour) {
                        visit(index, other);
                    }
                }
            }
        }
    }
}

/// Inverse of [`cell_index`].
fn cell_coordinates(params: &ParticleParams, cell: u32) -> [u32; 3] {
    let [x, y, _] = params.grid;
    [cell % x, (cell / x) % y, cell / (x * y)]
}

#[derive(Debug)]
pub(super) struct CpuParticles {
    params: ParticleParams,
    search: NeighbourSearch,
    particles: Vec<Particle>,
    grid: Grid,
    /// The particles in sorted order: the state every interaction reads (Jacobi).
    sorted: Vec<Particle>,
    /// The new state, in sorted order, before it is scattered back.
    updated: Vec<Particle>,
    /// Fixed-point force per sorted particle (14-cell search).
    forces: Vec<[i32; 3]>,
}

impl CpuParticles {
    /// Host memory [`new`](Self::new) allocates for `config` (bytes): the particles three
    /// times (state, sorted copy, new state), a (cell, particle) pair each, the fixed-point
    /// forces of the 14-cell search, and a start and an end per cell.
    pub fn bytes(config: &ParticleConfig) -> u64 {
        let forces = match config.search {
            NeighbourSearch::Full27 => 0,
            NeighbourSearch::Symmetric14 => size_of::<[i32; 3]>(),
        };
        let per_particle = 3 * size_of::<Particle>() + size_of::<(u32, u32)>() + forces;
        config.count as u64 * per_particle as u64 + config.cell_count() * 2 * 4
    }

    /// Allocates every array a step uses, with `try_reserve_exact`: the allocator's refusal
    /// is returned, never an abort, and a step allocates nothing.
    pub fn new(config: &ParticleConfig, particles: &[Particle]) -> Result<Self, TryReserveError> {
        let count = particles.len();
        let state = try_to_vec(particles)?;
        let updated = try_filled(count, Particle::default())?;
        let forces = match config.search {
            NeighbourSearch::Full27 => Vec::new(),
            NeighbourSearch::Symmetric14 => try_with_capacity(count)?,
        };
        Ok(Self {
            params: config.params(),
            search: config.search,
            particles: state,
            grid: Grid::with_capacity(count, config.cell_count() as usize)?,
            sorted: try_with_capacity(count)?,
            updated,
            forces,
        })
    }

    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    pub fn step(&mut self, profiler: &mut Profiler) {
        let params = &self.params;
        profiler.scope("hash", || self.grid.hash(params, &self.particles));
        profiler.scope("sort", || self.grid.sort());
        profiler.scope("cell start", || {
            self.grid.find_cell_bounds(params);
            let particles = &self.particles;
            self.sorted.clear();
            self.sorted.par_extend(
                self.grid
                    .pairs
                    .par_iter()
                    .map(|&(_, id)| particles[id as usize]),
            );
        });
        profiler.scope("collide", || match self.search {
            NeighbourSearch::Full27 => self.collide_full(),
            NeighbourSearch::Symmetric14 => self.collide_symmetric(),
        });
        let (particles, updated, pairs) = (&mut self.particles, &self.updated, &self.grid.pairs);
        profiler.scope("scatter", || {
            for (particle, &(_, id)) in updated.iter().zip(pairs) {
                particles[id as usize] = *particle;
            }
        });
    }

    /// 27-cell search, one particle per task, forces summed in stencil order.
    fn collide_full(&mut self) {
        let (params, grid, sorted) = (&self.params, &self.grid, &self.sorted);
        self.updated
            .par_iter_mut()
            .enumerate()
            .for_each(|(index, updated)| {
                let me = sorted[index];
                let (position, velocity) = (xyz(me.position), xyz(me.velocity));
                let force = neighbour_force(params, grid, sorted, index, false);
                let force = add(force, wall_force(params, position, velocity));
                *updated = integrate(params, position, velocity, force);
            });
    }

    /// 14-cell search: each pair once, its force added to both particles in fixed point (as
    /// the GPU's atomics do), then integration in parallel.
    fn collide_symmetric(&mut self) {
        let (params, sorted) = (&self.params, &self.sorted);
        let forces = &mut self.forces;
        forces.clear();
        forces.resize(sorted.len(), [0; 3]);
        self.grid.for_each_symmetric_pair(params, |index, other| {
            let (me, them) = (sorted[index], sorted[other]);
            let pair = pair_force(
                params,
                xyz(me.position),
                xyz(me.velocity),
                xyz(them.position),
                xyz(them.velocity),
            );
            let quanta = quantize(params, pair);
            for axis in 0..3 {
                forces[index][axis] = forces[index][axis].wrapping_add(quanta[axis]);
                forces[other][axis] = forces[other][axis].wrapping_sub(quanta[axis]);
            }
        });
        let forces = &self.forces;
        self.updated
            .par_iter_mut()
            .enumerate()
            .for_each(|(index, updated)| {
                let (position, velocity) =
                    (xyz(sorted[index].position), xyz(sorted[index].velocity));
                let summed = scale(
                    forces[index].map(|quanta| quanta as f32),
                    params.force_quantum,
                );
                let force = add(summed, wall_force(params, position, velocity));
                *updated = integrate(params, position, velocity, force);
            });
    }
}
