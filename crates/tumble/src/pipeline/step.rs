//! The step, stage by stage, in the order of DESIGN.md. Read top to bottom.

use std::sync::OnceLock;
use std::time::Instant;

use rayon::prelude::*;

use crate::dynamics::body::BodyMass;
use crate::dynamics::island::Islands;
use crate::dynamics::joint::MAX_ANGULAR_ROWS;
use crate::dynamics::wake::wake_candidates;
use crate::gpu::context::GpuError;
use crate::math::{Aabb, Mat3, Vec3};
use crate::pipeline::config::{Softness, StepConfig};
use crate::pipeline::devices::{Executor, Stage};
use crate::pipeline::gpu_stages::{
    BatchLayout, BodyInputs, BodyState, CollideOutput, GpuStages, JointRowInputs, OldPairs,
    RowSlots, RowsTo, StepPlan, SummaryOutput, WakeQuery,
};
use crate::pipeline::parallel::{FilterParts, filter_map_ordered};
use crate::pipeline::world::{DRAG_DAMPING_RATIO, DRAG_HERTZ};
use crate::pipeline::world::{StepStats, World, fetch_pair_keys};
use crate::profile::SpanKind;
use crate::stages::batching::{Coloring, batch_order, color_constraints, group_by_batch};
use crate::stages::constraints::tally::PairTally;
use crate::stages::constraints::{
    ContactConstraint, DRAG_JOINT, Drag, JointConstraint, RowInputs, build_constraints,
    build_joint_constraints, constraint_bodies, constraint_slots, drag_constraint, has_constraint,
    joint_slots, world_inverse_inertia,
};
use crate::stages::narrowphase::summary::PairSummary;
use crate::stages::pairs::pair_bodies;
use crate::stages::solver::batched::{BatchedImpulses, BatchedJointImpulses};
use crate::stages::solver::jacobi::{self, JacobiScratch};
use crate::stages::solver::{Batched, SolverBody, SolverKind, SolverSettings};
use crate::stages::{aabb, integrate, narrowphase, solver};

/// The rows' softness (see [`Softness`]): stiffness capped by the sub-step rate (Box2D v3: a
/// quarter of it for contacts, half for joints), stiffer against statics.
struct RowSoftness {
    contacts: Softness,
    statics: Softness,
    joints: Softness,
}

impl RowSoftness {
    fn new(config: &StepConfig) -> Self {
        let h = config.dt / config.substeps as f32;
        let contact_hertz = config.contact_hertz.min(0.25 / h);
        let damping = config.contact_damping_ratio;
        Self {
            contacts: Softness::new(contact_hertz, damping, h),
            statics: Softness::new(2.0 * contact_hertz, damping, h),
            joints: Softness::new(
                config.joint_hertz.min(0.5 / h),
                config.joint_damping_ratio,
                h,
            ),
        }
    }
}

/// The solver's settings of a step of `config`.
fn solver_settings(config: &StepConfig) -> SolverSettings {
    let softness = RowSoftness::new(config);
    SolverSettings {
        dt: config.dt,
        substeps: config.substeps,
        iterations: config.solver_iterations,
        gravity: config.gravity,
        max_push_velocity: config.max_push_velocity,
        restitution_threshold: config.restitution_threshold,
        contact_softness: softness.contacts,
        static_softness: softness.statics,
    }
}

/// Per-step working arrays, owned by the world so that a step allocates nothing once the
/// arrays have grown to the scene's size.
#[derive(Default)]
pub(crate) struct StepScratch {
    aabbs: Vec<Aabb>,
    /// Which bodies a GPU broadphase puts in its static tree ([`static_mask`]).
    is_static: Vec<bool>,
    /// The bodies' version `is_static` was made at.
    is_static_version: Option<u64>,
    pair_keys: Vec<u64>,
    /// Pairs added and removed by this step's collision, as the device counted them.
    pair_changes: (usize, usize),
    /// Pairs whose manifolds the narrowphase's pair functions computed this step
    /// ([`StepStats::pairs_computed`]).
    pairs_computed: usize,
    /// The rows' counts as this step's collision made them on the device (`tally_fresh`),
    /// and whether an island woke since (its rows are then counted on the host).
    pair_tally: PairTally,
    tally_fresh: bool,
    woke: bool,
    /// The contacts of `pair_keys` as one GPU submission computed them.
    collided: Vec<narrowphase::PairContact>,
    /// Every manifold slot's key and contact (pairs, then children), for GPU rows.
    slot_keys: Vec<u64>,
    slot_contacts: Vec<narrowphase::PairContact>,
    inverse_inertia: Vec<Mat3>,
    pub(crate) contacts: Vec<ContactConstraint>,
    joints: Vec<JointConstraint>,
    /// With the rows on the GPU, the joint rows the device builds: each one's joint slot (the
    /// drag's is the slot past the joints') and bodies, in row order ([`joint_slots`]).
    joint_row_slots: Vec<u32>,
    joint_row_bodies: Vec<(u32, u32)>,
    /// With rows, batching and solver all on the GPU the joint rows stay there too: their
    /// slots and bodies in batch order, the impulses read back.
    batched_joint_slots: Vec<u32>,
    batched_joint_bodies: Vec<(u32, u32)>,
    batched_joint_impulses: Vec<BatchedJointImpulses>,
    /// With rows, batching and solver on the GPU the contact rows stay there: what the host
    /// keeps of each (see [`RowSummary`]), the batch order sent down, the impulses read back.
    pub(crate) row_summaries: Vec<RowSummary>,
    /// Rows this step left on the device without summaries: where the batches are laid out
    /// there and the collision's tally counted them, nothing on the host needs them
    /// (`World::contact_batches` reads their slots from the device).
    unsummarized_rows: usize,
    /// [`filter_map_ordered`]'s chunks, for the rows' summaries, the islands' contact edges
    /// and the wake's pairs, and the resting pairs.
    row_parts: FilterParts<RowSummary>,
    edge_parts: FilterParts<(u32, u32)>,
    pub(crate) key_parts: FilterParts<u64>,
    /// The edges of the islands: the contacts' ([`link_contacts`]), then the joints'.
    sleep_edges: Vec<(u32, u32)>,
    /// Each body's root as the device linked the islands.
    island_roots: Vec<u32>,
    /// The touching pairs with a sleeping body, which the wake walks ([`World::wake_touched`]).
    wake_candidates: Vec<(u32, u32)>,
    /// Their keys, when the collision listed them on the device this step (`wake_listed`).
    pub(crate) wake_pair_keys: Vec<u64>,
    pub(crate) wake_listed: bool,
    batch_order: Vec<u32>,
    batched_impulses: Vec<BatchedImpulses>,
    pub(crate) coloring: Coloring,
    /// `contacts` and `joints` permuted into batch order, the layout the solver sweeps.
    batched_contacts: Vec<ContactConstraint>,
    contact_offsets: Vec<u32>,
    batched_joints: Vec<JointConstraint>,
    joint_offsets: Vec<u32>,
    solver_bodies: Vec<SolverBody>,
    jacobi: JacobiScratch,
}

