//! Sphere pairs: sphere–sphere, sphere–capsule, sphere–box (sphere–plane is in `plane.rs`).
//!
//! A sphere touches anything at one point, id 0. Capsule pairs reuse [`ball_ball`]: a capsule
//! is a ball swept along a segment, so once the closest point of the segment is known the
//! contact is the one of two balls.

use super::segment::closest_parameter_to_point;
use super::{COINCIDENT_DISTANCE_SQUARED, push_contact, sign_or_positive};
use crate::collision::manifold::Manifold;
use crate::math::{Transform, Vec3};
use crate::shape::{Capsule, Cuboid, Sphere};

/// The contact of ball A (`center_a`, `radius_a`) with ball B, all in world space (m).
/// `fallback_normal` (unit) is used when the centres coincide and give no direction.
#[allow(clippy::too_many_arguments)] // two balls, and the manifold's settings
pub(super) fn ball_ball(
    center_a: Vec3,
    radius_a: f32,
    center_b: Vec3,
    radius_b: f32,
    fallback_normal: Vec3,
    id: u32,
    margin: f32,
    out: &mut Manifold,
) {
    let offset = center_a - center_b;
    let distance_squared = offset.length_squared();
    let radii = radius_a + radius_b;
    // Compare squares first: most pairs the broadphase hands over do not touch.
    let reach = radii + margin;
    if distance_squared >= reach * reach {
        return;
    }
    let (normal, distance) = if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        let distance = distance_squared.sqrt();
        (offset / distance, distance)
    } else {
        (fallback_normal, 0.0)
    };
    out.normal = normal;
    push_contact(
        out,
        center_a - normal * radius_a,
        normal,
        distance - radii,
        id,
    );
}

pub(super) fn sphere_sphere(
    a: &Sphere,
    pose_a: &Transform,
    b: &Sphere,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    // Concentric spheres have no preferred direction: push along world up.
    ball_ball(
        pose_a.position,
        a.radius,
        pose_b.position,
        b.radius,
        Vec3::Y,
        0,
        margin,
        out,
    );
}

pub(super) fn sphere_capsule(
    a: &Sphere,
    pose_a: &Transform,
    b: &Capsule,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let half_axis = pose_b.transform_vector(Vec3::new(0.0, b.half_height, 0.0));
    let start = pose_b.position - half_axis;
    let delta = 2.0 * half_axis;
    let t = closest_parameter_to_point(pose_a.position, start, delta);
    // A centre on the capsule's axis: push out sideways, along the capsule's local x, which is
    // perpendicular to the axis (local y).
    let fallback_normal = pose_b.transform_vector(Vec3::X);
    ball_ball(
        pose_a.position,
        a.radius,
        start + delta * t,
        b.radius,
        fallback_normal,
        0,
        margin,
        out,
    );
}

