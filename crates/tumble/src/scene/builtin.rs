//! The talk's scenes, sized as in Bullet's benchmark demo, each with a `scale` so they run from
//! tiny (tests) to huge (benchmarks). `scale = 1` is the talk's size.

use crate::dynamics::body::BodyDesc;
use crate::math::Vec3;
use crate::pipeline::config::StepConfig;
use crate::scene::format::{Scene, SceneError};
use crate::scene::landscape::Landscape;
use crate::scene::ragdoll::{RAGDOLL_HALF_SPAN, add_ragdoll, arms_along_z};
use crate::scene::raycast::raycast;
use crate::shape::Shape;

/// Built-in scene names with a line on each.
pub const BUILTIN_SCENES: &[(&str, &str)] = &[
    (
        "falling-boxes",
        "3008 boxes (47 layers of 8 x 8) falling on a ground plane",
    ),
    (
        "stacked-boxes",
        "about 1000 boxes at rest: a pyramid, a brick wall and a tower",
    ),
    (
        "ragdolls",
        "136 ragdolls (11 capsules, hinges and cone-twists) in a pyramid 16 + 15 + ... + 1 falling on a plane",
    ),
    (
        "convex-hulls",
        "1000 barrel-like convex hulls (40 points) in 10 layers of 10 x 10 falling on a plane",
    ),
    (
        "convex-trimesh",
        "the 1000 barrels of convex-hulls falling on a generated landscape of about 100k triangles",
    ),
    (
        "compounds",
        "1000 compound bodies, dumbbells (two balls on a rod) and tables (a top on four legs), in 10 layers of 10 x 10 falling on a plane",
    ),
    (
        "raycast",
        "about 1000 boxes, spheres and capsules dropped on a landscape of about 100k triangles, a fan of 1000 rays cast each step",
    ),
];

/// The built-in scene `name` at `scale` (1 = the talk's size; body counts scale linearly).
pub fn builtin(name: &str, scale: f32) -> Result<Scene, SceneError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(SceneError::BadScale(scale));
    }
    match name {
        "falling-boxes" => Ok(falling_boxes(scale)),
        "stacked-boxes" => Ok(stacked_boxes(scale)),
        "ragdolls" => Ok(ragdolls(scale)),
        "convex-hulls" => Ok(convex_hulls(scale)),
        "convex-trimesh" => convex_trimesh(scale),
        "compounds" => Ok(compounds(scale)),
        "raycast" => raycast(scale),
        _ => Err(SceneError::UnknownScene(name.to_string())),
    }
}

fn ground() -> BodyDesc {
    BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0)).name("ground")
}

/// Bullet's BenchmarkDemo test 1: boxes of 2 m on a 3 m pitch, layer after layer, each layer
/// shifted a little so the boxes do not land square on each other.
fn falling_boxes(scale: f32) -> Scene {
    const HALF_EXTENT: f32 = 1.0;
    const PITCH: f32 = 3.0;
    let target = 3008.0 * scale;
    let side = ((8.0 * scale.cbrt()).round() as usize).max(1);
    let layers = ((target / (side * side) as f32).round() as usize).max(1);
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies.push(ground());
    let mut offset = -(side as f32) * PITCH * 0.5;
    let mut y = 2.0 * HALF_EXTENT;
    for _ in 0..layers {
        for j in 0..side {
            for i in 0..side {
                let position = Vec3::new(offset + i as f32 * PITCH, y, offset + j as f32 * PITCH);
                scene.bodies.push(
                    BodyDesc::dynamic(Shape::cuboid(Vec3::splat(HALF_EXTENT))).position(position),
                );
            }
        }
        offset -= 0.05 * (side as f32 - 1.0);
        y += PITCH;
    }
    scene
}

/// The points of a barrel 1 m tall and 1 m across: two rings of 16 points at the widest
/// (y = ±0.35 m, radius 0.5 m) and a square cap of 4 points at each end (y = ±0.5 m, radius
/// 0.3 m), 40 points in all. Symmetric about its centre, so the hull's frame is its own.
pub fn barrel_points() -> Vec<Vec3> {
    const RING: usize = 16;
    let ring = |count: usize, radius: f32, y: f32| {
        (0..count).map(move |k| {
            let angle = std::f32::consts::TAU * k as f32 / count as f32;
            Vec3::new(radius * angle.cos(), y, radius * angle.sin())
        })
    };
    ring(RING, 0.5, -0.35)
        .chain(ring(RING, 0.5, 0.35))
        .chain(ring(4, 0.3, -0.5))
        .chain(ring(4, 0.3, 0.5))
        .collect()
}

