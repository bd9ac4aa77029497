//! An orbit camera: a target point, a distance, and yaw / pitch angles around it (Y up).

use glam::{Mat4, Vec3};
use tumble::World;
use tumble::math::Aabb;
use tumble::shape::Shape;

/// Vertical field of view (radians).
const FOV_Y: f32 = 45.0 * std::f32::consts::PI / 180.0;
/// Pitch stays short of straight up or down, where yaw loses its meaning.
const MAX_PITCH: f32 = 89.0 * std::f32::consts::PI / 180.0;
/// The default view looks from 35° right of +Z, 25° above the horizon.
const DEFAULT_YAW: f32 = 35.0 * std::f32::consts::PI / 180.0;
const DEFAULT_PITCH: f32 = 25.0 * std::f32::consts::PI / 180.0;
/// The framed bodies fill the view up to this factor (1.08: 8% of room around them).
const FRAMING_MARGIN: f32 = 1.08;
/// The default camera stays at least this far from what it frames (m), so a single small body
/// is not seen from inside the near plane's reach.
const MIN_FRAMING_DISTANCE: f32 = 1.5;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub target: Vec3,
    /// Eye to target (m), > 0.
    pub distance: f32,
    /// Rotation of the eye about +Y from +Z, towards +X (radians).
    pub yaw: f32,
    /// Elevation of the eye above the target's horizontal plane (radians).
    pub pitch: f32,
}

impl Camera {
    /// The camera at `eye` looking at `target` (a zero distance is moved back by 1 m).
    pub fn look_at(eye: Vec3, target: Vec3) -> Self {
        let offset = eye - target;
        let distance = offset.length();
        if distance <= f32::EPSILON {
            return Self {
                target,
                distance: 1.0,
                yaw: 0.0,
                pitch: 0.0,
            };
        }
        Self {
            target,
            distance,
            yaw: offset.x.atan2(offset.z),
            pitch: (offset.y / distance).clamp(-1.0, 1.0).asin(),
        }
    }

    /// A camera that sees `world`'s dynamic bodies whole on a viewport of `aspect` = width /
    /// height, from above and to the side: the bodies are what moves, and a landscape under
    /// them can be a hundred times their extent. With no dynamic body it frames the finite
    /// static bodies (infinite planes are left out); a world with nothing else looks at the
    /// origin from 10 m.
    ///
    /// Tight framing: the target moves until the bodies sit in the middle of the picture, and
    /// the eye backs off just far enough that every corner of every framed body's bounding box
    /// fits inside both fields of view with a [`FRAMING_MARGIN`]. A flat pile seen from 25°
    /// above fills the picture's width, not the height of its bounding sphere.
    pub fn framing(world: &World, aspect: f32) -> Self {
        let mut boxes = framed_boxes(world, true);
        if boxes.is_empty() {
            boxes = framed_boxes(world, false);
        }
        Self::framing_boxes(&boxes, aspect)
    }

    /// The camera of [`Self::framing`] for `boxes` (none: the origin from 10 m).
    pub fn framing_boxes(boxes: &[Aabb], aspect: f32) -> Self {
        let mut camera = Self {
            target: Vec3::ZERO,
            distance: 10.0,
            yaw: DEFAULT_YAW,
            pitch: DEFAULT_PITCH,
        };
        let Some(bounds) = boxes.iter().copied().reduce(|a, b| a.union(&b)) else {
            return camera;
        };
        let corners: Vec<Vec3> = boxes.iter().flat_map(corners).collect();
        camera.target = bounds.center();
        // Centring changes the distance needed and the other way round; two rounds settle it
        // within a few pixels.
        for _ in 0..2 {
            camera.distance = camera.fitting_distance(&corners, aspect);
            camera.centre_on(&corners, aspect);
        }
        camera.distance = camera
            .fitting_distance(&corners, aspect)
            .max(MIN_FRAMING_DISTANCE);
        camera
    }

    /// The camera's frame: from the target towards the eye, then right and up across the view.
    fn axes(&self) -> (Vec3, Vec3, Vec3) {
        let back = Self {
            target: Vec3::ZERO,
            distance: 1.0,
            ..*self
        }
        .eye();
        let right = Vec3::Y.cross(back).normalize();
        (back, right, back.cross(right))
    }

