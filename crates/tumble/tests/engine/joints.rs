//! Joints against closed forms: a pendulum's length and small-angle period, a hinge limit under
//! load (both sign conventions), a hanging chain, a hinge motor's speed and torque limit, a
//! fixed joint, and the break threshold. Every test prints what it measured.
use crate::common;
use common::*;
use std::f32::consts::PI;
use tumble::math::{Quat, Vec3};
use tumble::{BodyDesc, BodyHandle, JointDesc, JointHandle, JointKind, Motor, Shape, World};

fn world(gravity: Vec3) -> World {
    // No sleeping: a hanging chain or a pendulum at rest is what these tests look at.
    World::new(tumble::StepConfig {
        gravity,
        sleeping: false,
        ..Default::default()
    })
    .unwrap()
}

/// A static sphere at `position`, something to hang joints on.
fn pivot(world: &mut World, position: Vec3) -> BodyHandle {
    world
        .add_body(BodyDesc::fixed(Shape::sphere(0.05)).position(position))
        .unwrap()
}

/// Distance between the joint's two anchors (m).
fn gap(world: &World, joint: JointHandle) -> f32 {
    let (a, b) = world.joint_anchors(joint).unwrap();
    (a - b).length()
}

/// Rotation of `body` about Z from its initial (identity) orientation (rad), taken from where
/// its local X axis points.
fn angle_about_z(world: &World, body: BodyHandle) -> f32 {
    let x = world.pose(body).unwrap().rotation * Vec3::X;
    x.y.atan2(x.x)
}

#[test]
fn pendulum_keeps_its_length_and_swings_with_the_small_angle_period() {
    const LENGTH: f32 = 1.0;
    const RADIUS: f32 = 0.05;
    const START_ANGLE: f32 = 0.1;
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let anchor = Vec3::new(0.0, 2.0, 0.0);
    let support = pivot(&mut world, anchor);
    let start = anchor + LENGTH * Vec3::new(START_ANGLE.sin(), -START_ANGLE.cos(), 0.0);
    let bob = world
        .add_body(BodyDesc::dynamic(Shape::sphere(RADIUS)).position(start))
        .unwrap();
    world
        .add_joint(JointDesc::new(JointKind::Point, support, bob, anchor))
        .unwrap();

    // Times at which the bob crosses the vertical moving in +x, linearly interpolated.
    let dt = world.config().dt;
    let mut crossings = Vec::new();
    let mut previous_x = start.x - anchor.x;
    let mut worst_length_error = 0.0f32;
    for step in 1..=(12.0 / dt) as usize {
        world.step();
        let offset = world.pose(bob).unwrap().position - anchor;
        worst_length_error = worst_length_error.max((offset.length() - LENGTH).abs() / LENGTH);
        if previous_x < 0.0 && offset.x >= 0.0 {
            let fraction = -previous_x / (offset.x - previous_x);
            crossings.push((step as f32 - 1.0 + fraction) * dt);
        }
        previous_x = offset.x;
    }
    let periods = crossings.len() - 1;
    let measured = (crossings[periods] - crossings[0]) / periods as f32;
    let small_angle = 2.0 * PI * (LENGTH / G).sqrt();
    let period_error = (measured - small_angle).abs() / small_angle;
    println!(
        "pendulum: {periods} periods, measured {measured:.5} s, 2π√(L/g) = {small_angle:.5} s, \
         error {:.3}%, worst length error {:.4}%",
        100.0 * period_error,
        100.0 * worst_length_error
    );
    assert!(periods >= 4, "only {periods} full periods in 12 s");
    assert!(
        worst_length_error < 1e-3,
        "length error {worst_length_error}"
    );
    assert!(
        period_error < 0.02,
        "period {measured} s vs {small_angle} s"
    );
}

