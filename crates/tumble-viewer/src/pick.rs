//! Picking with the mouse: the ray under the cursor grabs the dynamic body it hits first, at
//! the hit point, and the world pulls that point towards a target with its drag, a soft point
//! constraint ([`World::set_drag_target`]). As the cursor moves, the target is the point under
//! it on the plane through the picked point facing the camera: the grabbed point follows the
//! cursor across the screen at the depth where it was picked.
//!
//! Pure functions of the camera, the cursor and the world, so they are unit-tested without a
//! window; [`InputState`](crate::input::InputState) calls them.

use glam::Vec3;
use tumble::collision::ray::Ray;
use tumble::{BodyHandle, QueryFilter, World};

use crate::camera::Camera;

/// The drag's largest force, in weights of the grabbed body: enough to lift it briskly, not
/// enough to fling it (tumble's tests/engine/drag.rs: at 10 weights a box's top reaches a target 1.5 m
/// up within 1 cm in 0.3 s, without overshooting).
pub const DRAG_FORCE_PER_WEIGHT: f32 = 10.0;
/// Weight per kilogram (N / kg) the drag's force is sized by in a world with weaker or no
/// gravity, so that a body can still be pulled there.
const MIN_WEIGHT_PER_KG: f32 = 9.81;

/// A body held by the mouse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grab {
    pub body: BodyHandle,
    /// The grabbed point in the body's frame (m).
    pub local_anchor: Vec3,
    /// Where the cursor's ray hit the body (world frame, m); the drag plane passes through it.
    pub picked_at: Vec3,
    /// Where the grabbed point is pulled (world frame, m).
    pub target: Vec3,
    /// The drag's largest force (N).
    pub max_force: f32,
}

impl Grab {
    /// Hands the drag to the world: pull [`local_anchor`](Self::local_anchor) to
    /// [`target`](Self::target).
    pub fn apply(&self, world: &mut World) -> Result<(), tumble::BodyError> {
        world.set_drag_target(self.body, self.local_anchor, self.target, self.max_force)
    }
}

/// The dynamic body under the pixel `cursor` of a `viewport` (pixels) seen by `camera`,
/// grabbed where the ray hits it, its target still at that point. `None` when the ray hits
/// nothing or a static body first (clicking the ground does not pick what lies under it).
pub fn pick(
    world: &World,
    camera: &Camera,
    cursor: (f32, f32),
    viewport: (u32, u32),
) -> Option<Grab> {
    let (origin, direction) = camera.ray_through(cursor, viewport);
    // Not finite only for a degenerate camera: nothing is under the cursor then.
    let ray = Ray::new(origin, direction, f32::INFINITY).ok()?;
    let hit = world.cast_ray(&ray, &QueryFilter::default())?;
    if !world.is_dynamic(hit.body).ok()? {
        return None;
    }
    let desc = world.body_desc(hit.body).ok()?;
    let pose = world.pose(hit.body).ok()?;
    let gravity = world.config().gravity.length().max(MIN_WEIGHT_PER_KG);
    Some(Grab {
        body: hit.body,
        local_anchor: pose.inverse_transform_point(hit.point),
        picked_at: hit.point,
        target: hit.point,
        max_force: DRAG_FORCE_PER_WEIGHT * desc.mass * gravity,
    })
}

/// Where the ray from `origin` along `direction` crosses the plane through `point` with
/// `normal`; `None` when it runs along the plane or crosses it behind the origin.
pub fn ray_plane(origin: Vec3, direction: Vec3, point: Vec3, normal: Vec3) -> Option<Vec3> {
    let approach = direction.dot(normal);
    // Parallel within float noise: the crossing would be arbitrarily far away.
    if approach.abs() <= 1.0e-6 * direction.length() * normal.length() {
        return None;
    }
    let along = (point - origin).dot(normal) / approach;
    let crossing = origin + along * direction;
    (along >= 0.0 && crossing.is_finite()).then_some(crossing)
}

