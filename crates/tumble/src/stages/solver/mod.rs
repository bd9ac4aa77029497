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

use crate::math::Vec3;
use crate::stages::constraints::{ContactConstraint, Row, STATIC_BODY};
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

/// CPU executor. `constraints` are in batch order: batch `i` is
/// `constraints[offsets[i]..offsets[i + 1]]`; the last batch is the sequential overflow batch
/// when `has_overflow`.
pub fn solve(
    bodies: &mut [SolverBody],
    constraints: &mut [ContactConstraint],
    offsets: &[u32],
    has_overflow: bool,
    settings: SolverSettings,
) {
    let access = BodyAccess(bodies.as_mut_ptr(), bodies.len());
    let any_restitution = constraints.iter().any(|c| c.restitution > 0.0);
    for_each_batch(constraints, offsets, has_overflow, |c| {
        warm_start(access, c)
    });
    for _ in 0..settings.iterations {
        for_each_batch(constraints, offsets, has_overflow, |c| {
            solve_contact(access, c)
        });
    }
    if any_restitution {
        for_each_batch(constraints, offsets, has_overflow, |c| {
            apply_restitution(access, c, settings.restitution_threshold)
        });
    }
}

/// Runs `f` on every constraint, batch after batch; a batch in parallel unless it is the
/// overflow batch or too small to be worth splitting.
fn for_each_batch(
    constraints: &mut [ContactConstraint],
    offsets: &[u32],
    has_overflow: bool,
    f: impl Fn(&mut ContactConstraint) + Sync,
) {
    let batch_count = offsets.len().saturating_sub(1);
    for batch in 0..batch_count {
        let range = offsets[batch] as usize..offsets[batch + 1] as usize;
        let slice = &mut constraints[range];
        let sequential = (has_overflow && batch + 1 == batch_count)
            || slice.len() < 2 * MIN_CONSTRAINTS_PER_TASK;
        if sequential {
            slice.iter_mut().for_each(&f);
        } else {
            slice
                .par_iter_mut()
                .with_min_len(MIN_CONSTRAINTS_PER_TASK)
                .for_each(&f);
        }
    }
}

/// Shared access to the body array from the constraints of one batch.
#[derive(Clone, Copy)]
struct BodyAccess(*mut SolverBody, usize);

// SAFETY: the pointer is only dereferenced for bodies of constraints of the batch being solved,
// and the coloring guarantees that no two constraints of a parallel batch share a dynamic body;
// static bodies are never read through it.
unsafe impl Send for BodyAccess {}
unsafe impl Sync for BodyAccess {}

impl BodyAccess {
    #[inline]
    fn load(self, index: u32) -> SolverBody {
        if index == STATIC_BODY {
            return SolverBody::default();
        }
        assert!((index as usize) < self.1);
        // SAFETY: in bounds (checked above); no concurrent writer to this body (see the Sync impl).
        unsafe { *self.0.add(index as usize) }
    }

    #[inline]
    fn store(self, index: u32, body: &SolverBody) {
        if index != STATIC_BODY {
            assert!((index as usize) < self.1);
            // SAFETY: as in `load`.
            unsafe { *self.0.add(index as usize) = *body }
        }
    }
}

/// Normal velocity of the contact: how fast A moves away from B along the row (m/s).
#[inline]
fn row_velocity(row: &Row, direction: Vec3, a: &SolverBody, b: &SolverBody) -> f32 {
    direction.dot(a.linear_velocity - b.linear_velocity) + row.arm_a.dot(a.angular_velocity)
        - row.arm_b.dot(b.angular_velocity)
}

/// Inverse masses of a constraint's two bodies (1/kg).
#[derive(Clone, Copy)]
struct InverseMasses {
    a: f32,
    b: f32,
}

/// Applies `impulse` along a row: +impulse to A, −impulse to B.
#[inline]
fn apply(
    row: &Row,
    direction: Vec3,
    impulse: f32,
    masses: InverseMasses,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    a.linear_velocity += direction * (impulse * masses.a);
    a.angular_velocity += row.angular_a * impulse;
    b.linear_velocity -= direction * (impulse * masses.b);
    b.angular_velocity -= row.angular_b * impulse;
}