    /// Tangents of the half fields of view (horizontal, vertical), shrunk by the margin.
    fn framing_tangents(aspect: f32) -> (f32, f32) {
        let tan_y = (FOV_Y * 0.5).tan() / FRAMING_MARGIN;
        (tan_y * aspect, tan_y)
    }

    /// The smallest distance from the target at which every point lies inside the view
    /// (shrunk by [`FRAMING_MARGIN`]) of this camera's direction on a viewport of `aspect`.
    fn fitting_distance(&self, points: &[Vec3], aspect: f32) -> f32 {
        let (back, right, up) = self.axes();
        let (tan_x, tan_y) = Self::framing_tangents(aspect);
        points
            .iter()
            .map(|&point| {
                // The point is at depth (distance - z) in front of the eye, and in view while
                // |x| <= tan_x * depth and |y| <= tan_y * depth.
                let offset = point - self.target;
                let need_x = offset.dot(right).abs() / tan_x;
                let need_y = offset.dot(up).abs() / tan_y;
                offset.dot(back) + need_x.max(need_y)
            })
            .fold(0.0, f32::max)
    }

    /// Moves the target across the view so the points' extent in the picture is centred.
    fn centre_on(&mut self, points: &[Vec3], aspect: f32) {
        let (back, right, up) = self.axes();
        let (tan_x, tan_y) = Self::framing_tangents(aspect);
        let (mut low, mut high) = (glam::Vec2::MAX, glam::Vec2::MIN);
        for &point in points {
            let offset = point - self.target;
            let depth = (self.distance - offset.dot(back)).max(1.0e-3);
            let seen = glam::Vec2::new(
                offset.dot(right) / (depth * tan_x),
                offset.dot(up) / (depth * tan_y),
            );
            low = low.min(seen);
            high = high.max(seen);
        }
        // A shift of the picture's middle, turned back into metres at the target's depth.
        let middle = 0.5 * (low + high);
        self.target += self.distance * (right * middle.x * tan_x + up * middle.y * tan_y);
    }

    pub fn eye(&self) -> Vec3 {
        let (sin_yaw, cos_yaw) = self.yaw.sin_cos();
        let (sin_pitch, cos_pitch) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(cos_pitch * sin_yaw, sin_pitch, cos_pitch * cos_yaw)
    }

    /// World to clip space for a viewport of `aspect` = width / height; depth 0 (near) to 1.
    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        // The near plane follows the distance so that depth precision follows the zoom; the far
        // plane leaves room for the ground grid, which reaches several scene sizes out.
        let near = (self.distance * 0.01).max(1.0e-3);
        let far = self.distance * 100.0;
        let view = glam::camera::rh::view::look_at_mat4(self.eye(), self.target, Vec3::Y);
        // wgpu's clip space is DirectX's: y up, depth 0 to 1.
        glam::camera::rh::proj::directx::perspective(FOV_Y, aspect, near, far) * view
    }

    /// The camera's view direction (unit): from the eye towards the target.
    pub fn forward(&self) -> Vec3 {
        -self.axes().0
    }

    /// The ray from the eye through the pixel `cursor` (x right, y down, from the top-left
    /// corner) of a `viewport` of (width, height) pixels: (origin, unit direction). It is the
    /// inverse of [`view_projection`](Self::view_projection) at that aspect: every point on it
    /// projects to `cursor`. A zero viewport side counts as 1 pixel.
    pub fn ray_through(&self, cursor: (f32, f32), viewport: (u32, u32)) -> (Vec3, Vec3) {
        let (width, height) = (viewport.0.max(1) as f32, viewport.1.max(1) as f32);
        // Normalized device coordinates: -1..1 across the picture, y up.
        let ndc_x = 2.0 * cursor.0 / width - 1.0;
        let ndc_y = 1.0 - 2.0 * cursor.1 / height;
        let tan_y = (FOV_Y * 0.5).tan();
        let tan_x = tan_y * width / height;
        let (back, right, up) = self.axes();
        let direction = -back + right * (ndc_x * tan_x) + up * (ndc_y * tan_y);
        (self.eye(), direction.normalize())
    }

    /// Turns the eye around the target (radians).
    pub fn orbit(&mut self, yaw: f32, pitch: f32) {
        self.yaw += yaw;
        self.pitch = (self.pitch + pitch).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Moves the eye towards (`factor` < 1) or away from (> 1) the target.
    pub fn zoom(&mut self, factor: f32) {
        self.distance = (self.distance * factor).max(1.0e-2);
    }
}

