//! Contact rows in the solver: warm start, normal and friction sweeps, restitution.

use super::{BodyAccess, SolverBody, Sweep, bias_terms};
use crate::math::Vec3;
use crate::stages::constraints::{ContactConstraint, Row};

/// How fast A moves away from B along `direction` at a point with moments `(r_a × d, r_b × d)`
/// (m/s).
#[inline]
fn row_velocity(
    direction: Vec3,
    (arm_a, arm_b): (Vec3, Vec3),
    a: &SolverBody,
    b: &SolverBody,
) -> f32 {
    direction.dot(a.linear_velocity - b.linear_velocity) + arm_a.dot(a.angular_velocity)
        - arm_b.dot(b.angular_velocity)
}

/// Applies `impulse` along `row` of direction `direction` of `c`: +impulse to A, −impulse to
/// B. The row's `I⁻¹(r × d)` is the one its build computed; the device computes the same
/// product here (`solver.wgsl`'s `apply`).
#[inline]
fn apply(
    c: &ContactConstraint,
    row: &Row,
    direction: Vec3,
    impulse: f32,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    a.linear_velocity += direction * (impulse * c.inverse_mass_a);
    a.angular_velocity += row.angular_a * impulse;
    b.linear_velocity -= direction * (impulse * c.inverse_mass_b);
    b.angular_velocity -= row.angular_b * impulse;
}

pub(super) fn warm_start(access: BodyAccess, c: &mut ContactConstraint) {
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    warm_start_pair(c, &mut a, &mut b);
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}

/// [`warm_start`] on the bodies `a` and `b` of `c`, wherever they come from (the Jacobi sweep
/// passes copies).
pub(super) fn warm_start_pair(c: &ContactConstraint, a: &mut SolverBody, b: &mut SolverBody) {
    let [t1, t2] = c.tangents();
    for point in &c.points[..c.point_count as usize] {
        let rows = [
            (c.normal, point.normal),
            (t1, point.tangent[0]),
            (t2, point.tangent[1]),
        ];
        for (direction, row) in rows {
            apply(c, &row, direction, row.impulse, a, b);
        }
    }
}

pub(super) fn solve_contact(access: BodyAccess, c: &mut ContactConstraint, sweep: Sweep) {
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    solve_contact_pair(c, sweep, &mut a, &mut b);
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}

/// [`solve_contact`] on the bodies `a` and `b` of `c`.
pub(super) fn solve_contact_pair(
    c: &mut ContactConstraint,
    sweep: Sweep,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    let n = c.normal;
    let count = c.point_count as usize;
    let displacement =
        |body: &SolverBody, anchor: Vec3| body.delta_position + body.delta_rotation * anchor;
    for k in 0..count {
        let point = &mut c.points[k];
        // Current separation from the bodies' motion during the step (the Jacobian stays fixed),
        // or the one kept from the last sweep when the bodies have not moved since.
        if sweep.moved {
            let moved = displacement(a, point.anchor_a) - displacement(b, point.anchor_b);
            point.separation = n.dot(moved) + point.adjusted_separation;
        }
        let separation = point.separation;
        let (bias, mass_scale, impulse_scale) = bias_terms(separation, c.softness, sweep);
        // Non-penetration: normal velocity ≥ −bias, accumulated impulse ≥ 0.
        let arms = point.arms(n);
        let velocity = row_velocity(n, arms, a, b);
        let row = &mut point.normal;
        let impulse = -row.mass * mass_scale * (velocity + bias) - impulse_scale * row.impulse;
        let total = (row.impulse + impulse).max(0.0);
        let delta = total - row.impulse;
        row.impulse = total;
        point.max_normal_impulse = point.max_normal_impulse.max(total);
        let row = point.normal;
        apply(c, &row, n, delta, a, b);
    }
    // Friction: both tangent rows from the same velocities, then the impulse clamped to the
    // friction circle |λ_t| ≤ μ λ_n (clamping each row alone would allow √2 μ λ_n diagonally).
    let friction = c.friction;
    let [t1, t2] = c.tangents();
    for k in 0..count {
        let point = c.points[k];
        let (arms1, arms2) = (point.arms(t1), point.arms(t2));
        let (velocity1, velocity2) = (row_velocity(t1, arms1, a, b), row_velocity(t2, arms2, a, b));
        let [row1, row2] = point.tangent;
        let want1 = row1.impulse - velocity1 * row1.mass;
        let want2 = row2.impulse - velocity2 * row2.mass;
        let limit = friction * point.normal.impulse;
        let length_squared = want1 * want1 + want2 * want2;
        let scale = if length_squared > limit * limit {
            limit / length_squared.sqrt()
        } else {
            1.0
        };
        let (total1, total2) = (want1 * scale, want2 * scale);
        apply(c, &row1, t1, total1 - row1.impulse, a, b);
        apply(c, &row2, t2, total2 - row2.impulse, a, b);
        c.points[k].tangent[0].impulse = total1;
        c.points[k].tangent[1].impulse = total2;
    }
}

