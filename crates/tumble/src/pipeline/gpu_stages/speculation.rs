//! A step's rows, batching and solve submitted with its collision, on a guess, so that the
//! device runs the whole step without waiting for the host between the collision and the
//! solve.
//!
//! What the host reads between them, and so what the rows and the solve were recorded from
//! after the collision's wait, is a handful of counts: how many pairs there are (the broadphase
//! grows when they overflow it), how many rows (their buffers' size, the batching's and the
//! solver's counts), whether one bounces (the restitution sweep) and, while bodies sleep,
//! whether an island wakes (its masses change before the rows). The step guesses them: the
//! pairs whose keys the collision copies for the rows anyway, room for last step's rows and
//! some more, last step's restitution, no island waking. A one-thread kernel (`held.wgsl`)
//! checks the guesses against the collision's tally and the wake test on the device and hands
//! the batching and the solver their count, none where a guess was wrong; the integration and
//! the impulses' scatter, the only kernels that write what the step reads again, then write
//! nothing. After the one wait the host reads that word: where the step held, the rows',
//! batching's and solve's calls only take their results; where it did not, they record and
//! submit as they would have.
//!
//! The next step's solve is recorded during this step's wait for its own
//! ([`GpuStages::record_next_solve`]), so that the host records only the rows and the batching
//! between the collision's submission and the solve's.

use std::time::Instant;

use super::{
    BatchingPlan, CONSTRAINTS, GpuStages, Recording, SolveAhead, SolvePlan, elapsed_ms,
    encode_island_links, encode_pass, link_pairs,
};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{Binding, Dispatch, Kernel, Source, encode_all};
use crate::gpu::profiler::SpanPath;
use crate::profile::{Profiler, SpanKind};
use crate::stages::batching::Batcher;
use crate::stages::constraints::gpu::GpuRowInputs;
use crate::stages::solver::SolverSettings;

const WGSL: &str = include_str!("held.wgsl");
/// The guesses, the pair count, the rows' tally, the word, the batching's tally, the solve's
/// counts, the wake test's wakers.
const BINDINGS: [Binding; 7] = [
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
];
/// The check's pass, timed with the rows' and the batching's.
const HOLD_KERNEL: SpanPath = &["batching", "kernels: whether the step held"];
/// The rows', batching's and solver's commands recorded and submitted during the collision's
/// wait.
const SUBMITTED_AHEAD: SpanPath = &[
    "collision",
    "rows, batching and solver submitted (during the wait)",
];

/// The next step's solve recorded during this one's wait.
const NEXT_SOLVE_RECORDED: SpanPath = &["solver", "next step's solve encoded (during the wait)"];

/// What a step knows, before its collision, of the rows, the batching and the solve that
/// follow it when they all run on the device with the batch layout there (and the wake test
/// while bodies sleep): everything they are recorded from but the counts the collision finds.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StepPlan {
    /// The islands' links made with the rows.
    pub link_islands: bool,
    pub settings: SolverSettings,
    pub batcher: Batcher,
    /// The body slots.
    pub bodies: usize,
}

/// A step submitted ahead: what its rows, batching and solve were recorded from, and whether
/// it held (read after the collision's wait).
pub(super) struct Speculated {
    pub held: bool,
    pub link_islands: bool,
    pub batching: BatchingPlan,
    pub solve: SolvePlan,
}

/// The check of the guesses (`held.wgsl`), its dispatch kept for the buffers it binds.
pub(super) struct StepHold {
    kernel: Kernel,
    /// The guesses, sent with each step.
    guess: GpuVec<u32>,
    cached: Option<([wgpu::Buffer; 6], Dispatch)>,
}

/// The buffers the check reads and writes besides its guesses.
struct HoldBuffers<'a> {
    pair_count: &'a GpuVec<u32>,
    tally: &'a GpuVec<u32>,
    held: &'a GpuVec<u32>,
    batching_tally: &'a GpuVec<[u32; 4]>,
    batched_count: &'a GpuVec<u32>,
    wakers: &'a GpuVec<u32>,
}

