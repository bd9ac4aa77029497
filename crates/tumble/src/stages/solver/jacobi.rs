//! The soft step with projected **Jacobi** sweeps: the comparison DESIGN.md's stage 7 asks
//! for, beside the batched Gauss-Seidel of [`solve`](super::solve).
//!
//! The schedule is the soft step's (integrate velocities, warm start, `iterations` biased
//! sweeps, integrate positions, relax; restitution at the end); only the sweeps differ. A
//! Jacobi sweep has two phases:
//!
//! 1. every constraint (contacts `0..C`, then joints `C..C + J`) reads its two bodies as they
//!    were at the start of the sweep, solves its rows on private copies with the same rows,
//!    clamps, friction circle and softness as PGS (a manifold's points and a joint's rows one
//!    after the other, Gauss-Seidel inside the constraint), and writes each body's velocity
//!    change, scaled by the relaxation factor ω below, into its own [`VelocityDelta`] slot;
//! 2. every body adds the changes of its constraints, summed in constraint order through the
//!    [`Adjacency`] lists: the order is fixed, so the result is the same bits for any thread
//!    count (no float atomics).
//!
//! The coloring is not needed: phase 1 writes no body, phase 2 writes each body once.
//!
//! **Relaxation.** Constraints sharing a body all push it from the same start, so their full
//! changes added together overshoot (two contacts holding a box each remove the box's whole
//! velocity error: twice too much). A constraint's changes and its accumulated impulses
//! advance by ω = 1 / max(n_a, n_b) of what it solved, with n the number of constraints on a
//! dynamic body (static bodies count 0). Why this choice:
//! - scaling a constraint's impulse (not averaging each body's changes) applies equal and
//!   opposite impulses to both bodies, so momentum is conserved, and the accumulated impulses
//!   stay those actually applied, which warm starting and the impulse clamps rely on;
//! - with A = J M⁻¹ Jᵀ and D its constraint-diagonal blocks, A ≤ diag(max(n_a, n_b) D_c)
//!   (a body's block of A is a sum of n rank-limited terms, Cauchy-Schwarz), which is the
//!   condition under which relaxed Jacobi converges with ω = 1/max(n_a, n_b) (unclamped
//!   case); a fixed ω would have to be 1/(largest n in the scene), slow for all bodies;
//! - the relaxed impulse old + ω(new − old) lies between two feasible impulses, so it stays
//!   feasible (normal ≥ 0, friction inside the circle when both are, a drag's bound);
//! - a body with one constraint (a box alone on the ground, a two-body collision) gets ω = 1:
//!   exactly what PGS does there.
//!
//! The warm start applies the accumulated impulses whole (ω = 1): it is no iteration, just
//! J^T λ. The restitution sweep is relaxed like the others.
//!
//! `jacobi.wgsl` (driven by [`jacobi_gpu`](super::jacobi_gpu)) is the GPU twin, in the same
//! order of operations.

use rayon::prelude::*;

use super::{Batched, SolverBody, SolverSettings, Sweep, contact, joint};
use crate::math::Vec3;
use crate::stages::constraints::{ContactConstraint, JointConstraint, STATIC_BODY};

/// A constraint's change of one body's velocities in one sweep, relaxed. 32 bytes, WGSL
/// twin in `jacobi.wgsl`. Slot `2 c` is constraint c's body A, `2 c + 1` its body B.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VelocityDelta {
    pub linear: Vec3,
    pub _pad0: f32,
    pub angular: Vec3,
    pub _pad1: f32,
}
const _: () = assert!(size_of::<VelocityDelta>() == 32);

/// For each body, the [`VelocityDelta`] slots of the constraints on it, in constraint order:
/// body b's are `entries[offsets[b]..offsets[b + 1]]`. Static bodies and bodies of zero
/// inverse mass have none (nothing moves them).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Adjacency {
    pub offsets: Vec<u32>,
    pub entries: Vec<u32>,
}

