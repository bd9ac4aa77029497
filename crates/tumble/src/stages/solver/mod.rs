//! Stage 7: the solver — Box2D v3's *soft step* over the colored batches.
//!
//! Collision runs once per step; the solver then takes `substeps` sub-steps of h = dt/substeps,
//! each:
//!
//! 1. integrate velocities (gravity);
//! 2. warm start: apply the impulses accumulated last sub-step (last step's at first);
//! 3. `iterations` projected Gauss-Seidel sweeps over the batches **with** position bias: a
//!    contact or joint error C is removed by a soft spring-damper bias
//!    ([`Softness`](crate::pipeline::config::Softness)), capped at `max_push_velocity`;
//! 4. integrate positions — into per-body delta positions and rotations, from which the
//!    constraints track their current separations and angles;
//! 5. one **relax** sweep without bias, which takes the bias velocity back out so that
//!    position correction adds no kinetic energy.
//!
//! After the last sub-step, one restitution sweep (Box2D v3): a point that pushed this step and
//! approached faster than the threshold gets the normal velocity `−e · approach`.
//!
//! Why this and not plain PGS with split impulses or Baumgarte: measured here, a 10-box tower
//! with 10 PGS iterations and a split impulse kept swaying (kinetic energy growing to 0.09 J,
//! 8 cm drift in 10 s) because the position correction, solved point by point without warm
//! starting, injects small rotations every step; with 4 soft sub-steps of 1 iteration (less
//! work) it stands. Sub-stepping inside the solver also keeps collision at one pass per step,
//! which is what a GPU step can afford.
//!
//! Guarantees: a batch's constraints touch disjoint dynamic bodies (stage 6), so solving them in
//! parallel gives bitwise the same result as solving them in order, for any thread count.
//!
//! [`SolverKind::Jacobi`] runs the same soft step with Jacobi sweeps instead ([`jacobi`]): for
//! comparison, as DESIGN.md's stage 7 asks.

pub mod adjacency;
pub mod batched;
mod contact;
pub mod gpu;
pub mod jacobi;
pub mod jacobi_gpu;
mod joint;

use crate::math::{Quat, Vec3};
use crate::pipeline::config::Softness;
use crate::stages::constraints::{ContactConstraint, JointConstraint, STATIC_BODY};
use crate::stages::integrate::{clamp_rotation, integrate_rotation};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A body as the solver moves it during one step. 64 bytes, WGSL-aligned (repr(C), Pod).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SolverBody {
    pub linear_velocity: Vec3,
    pub inverse_mass: f32,
    pub angular_velocity: Vec3,
    pub _pad0: f32,
    /// Displacement since the start of the step (m).
    pub delta_position: Vec3,
    pub _pad1: f32,
    /// Rotation since the start of the step.
    pub delta_rotation: Quat,
}
const _: () = assert!(size_of::<SolverBody>() == 64);

impl SolverBody {
    /// A static body, or one that has not moved: zero velocity, identity delta.
    pub const STATIC: Self = Self {
        linear_velocity: Vec3::ZERO,
        inverse_mass: 0.0,
        angular_velocity: Vec3::ZERO,
        _pad0: 0.0,
        delta_position: Vec3::ZERO,
        _pad1: 0.0,
        delta_rotation: Quat::IDENTITY,
    };
}

/// How the sweeps of the soft step visit the constraints.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SolverKind {
    /// Projected Gauss-Seidel over the colored batches: each constraint sees the impulses of
    /// the batches before it in the same sweep.
    #[default]
    Pgs,
    /// Projected Jacobi ([`jacobi`]): every constraint of a sweep sees the velocities of the
    /// sweep's start and the relaxed changes are summed per body at its end. No batches, two
    /// GPU dispatches a sweep, and more iterations for the same error.
    Jacobi,
}

impl SolverKind {
    pub const ALL: [SolverKind; 2] = [SolverKind::Pgs, SolverKind::Jacobi];

    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Pgs => "pgs",
            SolverKind::Jacobi => "jacobi",
        }
    }
}