impl StepHold {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = Source::new().snippet("held.wgsl", WGSL);
        Ok(Self {
            kernel: Kernel::new(context, "hold_step", &source, "hold_step", &BINDINGS),
            guess: GpuVec::from_slice(context, "step guesses", &[0; 4])?,
            cached: None,
        })
    }

    /// Encodes the check of `guess` (the pairs the rows read, their room, the bounce, whether
    /// the wake test ran).
    fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        guess: [u32; 4],
        buffers: &HoldBuffers,
    ) -> Result<(), GpuError> {
        // Lands before the submission's commands run.
        self.guess.upload(context, &guess)?;
        let key = [
            buffers.pair_count.buffer().clone(),
            buffers.tally.buffer().clone(),
            buffers.held.buffer().clone(),
            buffers.batching_tally.buffer().clone(),
            buffers.batched_count.buffer().clone(),
            buffers.wakers.buffer().clone(),
        ];
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, _)| *cached != key)
        {
            let group = self.kernel.bind(
                context,
                &[
                    self.guess.whole(),
                    buffers.pair_count.whole(),
                    buffers.tally.whole(),
                    buffers.held.whole(),
                    buffers.batching_tally.whole(),
                    buffers.batched_count.whole(),
                    buffers.wakers.whole(),
                ],
            );
            self.cached = Some((key, self.kernel.dispatch(group, 1)));
        }
        if let Some((_, dispatch)) = &self.cached {
            encode_all(pass, std::slice::from_ref(dispatch));
        }
        Ok(())
    }
}

/// The rows' room beyond last step's count, at least (`expected_pair_count`'s margin).
pub(super) const ROW_MARGIN: usize = 1024;

/// Room for the rows of a step whose last had `last`: an eighth more, and at least `margin`
/// more, so that a pile coming to rest seldom outgrows it.
fn row_room(last: usize, margin: usize) -> usize {
    last + (last / 8).max(margin)
}

impl GpuStages {
    /// The step's plan, before its collision, for its rows, batching and solve to be
    /// submitted with it ([`Self::collide`]); `None` where they may not.
    pub(crate) fn plan_step(&mut self, plan: Option<StepPlan>) {
        // A step after one without rows (a world asleep, or not yet touching) likely has none
        // either, and a step without rows does not hold (the check asks for some): it runs its
        // stages as it would have.
        let likely = self.last_rows > 0;
        self.step_plan =
            plan.filter(|_| likely && self.speculates && !self.profiler.times_dispatches());
    }

