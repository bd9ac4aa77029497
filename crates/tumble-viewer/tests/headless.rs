//! Headless renders on whatever adapter wgpu finds (lavapipe where there is no GPU): one box on
//! a plane (the picture is not blank, shows the background where nothing is, and shows the box
//! where its centre projects with the same camera matrix the renderer uses; in wireframe, its
//! edges there and not its faces), a convex hull
//! and a compound drawn where their poses project (the compound child by child), one box on a
//! floor made of two triangles (the floor shows where it projects, the background around it),
//! a box above a plane (its shadow darkens the floor), the overlays (text pixels in the
//! overlay's panel with it, none without), joints drawn over the bodies they join with the
//! contacts and constraints on (two hinged boxes, a ragdoll), a world stepped on the GPU drawn
//! from the step's device buffers, each pass timed on the GPU, and a pile of boxes drawn alike
//! with every quality knob (quality.rs).

use tumble::math::Vec3;
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::shape::TriMesh;
use tumble::{BodyDesc, BodyHandle, JointDesc, JointKind, Shape, StepConfig, World};
use tumble_viewer::draw::{
    BACKGROUND, DrawList, DrawSettings, JOINT_COLOUR, TRIMESH_COLOUR, body_colour,
};
use tumble_viewer::headless::{Image, Offscreen};
use tumble_viewer::overlay::{TEXT_COLOUR, help_lines, panel_rect, profile_lines};
use tumble_viewer::quality::{DrawOrder, Quality};
use tumble_viewer::{Camera, GpuContext, LIGHT_DIRECTION};

// Small: lavapipe rasterizes on the CPU.
const WIDTH: u32 = 128;
const HEIGHT: u32 = 96;

/// sRGB encoding of a linear channel, as the Rgba8UnormSrgb target stores it.
fn encode_srgb(linear: f32) -> f32 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

fn decode_srgb(encoded: u8) -> f32 {
    let c = f32::from(encoded) / 255.0;
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The pixel where `point` projects with the renderer's matrix; panics outside the picture.
fn project(camera: &Camera, point: Vec3) -> (u32, u32) {
    let clip = camera.view_projection(WIDTH as f32 / HEIGHT as f32) * point.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    assert!(
        ndc.x.abs() < 1.0 && ndc.y.abs() < 1.0,
        "{point} is out of the picture"
    );
    let x = ((ndc.x + 1.0) * 0.5 * WIDTH as f32) as u32;
    let y = ((1.0 - ndc.y) * 0.5 * HEIGHT as f32) as u32;
    (x, y)
}

/// Asserts that the pixel has the background colour.
fn assert_background(pixel: [u8; 4], at: (u32, u32)) {
    let background = BACKGROUND.map(|c| (encode_srgb(c) * 255.0).round() as i32);
    for channel in 0..3 {
        assert!(
            (i32::from(pixel[channel]) - background[channel]).abs() <= 1,
            "pixel {at:?} = {pixel:?}, background {background:?}"
        );
    }
    assert_eq!(pixel[3], 255);
}

/// Asserts that the pixel has the hue of the linear `colour` (Lambert + ambient scale the
/// colour, keeping its hue).
fn assert_hue(pixel: [u8; 4], at: (u32, u32), colour: [f32; 3]) {
    let seen = chromaticity([0, 1, 2].map(|c| decode_srgb(pixel[c])));
    let expected = chromaticity(colour);
    assert!(
        seen.dot(expected) > 0.995,
        "pixel {at:?} = {pixel:?}: hue {seen:?}, expected {expected:?}"
    );
}

/// Direction of an RGB colour (its hue and saturation, without its brightness).
fn chromaticity(rgb: [f32; 3]) -> Vec3 {
    Vec3::from_array(rgb).normalize()
}

/// `world` from `camera`, drawn headless with the default settings.
fn render(world: &World, camera: &Camera) -> Image {
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    offscreen
        .render(&context, world, camera, DrawSettings::default(), &[])
        .unwrap()
}

/// A unit box resting on a ground plane, and a camera slightly above it and in front of it: the
/// top corners of the picture look at the sky.
fn box_on_the_ground() -> (World, BodyHandle, Camera) {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let cube = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0)),
        )
        .unwrap();
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 4.0), Vec3::new(0.0, 0.5, 0.0));
    (world, cube, camera)
}