impl std::fmt::Display for SolverKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A solver name that is none of [`SolverKind::ALL`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown solver {0:?}; solvers are pgs, jacobi")]
pub struct UnknownSolver(pub String);

impl std::str::FromStr for SolverKind {
    type Err = UnknownSolver;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        SolverKind::ALL
            .into_iter()
            .find(|kind| kind.name() == name)
            .ok_or_else(|| UnknownSolver(name.to_owned()))
    }
}

/// Solver settings for one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverSettings {
    pub dt: f32,
    pub substeps: u32,
    pub iterations: u32,
    pub gravity: Vec3,
    /// Fastest push out of overlap (m/s).
    pub max_push_velocity: f32,
    /// Approach speed above which restitution applies (m/s).
    pub restitution_threshold: f32,
    /// The contact rows' softness between two dynamic bodies and against a static one, as
    /// the rows were built with (each row carries its own too). The device's sweeps read it
    /// from here rather than load it with every constraint (`load_header` in solver.wgsl).
    pub contact_softness: Softness,
    pub static_softness: Softness,
}

impl SolverSettings {
    /// The softness of a contact row between bodies of inverse masses `mass_a` and `mass_b`
    /// (`build_constraints`' choice: against a static body when either is 0).
    pub fn contact_softness_of(&self, mass_a: f32, mass_b: f32) -> Softness {
        if mass_a == 0.0 || mass_b == 0.0 {
            self.static_softness
        } else {
            self.contact_softness
        }
    }
}

/// The constraints of a step laid out batch after batch: batch `i` is
/// `contacts[contact_offsets[i]..contact_offsets[i + 1]]` together with the same range of
/// `joints` through `joint_offsets`; the last batch is the sequential overflow batch when
/// `has_overflow`.
pub struct Batched<'a> {
    pub contacts: &'a mut [ContactConstraint],
    pub contact_offsets: &'a [u32],
    pub joints: &'a mut [JointConstraint],
    pub joint_offsets: &'a [u32],
    pub has_overflow: bool,
}

/// What a sweep does with position errors.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sweep {
    /// Sub-step length (s).
    pub h: f32,
    /// Remove position errors (solve) or not (relax).
    pub use_bias: bool,
    pub max_push_velocity: f32,
    /// The bodies moved since the last sweep: recompute the contact separations (two
    /// quaternion rotations per point) and keep them. Positions change only between the solve
    /// and relax sweeps of a sub-step, so the solve sweeps after the first reuse the last
    /// relax sweep's separations: 9 computations a step instead of 16. The GPU executor
    /// computes them in every sweep and keeps none (`solve_normal` in `solver.wgsl` says why):
    /// the same separations, so the same impulses.
    pub moved: bool,
}

/// CPU executor: the whole soft step; `bodies` come in with the step-start velocities and
/// zero deltas and leave with the final velocities and the step's deltas.
///
/// # Panics
///
/// If a constraint names a body past `bodies` (other than [`STATIC_BODY`]).
pub fn solve(bodies: &mut [SolverBody], batched: &mut Batched, settings: SolverSettings) {
    let body_count = bodies.len();
    // Checked once here rather than at each body access in the sweeps (see `BodyAccess`).
    let in_range = |body: u32| body == STATIC_BODY || (body as usize) < body_count;
    assert!(
        batched
            .contacts
            .iter()
            .all(|c| in_range(c.body_a) && in_range(c.body_b))
            && batched
                .joints
                .iter()
                .all(|j| in_range(j.body_a) && in_range(j.body_b)),
        "a constraint names a body that is not in the solver's body array"
    );
    let step = Step {
        bodies: BodyAccess(bodies.as_mut_ptr(), body_count),
        contacts: Shared::new(batched.contacts),
        contact_offsets: batched.contact_offsets,
        joints: Shared::new(batched.joints),
        joint_offsets: batched.joint_offsets,
        has_overflow: batched.has_overflow,
        restitution: batched.contacts.iter().any(|c| c.restitution > 0.0),
        settings,
    };
    // Workers past the widest stage's blocks would only wait at every stage's end, spinning
    // on the team's counters beside the workers that have blocks to run: a small world's
    // solve runs on one thread.
    let threads = rayon::current_num_threads().min(step.widest_stage());
    if threads == 1 {
        step.run(&mut Worker::alone());
        return;
    }
    // One rayon scope for the whole step: every worker walks the same schedule and claims
    // blocks of each stage (see `Worker`). A parallel iterator per batch instead cost a
    // fork-join with wake-ups for each of the ~500 stages of a step.
    let team = Team::default();
    rayon::scope(|scope| {
        for _ in 1..threads {
            scope.spawn(|_| step.run(&mut Worker::in_team(&team)));
        }
        step.run(&mut Worker::in_team(&team));
    });
}