    /// Records the rows, the batching and the solve of the planned step (`plan`) and submits
    /// them, after the collision's submission: `staged` pairs' keys are copied for the rows;
    /// `wake_checked`: the collision ran the wake test (bodies sleep).
    pub(super) fn submit_speculation(
        &mut self,
        profiler: &mut Profiler,
        plan: StepPlan,
        (staged, wake_checked): (usize, bool),
    ) -> Result<(), GpuError> {
        // A handle of its own (reference-counted), for the recording to borrow `self`.
        let context = &self.context.clone();
        let start = Instant::now();
        self.ahead_profiler.discard();
        self.ahead_batching_profiler.discard();
        let room = row_room(self.last_rows, self.row_margin).min(self.broadphase.capacity());
        let batching = BatchingPlan {
            any: true,
            body_count: plan.bodies,
            batcher: plan.batcher,
            rounds: self.batching_rounds,
        };
        let link_islands = plan.link_islands && !self.host_island_links;
        let rest = self.rests_bodies(plan.bodies).then_some(link_islands);
        let solve = SolvePlan {
            settings: plan.settings,
            jacobi: false,
            restitution: self.last_bounced,
            integrating: true,
            impulses_back: false,
            scatter: true,
            joints: false,
            by_body: self.warm_start_by_body,
            expected: Some(self.expected_batch_sizes),
            bodies: plan.bodies,
            rest,
            bodies_back: self.reads_bodies_back(rest),
        };
        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("rows, batching and solver, submitted ahead"),
            });
        // The rows: the keys the collision copied, the live count copied from the
        // broadphase's on the device.
        self.rows
            .encode_live_copy(&mut encoder, self.broadphase.count());
        let device = &self.bodies;
        let inputs = GpuRowInputs {
            keys: &self.keys,
            contacts: &self.contacts,
            poses: &device.poses,
            velocities: &device.velocities,
            masses: &device.masses,
            colliders: &device.colliders,
            softness: plan.settings.contact_softness,
            static_softness: plan.settings.static_softness,
        };
        let (rows, timer) = (&mut self.rows, &mut self.ahead_batching_profiler);
        encode_pass(&mut encoder, timer, CONSTRAINTS.kernel, |pass| {
            rows.encode(context, pass, &inputs, Some(room), true)
        })?;
        if link_islands {
            let pairs = link_pairs(&self.broadphase, &self.summaries);
            let passes = (&mut encoder, &mut *timer);
            encode_island_links(
                context,
                passes,
                &mut self.island_links,
                &pairs,
                &device.masses,
            )?;
        }
        // The batching's and the solve's buffers for the room; their counts are the check's.
        self.batched.size_for(context, room, 0)?;
        let bodies = (&self.rows.bodies, room);
        self.batching
            .prepare_device_bodies(context, bodies, plan.bodies)?;
        let zeros = [0; super::LAYOUT_BATCHES + 1];
        self.joint_batch_offsets.upload(context, &zeros)?;
        self.joint_rows.upload_order(context, &[])?;
        self.solver_bodies.resize(context, plan.bodies)?;
        let guess = [
            staged as u32,
            room as u32,
            u32::from(solve.restitution),
            u32::from(wake_checked),
        ];
        let buffers = HoldBuffers {
            pair_count: self.broadphase.count(),
            tally: self.row_tally.totals(),
            held: self.finalize_bodies.held(),
            batching_tally: self.batching.tally(),
            batched_count: self.batched.count(),
            wakers: self.wake.wakers(),
        };
        let hold = &mut self.step_hold;
        encode_pass(&mut encoder, timer, HOLD_KERNEL, |pass| {
            hold.encode(context, pass, guess, &buffers)
        })?;
        self.record_batching(&mut encoder, &batching, true)?;
        // The solve recorded during the last step's wait, where it solves as this one would
        // and reads the buffers this one would (none made since, the impulses' contacts
        // this step's).
        let resources = context.resources_made();
        let recorded = self.next_solve.take().filter(|(next, contacts)| {
            next.plan.solves_as(&solve)
                && next.resources == resources
                && contacts == self.contacts.buffer()
        });
        let solve_commands = match recorded {
            Some((next, _)) => {
                self.next_solves_submitted += 1;
                // Its spans are now the step's solve's.
                std::mem::swap(&mut self.ahead_profiler, &mut self.next_profiler);
                Some(next.commands)
            }
            None => {
                self.next_profiler.discard();
                self.encode_batched_solve(&mut encoder, &solve, None, Recording::Ahead)?;
                None
            }
        };
        self.finalize_bodies
            .encode_held_download(context, &mut encoder);
        let commands = encoder.finish();
        context
            .queue
            .submit(std::iter::once(commands).chain(solve_commands));
        profiler.record(SUBMITTED_AHEAD, SpanKind::Cpu, elapsed_ms(start));
        // The host would wait here: it records the next step's solve meanwhile.
        self.record_next_solve(profiler, &solve);
        self.speculated = Some(Speculated {
            held: false,
            link_islands,
            batching,
            solve,
        });
        Ok(())
    }

    /// Records the next step's solve (from `plan`, this step's) during this step's wait, for
    /// the next step submitted with its collision to submit ([`Recording::NextStep`]). A
    /// failure leaves it to record its solve itself, where it fails again.
    pub(super) fn record_next_solve(&mut self, profiler: &mut Profiler, plan: &SolvePlan) {
        self.next_solve = None;
        self.next_profiler.discard();
        // Only a device layout's solve, the contacts' impulses staying here, is submitted so.
        let speculative = plan.expected.is_some()
            && plan.integrating
            && plan.scatter
            && !plan.jacobi
            && !plan.joints
            && !plan.impulses_back;
        // Nor are steps whose dispatches are timed, or after one without rows (`plan_step`).
        let submitted = self.speculates
            && self.encodes_ahead
            && !self.profiler.times_dispatches()
            && self.last_rows > 0;
        if !(submitted && speculative) {
            return;
        }
        let start = Instant::now();
        let mut encoder =
            self.context
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("solver, recorded a step ahead"),
                });
        if self
            .encode_batched_solve(&mut encoder, plan, None, Recording::NextStep)
            .is_err()
        {
            self.next_profiler.discard();
            return;
        }
        let ahead = SolveAhead {
            plan: plan.clone(),
            resources: self.context.resources_made(),
            commands: encoder.finish(),
        };
        self.next_solve = Some((ahead, self.old_contacts.buffer().clone()));
        profiler.record(NEXT_SOLVE_RECORDED, SpanKind::Cpu, elapsed_ms(start));
    }

    /// After the collision's wait: whether the step submitted with it held.
    pub(super) fn read_speculation(&mut self) -> Result<(), GpuError> {
        if let Some(speculated) = &mut self.speculated {
            speculated.held = self.finalize_bodies.read_held(&self.context)?;
            if speculated.held {
                self.steps_held += 1;
            } else {
                self.steps_not_held += 1;
                // The step runs its stages again, integrating as any does.
                self.finalize_bodies.reset_held(&self.context)?;
            }
        }
        Ok(())
    }

    /// Whether this step's rows, batching and solve were submitted with its collision and
    /// held: the step then only takes their results.
    pub(crate) fn holds_step(&self) -> bool {
        self.held_step().is_some()
    }

    /// The step submitted with the collision, where it held: the stages after the collision
    /// then only take its results. `None` where it did not (they record and submit their
    /// commands).
    pub(super) fn held_step(&self) -> Option<&Speculated> {
        self.speculated
            .as_ref()
            .filter(|speculated| speculated.held)
    }
}

