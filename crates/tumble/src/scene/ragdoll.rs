//! A ragdoll: 11 capsules (pelvis, chest, head, upper and lower arms, upper and lower legs)
//! joined by hinges (elbows, knees) and cone-twists (spine, neck, shoulders, hips) with
//! human-like limits, after the ragdoll of Bullet's benchmark demo.
//!
//! The ragdoll is built in a T-pose, 1.76 m tall with its soles at the origin, facing +z with
//! its left hand along +x (Y up), 70 kg in all. Every joint is at zero in that pose; each
//! capsule runs from one joint to the next, so neighbours meet at their joint (their contacts
//! are skipped, being jointed).

use crate::dynamics::body::BodyDesc;
use crate::dynamics::joint::JointKind;
use crate::math::{Quat, Vec3};
use crate::scene::format::{Scene, SceneJoint};
use crate::shape::Shape;
use std::f32::consts::FRAC_PI_2;

/// Bodies per ragdoll.
pub const RAGDOLL_BODIES: usize = 11;

/// Height from the soles to the top of the head (m).
pub const RAGDOLL_HEIGHT: f32 = 1.76;

/// Half the T-pose's span, wrist to wrist (m).
pub const RAGDOLL_HALF_SPAN: f32 = 0.76;

/// Adds a ragdoll to `scene`, its soles centred on `feet`, turned by `facing` from the pose of
/// the module documentation. Returns the index of its first body (the pelvis); the others
/// follow in the order chest, head, then left and right upper arm, lower arm, upper leg and
/// lower leg.
pub fn add_ragdoll(scene: &mut Scene, feet: Vec3, facing: Quat) -> usize {
    let first = scene.bodies.len();
    let place = |point: Vec3| feet + facing * point;
    // A capsule of radius `radius` from joint point `from` to `to` (body frame: axis Y).
    let mut capsule = |from: Vec3, to: Vec3, radius: f32, mass: f32| {
        let length = (to - from).length();
        let rotation = Quat::from_rotation_arc(Vec3::Y, (to - from) / length);
        scene.bodies.push(
            BodyDesc::dynamic(Shape::capsule(radius, 0.5 * length - radius))
                .position(place(0.5 * (from + to)))
                .rotation(facing * rotation)
                .mass(mass),
        );
        scene.bodies.len() - 1
    };

    let waist = Vec3::new(0.0, 1.12, 0.0);
    let neck = Vec3::new(0.0, 1.5, 0.0);
    let pelvis = capsule(
        Vec3::new(-0.2, 1.0, 0.0),
        Vec3::new(0.2, 1.0, 0.0),
        0.12,
        10.0,
    );
    let chest = capsule(waist, neck, 0.14, 20.0);
    let head = capsule(neck, Vec3::new(0.0, RAGDOLL_HEIGHT, 0.0), 0.1, 5.0);

    let mut joints = vec![
        cone_twist(pelvis, chest, waist, Vec3::Y, 0.5, (-0.4, 0.4)),
        cone_twist(chest, head, neck, Vec3::Y, 0.6, (-0.9, 0.9)),
    ];
    for side in [1.0, -1.0] {
        // `side` is +1 on the left (+x), −1 on the right.
        let outward = Vec3::new(side, 0.0, 0.0);
        let shoulder = Vec3::new(0.16 * side, 1.42, 0.0);
        let elbow = Vec3::new(0.46 * side, 1.42, 0.0);
        let wrist = Vec3::new(RAGDOLL_HALF_SPAN * side, 1.42, 0.0);
        let hip = Vec3::new(0.1 * side, 0.92, 0.0);
        let knee = Vec3::new(0.1 * side, 0.5, 0.0);
        let sole = Vec3::new(0.1 * side, 0.0, 0.0);
        let upper_arm = capsule(shoulder, elbow, 0.05, 2.5);
        let lower_arm = capsule(elbow, wrist, 0.045, 1.5);
        let upper_leg = capsule(hip, knee, 0.07, 8.0);
        let lower_leg = capsule(knee, sole, 0.055, 5.5);
        // Elbows bend the forearm forward (+z): a positive turn about −y on the left, +y on
        // the right. Knees bend the shin backward (−z): a positive turn about +x.
        let elbow_axis = Vec3::new(0.0, -side, 0.0);
        joints.extend([
            cone_twist(chest, upper_arm, shoulder, outward, 1.5, (-0.6, 0.6)),
            hinge(upper_arm, lower_arm, elbow, elbow_axis, (0.0, 2.5)),
            cone_twist(pelvis, upper_leg, hip, -Vec3::Y, 0.9, (-0.4, 0.4)),
            hinge(upper_leg, lower_leg, knee, Vec3::X, (0.0, 2.3)),
        ]);
    }
    for mut joint in joints {
        joint.anchor = place(joint.anchor);
        joint.kind = match joint.kind {
            JointKind::Hinge {
                axis,
                limits,
                motor,
            } => JointKind::Hinge {
                axis: facing * axis,
                limits,
                motor,
            },
            JointKind::ConeTwist {
                axis,
                swing_limit,
                twist_limits,
            } => JointKind::ConeTwist {
                axis: facing * axis,
                swing_limit,
                twist_limits,
            },
            other => other,
        };
        scene.joints.push(joint);
    }
    debug_assert_eq!(scene.bodies.len() - first, RAGDOLL_BODIES);
    first
}

/// A cone-twist joint (angles in rad) in the ragdoll's own frame.
fn cone_twist(
    a: usize,
    b: usize,
    anchor: Vec3,
    axis: Vec3,
    swing_limit: f32,
    twist_limits: (f32, f32),
) -> SceneJoint {
    let kind = JointKind::ConeTwist {
        axis,
        swing_limit,
        twist_limits,
    };
    SceneJoint::new(kind, a, b, anchor)
}

/// A hinge with limits (rad) in the ragdoll's own frame.
fn hinge(a: usize, b: usize, anchor: Vec3, axis: Vec3, limits: (f32, f32)) -> SceneJoint {
    let kind = JointKind::Hinge {
        axis,
        limits: Some(limits),
        motor: None,
    };
    SceneJoint::new(kind, a, b, anchor)
}

/// A turn of the ragdoll about Y that puts its arms along z (so that ragdolls stand close
/// side by side along x).
pub fn arms_along_z() -> Quat {
    Quat::from_rotation_y(FRAC_PI_2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::config::StepConfig;

    #[test]
    fn a_ragdoll_has_eleven_bodies_ten_joints_and_seventy_kilograms() {
        let mut scene = Scene::new(StepConfig::default());
        let first = add_ragdoll(&mut scene, Vec3::ZERO, Quat::IDENTITY);
        assert_eq!(first, 0);
        assert_eq!(scene.bodies.len(), RAGDOLL_BODIES);
        assert_eq!(scene.joints.len(), 10);
        let mass: f32 = scene.bodies.iter().map(|body| body.mass).sum();
        assert_eq!(mass, 70.0);
        // Standing on its soles: the lowest capsule ends at y = 0.
        let world = scene.build().unwrap();
        let lowest = world
            .bodies()
            .map(|body| {
                let pose = world.pose(body).unwrap();
                let desc = world.body_desc(body).unwrap();
                let Shape::Capsule(capsule) = desc.shape else {
                    unreachable!("a ragdoll is made of capsules")
                };
                let tip = (pose.rotation * Vec3::Y * capsule.half_height).y.abs();
                pose.position.y - tip - capsule.radius
            })
            .fold(f32::INFINITY, f32::min);
        assert!(lowest.abs() < 1e-5, "lowest point at {lowest}");
    }
}