#[test]
fn box_on_a_plane() {
    let (world, cube, camera) = box_on_the_ground();

    let image = render(&world, &camera);
    assert_eq!(image.rgba.len(), (4 * WIDTH * HEIGHT) as usize);

    // Not blank: many distinct colours (sky, ground, grid lines, three lit box faces).
    let mut colours: Vec<[u8; 4]> = image
        .rgba
        .chunks_exact(4)
        .map(|p| p.try_into().unwrap())
        .collect();
    colours.sort_unstable();
    colours.dedup();
    assert!(colours.len() > 10, "only {} colours", colours.len());

    // Background in a corner where nothing is drawn.
    assert_background(image.pixel(0, 0), (0, 0));

    // The box's centre lands on one of its lit faces.
    let at = project(&camera, world.pose(cube).unwrap().position);
    assert_hue(
        image.pixel(at.0, at.1),
        at,
        body_colour(cube.index() as usize),
    );
}

/// Pixels of the picture with the hue of the linear `colour`.
fn pixels_of_hue(image: &Image, colour: [f32; 3]) -> usize {
    let expected = chromaticity(colour);
    image
        .rgba
        .chunks_exact(4)
        .filter(|p| chromaticity([0, 1, 2].map(|c| decode_srgb(p[c]))).dot(expected) > 0.995)
        .count()
}

#[test]
fn wireframe_draws_the_edges_and_not_the_faces() {
    let (world, cube, camera) = box_on_the_ground();
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    let mut render = |wireframe| {
        let settings = DrawSettings {
            wireframe,
            ..DrawSettings::default()
        };
        offscreen
            .render(&context, &world, &camera, settings, &[])
            .unwrap()
    };
    let (solid, wireframe) = (render(false), render(true));
    let colour = body_colour(cube.index() as usize);

    // The front face's middle: the box solid, the floor behind it in wireframe.
    let front = project(&camera, Vec3::new(0.0, 0.5, 0.5));
    assert_hue(solid.pixel(front.0, front.1), front, colour);
    let seen = chromaticity([0, 1, 2].map(|c| decode_srgb(wireframe.pixel(front.0, front.1)[c])));
    assert!(
        seen.dot(chromaticity(colour)) < 0.99,
        "the front face is filled in wireframe at {front:?}"
    );
    // The edges, in the box's colour unlit, where they project: the front face's top and
    // bottom edges' middles and a vertical edge's.
    for edge in [
        Vec3::new(0.0, 1.0, 0.5),
        Vec3::new(0.0, 0.0, 0.5),
        Vec3::new(0.5, 0.5, 0.5),
    ] {
        let at = project(&camera, edge);
        assert!(
            pixels_of(&wireframe, colour, around(at)) > 0,
            "no edge at {at:?} ({edge})"
        );
    }
    // Lines, not faces: a fraction of the solid box's pixels.
    let (filled, lines) = (
        pixels_of_hue(&solid, colour),
        pixels_of_hue(&wireframe, colour),
    );
    println!("the box: {filled} pixels solid, {lines} in wireframe");
    assert!(
        lines > 0 && 3 * lines < filled,
        "{lines} line pixels, {filled} solid"
    );
}

