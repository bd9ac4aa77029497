//! Spheres, capsules, boxes and convex hulls dropped on the generated landscape (a
//! ~5000-triangle mesh with slopes up to about 20°) land on it, never sink below its surface,
//! and the boxes come to rest; the `convex-trimesh` scene's barrels land on it.
use tumble::math::{Quat, Vec3};
use tumble::scene::landscape::Landscape;
use tumble::{BodyDesc, BodyHandle, Shape, StepConfig, World};

/// How far a body may dip into the surface (m) while landing and tumbling at up to 5 m/s and
/// 5 rad/s. Measured: 7.2 mm at most (a ball rolling over the hills), 1.5 mm for boxes alone,
/// 5.0 mm with barrels. Before contacts reached past concave edges and a box apart across an
/// edge pair got its face's points (`collision::contact::triangle`), a capsule pivoting on
/// one end put the other 11.6 mm into a valley triangle it had no point on, and a tumbling
/// box a corner 15 mm into a triangle whose only contact was an edge point.
const SINK_TOLERANCE: f32 = 0.010;

/// How far a body may sink once resting (m): the solver's penetration slop (5 mm) plus
/// rounding, as on a plane (`tests/engine/rest.rs`).
const REST_TOLERANCE: f32 = 0.006;

/// The lowest clearance (m) of a body above the landscape surface: sampled at the points where
/// each shape reaches lowest (sphere centre minus radius along the vertical, box corners,
/// capsule end spheres, hull vertices). Negative proves the body dips into the ground: the point straight
/// below a ball's centre at distance r is inside the ball. Bodies that rolled off the
/// landscape's edge give +∞ (nothing to check).
fn clearance(landscape: &Landscape, world: &World, body: BodyHandle, shape: &Shape) -> f32 {
    let pose = world.pose(body).unwrap();
    let surface = |p: Vec3| landscape.height_at(p.x, p.z).unwrap_or(f32::NEG_INFINITY);
    match shape {
        Shape::Sphere(sphere) => pose.position.y - sphere.radius - surface(pose.position),
        Shape::Capsule(capsule) => [-1.0f32, 1.0]
            .iter()
            .map(|&end| {
                let center = pose.transform_point(Vec3::new(0.0, end * capsule.half_height, 0.0));
                center.y - capsule.radius - surface(center)
            })
            .fold(f32::INFINITY, f32::min),
        Shape::Cuboid(cuboid) => (0..8)
            .map(|corner| {
                let local = Vec3::new(
                    if corner & 1 == 0 { -1.0 } else { 1.0 },
                    if corner & 2 == 0 { -1.0 } else { 1.0 },
                    if corner & 4 == 0 { -1.0 } else { 1.0 },
                ) * cuboid.half_extents;
                let point = pose.transform_point(local);
                point.y - surface(point)
            })
            .fold(f32::INFINITY, f32::min),
        Shape::ConvexHull(hull) => hull
            .vertices()
            .iter()
            .map(|&vertex| {
                let point = pose.transform_point(vertex);
                point.y - surface(point)
            })
            .fold(f32::INFINITY, f32::min),
        _ => unreachable!("only convex bodies are dropped"),
    }
}

/// A 6 × 6 grid of bodies over the middle of the landscape, `shapes` in turn, tilted a
/// little, 1.5 m above the ground; then 10 s of simulation, checking every step that no body
/// dips into the ground. Returns the world and bodies at the end.
fn drop_grid(
    landscape: &Landscape,
    shapes: &[Shape],
    config: StepConfig,
) -> (World, Vec<(BodyHandle, Shape)>) {
    let mut world = World::new(config).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::trimesh(landscape.mesh().unwrap())).friction(0.8))
        .unwrap();
    let mut bodies = Vec::new();
    for i in 0..6 {
        for j in 0..6 {
            let (x, z) = (-12.0 + 4.7 * i as f32, -11.0 + 4.3 * j as f32);
            let shape = shapes[(i + j) % shapes.len()].clone();
            let ground = landscape.height_at(x, z).unwrap();
            let rotation =
                Quat::from_euler(glam::EulerRot::XYZ, 0.3 * i as f32, 0.2, 0.1 * j as f32);
            let body = world
                .add_body(
                    BodyDesc::dynamic(shape.clone())
                        .position(Vec3::new(x, ground + 1.5, z))
                        .rotation(rotation)
                        .friction(0.8),
                )
                .unwrap();
            bodies.push((body, shape));
        }
    }
    for step in 0..600 {
        world.step();
        for (body, shape) in &bodies {
            let clearance = clearance(landscape, &world, *body, shape);
            assert!(
                clearance > -SINK_TOLERANCE,
                "step {step}: {shape:?} is {} m below the surface",
                -clearance
            );
        }
    }
    (world, bodies)
}

/// Balls and capsules roll down the hills (no rolling resistance), some off the edge: they
/// are checked for never dipping into the ground.
#[test]
fn spheres_capsules_and_boxes_dropped_together_never_sink() {
    let shapes = [
        Shape::sphere(0.3),
        Shape::capsule(0.2, 0.4),
        Shape::cuboid(Vec3::new(0.4, 0.3, 0.35)),
    ];
    drop_grid(&Landscape::new(0.05), &shapes, StepConfig::default());
}

fn drop_boxes(landscape: &Landscape, config: StepConfig) -> (World, Vec<(BodyHandle, Shape)>) {
    let shapes = [
        Shape::cuboid(Vec3::new(0.4, 0.3, 0.35)),
        Shape::cuboid(Vec3::new(0.25, 0.25, 0.6)),
    ];
    drop_grid(landscape, &shapes, config)
}