impl World {
    /// One step of `config.dt`: collision once, then the solver's sub-steps.
    pub(crate) fn step_stages(&mut self) -> Result<(), GpuError> {
        let config = self.config;
        let dt = config.dt;
        if let Some(gpu) = &mut self.gpu {
            gpu.begin_step();
        }
        self.device_timers = OnceLock::new();
        self.give_device_rest_timers()?;
        // The bodies stay on the device from step to step while nothing on the host needs
        // them; a step that does brings them over first.
        self.device_bodies = OnceLock::new();
        let may_stay = self.bodies_may_stay_on_device();
        if !may_stay {
            self.sync_bodies()?;
        }
        if let Some(gpu) = &mut self.gpu {
            gpu.set_bodies_may_stay(may_stay);
        }
        // What this step's collision may bring from the device.
        let scratch = &mut self.scratch;
        (scratch.tally_fresh, scratch.woke, scratch.wake_listed) = (false, false, false);
        // With every stage on the GPU and only pairs it computes, the contacts stay there from
        // step to step; a step that needs them on the host brings them over first.
        let device_contacts = self.keeps_contacts_on_device();
        if !device_contacts {
            self.sync_contacts()?;
        }
        if self.collides_in_one_submission() {
            // The resting pairs are found on the device, from last step's pairs there.
            self.collide_in_one_submission(device_contacts)?;
        } else {
            self.refresh_resting_pairs();
            self.collide_stage_by_stage()?;
        }

        // Islands touched by an awake body, or joined to one, wake before their rows are built.
        if self.islands.sleeping_count() > 0 {
            self.profiler.begin("wake");
            // The host's pass over every pair reads their summaries and keys.
            let fetched = if self.scratch.wake_listed {
                Ok(())
            } else {
                self.fetch_pair_summaries()
                    .and_then(|()| self.fetch_pair_keys())
            };
            if fetched.is_ok() {
                self.wake_touched();
            }
            self.profiler.end();
            fetched?;
            if self.scratch.woke && self.gpu.as_ref().is_some_and(GpuStages::holds_step) {
                // The device found no island to wake: a bug, reported rather than solved
                // again (its bodies have moved).
                return Err(GpuError::Unplanned { what: "the wake" });
            }
        }
        // Until an awake body may have rested long enough by the end of this step, no island
        // can fall asleep: the islands need no links.
        let may_sleep = config.sleeping && self.islands.may_rest(&self.masses, dt);
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;

        // 5. Constraint rows: joints, then contacts, soft (`RowSoftness`).
        profiler.begin("constraints");
        let h = dt / config.substeps as f32;
        let RowSoftness {
            contacts: softness,
            statics: static_softness,
            joints: joint_softness,
        } = RowSoftness::new(&config);
        // Rows, batching and solver all on the GPU: the rows stay on the device from build to
        // solve.
        let on_gpu = |stage| self.devices.get(stage) == Executor::Gpu;
        let rows_on_gpu = self.gpu.is_some() && on_gpu(Stage::Constraints);
        let chained = rows_on_gpu && on_gpu(Stage::Batching) && on_gpu(Stage::Solver);
        // Stage 8 on the GPU: in the solver's submission when the solver runs there too.
        let integrate_on_gpu = self.gpu.is_some() && on_gpu(Stage::Integrate);
        let integrate_in_solver = integrate_on_gpu && on_gpu(Stage::Solver);
        // The GPU rows compute the inertias they need themselves.
        if rows_on_gpu {
            scratch.inverse_inertia.clear();
        } else {
            world_inverse_inertia(&self.poses, &self.masses, &mut scratch.inverse_inertia);
        }
        let inputs = RowInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            masses: &self.masses,
            colliders: &self.colliders,
            inverse_inertia: &scratch.inverse_inertia,
            softness,
            static_softness,
        };
        // The drag (picking) joins the joints, so the batching and solver treat it as one. It
        // is built here on every path: one row.
        let drag = self
            .drag
            .filter(|drag| self.masses[drag.body as usize].inverse_mass > 0.0)
            .map(|drag| {
                let softness = Softness::new(DRAG_HERTZ, DRAG_DAMPING_RATIO, h);
                drag_constraint(&drag, &self.poses, &self.masses, softness, h)
            });
        scratch.joints.clear();
        scratch.joint_row_slots.clear();
        scratch.joint_row_bodies.clear();
        scratch.contacts.clear();
        scratch.row_summaries.clear();
        scratch.unsummarized_rows = 0;
        // The batch layout stays on the device too when nothing on the host needs it: no joint
        // rows (their layout is the host's), the contacts' impulses going to the pairs on the
        // device, and the PGS solver (the Jacobi solver's adjacency is built on the host).
        let mut device_layout = false;
        // With the layout on the device, the batching and the solver need only how many rows
        // there are and whether one bounces: the rows' summaries are made while it solves.
        let mut row_tally = None;
        match (self.devices.get(Stage::Constraints), &mut self.gpu) {
            (Executor::Gpu, Some(gpu)) => {
                for (slot, bodies) in joint_slots(&self.joints, &self.masses) {
                    scratch.joint_row_slots.push(slot);
                    scratch.joint_row_bodies.push(bodies);
                }
                if let Some(drag) = &drag {
                    scratch.joint_row_slots.push(self.joints.len() as u32);
                    scratch.joint_row_bodies.push((drag.body_a, drag.body_b));
                }
                let host_slots =
                    !(self.children.is_empty() && gpu.narrowphase_output_is_pair_cache());
                if host_slots {
                    let fetched =
                        fetch_pair_keys(gpu, profiler, &mut self.pairs, &mut self.device_keys);
                    if fetched.is_err() {
                        profiler.end();
                    }
                    fetched?;
                }
                let slots = if !host_slots {
                    // The GPU narrowphase's output is the pair cache: no copy, no upload.
                    RowSlots::Narrowphase
                } else {
                    // The GPU reads every manifold slot from one array: pairs, then children.
                    scratch.slot_keys.clear();
                    scratch.slot_keys.extend_from_slice(self.pairs.keys());
                    scratch
                        .slot_keys
                        .extend(self.children.keys().iter().map(|&(key, _)| key));
                    scratch.slot_contacts.clear();
                    scratch.slot_contacts.extend_from_slice(self.pairs.values());
                    scratch
                        .slot_contacts
                        .extend_from_slice(self.children.values());
                    RowSlots::Host {
                        keys: &scratch.slot_keys,
                        contacts: &scratch.slot_contacts,
                    }
                };
                let joint_inputs = JointRowInputs {
                    joints: &self.joints,
                    slots: &scratch.joint_row_slots,
                    drag: drag.as_ref(),
                    softness: joint_softness,
                };
                // Rows that stay on the device: their buffers are sized by the manifolds with
                // points, which the host counts.
                let at_most = if !chained {
                    None
                } else if self.contacts_on_device {
                    // The collision counted the pairs with points on the device.
                    debug_assert!(scratch.tally_fresh, "the contacts stay on the device");
                    debug_assert!(
                        !self.pair_summaries_fresh
                            || scratch.pair_tally.touching
                                == (self.pair_summaries.iter())
                                    .filter(|s| s.point_count > 0)
                                    .count()
                    );
                    Some(scratch.pair_tally.touching)
                } else {
                    let slots = constraint_slots(
                        self.pairs.keys(),
                        self.pairs.values(),
                        &self.children,
                        &self.masses,
                    );
                    let colliders = self.may_bounce.then_some(&self.colliders[..]);
                    scratch
                        .row_summaries
                        .extend(slots.map(|(slot, key, contact)| {
                            let count = contact.manifold.count;
                            RowSummary::new(slot, key, count, &self.masses, colliders)
                        }));
                    Some(scratch.row_summaries.len())
                };
                let to = match at_most {
                    Some(at_most) => RowsTo::Device {
                        at_most,
                        // With the pairs' summaries: the device links the islands too.
                        link_islands: may_sleep && self.contacts_on_device,
                    },
                    None => RowsTo::Host(&mut scratch.contacts, &mut scratch.joints),
                };
                device_layout = chained
                    && scratch.joint_row_bodies.is_empty()
                    && self.contacts_on_device
                    && config.solver == SolverKind::Pgs
                    && gpu.lays_out_batches();
                // The host counts the rows itself, or summarizes them, from the pairs'
                // summaries and keys: read back before the rows are submitted, whose kernels
                // the read's wait would otherwise wait for.
                if chained && self.contacts_on_device && (!device_layout || scratch.woke) {
                    let fetched = fetch_pair_summaries(
                        gpu,
                        profiler,
                        (self.pairs.len(), &mut self.pair_summaries),
                        &mut self.pair_summaries_fresh,
                    )
                    .and_then(|()| {
                        fetch_pair_keys(gpu, profiler, &mut self.pairs, &mut self.device_keys)
                    });
                    if fetched.is_err() {
                        profiler.end();
                    }
                    fetched?;
                }
                let built = gpu.build_constraints(
                    profiler,
                    slots,
                    &inputs,
                    (self.bodies_version, &self.body_changes),
                    &joint_inputs,
                    to,
                );
                if built.is_err() {
                    profiler.end();
                }
                built?;
                if chained && self.contacts_on_device {
                    // Only where the keys were fetched above.
                    let rows = || DeviceRows {
                        keys: self.pairs.keys(),
                        summaries: &self.pair_summaries,
                        masses: &self.masses,
                        colliders: self.may_bounce.then_some(&self.colliders[..]),
                    };
                    if device_layout {
                        // The collision's counts, unless an island woke since and so gave
                        // rows to its pairs: then a pass over every pair, on every core, while
                        // the device builds the rows.
                        let tally = scratch.pair_tally;
                        let counted = RowTally {
                            rows: tally.rows,
                            bounces: tally.bouncing > 0,
                        };
                        row_tally = Some(if scratch.woke {
                            rows().tally()
                        } else {
                            counted
                        });
                        debug_assert!(
                            scratch.woke
                                || !self.pair_summaries_fresh
                                || !self.pairs.has_keys()
                                || rows().tally() == counted,
                            "the device's tally of the rows is not the host's"
                        );
                    } else {
                        rows().summarize(&mut scratch.row_parts, &mut scratch.row_summaries);
                    }
                }
                let rows = row_tally.map_or(scratch.row_summaries.len(), |t: RowTally| t.rows);
                debug_assert!(
                    at_most.is_none_or(|at_most| rows <= at_most),
                    "more rows than the device's buffer was sized for"
                );
            }
            _ => {
                build_joint_constraints(
                    &self.joints,
                    &self.poses,
                    &self.masses,
                    &scratch.inverse_inertia,
                    joint_softness,
                    &mut scratch.joints,
                );
                scratch.joints.extend(drag);
                build_constraints(
                    self.pairs.keys(),
                    self.pairs.values(),
                    &self.children,
                    &inputs,
                    &mut scratch.contacts,
                );
            }
        }
        profiler.end();