fn warm_start(access: BodyAccess, c: &mut ContactConstraint) {
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    let masses = InverseMasses {
        a: c.inverse_mass_a,
        b: c.inverse_mass_b,
    };
    for point in &mut c.points[..c.point_count as usize] {
        apply(
            &point.normal,
            c.normal,
            point.normal.impulse,
            masses,
            &mut a,
            &mut b,
        );
        for (row, direction) in point.tangent.iter().zip(c.tangents) {
            apply(row, direction, row.impulse, masses, &mut a, &mut b);
        }
        point.max_normal_impulse = point.normal.impulse;
    }
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}

fn solve_contact(access: BodyAccess, c: &mut ContactConstraint) {
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    let n = c.normal;
    let masses = InverseMasses {
        a: c.inverse_mass_a,
        b: c.inverse_mass_b,
    };
    let count = c.point_count as usize;
    for point in &mut c.points[..count] {
        let row = &point.normal;
        // Split impulse on the pseudo-velocities: same Jacobian, its own accumulator.
        if point.push_target > 0.0 || point.push_impulse > 0.0 {
            let push_velocity = n.dot(a.push_linear - b.push_linear)
                + row.arm_a.dot(a.push_angular)
                - row.arm_b.dot(b.push_angular);
            let total =
                (point.push_impulse - (push_velocity - point.push_target) * row.mass).max(0.0);
            let delta = total - point.push_impulse;
            point.push_impulse = total;
            a.push_linear += n * (delta * masses.a);
            a.push_angular += row.angular_a * delta;
            b.push_linear -= n * (delta * masses.b);
            b.push_angular -= row.angular_b * delta;
        }
        // Non-penetration: normal velocity ≥ target, impulse ≥ 0.
        let velocity = row_velocity(row, n, &a, &b);
        let total = (row.impulse - (velocity - point.velocity_target) * row.mass).max(0.0);
        let delta = total - row.impulse;
        point.normal.impulse = total;
        point.max_normal_impulse = point.max_normal_impulse.max(total);
        apply(&point.normal, n, delta, masses, &mut a, &mut b);
    }
    // Friction: both tangent rows from the same velocities, then the impulse clamped to the
    // friction circle |λ_t| ≤ μ λ_n (clamping each row alone would allow √2 μ λ_n diagonally).
    let friction = c.friction;
    let [t1, t2] = c.tangents;
    for point in &mut c.points[..count] {
        let [row1, row2] = &mut point.tangent;
        let want1 = row1.impulse - row_velocity(row1, t1, &a, &b) * row1.mass;
        let want2 = row2.impulse - row_velocity(row2, t2, &a, &b) * row2.mass;
        let limit = friction * point.normal.impulse;
        let length_squared = want1 * want1 + want2 * want2;
        let scale = if length_squared > limit * limit {
            limit / length_squared.sqrt()
        } else {
            1.0
        };
        let (total1, total2) = (want1 * scale, want2 * scale);
        apply(row1, t1, total1 - row1.impulse, masses, &mut a, &mut b);
        apply(row2, t2, total2 - row2.impulse, masses, &mut a, &mut b);
        row1.impulse = total1;
        row2.impulse = total2;
    }
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}

fn apply_restitution(access: BodyAccess, c: &mut ContactConstraint, threshold: f32) {
    if c.restitution == 0.0 {
        return;
    }
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    let n = c.normal;
    let masses = InverseMasses {
        a: c.inverse_mass_a,
        b: c.inverse_mass_b,
    };
    let restitution = c.restitution;
    for point in &mut c.points[..c.point_count as usize] {
        if point.approach_velocity > -threshold || point.max_normal_impulse == 0.0 {
            continue;
        }
        let row = &point.normal;
        let velocity = row_velocity(row, n, &a, &b);
        let total =
            (row.impulse - (velocity + restitution * point.approach_velocity) * row.mass).max(0.0);
        let delta = total - row.impulse;
        point.normal.impulse = total;
        point.max_normal_impulse = point.max_normal_impulse.max(total);
        apply(&point.normal, n, delta, masses, &mut a, &mut b);
    }
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}