/// Bullet's BenchmarkDemo test 6 in spirit: barrels on a 1.5 m pitch, layer after layer, each
/// layer shifted and each barrel tipped a little so they land on rims and tumble.
fn convex_hulls(scale: f32) -> Scene {
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies.push(ground());
    add_barrel_layers(&mut scene, scale, |_, _| 0.0);
    scene
}

/// Bullet's BenchmarkDemo test 7 in spirit: the barrels of [`convex_hulls`] over a landscape
/// mesh of about `100 000 · scale` triangles (`scene::landscape`), each column starting 1 m
/// above the ground below it. The landscape's side grows as the barrels' (both as
/// `sqrt(scale)`), about 15 times theirs, so every barrel lands on it.
fn convex_trimesh(scale: f32) -> Result<Scene, SceneError> {
    let landscape = Landscape::new(scale);
    let mesh = landscape_mesh(&landscape)?;
    let mut scene = Scene::new(StepConfig::default());
    scene
        .bodies
        .push(BodyDesc::fixed(Shape::trimesh(mesh)).name("landscape"));
    add_barrel_layers(&mut scene, scale, |x, z| {
        // The barrels' square (about 15 m at scale 1) lies well inside the landscape.
        landscape.height_at(x, z).unwrap_or(0.0)
    });
    Ok(scene)
}

/// The landscape's mesh; it has no degenerate triangle at any scale, but a mesh error is still
/// reported as the scene's, not a panic.
pub(crate) fn landscape_mesh(landscape: &Landscape) -> Result<crate::shape::TriMesh, SceneError> {
    landscape.mesh().map_err(|error| SceneError::Invalid {
        field: "landscape".into(),
        message: error.to_string(),
    })
}

/// About `1000 · scale` barrels in layers of side × side on a 1.5 m pitch, the lowest 1 m above
/// `ground_height(x, z)` (m) below each column.
fn add_barrel_layers(scene: &mut Scene, scale: f32, ground_height: impl Fn(f32, f32) -> f32) {
    const PITCH: f32 = 1.5;
    let target = 1000.0 * scale;
    let side = ((10.0 * scale.cbrt()).round() as usize).max(1);
    let layers = ((target / (side * side) as f32).round() as usize).max(1);
    // One hull shared by every barrel (`Shape` clones share it).
    let barrel = Shape::convex_hull(&barrel_points()).expect("the barrel encloses volume");
    let mut offset = -(side as f32) * PITCH * 0.5;
    let mut y = 1.0;
    for layer in 0..layers {
        for j in 0..side {
            for i in 0..side {
                let (x, z) = (offset + i as f32 * PITCH, offset + j as f32 * PITCH);
                let position = Vec3::new(x, ground_height(x, z) + y, z);
                let tilt = 0.2 * (((i + 2 * j + 3 * layer) % 5) as f32 - 2.0);
                scene.bodies.push(
                    BodyDesc::dynamic(barrel.clone())
                        .position(position)
                        .rotation(crate::math::Quat::from_rotation_z(tilt)),
                );
            }
        }
        offset -= 0.05 * (side as f32 - 1.0);
        y += PITCH;
    }
}