#[test]
fn a_convex_hull_is_drawn_where_its_pose_projects() {
    // A wedge (a triangular prism), tilted: its centre of mass is off the points' origin, so
    // the body sits in the hull's own frame (convex_hull.rs), as a barrel of the scenes does.
    let mut points = Vec::new();
    for z in [-0.6, 0.6] {
        points.extend([
            Vec3::new(-0.7, 0.0, z),
            Vec3::new(0.7, 0.0, z),
            Vec3::new(0.0, 1.0, z),
        ]);
    }
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let hull = world
        .add_body(
            BodyDesc::dynamic(Shape::convex_hull(&points).unwrap())
                .position(Vec3::new(0.3, 0.4, 0.0))
                .rotation(tumble::math::Quat::from_rotation_y(0.5)),
        )
        .unwrap();
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 4.0), Vec3::new(0.0, 0.5, 0.0));
    let image = render(&world, &camera);
    assert_background(image.pixel(0, 0), (0, 0));
    // Its centre of mass, inside it, lands on a lit face of it.
    let centre = world.pose(hull).unwrap().position;
    let at = project(&camera, centre);
    assert_hue(
        image.pixel(at.0, at.1),
        at,
        body_colour(hull.index() as usize),
    );
    // Above the wedge's ridge, the floor and the sky: not the hull.
    let above = project(&camera, centre + Vec3::new(0.0, 1.2, 0.0));
    assert_background(image.pixel(above.0, above.1), above);
}

#[test]
fn a_compound_is_drawn_child_by_child_where_its_pose_projects() {
    use tumble::math::{Quat, Transform};
    use tumble::shape::CompoundChild;
    // A dumbbell: two balls on a rod, turned about the vertical.
    let ball = |x: f32| CompoundChild {
        shape: Shape::sphere(0.35),
        pose: Transform::new(Vec3::new(x, 0.0, 0.0), Quat::IDENTITY),
    };
    let rod = CompoundChild {
        shape: Shape::capsule(0.08, 0.6),
        pose: Transform::new(
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
        ),
    };
    let dumbbell = Shape::compound(vec![ball(-0.9), rod, ball(0.9)]).unwrap();
    let (position, rotation) = (Vec3::new(0.0, 0.5, 0.0), Quat::from_rotation_y(0.4));
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let body = world
        .add_body(
            BodyDesc::dynamic(dumbbell)
                .position(position)
                .rotation(rotation),
        )
        .unwrap();
    let camera = Camera::look_at(Vec3::new(0.5, 1.5, 4.0), Vec3::new(0.0, 0.5, 0.0));
    let image = render(&world, &camera);
    assert_background(image.pixel(0, 0), (0, 0));
    let colour = body_colour(body.index() as usize);
    let pose = Transform::new(position, rotation);
    // Each ball where its centre projects (its point nearest the camera, which is lit)...
    for x in [-0.9, 0.9] {
        let centre = pose.transform_point(Vec3::new(x, 0.0, 0.0));
        let front = centre + (camera.eye() - centre).normalize() * 0.3;
        let at = project(&camera, front);
        assert_hue(image.pixel(at.0, at.1), at, colour);
    }
    // ... and above the thin rod's middle, nothing of it: the floor, not the body.
    let above_rod = project(&camera, pose.transform_point(Vec3::new(0.0, 0.3, 0.0)));
    let seen =
        chromaticity([0, 1, 2].map(|c| decode_srgb(image.pixel(above_rod.0, above_rod.1)[c])));
    assert!(
        seen.dot(chromaticity(colour)) < 0.99,
        "the body's colour above its rod at {above_rod:?}"
    );
}