        // 6. Batching: joints and contacts colored together, then laid out batch after batch.
        profiler.begin("batching");
        let mut summary_bodies = scratch.row_summaries.iter().map(|r| r.bodies);
        let mut contact_bodies = scratch.contacts.iter().map(|c| (c.body_a, c.body_b));
        let contact_bodies: &mut dyn Iterator<Item = (u32, u32)> = if chained {
            &mut summary_bodies
        } else {
            &mut contact_bodies
        };
        // Joints first, in row order; the rows that stayed on the device are known by their
        // bodies.
        let mut row_joint_bodies = scratch.joint_row_bodies.iter().copied();
        let mut joint_bodies = scratch.joints.iter().map(|j| (j.body_a, j.body_b));
        let (joint_count, joint_bodies): (usize, &mut dyn Iterator<Item = (u32, u32)>) = if chained
        {
            (scratch.joint_row_bodies.len(), &mut row_joint_bodies)
        } else {
            (scratch.joints.len(), &mut joint_bodies)
        };
        let bodies = joint_bodies.chain(contact_bodies);
        let colored = match (self.devices.get(Stage::Batching), &mut self.gpu) {
            // The Jacobi solver sweeps every constraint at once: no coloring, one batch in
            // row order (the layout below then copies the rows as they are).
            _ if config.solver == SolverKind::Jacobi => {
                let coloring = &mut scratch.coloring;
                coloring.colors.clear();
                coloring.colors.resize(bodies.count(), 0);
                coloring.count_batches();
                coloring.rounds = 0;
                Ok(())
            }
            (Executor::Gpu, Some(gpu)) if device_layout => {
                // The rows' bodies are on the device: nothing to send.
                let count = row_tally.map_or(scratch.row_summaries.len(), |t| t.rows);
                gpu.color_constraints_on_device(profiler, count, self.poses.len(), config.batcher)
            }
            (Executor::Gpu, Some(gpu)) => gpu.color_constraints(
                profiler,
                bodies,
                self.poses.len(),
                joint_count,
                config.batcher,
                &mut scratch.coloring,
            ),
            _ => {
                color_constraints(
                    bodies,
                    self.poses.len(),
                    joint_count,
                    config.batcher,
                    &mut scratch.coloring,
                );
                Ok(())
            }
        };
        if colored.is_err() {
            profiler.end();
        }
        colored?;
        // Which batch each pair's manifold went to is found when the viewer asks
        // (`World::contact_batches`), from the rows and colors this step leaves in `scratch`,
        // or from the device's colors when the layout stays there.
        self.pair_batches = OnceLock::new();
        self.row_colors_on_device = device_layout;
        let (joint_colors, contact_colors) = scratch.coloring.colors.split_at(joint_count);
        let coloring = &scratch.coloring;
        if chained {
            // The device gathers the joint rows into this order, by slot.
            group_by_batch(
                &scratch.joint_row_slots,
                joint_colors,
                coloring,
                &mut scratch.batched_joint_slots,
                &mut scratch.joint_offsets,
            );
            group_by_batch(
                &scratch.joint_row_bodies,
                joint_colors,
                coloring,
                &mut scratch.batched_joint_bodies,
                &mut scratch.joint_offsets,
            );
            scratch.batched_joints.clear();
        } else {
            group_by_batch(
                &scratch.joints,
                joint_colors,
                coloring,
                &mut scratch.batched_joints,
                &mut scratch.joint_offsets,
            );
        }
        if device_layout {
            // On the device: the batches of the colors it brings back after the solve.
        } else if chained {
            // The device gathers the rows into this order.
            batch_order(
                contact_colors,
                coloring,
                &mut scratch.batch_order,
                &mut scratch.contact_offsets,
            );
        } else {
            group_by_batch(
                &scratch.contacts,
                contact_colors,
                coloring,
                &mut scratch.batched_contacts,
                &mut scratch.contact_offsets,
            );
        }
        profiler.end();