pub(super) fn apply_restitution(access: BodyAccess, c: &mut ContactConstraint, threshold: f32) {
    if c.restitution == 0.0 {
        return;
    }
    let (mut a, mut b) = (access.load(c.body_a), access.load(c.body_b));
    restitution_pair(c, threshold, &mut a, &mut b);
    access.store(c.body_a, &a);
    access.store(c.body_b, &b);
}

/// [`apply_restitution`] on the bodies `a` and `b` of `c` (a no-op when `c` does not bounce).
pub(super) fn restitution_pair(
    c: &mut ContactConstraint,
    threshold: f32,
    a: &mut SolverBody,
    b: &mut SolverBody,
) {
    if c.restitution == 0.0 {
        return;
    }
    let n = c.normal;
    let restitution = c.restitution;
    for k in 0..c.point_count as usize {
        let point = &mut c.points[k];
        if point.approach_velocity > -threshold || point.max_normal_impulse == 0.0 {
            continue;
        }
        let arms = point.arms(n);
        let velocity = row_velocity(n, arms, a, b);
        let row = &mut point.normal;
        let total =
            (row.impulse - (velocity + restitution * point.approach_velocity) * row.mass).max(0.0);
        let delta = total - row.impulse;
        row.impulse = total;
        point.max_normal_impulse = point.max_normal_impulse.max(total);
        let row = point.normal;
        apply(c, &row, n, delta, a, b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::dbvt::tests::TestRng;
    use crate::math::SymmetricMat3;
    use crate::stages::constraints::lanes::impulse_sums;

    /// The device's warm start by body applies a constraint's impulse sums; the batch sweeps
    /// and the CPU apply its rows one by one. On random constraints of 0 to 4 points both move
    /// the bodies alike, up to rounding.
    #[test]
    fn impulse_sums_move_the_bodies_as_the_rows_do() {
        let mut rng = TestRng::new(7);
        for case in 0..200 {
            let mut c = ContactConstraint {
                point_count: (case % 5) as u32,
                normal: rng.vec3(-1.0, 1.0).normalize(),
                tangent1: rng.vec3(-1.0, 1.0),
                tangent2: rng.vec3(-1.0, 1.0),
                inverse_mass_a: rng.range(0.0, 2.0),
                inverse_mass_b: rng.range(0.0, 2.0),
                ..ContactConstraint::default()
            };
            let inertia = |rng: &mut TestRng| SymmetricMat3 {
                diagonal: rng.vec3(0.0, 2.0),
                off_diagonal: rng.vec3(-0.5, 0.5),
            };
            c.inverse_inertia_a = inertia(&mut rng);
            c.inverse_inertia_b = inertia(&mut rng);
            let header = c;
            for point in &mut c.points[..c.point_count as usize] {
                point.anchor_a = rng.vec3(-1.0, 1.0);
                point.anchor_b = rng.vec3(-1.0, 1.0);
                let directions = [header.normal, header.tangent1, header.tangent2];
                let angular = directions.map(|direction| header.angular(point.arms(direction)));
                let [tangent1, tangent2] = &mut point.tangent;
                for (row, (a, b)) in [&mut point.normal, tangent1, tangent2]
                    .into_iter()
                    .zip(angular)
                {
                    (row.angular_a, row.angular_b) = (a, b);
                    row.impulse = rng.range(-3.0, 3.0);
                }
            }
            let body = |rng: &mut TestRng| SolverBody {
                linear_velocity: rng.vec3(-2.0, 2.0),
                angular_velocity: rng.vec3(-2.0, 2.0),
                ..SolverBody::STATIC
            };
            let (mut a, mut b) = (body(&mut rng), body(&mut rng));
            let (mut summed_a, mut summed_b) = (a, b);
            warm_start_pair(&c, &mut a, &mut b);
            let [linear, angular_a, angular_b] = impulse_sums(&c);
            summed_a.linear_velocity += linear * c.inverse_mass_a;
            summed_a.angular_velocity += angular_a;
            summed_b.linear_velocity -= linear * c.inverse_mass_b;
            summed_b.angular_velocity -= angular_b;
            let pairs = [
                (a.linear_velocity, summed_a.linear_velocity),
                (a.angular_velocity, summed_a.angular_velocity),
                (b.linear_velocity, summed_b.linear_velocity),
                (b.angular_velocity, summed_b.angular_velocity),
            ];
            for (rows, sums) in pairs {
                assert!(
                    (rows - sums).length() < 1e-5,
                    "case {case}: {rows} against {sums}"
                );
            }
        }
    }
}