/// The particle demo's picture: each particle a sphere of its colour where it projects, the
/// box's floor under them, sky where nothing is.
#[test]
fn particles_are_drawn_as_spheres_on_their_floor() {
    let positions = [[0.0, 0.5, 0.0], [1.5, 0.5, 0.0], [0.0, 2.0, -1.0]];
    let container = tumble::math::Aabb {
        min: Vec3::new(-2.0, 0.0, -2.0),
        max: Vec3::new(2.0, 4.0, 2.0),
    };
    let list = DrawList::particles(&positions, 0.5, container);
    assert_eq!(list.instances.values().map(Vec::len).sum::<usize>(), 3);
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 6.0), Vec3::new(0.5, 1.0, 0.0));
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    let image = offscreen
        .render_list(&context, &list, &camera, None)
        .unwrap();
    assert_background(image.pixel(0, 0), (0, 0));
    for (index, &position) in positions.iter().enumerate() {
        // The sphere's point nearest the camera: lit, so its hue is the particle's colour.
        let centre = Vec3::from(position);
        let front = centre + (camera.eye() - centre).normalize() * 0.45;
        let at = project(&camera, front);
        assert_hue(image.pixel(at.0, at.1), at, body_colour(index));
    }
    // The floor, in front of the particles and below them.
    let at = project(&camera, Vec3::new(0.0, 0.0, 1.8));
    let floor = image.pixel(at.0, at.1);
    assert!(
        floor != image.pixel(0, 0) && floor[0].abs_diff(floor[2]) < 40,
        "grey floor at {at:?}: {floor:?}"
    );
}

#[test]
fn box_on_a_triangle_mesh_floor() {
    // A floor 4 m square at y = 0, two triangles facing up; no ground plane.
    let corners = vec![
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, -2.0),
        Vec3::new(-2.0, 0.0, -2.0),
    ];
    let floor = TriMesh::new(corners, vec![[0, 1, 2], [0, 2, 3]]).unwrap();
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::trimesh(floor)))
        .unwrap();
    let cube = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0)),
        )
        .unwrap();
    let camera = Camera::look_at(Vec3::new(3.0, 5.0, 7.0), Vec3::ZERO);

    let image = render(&world, &camera);

    // The floor where its points project, in front of the box and behind it.
    for point in [
        Vec3::new(1.5, 0.0, 1.5),
        Vec3::new(-1.5, 0.0, 1.5),
        Vec3::new(-1.5, 0.0, -1.5),
    ] {
        let at = project(&camera, point);
        assert_hue(image.pixel(at.0, at.1), at, TRIMESH_COLOUR);
    }
    // The box stands on it.
    let at = project(&camera, world.pose(cube).unwrap().position);
    assert_hue(
        image.pixel(at.0, at.1),
        at,
        body_colour(cube.index() as usize),
    );
    // Beside the floor, in its plane, and in a corner: the background.
    for point in [Vec3::new(3.0, 0.0, 0.0), Vec3::new(-3.0, 0.0, 0.0)] {
        let at = project(&camera, point);
        assert_background(image.pixel(at.0, at.1), at);
    }
    assert_background(image.pixel(0, 0), (0, 0));
}

/// Linear luminance-like brightness of a pixel (the sum of its linear channels).
fn brightness(pixel: [u8; 4]) -> f32 {
    (0..3).map(|c| decode_srgb(pixel[c])).sum()
}

#[test]
fn a_box_shadows_the_floor_under_it() {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    // Floating 1 m above the floor (it is not stepped, so it stays there).
    let center = Vec3::new(0.0, 1.5, 0.0);
    world
        .add_body(BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(center))
        .unwrap();
    // From high above, so the floor in the box's shadow is in view beside the box.
    let camera = Camera::look_at(Vec3::new(0.0, 8.0, 0.5), Vec3::ZERO);

    let image = render(&world, &camera);

    // The light's ray through the box's centre meets the floor here; a grid cell's middle
    // near it (grid lines sit on whole metres) is in the shadow of the whole box.
    let light = LIGHT_DIRECTION.normalize();
    let under = center - light * (center.y / light.y);
    assert!(
        (under - Vec3::new(-0.94, 0.0, -0.56)).length() < 0.01,
        "{under}"
    );
    let shadowed = project(&camera, Vec3::new(-0.9, 0.0, -0.6));
    // Far from the box on the other side, the floor is lit.
    let lit = project(&camera, Vec3::new(1.5, 0.0, 1.5));
    let (dark, bright) = (
        brightness(image.pixel(shadowed.0, shadowed.1)),
        brightness(image.pixel(lit.0, lit.1)),
    );
    // Shadowed, only the ambient light (0.3) is left of ambient + Lambert (about 0.87).
    assert!(
        dark < 0.6 * bright,
        "floor in the shadow at {shadowed:?}: {dark}, lit at {lit:?}: {bright}"
    );
}