        // 7. Solver: the soft step's sub-steps over the batches.
        profiler.begin("solver");
        if chained && config.solver == SolverKind::Pgs {
            // The batched GPU solve makes its bodies on the device (`prepare.wgsl`): the host's
            // array only takes what may come back. (The Jacobi solver's adjacency reads their
            // masses on the host.)
            scratch
                .solver_bodies
                .resize(self.velocities.len(), SolverBody::STATIC);
        } else {
            integrate::prepare_bodies(&self.velocities, &self.masses, &mut scratch.solver_bodies);
        }
        let settings = solver_settings(&config);
        let mut batched = Batched {
            contacts: &mut scratch.batched_contacts,
            contact_offsets: &scratch.contact_offsets,
            joints: &mut scratch.batched_joints,
            joint_offsets: &scratch.joint_offsets,
            has_overflow: scratch.coloring.has_overflow,
        };
        let state = BodyState {
            poses: &mut self.poses,
            velocities: &mut self.velocities,
            masses: &self.masses,
            colliders: &self.colliders,
            version: self.bodies_version,
            changed: &self.body_changes,
        };
        let mut state = Some(state);
        // The solver takes the bodies when it integrates them too.
        let mut solver_state = || {
            if integrate_in_solver {
                state.take()
            } else {
                None
            }
        };
        // While the device solves, the host does what needs none of its results: this step's
        // islands (they need the contacts and masses, not the velocities: see `fall_asleep`)
        // and, with the layout on the device, the rows' summaries.
        let overlap = self.pairs.len() >= OVERLAP_MIN_PAIRS;
        let linked_on_device = self.gpu.as_ref().is_some_and(|gpu| gpu.islands_linked());
        let link_now = overlap
            && may_sleep
            && !linked_on_device
            && self.gpu.is_some()
            && self.devices.get(Stage::Solver) == Executor::Gpu;
        // The host's links read the pairs' summaries and keys.
        if link_now
            && self.contacts_on_device
            && let Some(gpu) = &mut self.gpu
        {
            let summaries = (self.pairs.len(), &mut self.pair_summaries);
            let fresh = &mut self.pair_summaries_fresh;
            let fetched = fetch_pair_summaries(gpu, profiler, summaries, fresh).and_then(|()| {
                fetch_pair_keys(gpu, profiler, &mut self.pairs, &mut self.device_keys)
            });
            if fetched.is_err() {
                profiler.end();
            }
            fetched?;
        }
        // The keys only where they were fetched above, for the host's links.
        let pair_edges = link_now.then(|| PairEdges {
            keys: self.pairs.keys(),
            values: self.pairs.values(),
            summaries: self.contacts_on_device.then_some(&self.pair_summaries[..]),
        });
        // With the collision's tally fresh, nothing needs the rows' summaries.
        if let Some(tally) = row_tally.filter(|_| !scratch.woke) {
            scratch.unsummarized_rows = tally.rows;
        }
        let summarize = row_tally.is_some() && scratch.woke;
        let device_rows = summarize.then(|| DeviceRows {
            keys: self.pairs.keys(),
            summaries: &self.pair_summaries,
            masses: &self.masses,
            colliders: self.may_bounce.then_some(&self.colliders[..]),
        });
        // Out of the scratch while they are made: the solve borrows the rest of it.
        let mut deferred_rows = Vec::new();
        if device_rows.is_some() {
            std::mem::swap(&mut deferred_rows, &mut scratch.row_summaries);
        }
        let (islands, masses) = (&mut self.islands, &self.masses);
        let (edge_parts, edges) = (&mut scratch.edge_parts, &mut scratch.sleep_edges);
        let row_parts = &mut scratch.row_parts;
        let host_work = || {
            let start = Instant::now();
            if let Some(pair_edges) = &pair_edges {
                link_contacts(islands, pair_edges, masses, edge_parts, edges);
            }
            let linked = Instant::now();
            if let Some(rows) = &device_rows {
                rows.summarize(row_parts, &mut deferred_rows);
            }
            let ms = |from: Instant, to: Instant| (to - from).as_secs_f64() * 1e3;
            (ms(start, linked), ms(linked, Instant::now()))
        };
        let devices = &self.devices;
        let mut solve = || match (devices.get(Stage::Solver), &mut self.gpu) {
            (Executor::Gpu, Some(gpu)) if chained => {
                let restitution = match row_tally {
                    Some(tally) => tally.bounces,
                    None => scratch.row_summaries.iter().any(|r| r.restitution),
                };
                let rows = &scratch.row_summaries;
                let contact_bodies = scratch
                    .batch_order
                    .iter()
                    .map(|&row| rows[row as usize].bodies);
                let layout = if device_layout {
                    BatchLayout::Device {
                        coloring: &mut scratch.coloring,
                    }
                } else {
                    BatchLayout::Host {
                        order: &scratch.batch_order,
                        offsets: &scratch.contact_offsets,
                        joint_order: &scratch.batched_joint_slots,
                        joint_offsets: batched.joint_offsets,
                        has_overflow: scratch.coloring.has_overflow,
                    }
                };
                gpu.solve_batched(
                    profiler,
                    config.solver,
                    &mut scratch.solver_bodies,
                    contact_bodies,
                    scratch.batched_joint_bodies.iter().copied(),
                    layout,
                    settings,
                    restitution,
                    // With the contacts on the device the solver writes their impulses there.
                    (!self.contacts_on_device).then_some(&mut scratch.batched_impulses),
                    &mut scratch.batched_joint_impulses,
                    solver_state(),
                )
            }
            (Executor::Gpu, Some(gpu)) => gpu.solve(
                profiler,
                config.solver,
                &mut scratch.solver_bodies,
                &mut batched,
                settings,
                solver_state(),
            ),
            _ => {
                match config.solver {
                    SolverKind::Pgs => profiler.scope("cpu", || {
                        solver::solve(&mut scratch.solver_bodies, &mut batched, settings)
                    }),
                    // Its own line, so the profile says which solver ran.
                    SolverKind::Jacobi => profiler.scope("jacobi (cpu)", || {
                        jacobi::solve(
                            &mut scratch.solver_bodies,
                            &mut batched,
                            settings,
                            &mut scratch.jacobi,
                        )
                    }),
                }
                Ok(())
            }
        };
        let (solved, host_ms) = if link_now || (overlap && device_rows.is_some()) {
            let (solved, ms) = rayon::join(solve, host_work);
            (solved, Some(ms))
        } else {
            let solved = solve();
            (solved, device_rows.is_some().then(host_work))
        };
        if device_rows.is_some() {
            std::mem::swap(&mut scratch.row_summaries, &mut deferred_rows);
            debug_assert_eq!(
                row_tally.map(|t| t.rows),
                Some(scratch.row_summaries.len()),
                "the rows' tally and their summaries disagree"
            );
        }
        let linked = link_now && host_ms.is_some();
        if let Some((links_ms, rows_ms)) = host_ms {
            let rows = if overlap {
                "row summaries (host, during the wait)"
            } else {
                "row summaries"
            };
            let during = [
                (link_now, "island links (host, during the wait)", links_ms),
                (device_rows.is_some(), rows, rows_ms),
            ];
            for (_, name, ms) in during.into_iter().filter(|&(done, _, _)| done) {
                profiler.record(&["solver", name], SpanKind::Cpu, ms);
            }
        }
        if solved.is_err() {
            profiler.end();
        }
        solved?;
        profiler.end();

        // 8. Integrate: the step's motion into the poses. Before the impulses are stored, so
        //    that a step whose integration fails leaves the world as it was.
        let integrated = match (&mut self.gpu, state) {
            (Some(gpu), Some(state)) if integrate_on_gpu => {
                profiler.begin("integrate");
                let integrated = gpu.integrate(profiler, &scratch.solver_bodies, state);
                profiler.end();
                integrated.map(|()| true)
            }
            (_, Some(state)) => {
                profiler.scope("integrate", || {
                    integrate::finalize_bodies(
                        &scratch.solver_bodies,
                        state.poses,
                        state.velocities,
                    )
                });
                Ok(false)
            }
            // Integrated in the solver's submission.
            (_, None) => Ok(true),
        };
        let integrated_on_gpu = integrated?;
        self.bodies_changed();
        if integrated_on_gpu && let Some(gpu) = &mut self.gpu {
            gpu.bodies_integrated(&BodyInputs {
                poses: &self.poses,
                velocities: &self.velocities,
                masses: &self.masses,
                colliders: &self.colliders,
                version: self.bodies_version,
                changed: &self.body_changes,
            });
        }
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;

        // The solved impulses into the pair cache and the joints, for the next step's warm
        // start and the joints' break test.
        profiler.begin("store impulses");
        let joint_broke = if chained {
            if self.contacts_on_device {
                // The solver wrote them into the contacts on the device, which are the newer.
                if let Some(gpu) = &mut self.gpu {
                    gpu.pair_cache_adopted(self.pairs.version());
                }
            } else {
                store_batched_impulses(
                    &scratch.batched_impulses,
                    &scratch.batch_order,
                    &scratch.row_summaries,
                    self.pairs.values_mut(),
                    self.children.values_mut(),
                );
                if let Some(gpu) = &mut self.gpu {
                    gpu.pair_cache_stored(self.pairs.version());
                }
            }
            // The rows' slots name the joints; the drag's is the one past them.
            let drag_slot = self.joints.len() as u32;
            let solved = scratch.batched_joint_impulses.iter();
            let solved = solved
                .zip(&scratch.batched_joint_slots)
                .map(|(impulse, &slot)| {
                    let joint = if slot == drag_slot { DRAG_JOINT } else { slot };
                    (joint, impulse.point, impulse.angular)
                });
            store_joint_impulses(solved, &mut self.joints, self.drag.as_mut())
        } else {
            store_contact_impulses(
                &scratch.batched_contacts,
                self.pairs.values_mut(),
                self.children.values_mut(),
            );
            let solved = scratch
                .batched_joints
                .iter()
                .map(|j| (j.joint, j.point_impulse, j.angular_impulse));
            let broke = store_joint_impulses(solved, &mut self.joints, self.drag.as_mut());
            // Solved here, not by the device's joint rows: their warm start is stale.
            if let Some(gpu) = &mut self.gpu
                && !scratch.batched_joints.is_empty()
            {
                gpu.joint_impulses_changed();
            }
            broke
        };
        profiler.end();

