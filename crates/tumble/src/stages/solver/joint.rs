//! Joint rows in the solver: the point part as one 3×3 block, then the angular rows, each
//! rebuilt from the current rotations (step-start rotation composed with the delta rotation).
//! `solver_joint.wgsl` is the GPU twin, in the same order of operations.

use super::{BodyAccess, SolverBody, Sweep, bias_terms};
use crate::math::{Mat3, Vec3};
use crate::stages::constraints::joint::skew;
use crate::stages::constraints::{JointConstraint, RowKind};

/// The arms and angular rows of a joint at the bodies' current rotations.
fn current(
    j: &JointConstraint,
    a: &SolverBody,
    b: &SolverBody,
    h: f32,
) -> (Vec3, Vec3, [crate::stages::constraints::AngularRow; 5]) {
    let q_a = a.delta_rotation * j.rotation_a;
    let q_b = b.delta_rotation * j.rotation_b;
    let (arm_a, arm_b) = j.arms(q_a, q_b);
    (arm_a, arm_b, j.angular_rows(q_a, q_b, h))
}

/// Applies the point impulse `impulse` (+ to B, − to A).
#[inline]
fn apply_point(
    j: &JointConstraint,
    arm_a: Vec3,
    arm_b: Vec3,
    impulse: Vec3,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    a.linear_velocity -= impulse * j.inverse_mass_a;
    a.angular_velocity -= j.inverse_inertia_a * arm_a.cross(impulse);
    b.linear_velocity += impulse * j.inverse_mass_b;
    b.angular_velocity += j.inverse_inertia_b * arm_b.cross(impulse);
}

/// Applies an angular impulse along `direction` (+ to B, − to A).
#[inline]
fn apply_angular(
    j: &JointConstraint,
    direction: Vec3,
    impulse: f32,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    a.angular_velocity -= j.inverse_inertia_a * direction * impulse;
    b.angular_velocity += j.inverse_inertia_b * direction * impulse;
}

pub(super) fn warm_start(access: BodyAccess, j: &mut JointConstraint, h: f32) {
    let (mut a, mut b) = (access.load(j.body_a), access.load(j.body_b));
    warm_start_pair(j, h, &mut a, &mut b);
    access.store(j.body_a, &a);
    access.store(j.body_b, &b);
}

/// [`warm_start`] on the bodies `a` and `b` of `j`, wherever they come from (the Jacobi sweep
/// passes copies).
pub(super) fn warm_start_pair(j: &JointConstraint, h: f32, a: &mut SolverBody, b: &mut SolverBody) {
    let (arm_a, arm_b, rows) = current(j, a, b, h);
    apply_point(j, arm_a, arm_b, j.point_impulse, a, b);
    for (row, &impulse) in rows.iter().zip(&j.angular_impulse) {
        if row.kind != RowKind::Unused {
            apply_angular(j, row.direction, impulse, a, b);
        }
    }
}

pub(super) fn solve_joint(access: BodyAccess, j: &mut JointConstraint, sweep: Sweep) {
    let (mut a, mut b) = (access.load(j.body_a), access.load(j.body_b));
    solve_joint_pair(j, sweep, &mut a, &mut b);
    access.store(j.body_a, &a);
    access.store(j.body_b, &b);
}

/// [`solve_joint`] on the bodies `a` and `b` of `j`.
pub(super) fn solve_joint_pair(
    j: &mut JointConstraint,
    sweep: Sweep,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    let (arm_a, arm_b, rows) = current(j, a, b, sweep.h);

    // Point part: the anchors move together; the gap between them is removed softly.
    let gap = (b.delta_position - a.delta_position) + (arm_b - arm_a) + j.center_offset;
    let (skew_a, skew_b) = (skew(arm_a), skew(arm_b));
    let k = Mat3::from_diagonal(Vec3::splat(j.inverse_mass_a + j.inverse_mass_b))
        - skew_a * j.inverse_inertia_a * skew_a
        - skew_b * j.inverse_inertia_b * skew_b;
    let velocity = b.linear_velocity + b.angular_velocity.cross(arm_b)
        - a.linear_velocity
        - a.angular_velocity.cross(arm_a);
    // A drag stays soft in the relax sweeps too, as Box2D's mouse joint does: a rigid relax
    // row would stop the dragged point at the end of every sub-step, so the body could only
    // creep after its target (a 10-weight drag lagged 0.5 m after 2 s).
    let soft = sweep.use_bias || j.max_point_impulse.is_finite();
    let (bias, mass_scale, impulse_scale) = if soft {
        (
            gap * j.softness.bias_rate,
            j.softness.mass_scale,
            j.softness.impulse_scale,
        )
    } else {
        (Vec3::ZERO, 1.0, 0.0)
    };
    if k.determinant().abs() > f32::MIN_POSITIVE {
        let mut impulse =
            -(k.inverse() * (velocity + bias)) * mass_scale - j.point_impulse * impulse_scale;
        if j.max_point_impulse.is_finite() {
            // A drag pulls with a bounded force: clamp the accumulated impulse (Box2D's mouse
            // joint does the same).
            let total = (j.point_impulse + impulse).clamp_length_max(j.max_point_impulse);
            impulse = total - j.point_impulse;
        }
        j.point_impulse += impulse;
        apply_point(j, arm_a, arm_b, impulse, a, b);
    }

    for (slot, row) in rows.iter().enumerate() {
        let accumulated = &mut j.angular_impulse[slot];
        let d = row.direction;
        let k = d.dot(j.inverse_inertia_a * d) + d.dot(j.inverse_inertia_b * d);
        if row.kind == RowKind::Unused || k <= 0.0 {
            continue;
        }
        let mass = 1.0 / k;
        let velocity = d.dot(b.angular_velocity - a.angular_velocity);
        let total = match row.kind {
            RowKind::Unused => continue,
            RowKind::Equality => {
                let (bias, mass_scale, impulse_scale) = if sweep.use_bias {
                    (
                        j.softness.bias_rate * row.error,
                        j.softness.mass_scale,
                        j.softness.impulse_scale,
                    )
                } else {
                    (0.0, 1.0, 0.0)
                };
                *accumulated - mass * mass_scale * (velocity + bias) - impulse_scale * *accumulated
            }
            RowKind::Limit => {
                let (bias, mass_scale, impulse_scale) = bias_terms(row.error, j.softness, sweep);
                (*accumulated
                    - mass * mass_scale * (velocity + bias)
                    - impulse_scale * *accumulated)
                    .max(0.0)
            }
            RowKind::Motor {
                target_speed,
                max_impulse,
            } => (*accumulated - mass * (velocity - target_speed)).clamp(-max_impulse, max_impulse),
        };
        let delta = total - *accumulated;
        *accumulated = total;
        apply_angular(j, d, delta, a, b);
    }
}