/// What every worker of a step shares: the bodies, the batched constraints (through raw
/// pointers, see [`Shared`]) and the settings.
struct Step<'a> {
    bodies: BodyAccess,
    contacts: Shared<ContactConstraint>,
    contact_offsets: &'a [u32],
    joints: Shared<JointConstraint>,
    joint_offsets: &'a [u32],
    has_overflow: bool,
    restitution: bool,
    settings: SolverSettings,
}

impl Step<'_> {
    /// The soft step's schedule. Every worker runs it; `worker.stage` hands each block of a
    /// stage to exactly one worker and starts a stage only when the one before it is done.
    fn run(&self, worker: &mut Worker) {
        let settings = self.settings;
        let h = settings.dt / settings.substeps as f32;
        let solve = Sweep {
            h,
            use_bias: true,
            max_push_velocity: settings.max_push_velocity,
            moved: false,
        };
        let relax = Sweep {
            use_bias: false,
            moved: true,
            ..solve
        };
        let access = self.bodies;
        for substep in 0..settings.substeps {
            self.for_each_body(worker, |body| integrate_velocity(body, settings.gravity, h));
            self.sweep(
                worker,
                |c| contact::warm_start(access, c),
                |j| joint::warm_start(access, j, h),
            );
            for iteration in 0..settings.iterations {
                // The constraints were built at the step-start positions; from then on the last
                // relax sweep has the current separations.
                let solve = Sweep {
                    moved: substep == 0 && iteration == 0,
                    ..solve
                };
                self.sweep(
                    worker,
                    |c| contact::solve_contact(access, c, solve),
                    |j| joint::solve_joint(access, j, solve),
                );
            }
            self.for_each_body(worker, |body| integrate_position(body, h));
            self.sweep(
                worker,
                |c| contact::solve_contact(access, c, relax),
                |j| joint::solve_joint(access, j, relax),
            );
        }
        if self.restitution {
            let threshold = settings.restitution_threshold;
            self.sweep(
                worker,
                |c| contact::apply_restitution(access, c, threshold),
                |_| {},
            );
        }
    }

    /// The blocks of batch `batch` when it is a stage of its own, its contacts' and its
    /// joints': a batch large enough to fill two blocks, but for the overflow batch.
    fn batch_blocks(&self, batch: usize) -> Option<(usize, usize)> {
        let batch_count = self.contact_offsets.len().saturating_sub(1);
        let contacts = range(self.contact_offsets, batch);
        let joints = range(self.joint_offsets, batch);
        let overflow = self.has_overflow && batch + 1 == batch_count;
        if overflow || contacts.len() + joints.len() < 2 * CONTACTS_PER_BLOCK {
            return None;
        }
        let contact_blocks = contacts.len().div_ceil(CONTACTS_PER_BLOCK);
        Some((contact_blocks, joints.len().div_ceil(JOINTS_PER_BLOCK)))
    }

    /// The most blocks one stage of the step has: the work of that many workers at most.
    fn widest_stage(&self) -> usize {
        let batch_count = self.contact_offsets.len().saturating_sub(1);
        let batches = (0..batch_count).filter_map(|batch| self.batch_blocks(batch));
        let widest_batch = batches.map(|(contacts, joints)| contacts + joints).max();
        let body_blocks = self.bodies.1.div_ceil(BODIES_PER_BLOCK);
        widest_batch.unwrap_or(1).max(body_blocks).max(1)
    }

    /// One stage over the bodies, in blocks of [`BODIES_PER_BLOCK`].
    fn for_each_body(&self, worker: &mut Worker, f: impl Fn(&mut SolverBody)) {
        let count = self.bodies.1;
        worker.stage(count.div_ceil(BODIES_PER_BLOCK), |block| {
            let start = block * BODIES_PER_BLOCK;
            let end = (start + BODIES_PER_BLOCK).min(count);
            // SAFETY: the blocks of a stage are disjoint and no constraint runs in this stage.
            unsafe { self.bodies.slice(start..end) }
                .iter_mut()
                .for_each(&f);
        });
    }

    /// Runs `on_contact` and `on_joint` on every constraint, batch after batch. A batch large
    /// enough to fill two blocks is one stage whose blocks run in parallel; runs of smaller
    /// batches (the tail of the coloring) and the overflow batch are one stage of one block,
    /// solved in order. Contacts and joints of one batch share no dynamic body, so their order
    /// inside a batch does not change the result: any thread count gives the same bits.
    fn sweep(
        &self,
        worker: &mut Worker,
        on_contact: impl Fn(&mut ContactConstraint),
        on_joint: impl Fn(&mut JointConstraint),
    ) {
        let batch_count = self.contact_offsets.len().saturating_sub(1);
        let contacts_of = |batch| range(self.contact_offsets, batch);
        let joints_of = |batch| range(self.joint_offsets, batch);
        // SAFETY (both closures): a block's constraints are touched by no other block of its
        // stage, and stages are ordered by `Worker::stage`.
        let in_order = |batches: std::ops::Range<usize>| {
            for batch in batches {
                unsafe { self.contacts.slice(contacts_of(batch)) }
                    .iter_mut()
                    .for_each(&on_contact);
                unsafe { self.joints.slice(joints_of(batch)) }
                    .iter_mut()
                    .for_each(&on_joint);
            }
        };
        let mut small_from = 0;
        for batch in 0..batch_count {
            let Some((contact_blocks, joint_blocks)) = self.batch_blocks(batch) else {
                continue;
            };
            let (contacts, joints) = (contacts_of(batch), joints_of(batch));
            if small_from < batch {
                worker.stage(1, |_| in_order(small_from..batch));
            }
            small_from = batch + 1;
            worker.stage(contact_blocks + joint_blocks, |block| {
                if block < contact_blocks {
                    let start = contacts.start + block * CONTACTS_PER_BLOCK;
                    let end = (start + CONTACTS_PER_BLOCK).min(contacts.end);
                    unsafe { self.contacts.slice(start..end) }
                        .iter_mut()
                        .for_each(&on_contact);
                } else {
                    let start = joints.start + (block - contact_blocks) * JOINTS_PER_BLOCK;
                    let end = (start + JOINTS_PER_BLOCK).min(joints.end);
                    unsafe { self.joints.slice(start..end) }
                        .iter_mut()
                        .for_each(&on_joint);
                }
            });
        }
        if small_from < batch_count {
            worker.stage(1, |_| in_order(small_from..batch_count));
        }
    }
}