        // The histogram's buffer is kept from step to step (no allocation per step).
        profiler.begin("statistics");
        let mut histogram = std::mem::take(&mut self.stats.batch_histogram);
        histogram.clone_from(&scratch.coloring.histogram);
        self.stats = StepStats {
            batch_histogram: histogram,
            ..collect_stats(
                &self.pairs,
                &self.children,
                // Stale where the collision left this step's on the device: then the tally
                // stands for them.
                match (self.contacts_on_device, self.pair_summaries_fresh) {
                    (true, true) => PairContacts::Summaries(&self.pair_summaries),
                    (true, false) => PairContacts::OnDevice,
                    (false, _) => PairContacts::Host,
                },
                // The collision's tally holds the rows' points unless an island woke since.
                (scratch.tally_fresh && !scratch.woke).then_some(scratch.pair_tally),
                &self.masses,
                scratch,
            )
        };
        profiler.end();
        if joint_broke {
            // The bodies of a broken joint collide again from the next step.
            self.joints_changed();
        }
        if config.sleeping {
            self.profiler.begin("sleep");
            self.fall_asleep(linked);
            self.profiler.end();
        }
        self.stats.sleeping = self.islands.sleeping_count();
        Ok(())
    }

    /// Whether this step's solve may leave the poses and velocities it integrates on the device
    /// ([`World::bodies_on_device`]): every stage on the GPU with the contacts staying there,
    /// the PGS solver (the Jacobi solver's adjacency reads the velocities on the host), and
    /// no drag (its row is built on the host from the pose).
    fn bodies_may_stay_on_device(&self) -> bool {
        self.bodies_may_stay_on_device
            && self.keeps_contacts_on_device()
            && self.devices.get(Stage::Integrate) == Executor::Gpu
            && self.config.solver == SolverKind::Pgs
            && self.drag.is_none()
    }

    /// Whether this step leaves the pairs' contacts on the device (see `contacts_on_device`):
    /// stages 1 to 4 in one submission, the rows, the batching and the solver on the GPU, and
    /// every pair one the GPU narrowphase computes.
    fn keeps_contacts_on_device(&self) -> bool {
        let on_gpu = |stage| self.devices.get(stage) == Executor::Gpu;
        self.contacts_may_stay_on_device
            && self.collides_in_one_submission()
            && on_gpu(Stage::Constraints)
            && on_gpu(Stage::Batching)
            && on_gpu(Stage::Solver)
            && self.host_shapes == 0
            && self.children.is_empty()
    }

    /// Whether stages 1 to 4 run as one GPU submission ([`GpuStages::collide`]): all four on
    /// the GPU, and no pair that the host must drop (pairs of removed bodies). Sleeping
    /// bodies' resting pairs, which no tree finds, go down with the bodies.
    fn collides_in_one_submission(&self) -> bool {
        let on_gpu = |stage| self.devices.get(stage) == Executor::Gpu;
        self.gpu.is_some()
            && on_gpu(Stage::Aabb)
            && on_gpu(Stage::Broadphase)
            && on_gpu(Stage::Narrowphase)
            && self.all_slots_live()
    }

    /// Whether no slot is free (no body removed since its slot was last reused): the free
    /// list says so without a pass over the slots.
    fn all_slots_live(&self) -> bool {
        debug_assert_eq!(
            self.free_slots.is_empty(),
            self.slots.iter().all(|slot| slot.is_live())
        );
        self.free_slots.is_empty()
    }

    /// Stages 1 to 4 in one GPU submission; the pair cache then takes the GPU's keys and
    /// contacts, and the host computes the pairs the GPU has no kernel for.
    fn collide_in_one_submission(&mut self, device_contacts: bool) -> Result<(), GpuError> {
        let version = self.pairs.version();
        if !self
            .gpu
            .as_ref()
            .is_some_and(|gpu| gpu.holds_pair_cache(version))
        {
            // The cache goes up from the host, keys included.
            self.fetch_pair_keys()?;
        }
        let config = self.config;
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;
        let gpu = self
            .gpu
            .as_mut()
            .expect("checked by collides_in_one_submission");
        static_mask(scratch, &self.masses, self.bodies_version);
        let bodies = BodyInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            masses: &self.masses,
            colliders: &self.colliders,
            version: self.bodies_version,
            changed: &self.body_changes,
        };
        debug_assert!(
            !self.contacts_on_device || gpu.holds_pair_cache(self.pairs.version()),
            "the host's contacts are stale and the device's are not the cache's"
        );
        // While bodies sleep, the device lists the wake test's candidates with the pairs.
        let wake = (device_contacts && self.islands.sleeping_count() > 0).then(|| WakeQuery {
            asleep: self.islands.asleep_bits(),
            candidates: &mut scratch.wake_pair_keys,
            listed: &mut scratch.wake_listed,
        });
        // Where the batches will be laid out on the device (no joint rows, the PGS solver) and
        // the device lists the wake's candidates, only the rarer steps read the pairs'
        // summaries (an island woken after the collision, the host's links): they stay there.
        let device_layout = config.solver == SolverKind::Pgs
            && gpu.lays_out_batches()
            && self.drag.is_none()
            && self.joints.iter().flatten().next().is_none();
        let summaries_back = !device_layout || gpu.lists_wake_candidates_on_host();
        self.pair_summaries_fresh = device_contacts && summaries_back;
        // With the batches laid out on the device (and the wake test there while bodies
        // sleep), the rows, the batching and the solve follow the collision without the host:
        // submitted with it, on a guess of its counts and that no island wakes.
        let on_gpu = |stage| self.devices.get(stage) == Executor::Gpu;
        let step_plan = (device_contacts
            && device_layout
            && on_gpu(Stage::Integrate)
            && (self.islands.sleeping_count() == 0 || !gpu.lists_wake_candidates_on_host()))
        .then(|| StepPlan {
            link_islands: config.sleeping && self.islands.may_rest(&self.masses, config.dt),
            settings: solver_settings(&config),
            batcher: config.batcher,
            bodies: self.poses.len(),
        });
        gpu.plan_step(step_plan);
        profiler.begin("collision");
        let collided = gpu.collide(
            profiler,
            &bodies,
            &scratch.is_static,
            OldPairs {
                count: self.pairs.len(),
                keys: self.pairs.has_keys().then(|| self.pairs.keys()),
                contacts: self.pairs.values(),
                version: self.pairs.version(),
            },
            &self.jointed_pairs,
            (config.contact_margin, config.dt),
            &mut scratch.pair_keys,
            if device_contacts {
                CollideOutput::Summaries(SummaryOutput {
                    summaries: summaries_back.then_some(&mut self.pair_summaries),
                    changes: &mut scratch.pair_changes,
                    tally: &mut scratch.pair_tally,
                    wake,
                })
            } else {
                CollideOutput::Contacts(&mut scratch.collided)
            },
        );
        if collided.is_err() {
            profiler.end();
            if self.contacts_on_device {
                // The device's contacts, the cache's values, may be half overwritten by now:
                // the cache starts afresh (the next step's pairs are all new, without warm
                // start) rather than from anything stale.
                self.pairs.update_keys(&[]);
                self.contacts_on_device = false;
            }
        }
        collided?;
        scratch.pairs_computed = gpu.pairs_computed();
        if device_contacts {
            scratch.tally_fresh = true;
            // The contacts are the device's, and so are the diff and the keys: they stay there
            // until the host needs them (`World::fetch_pair_keys`).
            let (count, changes) = (gpu.pair_count(), scratch.pair_changes);
            profiler.scope("pairs", || self.pairs.adopt_key_count(count, changes));
            self.device_keys = OnceLock::new();
        } else {
            profiler.scope("pairs", || self.pairs.update(&scratch.pair_keys));
        }
        if device_contacts {
            // Every pair is the GPU's (no host shapes, no child manifolds): the pair cache's
            // contacts stay on the device, where the rows read them.
            self.contacts_on_device = true;
            self.device_contacts = OnceLock::new();
            self.refresh_resting = false;
            gpu.pair_cache_is_collide_output();
            // From here the device's contacts are the cache's, even if a later stage of this
            // step fails.
            gpu.pair_cache_adopted(self.pairs.version());
            profiler.end();
            return Ok(());
        }
        let colliders = &self.colliders;
        let on_gpu = |key: u64| {
            let (a, b) = crate::stages::pairs::pair_bodies(key);
            narrowphase::gpu_pair(&colliders[a as usize].shape, &colliders[b as usize].shape)
        };
        let (keys, contacts) = self.pairs.keys_and_values_mut();
        let mut host_pairs = 0;
        for ((contact, collided), &key) in contacts.iter_mut().zip(&scratch.collided).zip(keys) {
            if on_gpu(key) {
                *contact = *collided;
            } else {
                host_pairs += 1;
            }
        }
        let inputs = narrowphase::NarrowphaseInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            colliders: &self.colliders,
            margin: config.contact_margin,
            dt: config.dt,
            skipped: &self.jointed_pairs,
            keep_resting: (!self.refresh_resting).then_some(&self.masses[..]),
        };
        self.refresh_resting = false;
        if host_pairs == 0 {
            gpu.pair_cache_is_collide_output();
        } else {
            scratch.pairs_computed += profiler.scope("cpu pairs", || {
                narrowphase::update_contacts_where(keys, contacts, &inputs, |a, b| {
                    !narrowphase::gpu_pair(a, b)
                })
            });
        }
        // Pairs with a mesh or a compound: one child manifold per touching triangle or child
        // pair, on the CPU.
        narrowphase::update_child_contacts(keys, &inputs, &mut self.children);
        profiler.end();
        Ok(())
    }

    /// Stages 1 to 4, each on its own executor.
    fn collide_stage_by_stage(&mut self) -> Result<(), GpuError> {
        let config = self.config;
        let dt = config.dt;
        let scratch = &mut self.scratch;
        let profiler = &mut self.profiler;
        let aabb_on_gpu = self.devices.get(Stage::Aabb) == Executor::Gpu;
        let broadphase_on_gpu = self.devices.get(Stage::Broadphase) == Executor::Gpu;

        // 1. World AABBs, grown by the speculative contact margin and swept over the step.
        profiler.begin("aabb");
        match &mut self.gpu {
            Some(gpu) if aabb_on_gpu => {
                let bodies = BodyInputs {
                    poses: &self.poses,
                    velocities: &self.velocities,
                    masses: &self.masses,
                    colliders: &self.colliders,
                    version: self.bodies_version,
                    changed: &self.body_changes,
                };
                // A GPU broadphase reads them where they are.
                let download = (!broadphase_on_gpu).then_some(&mut scratch.aabbs);
                let result =
                    gpu.compute_aabbs(profiler, &bodies, config.contact_margin, dt, download);
                profiler.end();
                result?;
            }
            _ => {
                aabb::compute_aabbs(
                    &self.poses,
                    &self.velocities,
                    &self.colliders,
                    config.contact_margin,
                    dt,
                    &mut scratch.aabbs,
                );
                profiler.end();
            }
        }

        // 2. Broadphase: refit the moving tree, then moving×moving and moving×static pairs.
        profiler.begin("broadphase");
        match &mut self.gpu {
            Some(gpu) if broadphase_on_gpu => {
                // Static to the broadphase: static, asleep or removed (their pairs go below).
                static_mask(scratch, &self.masses, self.bodies_version);
                let host_aabbs = (!aabb_on_gpu).then_some(&scratch.aabbs[..]);
                let result = gpu.find_pairs(
                    profiler,
                    host_aabbs,
                    &scratch.is_static,
                    &mut scratch.pair_keys,
                );
                if result.is_err() {
                    profiler.end();
                }
                result?;
                let slots = &self.slots;
                let live = |body: u32| slots[body as usize].is_live();
                scratch.pair_keys.retain(|&key| {
                    let (a, b) = crate::stages::pairs::pair_bodies(key);
                    live(a) && live(b)
                });
            }
            _ => {
                profiler.scope("update", || self.broadphase.update(&scratch.aabbs));
                profiler.scope("find pairs", || {
                    self.broadphase.find_pairs(&mut scratch.pair_keys)
                });
            }
        }
        // Sleeping bodies' pairs are in no tree's result: keep them with theirs.
        if !self.resting_pairs.is_empty() {
            merge_sorted(&mut scratch.pair_keys, &self.resting_pairs);
        }
        profiler.end();

        // 3. Pair cache: added / removed / kept; kept pairs keep their manifold.
        profiler.scope("pairs", || self.pairs.update(&scratch.pair_keys));

        // 4. Narrowphase: fresh manifolds, impulses carried over from matching points; pairs of
        //    polyhedra that barely moved move their old manifolds instead.
        profiler.begin("narrowphase");
        let (keys, contacts) = self.pairs.keys_and_values_mut();
        let inputs = narrowphase::NarrowphaseInputs {
            poses: &self.poses,
            velocities: &self.velocities,
            colliders: &self.colliders,
            margin: config.contact_margin,
            dt,
            skipped: &self.jointed_pairs,
            keep_resting: (!self.refresh_resting).then_some(&self.masses[..]),
        };
        self.refresh_resting = false;
        let narrowphase = match (self.devices.get(Stage::Narrowphase), &mut self.gpu) {
            (Executor::Gpu, Some(gpu)) => {
                let bodies = BodyInputs {
                    poses: &self.poses,
                    velocities: &self.velocities,
                    masses: &self.masses,
                    colliders: &self.colliders,
                    version: self.bodies_version,
                    changed: &self.body_changes,
                };
                gpu.update_contacts(profiler, keys, contacts, &inputs, &bodies)
            }
            _ => Ok(narrowphase::update_contacts(keys, contacts, &inputs)),
        };
        if let Ok(computed) = narrowphase {
            self.scratch.pairs_computed = computed;
            // Pairs with a mesh or a compound: one child manifold per touching triangle or
            // child pair (on the CPU: the GPU narrowphase has neither yet).
            narrowphase::update_child_contacts(keys, &inputs, &mut self.children);
        }
        profiler.end();
        narrowphase?;

        Ok(())
    }

    /// This step's pairs' summaries on the host (`pair_summaries`), read back from the device
    /// where the collision left them; nothing when they are here already, or when the
    /// contacts are the host's.
    fn fetch_pair_summaries(&mut self) -> Result<(), GpuError> {
        match &mut self.gpu {
            Some(gpu) if self.contacts_on_device => fetch_pair_summaries(
                gpu,
                &mut self.profiler,
                (self.pairs.len(), &mut self.pair_summaries),
                &mut self.pair_summaries_fresh,
            ),
            _ => Ok(()),
        }
    }

    /// Wakes every sleeping island that an awake dynamic body touches (a manifold with points)
    /// or is joined to, until none is left: a woken island may touch another.
    fn wake_touched(&mut self) {
        // The touching pairs with a sleeping body, the only ones that can wake one, then or
        // after a wake: listed by the collision on the device, or a pass over every pair.
        let mut candidates = std::mem::take(&mut self.scratch.wake_candidates);
        if self.scratch.wake_listed {
            let keys = self.scratch.wake_pair_keys.iter();
            candidates.clear();
            candidates.extend(keys.map(|&key| pair_bodies(key)));
        } else {
            // The step fetched the keys for this pass.
            let (keys, values) = (self.pairs.keys(), self.pairs.values());
            let summaries = self.contacts_on_device.then_some(&self.pair_summaries);
            let touching = |pair: usize| match summaries {
                Some(summaries) => summaries[pair].point_count > 0,
                None => values[pair].manifold.count > 0,
            };
            let islands = &self.islands;
            let asleep = |body: u32| islands.state(body).is_asleep();
            let parts = &mut self.scratch.edge_parts;
            wake_candidates(keys, touching, asleep, parts, &mut candidates);
        }
        let mut touched = Vec::new();
        loop {
            let awake = |i: u32| self.masses[i as usize].inverse_mass > 0.0;
            let asleep = |i: u32| self.islands.state(i).is_asleep();
            let touches = |(a, b): (u32, u32)| {
                if awake(a) && asleep(b) {
                    Some(b)
                } else if awake(b) && asleep(a) {
                    Some(a)
                } else {
                    None
                }
            };
            touched.extend(candidates.iter().copied().filter_map(touches));
            let joints = self.joints.iter().flatten().filter(|j| !j.broken);
            touched.extend(joints.filter_map(|joint| touches((joint.body_a, joint.body_b))));
            if touched.is_empty() {
                break;
            }
            self.scratch.woke = true;
            self.wake(&touched);
            touched.clear();
        }
        self.scratch.wake_candidates = candidates;
    }

    /// Gives the device the host's rest timers where they changed since it took them. Where
    /// the device moved them since and the host set some meanwhile (a velocity set, a body
    /// added), the device's come over first, with the host's set ones kept.
    fn give_device_rest_timers(&mut self) -> Result<(), GpuError> {
        if self.islands.set_on_host() {
            self.take_device_rest_timers()?;
        }
        let on_gpu = |stage| self.devices.get(stage) == Executor::Gpu;
        let solved_here = [
            Stage::Constraints,
            Stage::Batching,
            Stage::Solver,
            Stage::Integrate,
        ]
        .into_iter()
        .all(on_gpu);
        match &mut self.gpu {
            Some(gpu) => gpu.sync_rest_timers(&self.islands, self.config.sleeping, solved_here),
            None => Ok(()),
        }
    }

    /// The device's rest timers to the host, where the device moved them since the host had
    /// them (with the host's where it set some since).
    pub(crate) fn take_device_rest_timers(&mut self) -> Result<(), GpuError> {
        let Some(gpu) = self
            .gpu
            .as_mut()
            .filter(|_| self.islands.timers_on_device())
        else {
            return Ok(());
        };
        let timers = gpu.read_rest_timers(&mut self.profiler)?;
        if self.islands.adopt_device_timers(&timers) {
            return Ok(());
        }
        Err(GpuError::Readback {
            what: "rest timers",
            reason: format!(
                "{} timers for {} bodies, the others not set since",
                timers.len(),
                self.poses.len()
            ),
        })
    }

    /// Rest times from this step's velocities (moved on the device where its solve
    /// integrated the bodies); islands that rested long enough go to sleep and into the
    /// broadphase's fixed tree. `linked`: this step's contacts were linked into islands
    /// already (while the device solved); else the device's links are taken where it made
    /// them, or the host links them now. It cannot fail: the step has moved the bodies.
    fn fall_asleep(&mut self, linked: bool) {
        let tally = self.gpu.as_mut().and_then(GpuStages::take_rest_tally);
        let any_rested = match tally {
            Some(tally) => {
                self.islands.timers_moved_on_device(tally.max_timer);
                // The device found no island to put to sleep: the host leaves its timers
                // there (the usual step of a pile that stands).
                if !tally.may_sleep() {
                    return;
                }
                true
            }
            None => {
                // A read that fails leaves no island to sleep this step (the device's error
                // shows at its next submission); so below.
                if self.take_device_rest_timers().is_err() || self.sync_bodies().is_err() {
                    return;
                }
                let colliders = &self.colliders;
                self.profiler.begin("rest timers");
                let any_rested = self.islands.update_timers(
                    &self.velocities,
                    &self.masses,
                    |i| colliders[i].shape.bounding_radius(),
                    self.config.dt,
                );
                self.profiler.end();
                any_rested
            }
        };
        // No body has rested long enough to sleep: no island can (see update_timers). Else
        // the host needs every timer.
        if !any_rested || self.take_device_rest_timers().is_err() {
            return;
        }
        let mut linked = linked;
        if !linked && let Some(gpu) = &mut self.gpu {
            // A read that fails leaves the links to the host (the device's error shows at its
            // next submission).
            let roots = &mut self.scratch.island_roots;
            let read = gpu.read_island_links(&mut self.profiler, roots);
            linked = read.unwrap_or(false) && self.islands.adopt_links(roots);
        }
        if !linked && (self.fetch_pair_summaries().is_err() || self.fetch_pair_keys().is_err()) {
            // Nor can the host link them without the pairs' summaries and keys: no island
            // falls asleep this step.
            return;
        }
        let scratch = &mut self.scratch;
        if !linked {
            let contacts = PairEdges {
                keys: self.pairs.keys(),
                values: self.pairs.values(),
                summaries: self.contacts_on_device.then_some(&self.pair_summaries[..]),
            };
            let (islands, masses) = (&mut self.islands, &self.masses);
            let (parts, edges) = (&mut scratch.edge_parts, &mut scratch.sleep_edges);
            self.profiler.scope("links", || {
                link_contacts(islands, &contacts, masses, parts, edges)
            });
        }
        // The joints' edges after the solve, which may have broken some.
        scratch.sleep_edges.clear();
        let joints = self.joints.iter().flatten().filter(|j| !j.broken);
        scratch
            .sleep_edges
            .extend(joints.map(|j| (j.body_a, j.body_b)));
        self.islands.link(&scratch.sleep_edges, &self.masses);
        self.changed_bodies.clear();
        self.profiler.begin("islands");
        self.islands.fall_asleep(
            &mut self.masses,
            &mut self.velocities,
            self.drag.map(|drag| drag.body),
            &mut self.changed_bodies,
        );
        self.profiler.end();
        if self.changed_bodies.is_empty() {
            return;
        }
        // Their masses and velocities are zero now.
        self.masses_changed();
        for &body in &self.changed_bodies {
            self.broadphase.set_moving(body, false);
        }
        self.resting_pairs_changed();
        self.refresh_resting = true;
    }
}

