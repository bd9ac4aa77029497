//! Pairs with a plane (always B, the static one): sphere–plane, capsule–plane, box–plane.
//!
//! The normal is the plane's outward normal: from the solid half-space (B) towards the body (A).
//! A point's separation is the signed distance of A's lowest surface point above the plane.

use super::{POINT_SEGMENT_HALF_HEIGHT, push_contact};
use crate::collision::manifold::{ContactPoint, Manifold, reduce};
use crate::math::{Mat3, Transform, Vec3};
use crate::shape::{Capsule, Cuboid, Plane, Sphere};

/// The plane in world space: `(normal, offset)` with the solid side `normal · x <= offset`.
/// `normal · (R x_local + p) = (R n) · x_local + (R n) · p`, so the offset grows by `(R n) · p`.
#[inline]
fn world_plane(plane: &Plane, pose: &Transform) -> (Vec3, f32) {
    let normal = pose.transform_vector(plane.normal);
    (normal, plane.offset + normal.dot(pose.position))
}

pub(super) fn sphere_plane(
    a: &Sphere,
    pose_a: &Transform,
    b: &Plane,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let (normal, offset) = world_plane(b, pose_b);
    let separation = normal.dot(pose_a.position) - offset - a.radius;
    if separation >= margin {
        return;
    }
    out.normal = normal;
    push_contact(
        out,
        pose_a.position - normal * a.radius,
        normal,
        separation,
        0,
    );
}

/// One point per end of the segment (ids 0 and 1 for the `-half_height` and `+half_height`
/// ends), so a capsule lying on the plane rests on two points and does not roll about them.
pub(super) fn capsule_plane(
    a: &Capsule,
    pose_a: &Transform,
    b: &Plane,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let (normal, offset) = world_plane(b, pose_b);
    out.normal = normal;
    let half_axis = pose_a.transform_vector(Vec3::new(0.0, a.half_height, 0.0));
    // A capsule with no straight part has both ends in one place: one point, not two alike.
    let end_count = if a.half_height <= POINT_SEGMENT_HALF_HEIGHT {
        1
    } else {
        2
    };
    let ends = [pose_a.position - half_axis, pose_a.position + half_axis];
    for (id, end) in ends.iter().take(end_count).enumerate() {
        let separation = normal.dot(*end) - offset - a.radius;
        if separation < margin {
            push_contact(out, *end - normal * a.radius, normal, separation, id as u32);
        }
    }
}

/// Signs of box vertex `index` along the local axes: bit 0, 1, 2 set → + side of x, y, z.
#[inline]
fn vertex_signs(index: usize) -> Vec3 {
    let sign = |bit: usize| if index & (1 << bit) != 0 { 1.0 } else { -1.0 };
    Vec3::new(sign(0), sign(1), sign(2))
}