/// The drag's target for the pixel `cursor`: the point under it on the plane through
/// `picked_at` that faces `camera` (normal along its view direction). `None` when that plane
/// is behind the camera, e.g. after orbiting past the picked point.
pub fn drag_target(
    camera: &Camera,
    cursor: (f32, f32),
    viewport: (u32, u32),
    picked_at: Vec3,
) -> Option<Vec3> {
    let (origin, direction) = camera.ray_through(cursor, viewport);
    ray_plane(origin, direction, picked_at, camera.forward())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble::{BodyDesc, Shape, StepConfig};

    #[test]
    fn a_ray_crosses_a_plane_where_it_meets_it() {
        let origin = Vec3::new(1.0, 5.0, 2.0);
        // Down at 45° onto the plane y = 1.
        let hit = ray_plane(
            origin,
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(-7.0, 1.0, 3.0),
            Vec3::Y,
        );
        assert_eq!(hit, Some(Vec3::new(5.0, 1.0, 2.0)));
        // The normal's sign and length do not matter.
        let flipped = ray_plane(origin, Vec3::new(1.0, -1.0, 0.0), Vec3::Y, -3.0 * Vec3::Y);
        assert_eq!(flipped, hit);
        // Along the plane, or away from it: no crossing.
        assert_eq!(ray_plane(origin, Vec3::X, Vec3::Y, Vec3::Y), None);
        assert_eq!(ray_plane(origin, Vec3::Y, Vec3::Y, Vec3::Y), None);
    }

    #[test]
    fn the_drag_target_stays_on_the_plane_facing_the_camera() {
        let camera = Camera::look_at(Vec3::new(3.0, 4.0, 8.0), Vec3::new(0.0, 1.0, 0.0));
        let viewport = (800, 600);
        let picked_at = Vec3::new(0.5, 1.5, 0.5);
        let forward = camera.forward();
        for cursor in [(400.0, 300.0), (10.0, 20.0), (790.0, 590.0), (600.0, 100.0)] {
            let target = drag_target(&camera, cursor, viewport, picked_at).unwrap();
            // On the plane through the picked point, at right angles to the view...
            assert!((target - picked_at).dot(forward).abs() < 1e-4, "{target}");
            // ... and under the cursor.
            let (origin, direction) = camera.ray_through(cursor, viewport);
            let along = (target - origin).dot(direction);
            assert!((origin + along * direction - target).length() < 1e-4);
        }
        // The cursor where the picked point projects: the target is the picked point.
        let clip = camera.view_projection(800.0 / 600.0) * picked_at.extend(1.0);
        let ndc = clip.truncate() / clip.w;
        let cursor = ((ndc.x + 1.0) * 400.0, (1.0 - ndc.y) * 300.0);
        let target = drag_target(&camera, cursor, viewport, picked_at).unwrap();
        assert!((target - picked_at).length() < 1e-4, "{target}");
        // A plane behind the eye is never crossed.
        let behind = camera.eye() - 2.0 * forward;
        assert_eq!(drag_target(&camera, (400.0, 300.0), viewport, behind), None);
    }

    #[test]
    fn pick_grabs_the_first_dynamic_body_under_the_cursor() {
        let mut world = World::new(StepConfig::default()).unwrap();
        world
            .add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)))
            .unwrap();
        let mut heavy =
            BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5))).position(Vec3::new(0.0, 0.5, 0.0));
        heavy.mass = 4.0;
        let cube = world.add_body(heavy).unwrap();
        let camera = Camera::look_at(Vec3::new(0.0, 0.5, 5.0), Vec3::new(0.0, 0.5, 0.0));
        let viewport = (640, 480);

        // The centre of the picture looks at the middle of the cube's front face.
        let grab = pick(&world, &camera, (320.0, 240.0), viewport).unwrap();
        assert_eq!(grab.body, cube);
        assert!(
            (grab.picked_at - Vec3::new(0.0, 0.5, 0.5)).length() < 1e-4,
            "{grab:?}"
        );
        assert!((grab.local_anchor - Vec3::new(0.0, 0.0, 0.5)).length() < 1e-4);
        assert_eq!(grab.target, grab.picked_at);
        assert!((grab.max_force - DRAG_FORCE_PER_WEIGHT * 4.0 * 9.81).abs() < 1e-3);

        // The ground under the cube is static, and the sky is empty.
        assert_eq!(pick(&world, &camera, (320.0, 470.0), viewport), None);
        assert_eq!(pick(&world, &camera, (320.0, 5.0), viewport), None);
    }
}