/// This step's pairs' summaries into `summaries` (`count` of them) from `gpu`, unless
/// `fresh` says they are there already (see [`World::fetch_pair_summaries`]).
fn fetch_pair_summaries(
    gpu: &mut GpuStages,
    profiler: &mut crate::profile::Profiler,
    (count, summaries): (usize, &mut Vec<PairSummary>),
    fresh: &mut bool,
) -> Result<(), GpuError> {
    if !*fresh {
        gpu.read_pair_summaries(profiler, count, summaries)?;
        *fresh = true;
    }
    Ok(())
}

/// Pairs from which the host's work during the solve ([`link_contacts`], the rows'
/// summaries) runs beside it on the pool: below, handing the solve to a worker thread and back
/// costs more than the work saves, and the islands are linked after the solve, only when a
/// body has rested. Measured on an H200, falling-boxes at 3k (6.5k pairs): 2.47–2.52 ms a step
/// with the work beside the solve at every size, 2.10–2.32 with this threshold (2.37–2.41
/// before either).
const OVERLAP_MIN_PAIRS: usize = 8192;

/// The pairs as edges of the islands: their keys, and whether each has points (from the
/// summaries when the contacts are on the device, else from the contacts).
struct PairEdges<'a> {
    keys: &'a [u64],
    values: &'a [narrowphase::PairContact],
    summaries: Option<&'a [PairSummary]>,
}

