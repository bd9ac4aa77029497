//! Stage 8: integration. The solver integrates velocities and positions in its sub-steps
//! (semi-implicit Euler: velocities first, then positions from the new velocities) into
//! per-body deltas; this stage sets the bodies up for it and applies the deltas to the poses
//! at the end of the step.
//!
//! Guarantees: static bodies (inverse mass 0) never move; rotations stay unit quaternions.

use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity};
use crate::math::{Quat, Vec3};
use crate::stages::solver::SolverBody;
use rayon::prelude::*;

pub mod gpu;

/// Most a body may turn in one sub-step (rad): caps runaway spin, which the linearized
/// quaternion update cannot follow (Box2D caps at the same quarter turn).
pub const MAX_ROTATION_PER_STEP: f32 = 0.25 * std::f32::consts::PI;

const MIN_BODIES_PER_TASK: usize = 512;

/// The solver's bodies at the start of the step: current velocities, no motion yet.
pub fn prepare_bodies(
    velocities: &[BodyVelocity],
    masses: &[BodyMass],
    bodies: &mut Vec<SolverBody>,
) {
    bodies.resize(velocities.len(), SolverBody::STATIC);
    bodies
        .par_iter_mut()
        .zip(velocities.par_iter().zip(masses.par_iter()))
        .with_min_len(MIN_BODIES_PER_TASK)
        .for_each(|(body, (velocity, mass))| {
            let dynamic = mass.inverse_mass > 0.0;
            *body = SolverBody {
                linear_velocity: if dynamic { velocity.linear } else { Vec3::ZERO },
                inverse_mass: mass.inverse_mass,
                angular_velocity: if dynamic {
                    velocity.angular
                } else {
                    Vec3::ZERO
                },
                ..SolverBody::STATIC
            };
        });
}

/// The step's motion into the poses; the solved velocities become the bodies'.
pub fn finalize_bodies(
    bodies: &[SolverBody],
    poses: &mut [BodyPose],
    velocities: &mut [BodyVelocity],
) {
    poses
        .par_iter_mut()
        .zip(velocities.par_iter_mut())
        .zip(bodies.par_iter())
        .with_min_len(MIN_BODIES_PER_TASK)
        .for_each(|((pose, velocity), body)| {
            if body.inverse_mass == 0.0 {
                return;
            }
            *velocity = BodyVelocity::new(body.linear_velocity, body.angular_velocity);
            pose.position += body.delta_position;
            pose.rotation = (body.delta_rotation * pose.rotation).normalize();
        });
}

/// `angular_velocity` scaled down so that it turns at most [`MAX_ROTATION_PER_STEP`] in `dt`.
pub fn clamp_rotation(angular_velocity: Vec3, dt: f32) -> Vec3 {
    let angle = angular_velocity.length() * dt;
    if angle > MAX_ROTATION_PER_STEP {
        angular_velocity * (MAX_ROTATION_PER_STEP / angle)
    } else {
        angular_velocity
    }
}

/// q' = normalize(q + ½ dt (ω, 0) q), with ω in the world frame.
#[inline]
pub fn integrate_rotation(rotation: Quat, angular_velocity: Vec3, dt: f32) -> Quat {
    let spin = Quat::from_xyzw(
        angular_velocity.x,
        angular_velocity.y,
        angular_velocity.z,
        0.0,
    ) * rotation;
    (rotation + spin * (0.5 * dt)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_spin_turns_by_omega_t() {
        let mut q = Quat::IDENTITY;
        let omega = Vec3::new(0.0, 1.0, 0.0);
        for _ in 0..60 {
            q = integrate_rotation(q, omega, 1.0 / 600.0);
        }
        let (axis, angle) = q.to_axis_angle();
        assert!((angle - 0.1).abs() < 1e-4 && (axis - Vec3::Y).length() < 1e-4);
    }

    #[test]
    fn static_bodies_stay_put() {
        let mut poses = [BodyPose::new(Vec3::ONE, Quat::IDENTITY)];
        let mut velocities = [BodyVelocity::new(Vec3::X, Vec3::Y)];
        let masses = [BodyMass::default()];
        let mut bodies = Vec::new();
        prepare_bodies(&velocities, &masses, &mut bodies);
        bodies[0].delta_position = Vec3::ONE;
        finalize_bodies(&bodies, &mut poses, &mut velocities);
        assert_eq!(poses[0].position, Vec3::ONE);
    }
}
