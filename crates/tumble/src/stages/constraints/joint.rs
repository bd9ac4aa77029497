//! Joint rows. Every joint kind keeps its anchors together with a **point part**, solved as one
//! 3×3 block (Jolt's PointConstraintPart), plus up to [`MAX_ANGULAR_ROWS`] one-dimensional
//! **angular rows** solved one after the other.
//!
//! Point part, with r_a, r_b the world arms from each centre of mass to the anchor:
//!
//! ```text
//!   C     = (x_b + r_b) − (x_a + r_a)                       (m, world)
//!   C_dot = v_b + ω_b × r_b − v_a − ω_a × r_a
//!   K     = (1/m_a + 1/m_b) 𝟙 − [r_a]× I_a⁻¹ [r_a]× − [r_b]× I_b⁻¹ [r_b]×
//!   λ     = K⁻¹ (target − C_dot);  B gets +λ at r_b, A gets −λ at r_a
//! ```
//!
//! Angular row along a unit direction d: `C_dot = d·(ω_b − ω_a)`, `K = d·(I_a⁻¹ + I_b⁻¹) d`,
//! impulse clamped to `[lower, upper]`.
//! - hinge alignment: with a = A's axis and b₁, b₂ ⊥ B's axis, `C_i = a·b_i`, d = b_i × a;
//! - fixed: three rows along world X, Y, Z driving the rotation error to zero;
//! - limits: inequality rows (impulse ≥ 0) on the distance `s` to the limit, speculative like
//!   contacts (`C_dot ≥ −s/dt` while inside, split-impulse push when outside);
//! - hinge motor: `C_dot = target_speed`, |impulse| ≤ max_torque · dt.
//!
//! Position errors are removed by the split impulse, as for contacts: `push_target = −β C/dt`
//! on the pseudo-velocities, so joint correction adds no energy either.

use crate::dynamics::body::{BodyMass, BodyPose};
use crate::dynamics::joint::{Joint, JointKind, MAX_ANGULAR_ROWS};
use crate::math::{Mat3, Quat, Vec3, tangent_basis};
use crate::stages::constraints::STATIC_BODY;

/// One angular row of a joint; `mass == 0` marks an unused slot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AngularRow {
    /// Unit direction, world frame.
    pub direction: Vec3,
    /// I_a⁻¹ d and I_b⁻¹ d.
    pub inertia_a: Vec3,
    pub inertia_b: Vec3,
    /// 1/K.
    pub mass: f32,
    /// Accumulated impulse (N m s) and its bounds.
    pub impulse: f32,
    pub lower: f32,
    pub upper: f32,
    /// Relative angular speed the row drives to (rad/s); for inequality rows the least allowed.
    pub velocity_target: f32,
    /// Split-impulse target on the pseudo-velocities (rad/s) and its accumulated impulse.
    pub push_target: f32,
    pub push_impulse: f32,
}

/// The rows of one joint for one sub-step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointConstraint {
    pub body_a: u32,
    pub body_b: u32,
    /// Index of the joint in the world, to store impulses back.
    pub joint: u32,
    pub inverse_mass_a: f32,
    pub inverse_mass_b: f32,
    pub inverse_inertia_a: Mat3,
    pub inverse_inertia_b: Mat3,
    /// World arms from each centre of mass to the anchor (m).
    pub arm_a: Vec3,
    pub arm_b: Vec3,
    /// K⁻¹ of the point part.
    pub point_mass: Mat3,
    pub point_impulse: Vec3,
    pub point_push_target: Vec3,
    pub angular: [AngularRow; MAX_ANGULAR_ROWS],
}

/// Builds the rows of every live, unbroken joint (`None` is a free joint slot).
#[allow(clippy::too_many_arguments)]
pub fn build_joint_constraints(
    joints: &[Option<Joint>],
    poses: &[BodyPose],
    masses: &[BodyMass],
    inverse_inertia: &[Mat3],
    dt: f32,
    push_factor: f32,
    max_push_velocity: f32,
    out: &mut Vec<JointConstraint>,
) {
    out.clear();
    for (index, joint) in joints.iter().enumerate() {
        let Some(joint) = joint.filter(|joint| !joint.broken) else {
            continue;
        };
        out.push(build(
            index as u32,
            &joint,
            poses,
            masses,
            inverse_inertia,
            dt,
            push_factor,
            max_push_velocity,
        ));
    }
}