/// World AABBs of the dynamic bodies (`dynamic`) or of every body that is not a plane.
fn framed_boxes(world: &World, dynamic: bool) -> Vec<Aabb> {
    world
        .bodies()
        .filter(|&handle| !dynamic || world.is_dynamic(handle).unwrap_or(false))
        .filter_map(|handle| {
            let shape = world.body_desc(handle).ok()?.shape;
            if matches!(shape, Shape::Plane(_)) {
                return None;
            }
            Some(shape.aabb(&world.pose(handle).ok()?))
        })
        .collect()
}

fn corners(aabb: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        Vec3::new(
            if i & 1 == 0 { aabb.min.x } else { aabb.max.x },
            if i & 2 == 0 { aabb.min.y } else { aabb.max.y },
            if i & 4 == 0 { aabb.min.z } else { aabb.max.z },
        )
    })
}

/// Union of the world AABBs of every body that is not a plane.
pub fn finite_bounds(world: &World) -> Option<Aabb> {
    framed_boxes(world, false)
        .into_iter()
        .reduce(|a, b| a.union(&b))
}

/// Union of the world AABBs of the dynamic bodies.
pub fn dynamic_bounds(world: &World) -> Option<Aabb> {
    framed_boxes(world, true)
        .into_iter()
        .reduce(|a, b| a.union(&b))
}

