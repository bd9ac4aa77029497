//! The joint translation against Tumble: same motion where the mapping is exact, limits that
//! hold, and the ragdolls scene with every joint in place. CPU only (tumble-cpu and rapier).

use super::super::{SolverSettings, translate};
use crate::engine::{BuildError, EngineKind};
use rapier3d::prelude::*;
use tumble::dynamics::body::BodyDesc;
use tumble::dynamics::joint::{JointKind, Motor};
use tumble::math::{Quat, Vec3};
use tumble::scene::Scene;
use tumble::scene::format::SceneJoint;
use tumble::{Shape, StepConfig, World};

/// A scene of a static pivot (body 0) and one dynamic body (body 1) joined at `anchor`.
fn pivoted(body: BodyDesc, kind: JointKind, anchor: Vec3) -> Scene {
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies = vec![BodyDesc::fixed(Shape::sphere(0.05)).position(anchor), body];
    scene.joints = vec![SceneJoint::new(kind, 0, 1, anchor)];
    scene
}

fn steps(scene: &Scene, seconds: f32) -> usize {
    (seconds / scene.config.dt).round() as usize
}

/// Body 1's rotation after each step of `seconds`, on Tumble (CPU) and on rapier.
fn rotations(scene: &Scene, seconds: f32) -> (Vec<Quat>, Vec<Quat>) {
    let mut world: World = scene.build().unwrap();
    let body = world.bodies().nth(1).unwrap();
    let (mut rapier, handles) = translate(scene, SolverSettings::Matched).unwrap();
    let (mut tumble_rotations, mut rapier_rotations) = (Vec::new(), Vec::new());
    for _ in 0..steps(scene, seconds) {
        world.step();
        rapier.step();
        tumble_rotations.push(world.pose(body).unwrap().rotation);
        let q = rapier.bodies[handles[1]].rotation();
        rapier_rotations.push(Quat::from_xyzw(q.x, q.y, q.z, q.w));
    }
    (tumble_rotations, rapier_rotations)
}

/// Period (s) of a swing through x = 0: twice the mean time between crossings, each placed
/// between steps by linear interpolation.
fn swing_period(engine: EngineKind, scene: &Scene, seconds: f32) -> f32 {
    let mut simulation = engine.build(scene).unwrap();
    let dt = scene.config.dt;
    let mut crossings = Vec::new();
    let mut previous = simulation.dynamic_states()[0].position.x;
    for step in 0..steps(scene, seconds) {
        simulation.step();
        let x = simulation.dynamic_states()[0].position.x;
        if (previous > 0.0) != (x > 0.0) {
            crossings.push(dt * (step as f32 + previous / (previous - x)));
        }
        previous = x;
    }
    assert!(crossings.len() >= 3, "{engine:?}: {crossings:?}");
    let span = crossings.last().unwrap() - crossings[0];
    2.0 * span / (crossings.len() - 1) as f32
}

#[test]
fn a_pendulum_on_a_point_joint_swings_with_tumbles_period() {
    // A 0.1 m ball on a 1 m arm, released 0.3 rad from the vertical.
    let (length, radius, amplitude) = (1.0f32, 0.1f32, 0.3f32);
    let pivot = Vec3::new(0.0, 2.0, 0.0);
    let bob = pivot + length * Vec3::new(amplitude.sin(), -amplitude.cos(), 0.0);
    let scene = pivoted(
        BodyDesc::dynamic(Shape::sphere(radius)).position(bob),
        JointKind::Point,
        pivot,
    );
    let tumble = swing_period(EngineKind::TumbleCpu, &scene, 5.0);
    let rapier = swing_period(EngineKind::Rapier, &scene, 5.0);
    // Physical pendulum with the first amplitude correction: both engines swing a pendulum.
    let g = 9.81f32;
    let closed_form = 2.0
        * std::f32::consts::PI
        * ((length * length + 0.4 * radius * radius) / (g * length)).sqrt()
        * (1.0 + amplitude * amplitude / 16.0);
    assert!(
        (tumble / closed_form - 1.0).abs() < 0.03,
        "Tumble {tumble} s, closed form {closed_form} s"
    );
    assert!(
        (rapier / tumble - 1.0).abs() < 0.02,
        "rapier {rapier} s, Tumble {tumble} s"
    );
}

/// Rotation angle about +z (rad) of a rotation about z.
fn angle_about_z(q: Quat) -> f32 {
    2.0 * q.z.atan2(q.w)
}

