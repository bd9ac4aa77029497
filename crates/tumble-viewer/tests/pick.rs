//! The mouse drag through the viewer's input path, with no window: a press on a box picks it,
//! moving the cursor up lifts it after the cursor as the world steps, and letting go drops it.

use glam::Vec3;
use tumble::{BodyDesc, Shape, StepConfig, World};
use tumble_viewer::Camera;
use tumble_viewer::input::{InputState, MouseButton};

const VIEWPORT: (u32, u32) = (640, 480);

/// The pixel where `point` projects, as the renderer maps clip space to the picture.
fn pixel(camera: &Camera, point: Vec3) -> (f32, f32) {
    let clip = camera.view_projection(VIEWPORT.0 as f32 / VIEWPORT.1 as f32) * point.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    (
        (ndc.x + 1.0) * 0.5 * VIEWPORT.0 as f32,
        (1.0 - ndc.y) * 0.5 * VIEWPORT.1 as f32,
    )
}

#[test]
fn dragging_a_box_with_the_mouse_lifts_it_and_letting_go_drops_it() {
    let mut world = World::new(StepConfig::default()).unwrap();
    world
        .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
        .unwrap();
    let start = Vec3::new(0.0, 0.5, 0.0);
    let cube = world
        .add_body(BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(start))
        .unwrap();
    let camera = Camera::look_at(Vec3::new(1.0, 1.5, 6.0), start);
    let mut input = InputState::new(camera, VIEWPORT);

    let on_the_box = pixel(&camera, start);
    input.mouse_button(MouseButton::Left, true, on_the_box, Some(&mut world));
    let grab = *input.grab().expect("the press is on the box");
    assert_eq!(grab.body, cube);
    // The cursor a quarter of the picture higher.
    let cursor = (on_the_box.0, on_the_box.1 - VIEWPORT.1 as f32 / 4.0);
    input.cursor_moved(cursor, Some(&mut world));
    let target = input.grab().unwrap().target;
    assert!(target.y > grab.picked_at.y + 1.0, "{target}");
    // The target lies under the cursor.
    let seen = pixel(&camera, target);
    assert!(
        (seen.0 - cursor.0).abs() < 0.5 && (seen.1 - cursor.1).abs() < 0.5,
        "{seen:?}"
    );

    for _ in 0..120 {
        world.step();
    }
    let pose = world.pose(cube).unwrap();
    let grabbed = pose.transform_point(grab.local_anchor);
    println!(
        "after 2 s: the box's centre at {}, the grabbed point {:.1} mm from the target",
        pose.position,
        (grabbed - target).length() * 1e3
    );
    assert!(
        pose.position.y > start.y + 0.8,
        "not lifted: {}",
        pose.position
    );
    assert!((grabbed - target).length() < 0.05, "{grabbed} vs {target}");
    // The camera stayed put while the box was dragged.
    assert_eq!(input.camera, camera);

    input.mouse_button(MouseButton::Left, false, cursor, Some(&mut world));
    assert_eq!(input.grab(), None);
    for _ in 0..120 {
        world.step();
    }
    let y = world.pose(cube).unwrap().position.y;
    assert!(y < start.y + 0.05, "let go, the box still hangs at {y}");
}
