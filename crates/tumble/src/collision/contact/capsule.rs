//! Capsule pairs: capsule–capsule and capsule–box (capsule–plane is in `plane.rs`).
//!
//! A capsule is its segment swept by a ball, so a contact is found on the segment and moved out
//! by the radius. One point alone lets a capsule lying on something roll and rock about it, so
//! where the segment lies along the other shape (a parallel capsule, a box face) the contact is
//! two points, one per end of the part of the segment that lies over the other shape: ids 0
//! (the end towards the capsule's `-half_height` end) and 1. Elsewhere one point, id 0.

use super::segment::{closest_parameter_to_point, closest_parameters_between_segments};
use super::sphere::sphere_box;
use super::{
    COINCIDENT_DISTANCE_SQUARED, EDGE_RELATIVE_TOLERANCE, Face, PARALLEL_SINE_SQUARED,
    POINT_SEGMENT_HALF_HEIGHT, clearly_greater, push_contact, sign_or_positive,
};
use crate::collision::manifold::Manifold;
use crate::math::{Transform, Vec3};
use crate::shape::{Capsule, Cuboid, Sphere};

/// `sin²` of the angle under which two capsules count as parallel and get two points
/// (sin ≈ 0.02, about 1.1°).
pub(super) const PARALLEL_CAPSULES_SINE_SQUARED: f32 = 4.0e-4;

/// Overlap (m) of two parallel segments under which the two points would nearly coincide:
/// one is enough.
pub(super) const MINIMUM_OVERLAP: f32 = 1.0e-3;

/// The capsule's segment in world space: `(start, delta)`, from the `-half_height` end.
#[inline]
fn world_segment(capsule: &Capsule, pose: &Transform) -> (Vec3, Vec3) {
    let half_axis = pose.transform_vector(Vec3::new(0.0, capsule.half_height, 0.0));
    (pose.position - half_axis, 2.0 * half_axis)
}

pub(super) fn capsule_capsule(
    a: &Capsule,
    pose_a: &Transform,
    b: &Capsule,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let (start_a, delta_a) = world_segment(a, pose_a);
    let (start_b, delta_b) = world_segment(b, pose_b);
    let (s, t) = closest_parameters_between_segments(start_a, delta_a, start_b, delta_b);
    let closest_a = start_a + delta_a * s;
    let closest_b = start_b + delta_b * t;
    let radii = a.radius + b.radius;
    let offset = closest_a - closest_b;
    let distance_squared = offset.length_squared();
    let reach = radii + margin;
    if distance_squared >= reach * reach {
        return;
    }
    let cross = delta_a.cross(delta_b);
    let length_a_squared = delta_a.length_squared();
    let length_b_squared = delta_b.length_squared();
    let normal = if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        offset / distance_squared.sqrt()
    } else {
        // The segments touch: any direction perpendicular to both separates the axes; crossing
        // segments have one, their cross product, turned to point from B's centre to A's.
        let cross_length_squared = cross.length_squared();
        if cross_length_squared
            > PARALLEL_SINE_SQUARED * length_a_squared * length_b_squared
                + COINCIDENT_DISTANCE_SQUARED
        {
            let normal = cross / cross_length_squared.sqrt();
            normal * sign_or_positive(normal.dot(pose_a.position - pose_b.position))
        } else if b.half_height > POINT_SEGMENT_HALF_HEIGHT {
            // Collinear, or A is a point: local x is perpendicular to B's axis.
            pose_b.transform_vector(Vec3::X)
        } else {
            pose_a.transform_vector(Vec3::X)
        }
    };

    let parallel = a.half_height > POINT_SEGMENT_HALF_HEIGHT
        && b.half_height > POINT_SEGMENT_HALF_HEIGHT
        && cross.length_squared()
            <= PARALLEL_CAPSULES_SINE_SQUARED * length_a_squared * length_b_squared;
    if parallel {
        // The part of A over B: B's ends projected on A, as parameters of A.
        let end_b_0 = (start_b - start_a).dot(delta_a) / length_a_squared;
        let end_b_1 = (start_b + delta_b - start_a).dot(delta_a) / length_a_squared;
        let low = end_b_0.min(end_b_1).max(0.0);
        let high = end_b_0.max(end_b_1).min(1.0);
        if (high - low) * length_a_squared.sqrt() > MINIMUM_OVERLAP {
            out.normal = normal;
            for (id, parameter) in [(0, low), (1, high)] {
                let point_a = start_a + delta_a * parameter;
                let point_b =
                    start_b + delta_b * closest_parameter_to_point(point_a, start_b, delta_b);
                let separation = (point_a - point_b).dot(normal) - radii;
                if separation < margin {
                    push_contact(out, point_a - normal * a.radius, normal, separation, id);
                }
            }
            return;
        }
    }
    // The offset is along the normal, or (segments touching) nothing: below `reach` either way.
    out.normal = normal;
    let separation = offset.dot(normal) - radii;
    push_contact(out, closest_a - normal * a.radius, normal, separation, 0);
}