/// Gravity into the velocity of a dynamic body.
#[inline]
fn integrate_velocity(body: &mut SolverBody, gravity: Vec3, h: f32) {
    if body.inverse_mass > 0.0 {
        body.linear_velocity += gravity * h;
    }
}

/// The velocity of a dynamic body into its delta position and rotation.
#[inline]
fn integrate_position(body: &mut SolverBody, h: f32) {
    if body.inverse_mass > 0.0 {
        body.angular_velocity = clamp_rotation(body.angular_velocity, h);
        body.delta_position += body.linear_velocity * h;
        body.delta_rotation = integrate_rotation(body.delta_rotation, body.angular_velocity, h);
    }
}

fn range(offsets: &[u32], batch: usize) -> std::ops::Range<usize> {
    offsets[batch] as usize..offsets[batch + 1] as usize
}

/// Contacts per block, the unit of work a worker claims. TODO measured
const CONTACTS_PER_BLOCK: usize = 64;
/// Joints per block: a joint costs about twice a 4-point contact.
const JOINTS_PER_BLOCK: usize = 32;
const BODIES_PER_BLOCK: usize = 1024;

/// The counters a team of workers shares during one step. The stages of the step are numbered
/// block after block, stage after stage (in the order of [`Step::run`]); a worker claims the
/// next block number, waits until every block of the stages before that block's stage is done,
/// runs it and counts it done. So the blocks of one stage run in parallel, a stage starts only
/// after the previous one ended, and no worker waits for another that has nothing to do (a
/// preempted or late worker just finds the stages it missed claimed); the counters are the
/// only synchronization (Box2D v3's solver stages work the same way).
///
/// Deadlock-free: the lowest unfinished block was claimed by a worker whose wait is over, since
/// all blocks before it are done.
#[derive(Default)]
struct Team {
    next_block: CacheLine<AtomicUsize>,
    done_blocks: CacheLine<AtomicUsize>,
}

