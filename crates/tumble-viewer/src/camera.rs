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

    /// A camera that sees the bounding box of `world`'s dynamic bodies whole, from above and to
    /// the side: the bodies are what moves, and a landscape under them can be a hundred times
    /// their extent. With no dynamic body it frames the finite static bodies (infinite planes
    /// are left out); a world with nothing else looks at the origin from 10 m.
    pub fn framing(world: &World) -> Self {
        let (center, radius) = match dynamic_bounds(world).or_else(|| finite_bounds(world)) {
            Some(aabb) => (aabb.center(), aabb.half_extents().length().max(0.5)),
            None => (Vec3::ZERO, 4.0),
        };
        // The bounding sphere fits the narrower (vertical) field of view, with a 10% margin.
        let distance = 1.1 * radius / (FOV_Y * 0.5).sin();
        Self {
            target: center,
            distance,
            yaw: DEFAULT_YAW,
            pitch: DEFAULT_PITCH,
        }
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

/// Union of the world AABBs of every body that is not a plane.
pub fn finite_bounds(world: &World) -> Option<Aabb> {
    world
        .bodies()
        .filter_map(|handle| {
            let shape = world.body_desc(handle).ok()?.shape;
            if matches!(shape, Shape::Plane(_)) {
                return None;
            }
            Some(shape.aabb(&world.pose(handle).ok()?))
        })
        .reduce(|a, b| a.union(&b))
}

/// Union of the world AABBs of the dynamic bodies.
pub fn dynamic_bounds(world: &World) -> Option<Aabb> {
    world
        .bodies()
        .filter(|&handle| world.is_dynamic(handle).unwrap_or(false))
        .filter_map(|handle| {
            let shape = world.body_desc(handle).ok()?.shape;
            Some(shape.aabb(&world.pose(handle).ok()?))
        })
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

    fn fixed(world: &mut World, shape: Shape) {
        world.add_body(tumble::BodyDesc::fixed(shape)).unwrap();
    }

    #[test]
    fn framing_follows_the_dynamic_bodies() {
        let mut world = World::new(tumble::StepConfig::default()).unwrap();
        fixed(&mut world, Shape::plane(Vec3::Y, 0.0));
        // A floor 200 m wide, far larger than the bodies on it.
        fixed(&mut world, Shape::cuboid(Vec3::new(100.0, 0.5, 100.0)));
        let floor_only = Camera::framing(&world);
        assert!(floor_only.distance > 200.0, "{floor_only:?}");

        for x in [10.0, 12.0] {
            world
                .add_body(
                    tumble::BodyDesc::dynamic(Shape::cuboid(Vec3::splat(0.5)))
                        .position(Vec3::new(x, 1.0, 0.0)),
                )
                .unwrap();
        }
        let camera = Camera::framing(&world);
        assert!((camera.target - Vec3::new(11.0, 1.0, 0.0)).length() < 1e-5);
        // The two boxes span 3 x 1 x 1 m: their bounding sphere fills the view.
        let radius = Vec3::new(1.5, 0.5, 0.5).length();
        let expected = 1.1 * radius / (FOV_Y * 0.5).sin();
        assert!((camera.distance - expected).abs() < 1e-4, "{camera:?}");
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
