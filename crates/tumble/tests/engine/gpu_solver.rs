//! GPU solver parity: the soft step on random contact and joint sets, GPU against the CPU's
//! `solve`, over the same batches; and the same for the Jacobi solver (`jacobi::solve`).

use crate::gpu_common;

use gpu_common::{Random, context};
use tumble::collision::manifold::ContactPoint;
use tumble::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider};
use tumble::dynamics::joint::{Joint, JointKind, MAX_ANGULAR_ROWS, Motor};
use tumble::math::{Quat, Vec3, tangent_basis};
use tumble::pipeline::config::Softness;
use tumble::shape::Shape;
use tumble::stages::batching::{Batcher, Coloring, color_constraints, group_by_batch};
use tumble::stages::constraints::lanes;
use tumble::stages::constraints::{
    ContactConstraint, Drag, JointConstraint, RowInputs, build_constraints,
    build_joint_constraints, drag_constraint, world_inverse_inertia,
};
use tumble::stages::integrate::prepare_bodies;
use tumble::stages::narrowphase::PairContact;
use tumble::stages::pairs::pair_key;
use tumble::stages::solver::gpu::GpuSolver;
use tumble::stages::solver::jacobi::{self, JacobiScratch};
use tumble::stages::solver::jacobi_gpu::GpuJacobi;
use tumble::stages::solver::{Batched, SolverBody, SolverKind, SolverSettings, solve};

fn uniform(random: &mut Random, low: f32, high: f32) -> f32 {
    low + (high - low) * (random.next_u32() as f32 / u32::MAX as f32)
}

fn vector(random: &mut Random, extent: f32) -> Vec3 {
    Vec3::new(
        uniform(random, -extent, extent),
        uniform(random, -extent, extent),
        uniform(random, -extent, extent),
    )
}

/// A random world of `body_count` bodies (a fifth static) and `pair_count` manifolds between
/// random bodies, plus `hub` manifolds on body 0 (more than 64 force the overflow batch),
/// turned into contact rows as the step builds them, plus the `joints` joints of
/// [`random_joints`], colored and batched together as the step does.
#[derive(Clone)]
struct Problem {
    bodies: Vec<SolverBody>,
    contacts: Vec<ContactConstraint>,
    offsets: Vec<u32>,
    joints: Vec<JointConstraint>,
    joint_offsets: Vec<u32>,
    has_overflow: bool,
}

/// How many joints of a problem, and how many of them on body 0 (with the contact hub, they
/// land in the overflow batch).
#[derive(Clone, Copy, Default)]
struct Joints {
    count: usize,
    hub: usize,
}