pub(super) fn sphere_box(
    a: &Sphere,
    pose_a: &Transform,
    b: &Cuboid,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let half = b.half_extents;
    let center = pose_b.inverse_transform_point(pose_a.position);
    let box_point = center.clamp(-half, half);
    let offset = center - box_point;
    let distance_squared = offset.length_squared();
    let (normal_local, separation) = if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        let reach = a.radius + margin;
        if distance_squared >= reach * reach {
            return;
        }
        let distance = distance_squared.sqrt();
        (offset / distance, distance - a.radius)
    } else {
        // The centre is inside the box (or on its surface): leave through the face of least
        // penetration. `depth` is how far each face pair is from the centre (m, ≥ 0).
        let depth = half - center.abs();
        let mut axis = 0;
        for candidate in 1..3 {
            if depth[candidate] < depth[axis] {
                axis = candidate;
            }
        }
        let separation = -depth[axis] - a.radius;
        if separation >= margin {
            return;
        }
        (
            sign_or_positive(center[axis]) * Vec3::AXES[axis],
            separation,
        )
    };
    let normal = pose_b.transform_vector(normal_local);
    out.normal = normal;
    push_contact(
        out,
        pose_a.position - normal * a.radius,
        normal,
        separation,
        0,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};

    fn assert_close(actual: Vec3, expected: Vec3) {
        assert!(
            (actual - expected).length() < 1e-5,
            "{actual} != {expected}"
        );
    }

    #[test]
    fn sphere_sphere_distance_and_normal() {
        let mut out = Manifold::default();
        let a = Sphere { radius: 0.5 };
        let b = Sphere { radius: 1.0 };
        let pose_b = Transform::from_position(vec3(1.0, 2.0, 3.0));
        let direction = vec3(2.0, -1.0, 2.0) / 3.0;
        // Overlapping by 0.1 m.
        let pose_a = Transform::from_position(pose_b.position + direction * 1.4);
        sphere_sphere(&a, &pose_a, &b, &pose_b, 0.02, &mut out);
        assert_eq!(out.count, 1);
        assert_close(out.normal, direction);
        assert!((out.points[0].separation + 0.1).abs() < 1e-5);
        // Midway between A's surface (1.4 - 0.5 from B) and B's surface (1.0 from B).
        assert_close(out.points[0].position, pose_b.position + direction * 0.95);

        // Within the margin but apart: kept, positive separation.
        let mut out = Manifold::default();
        let pose_a = Transform::from_position(pose_b.position + direction * 1.51);
        sphere_sphere(&a, &pose_a, &b, &pose_b, 0.02, &mut out);
        assert_eq!(out.count, 1);
        assert!((out.points[0].separation - 0.01).abs() < 1e-5);

        // Beyond the margin: nothing.
        let mut out = Manifold::default();
        let pose_a = Transform::from_position(pose_b.position + direction * 1.53);
        sphere_sphere(&a, &pose_a, &b, &pose_b, 0.02, &mut out);
        assert_eq!(out.count, 0);
    }

    #[test]
    fn concentric_spheres_push_up_without_nan() {
        let mut out = Manifold::default();
        let pose = Transform::from_position(vec3(1.0, 1.0, 1.0));
        let sphere = Sphere { radius: 0.5 };
        sphere_sphere(&sphere, &pose, &sphere, &pose, 0.0, &mut out);
        assert_eq!(out.count, 1);
        assert_eq!(out.normal, Vec3::Y);
        assert_eq!(out.points[0].separation, -1.0);
        assert!(out.points[0].position.is_finite());
    }

    #[test]
    fn sphere_on_capsule_side_and_cap() {
        let capsule = Capsule {
            radius: 0.25,
            half_height: 1.0,
        };
        // Capsule lying along world x.
        let pose_b = Transform::new(
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
        );
        let sphere = Sphere { radius: 0.5 };
        let mut out = Manifold::default();
        sphere_capsule(
            &sphere,
            &Transform::from_position(vec3(0.3, 0.7, 0.0)),
            &capsule,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, Vec3::Y);
        assert!((out.points[0].separation + 0.05).abs() < 1e-5);
        // Beyond the cap at x = 1: distance from the segment end.
        let center = vec3(1.0, 0.0, 0.0) + vec3(3.0, 0.0, 4.0) / 5.0 * 0.7;
        let mut out = Manifold::default();
        sphere_capsule(
            &sphere,
            &Transform::from_position(center),
            &capsule,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, vec3(0.6, 0.0, 0.8));
        assert!((out.points[0].separation + 0.05).abs() < 1e-5);
        // Centre on the axis: sideways along the capsule's local x, finite.
        let mut out = Manifold::default();
        sphere_capsule(
            &sphere,
            &Transform::from_position(vec3(0.2, 0.0, 0.0)),
            &capsule,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, pose_b.transform_vector(Vec3::X));
        assert!((out.points[0].separation + 0.75).abs() < 1e-5);
    }

    /// Sphere of radius 0.5 against a unit box (half extents 1, 2, 3) turned and moved.
    #[test]
    fn sphere_box_face_edge_corner_and_inside() {
        let cuboid = Cuboid {
            half_extents: vec3(1.0, 2.0, 3.0),
        };
        let pose_b = Transform::new(vec3(0.5, -1.0, 2.0), Quat::from_rotation_y(0.6));
        let sphere = Sphere { radius: 0.5 };
        let cases = [
            // (centre in the box frame, expected normal in the box frame, separation)
            // 0.49 above the +y face: overlapping by 0.01.
            (vec3(0.3, 2.49, -1.0), Vec3::Y, -0.01),
            // Beside the edge x = 1, z = 3, 0.4 away diagonally.
            (
                vec3(1.0, 0.5, 3.0) + vec3(1.0, 0.0, 1.0).normalize() * 0.4,
                vec3(1.0, 0.0, 1.0).normalize(),
                -0.1,
            ),
            // Near the corner (-1, -2, -3), 0.51 away.
            (
                vec3(-1.0, -2.0, -3.0) - Vec3::ONE.normalize() * 0.51,
                -Vec3::ONE.normalize(),
                0.01,
            ),
            // Inside, 0.2 under the -x face (the nearest): out through -x by 0.2 + radius.
            (vec3(-0.8, 0.5, 1.0), -Vec3::X, -0.7),
        ];
        for (center_local, normal_local, separation) in cases {
            let mut out = Manifold::default();
            let pose_a = Transform::from_position(pose_b.transform_point(center_local));
            sphere_box(&sphere, &pose_a, &cuboid, &pose_b, 0.02, &mut out);
            assert_eq!(out.count, 1, "{center_local}");
            assert_close(out.normal, pose_b.transform_vector(normal_local));
            assert!(
                (out.points[0].separation - separation).abs() < 1e-5,
                "{center_local}: {}",
                out.points[0].separation
            );
            // Midway between the sphere's surface and the box's.
            let expected = pose_a.position - out.normal * (0.5 + 0.5 * separation);
            assert_close(out.points[0].position, expected);
            assert_eq!(out.points[0].id, 0);
        }
        // Apart by 0.1 over the face: beyond the margin.
        let mut out = Manifold::default();
        let pose_a = Transform::from_position(pose_b.transform_point(vec3(0.0, 2.6, 0.0)));
        sphere_box(&sphere, &pose_a, &cuboid, &pose_b, 0.02, &mut out);
        assert_eq!(out.count, 0);
    }

    #[test]
    fn sphere_at_box_centre_is_finite() {
        let mut out = Manifold::default();
        let cuboid = Cuboid {
            half_extents: Vec3::splat(1.0),
        };
        sphere_box(
            &Sphere { radius: 0.5 },
            &Transform::IDENTITY,
            &cuboid,
            &Transform::IDENTITY,
            0.0,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_eq!(out.normal, Vec3::X);
        assert_eq!(out.points[0].separation, -1.5);
    }
}
