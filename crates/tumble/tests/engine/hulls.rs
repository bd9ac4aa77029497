//! Convex hulls in the world: a hull rests on a plane, a stack of three stands, a box given as
//! a hull collides as the box does, and a hull whose points are off their centroid dumps and
//! loads back bitwise; hulls land on triangle meshes.
use crate::common;
use common::*;
use tumble::collision::contact::collide;
use tumble::collision::manifold::Manifold;
use tumble::math::{Quat, Transform, Vec3, vec3};
use tumble::scene::{Scene, barrel_points};
use tumble::{BodyDesc, Shape, World};

fn barrel() -> Shape {
    Shape::convex_hull(&barrel_points()).unwrap()
}

/// Largest displacement (m) of `bodies` from their poses after 1 s, over the next `seconds`.
fn drift_after_settling(world: &mut World, bodies: &[tumble::BodyHandle], seconds: f32) -> f32 {
    run(world, 1.0);
    let settled: Vec<Vec3> = bodies
        .iter()
        .map(|&b| world.pose(b).unwrap().position)
        .collect();
    run(world, seconds);
    bodies
        .iter()
        .zip(&settled)
        .map(|(&b, start)| (world.pose(b).unwrap().position - *start).length())
        .fold(0.0, f32::max)
}

#[test]
fn barrel_resting_on_a_plane_stays() {
    let mut world = world_with_ground(0.5, 0.0);
    let body = world
        .add_body(BodyDesc::dynamic(barrel()).position(vec3(0.2, 0.5, -0.1)))
        .unwrap();
    let drift = drift_after_settling(&mut world, &[body], 5.0);
    assert!(drift < 0.01, "drifted {drift} m");
    let y = world.pose(body).unwrap().position.y;
    assert!((y - 0.5).abs() < 0.006, "rests at y = {y}");
    assert_eq!(
        world.stats().contacts,
        4,
        "the square cap rests on its 4 corners"
    );
}

#[test]
fn stack_of_three_barrels_stands() {
    let mut world = world_with_ground(0.5, 0.0);
    let bodies: Vec<_> = (0..3)
        .map(|k| {
            world
                .add_body(BodyDesc::dynamic(barrel()).position(vec3(0.0, 0.5 + k as f32, 0.0)))
                .unwrap()
        })
        .collect();
    let drift = drift_after_settling(&mut world, &bodies, 5.0);
    assert!(drift < 0.01, "drifted {drift} m");
    let top = world.pose(bodies[2]).unwrap().position.y;
    assert!((top - 2.5).abs() < 0.02, "top at y = {top}");
}

/// A box built as a hull of its corners collides as the box itself: same normal, same points.
#[test]
fn box_as_hull_agrees_with_box_box() {
    let half = vec3(0.6, 0.4, 0.5);
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            half * vec3(
                [-1.0, 1.0][i & 1],
                [-1.0, 1.0][(i >> 1) & 1],
                [-1.0, 1.0][i >> 2],
            )
        })
        .collect();
    let as_box = Shape::cuboid(half);
    let as_hull = Shape::convex_hull(&corners).unwrap();
    let other = Shape::cuboid(vec3(0.5, 0.3, 0.7));
    let poses = [
        // Face on face, overlapping 2 cm, turned a little.
        Transform::new(vec3(0.1, 0.68, -0.05), Quat::from_rotation_y(0.3)),
        // Resting on an edge.
        Transform::new(vec3(0.0, 0.8, 0.0), Quat::from_rotation_z(0.7)),
        // Tipped onto a corner.
        Transform::new(
            vec3(0.2, 0.9, 0.1),
            Quat::from_euler(glam::EulerRot::XYZ, 0.5, 0.4, 0.3),
        ),
    ];
    let mut touched = 0;
    for pose_other in &poses {
        let mut expected = Manifold::default();
        let mut actual = Manifold::default();
        collide(
            &other,
            pose_other,
            &as_box,
            &Transform::IDENTITY,
            0.02,
            &mut expected,
        );
        collide(
            &other,
            pose_other,
            &as_hull,
            &Transform::IDENTITY,
            0.02,
            &mut actual,
        );
        assert_eq!(expected.count, actual.count, "{pose_other:?}");
        if expected.count == 0 {
            continue;
        }
        touched += 1;
        assert!((expected.normal - actual.normal).length() < 1e-5);
        for point in expected.points() {
            assert!(
                actual
                    .points()
                    .iter()
                    .any(|p| (p.position - point.position).length() < 1e-4
                        && (p.separation - point.separation).abs() < 1e-5),
                "{point:?} not in {:?}",
                actual.points()
            );
        }
    }
    assert_eq!(touched, poses.len());
}