fn problem(
    seed: u64,
    body_count: usize,
    pair_count: usize,
    hub: usize,
    joints: Joints,
    batcher: Batcher,
) -> Problem {
    let mut random = Random::new(seed);
    let h = 1.0 / 60.0;
    let mut poses = Vec::new();
    let mut velocities = Vec::new();
    let mut masses = Vec::new();
    let mut colliders = Vec::new();
    for body in 0..body_count {
        let axis = vector(&mut random, 1.0).normalize_or(Vec3::Y);
        let rotation = Quat::from_axis_angle(axis, uniform(&mut random, 0.0, 6.0));
        // Centres within a metre of each other: a contact's arms are about a body's size, as
        // between touching bodies (arms of 20 m would scale every rounding error by 20 through
        // I⁻¹(r × d), which no real contact does).
        poses.push(BodyPose::new(vector(&mut random, 0.5), rotation));
        velocities.push(BodyVelocity::new(
            vector(&mut random, 3.0),
            vector(&mut random, 2.0),
        ));
        // Body 0 is dynamic: the hub of the overflow test.
        let dynamic = body == 0 || random.below(5) != 0;
        masses.push(if dynamic {
            BodyMass {
                inverse_inertia: Vec3::new(
                    uniform(&mut random, 0.2, 3.0),
                    uniform(&mut random, 0.2, 3.0),
                    uniform(&mut random, 0.2, 3.0),
                ),
                inverse_mass: uniform(&mut random, 0.2, 2.0),
            }
        } else {
            BodyMass::default()
        });
        colliders.push(Collider {
            shape: Shape::sphere(0.5),
            friction: uniform(&mut random, 0.0, 1.0),
            restitution: if random.below(3) == 0 { 0.5 } else { 0.0 },
        });
    }
    let mut keys = Vec::new();
    let mut pair_contacts = Vec::new();
    let mut add = |random: &mut Random, a: u32, b: u32| {
        if a == b
            || (masses[a as usize].inverse_mass == 0.0 && masses[b as usize].inverse_mass == 0.0)
        {
            return;
        }
        let mut contact = PairContact::default();
        contact.manifold.normal = vector(random, 1.0).normalize_or(Vec3::Y);
        let middle = 0.5 * (poses[a as usize].position + poses[b as usize].position);
        // A pair with no point (count 0) is skipped by build_constraints, as in the step.
        for id in 0..random.below(5) {
            let separation = uniform(random, -0.05, 0.02);
            let point = ContactPoint::new(middle + vector(random, 0.25), separation, id);
            contact.manifold.push(point);
            let impulse = &mut contact.impulses[id as usize];
            impulse.normal = uniform(random, 0.0, 1.0);
            impulse.tangent = [uniform(random, -0.2, 0.2), uniform(random, -0.2, 0.2)];
        }
        keys.push(pair_key(a, b));
        pair_contacts.push(contact);
    };
    for _ in 0..pair_count {
        let a = random.below(body_count as u32);
        let b = random.below(body_count as u32);
        add(&mut random, a, b);
    }
    for other in 1..=hub as u32 {
        add(&mut random, 0, other);
    }
    let mut inverse_inertia = Vec::new();
    world_inverse_inertia(&poses, &masses, &mut inverse_inertia);
    let mut joint_constraints = Vec::new();
    if joints.count > 0 {
        let world_joints = random_joints(&mut random, &poses, &masses, joints);
        build_joint_constraints(
            &world_joints,
            &poses,
            &masses,
            &inverse_inertia,
            Softness::new(60.0, 2.0, h),
            &mut joint_constraints,
        );
        // A drag on the last dynamic body, with a pull small enough to clamp.
        if let Some(body) = (0..body_count)
            .rev()
            .find(|&b| masses[b].inverse_mass > 0.0)
        {
            let drag = Drag {
                body: body as u32,
                local_anchor: Vec3::new(0.1, 0.2, -0.1),
                target: poses[body].position + Vec3::new(0.5, 0.3, 0.0),
                max_force: 20.0,
                impulse: Vec3::new(0.05, 0.1, 0.0),
            };
            let softness = Softness::new(5.0, 0.7, h);
            joint_constraints.push(drag_constraint(&drag, &poses, &masses, softness, h));
        }
    }
    let inputs = RowInputs {
        poses: &poses,
        velocities: &velocities,
        masses: &masses,
        colliders: &colliders,
        inverse_inertia: &inverse_inertia,
        softness: contact_softness(),
        static_softness: static_softness(),
    };
    let mut constraints = Vec::new();
    build_constraints(
        &keys,
        &pair_contacts,
        &tumble::stages::narrowphase::ChildCache::default(),
        &inputs,
        &mut constraints,
    );
    // As the step colors them: joints first (kept in order), then contacts.
    let mut coloring = Coloring::default();
    color_constraints(
        joint_constraints
            .iter()
            .map(|j| (j.body_a, j.body_b))
            .chain(constraints.iter().map(|c| (c.body_a, c.body_b))),
        body_count,
        joint_constraints.len(),
        batcher,
        &mut coloring,
    );
    let (joint_colors, contact_colors) = coloring.colors.split_at(joint_constraints.len());
    let (mut contacts, mut offsets) = (Vec::new(), Vec::new());
    group_by_batch(
        &constraints,
        contact_colors,
        &coloring,
        &mut contacts,
        &mut offsets,
    );
    let (mut joints, mut joint_offsets) = (Vec::new(), Vec::new());
    group_by_batch(
        &joint_constraints,
        joint_colors,
        &coloring,
        &mut joints,
        &mut joint_offsets,
    );
    let mut bodies = Vec::new();
    prepare_bodies(&velocities, &masses, &mut bodies);
    Problem {
        bodies,
        contacts,
        offsets,
        joints,
        joint_offsets,
        has_overflow: coloring.has_overflow,
    }
}