/// Parses `--camera eye_x,eye_y,eye_z,target_x,target_y,target_z` (metres).
pub fn parse_camera(text: &str) -> Result<Camera, String> {
    let numbers: Vec<f32> = text
        .split(',')
        .map(|part| {
            part.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{part:?} is not a finite number"))
        })
        .collect::<Result<_, _>>()?;
    let [ex, ey, ez, tx, ty, tz] = numbers[..] else {
        return Err(format!(
            "expected 6 numbers eye_x,eye_y,eye_z,target_x,target_y,target_z, got {}",
            numbers.len()
        ));
    };
    let (eye, target) = (Vec3::new(ex, ey, ez), Vec3::new(tx, ty, tz));
    if eye == target {
        return Err("the eye and the target are the same point".into());
    }
    Ok(Camera::look_at(eye, target))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_round_trips_the_eye() {
        let eye = Vec3::new(3.0, 4.0, -5.0);
        let target = Vec3::new(1.0, 0.5, 2.0);
        let camera = Camera::look_at(eye, target);
        assert!((camera.eye() - eye).length() < 1e-4, "{:?}", camera.eye());
    }

    #[test]
    fn the_target_projects_to_the_centre() {
        let camera = Camera::look_at(Vec3::new(2.0, 3.0, 6.0), Vec3::new(0.0, 1.0, 0.0));
        let clip = camera.view_projection(4.0 / 3.0) * Vec3::new(0.0, 1.0, 0.0).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        assert!(ndc.x.abs() < 1e-5 && ndc.y.abs() < 1e-5);
        assert!((0.0..1.0).contains(&ndc.z));
    }

    #[test]
    fn the_centre_pixel_unprojects_to_the_forward_ray() {
        let camera = Camera::look_at(Vec3::new(2.0, 3.0, 6.0), Vec3::new(0.0, 1.0, 0.0));
        for viewport in [(800, 600), (600, 800), (1, 1)] {
            let centre = (viewport.0 as f32 / 2.0, viewport.1 as f32 / 2.0);
            let (origin, direction) = camera.ray_through(centre, viewport);
            assert!((origin - camera.eye()).length() < 1e-5, "{origin}");
            let forward = (camera.target - camera.eye()).normalize();
            assert!(
                (direction - forward).length() < 1e-5,
                "{direction} vs {forward}"
            );
            assert!((camera.forward() - forward).length() < 1e-5);
        }
    }

    #[test]
    fn a_projected_point_unprojects_onto_the_ray_through_it() {
        let camera = Camera::look_at(Vec3::new(-3.0, 4.0, 5.0), Vec3::new(0.5, 0.0, -1.0));
        let viewport = (1280, 720);
        let aspect = 1280.0 / 720.0;
        for point in [
            Vec3::new(0.5, 0.0, -1.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(-1.5, -0.5, -3.0),
            Vec3::new(1.0, 2.5, 1.0),
        ] {
            // To the pixel, as the renderer and the headless tests map clip space.
            let p = ndc(&camera, aspect, point);
            assert!(p.x.abs() < 1.0 && p.y.abs() < 1.0, "{point} out of view");
            let cursor = (
                (p.x + 1.0) * 0.5 * viewport.0 as f32,
                (1.0 - p.y) * 0.5 * viewport.1 as f32,
            );
            let (origin, direction) = camera.ray_through(cursor, viewport);
            let along = (point - origin).dot(direction);
            let miss = (origin + along * direction - point).length();
            assert!(along > 0.0 && miss < 1e-4, "{point}: {miss} m off the ray");
        }
    }

    fn fixed(world: &mut World, shape: Shape) {
        world.add_body(tumble::BodyDesc::fixed(shape)).unwrap();
    }

    /// Where `point` lands in normalized device coordinates (x, y in -1..1 when in view).
    fn ndc(camera: &Camera, aspect: f32, point: Vec3) -> Vec3 {
        let clip = camera.view_projection(aspect) * point.extend(1.0);
        clip.truncate() / clip.w
    }

    #[test]
    fn framing_follows_the_dynamic_bodies() {
        let mut world = World::new(tumble::StepConfig::default()).unwrap();
        fixed(&mut world, Shape::plane(Vec3::Y, 0.0));
        // A floor 200 m wide, far larger than the bodies on it.
        fixed(&mut world, Shape::cuboid(Vec3::new(100.0, 0.5, 100.0)));
        let floor_only = Camera::framing(&world, 16.0 / 9.0);
        assert!(floor_only.distance > 100.0, "{floor_only:?}");

        for x in [10.0, 12.0] {
            world
                .add_body(
                    tumble::BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                        .position(Vec3::new(x, 1.0, 0.0)),
                )
                .unwrap();
        }
        let camera = Camera::framing(&world, 16.0 / 9.0);
        assert!(
            (camera.target - Vec3::new(11.0, 1.0, 0.0)).length() < 0.5,
            "{camera:?}"
        );
        assert!(camera.distance < 10.0, "{camera:?}");
    }

    #[test]
    fn framing_fits_and_centres_the_bodies_at_any_aspect() {
        // A flat pile 20 x 1 x 20 m, as the falling scenes leave their bodies: a box at each
        // of its corners.
        let mut world = World::new(tumble::StepConfig::default()).unwrap();
        let mut corners = Vec::new();
        for (x, z) in [(-9.5, -9.5), (9.5, -9.5), (-9.5, 9.5), (9.5, 9.5)] {
            let aabb = Aabb {
                min: Vec3::new(x - 0.5, 0.0, z - 0.5),
                max: Vec3::new(x + 0.5, 1.0, z + 0.5),
            };
            corners.extend(super::corners(&aabb));
            world
                .add_body(
                    tumble::BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                        .position(aabb.center()),
                )
                .unwrap();
        }
        for aspect in [16.0 / 9.0, 1.0, 0.5] {
            let camera = Camera::framing(&world, aspect);
            let (mut low, mut high) = (Vec3::MAX, Vec3::MIN);
            for &corner in &corners {
                let p = ndc(&camera, aspect, corner);
                assert!(
                    p.x.abs() <= 1.0 && p.y.abs() <= 1.0,
                    "{corner} at {p}, {aspect}"
                );
                low = low.min(p);
                high = high.max(p);
            }
            // Tight: the bodies reach the margin on one axis or the other...
            let reach = high.max(-low);
            let widest = reach.x.max(reach.y);
            assert!(
                (widest - 1.0 / FRAMING_MARGIN).abs() < 0.01,
                "aspect {aspect}: corners reach {reach}"
            );
            // ... and sit in the middle of the picture.
            let middle = 0.5 * (low + high);
            assert!(
                middle.x.abs() < 0.02 && middle.y.abs() < 0.02,
                "aspect {aspect}: middle {middle}"
            );
        }
    }

    #[test]
    fn camera_argument() {
        let camera = parse_camera("0,2,10, 0,0,0").unwrap();
        assert!((camera.eye() - Vec3::new(0.0, 2.0, 10.0)).length() < 1e-4);
        assert!(parse_camera("1,2,3").is_err());
        assert!(parse_camera("1,2,3,4,5,x").is_err());
        assert!(parse_camera("1,2,3,1,2,3").is_err());
        assert!(parse_camera("1,2,3,4,5,inf").is_err());
    }
}