/// A 1 m bar, hinged at its end about Z to a static pivot and starting horizontal along +x, so
/// gravity turns it clockwise (negative angle) until a limit stops it. With `bar_is_b` false
/// the bar is body A: the joint angle (B relative to A) is then minus the bar's.
fn hinged_bar(limits: (f32, f32), bar_is_b: bool) -> (World, BodyHandle, JointHandle) {
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let support = pivot(&mut world, Vec3::ZERO);
    let bar = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.05, 0.05)))
                .position(Vec3::new(0.5, 0.0, 0.0))
                .mass(5.0),
        )
        .unwrap();
    let (a, b) = if bar_is_b {
        (support, bar)
    } else {
        (bar, support)
    };
    let kind = JointKind::Hinge {
        axis: Vec3::Z,
        limits: Some(limits),
        motor: None,
    };
    let joint = world
        .add_joint(JointDesc::new(kind, a, b, Vec3::ZERO))
        .unwrap();
    (world, bar, joint)
}

#[test]
fn hinge_limit_holds_the_bar_under_gravity_in_both_conventions() {
    const TOLERANCE: f32 = 0.02;
    // The bar falls clockwise; it must stop at the lower limit when it is B, and where the
    // joint angle (minus the bar's) reaches the upper limit when it is A. Unequal limits
    // tell the two apart.
    for (bar_is_b, stop) in [(true, -0.3), (false, -0.6)] {
        let (mut world, bar, joint) = hinged_bar((-0.3, 0.6), bar_is_b);
        let mut lowest = 0.0f32;
        let mut worst_gap = 0.0f32;
        for _ in 0..180 {
            world.step();
            lowest = lowest.min(angle_about_z(&world, bar));
            worst_gap = worst_gap.max(gap(&world, joint));
        }
        let rest = angle_about_z(&world, bar);
        println!(
            "hinge limit (bar is {}): stop at {stop}, lowest {lowest:.4}, rest {rest:.4} rad, \
             worst gap {:.2} mm",
            if bar_is_b { "B" } else { "A" },
            worst_gap * 1e3
        );
        assert!(lowest > stop - TOLERANCE, "swung past the limit: {lowest}");
        assert!(
            (rest - stop).abs() < TOLERANCE,
            "rests at {rest}, not {stop}"
        );
        assert!(worst_gap < 0.01, "hinge point opened by {worst_gap} m");
        // The axis stays Z: the bar only turned in the XY plane.
        let axis = world.pose(bar).unwrap().rotation * Vec3::Z;
        assert!(axis.z > 0.999, "hinge axis tilted to {axis}");
    }
}

#[test]
fn a_hinge_between_limits_swings_freely() {
    // Wide limits: the bar swings down through vertical (−π/2) unhindered.
    let (mut world, bar, _) = hinged_bar((-PI, PI), true);
    let mut lowest = 0.0f32;
    for _ in 0..60 {
        world.step();
        lowest = lowest.min(angle_about_z(&world, bar));
    }
    assert!(lowest < -1.5, "the bar only reached {lowest} rad");
}

/// A 1 m bar along +x, joined at its end (the origin) to a static pivot by a cone-twist joint
/// whose twist axis is the bar's.
fn cone_twist_bar(
    gravity: Vec3,
    swing_limit: f32,
    twist_limits: (f32, f32),
) -> (World, BodyHandle) {
    let mut world = world(gravity);
    let support = pivot(&mut world, Vec3::ZERO);
    let bar = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.05, 0.05)))
                .position(Vec3::new(0.5, 0.0, 0.0)),
        )
        .unwrap();
    let kind = JointKind::ConeTwist {
        axis: Vec3::X,
        swing_limit,
        twist_limits,
    };
    world
        .add_joint(JointDesc::new(kind, support, bar, Vec3::ZERO))
        .unwrap();
    (world, bar)
}