/// `joints.count` joints of every kind: a chain of point joints through the first bodies, then
/// hinges with limits and a motor, cone-twists, fixed joints and point joints between random
/// bodies, the first `joints.hub` of them on body 0. Each is created at poses turned from
/// the problem's by up to about 0.6 rad, so that the solver meets angle errors and limits
/// pushed past, with random warm-start impulses.
fn random_joints(
    random: &mut Random,
    poses: &[BodyPose],
    masses: &[BodyMass],
    joints: Joints,
) -> Vec<Option<Joint>> {
    let body_count = poses.len() as u32;
    let chain = (joints.count / 4).min(body_count.saturating_sub(1) as usize);
    let mut out = Vec::new();
    for index in 0..joints.count {
        let (a, b) = if index < joints.hub {
            (0, 1 + random.below(body_count - 1))
        } else if index < joints.hub + chain {
            let link = (index - joints.hub) as u32;
            (link, link + 1)
        } else {
            (random.below(body_count), random.below(body_count))
        };
        if a == b
            || (masses[a as usize].inverse_mass == 0.0 && masses[b as usize].inverse_mass == 0.0)
        {
            continue;
        }
        let axis = vector(random, 1.0).normalize_or(Vec3::X);
        let kind = match index % 5 {
            0 => JointKind::Hinge {
                axis,
                limits: Some((uniform(random, -0.6, 0.0), uniform(random, 0.0, 0.6))),
                motor: Some(Motor {
                    target_speed: uniform(random, -2.0, 2.0),
                    max_torque: uniform(random, 0.5, 20.0),
                }),
            },
            1 => JointKind::Hinge {
                axis,
                limits: Some((-0.3, 0.3)),
                motor: None,
            },
            2 => JointKind::ConeTwist {
                axis,
                swing_limit: uniform(random, 0.2, 1.0),
                twist_limits: (uniform(random, -0.5, 0.0), uniform(random, 0.0, 0.5)),
            },
            3 => JointKind::Fixed,
            _ => JointKind::Point,
        };
        // The poses at creation: each body turned from its current pose.
        let turned = |random: &mut Random, body: u32| {
            let turn = vector(random, 0.35);
            Quat::from_scaled_axis(turn) * poses[body as usize].rotation
        };
        let (rotation_a, rotation_b) = (turned(random, a), turned(random, b));
        let (position_a, position_b) = (poses[a as usize].position, poses[b as usize].position);
        let anchor = 0.5 * (position_a + position_b) + vector(random, 0.2);
        let joint_axis = match kind {
            JointKind::Hinge { axis, .. } | JointKind::ConeTwist { axis, .. } => axis,
            JointKind::Point | JointKind::Fixed => Vec3::X,
        };
        // As Joint::new does, from these poses.
        let (reference, _) = tangent_basis(joint_axis);
        let (inverse_a, inverse_b) = (rotation_a.inverse(), rotation_b.inverse());
        let mut angular_impulse = [0.0; MAX_ANGULAR_ROWS];
        for impulse in &mut angular_impulse {
            *impulse = uniform(random, 0.0, 0.05);
        }
        out.push(Some(Joint {
            kind,
            body_a: a,
            body_b: b,
            local_anchor_a: inverse_a * (anchor - position_a),
            local_anchor_b: inverse_b * (anchor - position_b),
            local_axis_a: inverse_a * joint_axis,
            local_axis_b: inverse_b * joint_axis,
            local_reference_a: inverse_a * reference,
            local_reference_b: inverse_b * reference,
            relative_rotation: inverse_a * rotation_b,
            break_impulse: None,
            broken: false,
            point_impulse: vector(random, 0.1),
            angular_impulse,
        }));
    }
    out
}

fn close(gpu: f32, cpu: f32, tolerance: f32) -> bool {
    (gpu - cpu).abs() <= tolerance * cpu.abs().max(1.0)
}

fn close3(gpu: Vec3, cpu: Vec3, tolerance: f32) -> bool {
    (0..3).all(|i| close(gpu[i], cpu[i], tolerance))
}