/// Pixels inside (left, top, right, bottom) of the unlit linear `colour` (text, lines).
fn pixels_of(
    image: &Image,
    colour: [f32; 3],
    (left, top, right, bottom): (u32, u32, u32, u32),
) -> usize {
    let encoded = colour.map(|c| (encode_srgb(c) * 255.0).round() as i32);
    let mut count = 0;
    for y in top..bottom {
        for x in left..right {
            let pixel = image.pixel(x, y);
            if (0..3).all(|c| (i32::from(pixel[c]) - encoded[c]).abs() <= 2) {
                count += 1;
            }
        }
    }
    count
}

/// Pixels inside the rectangle that have the overlay text's colour.
fn text_pixels(image: &Image, rect: (u32, u32, u32, u32)) -> usize {
    pixels_of(image, TEXT_COLOUR, rect)
}

/// The 3 x 3 pixels around `at`: a line through a point may be rasterized a pixel beside it.
fn around((x, y): (u32, u32)) -> (u32, u32, u32, u32) {
    (x.saturating_sub(1), y.saturating_sub(1), x + 2, y + 2)
}

const WHOLE: (u32, u32, u32, u32) = (0, 0, WIDTH, HEIGHT);

fn contacts_and_constraints() -> DrawSettings {
    DrawSettings {
        contacts: true,
        ..DrawSettings::default()
    }
}

