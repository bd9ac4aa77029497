//! Tumble's joints as rapier impulse joints, one for one.
//!
//! # Frames
//!
//! Each joint gets the frames Tumble gives it ([`SceneJoint::state_in`]): in each body's frame,
//! the anchor and a rotation whose X is the joint axis and whose Y is Tumble's reference
//! direction (zero angle where A's and B's coincide). Rapier measures its angles as the
//! rotation of B's frame relative to A's, so its angles are Tumble's, zero at the same pose
//! and with the same sign. The joints are built as [`GenericJoint`]s only to pass both full
//! frames (rapier's `RevoluteJointBuilder` takes just an axis and would pick its own
//! reference, shifting the limits); their locked axes are exactly those of rapier's named
//! joints, so `as_spherical` / `as_revolute` / `as_fixed` see them as such.
//!
//! # Kinds
//!
//! - point → `SphericalJoint`: the three linear axes locked. Exact.
//! - hinge → `RevoluteJoint`: linear axes and angular Y, Z locked, angular X free. Limits on
//!   angular X are the same angle (twist about the axis). A motor becomes a velocity motor on
//!   angular X with the same target speed and `max_force` = `max_torque` (rapier bounds the
//!   impulse by max_force · sub-step, as Tumble does) and an infinite damping factor, which
//!   makes rapier's motor rigid like Tumble's (no CFM softening).
//! - cone-twist → a `SphericalJoint` with angular limits, exact in what it allows: angular
//!   Y and Z are *coupled* with the limit swing_limit, which rapier enforces as one cone
//!   on the angle between A's and B's X axes (Tumble's swing); angular X gets the twist
//!   limits, which rapier measures as 2·atan2(q.x, q.w) of the relative rotation, the twist of
//!   a swing-twist decomposition — Tumble's twist (B's reference swung back by the shortest
//!   arc). The rows differ: rapier pushes along A's axis for twist, Tumble along the bisector
//!   of the two axes, so a swung joint's twist limit acts with other effective masses.
//! - fixed → `FixedJoint`: all six axes locked. Exact.
//!
//! All kinds: contacts between the two bodies off (`contacts_enabled(false)`), as Tumble skips
//! jointed pairs. [`SolverSettings::Matched`] gives every joint Tumble's joint softness
//! (`joint_hertz` capped at half the sub-step rate, `joint_damping_ratio`); rapier's defaults
//! are near-rigid. Rapier's limits act only once reached, Tumble's speculatively before (as
//! its contacts), so a fast limb may pass a rapier limit by a sub-step's motion before it is
//! pushed back.
//!
//! # What is refused
//!
//! A joint with a `break_impulse`: rapier has no breakable joints, and leaving one unbreakable
//! would change the scene, so [`insert_joints`] refuses the scene and the benchmark reports the
//! case as `unsupported`. A dumped joint that already broke is inert in Tumble and is not
//! inserted (its bodies collide again, in both engines).

use super::{SolverSettings, vector};
use rapier3d::prelude::*;
use tumble::dynamics::joint::{JointKind, JointState};
use tumble::math::{Mat3, Quat};
use tumble::scene::Scene;
use tumble::scene::format::SceneJoint;

/// Inserts the scene's joints between `handles` (the scene's bodies, in order); `Err` says why
/// a joint cannot go to rapier faithfully.
pub fn insert_joints(
    world: &mut PhysicsWorld,
    scene: &Scene,
    handles: &[RigidBodyHandle],
    settings: SolverSettings,
) -> Result<(), String> {
    let softness = match settings {
        SolverSettings::Matched => {
            let config = &scene.config;
            let substep = config.dt / config.substeps.max(1) as f32;
            Some(SpringCoefficients::new(
                config.joint_hertz.min(0.5 / substep),
                config.joint_damping_ratio,
            ))
        }
        SolverSettings::RapierDefault => None,
    };
    // Check every joint first, so a refused scene inserts nothing.
    let mut joints = Vec::with_capacity(scene.joints.len());
    for (i, joint) in scene.joints.iter().enumerate() {
        if joint.break_impulse.is_some() {
            return Err(format!(
                "joints[{i}] has a break_impulse; rapier has no breakable joints"
            ));
        }
        let state = joint
            .state_in(&scene.bodies)
            .ok_or_else(|| format!("joints[{i}] refers to a body that does not exist"))?;
        if !state.broken {
            joints.push((joint, state));
        }
    }
    for (joint, state) in joints {
        let mut rapier_joint = rapier_joint(joint, &state);
        if let Some(softness) = softness {
            rapier_joint.softness = softness;
        }
        world.insert_impulse_joint(handles[joint.body_a], handles[joint.body_b], rapier_joint);
    }
    Ok(())
}

/// The rapier joint of one Tumble joint with frames `state` (module docs).
fn rapier_joint(joint: &SceneJoint, state: &JointState) -> GenericJoint {
    let builder = match joint.kind {
        JointKind::Point => GenericJointBuilder::new(JointAxesMask::LOCKED_SPHERICAL_AXES),
        JointKind::Fixed => GenericJointBuilder::new(JointAxesMask::LOCKED_FIXED_AXES),
        JointKind::Hinge { limits, motor, .. } => {
            let mut builder = GenericJointBuilder::new(JointAxesMask::LOCKED_REVOLUTE_AXES);
            if let Some((lower, upper)) = limits {
                builder = builder.limits(JointAxis::AngX, [lower, upper]);
            }
            if let Some(motor) = motor {
                builder = builder
                    .motor_velocity(JointAxis::AngX, motor.target_speed, f32::INFINITY)
                    .motor_max_force(JointAxis::AngX, motor.max_torque);
            }
            builder
        }
        JointKind::ConeTwist {
            swing_limit,
            twist_limits: (lower, upper),
            ..
        } => GenericJointBuilder::new(JointAxesMask::LOCKED_SPHERICAL_AXES)
            .coupled_axes(JointAxesMask::ANG_Y | JointAxesMask::ANG_Z)
            // The swing angle is ≥ 0, so only the upper bound ever acts. A lower bound of 0
            // would turn on a row about an arbitrary axis whenever the axes align exactly
            // (as at creation), so it lies below any angle.
            .limits(JointAxis::AngY, [-swing_limit, swing_limit])
            .limits(JointAxis::AngX, [lower, upper]),
    };
    let frame = |anchor, axis, reference| {
        let rotation =
            Quat::from_mat3(&Mat3::from_cols(axis, reference, axis.cross(reference))).normalize();
        Pose::from_parts(
            vector(anchor),
            Rotation::from_xyzw(rotation.x, rotation.y, rotation.z, rotation.w),
        )
    };
    builder
        .local_frame1(frame(
            state.local_anchor_a,
            state.local_axis_a,
            state.local_reference_a,
        ))
        .local_frame2(frame(
            state.local_anchor_b,
            state.local_axis_b,
            state.local_reference_b,
        ))
        .contacts_enabled(false)
        .build()
}

#[cfg(test)]
mod tests;