/// `problem` solved on the CPU from `bodies` by the `kind` solver.
fn cpu_solve(
    problem: &Problem,
    mut bodies: Vec<SolverBody>,
    settings: SolverSettings,
    kind: SolverKind,
) -> Solved {
    let mut contacts = problem.contacts.clone();
    let mut joints = problem.joints.clone();
    let mut batched = Batched {
        contacts: &mut contacts,
        contact_offsets: &problem.offsets,
        joints: &mut joints,
        joint_offsets: &problem.joint_offsets,
        has_overflow: problem.has_overflow,
    };
    match kind {
        SolverKind::Pgs => solve(&mut bodies, &mut batched, settings),
        SolverKind::Jacobi => jacobi::solve(
            &mut bodies,
            &mut batched,
            settings,
            &mut JacobiScratch::default(),
        ),
    }
    Solved {
        bodies,
        contacts,
        joints,
    }
}

/// What a solve leaves: the bodies and the constraints with their impulses.
struct Solved {
    bodies: Vec<SolverBody>,
    contacts: Vec<ContactConstraint>,
    joints: Vec<JointConstraint>,
}

impl Solved {
    /// Every impulse of the solve, contacts then joints, in one order for both executors.
    fn impulses(&self) -> Vec<f32> {
        let mut out = Vec::new();
        for c in &self.contacts {
            for p in &c.points {
                out.extend([p.normal.impulse, p.tangent[0].impulse, p.tangent[1].impulse]);
            }
        }
        for j in &self.joints {
            out.extend(j.point_impulse.to_array());
            out.extend(j.angular_impulse);
        }
        out
    }

    /// Every body's velocities, linear then angular.
    fn velocities(&self) -> Vec<f32> {
        self.bodies
            .iter()
            .flat_map(|b| {
                b.linear_velocity
                    .to_array()
                    .into_iter()
                    .chain(b.angular_velocity.to_array())
            })
            .collect()
    }
}

/// How far the CPU's own impulses and final body velocities move (in `close`'s measure) when
/// every input velocity, and every joint's step-start rotations, move by one ulp: the
/// problem's conditioning, the yardstick for another executor's rounding. The worst of four
/// patterns of nudges (all up, all down, and up or down by index parity either way), since
/// one pattern can happen to cancel along a chain of constraints.
///
/// Why the velocities too: under Jacobi a body's velocity is the sum of its constraints'
/// relaxed changes, and it responds more than any one impulse (on 12 bodies with 17 joints:
/// 1.1e-5 against 4.3e-6; the GPU's bodies differed by 4.2e-5, its impulses passed).
///
/// Why rotations: a joint rebuilds its angles from whole rotations at every sweep, and a
/// limit row turns its angle error e into the bias e / h (speculative) or `bias_rate` · e, so
/// a rounding of 1e-7 rad in the angle moves its impulse by about 6e-6 · mass at 60 Hz — far
/// more than one ulp of the velocities does. Contacts only add small displacements to a
/// fixed separation, so this adds nothing for them.
fn cpu_sensitivity(
    problem: &Problem,
    settings: SolverSettings,
    kind: SolverKind,
    cpu: &Solved,
) -> f32 {
    let cpu_velocities = cpu.velocities();
    let cpu = cpu.impulses();
    let mut worst = 0.0f32;
    for pattern in 0..4 {
        let up = |index: usize| match pattern {
            0 => true,
            1 => false,
            2 => index.is_multiple_of(2),
            _ => !index.is_multiple_of(2),
        };
        let nudge = |up: bool| move |x: f32| if up { x.next_up() } else { x.next_down() };
        let nudged: Vec<SolverBody> = problem
            .bodies
            .iter()
            .enumerate()
            .map(|(index, body)| SolverBody {
                linear_velocity: body.linear_velocity.map(nudge(up(index))),
                angular_velocity: body.angular_velocity.map(nudge(up(index))),
                ..*body
            })
            .collect();
        let joints = problem
            .joints
            .iter()
            .enumerate()
            .map(|(index, joint)| {
                let rotate = |q: Quat| Quat::from_array(q.to_array().map(nudge(up(index))));
                JointConstraint {
                    rotation_a: rotate(joint.rotation_a),
                    rotation_b: rotate(joint.rotation_b),
                    ..*joint
                }
            })
            .collect();
        let nudged_problem = Problem {
            joints,
            ..problem.clone()
        };
        let moved = cpu_solve(&nudged_problem, nudged, settings, kind);
        let pairs = moved.impulses().into_iter().zip(cpu.iter().copied());
        let velocities = moved
            .velocities()
            .into_iter()
            .zip(cpu_velocities.iter().copied());
        for (x, y) in pairs.chain(velocities) {
            worst = worst.max((x - y).abs() / y.abs().max(1.0));
        }
    }
    worst
}