#[test]
fn joints_are_drawn_over_the_bodies_they_join() {
    // Two boxes hinged at the point between them, seen from the front; not stepped.
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let (centre_a, anchor) = (Vec3::new(-1.0, 2.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
    let cube = Shape::cuboid(Vec3::splat(0.5));
    let a = world
        .add_body(BodyDesc::dynamic(cube.clone()).position(centre_a))
        .unwrap();
    let b = world
        .add_body(BodyDesc::dynamic(cube).position(Vec3::new(1.0, 2.0, 0.0)))
        .unwrap();
    let hinge = JointKind::Hinge {
        axis: Vec3::Z,
        limits: None,
        motor: None,
    };
    world
        .add_joint(JointDesc::new(hinge, a, b, anchor))
        .unwrap();
    let camera = Camera::look_at(Vec3::new(0.0, 2.5, 5.0), Vec3::new(0.0, 2.0, 0.0));
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    let mut render = |settings| {
        offscreen
            .render(&context, &world, &camera, settings, &[])
            .unwrap()
    };
    let (without, with) = (
        render(DrawSettings::default()),
        render(contacts_and_constraints()),
    );
    // The line from A's centre to the anchor runs inside A, behind its front face: drawn
    // over it with the constraints, and only then.
    let inside_a = project(&camera, centre_a.lerp(anchor, 0.25));
    assert_hue(
        without.pixel(inside_a.0, inside_a.1),
        inside_a,
        body_colour(a.index() as usize),
    );
    assert_eq!(pixels_of(&without, JOINT_COLOUR, WHOLE), 0);
    assert!(
        pixels_of(&with, JOINT_COLOUR, around(inside_a)) > 0,
        "no joint line at {inside_a:?}"
    );
    // The anchor's cross, in the gap between the boxes, where the ground is behind it.
    let at = project(&camera, anchor);
    assert!(
        pixels_of(&with, JOINT_COLOUR, around(at)) > 0,
        "no anchor at {at:?}"
    );
}

#[test]
fn the_ragdolls_show_their_joints() {
    let mut world = tumble::scene::builtin("ragdolls", 0.01)
        .unwrap()
        .build()
        .unwrap();
    let joints = world.joints().count();
    assert!(joints >= 10, "{joints} joints");
    for _ in 0..30 {
        world.step();
    }
    let camera = Camera::framing(&world, WIDTH as f32 / HEIGHT as f32);
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    let mut joint_pixels = |settings| {
        let image = offscreen
            .render(&context, &world, &camera, settings, &[])
            .unwrap();
        pixels_of(&image, JOINT_COLOUR, WHOLE)
    };
    assert_eq!(joint_pixels(DrawSettings::default()), 0);
    // A line or two of pixels along each limb at least.
    let drawn = joint_pixels(contacts_and_constraints());
    assert!(
        drawn > 2 * joints,
        "{drawn} joint pixels for {joints} joints"
    );
}

#[test]
fn overlays_draw_text_in_their_panel() {
    // Wide enough for the help's longest line, so the picture has room beside the panel.
    let (width, height) = (640, 480);
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0)),
        )
        .unwrap();
    world.step();
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 4.0), Vec3::new(0.0, 0.5, 0.0));
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let mut offscreen = Offscreen::new(&context, width, height).unwrap();
    let mut render = |overlay: &[String]| {
        offscreen
            .render(&context, &world, &camera, DrawSettings::default(), overlay)
            .unwrap()
    };

    let help = help_lines();
    let profile = profile_lines(
        &world.profiler().report(),
        world.body_count(),
        world.stats(),
    );
    let without = render(&[]);
    for lines in [&help, &profile] {
        let panel = panel_rect(lines, height);
        let (right, bottom) = (panel.2, panel.3);
        assert!(right < width && bottom < height, "{panel:?}");
        assert_eq!(text_pixels(&without, panel), 0, "no overlay, no text");
        let with = render(lines);
        let drawn = text_pixels(&with, panel);
        // Each line puts ink in dozens of pixels.
        assert!(drawn > 20 * lines.len(), "{drawn} text pixels in {panel:?}");
        // Beside and below the panel, the picture is the scene's, untouched.
        for (x, y) in [(right, 0), (width - 1, height - 1), (0, bottom)] {
            assert_eq!(with.pixel(x, y), without.pixel(x, y), "at {x}, {y}");
        }
    }
}

#[test]
fn a_gpu_step_is_drawn_from_its_device_buffers() {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    // Sliding at 60 m/s: a step moves it a metre, twice its size.
    let start = Vec3::new(-1.5, 0.5, 0.0);
    let cube = world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                .position(start)
                .linear_velocity(Vec3::new(60.0, 0.0, 0.0)),
        )
        .unwrap();
    world
        .set_stage_devices(StageDevices::all(Executor::Gpu))
        .unwrap();
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    assert!(
        world.device_poses().is_none(),
        "no step, no poses on the device"
    );
    world.step();
    let end = world.pose(cube).unwrap().position;
    assert!((end - start).x > 0.8, "{start} -> {end}");
    let poses = world
        .device_poses()
        .expect("every stage ran on the GPU: the poses are on the device");

    // The host's models are sent far away: a box in the picture comes from the device.
    let mut list = DrawList::build(&world, DrawSettings::default());
    for instance in list.instances.values_mut().flatten() {
        instance.model[3] = [1000.0, 0.0, 0.0, 1.0];
    }
    let camera = Camera::look_at(Vec3::new(0.0, 4.0, 8.0), Vec3::new(-1.0, 0.5, 0.0));
    let mut offscreen = Offscreen::new(&context, WIDTH, HEIGHT).unwrap();
    let image = offscreen
        .render_list(&context, &list, &camera, Some(poses))
        .unwrap();

    // Where the step left it (the start pose moved by the solver's motion)...
    let colour = body_colour(cube.index() as usize);
    let at = project(&camera, end);
    assert_hue(image.pixel(at.0, at.1), at, colour);
    // ... and not where the step began.
    let at = project(&camera, start);
    let seen = chromaticity([0, 1, 2].map(|c| decode_srgb(image.pixel(at.0, at.1)[c])));
    assert!(
        seen.dot(chromaticity(colour)) < 0.99,
        "the box is still drawn at its start pose {start}: {:?}",
        image.pixel(at.0, at.1)
    );
}

