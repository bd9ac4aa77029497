//! The `raycast` scene of Bullet's benchmark demo: about 1000 primitives (boxes, spheres,
//! capsules) dropped on a landscape triangle mesh, and a fan of 1000 rays cast through the
//! world every step.
//!
//! The landscape is `scene::landscape` at the same scale (about 100 000 triangles at scale 1),
//! its side about 2.8 times the primitives' grid, so the fan's cone, which reaches a little past
//! the grid's corners, ends on it. The fan is [`RayFan`]: the CLI casts it after each step with
//! [`World::step_then`], so its profiler scope `raycast` shows in the step's report.

use rayon::prelude::*;
use std::time::Instant;

use crate::collision::ray::Ray;
use crate::dynamics::body::BodyDesc;
use crate::math::{Quat, Vec3};
use crate::pipeline::config::StepConfig;
use crate::pipeline::query::QueryFilter;
use crate::pipeline::world::World;
use crate::profile::median;
use crate::scene::builtin::landscape_mesh;
use crate::scene::format::{Scene, SceneError};
use crate::scene::landscape::Landscape;
use crate::shape::Shape;

/// Primitives and rays at scale 1, as in Bullet's demo.
const PRIMITIVES: f32 = 1000.0;
const RAYS: f32 = 1000.0;

/// Distance between neighbouring primitives on the ground grid (m).
const PITCH: f32 = 2.5;

/// Height of the fan's apex above the landscape's mean level y = 0 (m).
const APEX_HEIGHT: f32 = 20.0;

/// How far a primitive's lowest point starts above the highest of the surface samples under
/// it (m): the surface is piecewise flat in 1 m cells, and on the hills' gentle curvature it
/// rises less than 2 cm above the samples' plane within a primitive's reach.
const DROP_CLEARANCE: f32 = 0.05;

/// `1000 · scale` primitives on a square grid, cycling box, sphere, capsule (lying down), each
/// a little above the landscape below it, to drop and settle there (spheres and capsules roll
/// on downhill: the hills slope up to about 20°).
pub fn raycast(scale: f32) -> Result<Scene, SceneError> {
    let count = ((PRIMITIVES * scale).round() as usize).max(1);
    let side = (count as f32).sqrt().ceil() as usize;
    let half_span = 0.5 * (side as f32 - 1.0) * PITCH;
    let landscape = Landscape::new(scale);
    let mut scene = Scene::new(StepConfig::default());
    scene
        .bodies
        .push(BodyDesc::fixed(Shape::trimesh(landscape_mesh(&landscape)?)).name("landscape"));
    // Highest surface point among the centre and 8 points around it at `reach` (m); off the
    // landscape (not at the scales the scene is built for) the level y = 0.
    let highest_ground = |x: f32, z: f32, reach: f32| {
        let mut highest = f32::NEG_INFINITY;
        for dx in [-reach, 0.0, reach] {
            for dz in [-reach, 0.0, reach] {
                highest = highest.max(landscape.height_at(x + dx, z + dz).unwrap_or(0.0));
            }
        }
        highest
    };
    for index in 0..count {
        let (i, j) = (index % side, index / side);
        let x = i as f32 * PITCH - half_span;
        let z = j as f32 * PITCH - half_span;
        // (shape, rotation, half height, horizontal reach (m)).
        let (shape, rotation, half_height, reach) = match index % 3 {
            0 => (
                Shape::cuboid(Vec3::new(0.5, 0.4, 0.6)),
                Quat::IDENTITY,
                0.4,
                0.6,
            ),
            1 => (Shape::sphere(0.5), Quat::IDENTITY, 0.5, 0.5),
            // Lying along X.
            _ => (
                Shape::capsule(0.3, 0.5),
                Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
                0.3,
                0.8,
            ),
        };
        let y = highest_ground(x, z, reach) + half_height + DROP_CLEARANCE;
        scene.bodies.push(
            BodyDesc::dynamic(shape)
                .position(Vec3::new(x, y, z))
                .rotation(rotation),
        );
    }
    Ok(scene)
}

/// A fan of rays from one apex above the middle of the scene, spread evenly (a golden-angle
/// spiral) over a downward cone that covers the grid of [`raycast`] at the same scale.
#[derive(Clone, Debug)]
pub struct RayFan {
    rays: Vec<Ray>,
    /// Wall time of each [`RayFan::cast`] (ms).
    cast_ms: Vec<f64>,
    last_hits: usize,
}

/// What the fan saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayFanStats {
    pub rays: usize,
    /// Rays that hit something in the last cast.
    pub hits: usize,
    /// Median over the casts of (wall time / rays) (µs).
    pub us_per_ray: f64,
}