/// This step's islands from the pairs with points: [`Islands::unlink_all`], then the edges
/// between awake dynamic bodies (a pass over every pair, on every core) linked.
fn link_contacts(
    islands: &mut Islands,
    pairs: &PairEdges,
    masses: &[BodyMass],
    parts: &mut FilterParts<(u32, u32)>,
    edges: &mut Vec<(u32, u32)>,
) {
    let touching = |pair: usize| match pairs.summaries {
        Some(summaries) => summaries[pair].point_count > 0,
        None => pairs.values[pair].manifold.count > 0,
    };
    let awake = |body: u32| masses[body as usize].inverse_mass > 0.0;
    let edge = |pair: usize| {
        // The summary first: read in order, and most pairs of a pile have no points.
        if !touching(pair) {
            return None;
        }
        let (a, b) = crate::stages::pairs::pair_bodies(pairs.keys[pair]);
        (awake(a) && awake(b)).then_some((a, b))
    };
    filter_map_ordered(pairs.keys.len(), edge, parts, edges);
    islands.unlink_all();
    islands.link(edges, masses);
}

/// Solved impulses back into the pair and child caches (by slot, see
/// [`ContactConstraint::pair`]), for next step's warm start.
fn store_contact_impulses(
    constraints: &[ContactConstraint],
    contacts: &mut [narrowphase::PairContact],
    children: &mut [narrowphase::PairContact],
) {
    let pair_count = contacts.len();
    for constraint in constraints {
        let slot = constraint.pair as usize;
        let contact = if slot < pair_count {
            &mut contacts[slot]
        } else {
            &mut children[slot - pair_count]
        };
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

/// What the host keeps of a contact row that stays on the device: its manifold slot, the
/// bodies the batching sees, its point count, whether it bounces.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RowSummary {
    pub(crate) slot: u32,
    bodies: (u32, u32),
    point_count: u32,
    restitution: bool,
}

/// The pairs whose contacts stayed on the device, as the device's rows are built from them:
/// one row per pair that [`has_constraint`], in pair order.
struct DeviceRows<'a> {
    keys: &'a [u64],
    summaries: &'a [PairSummary],
    masses: &'a [BodyMass],
    /// `None` when no collider in the world bounces.
    colliders: Option<&'a [crate::dynamics::body::Collider]>,
}

/// How many rows [`DeviceRows`] makes, and whether any bounces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RowTally {
    rows: usize,
    bounces: bool,
}

impl DeviceRows<'_> {
    fn row(&self, slot: usize) -> Option<RowSummary> {
        let (key, count) = (self.keys[slot], self.summaries[slot].point_count);
        has_constraint(key, count, self.masses)
            .then(|| RowSummary::new(slot as u32, key, count, self.masses, self.colliders))
    }

    /// The rows' summaries, in row order: a pass over every pair, on every core.
    fn summarize(&self, parts: &mut FilterParts<RowSummary>, out: &mut Vec<RowSummary>) {
        filter_map_ordered(self.keys.len(), |slot| self.row(slot), parts, out);
    }

    /// What the batching and the solver need of the rows before their summaries: a count on
    /// every core, with no output.
    fn tally(&self) -> RowTally {
        let tally = |slot| match self.row(slot) {
            Some(row) => (1, row.restitution),
            None => (0, false),
        };
        let (rows, bounces) = (0..self.keys.len())
            .into_par_iter()
            .with_min_len(MIN_PER_TASK)
            .map(tally)
            .reduce(|| (0, false), |a, b| (a.0 + b.0, a.1 || b.1));
        RowTally { rows, bounces }
    }
}