impl Adjacency {
    /// The lists for `constraints` (body A, body B of each, contacts then joints) over
    /// `bodies`: a counting sort, so each list comes in constraint order.
    ///
    /// # Panics
    ///
    /// If a constraint names a body past `bodies` (other than [`STATIC_BODY`]).
    pub fn build(
        &mut self,
        bodies: &[SolverBody],
        constraints: impl Iterator<Item = (u32, u32)> + Clone,
    ) {
        let moves = |body: u32| {
            body != STATIC_BODY && {
                let body = bodies
                    .get(body as usize)
                    .expect("a constraint names a body that is not in the solver's body array");
                body.inverse_mass > 0.0
            }
        };
        self.offsets.clear();
        self.offsets.resize(bodies.len() + 1, 0);
        for (a, b) in constraints.clone() {
            for body in [a, b] {
                if moves(body) {
                    self.offsets[body as usize + 1] += 1;
                }
            }
        }
        for i in 1..self.offsets.len() {
            self.offsets[i] += self.offsets[i - 1];
        }
        self.entries.clear();
        self.entries
            .resize(*self.offsets.last().unwrap_or(&0) as usize, 0);
        // offsets[b] is body b's cursor while filling, which leaves it at b's end, that is
        // at b + 1's start: shifting by one gives the offsets back.
        for (constraint, (a, b)) in constraints.enumerate() {
            for (side, body) in [a, b].into_iter().enumerate() {
                if moves(body) {
                    let at = &mut self.offsets[body as usize];
                    self.entries[*at as usize] = (2 * constraint + side) as u32;
                    *at += 1;
                }
            }
        }
        self.offsets.copy_within(..bodies.len(), 1);
        self.offsets[0] = 0;
    }

    /// Constraints on `body` (0 for a static body).
    #[inline]
    pub fn count(&self, body: u32) -> u32 {
        if body == STATIC_BODY {
            return 0;
        }
        self.offsets[body as usize + 1] - self.offsets[body as usize]
    }

    /// The relaxation factor ω of a constraint between `a` and `b` (see the module docs).
    #[inline]
    pub fn relaxation(&self, a: u32, b: u32) -> f32 {
        1.0 / self.count(a).max(self.count(b)).max(1) as f32
    }
}

/// The Jacobi solver's working arrays, kept from step to step.
#[derive(Default)]
pub struct JacobiScratch {
    adjacency: Adjacency,
    deltas: Vec<VelocityDelta>,
}

/// What a sweep does to each constraint.
#[derive(Clone, Copy)]
enum Pass {
    WarmStart { h: f32 },
    Solve(Sweep),
    Restitution { threshold: f32 },
}

/// Contacts per rayon task (joints: half as many), and bodies: the PGS sweep's block sizes
/// (`CONTACTS_PER_BLOCK`, `BODIES_PER_BLOCK`), not measured for Jacobi.
const CONSTRAINTS_PER_TASK: usize = 64;
const BODIES_PER_TASK: usize = 1024;

/// CPU executor: the soft step with Jacobi sweeps, [`solve`](super::solve)'s contract (bodies
/// in with the step-start velocities and zero deltas, out with the final velocities and the
/// step's deltas; accumulated impulses in the constraints). The batches are ignored: the
/// constraints are swept as one array in their order there (the step puts them all in one
/// batch, in row order, and skips the coloring).
///
/// # Panics
///
/// If a constraint names a body past `bodies` (other than [`STATIC_BODY`]).
pub fn solve(
    bodies: &mut [SolverBody],
    batched: &mut Batched,
    settings: SolverSettings,
    scratch: &mut JacobiScratch,
) {
    let contact_bodies = batched.contacts.iter().map(|c| (c.body_a, c.body_b));
    let joint_bodies = batched.joints.iter().map(|j| (j.body_a, j.body_b));
    scratch
        .adjacency
        .build(bodies, contact_bodies.chain(joint_bodies));
    let slots = 2 * (batched.contacts.len() + batched.joints.len());
    scratch.deltas.clear();
    scratch.deltas.resize(slots, VelocityDelta::default());

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
    let restitution = batched.contacts.iter().any(|c| c.restitution > 0.0);
    let mut sweep = |bodies: &mut [SolverBody], pass| {
        jacobi_sweep(
            bodies,
            batched,
            &scratch.adjacency,
            &mut scratch.deltas,
            pass,
        );
    };
    for substep in 0..settings.substeps {
        for_each_body(bodies, |body| {
            super::integrate_velocity(body, settings.gravity, h)
        });
        sweep(bodies, Pass::WarmStart { h });
        for iteration in 0..settings.iterations {
            // As in PGS: only the first solve of the step sees positions no sweep has seen.
            let moved = substep == 0 && iteration == 0;
            sweep(bodies, Pass::Solve(Sweep { moved, ..solve }));
        }
        for_each_body(bodies, |body| super::integrate_position(body, h));
        sweep(bodies, Pass::Solve(relax));
    }
    if restitution {
        let threshold = settings.restitution_threshold;
        sweep(bodies, Pass::Restitution { threshold });
    }
}

