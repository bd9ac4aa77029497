//! Stage 7: projected Gauss-Seidel over the colored batches.
//!
//! Per sub-step: warm start (apply last step's impulses), `iterations` sweeps over the batches
//! in order — each constraint solving its normal rows, then its friction rows clamped to the
//! friction circle (|λ_t| ≤ μ λ_n) — then one restitution sweep.
//!
//! Position correction is a **split impulse** (Bullet's `splitImpulse`, Catto's pseudo
//! velocities): penetration beyond the slop is removed by separate pseudo-velocities that move
//! the bodies this step and are then thrown away. Chosen over Baumgarte, which feeds the
//! correction into the real velocities and adds energy (bodies pop out of deep overlaps), and
//! over Box2D v3's soft step, whose "relax" iterations remove the bias velocity well only with
//! several sub-steps — the scene default here is one sub-step with 10 iterations. With the split
//! impulse the real velocities never carry correction speed, so resting contacts gain no energy
//! and warm starting is not polluted by it.
//!
//! Restitution follows Box2D v3: after the iterations, a point that pushed this step
//! (`max_normal_impulse > 0`) and approached faster than the threshold gets the normal velocity
//! `−e · approach`; speculative contacts therefore still bounce.
//!
//! Guarantees: a batch's constraints touch disjoint dynamic bodies (stage 6), so solving them
//! in parallel gives bitwise the same result as solving them in order, for any thread count.

mod contact;
mod joint;

use crate::math::Vec3;
use crate::stages::constraints::{ContactConstraint, JointConstraint, STATIC_BODY};
use rayon::prelude::*;

/// Velocities the solver works on, one per body slot. 64 bytes, WGSL-aligned (repr(C), Pod).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SolverBody {
    pub linear_velocity: Vec3,
    pub inverse_mass: f32,
    pub angular_velocity: Vec3,
    pub _pad0: f32,
    /// Split-impulse pseudo-velocities: move the body this step only.
    pub push_linear: Vec3,
    pub _pad1: f32,
    pub push_angular: Vec3,
    pub _pad2: f32,
}
const _: () = assert!(size_of::<SolverBody>() == 64);

/// Constraints per rayon task inside one batch.
const MIN_CONSTRAINTS_PER_TASK: usize = 128;

/// Solver settings for one sub-step.
#[derive(Clone, Copy, Debug)]
pub struct SolverSettings {
    pub iterations: u32,
    /// Approach speed above which restitution applies (m/s).
    pub restitution_threshold: f32,
}

/// The constraints of a sub-step laid out batch after batch: batch `i` is
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

/// CPU executor: warm start, `iterations` sweeps, restitution.
pub fn solve(bodies: &mut [SolverBody], batched: &mut Batched, settings: SolverSettings) {
    let access = BodyAccess(bodies.as_mut_ptr(), bodies.len());
    let any_restitution = batched.contacts.iter().any(|c| c.restitution > 0.0);
    for_each_batch(
        batched,
        |c| contact::warm_start(access, c),
        |j| joint::warm_start(access, j),
    );
    for _ in 0..settings.iterations {
        for_each_batch(
            batched,
            |c| contact::solve_contact(access, c),
            |j| joint::solve_joint(access, j),
        );
    }
    if any_restitution {
        let threshold = settings.restitution_threshold;
        for_each_batch(
            batched,
            |c| contact::apply_restitution(access, c, threshold),
            |_| {},
        );
    }
}

/// Runs `on_contact` and `on_joint` on every constraint, batch after batch; a batch in parallel
/// unless it is the overflow batch or too small to be worth splitting. Contacts and joints of
/// one batch share no dynamic body, so their order inside a batch does not change the result.
fn for_each_batch(
    batched: &mut Batched,
    on_contact: impl Fn(&mut ContactConstraint) + Sync,
    on_joint: impl Fn(&mut JointConstraint) + Sync,
) {
    let batch_count = batched.contact_offsets.len().saturating_sub(1);
    for batch in 0..batch_count {
        let overflow = batched.has_overflow && batch + 1 == batch_count;
        let contacts = &mut batched.contacts[range(batched.contact_offsets, batch)];
        run_batch(contacts, overflow, &on_contact);
        let joints = &mut batched.joints[range(batched.joint_offsets, batch)];
        run_batch(joints, overflow, &on_joint);
    }
}

fn range(offsets: &[u32], batch: usize) -> std::ops::Range<usize> {
    offsets[batch] as usize..offsets[batch + 1] as usize
}

fn run_batch<T: Send>(items: &mut [T], overflow: bool, f: &(impl Fn(&mut T) + Sync)) {
    if overflow || items.len() < 2 * MIN_CONSTRAINTS_PER_TASK {
        items.iter_mut().for_each(f);
    } else {
        items
            .par_iter_mut()
            .with_min_len(MIN_CONSTRAINTS_PER_TASK)
            .for_each(f);
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
            return SolverBody::default();
        }
        assert!((index as usize) < self.1);
        // SAFETY: in bounds (checked above); no concurrent writer to this body (see the Sync impl).
        unsafe { *self.0.add(index as usize) }
    }

    #[inline]
    pub(super) fn store(self, index: u32, body: &SolverBody) {
        if index != STATIC_BODY {
            assert!((index as usize) < self.1);
            // SAFETY: as in `load`.
            unsafe { *self.0.add(index as usize) = *body }
        }
    }
}