#[test]
fn cone_twist_swing_limit_holds_under_gravity() {
    const SWING_LIMIT: f32 = 0.5;
    let (mut world, bar) = cone_twist_bar(Vec3::new(0.0, -G, 0.0), SWING_LIMIT, (-0.2, 0.2));
    let mut widest = 0.0f32;
    for _ in 0..180 {
        world.step();
        let axis = world.pose(bar).unwrap().rotation * Vec3::X;
        widest = widest.max(axis.dot(Vec3::X).clamp(-1.0, 1.0).acos());
    }
    let axis = world.pose(bar).unwrap().rotation * Vec3::X;
    let rest = axis.dot(Vec3::X).clamp(-1.0, 1.0).acos();
    println!("cone swing: limit {SWING_LIMIT}, widest {widest:.4}, rest {rest:.4} rad");
    assert!(widest < SWING_LIMIT + 0.02, "swung out to {widest} rad");
    assert!((rest - SWING_LIMIT).abs() < 0.02, "rests at {rest} rad");
    assert!(axis.y < 0.0, "the bar hangs down: {axis}");
}

#[test]
fn cone_twist_twist_limits_stop_a_spinning_bar() {
    // No gravity: the bar spins about its own axis, which passes through the joint.
    for (spin, stop) in [(3.0, 0.4), (-3.0, -0.2)] {
        let (mut world, bar) = cone_twist_bar(Vec3::ZERO, 0.5, (-0.2, 0.4));
        world
            .set_velocity(bar, Vec3::ZERO, Vec3::new(spin, 0.0, 0.0))
            .unwrap();
        let twist = |world: &World| {
            let y = world.pose(bar).unwrap().rotation * Vec3::Y;
            y.z.atan2(y.y)
        };
        let mut furthest = 0.0f32;
        for _ in 0..60 {
            world.step();
            let angle = twist(&world);
            if angle.abs() > furthest.abs() {
                furthest = angle;
            }
        }
        println!("cone twist: spin {spin} rad/s, stop at {stop}, furthest {furthest:.4} rad");
        assert!((furthest - stop).abs() < 0.02, "twisted to {furthest} rad");
        assert!((twist(&world) - stop).abs() < 0.02);
    }
}

#[test]
fn a_hinge_limit_stops_its_own_motor() {
    // The motor drives towards +∞ with torque to spare; the upper limit must still win.
    let mut world = world(Vec3::ZERO);
    let support = pivot(&mut world, Vec3::ZERO);
    let bar = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.5, 0.05, 0.05)))
                .position(Vec3::new(0.5, 0.0, 0.0)),
        )
        .unwrap();
    let kind = JointKind::Hinge {
        axis: Vec3::Z,
        limits: Some((-0.5, 0.5)),
        motor: Some(Motor {
            target_speed: 5.0,
            max_torque: 50.0,
        }),
    };
    world
        .add_joint(JointDesc::new(kind, support, bar, Vec3::ZERO))
        .unwrap();
    let mut highest = 0.0f32;
    for _ in 0..120 {
        world.step();
        highest = highest.max(angle_about_z(&world, bar));
    }
    let rest = angle_about_z(&world, bar);
    println!("motor against limit: highest {highest:.4}, rest {rest:.4} rad (limit 0.5)");
    assert!(highest < 0.52, "the motor pushed the bar to {highest} rad");
    assert!((rest - 0.5).abs() < 0.02, "rests at {rest} rad");
}

