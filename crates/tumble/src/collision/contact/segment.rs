//! Closest points on segments: the core of the capsule pairs and of box edge–edge contacts.
//!
//! A segment is `start + t * delta` for `t ∈ [0, 1]`. Every function returns parameters, not
//! points, so callers can tell which end a point came from (feature ids), and never divides by
//! a length that may be zero.

use crate::math::Vec3;

/// Squared length (m²) under which a segment is a point: its direction means nothing.
pub(super) const DEGENERATE_LENGTH_SQUARED: f32 = 1.0e-12;

/// `sin²` of the angle under which two segments are parallel: the closest points are then a
/// whole interval and one of them is picked without dividing by the vanishing determinant.
pub(super) const PARALLEL_SINE_SQUARED: f32 = 1.0e-10;

/// Parameter of the point of the segment closest to `point`.
#[inline]
pub(crate) fn closest_parameter_to_point(point: Vec3, start: Vec3, delta: Vec3) -> f32 {
    let length_squared = delta.length_squared();
    if length_squared <= DEGENERATE_LENGTH_SQUARED {
        return 0.0;
    }
    ((point - start).dot(delta) / length_squared).clamp(0.0, 1.0)
}

/// Parameters `(s, t)` of the closest points `start_a + s * delta_a` and
/// `start_b + t * delta_b` of two segments (Ericson, "Real-Time Collision Detection", 5.1.9).
/// Parallel segments get `s = 0` unless that end lies past `b`, so the answer is deterministic.
pub(crate) fn closest_parameters_between_segments(
    start_a: Vec3,
    delta_a: Vec3,
    start_b: Vec3,
    delta_b: Vec3,
) -> (f32, f32) {
    let length_a_squared = delta_a.length_squared();
    let length_b_squared = delta_b.length_squared();
    let start_offset = start_a - start_b;
    let along_b = delta_b.dot(start_offset);
    if length_a_squared <= DEGENERATE_LENGTH_SQUARED {
        if length_b_squared <= DEGENERATE_LENGTH_SQUARED {
            return (0.0, 0.0);
        }
        return (0.0, (along_b / length_b_squared).clamp(0.0, 1.0));
    }
    let along_a = delta_a.dot(start_offset);
    if length_b_squared <= DEGENERATE_LENGTH_SQUARED {
        return ((-along_a / length_a_squared).clamp(0.0, 1.0), 0.0);
    }
    let cosine_term = delta_a.dot(delta_b);
    // |delta_a × delta_b|² = |delta_a|² |delta_b|² sin²(angle).
    let determinant = length_a_squared * length_b_squared - cosine_term * cosine_term;
    let mut s = if determinant > PARALLEL_SINE_SQUARED * length_a_squared * length_b_squared {
        ((cosine_term * along_b - along_a * length_b_squared) / determinant).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut t = (cosine_term * s + along_b) / length_b_squared;
    // The point of b nearest to a's point fell off b: clamp it and take a's point again.
    if t < 0.0 {
        t = 0.0;
        s = (-along_a / length_a_squared).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((cosine_term - along_a) / length_a_squared).clamp(0.0, 1.0);
    }
    (s, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3;

    #[test]
    fn crossing_segments_meet_at_their_middles() {
        let (s, t) = closest_parameters_between_segments(
            vec3(-1.0, 0.0, 0.0),
            vec3(2.0, 0.0, 0.0),
            vec3(0.0, 1.0, -1.0),
            vec3(0.0, 0.0, 2.0),
        );
        assert!((s - 0.5).abs() < 1e-6 && (t - 0.5).abs() < 1e-6);
    }

    #[test]
    fn parallel_and_point_segments_give_finite_parameters() {
        // Parallel, overlapping: a's start (s = 0) is over b, so t is its projection.
        let (s, t) = closest_parameters_between_segments(
            vec3(0.0, 1.0, 0.0),
            vec3(2.0, 0.0, 0.0),
            vec3(-1.0, 0.0, 0.0),
            vec3(4.0, 0.0, 0.0),
        );
        assert_eq!((s, t), (0.0, 0.25));
        // Both segments points.
        let (s, t) =
            closest_parameters_between_segments(Vec3::ONE, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        assert_eq!((s, t), (0.0, 0.0));
        // a is a point above the middle of b.
        let (s, t) =
            closest_parameters_between_segments(Vec3::Y, Vec3::ZERO, -Vec3::X, 2.0 * Vec3::X);
        assert_eq!((s, t), (0.0, 0.5));
        assert_eq!(
            closest_parameter_to_point(Vec3::Y, Vec3::ZERO, Vec3::ZERO),
            0.0
        );
        assert_eq!(
            closest_parameter_to_point(vec3(5.0, 1.0, 0.0), Vec3::ZERO, Vec3::X),
            1.0
        );
    }
}