fn for_each_body(bodies: &mut [SolverBody], f: impl Fn(&mut SolverBody) + Sync + Send) {
    bodies
        .par_iter_mut()
        .with_min_len(BODIES_PER_TASK)
        .for_each(f);
}

/// One Jacobi sweep: phase 1 over the constraints, phase 2 over the bodies.
fn jacobi_sweep(
    bodies: &mut [SolverBody],
    batched: &mut Batched,
    adjacency: &Adjacency,
    deltas: &mut [VelocityDelta],
    pass: Pass,
) {
    let (contact_deltas, joint_deltas) = deltas.split_at_mut(2 * batched.contacts.len());
    {
        let bodies: &[SolverBody] = bodies;
        batched
            .contacts
            .par_iter_mut()
            .zip(contact_deltas.par_chunks_exact_mut(2))
            .with_min_len(CONSTRAINTS_PER_TASK)
            .for_each(|(c, out)| contact_deltas_of(bodies, adjacency, c, pass, out));
        if !matches!(pass, Pass::Restitution { .. }) {
            batched
                .joints
                .par_iter_mut()
                .zip(joint_deltas.par_chunks_exact_mut(2))
                .with_min_len(CONSTRAINTS_PER_TASK / 2)
                .for_each(|(j, out)| joint_deltas_of(bodies, adjacency, j, pass, out));
        } else {
            // Joints do not bounce: their slots add nothing.
            joint_deltas.fill(VelocityDelta::default());
        }
    }
    let deltas: &[VelocityDelta] = deltas;
    bodies
        .par_iter_mut()
        .enumerate()
        .with_min_len(BODIES_PER_TASK)
        .for_each(|(index, body)| apply_deltas(adjacency, deltas, index, body));
}

/// Phase 2 for one body: its constraints' changes summed in constraint order, then added.
#[inline]
fn apply_deltas(
    adjacency: &Adjacency,
    deltas: &[VelocityDelta],
    index: usize,
    body: &mut SolverBody,
) {
    let entries = &adjacency.entries
        [adjacency.offsets[index] as usize..adjacency.offsets[index + 1] as usize];
    if entries.is_empty() {
        return;
    }
    let (mut linear, mut angular) = (Vec3::ZERO, Vec3::ZERO);
    for &slot in entries {
        let delta = &deltas[slot as usize];
        linear += delta.linear;
        angular += delta.angular;
    }
    body.linear_velocity += linear;
    body.angular_velocity += angular;
}

#[inline]
fn load(bodies: &[SolverBody], index: u32) -> SolverBody {
    if index == STATIC_BODY {
        SolverBody::STATIC
    } else {
        bodies[index as usize]
    }
}

/// The change from `start` to `end`, times `omega`.
#[inline]
fn delta(start: &SolverBody, end: &SolverBody, omega: f32) -> VelocityDelta {
    VelocityDelta {
        linear: (end.linear_velocity - start.linear_velocity) * omega,
        _pad0: 0.0,
        angular: (end.angular_velocity - start.angular_velocity) * omega,
        _pad1: 0.0,
    }
}

/// `old + ω (new − old)`: the relaxed accumulated impulse.
#[inline]
fn relax(old: f32, new: f32, omega: f32) -> f32 {
    old + omega * (new - old)
}