/// Solves `problem` on both executors and compares every impulse and body within `tolerance`
/// (relative above 1, absolute below), or within eight times the CPU's own response to one ulp
/// of input noise where the problem is worse conditioned than that: the GPU rounds
/// differently (fused multiply-adds), and Gauss-Seidel carries each difference through every
/// constraint of a body.
fn check(problem: &Problem, settings: SolverSettings, tolerance: f32, what: &str) {
    check_kind(SolverKind::Pgs, problem, settings, tolerance, what);
}

/// [`check`] for the `kind` solver.
fn check_kind(
    kind: SolverKind,
    problem: &Problem,
    settings: SolverSettings,
    tolerance: f32,
    what: &str,
) {
    let context = context();
    let cpu = cpu_solve(problem, problem.bodies.clone(), settings, kind);
    let sensitivity = cpu_sensitivity(problem, settings, kind, &cpu);
    // Eight: measured GPU/CPU differences on the 6000-pair set were 1.4 and 6.7 times the
    // sensitivity with the two batchers' layouts of the same problem (lavapipe), and exactly
    // the same with the small-batch workgroup walk disabled (every batch its own dispatch):
    // rounding, not the walk.
    let tolerance = tolerance.max(8.0 * sensitivity);
    let (mut gpu_bodies, mut gpu_contacts) = (problem.bodies.clone(), problem.contacts.clone());
    let mut gpu_joints = problem.joints.clone();
    let mut batched = Batched {
        contacts: &mut gpu_contacts,
        contact_offsets: &problem.offsets,
        joints: &mut gpu_joints,
        joint_offsets: &problem.joint_offsets,
        has_overflow: problem.has_overflow,
    };
    match kind {
        SolverKind::Pgs => {
            GpuSolver::new(&context)
                .expect("solver")
                .run(&mut gpu_bodies, &mut batched, settings)
        }
        SolverKind::Jacobi => {
            GpuJacobi::new(&context)
                .expect("solver")
                .run(&mut gpu_bodies, &mut batched, settings)
        }
    }
    .expect("GPU solve");
    let (cpu_bodies, cpu_contacts) = (&cpu.bodies, &cpu.contacts);
    for (index, (gpu, cpu)) in gpu_contacts.iter().zip(cpu_contacts).enumerate() {
        for (point, (g, c)) in gpu.points.iter().zip(&cpu.points).enumerate() {
            let pairs = [
                (g.normal.impulse, c.normal.impulse),
                (g.tangent[0].impulse, c.tangent[0].impulse),
                (g.tangent[1].impulse, c.tangent[1].impulse),
                (g.max_normal_impulse, c.max_normal_impulse),
            ];
            for (g, c) in pairs {
                assert!(
                    close(g, c, tolerance),
                    "{what}: constraint {index} point {point}: GPU {g}, CPU {c} \
                     (tolerance {tolerance}, CPU sensitivity {sensitivity})"
                );
            }
            // The device computes each sweep's separations and keeps the rows' own (the CPU
            // keeps the last sweep's).
            let built = problem.contacts[index].points[point].separation;
            assert_eq!(
                g.separation.to_bits(),
                built.to_bits(),
                "{what}: separation"
            );
        }
    }
    for (index, (g, c)) in gpu_joints.iter().zip(&cpu.joints).enumerate() {
        let pairs = c
            .point_impulse
            .to_array()
            .into_iter()
            .chain(c.angular_impulse)
            .zip(
                g.point_impulse
                    .to_array()
                    .into_iter()
                    .chain(g.angular_impulse),
            );
        for (slot, (c, g)) in pairs.enumerate() {
            assert!(
                close(g, c, tolerance),
                "{what}: joint {index} (kind {}) impulse {slot}: GPU {g}, CPU {c} \
                 (tolerance {tolerance}, CPU sensitivity {sensitivity})",
                cpu.joints[index].frame.kind
            );
        }
    }
    for (index, (g, c)) in gpu_bodies.iter().zip(cpu_bodies).enumerate() {
        let ok = close3(g.linear_velocity, c.linear_velocity, tolerance)
            && close3(g.angular_velocity, c.angular_velocity, tolerance)
            && close3(g.delta_position, c.delta_position, tolerance)
            && {
                let (g, c) = (g.delta_rotation.to_array(), c.delta_rotation.to_array());
                (0..4).all(|i| close(g[i], c[i], tolerance))
            };
        assert!(ok, "{what}: body {index}: GPU {g:?}\nCPU {c:?}");
    }
}

