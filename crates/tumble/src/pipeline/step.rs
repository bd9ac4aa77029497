//! The step, stage by stage, in the order of DESIGN.md. Read top to bottom.

use crate::math::{Aabb, Mat3};
use crate::pipeline::config::Softness;
use crate::pipeline::world::{DRAG_DAMPING_RATIO, DRAG_HERTZ};
use crate::pipeline::world::{NO_BATCH, StepStats, World};
use crate::stages::batching::{Coloring, color_constraints, group_by_batch};
use crate::stages::constraints::{
    ContactConstraint, DRAG_JOINT, JointConstraint, RowInputs, build_constraints,
    build_joint_constraints, drag_constraint, world_inverse_inertia,
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
    /// One step of `config.dt`: collision once, then the solver's sub-steps.
    pub(crate) fn step_stages(&mut self) {
        let config = self.config;
        let dt = config.dt;
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;

        // 1. World AABBs, grown by the speculative contact margin and swept over the step.
        profiler.scope("aabb", || {
            aabb::compute_aabbs(
                &self.poses,
                &self.velocities,
                &self.colliders,
                config.contact_margin,
                dt,
                &mut scratch.aabbs,
            )
        });

        // 2. Broadphase: refit the moving tree, then moving×moving and moving×static pairs.
        profiler.begin("broadphase");
        profiler.scope("update", || self.broadphase.update(&scratch.aabbs));
        profiler.scope("find pairs", || {
            self.broadphase.find_pairs(&mut scratch.pair_keys)
        });
        profiler.end();

        // 3. Pair cache: added / removed / kept; kept pairs keep their manifold.
        profiler.scope("pairs", || self.pairs.update(&scratch.pair_keys));

        // 4. Narrowphase: fresh manifolds, impulses carried over from matching points.
        profiler.scope("narrowphase", || {
            let (keys, contacts) = self.pairs.keys_and_values_mut();
            let inputs = narrowphase::NarrowphaseInputs {
                poses: &self.poses,
                velocities: &self.velocities,
                colliders: &self.colliders,
                margin: config.contact_margin,
                dt,
                skipped: &self.jointed_pairs,
            };
            narrowphase::update_contacts(keys, contacts, &inputs)
        });

        // 5. Constraint rows: contacts, then joints. Stiffness is capped by the sub-step rate
        //    (Box2D v3: a quarter of it for contacts, half for joints), stiffer against statics.
        profiler.begin("constraints");
        let h = dt / config.substeps as f32;
        let contact_hertz = config.contact_hertz.min(0.25 / h);
        let softness = Softness::new(contact_hertz, config.contact_damping_ratio, h);
        let static_softness = Softness::new(2.0 * contact_hertz, config.contact_damping_ratio, h);
        let joint_softness = Softness::new(
            config.joint_hertz.min(0.5 / h),
            config.joint_damping_ratio,
            h,
        );
        world_inverse_inertia(&self.poses, &self.masses, &mut scratch.inverse_inertia);
        let inputs = RowInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            masses: &self.masses,
            colliders: &self.colliders,
            inverse_inertia: &scratch.inverse_inertia,
            softness,
            static_softness,
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
            joint_softness,
            &mut scratch.joints,
        );
        // The drag (picking) joins the joints, so the batching and solver treat it as one.
        if let Some(drag) = &self.drag
            && self.masses[drag.body as usize].inverse_mass > 0.0
        {
            let softness = Softness::new(DRAG_HERTZ, DRAG_DAMPING_RATIO, h);
            scratch.joints.push(drag_constraint(
                drag,
                &self.poses,
                &self.masses,
                &scratch.inverse_inertia,
                softness,
                h,
            ));
        }
        profiler.end();

        // 6. Batching: joints and contacts colored together, then laid out batch after batch.
        profiler.scope("batching", || {
            let bodies = scratch.joints.iter().map(|j| (j.body_a, j.body_b));
            let bodies = bodies.chain(scratch.contacts.iter().map(|c| (c.body_a, c.body_b)));
            color_constraints(bodies, self.poses.len(), &mut scratch.coloring);
            let (joint_colors, contact_colors) =
                scratch.coloring.colors.split_at(scratch.joints.len());
            let coloring = &scratch.coloring;
            group_by_batch(
                &scratch.joints,
                joint_colors,
                coloring,
                &mut scratch.batched_joints,
                &mut scratch.joint_offsets,
            );
            group_by_batch(
                &scratch.contacts,
                contact_colors,
                coloring,
                &mut scratch.batched_contacts,
                &mut scratch.contact_offsets,
            );
            // Which batch each pair's manifold went to, for the viewer's colored batches.
            self.pair_batches.clear();
            self.pair_batches.resize(self.pairs.len(), NO_BATCH);
            for (constraint, &color) in scratch.contacts.iter().zip(contact_colors) {
                self.pair_batches[constraint.pair as usize] = coloring.batch_of(color) as u32;
            }
        });

        // 7. Solver: the soft step's sub-steps over the batches.
        profiler.begin("solver");
        integrate::prepare_bodies(&self.velocities, &self.masses, &mut scratch.solver_bodies);
        let settings = SolverSettings {
            dt,
            substeps: config.substeps,
            iterations: config.solver_iterations,
            gravity: config.gravity,
            max_push_velocity: config.max_push_velocity,
            restitution_threshold: config.restitution_threshold,
        };
        let mut batched = Batched {
            contacts: &mut scratch.batched_contacts,
            contact_offsets: &scratch.contact_offsets,
            joints: &mut scratch.batched_joints,
            joint_offsets: &scratch.joint_offsets,
            has_overflow: scratch.coloring.has_overflow,
        };
        match &mut self.gpu_solver {
            Some(gpu) if batched.joints.is_empty() => profiler.scope("gpu", || {
                // Device loss is no input error the step could report; it ends the run.
                gpu.run(&mut scratch.solver_bodies, &mut batched, settings)
                    .unwrap_or_else(|error| panic!("the GPU solver failed: {error}"))
            }),
            _ => profiler.scope("cpu", || {
                solver::solve(&mut scratch.solver_bodies, &mut batched, settings)
            }),
        }
        store_contact_impulses(&scratch.batched_contacts, self.pairs.values_mut());
        let joint_broke = store_joint_impulses(&scratch.batched_joints, &mut self.joints);
        if let Some(drag) = self.drag.as_mut()
            && let Some(solved) = scratch
                .batched_joints
                .iter()
                .find(|j| j.joint == DRAG_JOINT)
        {
            drag.impulse = solved.point_impulse;
        }
        profiler.end();

        // 8. Integrate: the step's motion into the poses.
        profiler.scope("integrate", || {
            integrate::finalize_bodies(
                &scratch.solver_bodies,
                &mut self.poses,
                &mut self.velocities,
            )
        });

        // The histogram's buffer is kept from step to step (no allocation per step).
        let mut histogram = std::mem::take(&mut self.stats.batch_histogram);
        histogram.clone_from(&scratch.coloring.histogram);
        self.stats = StepStats {
            batch_histogram: histogram,
            ..collect_stats(&scratch.pair_keys, &self.pairs, scratch)
        };
        if joint_broke {
            // The bodies of a broken joint collide again from the next step.
            self.update_jointed_pairs();
        }
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
/// Returns whether one broke.
fn store_joint_impulses(
    constraints: &[JointConstraint],
    joints: &mut [Option<crate::dynamics::joint::Joint>],
) -> bool {
    let mut any_broke = false;
    for constraint in constraints {
        // The drag (`DRAG_JOINT`) is no joint of the world: it has no slot here.
        let Some(joint) = joints
            .get_mut(constraint.joint as usize)
            .and_then(Option::as_mut)
        else {
            continue;
        };
        joint.point_impulse = constraint.point_impulse;
        joint.angular_impulse = constraint.angular_impulse;
        if let Some(threshold) = joint.break_impulse {
            let total = constraint.point_impulse.length()
                + constraint
                    .angular_impulse
                    .iter()
                    .map(|i| i.abs())
                    .sum::<f32>();
            joint.broken = total > threshold;
            any_broke |= joint.broken;
        }
    }
    any_broke
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
        batch_histogram: Vec::new(),
    }
}