/// A step that held was planned otherwise than the stage after the collision planned it: a
/// bug, reported rather than solved again, since the device has integrated the bodies.
pub(super) fn unplanned(what: &'static str) -> GpuError {
    GpuError::Unplanned { what }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The check holds a step exactly when its guesses were right: the pairs within those the
    /// rows read, some rows and no more than their room, the bounce as guessed; and hands the
    /// batching and the solve the rows' count, or none.
    #[test]
    fn the_check_holds_a_step_exactly_when_its_guesses_were_right() {
        let _turn = super::super::tests::turn();
        let context = GpuContext::shared()
            .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"));
        let mut hold = StepHold::new(&context).unwrap();
        // (pairs, rows, bouncing rows, wakers), the guesses (pairs read, room, bounce, wake
        // test), held.
        let cases = [
            ((90, 40, 0, 0), [100, 50, 0, 0], true),
            ((100, 50, 3, 0), [100, 50, 1, 0], true),
            ((90, 40, 0, 1), [100, 50, 0, 0], true),
            ((90, 40, 0, 0), [100, 50, 0, 1], true),
            ((101, 40, 0, 0), [100, 50, 0, 0], false),
            ((90, 51, 0, 0), [100, 50, 0, 0], false),
            ((90, 0, 0, 0), [100, 50, 0, 0], false),
            ((90, 40, 2, 0), [100, 50, 0, 0], false),
            ((90, 40, 0, 0), [100, 50, 1, 0], false),
            ((90, 40, 0, 1), [100, 50, 0, 1], false),
        ];
        for ((pairs, rows, bouncing, wakers), guess, held) in cases {
            let mut tally = [0; 8];
            (tally[1], tally[2]) = (rows, bouncing);
            let buffers = HoldBuffers {
                pair_count: &GpuVec::from_slice(&context, "pairs", &[pairs]).unwrap(),
                tally: &GpuVec::from_slice(&context, "tally", &tally).unwrap(),
                held: &GpuVec::from_slice(&context, "held", &[7]).unwrap(),
                batching_tally: &GpuVec::from_slice(&context, "tally", &[[0, 9, 0, 9]]).unwrap(),
                batched_count: &GpuVec::from_slice(&context, "counts", &[9, 0]).unwrap(),
                wakers: &GpuVec::from_slice(&context, "wakers", &[wakers]).unwrap(),
            };
            context.submit_pass("hold", |pass| {
                hold.encode(&context, pass, guess, &buffers).unwrap();
            });
            let count = if held { rows } else { 0 };
            let case = format!(
                "{pairs} pairs, {rows} rows, {bouncing} bouncing, {wakers} wakers, {guess:?}"
            );
            assert_eq!(
                buffers.held.read(&context).unwrap(),
                [u32::from(held)],
                "{case}"
            );
            let batching = buffers.batching_tally.read(&context).unwrap();
            assert_eq!(batching, [[0, count, 0, 9]], "{case}");
            let batched = buffers.batched_count.read(&context).unwrap();
            assert_eq!(batched, [count, 0], "{case}");
        }
    }
}