pub(super) fn capsule_box(
    a: &Capsule,
    pose_a: &Transform,
    b: &Cuboid,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    if a.half_height <= POINT_SEGMENT_HALF_HEIGHT {
        sphere_box(&Sphere { radius: a.radius }, pose_a, b, pose_b, margin, out);
        return;
    }
    // In the box frame the box is axis aligned at the origin.
    let half = b.half_extents;
    let center = pose_b.inverse_transform_point(pose_a.position);
    let half_axis = pose_b.inverse_transform_vector(pose_a.transform_vector(Vec3::new(
        0.0,
        a.half_height,
        0.0,
    )));
    let segment = LocalSegment {
        start: center - half_axis,
        delta: 2.0 * half_axis,
    };
    let t = closest_parameter_segment_box(segment.start, segment.delta, half);
    let point = segment.start + segment.delta * t;
    let box_point = point.clamp(-half, half);
    let offset = point - box_point;
    let distance_squared = offset.length_squared();
    let reach = a.radius + margin;
    if distance_squared >= reach * reach {
        return;
    }
    if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        // Apart: the closest point of the box is on a face when only one coordinate was
        // clamped; the segment may then lie along that face.
        let outside = point.abs().cmpgt(half).bitmask();
        if outside.count_ones() == 1 {
            let axis = outside.trailing_zeros() as usize;
            let face = Face {
                axis,
                sign: sign_or_positive(point[axis]),
            };
            capsule_on_face(&segment, a.radius, half, face, t, margin, pose_b, out);
        } else {
            let distance = distance_squared.sqrt();
            let normal_local = offset / distance;
            let separation = distance - a.radius;
            let normal = pose_b.transform_vector(normal_local);
            out.normal = normal;
            let surface_a = pose_b.transform_point(point - normal_local * a.radius);
            push_contact(out, surface_a, normal, separation, 0);
        }
        return;
    }
    capsule_in_box(&segment, t, a.radius, half, margin, pose_b, out);
}

/// A segment in the box frame, `start + t * delta` for `t ∈ [0, 1]` (m).
struct LocalSegment {
    start: Vec3,
    delta: Vec3,
}