#[test]
fn chain_of_twenty_links_hangs_still() {
    const LINKS: usize = 20;
    const LINK_LENGTH: f32 = 0.25;
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let top = Vec3::new(0.0, 10.0, 0.0);
    let support = pivot(&mut world, top);
    // Capsules along Y, end to end below the support. Nothing in the engine damps a swinging
    // chain (no joint friction, no air), so it starts hanging straight: the test is that the
    // joints take the load without jitter, drift or creeping apart.
    let mut joints = Vec::new();
    let mut previous = support;
    let mut links = Vec::new();
    for i in 0..LINKS {
        let anchor = top - Vec3::new(0.0, i as f32 * LINK_LENGTH, 0.0);
        let center = anchor - Vec3::new(0.0, 0.5 * LINK_LENGTH, 0.0);
        let link = world
            .add_body(
                BodyDesc::dynamic(Shape::capsule(0.04, 0.5 * LINK_LENGTH - 0.04)).position(center),
            )
            .unwrap();
        let joint = JointDesc::new(JointKind::Point, previous, link, anchor);
        joints.push(world.add_joint(joint).unwrap());
        links.push(link);
        previous = link;
    }
    run(&mut world, 5.0);
    let energy = world.kinetic_energy();
    let worst_gap = joints
        .iter()
        .map(|&joint| gap(&world, joint))
        .fold(0.0, f32::max);
    let bottom = world.pose(links[LINKS - 1]).unwrap().position;
    let expected_bottom = top.y - (LINKS as f32 - 0.5) * LINK_LENGTH;
    println!(
        "chain: kinetic energy {energy:.2e} J, worst gap {:.3} mm, bottom link {:.2} mm low",
        worst_gap * 1e3,
        (expected_bottom - bottom.y) * 1e3
    );
    assert!(worst_gap < 0.01, "a joint opened by {worst_gap} m");
    assert!(energy < 1e-6, "the chain still moves: {energy} J");
    assert!(
        bottom.x.abs() < 1e-3 && bottom.z.abs() < 1e-3,
        "bottom link at {bottom}"
    );
    // The soft joints (60 Hz springs) stretch under the weight below them, a few mm at the top.
    let stretch = expected_bottom - bottom.y;
    assert!(
        (0.0..0.05).contains(&stretch),
        "the chain stretched by {stretch} m"
    );
}

#[test]
fn a_swinging_chain_gains_no_energy_and_stays_together() {
    // Released horizontal, the chain whips down; the soft joints must not add energy (the relax
    // sweep takes the position-correction velocity back out) nor open up. Potential energy is
    // measured from y = 0, so the total is large; what matters is that it never grows.
    const LINKS: usize = 20;
    const LINK_LENGTH: f32 = 0.25;
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let top = Vec3::new(0.0, 10.0, 0.0);
    let support = pivot(&mut world, top);
    let along_x = Quat::from_rotation_z(-0.5 * PI);
    let mut previous = support;
    let mut joints = Vec::new();
    let mut links = Vec::new();
    for i in 0..LINKS {
        let anchor = top + Vec3::new(i as f32 * LINK_LENGTH, 0.0, 0.0);
        let link = world
            .add_body(
                BodyDesc::dynamic(Shape::capsule(0.04, 0.5 * LINK_LENGTH - 0.04))
                    .position(anchor + Vec3::new(0.5 * LINK_LENGTH, 0.0, 0.0))
                    .rotation(along_x),
            )
            .unwrap();
        joints.push(
            world
                .add_joint(JointDesc::new(JointKind::Point, previous, link, anchor))
                .unwrap(),
        );
        links.push(link);
        previous = link;
    }
    // Each link has 1 kg.
    let energy = |world: &World| {
        let potential: f32 = links
            .iter()
            .map(|&link| G * world.pose(link).unwrap().position.y)
            .sum();
        world.kinetic_energy() + potential as f64
    };
    let start = energy(&world);
    let mut highest = start;
    let mut worst_gap = 0.0f32;
    for _ in 0..180 {
        world.step();
        highest = highest.max(energy(&world));
        for &joint in &joints {
            worst_gap = worst_gap.max(gap(&world, joint));
        }
    }
    let end = energy(&world);
    println!(
        "swinging chain: energy {start:.3} J at release, highest {highest:.3} J, {end:.3} J after \
         3 s; worst gap {:.2} mm",
        worst_gap * 1e3
    );
    assert!(
        highest < start + 0.1,
        "energy grew to {highest} J from {start} J"
    );
    // The whip at the free end pulls hardest (measured 9.6 mm at 8 sub-steps); 2 cm is still
    // far from a chain coming apart.
    assert!(worst_gap < 0.02, "a joint opened by {worst_gap} m");
}