/// Every box vertex closer to the plane than `margin` is a candidate (id: the vertex index);
/// more than four (a box within the margin of a plane edge-on, or with a large margin) go
/// through [`reduce`].
pub(super) fn box_plane(
    a: &Cuboid,
    pose_a: &Transform,
    b: &Plane,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let (normal, offset) = world_plane(b, pose_b);
    let rotation = Mat3::from_quat(pose_a.rotation);
    // Height of vertex s ∘ h above the plane = centre height + Σ s_i h_i (R^T n)_i: `reach`
    // holds the terms, the vertex signs pick theirs.
    let reach = (rotation.transpose() * normal) * a.half_extents;
    let center_height = normal.dot(pose_a.position) - offset;
    if center_height - reach.abs().element_sum() >= margin {
        return;
    }
    let mut candidates = [ContactPoint::default(); 8];
    let mut count = 0;
    for index in 0..8 {
        let signs = vertex_signs(index);
        let separation = center_height + (signs * reach).element_sum();
        if separation < margin {
            let vertex = pose_a.position + rotation * (signs * a.half_extents);
            candidates[count] = ContactPoint::new(
                vertex - normal * (0.5 * separation),
                separation,
                index as u32,
            );
            count += 1;
        }
    }
    if count > out.points.len() {
        *out = reduce(&candidates[..count], normal);
    } else {
        out.normal = normal;
        for candidate in &candidates[..count] {
            out.push(*candidate);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};

    fn ground() -> Plane {
        Plane {
            normal: Vec3::Y,
            offset: 0.0,
        }
    }

    #[test]
    fn sphere_on_a_moved_plane() {
        // The plane y <= 1 in its frame, the frame raised by 0.5: world y <= 1.5.
        let pose_b = Transform::from_position(vec3(3.0, 0.5, 0.0));
        let plane = Plane {
            normal: Vec3::Y,
            offset: 1.0,
        };
        let mut out = Manifold::default();
        let pose_a = Transform::from_position(vec3(0.0, 1.9, 0.0));
        sphere_plane(
            &Sphere { radius: 0.5 },
            &pose_a,
            &plane,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_eq!(out.normal, Vec3::Y);
        assert!((out.points[0].separation + 0.1).abs() < 1e-5);
        assert!((out.points[0].position - vec3(0.0, 1.45, 0.0)).length() < 1e-5);
    }

    #[test]
    fn capsule_lying_on_plane_rests_on_its_ends() {
        let capsule = Capsule {
            radius: 0.3,
            half_height: 1.0,
        };
        let height = 0.31;
        // Lying along x (local y turned onto world x).
        let pose_a = Transform::new(
            vec3(0.5, height, -0.2),
            Quat::from_rotation_z(-std::f32::consts::FRAC_PI_2),
        );
        let mut out = Manifold::default();
        capsule_plane(
            &capsule,
            &pose_a,
            &ground(),
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 2);
        assert_eq!(out.normal, Vec3::Y);
        for point in out.points() {
            assert!((point.separation - (height - capsule.radius)).abs() < 1e-5);
        }
        // Id 0 is the -half_height end, here at x = 0.5 - 1.
        assert_eq!(out.points[0].id, 0);
        assert!((out.points[0].position - vec3(-0.5, 0.005, -0.2)).length() < 1e-5);
        assert_eq!(out.points[1].id, 1);
        assert!((out.points[1].position - vec3(1.5, 0.005, -0.2)).length() < 1e-5);

        // Standing: only the lower end touches.
        let mut out = Manifold::default();
        let pose_a = Transform::from_position(vec3(0.0, 1.2, 0.0));
        capsule_plane(
            &capsule,
            &pose_a,
            &ground(),
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_eq!(out.points[0].id, 0);
        assert!((out.points[0].separation + 0.1).abs() < 1e-5);

        // No straight part: one point, not two alike.
        let mut out = Manifold::default();
        let ball = Capsule {
            radius: 0.3,
            half_height: 0.0,
        };
        capsule_plane(
            &ball,
            &pose_a,
            &ground(),
            &Transform::IDENTITY,
            2.0,
            &mut out,
        );
        assert_eq!(out.count, 1);
    }

    #[test]
    fn box_resting_flat_gives_its_four_bottom_corners() {
        let cuboid = Cuboid {
            half_extents: vec3(0.5, 0.25, 1.0),
        };
        let pose_a = Transform::new(vec3(2.0, 0.25, -1.0), Quat::from_rotation_y(0.3));
        let mut out = Manifold::default();
        box_plane(
            &cuboid,
            &pose_a,
            &ground(),
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 4);
        assert_eq!(out.normal, Vec3::Y);
        let mut ids: Vec<u32> = out.points().iter().map(|point| point.id).collect();
        ids.sort();
        // The vertices with bit 1 (local +y) clear.
        assert_eq!(ids, [0, 1, 4, 5]);
        for point in out.points() {
            assert!(point.separation.abs() < 1e-5);
            let corner =
                pose_a.transform_point(vertex_signs(point.id as usize) * cuboid.half_extents);
            assert!(corner.y.abs() < 1e-5);
            assert!((point.position - corner).length() < 1e-5);
        }

        // Lifted by 0.01 (within the margin): the same four, apart by 0.01.
        let lifted = Transform::new(pose_a.position + vec3(0.0, 0.01, 0.0), pose_a.rotation);
        let mut out = Manifold::default();
        box_plane(
            &cuboid,
            &lifted,
            &ground(),
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 4);
        for point in out.points() {
            assert!((point.separation - 0.01).abs() < 1e-5);
        }

        // Lifted by 0.03: beyond the margin.
        let lifted = Transform::new(pose_a.position + vec3(0.0, 0.03, 0.0), pose_a.rotation);
        let mut out = Manifold::default();
        box_plane(
            &cuboid,
            &lifted,
            &ground(),
            &Transform::IDENTITY,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 0);
    }

    #[test]
    fn box_within_a_large_margin_keeps_four_spread_points() {
        let cuboid = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        let pose_a = Transform::new(vec3(0.0, 0.6, 0.0), Quat::from_rotation_x(0.2));
        let mut out = Manifold::default();
        box_plane(
            &cuboid,
            &pose_a,
            &ground(),
            &Transform::IDENTITY,
            5.0,
            &mut out,
        );
        assert_eq!(out.count, 4);
        // The deepest vertex is kept, and ids stay distinct.
        let deepest = (0..8)
            .map(|index| pose_a.transform_point(vertex_signs(index) * 0.5).y)
            .fold(f32::INFINITY, f32::min);
        let kept = out
            .points()
            .iter()
            .map(|point| point.separation)
            .fold(f32::INFINITY, f32::min);
        assert!((kept - deepest).abs() < 1e-5);
        let mut ids: Vec<u32> = out.points().iter().map(|point| point.id).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), 4);
    }
}