/// The segment cuts into the box: the separating-axis test between segment and box finds the
/// direction of least penetration. The axes are the box's three face normals and the three
/// cross products of the segment with the box edges; the segment has no face of its own.
/// `parameter` (of the segment, no unit) is a point of the segment inside the box.
fn capsule_in_box(
    segment: &LocalSegment,
    parameter: f32,
    radius: f32,
    half: Vec3,
    margin: f32,
    pose_b: &Transform,
    out: &mut Manifold,
) {
    let center = segment.start + 0.5 * segment.delta;
    let half_delta = 0.5 * segment.delta;
    // Separation along an axis = gap between the projections (m, < 0 overlapping).
    let face_separations = center.abs() - half_delta.abs() - half;
    let mut face_axis = 0;
    for axis in 1..3 {
        if face_separations[axis] > face_separations[face_axis] {
            face_axis = axis;
        }
    }
    let face_separation = face_separations[face_axis];

    // (normal, separation, box axis the edge runs along) of the best edge axis.
    let mut edge: Option<(Vec3, f32, usize)> = None;
    let length_squared = segment.delta.length_squared();
    for (edge_axis, box_axis) in Vec3::AXES.into_iter().enumerate() {
        let axis = segment.delta.cross(box_axis);
        let axis_length_squared = axis.length_squared();
        if axis_length_squared <= PARALLEL_SINE_SQUARED * length_squared {
            continue;
        }
        let axis = axis / axis_length_squared.sqrt();
        // The segment is perpendicular to this axis: it projects to the single point centre.
        let along = center.dot(axis);
        let separation = along.abs() - (half * axis.abs()).element_sum();
        if edge.is_none_or(|(_, best, _)| separation > best) {
            edge = Some((axis * sign_or_positive(along), separation, edge_axis));
        }
    }

    match edge {
        Some((normal_local, edge_separation, edge_axis))
            if clearly_greater(edge_separation, face_separation, EDGE_RELATIVE_TOLERANCE) =>
        {
            if edge_separation - radius >= margin {
                return;
            }
            // The box edge along `edge_axis` that reaches furthest towards the capsule: on the
            // other axes it sits on the side the normal points to (the normal has no
            // component along the edge).
            let mut edge_start = Vec3::ZERO;
            for axis in 0..3 {
                edge_start[axis] = sign_or_positive(normal_local[axis]) * half[axis];
            }
            edge_start[edge_axis] = -half[edge_axis];
            let edge_delta = 2.0 * half[edge_axis] * Vec3::AXES[edge_axis];
            let (s, t) = closest_parameters_between_segments(
                segment.start,
                segment.delta,
                edge_start,
                edge_delta,
            );
            let point = segment.start + segment.delta * s;
            let separation = (point - (edge_start + edge_delta * t)).dot(normal_local) - radius;
            let normal = pose_b.transform_vector(normal_local);
            out.normal = normal;
            let surface_a = pose_b.transform_point(point - normal_local * radius);
            push_contact(out, surface_a, normal, separation, 0);
        }
        _ => {
            if face_separation - radius >= margin {
                return;
            }
            let face = Face {
                axis: face_axis,
                sign: sign_or_positive(center[face_axis]),
            };
            capsule_on_face(segment, radius, half, face, parameter, margin, pose_b, out);
        }
    }
}

/// Two points: the ends of the part of the segment over `face` (clipped against the face's
/// four side planes), each at its own height above the face. `fallback_parameter` is used if
/// the clipped part is empty, which happens only when rounding puts the segment a hair outside
/// the face's rim.
#[allow(clippy::too_many_arguments)] // the segment, the box face, and the manifold's settings
fn capsule_on_face(
    segment: &LocalSegment,
    radius: f32,
    half: Vec3,
    face: Face,
    fallback_parameter: f32,
    margin: f32,
    pose_b: &Transform,
    out: &mut Manifold,
) {
    let mut low: f32 = 0.0;
    let mut high: f32 = 1.0;
    for axis in [(face.axis + 1) % 3, (face.axis + 2) % 3] {
        // Parameters where the segment crosses the slab |x_axis| <= half_axis (Liang–Barsky).
        // A segment parallel to the slab stays inside it: the closest point is over the face.
        if segment.delta[axis] != 0.0 {
            let enter = (-half[axis] - segment.start[axis]) / segment.delta[axis];
            let leave = (half[axis] - segment.start[axis]) / segment.delta[axis];
            low = low.max(enter.min(leave));
            high = high.min(enter.max(leave));
        }
    }
    if low > high {
        low = fallback_parameter;
        high = fallback_parameter;
    }
    let normal_local = face.sign * Vec3::AXES[face.axis];
    let normal = pose_b.transform_vector(normal_local);
    out.normal = normal;
    let parameters = [low, high];
    let count = if high > low { 2 } else { 1 };
    for (id, parameter) in parameters.iter().take(count).enumerate() {
        let point = segment.start + segment.delta * *parameter;
        // Height of the segment point above the face, less the radius (m).
        let separation = face.sign * point[face.axis] - half[face.axis] - radius;
        if separation < margin {
            let surface_a = pose_b.transform_point(point - normal_local * radius);
            push_contact(out, surface_a, normal, separation, id as u32);
        }
    }
}