/// Keeps its value alone on a cache line, so the two counters do not slow each other down.
#[derive(Default)]
#[repr(align(128))]
struct CacheLine<T>(T);

/// One worker's walk through the stages of a step.
struct Worker<'a> {
    team: Option<&'a Team>,
    /// Number of the first block of the current stage.
    stage_start: usize,
    /// The block this worker claimed and has not run yet (≥ `stage_start`).
    claimed: usize,
}

impl<'a> Worker<'a> {
    /// The only worker: runs every block in order.
    fn alone() -> Self {
        Self {
            team: None,
            stage_start: 0,
            claimed: 0,
        }
    }

    fn in_team(team: &'a Team) -> Self {
        Self {
            team: Some(team),
            stage_start: 0,
            claimed: team.next_block.0.fetch_add(1, Ordering::Relaxed),
        }
    }

    /// The next stage, of `blocks` blocks: runs `run(block)` for the blocks this worker claims,
    /// each after the previous stages have ended.
    fn stage(&mut self, blocks: usize, run: impl Fn(usize)) {
        let Some(team) = self.team else {
            (0..blocks).for_each(run);
            return;
        };
        let end = self.stage_start + blocks;
        while self.claimed < end {
            wait_until(&team.done_blocks.0, self.stage_start);
            run(self.claimed - self.stage_start);
            // Release: the block's writes happen before any block of a later stage starts.
            team.done_blocks.0.fetch_add(1, Ordering::Release);
            self.claimed = team.next_block.0.fetch_add(1, Ordering::Relaxed);
        }
        self.stage_start = end;
    }
}

/// Waits until `counter` ≥ `target`: spins a little (a block takes microseconds), then yields
/// the core, which matters when there are more threads than free cores.
fn wait_until(counter: &AtomicUsize, target: usize) {
    let mut spins = 0;
    // Acquire: pairs with the Release of `Worker::stage`.
    while counter.load(Ordering::Acquire) < target {
        if spins < SPINS_BEFORE_YIELD {
            std::hint::spin_loop();
            spins += 1;
        } else {
            std::thread::yield_now();
        }
    }
}

const SPINS_BEFORE_YIELD: u32 = 1000;

/// A slice shared by the workers of a step, which touch disjoint parts of it in each stage.
#[derive(Clone, Copy)]
struct Shared<T>(*mut T, usize);

// SAFETY: workers only reach disjoint ranges at a time (see `Shared::slice`).
unsafe impl<T: Send> Send for Shared<T> {}
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T> Shared<T> {
    fn new(items: &mut [T]) -> Self {
        Self(items.as_mut_ptr(), items.len())
    }

    /// # Safety
    ///
    /// No other reference into `range` may be alive while the result is.
    #[allow(clippy::mut_from_ref)]
    unsafe fn slice<'s>(self, range: std::ops::Range<usize>) -> &'s mut [T] {
        assert!(range.start <= range.end && range.end <= self.1);
        // SAFETY: in bounds (checked above); exclusive by the caller's promise.
        unsafe { std::slice::from_raw_parts_mut(self.0.add(range.start), range.len()) }
    }
}

/// Shared access to the body array from the constraints of one batch.
#[derive(Clone, Copy)]
pub(super) struct BodyAccess(*mut SolverBody, usize);

// SAFETY: the pointer is only dereferenced for bodies of constraints of the batch being solved,
// and the coloring guarantees that no two constraints of a parallel batch share a dynamic body;
// static bodies are never read through it.
unsafe impl Send for BodyAccess {}
unsafe impl Sync for BodyAccess {}

