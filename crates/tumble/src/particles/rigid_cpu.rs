//! CPU executor of the rigid particle bodies (rayon), the twin of `rigid_gpu.rs`: the same
//! stages and the same arithmetic in the same order as `rigid_*.wgsl`.

use std::collections::TryReserveError;

use rayon::prelude::*;

use crate::particles::cpu::{Grid, Vector, add, neighbour_force, scale, wall_force, xyz};
use crate::particles::host_memory::{try_filled, try_to_vec, try_with_capacity};
use crate::particles::rigid::{BodyInfo, Flat, RigidBody, cross, rotate};
use crate::particles::{Particle, ParticleParams};
use crate::profile::Profiler;

/// Stage 1: a particle's world position and velocity from its body's state; `w` of the
/// position carries the body's index, so that the collide stage can skip its own body.
pub(super) fn world_particle(body: &RigidBody, offset: [f32; 4]) -> Particle {
    let arm = rotate(body.orientation, xyz(offset));
    let position = add(xyz(body.position), arm);
    let velocity = add(
        xyz(body.linear_velocity),
        cross(xyz(body.angular_velocity), arm),
    );
    Particle {
        position: [position[0], position[1], position[2], offset[3]],
        velocity: [velocity[0], velocity[1], velocity[2], 0.0],
    }
}

/// The ground's (and walls') friction: the tangential velocity of a particle inside a wall
/// is damped by `shear` (N).
pub(super) fn wall_friction(params: &ParticleParams, position: Vector, velocity: Vector) -> Vector {
    let mut force = [0.0; 3];
    for (axis, &coordinate) in position.iter().enumerate() {
        let low = params.origin[axis] + params.radius;
        let high =
            params.origin[axis] + params.grid[axis] as f32 * params.cell_size - params.radius;
        if coordinate < low || coordinate > high {
            for other in 0..3 {
                if other != axis {
                    force[other] -= params.shear * velocity[other];
                }
            }
        }
    }
    force
}

/// Stage 4: a body sums its particles' forces and torques in particle order, then
/// integrates: semi-implicit Euler, the orientation by its angular velocity, renormalized.
/// Invocations of the GPU's per-body workgroup, and so the lanes of the per-body sums on both
/// executors (a power of two). 64 covers a bunny's 238 particles in 4 rounds.
pub(super) const BODY_LANES: usize = 64;

pub(super) fn step_body(
    params: &ParticleParams,
    info: &BodyInfo,
    offsets: &[[f32; 4]],
    forces: &[[f32; 4]],
    body: &RigidBody,
) -> RigidBody {
    let q = body.orientation;
    // The GPU's order (`rigid_bodies.wgsl`): lane l sums particles l, l + BODY_LANES, ...,
    // then the lanes add up in halving strides.
    let mut lanes = [[[0.0; 3]; 2]; BODY_LANES];
    let (first, end) = (
        info.first_particle as usize,
        (info.first_particle + info.particle_count) as usize,
    );
    for (lane, [force, torque]) in lanes.iter_mut().enumerate() {
        for index in (first + lane..end).step_by(BODY_LANES) {
            let particle_force = xyz(forces[index]);
            let arm = rotate(q, xyz(offsets[index]));
            *force = add(*force, particle_force);
            *torque = add(*torque, cross(arm, particle_force));
        }
    }
    let mut stride = BODY_LANES / 2;
    while stride > 0 {
        for lane in 0..stride {
            let [force, torque] = lanes[lane + stride];
            lanes[lane] = [add(lanes[lane][0], force), add(lanes[lane][1], torque)];
        }
        stride /= 2;
    }
    let [force, torque] = lanes[0];
    let acceleration = add(scale(force, info.inverse_mass), params.gravity);
    let velocity = add(xyz(body.linear_velocity), scale(acceleration, params.dt));
    // I⁻¹ in the world: rotate the torque into the body frame and back.
    let local = rotate([-q[0], -q[1], -q[2], q[3]], torque);
    let columns = info.inverse_inertia.map(xyz);
    let local = add(
        add(scale(columns[0], local[0]), scale(columns[1], local[1])),
        scale(columns[2], local[2]),
    );
    let angular = add(
        xyz(body.angular_velocity),
        scale(rotate(q, local), params.dt),
    );
    let position = add(xyz(body.position), scale(velocity, params.dt));
    // dq/dt = ½ (ω, 0) ⊗ q.
    let axis = xyz(q);
    let spin_axis = add(scale(angular, q[3]), cross(angular, axis));
    let spin = [
        spin_axis[0],
        spin_axis[1],
        spin_axis[2],
        -(angular[0] * axis[0] + angular[1] * axis[1] + angular[2] * axis[2]),
    ];
    let half_dt = 0.5 * params.dt;
    let moved: [f32; 4] = [0, 1, 2, 3].map(|i| q[i] + spin[i] * half_dt);
    let norm = 1.0
        / (moved[0] * moved[0] + moved[1] * moved[1] + moved[2] * moved[2] + moved[3] * moved[3])
            .sqrt();
    RigidBody {
        position: [position[0], position[1], position[2], 0.0],
        orientation: moved.map(|c| c * norm),
        linear_velocity: [velocity[0], velocity[1], velocity[2], 0.0],
        angular_velocity: [angular[0], angular[1], angular[2], 0.0],
    }
}