/// Parameter of the point of the segment `start + t * delta` nearest to the box
/// `|x_i| <= half_i`, exactly. The squared distance `Σ max(|x_i(t)| - half_i, 0)²` is convex
/// and, between the parameters where the segment crosses a face plane, a plain quadratic: the
/// minimum over those at most seven pieces is the minimum. Ties go to the lowest parameter.
fn closest_parameter_segment_box(start: Vec3, delta: Vec3, half: Vec3) -> f32 {
    let mut breaks = [0.0f32; 8];
    let mut count = 1;
    for axis in 0..3 {
        if delta[axis] == 0.0 {
            continue;
        }
        for plane in [-half[axis], half[axis]] {
            let t = (plane - start[axis]) / delta[axis];
            if t > 0.0 && t < 1.0 {
                breaks[count] = t;
                count += 1;
            }
        }
    }
    breaks[count] = 1.0;
    count += 1;
    breaks[..count].sort_unstable_by(f32::total_cmp);

    let distance_squared = |t: f32| {
        let point = start + delta * t;
        (point - point.clamp(-half, half)).length_squared()
    };
    let mut best = 0.0;
    let mut best_distance_squared = distance_squared(0.0);
    for piece in breaks[..count].windows(2) {
        let (low, high) = (piece[0], piece[1]);
        // On this piece each coordinate is below, inside or above its slab throughout: the
        // distance is Σ (offset_i + slope_i t)² over the outside ones; its minimum is where the
        // derivative vanishes, clamped to the piece.
        let middle = start + delta * (0.5 * (low + high));
        let mut offset_times_slope = 0.0;
        let mut slope_squared = 0.0;
        for axis in 0..3 {
            let (offset, slope) = if middle[axis] > half[axis] {
                (start[axis] - half[axis], delta[axis])
            } else if middle[axis] < -half[axis] {
                (-start[axis] - half[axis], -delta[axis])
            } else {
                continue;
            };
            offset_times_slope += offset * slope;
            slope_squared += slope * slope;
        }
        let t = if slope_squared > 0.0 {
            (-offset_times_slope / slope_squared).clamp(low, high)
        } else {
            low
        };
        let candidate = distance_squared(t);
        if candidate < best_distance_squared {
            best = t;
            best_distance_squared = candidate;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};
    use std::f32::consts::FRAC_PI_2;

    fn assert_close(actual: Vec3, expected: Vec3) {
        assert!(
            (actual - expected).length() < 1e-5,
            "{actual} != {expected}"
        );
    }

    /// Local y (the capsule axis) turned onto world +x.
    fn along_x(position: Vec3) -> Transform {
        Transform::new(position, Quat::from_rotation_z(-FRAC_PI_2))
    }

    /// Local y turned onto world +z.
    fn along_z(position: Vec3) -> Transform {
        Transform::new(position, Quat::from_rotation_x(FRAC_PI_2))
    }

    fn capsule(radius: f32, half_height: f32) -> Capsule {
        Capsule {
            radius,
            half_height,
        }
    }

    #[test]
    fn capsules_crossing_at_right_angles_touch_at_one_point() {
        let mut out = Manifold::default();
        let a = capsule(0.25, 1.0);
        let b = capsule(0.25, 2.0);
        capsule_capsule(
            &a,
            &along_x(vec3(0.2, 0.45, 0.3)),
            &b,
            &along_z(vec3(0.0, 0.0, 0.1)),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, Vec3::Y);
        assert!((out.points[0].separation + 0.05).abs() < 1e-5);
        // Midway between A's underside (0.45 - 0.25) and B's top (0.25).
        assert_close(out.points[0].position, vec3(0.0, 0.225, 0.3));
        assert_eq!(out.points[0].id, 0);
    }

    #[test]
    fn parallel_capsules_touch_at_both_ends_of_their_overlap() {
        let mut out = Manifold::default();
        let a = capsule(0.25, 1.0);
        // A spans x in [-0.5, 1.5], B spans [-1, 1]: they overlap on [-0.5, 1].
        capsule_capsule(
            &a,
            &along_x(vec3(0.5, 0.45, 0.0)),
            &a,
            &along_x(Vec3::ZERO),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 2);
        assert_close(out.normal, Vec3::Y);
        assert_eq!((out.points[0].id, out.points[1].id), (0, 1));
        assert_close(out.points[0].position, vec3(-0.5, 0.225, 0.0));
        assert_close(out.points[1].position, vec3(1.0, 0.225, 0.0));
        for point in out.points() {
            assert!((point.separation + 0.05).abs() < 1e-5);
        }
        // B reversed (its -half_height end at +x): the same ids, by A's ends.
        let mut reversed = Manifold::default();
        let pose_b = Transform::new(Vec3::ZERO, Quat::from_rotation_z(FRAC_PI_2));
        capsule_capsule(
            &a,
            &along_x(vec3(0.5, 0.45, 0.0)),
            &a,
            &pose_b,
            0.02,
            &mut reversed,
        );
        assert_eq!(reversed.count, 2);
        for (point, other) in out.points().iter().zip(reversed.points()) {
            assert_close(point.position, other.position);
            assert_eq!(point.id, other.id);
        }
    }

    #[test]
    fn degenerate_capsule_pairs_stay_finite() {
        let a = capsule(0.25, 1.0);
        let ball = capsule(0.25, 0.0);
        // Coaxial and overlapping: sideways along B's local x, at both ends of the overlap.
        let mut out = Manifold::default();
        capsule_capsule(
            &a,
            &along_x(vec3(0.3, 0.0, 0.0)),
            &a,
            &along_x(Vec3::ZERO),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 2);
        assert_close(out.normal, along_x(Vec3::ZERO).transform_vector(Vec3::X));
        assert!(
            out.points()
                .iter()
                .all(|point| (point.separation + 0.5).abs() < 1e-5)
        );
        let cases = [
            // Two balls in one place.
            (ball, Transform::IDENTITY, ball, Transform::IDENTITY, -0.5),
            // A ball on B's axis.
            (
                ball,
                Transform::from_position(vec3(0.5, 0.0, 0.0)),
                a,
                along_x(Vec3::ZERO),
                -0.5,
            ),
            // Axes crossing: the cross product, turned from B's centre to A's.
            (
                a,
                along_x(vec3(0.0, 0.0, 0.0)),
                a,
                along_z(vec3(0.0, 0.0, 0.0)),
                -0.5,
            ),
        ];
        for (a, pose_a, b, pose_b, separation) in cases {
            let mut out = Manifold::default();
            capsule_capsule(&a, &pose_a, &b, &pose_b, 0.02, &mut out);
            assert_eq!(out.count, 1, "{pose_a:?}");
            assert!((out.normal.length() - 1.0).abs() < 1e-5);
            assert!((out.points[0].separation - separation).abs() < 1e-5);
            assert!(out.points[0].position.is_finite());
        }
    }

    #[test]
    fn capsules_apart_beyond_and_within_the_margin() {
        let a = capsule(0.25, 1.0);
        let mut out = Manifold::default();
        capsule_capsule(
            &a,
            &along_x(vec3(0.0, 0.53, 0.0)),
            &a,
            &along_z(Vec3::ZERO),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 0);
        capsule_capsule(
            &a,
            &along_x(vec3(0.0, 0.51, 0.0)),
            &a,
            &along_z(Vec3::ZERO),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert!((out.points[0].separation - 0.01).abs() < 1e-5);
    }

    /// A box of half extents (1, 0.5, 1), turned and moved; capsule poses given in its frame.
    fn box_and_pose() -> (Cuboid, Transform) {
        (
            Cuboid {
                half_extents: vec3(1.0, 0.5, 1.0),
            },
            Transform::new(vec3(1.0, -0.5, 2.0), Quat::from_rotation_y(0.4)),
        )
    }

    #[test]
    fn capsule_lying_on_a_box_face_rests_on_two_points() {
        let (cuboid, pose_b) = box_and_pose();
        let a = capsule(0.2, 0.8);
        // Spans x in [-0.3, 1.3] in the box frame, 0.01 into the top face; past x = 1 it hangs
        // over the edge, so the second point is at the rim.
        let pose_a = pose_b.mul_transform(&along_x(vec3(0.5, 0.69, 0.3)));
        let mut out = Manifold::default();
        capsule_box(&a, &pose_a, &cuboid, &pose_b, 0.02, &mut out);
        assert_eq!(out.count, 2);
        assert_close(out.normal, pose_b.transform_vector(Vec3::Y));
        assert_eq!((out.points[0].id, out.points[1].id), (0, 1));
        assert_close(
            out.points[0].position,
            pose_b.transform_point(vec3(-0.3, 0.495, 0.3)),
        );
        assert_close(
            out.points[1].position,
            pose_b.transform_point(vec3(1.0, 0.495, 0.3)),
        );
        for point in out.points() {
            assert!((point.separation + 0.01).abs() < 1e-5);
        }

        // Tilted by 0.1 rad about z: only the lower (-half_height) end within the margin.
        let tilted = Transform::new(
            vec3(0.0, 0.69 + 0.8 * 0.1f32.sin(), 0.0),
            Quat::from_rotation_z(-FRAC_PI_2 + 0.1),
        );
        let mut out = Manifold::default();
        capsule_box(
            &a,
            &pose_b.mul_transform(&tilted),
            &cuboid,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_eq!(out.points[0].id, 0);
        assert_close(out.normal, pose_b.transform_vector(Vec3::Y));
        assert!((out.points[0].separation + 0.01).abs() < 1e-4);
    }

    #[test]
    fn capsule_beside_a_box_edge_touches_at_one_point() {
        let (cuboid, pose_b) = box_and_pose();
        let a = capsule(0.2, 0.5);
        // Parallel to the edge x = 1, y = 0.5, 0.19 away diagonally, within z in [-1, 1].
        let diagonal = vec3(1.0, 1.0, 0.0).normalize();
        let center = vec3(1.0, 0.5, 0.2) + diagonal * 0.19;
        let mut out = Manifold::default();
        capsule_box(
            &a,
            &pose_b.mul_transform(&along_z(center)),
            &cuboid,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, pose_b.transform_vector(diagonal));
        assert!((out.points[0].separation + 0.01).abs() < 1e-5);
    }

    #[test]
    fn capsule_through_a_box_leaves_by_the_nearest_face_or_edge() {
        let (cuboid, pose_b) = box_and_pose();
        let a = capsule(0.2, 1.0);
        // Upright through the box, its axis 0.1 inside the +x face: two points on the face's
        // rim, 0.1 + radius deep, midway between the capsule's side (x = 0.7) and the face.
        let upright = Transform::from_position(vec3(0.9, 0.0, 0.0));
        let mut out = Manifold::default();
        capsule_box(
            &a,
            &pose_b.mul_transform(&upright),
            &cuboid,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 2);
        assert_close(out.normal, pose_b.transform_vector(Vec3::X));
        for point in out.points() {
            assert!((point.separation + 0.3).abs() < 1e-5);
        }
        assert_close(
            out.points[0].position,
            pose_b.transform_point(vec3(0.85, -0.5, 0.0)),
        );
        assert_close(
            out.points[1].position,
            pose_b.transform_point(vec3(0.85, 0.5, 0.0)),
        );

        // Across the edge x = 1, y = 0.5 (along z), diagonally through (0.9, 0.4, 0): the edge
        // axis, 0.1 * sqrt(2) deep, one point.
        let diagonal = vec3(1.0, 1.0, 0.0).normalize();
        let across = Transform::new(vec3(0.9, 0.4, 0.0), Quat::from_rotation_z(FRAC_PI_2 / 2.0));
        let mut out = Manifold::default();
        capsule_box(
            &a,
            &pose_b.mul_transform(&across),
            &cuboid,
            &pose_b,
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_close(out.normal, pose_b.transform_vector(diagonal));
        let depth = 0.1 * std::f32::consts::SQRT_2;
        assert!((out.points[0].separation + depth + 0.2).abs() < 1e-5);
        let expected = vec3(1.0, 0.5, 0.0) + diagonal * (-depth - 0.2) * 0.5;
        assert_close(out.points[0].position, pose_b.transform_point(expected));
    }

    #[test]
    fn capsule_without_straight_part_is_a_sphere_against_a_box() {
        let (cuboid, pose_b) = box_and_pose();
        let pose_a = pose_b.mul_transform(&Transform::from_position(vec3(0.2, 0.6, 0.1)));
        let mut out = Manifold::default();
        capsule_box(
            &capsule(0.3, 0.0),
            &pose_a,
            &cuboid,
            &pose_b,
            0.02,
            &mut out,
        );
        let mut expected = Manifold::default();
        sphere_box(
            &Sphere { radius: 0.3 },
            &pose_a,
            &cuboid,
            &pose_b,
            0.02,
            &mut expected,
        );
        assert_eq!(out, expected);
        assert_eq!(out.count, 1);
    }

    /// Random capsules and boxes: where they are apart, the deepest point's separation is
    /// their distance (brute force along the segment); every point lies between the surfaces:
    /// half the separation behind it along the normal is the box's surface, half ahead is on
    /// or inside the capsule.
    #[test]
    fn random_capsule_box_pairs_give_consistent_points() {
        let mut state: u32 = 0x9e37_79b9;
        let mut random = move || {
            // xorshift32: deterministic, no dependency.
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let margin = 0.02;
        let mut touching = 0;
        for _ in 0..2000 {
            let mut random_vector = |low: f32, high: f32| {
                Vec3::new(random(), random(), random()) * (high - low) + Vec3::splat(low)
            };
            let half = random_vector(0.1, 1.0);
            let shape = random_vector(0.0, 1.0);
            let a = capsule(0.05 + 0.45 * shape.x, shape.y);
            let pose_a = Transform::new(
                random_vector(-1.8, 1.8),
                Quat::from_vec4(random_vector(-1.0, 1.0).extend(0.4)).normalize(),
            );
            let pose_b = Transform::new(
                random_vector(-0.2, 0.2),
                Quat::from_vec4(random_vector(-1.0, 1.0).extend(-0.6)).normalize(),
            );
            let cuboid = Cuboid { half_extents: half };
            let mut out = Manifold::default();
            capsule_box(&a, &pose_a, &cuboid, &pose_b, margin, &mut out);

            let box_distance = |point: Vec3| {
                let q = pose_b.inverse_transform_point(point).abs() - half;
                q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
            };
            let (start, delta) = world_segment(&a, &pose_a);
            let segment_distance = (0..=4000)
                .map(|step| box_distance(start + delta * (step as f32 / 4000.0)))
                .fold(f32::INFINITY, f32::min);
            let distance = segment_distance - a.radius;
            if distance >= margin + 1e-3 {
                assert_eq!(out.count, 0, "apart by {distance}");
            }
            if distance < -1e-3 {
                assert!(out.count > 0, "overlapping by {distance}");
            }
            if out.count == 0 {
                continue;
            }
            touching += 1;
            assert!((out.normal.length() - 1.0).abs() < 1e-5);
            let deepest = out
                .points()
                .iter()
                .map(|point| point.separation)
                .fold(f32::INFINITY, f32::min);
            if segment_distance > 1e-3 {
                assert!((deepest - distance).abs() < 1e-3, "{deepest} vs {distance}");
            }
            for point in out.points() {
                assert!(point.separation < margin);
                let on_a = point.position + out.normal * (0.5 * point.separation);
                let on_b = point.position - out.normal * (0.5 * point.separation);
                let t = closest_parameter_to_point(on_a, start, delta);
                let capsule_distance = (on_a - (start + delta * t)).length() - a.radius;
                assert!(capsule_distance < 1e-4, "{point:?}: {capsule_distance}");
                assert!(
                    box_distance(on_b).abs() < 1e-4,
                    "{point:?}: {}",
                    box_distance(on_b)
                );
            }
        }
        assert!(touching > 300, "{touching}");
    }

    #[test]
    fn segment_box_closest_parameter_is_exact() {
        let half = vec3(1.0, 0.5, 1.0);
        // Passes over the corner region then the top face: nearest where it is lowest.
        let t = closest_parameter_segment_box(vec3(-3.0, 2.0, 0.0), vec3(4.0, -1.0, 0.0), half);
        assert!((t - 1.0).abs() < 1e-6);
        // Points (3 - 4t, 2, 4t) pass the corner region x > 1, z > 1 at a height: for t in
        // [0.25, 0.5] the distance² is 1.5² + (2 - 4t)² + (4t - 1)², least at t = 0.375.
        let t = closest_parameter_segment_box(vec3(3.0, 2.0, 0.0), vec3(-4.0, 0.0, 4.0), half);
        assert!((t - 0.375).abs() < 1e-5, "{t}");
    }
}