#[test]
fn a_world_runs_its_gpu_stages_on_the_device_it_is_given() {
    // A device of its own, as a window makes (not the process's shared one).
    let own = tumble::gpu::GpuContext::new().expect("an adapter (install mesa-vulkan-drivers)");
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let start = Vec3::new(0.0, 2.0, 0.0);
    let ball = world
        .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(start))
        .unwrap();
    world.set_gpu_context(own.clone()).unwrap();
    world
        .set_stage_devices(StageDevices::all(Executor::Gpu))
        .unwrap();
    world.step();
    let poses = world.device_poses().expect("the step ran on the GPU");

    // The poses' buffer belongs to `own`'s device: copying it there is valid...
    let bytes = (poses.count * 32) as u64;
    let readback = own.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let scope = own.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let mut encoder = own.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(poses.poses, 0, &readback, 0, bytes);
    own.queue.submit([encoder.finish()]);
    let error = pollster::block_on(scope.pop());
    assert!(error.is_none(), "{error:?}");
    // ... and holds the ball where the step left it, which has moved (a pose is 8 floats:
    // position, pad, rotation).
    readback
        .slice(..)
        .map_async(wgpu::MapMode::Read, |result| result.unwrap());
    own.wait().unwrap();
    let mapped = readback.slice(..).get_mapped_range().unwrap();
    let floats: &[f32] = bytemuck::cast_slice(&mapped);
    let slot = 8 * ball.index() as usize;
    let end = world.pose(ball).unwrap().position;
    assert_ne!(end, start);
    assert_eq!(floats[slot..slot + 3], end.to_array());
}

#[test]
fn each_pass_is_timed_on_the_gpu() {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    world
        .add_body(
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0)),
        )
        .unwrap();
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 4.0), Vec3::new(0.0, 0.5, 0.0));
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let timestamps = context
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY);
    let overlay = help_lines();
    for quality in [
        Quality::default(),
        Quality::LEGACY,
        "prepass=on".parse().unwrap(),
    ] {
        let mut offscreen = Offscreen::with_quality(&context, WIDTH, HEIGHT, quality).unwrap();
        offscreen
            .render(&context, &world, &camera, DrawSettings::default(), &overlay)
            .unwrap();
        let Some(passes) = &offscreen.last_times.gpu_passes else {
            assert!(
                !timestamps,
                "{}: timestamp queries but no times",
                context.describe()
            );
            continue;
        };
        let names: Vec<&str> = passes.iter().map(|&(name, _)| name).collect();
        let expected: &[&str] = match (quality.order, quality.depth_prepass) {
            (DrawOrder::FrontToBack, false) => &["shadow", "meshes", "ground", "overlay"],
            (DrawOrder::FrontToBack, true) => {
                &["shadow", "depth pre-pass", "meshes", "ground", "overlay"]
            }
            (DrawOrder::Submitted, _) => &["shadow", "ground", "meshes", "overlay"],
        };
        assert_eq!(names, expected, "{quality}");
        for &(name, ms) in passes {
            assert!(ms > 0.0 && ms < 10_000.0, "{quality}: {name} took {ms} ms");
        }
    }
}

