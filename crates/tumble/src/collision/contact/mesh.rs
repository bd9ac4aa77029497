//! A convex shape against a static triangle mesh: the mesh's BVH yields the triangles near the
//! shape, and each touching triangle gets its own manifold (a child manifold: one normal per
//! manifold, and a shape on a seam or in a valley touches faces with different normals).

use super::hull_triangle::hull_triangle;
use super::triangle::{box_triangle, capsule_triangle, sphere_triangle};
use crate::collision::manifold::{ContactPoint, Manifold};
use crate::math::{Transform, Vec3};
use crate::shape::{Shape, TriMesh};

/// Calls `found(triangle, manifold)` for each triangle of `mesh` (at `pose_b`) with contacts
/// closer than `margin` (m) to `shape` (at `pose_a`), in ascending triangle order. Manifolds are
/// in world space with the normal from the triangle (B) to the shape (A). Shapes that cannot
/// touch a mesh (planes, meshes: both static) give nothing.
pub fn collide_mesh(
    shape: &Shape,
    pose_a: &Transform,
    mesh: &TriMesh,
    pose_b: &Transform,
    margin: f32,
    found: &mut Vec<(u32, Manifold)>,
) {
    found.clear();
    // The shape in the mesh frame: triangles stay as stored, only one pose is transformed.
    let local_pose = pose_b.inverse().mul_transform(pose_a);
    let query = shape.aabb(&local_pose).expanded(margin);
    let mut triangles = Vec::new();
    mesh.bvh()
        .query_aabb(&query, mesh.triangle_aabbs(), |triangle| {
            triangles.push(triangle)
        });
    // BVH order is deterministic but not sorted; the child cache is keyed by triangle index.
    triangles.sort_unstable();
    for triangle_index in triangles {
        let triangle = mesh.triangle(triangle_index);
        let mut local = Manifold::default();
        match shape {
            Shape::Sphere(sphere) => sphere_triangle(
                local_pose.position,
                sphere.radius,
                &triangle,
                margin,
                &mut local,
            ),
            Shape::Capsule(capsule) => {
                let axis = local_pose.transform_vector(Vec3::new(0.0, capsule.half_height, 0.0));
                let center = local_pose.position;
                capsule_triangle(
                    center - axis,
                    center + axis,
                    capsule.radius,
                    &triangle,
                    margin,
                    &mut local,
                )
            }
            Shape::Cuboid(cuboid) => {
                box_triangle(cuboid, &local_pose, &triangle, margin, &mut local)
            }
            Shape::ConvexHull(hull) => {
                hull_triangle(hull, &local_pose, &triangle, margin, &mut local)
            }
            // A compound meets a mesh child by child (`stages::narrowphase::children`); planes
            // and meshes are static: they never meet a mesh.
            Shape::Plane(_) | Shape::TriMesh(_) | Shape::Compound(_) => return,
        }
        if local.count == 0 {
            continue;
        }
        let mut world = Manifold {
            normal: pose_b.transform_vector(local.normal),
            ..Manifold::default()
        };
        for point in local.points() {
            world.push(ContactPoint::new(
                pose_b.transform_point(point.position),
                point.separation,
                point.id,
            ));
        }
        found.push((triangle_index, world));
    }
}