/// A 1 kg sphere of radius 0.5 (I = 0.1 kg m²) on a hinge about Y through its centre, no
/// gravity. With `sphere_is_b` false the sphere is body A, so the motor (which drives B
/// relative to A) turns it the other way.
fn motorized_wheel(motor: Motor, sphere_is_b: bool) -> (World, BodyHandle) {
    let mut world = world(Vec3::ZERO);
    let support = pivot(&mut world, Vec3::new(0.0, -1.0, 0.0));
    let wheel = world
        .add_body(BodyDesc::dynamic(Shape::sphere(0.5)))
        .unwrap();
    let (a, b) = if sphere_is_b {
        (support, wheel)
    } else {
        (wheel, support)
    };
    let kind = JointKind::Hinge {
        axis: Vec3::Y,
        limits: None,
        motor: Some(motor),
    };
    world
        .add_joint(JointDesc::new(kind, a, b, Vec3::ZERO))
        .unwrap();
    (world, wheel)
}

#[test]
fn hinge_motor_reaches_its_target_speed() {
    let motor = Motor {
        target_speed: 3.0,
        max_torque: 100.0,
    };
    for (sphere_is_b, expected) in [(true, 3.0), (false, -3.0)] {
        let (mut world, wheel) = motorized_wheel(motor, sphere_is_b);
        run(&mut world, 0.5);
        let speed = world.angular_velocity(wheel).unwrap();
        println!("motor: ω = {speed}, expected {expected} about Y");
        assert!(
            (speed.y - expected).abs() < 0.02 * expected.abs(),
            "ω_y = {}",
            speed.y
        );
        assert!(speed.x.abs() < 1e-3 && speed.z.abs() < 1e-3, "ω = {speed}");
    }
}

#[test]
fn hinge_motor_is_limited_by_its_max_torque() {
    const MAX_TORQUE: f32 = 0.1;
    const INERTIA: f32 = 0.4 * 1.0 * 0.5 * 0.5;
    let motor = Motor {
        target_speed: 10.0,
        max_torque: MAX_TORQUE,
    };
    let (mut world, wheel) = motorized_wheel(motor, true);
    run(&mut world, 1.0);
    let speed = world.angular_velocity(wheel).unwrap().y;
    // Constant torque from rest: ω(t) = (τ / I) t.
    let expected = MAX_TORQUE / INERTIA * 1.0;
    println!("motor at max torque: ω = {speed:.5} rad/s after 1 s, τ t / I = {expected}");
    assert!((speed - expected).abs() < 0.02 * expected, "ω = {speed}");
}

#[test]
fn fixed_joint_holds_a_cantilever() {
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let wall = world
        .add_body(BodyDesc::fixed(Shape::cuboid(Vec3::splat(0.5))))
        .unwrap();
    let start = Vec3::new(1.0, 0.0, 0.0);
    let beam = world
        .add_body(BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(start))
        .unwrap();
    let joint = world
        .add_joint(JointDesc::new(
            JointKind::Fixed,
            wall,
            beam,
            Vec3::new(0.5, 0.0, 0.0),
        ))
        .unwrap();
    run(&mut world, 3.0);
    let pose = world.pose(beam).unwrap();
    let sag = (pose.position - start).length();
    let tilt = angle_between(Quat::IDENTITY, pose.rotation);
    println!(
        "cantilever: sag {:.3} mm, tilt {tilt:.2e} rad, gap {:.3} mm",
        sag * 1e3,
        gap(&world, joint) * 1e3
    );
    assert!(sag < 0.005, "sagged {sag} m");
    assert!(tilt < 0.005, "tilted {tilt} rad");
    assert!(world.kinetic_energy() < 1e-6);
}

