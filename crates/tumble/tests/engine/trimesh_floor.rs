//! A floor made of many triangles holds bodies as a plane does: no sinking, no bumps on the
//! seams between triangles (internal edges), the same friction.
use crate::common;
use common::*;
use tumble::math::{Quat, Vec3};
use tumble::shape::TriMesh;
use tumble::{BodyDesc, BodyHandle, Shape, StepConfig, World};

/// A flat floor at y = 0 over [-half, half]² of `cells`² squares, each split into two
/// triangles facing +y, alternating the diagonal so seams run every way.
fn floor(half: f32, cells: u32) -> Shape {
    let mut vertices = Vec::new();
    let step = 2.0 * half / cells as f32;
    for row in 0..=cells {
        for column in 0..=cells {
            vertices.push(Vec3::new(
                -half + column as f32 * step,
                0.0,
                -half + row as f32 * step,
            ));
        }
    }
    let mut triangles = Vec::new();
    let index = |row: u32, column: u32| row * (cells + 1) + column;
    for row in 0..cells {
        for column in 0..cells {
            let (a, b, c, d) = (
                index(row, column),
                index(row, column + 1),
                index(row + 1, column),
                index(row + 1, column + 1),
            );
            // Counter-clockwise seen from +y: (x, z) → (x, z + 1) → (x + 1, z) faces up.
            if (row + column) % 2 == 0 {
                triangles.push([a, c, b]);
                triangles.push([b, c, d]);
            } else {
                triangles.push([a, c, d]);
                triangles.push([a, d, b]);
            }
        }
    }
    Shape::trimesh(TriMesh::new(vertices, triangles).unwrap())
}

fn world_on(ground: Shape, friction: f32) -> World {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(ground).friction(friction))
        .unwrap();
    world
}

fn drop_on(world: &mut World, shape: Shape, position: Vec3, rotation: Quat) -> BodyHandle {
    world
        .add_body(
            BodyDesc::dynamic(shape)
                .position(position)
                .rotation(rotation),
        )
        .unwrap()
}

#[test]
fn the_floor_faces_up() {
    let Shape::TriMesh(mesh) = floor(2.0, 4) else {
        unreachable!()
    };
    for index in 0..mesh.triangles().len() as u32 {
        assert!((mesh.triangle(index).normal - Vec3::Y).length() < 1e-6);
        // Only the floor's border is active.
        assert_ne!(mesh.triangle(index).active_edges, 0b111);
    }
}

#[test]
fn box_rests_on_a_tessellated_floor_as_on_a_plane() {
    // Off the grid lines and turned, so the box's corners sit on different triangles.
    let start = Vec3::new(0.13, 0.5, -0.27);
    let rotation = Quat::from_rotation_y(0.4);
    let mut world = world_on(floor(5.0, 10), 0.5);
    let body = drop_on(&mut world, Shape::cuboid(Vec3::splat(0.5)), start, rotation);
    for step in 0..600 {
        world.step();
        let y = world.pose(body).unwrap().position.y;
        assert!((y - 0.5).abs() < 0.006, "step {step}: y = {y}");
    }
    let pose = world.pose(body).unwrap();
    assert!(
        (pose.position - start).length() < 1e-3,
        "drifted to {:?}",
        pose.position
    );
    assert!(angle_between(pose.rotation, rotation) < 1e-3);
    assert!(world.linear_velocity(body).unwrap().length() < 1e-3);
    assert!(world.angular_velocity(body).unwrap().length() < 1e-3);
}

/// `shape` (friction 0.3) set down with its centre `height` above the ground and pushed at
/// (4, 0, 0.5) m/s: its position, velocity and spin at each of 120 steps.
fn slide(ground: Shape, shape: Shape, height: f32) -> Vec<(Vec3, Vec3, Vec3)> {
    let mut world = world_on(ground, 0.3);
    let body = world
        .add_body(
            BodyDesc::dynamic(shape)
                .friction(0.3)
                .position(Vec3::new(-6.0, height, 0.1))
                .linear_velocity(Vec3::new(4.0, 0.0, 0.5)),
        )
        .unwrap();
    let mut trace = Vec::new();
    for _ in 0..120 {
        world.step();
        trace.push((
            world.pose(body).unwrap().position,
            world.linear_velocity(body).unwrap(),
            world.angular_velocity(body).unwrap(),
        ));
    }
    trace
}