#[test]
fn a_hinge_limit_holds_in_rapier_at_tumbles_angle() {
    // A 1 m rod along +x, hinged at its end about +z, falls (turning about −z) onto its lower
    // limit. The limits are asymmetric, so a sign error would stop it at −1.0 instead.
    let (lower, upper) = (-0.4, 1.0);
    let kind = JointKind::Hinge {
        axis: Vec3::Z,
        limits: Some((lower, upper)),
        motor: None,
    };
    let rod = BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.05, 0.05)))
        .position(Vec3::new(0.5, 2.0, 0.0));
    let scene = pivoted(rod, kind, Vec3::new(0.0, 2.0, 0.0));
    let (tumble, rapier) = rotations(&scene, 2.0);
    let lowest = rapier
        .iter()
        .map(|&q| angle_about_z(q))
        .fold(f32::INFINITY, f32::min);
    assert!(lowest > lower - 0.05, "rapier passed the limit: {lowest}");
    let (tumble_end, rapier_end) = (
        angle_about_z(*tumble.last().unwrap()),
        angle_about_z(*rapier.last().unwrap()),
    );
    assert!(
        (tumble_end - lower).abs() < 0.02,
        "Tumble rests at {tumble_end}"
    );
    assert!(
        (rapier_end - lower).abs() < 0.02,
        "rapier rests at {rapier_end}"
    );
}

#[test]
fn a_hinge_motor_reaches_its_speed_in_both_engines() {
    let kind = JointKind::Hinge {
        axis: Vec3::Z,
        limits: None,
        motor: Some(Motor {
            target_speed: 3.0,
            max_torque: 50.0,
        }),
    };
    let wheel = BodyDesc::dynamic(Shape::sphere(0.3)).position(Vec3::new(0.0, 2.0, 0.0));
    let scene = pivoted(wheel, kind, Vec3::new(0.0, 2.0, 0.0));
    let mut world = scene.build().unwrap();
    let body = world.bodies().nth(1).unwrap();
    let (mut rapier, handles) = translate(&scene, SolverSettings::Matched).unwrap();
    for _ in 0..steps(&scene, 0.5) {
        world.step();
        rapier.step();
    }
    let tumble = world.angular_velocity(body).unwrap().z;
    let rapier = rapier.bodies[handles[1]].angvel().z;
    assert!((tumble - 3.0).abs() < 0.03, "Tumble at {tumble} rad/s");
    assert!((rapier - 3.0).abs() < 0.03, "rapier at {rapier} rad/s");
}

#[test]
fn a_fixed_joint_holds_a_cantilever_in_rapier() {
    // A 1 m rod along +x welded at its end to a static body: it must neither droop nor turn.
    let rod = BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.05, 0.05)))
        .position(Vec3::new(0.5, 2.0, 0.0));
    let scene = pivoted(rod, JointKind::Fixed, Vec3::new(0.0, 2.0, 0.0));
    let (world, _) = translate(&scene, SolverSettings::Matched).unwrap();
    let (_, joint) = world.impulse_joints.iter().next().unwrap();
    assert!(joint.data.as_fixed().is_some());
    let (tumble, rapier) = rotations(&scene, 1.0);
    for (engine, rotations) in [("Tumble", tumble), ("rapier", rapier)] {
        let droop = angle_about_z(*rotations.last().unwrap());
        assert!(
            droop.abs() < 0.01,
            "{engine}: the rod turned by {droop} rad"
        );
    }
}

/// Swing (angle between the rest axis −y and the rod's axis) and twist (about the rod's axis,
/// swing-twist decomposition) of a rotation from rest.
fn swing_and_twist(q: Quat) -> (f32, f32) {
    let axis = q * Vec3::NEG_Y;
    let swing = axis.dot(Vec3::NEG_Y).clamp(-1.0, 1.0).acos();
    // The twist is about the rest axis −y: q = swing · twist, twist = (w, y·ŷ) normalized.
    let twist = -2.0 * q.y.atan2(q.w);
    (swing, twist)
}