/// The contact rows' softness of every problem, between dynamic bodies and against a static
/// one: what the solver settings must say too (the device's sweeps take it from them).
fn contact_softness() -> Softness {
    Softness::new(30.0, 3.0, 1.0 / 60.0)
}

fn static_softness() -> Softness {
    Softness::new(60.0, 3.0, 1.0 / 60.0)
}

fn one_iteration() -> SolverSettings {
    SolverSettings {
        dt: 1.0 / 60.0,
        substeps: 1,
        iterations: 1,
        gravity: Vec3::new(0.0, -9.81, 0.0),
        max_push_velocity: 3.0,
        restitution_threshold: 1.0,
        contact_softness: contact_softness(),
        static_softness: static_softness(),
    }
}

// The random sets have about two manifolds per body, as in a pile. The two executors round
// differently (WGSL fuses multiply-adds), and the Gauss-Seidel sweeps carry each difference
// through every constraint of a body: with 13 manifolds of 4 points per body (3000 bodies,
// 20 000 pairs) one iteration differs by up to 1.4e-5, the same as the CPU's own change when
// the input velocities are nudged by one ulp (2.1e-5), so that density is no parity test.

#[test]
fn one_iteration_matches_cpu_on_random_contacts() {
    for batcher in Batcher::ALL {
        for (seed, &(bodies, pairs)) in [(1, 0), (2, 1), (10, 30), (101, 257), (3001, 6000)]
            .iter()
            .enumerate()
        {
            let problem = problem(seed as u64, bodies, pairs, 0, Joints::default(), batcher);
            check(
                &problem,
                one_iteration(),
                1e-5,
                &format!("{bodies} bodies, {pairs} pairs, {batcher}"),
            );
        }
    }
}

#[test]
fn overflow_batch_matches_cpu() {
    let problem = problem(7, 200, 300, 150, Joints::default(), Batcher::Colors);
    assert!(problem.has_overflow, "the hub overflows the 64 colors");
    check(&problem, one_iteration(), 1e-5, "hub of 150 contacts");
}

/// Sub-steps and several iterations: the joint rows are rebuilt from rotations that moved.
fn substeps() -> SolverSettings {
    SolverSettings {
        substeps: 4,
        iterations: 2,
        ..one_iteration()
    }
}

#[test]
fn joints_and_contacts_match_cpu() {
    for batcher in Batcher::ALL {
        for (seed, &(bodies, pairs, joints)) in
            [(1, 0, 1), (2, 1, 2), (12, 10, 17), (101, 120, 257)]
                .iter()
                .enumerate()
        {
            let problem = problem(
                100 + seed as u64,
                bodies,
                pairs,
                0,
                Joints {
                    count: joints,
                    hub: 0,
                },
                batcher,
            );
            assert!(!problem.joints.is_empty(), "{bodies} bodies: some joints");
            for (settings, name) in [(one_iteration(), "1 iteration"), (substeps(), "4 substeps")] {
                check(
                    &problem,
                    settings,
                    1e-5,
                    &format!("{bodies} bodies, {pairs} pairs, {joints} joints, {batcher}, {name}"),
                );
            }
        }
    }
}