/// The same slide on a plane and on the tessellated floor: the same deceleration, no hop, no
/// spin beyond the plane's, the same stop. The plane's slide is checked against the closed form first.
fn slides_as_on_a_plane(shape: Shape, height: f32) {
    let on_plane = slide(Shape::plane(Vec3::Y, 0.0), shape.clone(), height);
    // 0.5 m cells: the body crosses about a dozen seams in x and several diagonals.
    let on_mesh = slide(floor(10.0, 40), shape, height);
    // Closed form on the plane: v = v0 - mu g t until it stops (4.03 m/s / 2.94 m/s²: 1.37 s).
    let speed_0 = Vec3::new(4.0, 0.0, 0.5).length();
    let t = 0.5;
    let expected = speed_0 - 0.3 * G * t;
    let speed = on_plane[29].1.length();
    assert!(
        (speed - expected).abs() < 0.05,
        "plane: {speed} m/s at 0.5 s, expected {expected}"
    );
    for (step, (plane, mesh)) in on_plane.iter().zip(&on_mesh).enumerate() {
        let (mesh_position, mesh_velocity, mesh_spin) = *mesh;
        assert!(
            mesh_velocity.y.abs() < 0.02,
            "step {step}: vertical velocity {}",
            mesh_velocity.y
        );
        // The spin the plane gives (none for a box; the barrel's square cap yaws up to 0.05
        // rad/s on a plane too) plus at most 0.02 rad/s.
        assert!(
            (mesh_spin - plane.2).length() < 0.02,
            "step {step}: angular velocity {mesh_spin:?}, on the plane {:?}",
            plane.2
        );
        assert!(
            (mesh_position.y - height).abs() < 0.006,
            "step {step}: y = {}",
            mesh_position.y
        );
        let speed_gap = (mesh_velocity - plane.1).length();
        assert!(
            speed_gap < 0.02,
            "step {step}: velocity {mesh_velocity:?} vs plane {:?}",
            plane.1
        );
    }
    let (plane_end, mesh_end) = (on_plane[119].0, on_mesh[119].0);
    assert!(
        (plane_end - mesh_end).length() < 0.01,
        "stops at {mesh_end:?}, on the plane at {plane_end:?}"
    );
}

/// Without the active-edge correction the box hops at the first seam (vertical velocity
/// 1.2 m/s at step 1); with a manifold per triangle instead of merged coplanar ones it yaws at
/// 0.05 rad/s and leaves the plane's path (see `stages::narrowphase::children`).
#[test]
fn box_slides_across_seams_without_bumping() {
    slides_as_on_a_plane(Shape::cuboid(Vec3::new(0.4, 0.25, 0.3)), 0.25);
}

/// The barrel of the `convex-hulls` scene, standing on its square cap (0.42 m a side, so it
/// does not tip: mu = 0.3 < half the cap / the centre's height = 0.42), slides as on a plane.
#[test]
fn hull_slides_across_seams_without_bumping() {
    slides_as_on_a_plane(barrel(), 0.5);
}

fn barrel() -> Shape {
    Shape::convex_hull(&tumble::scene::barrel_points()).unwrap()
}

/// The barrel standing on its cap, off the grid lines and turned so its four cap corners sit
/// on different triangles, stays where it was put for 10 s: it never sinks deeper than the
/// solver's penetration slop (5 mm) plus a millimetre, and it neither drifts nor turns (the
/// bounds of the box's test above, which a plane meets too).
#[test]
fn hull_rests_on_a_tessellated_floor_as_on_a_plane() {
    let start = Vec3::new(0.13, 0.5, -0.27);
    let rotation = Quat::from_rotation_y(0.4);
    let mut world = world_on(floor(5.0, 10), 0.5);
    let body = drop_on(&mut world, barrel(), start, rotation);
    let mut deepest: f32 = 0.0;
    for step in 0..600 {
        world.step();
        let y = world.pose(body).unwrap().position.y;
        deepest = deepest.max(0.5 - y);
        assert!((y - 0.5).abs() < 0.006, "step {step}: y = {y}");
    }
    let pose = world.pose(body).unwrap();
    println!("deepest {deepest} m, drift {:?}", pose.position - start);
    assert!(
        (pose.position - start).length() < 1e-3,
        "drifted to {:?}",
        pose.position
    );
    assert!(angle_between(pose.rotation, rotation) < 1e-3);
    assert!(world.linear_velocity(body).unwrap().length() < 1e-3);
    assert!(world.angular_velocity(body).unwrap().length() < 1e-3);
}

#[test]
fn sphere_and_capsule_rest_on_a_tessellated_floor() {
    let mut world = world_on(floor(5.0, 10), 0.5);
    let ball = drop_on(
        &mut world,
        Shape::sphere(0.3),
        Vec3::new(0.5, 1.0, 0.5), // above a grid vertex: six triangles meet there
        Quat::IDENTITY,
    );
    let lying = drop_on(
        &mut world,
        Shape::capsule(0.2, 0.6),
        Vec3::new(-2.0, 1.0, 1.3),
        Quat::from_rotation_z(std::f32::consts::FRAC_PI_2) * Quat::from_rotation_x(0.3),
    );
    run(&mut world, 3.0);
    let ball_pose = world.pose(ball).unwrap();
    assert!(
        (ball_pose.position.y - 0.3).abs() < 0.006,
        "ball at {:?}",
        ball_pose.position
    );
    assert!((ball_pose.position.x - 0.5).abs() < 1e-3 && (ball_pose.position.z - 0.5).abs() < 1e-3);
    let capsule_pose = world.pose(lying).unwrap();
    assert!(
        (capsule_pose.position.y - 0.2).abs() < 0.006,
        "capsule at {:?}",
        capsule_pose.position
    );
    for body in [ball, lying] {
        assert!(world.linear_velocity(body).unwrap().length() < 1e-2);
    }
}