impl RayFan {
    /// `1000 · scale` rays (at least 1) for the [`raycast`] scene at `scale`.
    pub fn new(scale: f32) -> Self {
        let count = ((RAYS * scale).round() as usize).max(1);
        let primitives = ((PRIMITIVES * scale).round() as usize).max(1);
        let half_span = 0.5 * (primitives as f32).sqrt().ceil() * PITCH;
        // The cone reaches the grid's corners on the ground, and a little past them.
        let max_angle = (1.1 * half_span * std::f32::consts::SQRT_2 / APEX_HEIGHT).atan();
        let apex = Vec3::new(0.0, APEX_HEIGHT, 0.0);
        let golden_angle = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
        let rays = (0..count)
            .map(|k| {
                // Equal solid angle per ray: cos θ uniform over the cap.
                let u = (k as f32 + 0.5) / count as f32;
                let cos_theta = 1.0 - u * (1.0 - max_angle.cos());
                let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
                let phi = k as f32 * golden_angle;
                let direction = Vec3::new(sin_theta * phi.cos(), -cos_theta, sin_theta * phi.sin());
                Ray::new(apex, direction, 2.0 * APEX_HEIGHT / max_angle.cos())
                    .expect("a unit direction from a finite apex is a valid ray")
            })
            .collect();
        Self {
            rays,
            cast_ms: Vec::new(),
            last_hits: 0,
        }
    }

    /// The fan for the built-in scene `name` at `scale`: `Some` for `raycast` only.
    pub fn for_scene(name: &str, scale: f32) -> Option<Self> {
        (name == "raycast").then(|| Self::new(scale))
    }

    pub fn rays(&self) -> &[Ray] {
        &self.rays
    }

    /// Casts every ray for its closest hit, in parallel, inside the profiler scope `raycast`;
    /// returns how many rays hit. The count does not depend on the thread count: each ray's
    /// closest hit is deterministic.
    pub fn cast(&mut self, world: &mut World) -> usize {
        world.profiler_mut().begin("raycast");
        let start = Instant::now();
        let world_ref = &*world;
        // A filter per ray: its predicate, were there one, need not be shareable across threads.
        let hits = self
            .rays
            .par_iter()
            .filter(|ray| world_ref.cast_ray(ray, &QueryFilter::default()).is_some())
            .count();
        self.cast_ms.push(start.elapsed().as_secs_f64() * 1e3);
        world.profiler_mut().end();
        self.last_hits = hits;
        hits
    }

    pub fn stats(&self) -> RayFanStats {
        let per_ray: Vec<f64> = self
            .cast_ms
            .iter()
            .map(|ms| ms * 1e3 / self.rays.len() as f64)
            .collect();
        RayFanStats {
            rays: self.rays.len(),
            hits: self.last_hits,
            us_per_ray: median(&per_ray),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn talk_size_and_every_primitive_kind() {
        let scene = raycast(1.0).unwrap();
        assert_eq!(scene.bodies.len(), 1000 + 1);
        let Shape::TriMesh(mesh) = &scene.bodies[0].shape else {
            panic!("the ground is the landscape mesh")
        };
        assert!((99_000..=101_000).contains(&mesh.triangles().len()));
        assert_eq!(RayFan::new(1.0).rays().len(), 1000);
        assert_eq!(raycast(0.001).unwrap().bodies.len(), 2);
    }

    /// The bodies land on the landscape and stay on it (none falls through; balls and capsules
    /// roll downhill and knock boxes about), and the fan hits both them and the landscape:
    /// every ray ends on something, the one straight along a grid line included.
    #[test]
    fn primitives_land_and_rays_hit() {
        let scale = 0.05;
        let landscape = Landscape::new(scale);
        let mut world = raycast(scale).unwrap().build().unwrap();
        let mut fan = RayFan::new(scale);
        let mut hits = 0;
        for _ in 0..90 {
            hits = world.step_then(|world| fan.cast(world));
        }
        assert_eq!(
            hits,
            fan.rays().len(),
            "every ray meets the landscape or a body"
        );
        for (index, body) in world.bodies().enumerate().skip(1) {
            let position = world.pose(body).unwrap().position;
            let ground = landscape.height_at(position.x, position.z).unwrap();
            // Every centre is at least 0.3 m (the smallest half height) over the ground, less
            // the penetration slop and a slope's lean.
            assert!(
                position.y - ground > 0.2,
                "body {index} at {position:?}, ground at {ground}"
            );
        }
        let filter = QueryFilter::default().exclude_static();
        let on_bodies = fan
            .rays()
            .iter()
            .filter(|ray| world.cast_ray(ray, &filter).is_some())
            .count();
        assert!(on_bodies > 0 && on_bodies < fan.rays().len());
        let stats = fan.stats();
        assert_eq!((stats.rays, stats.hits), (50, 50));
        assert!(stats.us_per_ray > 0.0);
        assert!(
            world
                .profiler()
                .report()
                .stage_ms()
                .iter()
                .any(|(name, _)| *name == "raycast")
        );
    }
}