impl BodyAccess {
    #[inline]
    pub(super) fn load(self, index: u32) -> SolverBody {
        if index == STATIC_BODY {
            return SolverBody::STATIC;
        }
        // In bounds: `solve` checked every constraint's bodies on entry, and the sweeps reach
        // bodies only through their constraints. (An assert here cost X of the solver.)
        debug_assert!((index as usize) < self.1);
        // SAFETY: in bounds (above); no concurrent writer to this body (see the Sync impl).
        unsafe { *self.0.add(index as usize) }
    }

    #[inline]
    pub(super) fn store(self, index: u32, body: &SolverBody) {
        if index != STATIC_BODY {
            debug_assert!((index as usize) < self.1);
            // SAFETY: as in `load`.
            unsafe { *self.0.add(index as usize) = *body }
        }
    }

    /// # Safety
    ///
    /// As [`Shared::slice`]: no constraint may be solved while the result is alive.
    unsafe fn slice<'s>(self, range: std::ops::Range<usize>) -> &'s mut [SolverBody] {
        // SAFETY: forwarded to the caller.
        unsafe { Shared(self.0, self.1).slice(range) }
    }
}

/// Bias, mass scale and impulse scale of a row with position error (or separation) `error`:
/// speculative when apart (may close the gap within the sub-step), soft when overlapping and
/// biased, rigid otherwise.
#[inline]
pub(super) fn bias_terms(
    error: f32,
    softness: crate::pipeline::config::Softness,
    sweep: Sweep,
) -> (f32, f32, f32) {
    if error > 0.0 {
        (error / sweep.h, 1.0, 0.0)
    } else if sweep.use_bias {
        (
            (softness.bias_rate * error).max(-sweep.max_push_velocity),
            softness.mass_scale,
            softness.impulse_scale,
        )
    } else {
        (0.0, 1.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step over `bodies` and `contacts` batched by `offsets` (the joints' offsets set by
    /// the caller).
    fn step_over<'a>(
        bodies: &'a mut [SolverBody],
        contacts: &'a mut [ContactConstraint],
        offsets: &'a [u32],
    ) -> Step<'a> {
        Step {
            bodies: BodyAccess(bodies.as_mut_ptr(), bodies.len()),
            contacts: Shared::new(contacts),
            contact_offsets: offsets,
            joints: Shared::new(&mut []),
            joint_offsets: &[],
            has_overflow: false,
            restitution: false,
            settings: SolverSettings {
                dt: 1.0 / 60.0,
                substeps: 1,
                iterations: 1,
                gravity: Vec3::ZERO,
                max_push_velocity: 3.0,
                restitution_threshold: 1.0,
                contact_softness: Softness::RIGID,
                static_softness: Softness::RIGID,
            },
        }
    }

    /// The team is as wide as the widest stage: one worker for a small world, the largest
    /// batch's blocks (or the bodies') for a larger one.
    #[test]
    fn the_widest_stage_counts_the_blocks_a_worker_can_take() {
        let mut bodies = vec![SolverBody::STATIC; 3000];
        let mut contacts = vec![ContactConstraint::default(); 1000];
        // Batches of 100 (walked in order), 700 (11 blocks of 64) and 200 (4 blocks).
        let offsets = [0, 100, 800, 1000];
        let joint_offsets = [0, 0, 0, 0];
        let step = Step {
            joint_offsets: &joint_offsets,
            ..step_over(&mut bodies, &mut contacts, &offsets)
        };
        assert_eq!(step.batch_blocks(0), None);
        assert_eq!(step.batch_blocks(1), Some((11, 0)));
        assert_eq!(step.widest_stage(), 11);
        let small = [0, 100, 150];
        let step = Step {
            joint_offsets: &joint_offsets[..3],
            ..step_over(&mut bodies[..200], &mut contacts[..150], &small)
        };
        assert_eq!(step.widest_stage(), 1);
        // Many bodies and no contact: the body stages (1024 a block) are the widest.
        let step = Step {
            joint_offsets: &joint_offsets[..1],
            ..step_over(&mut bodies, &mut [], &[0])
        };
        assert_eq!(step.widest_stage(), 3);
    }
}
