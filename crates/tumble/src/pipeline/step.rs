//! The step, stage by stage, in the order of DESIGN.md. Read top to bottom.

use crate::math::{Aabb, Mat3};
use crate::pipeline::world::{StepStats, World};
use crate::stages::batching::{Coloring, color_constraints, group_by_batch};
use crate::stages::constraints::{
    ContactConstraint, JointConstraint, RowInputs, build_constraints, build_joint_constraints,
    world_inverse_inertia,
};
use crate::stages::solver::{Batched, SolverBody, SolverSettings};
use crate::stages::{aabb, integrate, narrowphase, solver};

/// Per-step working arrays, owned by the world so that a step allocates nothing once the
/// arrays have grown to the scene's size.
#[derive(Default)]
pub(crate) struct StepScratch {
    aabbs: Vec<Aabb>,
    pair_keys: Vec<u64>,
    inverse_inertia: Vec<Mat3>,
    contacts: Vec<ContactConstraint>,
    joints: Vec<JointConstraint>,
    coloring: Coloring,
    /// `contacts` and `joints` permuted into batch order, the layout the solver sweeps.
    batched_contacts: Vec<ContactConstraint>,
    contact_offsets: Vec<u32>,
    batched_joints: Vec<JointConstraint>,
    joint_offsets: Vec<u32>,
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
                &self.jointed_pairs,
            )
        });

        // 5. Constraint rows: contacts, then joints.
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
            &mut scratch.contacts,
        );
        build_joint_constraints(
            &self.joints,
            &self.poses,
            &self.masses,
            &scratch.inverse_inertia,
            dt,
            config.push_factor,
            config.max_push_velocity,
            &mut scratch.joints,
        );
        profiler.end();

        // 6. Batching: joints and contacts colored together, then laid out batch after batch.
        profiler.scope("batching", || {
            let bodies = scratch.joints.iter().map(|j| (j.body_a, j.body_b));
            let bodies = bodies.chain(scratch.contacts.iter().map(|c| (c.body_a, c.body_b)));
            color_constraints(bodies, self.poses.len(), &mut scratch.coloring);
            let (joint_colors, contact_colors) =
                scratch.coloring.colors.split_at(scratch.joints.len());
            group_by_batch(
                &scratch.joints,
                joint_colors,
                &scratch.coloring,
                &mut scratch.batched_joints,
                &mut scratch.joint_offsets,
            );
            group_by_batch(
                &scratch.contacts,
                contact_colors,
                &scratch.coloring,
                &mut scratch.batched_contacts,
                &mut scratch.contact_offsets,
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
        let mut batched = Batched {
            contacts: &mut scratch.batched_contacts,
            contact_offsets: &scratch.contact_offsets,
            joints: &mut scratch.batched_joints,
            joint_offsets: &scratch.joint_offsets,
            has_overflow: scratch.coloring.has_overflow,
        };
        solver::solve(&mut scratch.solver_bodies, &mut batched, settings);
        store_contact_impulses(&scratch.batched_contacts, self.pairs.values_mut());
        store_joint_impulses(&scratch.batched_joints, &mut self.joints);
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

        self.stats = collect_stats(&scratch.pair_keys, &self.pairs, scratch);
    }
}

/// Solved impulses back into the pair cache, for next step's warm start.
fn store_contact_impulses(
    constraints: &[ContactConstraint],
    contacts: &mut [narrowphase::PairContact],
) {
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

/// Solved impulses back into the joints; a joint whose impulse passed its threshold breaks.
fn store_joint_impulses(
    constraints: &[JointConstraint],
    joints: &mut [Option<crate::dynamics::joint::Joint>],
) {
    for constraint in constraints {
        let Some(joint) = joints[constraint.joint as usize].as_mut() else {
            continue;
        };
        joint.point_impulse = constraint.point_impulse;
        for (stored, row) in joint.angular_impulse.iter_mut().zip(&constraint.angular) {
            *stored = row.impulse;
        }
        if let Some(threshold) = joint.break_impulse {
            let total = constraint.point_impulse.length()
                + constraint
                    .angular
                    .iter()
                    .map(|row| row.impulse.abs())
                    .sum::<f32>();
            joint.broken = total > threshold;
        }
    }
}

fn collect_stats(
    pair_keys: &[u64],
    pairs: &crate::stages::pairs::PairCache<narrowphase::PairContact>,
    scratch: &StepScratch,
) -> StepStats {
    let max_penetration = pairs
        .values()
        .iter()
        .flat_map(|c| c.manifold.points().iter().map(|p| -p.separation))
        .fold(0.0f32, f32::max);
    StepStats {
        pairs: pair_keys.len(),
        pairs_added: pairs.added().len(),
        pairs_removed: pairs.removed().len(),
        manifolds: scratch.contacts.len(),
        contacts: scratch
            .contacts
            .iter()
            .map(|c| c.point_count as usize)
            .sum(),
        max_penetration,
        joints: scratch.joints.len(),
        batch_histogram: scratch.coloring.histogram.clone(),
    }
}