/// Distances between hulls placed apart along a known axis: a barrel above another's cap.
#[test]
fn hull_pair_separation_is_the_gap() {
    let hull = barrel();
    for gap in [0.005f32, 0.01, 0.015] {
        let mut out = Manifold::default();
        let above = Transform::from_position(vec3(0.05, 1.0 + gap, 0.0));
        collide(&hull, &above, &hull, &Transform::IDENTITY, 0.02, &mut out);
        assert_eq!(out.count, 4, "the caps meet on their square");
        assert!((out.normal - Vec3::Y).length() < 1e-6);
        for point in out.points() {
            assert!((point.separation - gap).abs() < 1e-6, "{point:?}");
        }
    }
}

/// Points off their centroid and off principal axes: the body's pose absorbs the hull frame,
/// and a dump loads back to the same state.
#[test]
fn off_centre_hull_dumps_and_loads_bitwise() {
    let points: Vec<Vec3> = barrel_points()
        .iter()
        .map(|&p| Quat::from_rotation_x(0.4) * (p * vec3(1.0, 1.5, 0.7)) + vec3(3.0, 0.0, 1.0))
        .collect();
    let mut world = world_with_ground(0.5, 0.0);
    let body = world
        .add_body(
            BodyDesc::dynamic(Shape::convex_hull(&points).unwrap()).position(vec3(-3.0, 2.0, -1.0)),
        )
        .unwrap();
    // The body frame is the centroid: the user's origin moved by the points' offset.
    let pose = world.pose(body).unwrap();
    assert!(
        (pose.position - vec3(0.0, 2.0, 0.0)).length() < 1e-4,
        "{pose:?}"
    );
    run(&mut world, 0.5);
    let dump = Scene::from_world(&world).to_json();
    let mut loaded = Scene::from_json(&dump).unwrap().build().unwrap();
    assert_eq!(Scene::from_world(&loaded).to_json(), dump);
    run(&mut world, 0.5);
    run(&mut loaded, 0.5);
    assert_eq!(
        Scene::from_world(&loaded).to_json(),
        Scene::from_world(&world).to_json()
    );
}

/// Hulls and triangle meshes share a world in either order of adding, and a barrel dropped
/// on a mesh lands on it (one triangle here; `tests/engine/trimesh_floor.rs` has the tessellated
/// floor and `tests/engine/landscape.rs` the hills).
#[test]
fn hulls_and_meshes_collide() {
    use tumble::shape::TriMesh;
    let floor = || {
        let vertices = vec![
            vec3(-5.0, 0.0, -5.0),
            vec3(0.0, 0.0, 5.0),
            vec3(5.0, 0.0, -5.0),
        ];
        Shape::trimesh(TriMesh::new(vertices, vec![[0, 1, 2]]).unwrap())
    };
    let mut mesh_first = World::new(awake_config()).unwrap();
    mesh_first.add_body(BodyDesc::fixed(floor())).unwrap();
    let barrel_body = mesh_first
        .add_body(BodyDesc::dynamic(barrel()).position(vec3(0.0, 1.0, -1.0)))
        .unwrap();
    let mut hull_first = World::new(awake_config()).unwrap();
    let hull_body = hull_first
        .add_body(BodyDesc::dynamic(barrel()).position(vec3(0.0, 1.0, -1.0)))
        .unwrap();
    hull_first.add_body(BodyDesc::fixed(floor())).unwrap();
    for (mut world, body) in [(mesh_first, barrel_body), (hull_first, hull_body)] {
        run(&mut world, 2.0);
        // Standing on its square cap: the centre 0.5 m up, sunk no more than the solver's slop.
        let y = world.pose(body).unwrap().position.y;
        assert!((y - 0.5).abs() < 0.006, "rests at y = {y}");
        assert_eq!(world.stats().contacts, 4, "the cap's 4 corners");
    }
}