/// The `convex-hulls` layout with compounds: dumbbells and tables in a checkerboard, each
/// layer turned a quarter turn from the last so bars land across bars.
fn compounds(scale: f32) -> Scene {
    use crate::math::{Quat, Transform};
    use crate::shape::CompoundChild;
    const PITCH: f32 = 2.0;
    let target = 1000.0 * scale;
    let side = ((10.0 * scale.cbrt()).round() as usize).max(1);
    let layers = ((target / (side * side) as f32).round() as usize).max(1);
    let part = |shape: Shape, position: Vec3, rotation: Quat| CompoundChild {
        shape,
        pose: Transform::new(position, rotation),
    };
    // Two 0.25 m balls on a 0.05 m rod, 1.5 m long in all.
    let dumbbell = Shape::compound(vec![
        part(
            Shape::sphere(0.25),
            Vec3::new(-0.5, 0.0, 0.0),
            Quat::IDENTITY,
        ),
        part(
            Shape::capsule(0.05, 0.4),
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
        ),
        part(
            Shape::sphere(0.25),
            Vec3::new(0.5, 0.0, 0.0),
            Quat::IDENTITY,
        ),
    ])
    .expect("the dumbbell's children are convex and sized");
    // A 1.2 x 0.1 x 0.8 m top on four 0.6 m legs.
    let mut table = vec![part(
        Shape::cuboid(Vec3::new(0.6, 0.05, 0.4)),
        Vec3::new(0.0, 0.3, 0.0),
        Quat::IDENTITY,
    )];
    for (x, z) in [(-0.5, -0.3), (0.5, -0.3), (-0.5, 0.3), (0.5, 0.3)] {
        table.push(part(
            Shape::cuboid(Vec3::new(0.05, 0.3, 0.05)),
            Vec3::new(x, -0.05, z),
            Quat::IDENTITY,
        ));
    }
    let table = Shape::compound(table).expect("the table's children are convex and sized");
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies.push(ground());
    let mut offset = -(side as f32) * PITCH * 0.5;
    let mut y = 1.0;
    for layer in 0..layers {
        let turn = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2 * (layer % 2) as f32);
        for j in 0..side {
            for i in 0..side {
                let position = Vec3::new(offset + i as f32 * PITCH, y, offset + j as f32 * PITCH);
                let shape = if (i + j + layer) % 2 == 0 {
                    dumbbell.clone()
                } else {
                    table.clone()
                };
                scene
                    .bodies
                    .push(BodyDesc::dynamic(shape).position(position).rotation(turn));
            }
        }
        offset -= 0.05 * (side as f32 - 1.0);
        y += PITCH;
    }
    scene
}

/// A square pyramid, a brick wall and a tower of 1 m boxes, all resting on the ground.
fn stacked_boxes(scale: f32) -> Scene {
    const HALF: f32 = 0.5;
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies.push(ground());
    // Up to scale 1 the structures shrink (about scale³ of the boxes per dimension cubed);
    // past it, whole copies are set side by side.
    let (size, copies) = if scale < 1.0 {
        (scale.cbrt(), 1)
    } else {
        (1.0, scale.round() as usize)
    };
    let grid = (copies as f32).sqrt().ceil() as usize;
    let cube =
        |position: Vec3| BodyDesc::dynamic(Shape::cuboid(Vec3::splat(HALF))).position(position);
    for copy in 0..copies {
        let origin = Vec3::new(
            (copy % grid) as f32 * 60.0,
            0.0,
            (copy / grid) as f32 * 60.0,
        );
        // Pyramid: square layers base², (base−1)², ..., 1.
        let base = ((11.0 * size).round() as usize).max(1);
        for layer in 0..base {
            let n = base - layer;
            let start = -(n as f32 - 1.0) * 0.5;
            for j in 0..n {
                for i in 0..n {
                    let p = Vec3::new(start + i as f32, HALF + layer as f32, start + j as f32);
                    scene.bodies.push(cube(origin + p));
                }
            }
        }
        // Brick wall along x, every other row shifted by half a box and one box shorter, so
        // that every brick rests on two below. A full row's end bricks rest on half a brick,
        // their centres right above its edge: the shifted row above holds them down, so the
        // wall has an even number of rows and ends with a shifted one (with a full row on top,
        // its end bricks topple, as the scene at a tenth of its size did).
        let width = ((24.0 * size).round() as usize).max(1);
        let height = ((8.0 * size).round() as usize).max(1) * 2;
        for row in 0..height {
            let (shift, bricks) = if row % 2 == 1 {
                (0.5, width.saturating_sub(1).max(1))
            } else {
                (0.0, width)
            };
            for i in 0..bricks {
                let p = Vec3::new(
                    -(width as f32) * 0.5 + i as f32 + shift,
                    HALF + row as f32,
                    -12.0,
                );
                scene.bodies.push(cube(origin + p));
            }
        }
        // Tower: 3 x 3 boxes per layer.
        let layers = ((13.0 * size).round() as usize).max(1);
        for layer in 0..layers {
            for k in 0..9 {
                let p = Vec3::new(
                    12.0 + (k % 3) as f32 - 1.0,
                    HALF + layer as f32,
                    (k / 3) as f32 - 1.0,
                );
                scene.bodies.push(cube(origin + p));
            }
        }
    }
    scene
}