#[derive(Debug)]
pub(super) struct CpuRigid {
    params: ParticleParams,
    offsets: Vec<[f32; 4]>,
    info: Vec<BodyInfo>,
    bodies: Vec<RigidBody>,
    particles: Vec<Particle>,
    grid: Grid,
    sorted: Vec<Particle>,
    /// Force on each particle, in sorted order, then scattered to body order.
    sorted_forces: Vec<[f32; 4]>,
    forces: Vec<[f32; 4]>,
}

impl CpuRigid {
    /// Host memory [`new`](Self::new) allocates for `bodies` bodies of `particles` particles
    /// in all in `cells` grid cells (bytes): its copies of the offsets, the body constants
    /// and states; the world particles twice (body and sorted order), the forces twice, a
    /// (cell, particle) pair each; a start and an end per cell.
    pub fn bytes(bodies: usize, particles: usize, cells: u64) -> u64 {
        let per_body = size_of::<BodyInfo>() + size_of::<RigidBody>();
        let per_particle = size_of::<[f32; 4]>()
            + 2 * size_of::<Particle>()
            + 2 * size_of::<[f32; 4]>()
            + size_of::<(u32, u32)>();
        bodies as u64 * per_body as u64 + particles as u64 * per_particle as u64 + cells * 2 * 4
    }

    /// Allocates every array a step uses, with `try_reserve_exact`: the allocator's refusal
    /// is returned, never an abort, and a step allocates nothing.
    pub fn new(flat: &Flat) -> Result<Self, TryReserveError> {
        let count = flat.offsets.len();
        Ok(Self {
            params: flat.particles.params(),
            offsets: try_to_vec(&flat.offsets)?,
            info: try_to_vec(&flat.info)?,
            bodies: try_to_vec(&flat.bodies)?,
            particles: try_filled(count, Particle::default())?,
            grid: Grid::with_capacity(count, flat.particles.cell_count() as usize)?,
            sorted: try_with_capacity(count)?,
            sorted_forces: try_filled(count, [0.0; 4])?,
            forces: try_filled(count, [0.0; 4])?,
        })
    }

    pub fn bodies(&self) -> &[RigidBody] {
        &self.bodies
    }

    pub fn step(&mut self, profiler: &mut Profiler) {
        let params = &self.params;
        let (bodies, offsets) = (&self.bodies, &self.offsets);
        profiler.scope("world particles", || {
            self.particles
                .par_iter_mut()
                .zip(offsets)
                .for_each(|(particle, &offset)| {
                    *particle = world_particle(&bodies[offset[3] as usize], offset);
                });
        });
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
        profiler.scope("collide", || {
            collide(params, &self.grid, &self.sorted, &mut self.sorted_forces);
            for (force, &(_, id)) in self.sorted_forces.iter().zip(&self.grid.pairs) {
                self.forces[id as usize] = *force;
            }
        });
        let (info, forces) = (&self.info, &self.forces);
        profiler.scope("bodies", || {
            self.bodies
                .par_iter_mut()
                .zip(info)
                .for_each(|(body, info)| {
                    *body = step_body(params, info, offsets, forces, body);
                });
        });
    }
}

/// Stage 3: 27-cell search, one sorted particle per task, pairs of the same body skipped,
/// forces summed in stencil order.
fn collide(params: &ParticleParams, grid: &Grid, sorted: &[Particle], forces: &mut [[f32; 4]]) {
    forces.par_iter_mut().enumerate().for_each(|(index, out)| {
        let me = sorted[index];
        let (position, velocity) = (xyz(me.position), xyz(me.velocity));
        let mut force = neighbour_force(params, grid, sorted, index, true);
        force = add(force, wall_force(params, position, velocity));
        force = add(force, wall_friction(params, position, velocity));
        *out = [force[0], force[1], force[2], 0.0];
    });
}