impl RowSummary {
    fn new(
        slot: u32,
        key: u64,
        point_count: u32,
        masses: &[crate::dynamics::body::BodyMass],
        colliders: Option<&[crate::dynamics::body::Collider]>,
    ) -> Self {
        let (a, b) = crate::stages::pairs::pair_bodies(key);
        Self {
            slot,
            bodies: constraint_bodies(key, masses),
            point_count,
            // As the rows compute it: the larger of the two restitutions. No colliders: none
            // in the world bounces.
            restitution: colliders.is_some_and(|colliders| {
                colliders[a as usize]
                    .restitution
                    .max(colliders[b as usize].restitution)
                    > 0.0
            }),
        }
    }
}

/// [`store_contact_impulses`] for rows that stayed on the device: `impulses[i]` belongs to
/// row `order[i]`.
fn store_batched_impulses(
    impulses: &[BatchedImpulses],
    order: &[u32],
    rows: &[RowSummary],
    contacts: &mut [narrowphase::PairContact],
    children: &mut [narrowphase::PairContact],
) {
    let pair_count = contacts.len();
    for (solved, &row) in impulses.iter().zip(order) {
        let row = rows[row as usize];
        let slot = row.slot as usize;
        let contact = if slot < pair_count {
            &mut contacts[slot]
        } else {
            &mut children[slot - pair_count]
        };
        for (k, impulse) in contact
            .impulses
            .iter_mut()
            .enumerate()
            .take(row.point_count as usize)
        {
            impulse.normal = solved.normal[k];
            impulse.tangent = [solved.tangent1[k], solved.tangent2[k]];
        }
    }
}

/// Solved impulses, as (joint index, point impulse, angular impulses), back into the joints
/// and the drag ([`DRAG_JOINT`]); a joint whose impulse passed its threshold breaks. Returns
/// whether one broke.
fn store_joint_impulses(
    solved: impl Iterator<Item = (u32, Vec3, [f32; MAX_ANGULAR_ROWS])>,
    joints: &mut [Option<crate::dynamics::joint::Joint>],
    mut drag: Option<&mut Drag>,
) -> bool {
    let mut any_broke = false;
    for (index, point_impulse, angular_impulse) in solved {
        if index == DRAG_JOINT {
            if let Some(drag) = drag.as_deref_mut() {
                drag.impulse = point_impulse;
            }
            continue;
        }
        let Some(joint) = joints.get_mut(index as usize).and_then(Option::as_mut) else {
            continue;
        };
        joint.point_impulse = point_impulse;
        joint.angular_impulse = angular_impulse;
        if let Some(threshold) = joint.break_impulse {
            let total =
                point_impulse.length() + angular_impulse.iter().map(|i| i.abs()).sum::<f32>();
            joint.broken = total > threshold;
            any_broke |= joint.broken;
        }
    }
    any_broke
}

/// `scratch.is_static`, the bodies that are static to a GPU broadphase (static, asleep or
/// removed: no mass), made again only when the bodies changed since (`version`, the world's
/// `bodies_version`, which every change of a mass moves): a pass over every body's mass was
/// 0.1 ms of a 100k pile's step, before anything went to the device.
fn static_mask(scratch: &mut StepScratch, masses: &[BodyMass], version: u64) {
    let fixed = |mass: &BodyMass| mass.inverse_mass == 0.0;
    if scratch.is_static_version != Some(version) {
        scratch.is_static.clear();
        scratch.is_static.extend(masses.iter().map(fixed));
        scratch.is_static_version = Some(version);
    }
    debug_assert!(
        scratch
            .is_static
            .iter()
            .copied()
            .eq(masses.iter().map(fixed)),
        "a mass changed without moving the bodies' version"
    );
}

/// Merges the sorted, disjoint `extra` keys into the sorted `keys`.
pub(crate) fn merge_sorted(keys: &mut Vec<u64>, extra: &[u64]) {
    keys.extend_from_slice(extra);
    // Two sorted runs: the standard library's stable sort finds them and merges in O(n).
    keys.sort();
    debug_assert!(keys.windows(2).all(|w| w[0] < w[1]), "pair sets overlap");
}

/// Items a task of [`collect_stats`] takes at least: a few thousand stay on one thread.
const MIN_PER_TASK: usize = 8192;

/// Where [`collect_stats`] finds the pairs' contacts.
#[derive(Clone, Copy)]
enum PairContacts<'a> {
    /// In the pair cache.
    Host,
    /// On the device, this step's summaries read back.
    Summaries(&'a [PairSummary]),
    /// On the device with their summaries: the collision's tally must stand for them.
    OnDevice,
}

/// The step's statistics; `contacts` says where the pairs' contacts are (their summaries
/// stand for them when they stayed on the device), and `tally` stands for the passes over
/// them and the rows when the device counted them.
fn collect_stats(
    pairs: &crate::stages::pairs::PairCache<narrowphase::PairContact>,
    children: &narrowphase::ChildCache,
    contacts: PairContacts,
    tally: Option<PairTally>,
    masses: &[BodyMass],
    scratch: &StepScratch,
) -> StepStats {
    let summaries = match contacts {
        PairContacts::Summaries(summaries) => Some(summaries),
        PairContacts::OnDevice | PairContacts::Host => None,
    };
    let stats = StepStats {
        pairs: pairs.len(),
        pairs_added: pairs.changes().0,
        pairs_removed: pairs.changes().1,
        pairs_computed: scratch.pairs_computed,
        child_manifolds: children.len(),
        child_manifolds_added: children.added(),
        child_manifolds_removed: children.removed(),
        manifolds: scratch.contacts.len() + scratch.row_summaries.len() + scratch.unsummarized_rows,
        contacts: 0,
        max_penetration: 0.0,
        // The rows that stayed on the device are known by their slots.
        joints: scratch.joints.len().max(scratch.joint_row_slots.len()),
        sleeping: 0,
        batch_histogram: Vec::new(),
        batching_rounds: scratch.coloring.rounds,
    };
    let host_contacts = scratch.contacts.iter().map(|c| c.point_count as usize);
    let host_contacts = host_contacts.sum::<usize>();
    if let Some(tally) = tally {
        let counted = StepStats {
            contacts: host_contacts + tally.contacts,
            max_penetration: tally.deepest,
            ..stats.clone()
        };
        // The host's passes, where it has what they read.
        debug_assert!(
            matches!(contacts, PairContacts::OnDevice)
                || !pairs.has_keys()
                || counted
                    == host_stats(
                        stats.clone(),
                        host_contacts,
                        pairs,
                        children,
                        (summaries, masses),
                        scratch
                    ),
            "the device's tally of the rows is not the host's"
        );
        return counted;
    }
    debug_assert!(
        !matches!(contacts, PairContacts::OnDevice),
        "the host counts from the pairs' summaries, which it has not read"
    );
    let pair_contacts = (summaries, masses);
    host_stats(
        stats,
        host_contacts,
        pairs,
        children,
        pair_contacts,
        scratch,
    )
}

/// [`collect_stats`]' passes over every pair and row, on every core when there are many (max
/// and sum give the same result in any order).
fn host_stats(
    stats: StepStats,
    host_contacts: usize,
    pairs: &crate::stages::pairs::PairCache<narrowphase::PairContact>,
    children: &narrowphase::ChildCache,
    (summaries, masses): (Option<&[PairSummary]>, &[BodyMass]),
    scratch: &StepScratch,
) -> StepStats {
    let max_penetration = match summaries {
        Some(summaries) => {
            summaries
            .par_iter()
            .with_min_len(MIN_PER_TASK)
            .map(|s| s.depth)
            .reduce(|| 0.0f32, f32::max)
            // −0 and +0 compare equal, and which one `max` keeps may depend on the order.
            + 0.0
        }
        None => pairs
            .values()
            .iter()
            .chain(children.values())
            .map(|c| PairSummary::of(c).depth)
            .fold(0.0f32, f32::max),
    };
    let row_points = if scratch.unsummarized_rows == 0 {
        let rows = scratch.row_summaries.par_iter().with_min_len(MIN_PER_TASK);
        rows.map(|r| r.point_count as usize).sum::<usize>()
    } else {
        // The rows left on the device unsummarized: the pairs with a constraint.
        let summaries = summaries.unwrap_or_default();
        let pairs = pairs.keys().par_iter().zip(summaries);
        let row = |(&key, summary): (&u64, &PairSummary)| {
            let count = summary.point_count;
            has_constraint(key, count, masses).then_some((1, count as usize))
        };
        let (rows, points) = (pairs.with_min_len(MIN_PER_TASK).filter_map(row))
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        debug_assert_eq!(rows, scratch.unsummarized_rows, "rows left on the device");
        points
    };
    StepStats {
        contacts: host_contacts + row_points,
        max_penetration,
        ..stats
    }
}