/// Bullet's BenchmarkDemo test 3: standing ragdolls in a pyramid of rows 16, 15, ..., 1 (136),
/// each row in the air above the one below, side by side along x with their arms along z, all
/// falling onto each other and a plane. Below scale 1 the pyramid's base shrinks (about
/// 136 · scale ragdolls); above it, whole pyramids stand side by side along z.
fn ragdolls(scale: f32) -> Scene {
    /// Distance between neighbours in a row (m): a little more than a pelvis is wide.
    const SPACING: f32 = 0.6;
    /// Height between rows, soles to soles (m): a ragdoll is 1.76 m tall.
    const ROW_HEIGHT: f32 = 2.0;
    /// The lowest row's soles start this high (m).
    const DROP: f32 = 0.5;
    let (base, copies) = if scale < 1.0 {
        // Rows n, n − 1, ..., 1 hold n (n + 1) / 2 ragdolls.
        let target = 136.0 * scale;
        let base = ((((1.0 + 8.0 * target).sqrt() - 1.0) * 0.5).round() as usize).max(1);
        (base, 1)
    } else {
        (16, scale.round() as usize)
    };
    let mut scene = Scene::new(StepConfig::default());
    scene.bodies.push(ground());
    let copy_pitch = 2.0 * RAGDOLL_HALF_SPAN + 1.0;
    for copy in 0..copies {
        let z = (copy as f32 - 0.5 * (copies as f32 - 1.0)) * copy_pitch;
        for row in 0..base {
            let count = base - row;
            for i in 0..count {
                let x = (i as f32 - 0.5 * (count as f32 - 1.0)) * SPACING;
                let feet = Vec3::new(x, DROP + row as f32 * ROW_HEIGHT, z);
                add_ragdoll(&mut scene, feet, arms_along_z());
            }
        }
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn talk_sizes() {
        assert_eq!(
            builtin("falling-boxes", 1.0).unwrap().bodies.len(),
            3008 + 1
        );
        let stacked = builtin("stacked-boxes", 1.0).unwrap().bodies.len() - 1;
        assert!((950..=1050).contains(&stacked), "{stacked} boxes");
        let ragdolls = builtin("ragdolls", 1.0).unwrap();
        assert_eq!(ragdolls.bodies.len(), 136 * 11 + 1);
        assert_eq!(ragdolls.joints.len(), 136 * 10);
        assert_eq!(builtin("ragdolls", 10.0).unwrap().joints.len(), 1360 * 10);
        assert_eq!(builtin("ragdolls", 0.05).unwrap().joints.len(), 6 * 10);
        let convex_trimesh = builtin("convex-trimesh", 1.0).unwrap();
        assert_eq!(convex_trimesh.bodies.len(), 1000 + 1);
        let Shape::TriMesh(landscape) = &convex_trimesh.bodies[0].shape else {
            panic!("the ground is the landscape mesh")
        };
        assert!((99_000..=101_000).contains(&landscape.triangles().len()));
        // The same barrels as convex-hulls, each column lifted by the ground under it.
        let on_plane = builtin("convex-hulls", 1.0).unwrap();
        for (barrel, on_landscape) in on_plane.bodies[1..].iter().zip(&convex_trimesh.bodies[1..]) {
            assert_eq!(barrel.position.x, on_landscape.position.x);
            assert_eq!(barrel.position.z, on_landscape.position.z);
            assert_eq!(barrel.rotation, on_landscape.rotation);
        }
    }

    #[test]
    fn bad_names_and_scales_are_errors() {
        assert!(matches!(
            builtin("nope", 1.0),
            Err(SceneError::UnknownScene(_))
        ));
        assert!(matches!(
            builtin("falling-boxes", 0.0),
            Err(SceneError::BadScale(_))
        ));
        assert!(matches!(
            builtin("falling-boxes", f32::NAN),
            Err(SceneError::BadScale(_))
        ));
    }
}