#[test]
fn cone_twist_limits_hold_in_rapier() {
    // A 1 m rod hanging from a pivot, kicked about the pivot (its centre moving at ω × r) to
    // swing and twist past its limits.
    let (swing_limit, twist_limits) = (0.5, (-0.3, 0.3));
    let kind = JointKind::ConeTwist {
        axis: Vec3::NEG_Y,
        swing_limit,
        twist_limits,
    };
    let rod = BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.05, 0.5, 0.05)))
        .position(Vec3::new(0.0, 1.5, 0.0))
        .angular_velocity(Vec3::new(0.0, 4.0, 8.0))
        .linear_velocity(Vec3::new(4.0, 0.0, 0.0));
    let scene = pivoted(rod, kind, Vec3::new(0.0, 2.0, 0.0));
    let (tumble, rapier) = rotations(&scene, 1.5);
    for (engine, rotations) in [("Tumble", tumble), ("rapier", rapier)] {
        let (mut swing, mut twist) = (0.0f32, 0.0f32);
        for &q in &rotations {
            let (s, t) = swing_and_twist(q);
            swing = swing.max(s);
            twist = twist.max(t.abs());
        }
        // Reached each limit, and held it (within what one sub-step may carry past).
        assert!(
            (swing - swing_limit).abs() < 0.05,
            "{engine}: largest swing {swing}"
        );
        assert!(
            (twist - twist_limits.1).abs() < 0.05,
            "{engine}: largest twist {twist}"
        );
    }
}

#[test]
fn ragdolls_run_on_rapier_with_every_joint_and_none_falls_through_the_ground() {
    let scene = tumble::scene::builtin("ragdolls", 0.05).unwrap();
    assert_eq!(scene.joints.len(), 60, "6 ragdolls of 10 joints");
    let (mut world, handles) = translate(&scene, SolverSettings::Matched).unwrap();
    assert_eq!(world.impulse_joints.len(), scene.joints.len());
    let (mut spherical, mut revolute) = (0, 0);
    for (_, joint) in world.impulse_joints.iter() {
        assert!(!joint.data.contacts_enabled());
        spherical += joint.data.as_spherical().is_some() as usize;
        revolute += joint.data.as_revolute().is_some() as usize;
    }
    // Per ragdoll: spine, neck, shoulders and hips are cone-twists, elbows and knees hinges.
    assert_eq!((spherical, revolute), (36, 24));
    // Each joint's two frames in the world: they coincide at creation (all angles zero).
    let world_frames = |world: &PhysicsWorld| -> Vec<(Pose, Pose)> {
        world
            .impulse_joints
            .iter()
            .map(|(_, joint)| {
                let pose = |body: RigidBodyHandle| *world.bodies[body].position();
                (
                    pose(joint.body1()) * joint.data.local_frame1,
                    pose(joint.body2()) * joint.data.local_frame2,
                )
            })
            .collect()
    };
    let worst_gap = |world: &PhysicsWorld| {
        world_frames(world)
            .iter()
            .map(|(frame1, frame2)| (frame1.translation - frame2.translation).length())
            .fold(0.0f32, f32::max)
    };
    for (frame1, frame2) in world_frames(&world) {
        assert!((frame1.translation - frame2.translation).length() < 1e-5);
        assert!(frame1.rotation.dot(frame2.rotation).abs() > 1.0 - 1e-6);
    }
    let dynamic: Vec<_> = handles
        .iter()
        .zip(&scene.bodies)
        .filter(|(_, desc)| !desc.is_static())
        .map(|(&handle, _)| handle)
        .collect();
    let (mut lowest, mut gap) = (f32::INFINITY, 0.0f32);
    for _ in 0..steps(&scene, 2.0) {
        world.step();
        for &handle in &dynamic {
            lowest = lowest.min(world.bodies[handle].translation().y);
        }
        gap = gap.max(worst_gap(&world));
    }
    // Capsule centres (radius ≥ 0.045 m) stay above the ground plane at y = 0.
    assert!(lowest > 0.0, "a body sank to y = {lowest}");
    // Soft joints stretch as the rows land (up to about 3 cm here, Tumble's about 1 cm).
    assert!(gap < 0.05, "a joint came apart by {gap} m");
}

#[test]
fn a_breakable_joint_is_unsupported_on_rapier() {
    let mut scene = pivoted(
        BodyDesc::dynamic(Shape::sphere(0.1)).position(Vec3::new(1.0, 2.0, 0.0)),
        JointKind::Point,
        Vec3::new(0.0, 2.0, 0.0),
    );
    scene.joints[0].break_impulse = Some(10.0);
    for engine in [EngineKind::Rapier, EngineKind::RapierDefault] {
        match engine.build(&scene) {
            Err(BuildError::Unsupported(why)) => assert!(why.contains("break_impulse"), "{why}"),
            Err(other) => panic!("{engine:?}: {other:?}"),
            Ok(_) => panic!("{engine:?} ran a scene whose joint it cannot break"),
        }
    }
}