#[test]
fn joints_in_the_overflow_batch_match_cpu() {
    let problem = problem(
        8,
        200,
        300,
        150,
        // Joints take colors before contacts: past 64 on body 0, they overflow too.
        Joints {
            count: 120,
            hub: 80,
        },
        Batcher::Colors,
    );
    assert!(problem.has_overflow, "the hub overflows the 64 colors");
    let last = problem.joint_offsets.len() - 2;
    assert!(
        problem.joint_offsets[last + 1] > problem.joint_offsets[last],
        "joints in the overflow batch"
    );
    check(
        &problem,
        substeps(),
        1e-5,
        "hub of 150 contacts and 80 joints",
    );
}

// Jacobi: every constraint of a sweep starts from the same velocities, so a rounding
// difference reaches only the constraints next to a body in a sweep, not a whole chain.

#[test]
fn jacobi_matches_cpu_on_random_contacts() {
    for (seed, &(bodies, pairs)) in [(0, 0), (1, 0), (2, 1), (10, 30), (101, 257), (3001, 6000)]
        .iter()
        .enumerate()
    {
        let problem = problem(
            200 + seed as u64,
            bodies,
            pairs,
            0,
            Joints::default(),
            Batcher::Colors,
        );
        for (settings, name) in [(one_iteration(), "1 iteration"), (substeps(), "4 substeps")] {
            check_kind(
                SolverKind::Jacobi,
                &problem,
                settings,
                1e-5,
                &format!("jacobi: {bodies} bodies, {pairs} pairs, {name}"),
            );
        }
    }
}

/// The hub (150 contacts on body 0, relaxed by 1/150) and joints: Jacobi ignores the overflow
/// batch and the coloring.
#[test]
fn jacobi_with_joints_and_a_hub_matches_cpu() {
    for (seed, &(bodies, pairs, hub, joints, joint_hub)) in [
        (1, 0, 0, 1, 0),
        (12, 10, 0, 17, 0),
        (200, 300, 150, 120, 80),
    ]
    .iter()
    .enumerate()
    {
        let problem = problem(
            300 + seed as u64,
            bodies,
            pairs,
            hub,
            Joints {
                count: joints,
                hub: joint_hub,
            },
            Batcher::Colors,
        );
        check_kind(
            SolverKind::Jacobi,
            &problem,
            substeps(),
            1e-5,
            &format!("jacobi: {bodies} bodies, {pairs} pairs, hub {hub}, {joints} joints"),
        );
    }
}

/// Same input, same device: bitwise the same output (no atomics in the sums).
#[test]
fn jacobi_on_the_gpu_is_deterministic() {
    let context = context();
    let problem = problem(
        9,
        300,
        700,
        40,
        Joints { count: 30, hub: 5 },
        Batcher::Colors,
    );
    let run = |solver: &mut GpuJacobi| {
        let (mut bodies, mut contacts) = (problem.bodies.clone(), problem.contacts.clone());
        let mut joints = problem.joints.clone();
        solver
            .run(
                &mut bodies,
                &mut Batched {
                    contacts: &mut contacts,
                    contact_offsets: &problem.offsets,
                    joints: &mut joints,
                    joint_offsets: &problem.joint_offsets,
                    has_overflow: problem.has_overflow,
                },
                substeps(),
            )
            .expect("GPU solve");
        let mut bytes = bytemuck::cast_slice::<_, u8>(&bodies).to_vec();
        bytes.extend_from_slice(bytemuck::cast_slice(&contacts));
        bytes.extend_from_slice(bytemuck::cast_slice(&joints));
        bytes
    };
    let mut solver = GpuJacobi::new(&context).expect("solver");
    let first = run(&mut solver);
    assert_eq!(first, run(&mut solver), "same solver, second run");
    assert_eq!(first, run(&mut GpuJacobi::new(&context).expect("solver")));
}