/// A pile of 64 boxes, some tilted and some in the air (shadows on boxes and on the ground),
/// seen from above at an angle.
fn pile() -> (World, Camera) {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    for i in 0..64 {
        let (x, z, y) = ((i % 4) as f32, ((i / 4) % 4) as f32, (i / 16) as f32);
        let rotation = tumble::math::Quat::from_rotation_y(0.3 * i as f32);
        world
            .add_body(
                BodyDesc::dynamic(Shape::cuboid(Vec3::new(0.4, 0.3, 0.35)))
                    .position(Vec3::new(1.1 * x - 1.6, 0.3 + 1.2 * y, 1.1 * z - 1.6))
                    .rotation(rotation),
            )
            .unwrap();
    }
    let camera = Camera::look_at(Vec3::new(5.0, 7.0, 9.0), Vec3::new(0.0, 1.5, 0.0));
    (world, camera)
}

/// Per pixel, the largest difference of a colour channel (0 to 255).
fn channel_differences(a: &Image, b: &Image) -> Vec<u8> {
    a.rgba
        .chunks_exact(4)
        .zip(b.rgba.chunks_exact(4))
        .map(|(p, q)| (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap())
        .collect()
}

#[test]
fn every_quality_draws_the_legacy_picture() {
    let (world, camera) = pile();
    let context = GpuContext::headless().expect("an adapter (install mesa-vulkan-drivers)");
    let (width, height) = (320, 240);
    let render = |quality: Quality| {
        let mut offscreen = Offscreen::with_quality(&context, width, height, quality).unwrap();
        offscreen
            .render(&context, &world, &camera, DrawSettings::default(), &[])
            .unwrap()
    };
    let legacy = render(Quality::LEGACY);
    let changes = |text: &str| -> Quality { text.parse().unwrap() };
    // (knobs, differing pixels allowed (by more than 2 of 255), largest difference allowed)
    for (quality, differing, largest) in [
        // The same filter as legacy's in other reads: only the bilinear weights' rounding.
        (changes("legacy,filter=gather4"), 0, 2),
        // Another order: where two surfaces have the same depth, the other one wins.
        (
            changes("legacy,order=front-to-back"),
            width * height / 1000,
            255,
        ),
        (changes("legacy,prepass=on"), width * height / 1000, 255),
        // The default's filter and order at legacy's shadow map size.
        (changes("shadow-size=2048"), width * height / 1000, 255),
        (
            changes("prepass=on,shadow-size=2048"),
            width * height / 1000,
            255,
        ),
    ] {
        let image = render(quality);
        let differences = channel_differences(&legacy, &image);
        let over = differences.iter().filter(|&&d| d > 2).count();
        let max = differences.iter().copied().max().unwrap();
        let mean =
            differences.iter().map(|&d| f64::from(d)).sum::<f64>() / differences.len() as f64;
        println!("{quality}: {over} pixels differ by more than 2, at most {max}, mean {mean:.4}");
        assert!(
            over <= differing as usize && max <= largest,
            "{quality}: {over} pixels differ by more than 2 (at most {differing}), largest {max}"
        );
    }
    // Without shadows, the shadowed pixels change (over 1% of the picture); one bilinear tap
    // keeps the shadows and changes only their edges (under a tenth as many pixels).
    let differing = |filter: &str| {
        let quality = changes(&format!("filter={filter}"));
        let over = channel_differences(&legacy, &render(quality))
            .iter()
            .filter(|&&d| d > 2)
            .count();
        println!("{quality}: {over} pixels differ by more than 2");
        over
    };
    let (unshadowed, one_tap) = (differing("off"), differing("tap1"));
    assert!(unshadowed > (width * height / 100) as usize, "{unshadowed}");
    assert!(one_tap < unshadowed / 10, "{one_tap} against {unshadowed}");
    // The default's smaller shadow map moves only shadow edges, as one tap does.
    let over = channel_differences(&legacy, &render(Quality::default()))
        .iter()
        .filter(|&&d| d > 2)
        .count();
    println!("default: {over} pixels differ by more than 2");
    assert!(over < unshadowed / 10, "{over} against {unshadowed}");
}
