//! The step, stage by stage, in the order of DESIGN.md. Read top to bottom.

use crate::math::{Aabb, Mat3};
use crate::pipeline::world::{StepStats, World};
use crate::stages::batching::{Batches, color_constraints};
use crate::stages::constraints::{
    ContactConstraint, RowInputs, build_constraints, world_inverse_inertia,
};
use crate::stages::solver::{SolverBody, SolverSettings};
use crate::stages::{aabb, integrate, narrowphase, solver};

/// Per-step working arrays, owned by the world so that a step allocates nothing once the
/// arrays have grown to the scene's size.
#[derive(Default)]
pub(crate) struct StepScratch {
    aabbs: Vec<Aabb>,
    pair_keys: Vec<u64>,
    inverse_inertia: Vec<Mat3>,
    constraints: Vec<ContactConstraint>,
    /// `constraints` permuted into batch order, the layout the solver sweeps.
    batched: Vec<ContactConstraint>,
    batches: Batches,
    solver_bodies: Vec<SolverBody>,
}

impl World {
    pub(crate) fn substep(&mut self, dt: f32) {
        let config = self.config;
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;

        // 1. World AABBs, grown by the speculative contact margin.
        profiler.scope("aabb", || {
            aabb::compute_aabbs(
                &self.poses,
                &self.colliders,
                config.contact_margin,
                &mut scratch.aabbs,
            )
        });

        // 2. Broadphase: refit the moving tree, then moving×moving and moving×static pairs.
        profiler.begin("broadphase");
        self.broadphase.update(&scratch.aabbs);
        self.broadphase.find_pairs(&mut scratch.pair_keys);
        profiler.end();

        // 3. Pair cache: added / removed / kept; kept pairs keep their manifold.
        profiler.scope("pairs", || self.pairs.update(&scratch.pair_keys));

        // 4. Narrowphase: fresh manifolds, impulses carried over by feature id.
        profiler.scope("narrowphase", || {
            let (keys, contacts) = self.pairs.keys_and_values_mut();
            narrowphase::update_contacts(
                keys,
                contacts,
                &self.poses,
                &self.colliders,
                config.contact_margin,
            )
        });

        // 5. Constraint rows.
        profiler.begin("constraints");
        world_inverse_inertia(&self.poses, &self.masses, &mut scratch.inverse_inertia);
        let inputs = RowInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            masses: &self.masses,
            colliders: &self.colliders,
            inverse_inertia: &scratch.inverse_inertia,
            dt,
            penetration_slop: config.penetration_slop,
            push_factor: config.push_factor,
            max_push_velocity: config.max_push_velocity,
        };
        build_constraints(
            self.pairs.keys(),
            self.pairs.values(),
            &inputs,
            &mut scratch.constraints,
        );
        profiler.end();

        // 6. Batching by graph coloring, then the constraints laid out batch after batch.
        profiler.scope("batching", || {
            color_constraints(&scratch.constraints, self.poses.len(), &mut scratch.batches);
            scratch.batched.clear();
            scratch.batched.extend(
                scratch
                    .batches
                    .order
                    .iter()
                    .map(|&i| scratch.constraints[i as usize]),
            );
        });

        // 7. Solver: gravity into the velocities, then projected Gauss-Seidel over the batches.
        profiler.begin("solver");
        integrate::integrate_velocities(
            &self.velocities,
            &self.masses,
            config.gravity,
            dt,
            &mut scratch.solver_bodies,
        );
        let settings = SolverSettings {
            iterations: config.solver_iterations,
            restitution_threshold: config.restitution_threshold,
        };
        solver::solve(
            &mut scratch.solver_bodies,
            &mut scratch.batched,
            &scratch.batches.offsets,
            scratch.batches.has_overflow,
            settings,
        );
        store_impulses(&scratch.batched, self.pairs.values_mut());
        profiler.end();

        // 8. Integrate positions from the solved velocities (+ split-impulse pseudo-velocities).
        profiler.scope("integrate", || {
            integrate::integrate_positions(
                &scratch.solver_bodies,
                dt,
                &mut self.poses,
                &mut self.velocities,
            )
        });

        self.stats = collect_stats(
            &scratch.pair_keys,
            &self.pairs,
            &scratch.batched,
            &scratch.batches,
        );
    }
}

/// Solved impulses back into the pair cache, for next step's warm start.
fn store_impulses(constraints: &[ContactConstraint], contacts: &mut [narrowphase::PairContact]) {
    for constraint in constraints {
        let contact = &mut contacts[constraint.pair as usize];
        for (impulse, point) in contact
            .impulses
            .iter_mut()
            .zip(&constraint.points[..constraint.point_count as usize])
        {
            impulse.normal = point.normal.impulse;
            impulse.tangent = [point.tangent[0].impulse, point.tangent[1].impulse];
        }
    }
}

fn collect_stats(
    pair_keys: &[u64],
    pairs: &crate::stages::pairs::PairCache<narrowphase::PairContact>,
    constraints: &[ContactConstraint],
    batches: &Batches,
) -> StepStats {
    let contacts = pairs.values();
    let max_penetration = contacts
        .iter()
        .flat_map(|c| c.manifold.points().iter().map(|p| -p.separation))
        .fold(0.0f32, f32::max);
    StepStats {
        pairs: pair_keys.len(),
        pairs_added: pairs.added().len(),
        pairs_removed: pairs.removed().len(),
        manifolds: constraints.len(),
        contacts: constraints.iter().map(|c| c.point_count as usize).sum(),
        max_penetration,
        batch_histogram: batches.histogram(),
    }
}