/// Boxes alone (nothing rolls into them): after landing each one lies on the surface where it
/// landed, sunk no deeper than on a plane.
#[test]
fn boxes_dropped_on_the_landscape_lie_on_it() {
    let landscape = Landscape::new(0.05);
    let (world, bodies) = drop_boxes(&landscape, StepConfig::default());
    for (body, shape) in &bodies {
        let clearance = clearance(&landscape, &world, *body, shape);
        // Slopes are at most about 20° and friction 0.8: every box stays on the landscape.
        assert!(clearance.is_finite(), "a box slid off the landscape");
        // A box on a slope touches with a corner at least.
        assert!(clearance < 0.02, "{shape:?} hovers {clearance} m up");
        assert!(
            clearance > -REST_TOLERANCE,
            "{shape:?} rests {clearance} m deep"
        );
    }
}

/// After landing (10 s), every box is at rest (asleep or nearly still). Ignored once for one
/// box (body 12, on a slope at (-2.27, 0.95, -11.25)) creeping downhill at about 1.6 mm/s;
/// sleeping (`dynamics::island`: under 5 cm/s for 0.5 s) now stops it, and the creep itself is
/// the ignored test below.
#[test]
fn boxes_dropped_on_the_landscape_come_to_rest() {
    let landscape = Landscape::new(0.05);
    let (world, bodies) = drop_boxes(&landscape, StepConfig::default());
    for (body, _) in &bodies {
        let speed = world.linear_velocity(*body).unwrap().length();
        let spin = world.angular_velocity(*body).unwrap().length();
        assert!(
            speed < 0.005 && spin < 0.01,
            "box still moving: {speed} m/s, {spin} rad/s"
        );
    }
}

/// Known defect: with sleeping off, the same boxes do not all stay where they landed: body 12
/// moves 14 mm downhill between 10 s and 20 s (about 1.4 mm/s). Preferring the triangle's face
/// over the box's as the reference everywhere makes more boxes move; the friction anchors
/// across the box's several unmerged triangle manifolds are the next suspect.
#[test]
#[ignore = "known defect: with sleeping off, a box creeps downhill at ~1.3 mm/s"]
fn boxes_dropped_on_the_landscape_stay_put_with_sleeping_off() {
    let landscape = Landscape::new(0.05);
    let config = StepConfig {
        sleeping: false,
        ..StepConfig::default()
    };
    let (mut world, bodies) = drop_boxes(&landscape, config);
    let landed: Vec<Vec3> = bodies
        .iter()
        .map(|(body, _)| world.pose(*body).unwrap().position)
        .collect();
    for _ in 0..600 {
        world.step();
    }
    for ((body, _), landed) in bodies.iter().zip(&landed) {
        let moved = world.pose(*body).unwrap().position.distance(*landed);
        assert!(moved < 0.001, "a resting box moved {moved} m in 10 s");
    }
}

/// Barrels (the `convex-hulls` hull, 40 points) dropped with the other shapes never dip into
/// the ground by more than the landing tolerance.
#[test]
fn barrels_dropped_with_the_other_shapes_never_sink() {
    let shapes = [
        Shape::convex_hull(&tumble::scene::barrel_points()).unwrap(),
        Shape::sphere(0.3),
        Shape::cuboid(Vec3::new(0.4, 0.3, 0.35)),
    ];
    drop_grid(&Landscape::new(0.05), &shapes, StepConfig::default());
}

/// The `convex-trimesh` scene at a small scale: its barrels fall onto the landscape, none
/// sinks into it, and after 3 s they lie on it or on each other: at least half touch it
/// (within 5 cm), none is higher than a barrel (1 m) on another.
#[test]
fn convex_trimesh_barrels_land_on_the_landscape() {
    let scale = 0.02;
    let scene = tumble::scene::builtin("convex-trimesh", scale).unwrap();
    let landscape = Landscape::new(scale);
    let Shape::TriMesh(mesh) = &scene.bodies[0].shape else {
        panic!("the ground is the landscape mesh")
    };
    assert_eq!(
        mesh.triangles().len(),
        2 * landscape.cells() as usize * landscape.cells() as usize
    );
    let barrels: Vec<Shape> = scene.bodies[1..].iter().map(|b| b.shape.clone()).collect();
    assert!(barrels.len() >= 15, "{} barrels", barrels.len());
    let mut world = scene.build().unwrap();
    let bodies: Vec<BodyHandle> = world.bodies().skip(1).collect();
    let mut lowest = f32::INFINITY;
    for _ in 0..180 {
        world.step();
        for (body, shape) in bodies.iter().zip(&barrels) {
            lowest = lowest.min(clearance(&landscape, &world, *body, shape));
        }
    }
    assert!(
        lowest > -SINK_TOLERANCE,
        "a barrel dipped {} m into the ground",
        -lowest
    );
    let on_ground = bodies
        .iter()
        .zip(&barrels)
        .filter(|(body, shape)| clearance(&landscape, &world, **body, shape) < 0.05)
        .count();
    println!(
        "lowest clearance {lowest} m, {on_ground} of {} barrels on the ground",
        bodies.len()
    );
    assert!(
        on_ground * 2 >= bodies.len(),
        "{on_ground} of {} barrels on the ground",
        bodies.len()
    );
    for (body, shape) in bodies.iter().zip(&barrels) {
        let clearance = clearance(&landscape, &world, *body, shape);
        assert!(clearance < 1.05, "a barrel still {clearance} m up");
    }
}