/// Phase 1 for one contact.
fn contact_deltas_of(
    bodies: &[SolverBody],
    adjacency: &Adjacency,
    c: &mut ContactConstraint,
    pass: Pass,
    out: &mut [VelocityDelta],
) {
    let start = [load(bodies, c.body_a), load(bodies, c.body_b)];
    let [mut a, mut b] = start;
    let omega = match pass {
        Pass::WarmStart { .. } => {
            contact::warm_start_pair(c, &mut a, &mut b);
            1.0
        }
        Pass::Solve(_) | Pass::Restitution { .. } => {
            let omega = adjacency.relaxation(c.body_a, c.body_b);
            let old = c.points.map(|p| {
                [
                    p.normal.impulse,
                    p.tangent[0].impulse,
                    p.tangent[1].impulse,
                    p.max_normal_impulse,
                ]
            });
            match pass {
                Pass::Solve(sweep) => contact::solve_contact_pair(c, sweep, &mut a, &mut b),
                Pass::Restitution { threshold } => {
                    contact::restitution_pair(c, threshold, &mut a, &mut b)
                }
                Pass::WarmStart { .. } => unreachable!("handled above"),
            }
            if omega != 1.0 {
                let count = c.point_count as usize;
                for (point, [normal, tangent1, tangent2, max]) in
                    c.points[..count].iter_mut().zip(old)
                {
                    point.normal.impulse = relax(normal, point.normal.impulse, omega);
                    point.tangent[0].impulse = relax(tangent1, point.tangent[0].impulse, omega);
                    point.tangent[1].impulse = relax(tangent2, point.tangent[1].impulse, omega);
                    point.max_normal_impulse = max.max(point.normal.impulse);
                }
            }
            omega
        }
    };
    out[0] = delta(&start[0], &a, omega);
    out[1] = delta(&start[1], &b, omega);
}

/// Phase 1 for one joint.
fn joint_deltas_of(
    bodies: &[SolverBody],
    adjacency: &Adjacency,
    j: &mut JointConstraint,
    pass: Pass,
    out: &mut [VelocityDelta],
) {
    let start = [load(bodies, j.body_a), load(bodies, j.body_b)];
    let [mut a, mut b] = start;
    let omega = match pass {
        Pass::WarmStart { h } => {
            joint::warm_start_pair(j, h, &mut a, &mut b);
            1.0
        }
        Pass::Solve(sweep) => {
            let omega = adjacency.relaxation(j.body_a, j.body_b);
            let (old_point, old_angular) = (j.point_impulse, j.angular_impulse);
            joint::solve_joint_pair(j, sweep, &mut a, &mut b);
            if omega != 1.0 {
                j.point_impulse = old_point + (j.point_impulse - old_point) * omega;
                for (impulse, old) in j.angular_impulse.iter_mut().zip(old_angular) {
                    *impulse = relax(old, *impulse, omega);
                }
            }
            omega
        }
        Pass::Restitution { .. } => unreachable!("joints do not bounce"),
    };
    out[0] = delta(&start[0], &a, omega);
    out[1] = delta(&start[1], &b, omega);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dynamic() -> SolverBody {
        SolverBody {
            inverse_mass: 1.0,
            ..SolverBody::STATIC
        }
    }

    #[test]
    fn adjacency_lists_each_body_s_constraints_in_order() {
        let bodies = [dynamic(), dynamic(), SolverBody::STATIC, dynamic()];
        let mut adjacency = Adjacency::default();
        let constraints = [(0, STATIC_BODY), (1, 0), (3, 2), (0, 3)];
        adjacency.build(&bodies, constraints.into_iter());
        assert_eq!(adjacency.offsets, [0, 3, 4, 4, 6]);
        // Body 0: A of 0, B of 1, A of 3; body 1: A of 1; body 2 (zero mass): none.
        assert_eq!(adjacency.entries, [0, 3, 6, 2, 4, 7]);
        assert_eq!(adjacency.relaxation(0, STATIC_BODY), 1.0 / 3.0);
        assert_eq!(adjacency.relaxation(1, 2), 1.0);
        assert_eq!(adjacency.relaxation(3, 1), 0.5);
    }

    #[test]
    fn no_constraints_no_lists() {
        let mut adjacency = Adjacency::default();
        adjacency.build(&[], std::iter::empty());
        assert_eq!(adjacency.offsets, [0]);
        assert!(adjacency.entries.is_empty());
    }
}