#[allow(clippy::too_many_arguments)]
fn build(
    index: u32,
    joint: &Joint,
    poses: &[BodyPose],
    masses: &[BodyMass],
    inverse_inertia: &[Mat3],
    dt: f32,
    push_factor: f32,
    max_push_velocity: f32,
) -> JointConstraint {
    let (ia, ib) = (joint.body_a as usize, joint.body_b as usize);
    let (pose_a, pose_b) = (poses[ia], poses[ib]);
    let (mass_a, mass_b) = (masses[ia].inverse_mass, masses[ib].inverse_mass);
    let (inertia_a, inertia_b) = (inverse_inertia[ia], inverse_inertia[ib]);
    let arm_a = pose_a.rotation * joint.local_anchor_a;
    let arm_b = pose_b.rotation * joint.local_anchor_b;
    let error = (pose_b.position + arm_b) - (pose_a.position + arm_a);
    let skew_a = skew(arm_a);
    let skew_b = skew(arm_b);
    let k = Mat3::from_diagonal(Vec3::splat(mass_a + mass_b))
        - skew_a * inertia_a * skew_a
        - skew_b * inertia_b * skew_b;
    let point_mass = if k.determinant().abs() > f32::MIN_POSITIVE {
        k.inverse()
    } else {
        Mat3::ZERO
    };
    let push = |error: f32| -> f32 {
        (-push_factor * error / dt).clamp(-max_push_velocity, max_push_velocity)
    };
    let point_push_target = Vec3::new(push(error.x), push(error.y), push(error.z));

    let mut constraint = JointConstraint {
        body_a: if mass_a > 0.0 {
            joint.body_a
        } else {
            STATIC_BODY
        },
        body_b: if mass_b > 0.0 {
            joint.body_b
        } else {
            STATIC_BODY
        },
        joint: index,
        inverse_mass_a: mass_a,
        inverse_mass_b: mass_b,
        inverse_inertia_a: inertia_a,
        inverse_inertia_b: inertia_b,
        arm_a,
        arm_b,
        point_mass,
        point_impulse: joint.point_impulse,
        point_push_target,
        angular: [AngularRow::default(); MAX_ANGULAR_ROWS],
    };
    let row = |direction: Vec3, impulse: f32| -> AngularRow {
        let (ia_d, ib_d) = (inertia_a * direction, inertia_b * direction);
        let k = direction.dot(ia_d) + direction.dot(ib_d);
        AngularRow {
            direction,
            inertia_a: ia_d,
            inertia_b: ib_d,
            mass: if k > 0.0 { 1.0 / k } else { 0.0 },
            impulse,
            lower: f32::NEG_INFINITY,
            upper: f32::INFINITY,
            ..AngularRow::default()
        }
    };
    // An equality row driving `error` (along its direction) to zero.
    let equality = |direction: Vec3, error: f32, impulse: f32| AngularRow {
        push_target: push(error),
        ..row(direction, impulse)
    };
    // An inequality row keeping the distance `s` to a limit ≥ 0 (impulse ≥ 0).
    let limit = |direction: Vec3, s: f32, impulse: f32| AngularRow {
        lower: 0.0,
        velocity_target: if s > 0.0 { -s / dt } else { 0.0 },
        push_target: if s < 0.0 {
            (-push_factor * s / dt).min(max_push_velocity)
        } else {
            0.0
        },
        ..row(direction, impulse)
    };
    let warm = joint.angular_impulse;
    let rows = &mut constraint.angular;
    let axis_a = pose_a.rotation * joint.local_axis_a;
    let axis_b = pose_b.rotation * joint.local_axis_b;
    match joint.kind {
        JointKind::Point => {}
        JointKind::Fixed => {
            // Rotation taking where B should be (q_a · q_rel) to where it is: θ ≈ 2 · vec(q_err).
            let mut rotation_error =
                pose_b.rotation * (pose_a.rotation * joint.relative_rotation).inverse();
            if rotation_error.w < 0.0 {
                rotation_error = -rotation_error;
            }
            let angle = 2.0 * Vec3::new(rotation_error.x, rotation_error.y, rotation_error.z);
            for (i, direction) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
                rows[i] = equality(direction, angle[i], warm[i]);
            }
        }
        JointKind::Hinge { limits, motor, .. } => {
            let (b1, b2) = tangent_basis(axis_b);
            rows[0] = equality(b1.cross(axis_a), axis_a.dot(b1), warm[0]);
            rows[1] = equality(b2.cross(axis_a), axis_a.dot(b2), warm[1]);
            if let Some((lower, upper)) = limits {
                let angle = twist_angle(joint, &pose_a, &pose_b, axis_a, axis_b);
                rows[2] = limit(axis_a, angle - lower, warm[2]);
                rows[3] = limit(-axis_a, upper - angle, warm[3]);
            }
            if let Some(motor) = motor {
                let max_impulse = motor.max_torque * dt;
                rows[4] = AngularRow {
                    velocity_target: motor.target_speed,
                    lower: -max_impulse,
                    upper: max_impulse,
                    ..row(axis_a, warm[4])
                };
            }
        }
        JointKind::ConeTwist {
            swing_limit,
            twist_limits: (lower, upper),
            ..
        } => {
            let swing_axis = axis_a.cross(axis_b);
            let sin_swing = swing_axis.length();
            if sin_swing > 1e-6 {
                let swing = sin_swing.atan2(axis_a.dot(axis_b));
                // Swinging further turns B's axis away from A's about a × b.
                rows[0] = limit(-swing_axis / sin_swing, swing_limit - swing, warm[0]);
            }
            let angle = twist_angle(joint, &pose_a, &pose_b, axis_a, axis_b);
            rows[1] = limit(axis_a, angle - lower, warm[1]);
            rows[2] = limit(-axis_a, upper - angle, warm[2]);
        }
    }
    constraint
}

/// Rotation of B relative to A about the axis (rad, in (−π, π]), zero at creation: B's
/// reference direction is first swung back onto A's axis, then compared with A's.
fn twist_angle(
    joint: &Joint,
    pose_a: &BodyPose,
    pose_b: &BodyPose,
    axis_a: Vec3,
    axis_b: Vec3,
) -> f32 {
    let reference_a = pose_a.rotation * joint.local_reference_a;
    let reference_b =
        Quat::from_rotation_arc(axis_b, axis_a) * (pose_b.rotation * joint.local_reference_b);
    reference_a
        .cross(reference_b)
        .dot(axis_a)
        .atan2(reference_a.dot(reference_b))
}

/// [v]×: the matrix of the cross product, [v]× u = v × u.
fn skew(v: Vec3) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(0.0, v.z, -v.y),
        Vec3::new(-v.z, 0.0, v.x),
        Vec3::new(v.y, -v.x, 0.0),
    )
}