#[test]
fn fixed_joint_keeps_two_spinning_bodies_together() {
    // Two boxes welded side by side, thrown spinning in free fall: their relative pose holds.
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let spin = Vec3::new(1.0, 2.0, 0.5);
    let velocity = Vec3::new(1.0, 3.0, 0.0);
    let body = |position: Vec3, half_extents: Vec3, mass: f32| {
        BodyDesc::dynamic(Shape::cuboid(half_extents))
            .position(position)
            .mass(mass)
            .linear_velocity(velocity + spin.cross(position))
            .angular_velocity(spin)
    };
    let a = world
        .add_body(body(Vec3::ZERO, Vec3::splat(0.5), 1.0))
        .unwrap();
    let b = world
        .add_body(body(
            Vec3::new(0.8, 0.0, 0.0),
            Vec3::new(0.3, 0.2, 0.1),
            0.3,
        ))
        .unwrap();
    let joint = world
        .add_joint(JointDesc::new(
            JointKind::Fixed,
            a,
            b,
            Vec3::new(0.5, 0.0, 0.0),
        ))
        .unwrap();
    let relative = |world: &World| {
        let (pose_a, pose_b) = (world.pose(a).unwrap(), world.pose(b).unwrap());
        (
            pose_a.inverse_transform_point(pose_b.position),
            pose_a.rotation.inverse() * pose_b.rotation,
        )
    };
    let (start_offset, start_rotation) = relative(&world);
    let mut worst_offset = 0.0f32;
    let mut worst_angle = 0.0f32;
    for _ in 0..120 {
        world.step();
        let (offset, rotation) = relative(&world);
        worst_offset = worst_offset.max((offset - start_offset).length());
        worst_angle = worst_angle.max(angle_between(start_rotation, rotation));
    }
    println!(
        "welded pair: worst offset {:.3} mm, worst angle {worst_angle:.2e} rad, gap {:.3} mm",
        worst_offset * 1e3,
        gap(&world, joint) * 1e3
    );
    assert!(worst_offset < 0.005, "the pair slid by {worst_offset} m");
    assert!(worst_angle < 0.01, "the pair twisted by {worst_angle} rad");
}

/// A 1 kg box hanging from a static pivot on a point joint that breaks at `break_impulse`.
fn hanging_box(break_impulse: f32) -> (World, BodyHandle, JointHandle) {
    let mut world = world(Vec3::new(0.0, -G, 0.0));
    let support = pivot(&mut world, Vec3::new(0.0, 5.0, 0.0));
    let weight = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.2))).position(Vec3::new(0.0, 4.5, 0.0)),
        )
        .unwrap();
    let joint = world
        .add_joint(
            JointDesc::new(JointKind::Point, support, weight, Vec3::new(0.0, 5.0, 0.0))
                .break_impulse(break_impulse),
        )
        .unwrap();
    (world, weight, joint)
}

#[test]
fn a_joint_breaks_above_its_threshold_and_not_below() {
    // The threshold is an impulse per sub-step: holding 1 kg against gravity takes m·g·h.
    let config = tumble::StepConfig::default();
    let holding = G * config.dt / config.substeps as f32;
    let (mut world, weight, joint) = hanging_box(1.25 * holding);
    run(&mut world, 2.0);
    assert!(
        !world.is_joint_broken(joint).unwrap(),
        "broke below the threshold"
    );
    let y = world.pose(weight).unwrap().position.y;
    assert!((y - 4.5).abs() < 0.01, "the box hangs at {y}");

    let (mut world, weight, joint) = hanging_box(0.8 * holding);
    run(&mut world, 0.1);
    assert!(
        world.is_joint_broken(joint).unwrap(),
        "held above the threshold"
    );
    run(&mut world, 0.5);
    let y = world.pose(weight).unwrap().position.y;
    assert!(y < 4.0, "a broken joint still holds the box at {y}");
}
