//! Joint rows in the solver: the point part as one 3×3 block, then the angular rows, each on
//! the real velocities and, for position errors, on the split-impulse pseudo-velocities.

use super::{BodyAccess, SolverBody};
use crate::math::Vec3;
use crate::stages::constraints::{AngularRow, JointConstraint};

/// Velocity of B's anchor relative to A's (m/s), from linear and angular velocities.
#[inline]
fn point_velocity(
    j: &JointConstraint,
    linear_a: Vec3,
    angular_a: Vec3,
    linear_b: Vec3,
    angular_b: Vec3,
) -> Vec3 {
    linear_b + angular_b.cross(j.arm_b) - linear_a - angular_a.cross(j.arm_a)
}

/// Applies the point impulse `impulse` (+ to B, − to A) to the real velocities.
#[inline]
fn apply_point(j: &JointConstraint, impulse: Vec3, a: &mut SolverBody, b: &mut SolverBody) {
    a.linear_velocity -= impulse * j.inverse_mass_a;
    a.angular_velocity -= j.inverse_inertia_a * j.arm_a.cross(impulse);
    b.linear_velocity += impulse * j.inverse_mass_b;
    b.angular_velocity += j.inverse_inertia_b * j.arm_b.cross(impulse);
}

#[inline]
fn apply_angular(row: &AngularRow, impulse: f32, a: &mut SolverBody, b: &mut SolverBody) {
    a.angular_velocity -= row.inertia_a * impulse;
    b.angular_velocity += row.inertia_b * impulse;
}

pub(super) fn warm_start(access: BodyAccess, j: &mut JointConstraint) {
    let (mut a, mut b) = (access.load(j.body_a), access.load(j.body_b));
    apply_point(j, j.point_impulse, &mut a, &mut b);
    for row in j.angular.iter().filter(|row| row.mass > 0.0) {
        apply_angular(row, row.impulse, &mut a, &mut b);
    }
    access.store(j.body_a, &a);
    access.store(j.body_b, &b);
}

pub(super) fn solve_joint(access: BodyAccess, j: &mut JointConstraint) {
    let (mut a, mut b) = (access.load(j.body_a), access.load(j.body_b));

    // Point part, pseudo-velocities: drive the anchor gap to zero (equality, not accumulated).
    if j.point_push_target != Vec3::ZERO {
        let velocity = point_velocity(
            j,
            a.push_linear,
            a.push_angular,
            b.push_linear,
            b.push_angular,
        );
        let impulse = j.point_mass * (j.point_push_target - velocity);
        a.push_linear -= impulse * j.inverse_mass_a;
        a.push_angular -= j.inverse_inertia_a * j.arm_a.cross(impulse);
        b.push_linear += impulse * j.inverse_mass_b;
        b.push_angular += j.inverse_inertia_b * j.arm_b.cross(impulse);
    }
    // Point part, real velocities: the anchors move together.
    let velocity = point_velocity(
        j,
        a.linear_velocity,
        a.angular_velocity,
        b.linear_velocity,
        b.angular_velocity,
    );
    let impulse = j.point_mass * -velocity;
    j.point_impulse += impulse;
    apply_point(j, impulse, &mut a, &mut b);

    for row in j.angular.iter_mut().filter(|row| row.mass > 0.0) {
        if row.push_target != 0.0 || row.push_impulse != 0.0 {
            let velocity = row.direction.dot(b.push_angular - a.push_angular);
            let total = (row.push_impulse + (row.push_target - velocity) * row.mass)
                .clamp(row.lower, row.upper);
            let delta = total - row.push_impulse;
            row.push_impulse = total;
            a.push_angular -= row.inertia_a * delta;
            b.push_angular += row.inertia_b * delta;
        }
        let velocity = row.direction.dot(b.angular_velocity - a.angular_velocity);
        let total =
            (row.impulse + (row.velocity_target - velocity) * row.mass).clamp(row.lower, row.upper);
        let delta = total - row.impulse;
        row.impulse = total;
        apply_angular(row, delta, &mut a, &mut b);
    }
    access.store(j.body_a, &a);
    access.store(j.body_b, &b);
}