/// A device layout's batch sizes (every color a batch, the overflow batch last, the end of the
/// used batches after them) solve as the host's offsets do, bit for bit, whichever plan the
/// expected sizes choose: every batch walked by one workgroup, every batch a dispatch too
/// small for it (threads taking several constraints), or the plan of the actual sizes.
#[test]
fn device_layout_sizes_solve_as_host_offsets() {
    use tumble::gpu::buffer::GpuVec;
    use tumble::stages::batching::MAX_COLORS;
    use tumble::stages::batching::layout::{LAYOUT_BATCHES, USED_END};
    use tumble::stages::solver::gpu::{BatchSizes, DeviceBatched, SMALL_BATCH};

    let context = context();
    let settings = substeps();
    for (seed, bodies, pairs, hub) in [(3, 10, 30, 0), (4, 3000, 6000, 0), (7, 200, 300, 150)] {
        let problem = problem(seed, bodies, pairs, hub, Joints::default(), Batcher::Colors);
        assert_eq!(problem.has_overflow, hub > 0);
        let (mut host_bodies, mut host_contacts) =
            (problem.bodies.clone(), problem.contacts.clone());
        let mut batched = Batched {
            contacts: &mut host_contacts,
            contact_offsets: &problem.offsets,
            joints: &mut Vec::new(),
            joint_offsets: &vec![0; problem.offsets.len()],
            has_overflow: problem.has_overflow,
        };
        let mut solver = GpuSolver::new(&context).unwrap();
        solver
            .run(&mut host_bodies, &mut batched, settings)
            .unwrap();

        // The host's batches at the device layout's places: batch k is color k.
        let host_batches = problem.offsets.len() - 1;
        let used = host_batches - problem.has_overflow as usize;
        let batch_range = |batch: usize| {
            if batch < used {
                (problem.offsets[batch], problem.offsets[batch + 1])
            } else if batch == MAX_COLORS && problem.has_overflow {
                (
                    problem.offsets[host_batches - 1],
                    problem.offsets[host_batches],
                )
            } else {
                let end = problem.offsets[used];
                (end, end)
            }
        };
        let mut offsets: Vec<u32> = (0..LAYOUT_BATCHES).map(|b| batch_range(b).0).collect();
        offsets.push(*problem.offsets.last().unwrap());
        offsets.push(if problem.has_overflow {
            LAYOUT_BATCHES as u32
        } else {
            used as u32
        });
        assert_eq!(offsets.len(), USED_END + 1);
        let sizes: Vec<u32> = (0..LAYOUT_BATCHES)
            .map(|b| offsets[b + 1] - offsets[b])
            .collect();
        // The 6000 pairs have batches larger than the dispatches of `all_small_dispatches`.
        let largest = sizes.iter().copied().max().unwrap();
        assert!(
            pairs < 6000 || largest > 2 * SMALL_BATCH,
            "{pairs} pairs: {largest}"
        );
        let contact_offsets = GpuVec::from_slice(&context, "test offsets", &offsets).unwrap();
        let zeros = vec![0u32; USED_END + 1];
        let joint_offsets = GpuVec::from_slice(&context, "test joint offsets", &zeros).unwrap();
        let joints = GpuVec::<JointConstraint>::with_capacity(&context, "none", 0).unwrap();
        // As the host's run decides it.
        let restitution = problem.contacts.iter().any(|c| c.restitution > 0.0);
        let all_walked = vec![0; LAYOUT_BATCHES];
        let all_small_dispatches = vec![SMALL_BATCH; LAYOUT_BATCHES];
        for expected in [&all_walked, &all_small_dispatches, &sizes] {
            let mut bodies_on_device =
                GpuVec::from_slice(&context, "test bodies", &problem.bodies).unwrap();
            let mut words = Vec::new();
            lanes::lay_out(&problem.contacts, &mut words);
            let mut contacts = GpuVec::from_slice(&context, "test contacts", &words).unwrap();
            let device = DeviceBatched {
                contacts: &contacts,
                contact_offsets: &contact_offsets,
                joints: &joints,
                joint_offsets: &joint_offsets,
                sizes: BatchSizes::Device { expected },
                adjacency: None,
            };
            context.submit_pass("device sizes", |pass| {
                solver.encode(pass, &bodies_on_device, &device, settings, restitution)
            });
            let what = format!("{pairs} pairs, hub {hub}, expected {:?}", &expected[..12]);
            let device_bodies = bodies_on_device.download(&context).unwrap();
            assert!(device_bodies == host_bodies, "{what}: bodies");
            let mut device_contacts = vec![ContactConstraint::default(); problem.contacts.len()];
            lanes::read_back(&contacts.download(&context).unwrap(), &mut device_contacts);
            let bits = |c: &[ContactConstraint]| bytemuck::cast_slice::<_, u32>(c).to_vec();
            assert!(bits(&device_contacts) == bits(&host_contacts), "{what}");
        }
    }
}
