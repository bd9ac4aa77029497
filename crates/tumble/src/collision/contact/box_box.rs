//! Box–box: the separating-axis test over 15 axes, then a face contact or an edge contact.
//!
//! # Method
//!
//! Everything is computed in B's frame, where B is axis aligned at the origin and A has the
//! rotation `R = R_B^T R_A` (its axes are the columns) and centre `t`. The 15 axes are B's three
//! face normals, A's three, and the nine cross products `e_i × a_j` of an edge direction of each
//! (skipped when nearly parallel: they are then mostly rounding). Along each axis the
//! separation is the gap between the two projections (m, > 0 apart); any gap `>= margin`
//! proves the boxes too far apart and ends the test. Otherwise the axis with the largest
//! separation (least penetration) is the contact normal, with a preference for faces: an edge
//! axis must beat the best face by 5 % and 0.5 mm, and one box's face beats the other's only
//! by 2 % and 0.5 mm (else the box with the larger face is the reference, B on a tie), so the
//! choice does not flip from step to step on rounding.
//!
//! - Face contact: the chosen face is the reference face; the incident face is the face of
//!   the other box most anti-parallel to it. The incident face (4 vertices) is clipped against
//!   the reference face's 4 side planes (Sutherland–Hodgman, at most 8 vertices); each clipped
//!   vertex below `margin` above the reference face is a point, placed midway between the
//!   vertex and its projection on the reference face. More than 4 go through [`reduce`].
//! - Edge contact: one point, midway between the closest points of the two edges that reach
//!   furthest towards each other along the normal.
//!
//! # Feature ids
//!
//! Face contact, bits from the lowest:
//!
//! - bits 0–5, the clip feature: `0..=3` an incident face vertex (in the face's winding order);
//!   `4 + 4 * line + plane` a vertex cut by side plane `plane` (0..=3) on the polygon edge lying
//!   on `line`: `0..=3` an incident face edge (from vertex `line` to `line + 1`), `4..=7` side
//!   plane `line - 4` (the vertex is then a corner of the reference face).
//! - bits 6–8: the reference face, `2 * axis + (1 if its normal is along -axis)`.
//! - bits 9–11: the incident face, same encoding, in its own box.
//! - bit 12: set when the reference face is A's.
//!
//! Side planes of a reference face along `axis` are numbered `+u, -u, +v, -v` with
//! `u = (axis + 1) % 3`, `v = (axis + 2) % 3`. Edge contact: bit 13 set, B's edge index in
//! bits 0–3 and A's in bits 4–7, an edge index being `4 * axis + (1 if on the + side of
//! (axis + 1) % 3) + (2 if on the + side of (axis + 2) % 3)`.

use super::segment::closest_parameters_between_segments;
use super::{
    EDGE_RELATIVE_TOLERANCE, Face, PARALLEL_SINE_SQUARED, clearly_greater, sign_or_positive,
};
use crate::collision::manifold::{ContactPoint, MAX_MANIFOLD_POINTS, Manifold, reduce};
use crate::math::{Mat3, Transform, Vec3};
use crate::shape::Cuboid;

/// One box's face is the reference only if its separation beats the other box's best face by
/// this fraction (see `clearly_greater`); within it, the larger face wins.
pub(super) const FACE_RELATIVE_TOLERANCE: f32 = 0.02;

/// Most vertices of the clipped incident face: a quadrilateral cut by four half-planes.
const MAX_CLIPPED_VERTICES: usize = 8;

/// Bit 12 of a face contact id: the reference face is A's.
pub(super) const REFERENCE_IS_A_BIT: u32 = 1 << 12;

/// Bit 13 of an id: an edge–edge contact.
pub(super) const EDGE_CONTACT_BIT: u32 = 1 << 13;

pub(super) fn box_box(
    a: &Cuboid,
    pose_a: &Transform,
    b: &Cuboid,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let half_a = a.half_extents;
    let half_b = b.half_extents;
    let rotation_a = Mat3::from_quat(pose_a.rotation);
    let rotation_b = Mat3::from_quat(pose_b.rotation);
    let to_b = rotation_b.transpose();
    let frame = RelativeFrame {
        rotation: to_b * rotation_a,
        translation: to_b * (pose_a.position - pose_b.position),
    };
    let rotation = frame.rotation;
    let translation = frame.translation;
    let absolute = Mat3::from_cols(
        rotation.x_axis.abs(),
        rotation.y_axis.abs(),
        rotation.z_axis.abs(),
    );

    // B's face normals e_i: A reaches Σ_j half_a_j |R_ij| = (|R| half_a)_i along e_i.
    let (axis_b, separation_b) = largest_component(translation.abs() - half_b - absolute * half_a);
    if separation_b >= margin {
        return;
    }
    // A's face normals a_j: the centres are (R^T t)_j apart along a_j, B reaches (|R|^T half_b)_j.
    let rotation_transposed = rotation.transpose();
    let translation_in_a = rotation_transposed * translation;
    let (axis_a, separation_a) =
        largest_component(translation_in_a.abs() - half_a - absolute.transpose() * half_b);
    if separation_a >= margin {
        return;
    }

    // Edge axes L = e_i × a_j, in closed form from R (Gottschalk et al., "OBBTree", 1996): with
    // (i, n, l) and (j, p, q) cyclic, L = (0 at i, -R_lj at n, R_nj at l), and
    // a_k · L = e_i · (a_j × a_k) leaves A's reach ha_p |R_iq| + ha_q |R_ip|. Unnormalized until
    // the separation is divided by |L|.
    let mut best_edge: Option<EdgeAxis> = None;
    for axis_of_b in 0..3 {
        let (next_b, last_b) = ((axis_of_b + 1) % 3, (axis_of_b + 2) % 3);
        for axis_of_a in 0..3 {
            let (next_a, last_a) = ((axis_of_a + 1) % 3, (axis_of_a + 2) % 3);
            let column = rotation.col(axis_of_a);
            let absolute_column = absolute.col(axis_of_a);
            // |L|² = 1 - R_ij², summed from the two other terms, which keeps its precision.
            let length_squared = column[next_b] * column[next_b] + column[last_b] * column[last_b];
            if length_squared <= PARALLEL_SINE_SQUARED {
                continue;
            }
            let along = translation[last_b] * column[next_b] - translation[next_b] * column[last_b];
            let reach_b =
                half_b[next_b] * absolute_column[last_b] + half_b[last_b] * absolute_column[next_b];
            let reach_a = half_a[next_a] * absolute.col(last_a)[axis_of_b]
                + half_a[last_a] * absolute.col(next_a)[axis_of_b];
            let inverse_length = length_squared.sqrt().recip();
            let separation = (along.abs() - reach_a - reach_b) * inverse_length;
            if separation >= margin {
                return;
            }
            if best_edge.is_none_or(|best| separation > best.separation) {
                let mut normal = Vec3::ZERO;
                normal[next_b] = -column[last_b];
                normal[last_b] = column[next_b];
                best_edge = Some(EdgeAxis {
                    normal: normal * (sign_or_positive(along) * inverse_length),
                    separation,
                    axis_of_b,
                    axis_of_a,
                });
            }
        }
    }

    let face_separation = separation_a.max(separation_b);
    if let Some(edge) = best_edge
        && clearly_greater(edge.separation, face_separation, EDGE_RELATIVE_TOLERANCE)
    {
        let world = RelativeFrame {
            rotation: rotation_b,
            translation: pose_b.position,
        };
        edge_contact(&edge, half_a, half_b, &frame, &world, margin, out);
        return;
    }

    let reference_is_a = if clearly_greater(separation_a, separation_b, FACE_RELATIVE_TOLERANCE) {
        true
    } else if clearly_greater(separation_b, separation_a, FACE_RELATIVE_TOLERANCE) {
        false
    } else {
        face_area(half_a, axis_a) > face_area(half_b, axis_b)
    };
    // The clipping runs in the reference box's frame.
    let (reference, incident, reference_rotation, reference_position) = if reference_is_a {
        // B's centre in A's frame is -R^T t; its axes there are the columns of R^T.
        let face = Face {
            axis: axis_a,
            sign: sign_or_positive(-translation_in_a[axis_a]),
        };
        let incident = IncidentBox {
            half: half_b,
            frame: RelativeFrame {
                rotation: rotation_transposed,
                translation: -translation_in_a,
            },
        };
        ((half_a, face), incident, rotation_a, pose_a.position)
    } else {
        let face = Face {
            axis: axis_b,
            sign: sign_or_positive(translation[axis_b]),
        };
        let incident = IncidentBox {
            half: half_a,
            frame,
        };
        ((half_b, face), incident, rotation_b, pose_b.position)
    };
    let (reference_half, face) = reference;
    let mut candidates = [ContactPoint::default(); MAX_CLIPPED_VERTICES];
    let count = clip_incident_face(reference_half, face, &incident, margin, &mut candidates);
    let id_flag = if reference_is_a {
        REFERENCE_IS_A_BIT
    } else {
        0
    };
    for candidate in &mut candidates[..count] {
        candidate.position = reference_position + reference_rotation * candidate.position;
        candidate.id |= id_flag;
    }
    // The reference normal points from the reference box to the incident one; the manifold's
    // from B to A.
    let reference_normal = reference_rotation * (face.sign * Vec3::AXES[face.axis]);
    let normal = if reference_is_a {
        -reference_normal
    } else {
        reference_normal
    };
    if count > MAX_MANIFOLD_POINTS {
        *out = reduce(&candidates[..count], normal);
    } else {
        out.normal = normal;
        for candidate in &candidates[..count] {
            out.push(*candidate);
        }
    }
}

/// A box's pose in another frame (another box's, or the world): its axes are the columns of
/// `rotation`, its centre is `translation` (m).
#[derive(Clone, Copy)]
struct RelativeFrame {
    rotation: Mat3,
    translation: Vec3,
}

/// The box whose face is clipped, in the reference box's frame.
struct IncidentBox {
    half: Vec3,
    frame: RelativeFrame,
}

/// The best edge axis: `normal` (unit, B's frame, from B to A), its separation (m), and the
/// axes of B and A whose edges it crosses.
#[derive(Clone, Copy)]
struct EdgeAxis {
    normal: Vec3,
    separation: f32,
    axis_of_b: usize,
    axis_of_a: usize,
}

/// (index, value) of the largest component; the lower index on ties.
#[inline]
fn largest_component(values: Vec3) -> (usize, f32) {
    let mut index = 0;
    for axis in 1..3 {
        if values[axis] > values[index] {
            index = axis;
        }
    }
    (index, values[index])
}

/// A quarter of the area of the faces normal to `axis` (m²): only compared.
#[inline]
fn face_area(half: Vec3, axis: usize) -> f32 {
    half[(axis + 1) % 3] * half[(axis + 2) % 3]
}

/// One point between the two edges that reach furthest towards each other along the edge
/// axis. `frame` is A in B's frame, `world` is B in world space.
fn edge_contact(
    edge: &EdgeAxis,
    half_a: Vec3,
    half_b: Vec3,
    frame: &RelativeFrame,
    world: &RelativeFrame,
    margin: f32,
    out: &mut Manifold,
) {
    let normal = edge.normal;
    // B's edge along e_i furthest along +normal: on the other axes, on the normal's side.
    let mut corner_b = Vec3::ZERO;
    for axis in 0..3 {
        corner_b[axis] = sign_or_positive(normal[axis]) * half_b[axis];
    }
    corner_b[edge.axis_of_b] = -half_b[edge.axis_of_b];
    let delta_b = 2.0 * half_b[edge.axis_of_b] * Vec3::AXES[edge.axis_of_b];
    // A's edge along a_j furthest along -normal, found in A's frame.
    let normal_in_a = frame.rotation.transpose() * normal;
    let mut corner_a = Vec3::ZERO;
    for axis in 0..3 {
        corner_a[axis] = -sign_or_positive(normal_in_a[axis]) * half_a[axis];
    }
    corner_a[edge.axis_of_a] = -half_a[edge.axis_of_a];
    let start_a = frame.translation + frame.rotation * corner_a;
    let delta_a = 2.0 * half_a[edge.axis_of_a] * frame.rotation.col(edge.axis_of_a);

    let (s, t) = closest_parameters_between_segments(start_a, delta_a, corner_b, delta_b);
    let point_a = start_a + delta_a * s;
    let point_b = corner_b + delta_b * t;
    let separation = (point_a - point_b).dot(normal);
    if separation >= margin {
        return;
    }
    out.normal = world.rotation * normal;
    out.push(ContactPoint::new(
        world.translation + world.rotation * (0.5 * (point_a + point_b)),
        separation,
        EDGE_CONTACT_BIT
            | edge_index(edge.axis_of_b, corner_b)
            | (edge_index(edge.axis_of_a, corner_a) << 4),
    ));
}

/// `4 * axis + (1 if corner is on the + side of (axis + 1) % 3) + (2 if of (axis + 2) % 3)`.
#[inline]
fn edge_index(axis: usize, corner: Vec3) -> u32 {
    4 * axis as u32
        + u32::from(corner[(axis + 1) % 3] > 0.0)
        + 2 * u32::from(corner[(axis + 2) % 3] > 0.0)
}

/// A vertex of the polygon being clipped, in the reference frame: its clip feature (module
/// docs) and the line the polygon edge leaving it lies on (0..=3 incident edges, 4..=7 side
/// planes).
#[derive(Clone, Copy, Default)]
struct ClipVertex {
    position: Vec3,
    feature: u8,
    line: u8,
}

#[derive(Clone, Copy, Default)]
struct Polygon {
    vertices: [ClipVertex; MAX_CLIPPED_VERTICES],
    count: usize,
}

impl Polygon {
    /// A convex quadrilateral cut by four half-planes has at most eight vertices; a ninth could
    /// only come from rounding on a vertex lying on a plane, a duplicate: it is left out.
    #[inline]
    fn push(&mut self, vertex: ClipVertex) {
        if self.count < MAX_CLIPPED_VERTICES {
            self.vertices[self.count] = vertex;
            self.count += 1;
        }
    }

    /// The part of the polygon where `sign * x[axis] <= limit` (Sutherland–Hodgman).
    fn clipped(&self, axis: usize, sign: f32, limit: f32, plane: u8) -> Polygon {
        let mut output = Polygon::default();
        if self.count == 0 {
            return output;
        }
        let distance = |position: Vec3| sign * position[axis] - limit;
        let mut previous = self.vertices[self.count - 1];
        let mut previous_distance = distance(previous.position);
        for &current in &self.vertices[..self.count] {
            let current_distance = distance(current.position);
            // The edge from `previous` to `current` lies on `previous.line`. The distances have
            // opposite signs when it crosses the plane, so the division is safe.
            let crossing = |line_after: u8| ClipVertex {
                position: previous.position
                    + (current.position - previous.position)
                        * (previous_distance / (previous_distance - current_distance)),
                feature: 4 + 4 * previous.line + plane,
                line: line_after,
            };
            if current_distance <= 0.0 {
                if previous_distance > 0.0 {
                    // Entering: the rest of the edge continues on its line.
                    output.push(crossing(previous.line));
                }
                output.push(current);
            } else if previous_distance <= 0.0 {
                // Leaving: the polygon now runs along the side plane until it re-enters.
                output.push(crossing(4 + plane));
            }
            previous = current;
            previous_distance = current_distance;
        }
        output
    }
}

/// Clips the incident box's face most anti-parallel to `face` against `face`'s side planes and
/// writes the clipped vertices closer than `margin` to the face into `candidates`, in the
/// reference frame, with their ids (without the reference-is-A bit). Returns how many.
fn clip_incident_face(
    reference_half: Vec3,
    face: Face,
    incident: &IncidentBox,
    margin: f32,
    candidates: &mut [ContactPoint; MAX_CLIPPED_VERTICES],
) -> usize {
    let reference_normal = face.sign * Vec3::AXES[face.axis];
    let rotation = incident.frame.rotation;
    // Cosine of each incident face normal with the reference normal: the most negative (in
    // absolute value, sign fixed after) is the incident face.
    let cosines = rotation.transpose() * reference_normal;
    let (incident_axis, _) = largest_component(cosines.abs());
    let incident_face = Face {
        axis: incident_axis,
        sign: -sign_or_positive(cosines[incident_axis]),
    };

    // The incident face's vertices in winding order, (+u, +v), (-u, +v), (-u, -v), (+u, -v).
    let half = incident.half;
    let u = (incident_axis + 1) % 3;
    let v = (incident_axis + 2) % 3;
    let mut polygon = Polygon::default();
    for (index, (sign_u, sign_v)) in [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
        .into_iter()
        .enumerate()
    {
        let mut corner = Vec3::ZERO;
        corner[incident_axis] = incident_face.sign * half[incident_axis];
        corner[u] = sign_u * half[u];
        corner[v] = sign_v * half[v];
        polygon.push(ClipVertex {
            position: incident.frame.translation + rotation * corner,
            feature: index as u8,
            line: index as u8,
        });
    }

    let side_u = (face.axis + 1) % 3;
    let side_v = (face.axis + 2) % 3;
    let side_planes = [(side_u, 1.0), (side_u, -1.0), (side_v, 1.0), (side_v, -1.0)];
    for (plane, (axis, sign)) in side_planes.into_iter().enumerate() {
        polygon = polygon.clipped(axis, sign, reference_half[axis], plane as u8);
    }

    let id_base = (face.index() << 6) | (incident_face.index() << 9);
    let mut count = 0;
    for vertex in &polygon.vertices[..polygon.count] {
        // Height of the clipped vertex above the reference face (m, < 0 below it).
        let separation = face.sign * vertex.position[face.axis] - reference_half[face.axis];
        if separation < margin {
            candidates[count] = ContactPoint::new(
                vertex.position - reference_normal * (0.5 * separation),
                separation,
                id_base | u32::from(vertex.feature),
            );
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};
    use std::f32::consts::{FRAC_PI_4, SQRT_2};

    fn cuboid(x: f32, y: f32, z: f32) -> Cuboid {
        Cuboid {
            half_extents: vec3(x, y, z),
        }
    }

    fn collide_boxes(
        a: &Cuboid,
        pose_a: &Transform,
        b: &Cuboid,
        pose_b: &Transform,
        margin: f32,
    ) -> Manifold {
        let mut out = Manifold::default();
        box_box(a, pose_a, b, pose_b, margin, &mut out);
        out
    }

    fn sorted_ids(manifold: &Manifold) -> Vec<u32> {
        let mut ids: Vec<u32> = manifold.points().iter().map(|point| point.id).collect();
        ids.sort();
        ids
    }

    /// A small box (A) 0.01 into the top of a big one (B), both turned about y, B moved.
    fn resting_pair(lift: f32) -> (Cuboid, Transform, Cuboid, Transform) {
        let small = cuboid(0.5, 0.25, 0.4);
        let big = cuboid(2.0, 0.5, 2.0);
        let pose_b = Transform::new(vec3(1.0, -2.0, 0.5), Quat::from_rotation_y(0.2));
        let local_a = Transform::new(
            vec3(0.3, 0.5 + 0.25 - 0.01 + lift, -0.2),
            Quat::from_rotation_y(0.5),
        );
        (small, pose_b.mul_transform(&local_a), big, pose_b)
    }

    #[test]
    fn box_resting_on_a_bigger_box_touches_at_its_four_bottom_corners() {
        let (small, pose_a, big, pose_b) = resting_pair(0.0);
        let out = collide_boxes(&small, &pose_a, &big, &pose_b, 0.02);
        assert_eq!(out.count, 4);
        let up = pose_b.transform_vector(Vec3::Y);
        assert!((out.normal - up).length() < 1e-5);
        for point in out.points() {
            assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
        }
        // Each point is a bottom corner of A moved half the overlap up.
        for (sign_x, sign_z) in [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)] {
            let corner = pose_a.transform_point(vec3(0.5 * sign_x, -0.25, 0.4 * sign_z));
            let expected = corner + up * 0.005;
            assert!(
                out.points()
                    .iter()
                    .any(|point| (point.position - expected).length() < 1e-5),
                "no point at {expected}"
            );
        }
        let ids = sorted_ids(&out);
        assert!(ids.windows(2).all(|pair| pair[0] != pair[1]));
    }

    #[test]
    fn swapped_boxes_give_the_same_points_with_the_normal_flipped() {
        let (small, pose_a, big, pose_b) = resting_pair(0.0);
        let forward = collide_boxes(&small, &pose_a, &big, &pose_b, 0.02);
        let backward = collide_boxes(&big, &pose_b, &small, &pose_a, 0.02);
        assert_eq!(forward.count, backward.count);
        assert!((forward.normal + backward.normal).length() < 1e-5);
        for point in forward.points() {
            assert!(backward.points().iter().any(|other| {
                (other.position - point.position).length() < 1e-5
                    && (other.separation - point.separation).abs() < 1e-5
            }));
        }
    }

    #[test]
    fn apart_within_the_margin_keeps_points_and_beyond_it_none() {
        let (small, pose_a, big, pose_b) = resting_pair(0.02);
        let out = collide_boxes(&small, &pose_a, &big, &pose_b, 0.02);
        assert_eq!(out.count, 4);
        for point in out.points() {
            assert!((point.separation - 0.01).abs() < 1e-5);
        }
        let (small, pose_a, big, pose_b) = resting_pair(0.04);
        assert_eq!(collide_boxes(&small, &pose_a, &big, &pose_b, 0.02).count, 0);
        // Apart sideways, beyond the margin on an edge axis only.
        let pose_a = Transform::new(vec3(0.0, 0.0, 0.0), Quat::from_rotation_y(FRAC_PI_4));
        let pose_b = Transform::from_position(vec3(0.5 + SQRT_2 * 0.5 + 0.03, 0.0, 0.0));
        let unit = cuboid(0.5, 0.5, 0.5);
        assert_eq!(collide_boxes(&unit, &pose_a, &unit, &pose_b, 0.02).count, 0);
    }

    #[test]
    fn ids_stay_the_same_while_the_same_features_touch() {
        let (small, pose_a, big, pose_b) = resting_pair(0.0);
        let before = collide_boxes(&small, &pose_a, &big, &pose_b, 0.02);
        let nudged = Transform::new(
            pose_a.position + vec3(0.002, -0.001, 0.003),
            Quat::from_rotation_x(0.002) * Quat::from_rotation_y(0.01) * pose_a.rotation,
        );
        let after = collide_boxes(&small, &nudged, &big, &pose_b, 0.02);
        assert_eq!(after.count, 4);
        assert_eq!(sorted_ids(&before), sorted_ids(&after));
    }

    #[test]
    fn box_turned_45_degrees_on_an_equal_box_keeps_four_of_eight_points() {
        let unit = cuboid(0.5, 0.5, 0.5);
        let local_a = Transform::new(vec3(0.0, 1.0, 0.0), Quat::from_rotation_y(FRAC_PI_4));
        // The clip alone: the octagon where the two squares overlap.
        let incident = IncidentBox {
            half: unit.half_extents,
            frame: RelativeFrame {
                rotation: Mat3::from_quat(local_a.rotation),
                translation: local_a.position,
            },
        };
        let face = Face { axis: 1, sign: 1.0 };
        let mut candidates = [ContactPoint::default(); MAX_CLIPPED_VERTICES];
        let count = clip_incident_face(unit.half_extents, face, &incident, 0.02, &mut candidates);
        assert_eq!(count, 8);
        let mut ids: Vec<u32> = candidates.iter().map(|point| point.id).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), 8);

        let pose_b = Transform::new(vec3(3.0, 1.0, -2.0), Quat::from_rotation_z(0.3));
        let out = collide_boxes(&unit, &pose_b.mul_transform(&local_a), &unit, &pose_b, 0.02);
        assert_eq!(out.count, 4);
        let mut corners = Vec::new();
        for point in out.points() {
            assert!(point.separation.abs() < 1e-5);
            let local = pose_b.inverse_transform_point(point.position);
            assert!((local.y - 0.5).abs() < 1e-5);
            assert!(local.x.abs() <= 0.5 + 1e-5 && local.z.abs() <= 0.5 + 1e-5);
            corners.push(local);
        }
        // Spread: the kept quadrilateral covers most of the octagon (area 2√2 - 2 ≈ 0.83 m²);
        // the best four of eight vertices cover 1/√2 of it.
        corners.sort_by(|p, q| p.z.atan2(p.x).total_cmp(&q.z.atan2(q.x)));
        let mut area = 0.0;
        for index in 0..4 {
            let (p, q) = (corners[index], corners[(index + 1) % 4]);
            area += 0.5 * (p.x * q.z - q.x * p.z);
        }
        let octagon = 2.0 * SQRT_2 - 2.0;
        assert!(area.abs() > 0.65 * octagon, "area {area}");
    }

    #[test]
    fn crossed_edges_touch_at_one_point() {
        let unit = cuboid(1.0, 1.0, 1.0);
        // B turned 45° about z: its top is the edge along z at height √2. A turned 45° about
        // x: its bottom is the edge along x, √2 under its centre. 0.05 overlap.
        let pose_b = Transform::new(Vec3::ZERO, Quat::from_rotation_z(FRAC_PI_4));
        let pose_a = Transform::new(
            vec3(0.0, 2.0 * SQRT_2 - 0.05, 0.0),
            Quat::from_rotation_x(FRAC_PI_4),
        );
        let out = collide_boxes(&unit, &pose_a, &unit, &pose_b, 0.02);
        assert_eq!(out.count, 1);
        assert!((out.normal - Vec3::Y).length() < 1e-5);
        assert!((out.points[0].separation + 0.05).abs() < 1e-5);
        assert!((out.points[0].position - vec3(0.0, SQRT_2 - 0.025, 0.0)).length() < 1e-5);
        assert_ne!(out.points[0].id & EDGE_CONTACT_BIT, 0);

        // Moved a little along both edges: the same edges, the same id.
        let moved = Transform::new(pose_a.position + vec3(0.1, 0.0, -0.2), pose_a.rotation);
        let after = collide_boxes(&unit, &moved, &unit, &pose_b, 0.02);
        assert_eq!(after.count, 1);
        assert_eq!(after.points[0].id, out.points[0].id);
        assert!((after.points[0].separation + 0.05).abs() < 1e-5);

        // Apart by 0.01: kept, positive.
        let apart = Transform::new(pose_a.position + vec3(0.0, 0.06, 0.0), pose_a.rotation);
        let out = collide_boxes(&unit, &apart, &unit, &pose_b, 0.02);
        assert_eq!(out.count, 1);
        assert!((out.points[0].separation - 0.01).abs() < 1e-5);
    }

    /// Signed distance from `point` to the surface of the box (m, < 0 inside).
    fn box_distance(half: Vec3, pose: &Transform, point: Vec3) -> f32 {
        let q = pose.inverse_transform_point(point).abs() - half;
        q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
    }

    fn box_vertices(half: Vec3, pose: &Transform) -> [Vec3; 8] {
        std::array::from_fn(|index| {
            let signs = Vec3::new(
                if index & 1 != 0 { 1.0 } else { -1.0 },
                if index & 2 != 0 { 1.0 } else { -1.0 },
                if index & 4 != 0 { 1.0 } else { -1.0 },
            );
            pose.transform_point(signs * half)
        })
    }

    /// Gap between the boxes' vertex projections on `axis`: A's lowest minus B's highest.
    fn gap_along(axis: Vec3, vertices_a: &[Vec3; 8], vertices_b: &[Vec3; 8]) -> f32 {
        let lowest_a = vertices_a
            .iter()
            .map(|v| v.dot(axis))
            .fold(f32::INFINITY, f32::min);
        let highest_b = vertices_b
            .iter()
            .map(|v| v.dot(axis))
            .fold(f32::NEG_INFINITY, f32::max);
        lowest_a - highest_b
    }

    /// Random pairs of boxes: every point lies between the two surfaces, its separation is the
    /// distance between them along the normal, never deeper than the boxes' overlap along it;
    /// no points where an independent separating axis (brute force over vertices) says apart.
    #[test]
    fn random_box_pairs_give_consistent_points() {
        let mut state: u32 = 0x2545_f491;
        let mut random = move || {
            // xorshift32: deterministic, no dependency.
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let margin = 0.02;
        let mut touching = 0;
        for _ in 0..3000 {
            let mut random_vector = |low: f32, high: f32| {
                Vec3::new(random(), random(), random()) * (high - low) + Vec3::splat(low)
            };
            let half_a = random_vector(0.1, 1.0);
            let half_b = random_vector(0.1, 1.0);
            let offset = random_vector(-1.5, 1.5);
            let rotation_a = Quat::from_vec4(random_vector(-1.0, 1.0).extend(0.5)).normalize();
            let rotation_b = Quat::from_vec4(random_vector(-1.0, 1.0).extend(-0.3)).normalize();
            let pose_a = Transform::new(offset, rotation_a);
            let pose_b = Transform::new(Vec3::ZERO, rotation_b);
            let out = collide_boxes(
                &cuboid(half_a.x, half_a.y, half_a.z),
                &pose_a,
                &cuboid(half_b.x, half_b.y, half_b.z),
                &pose_b,
                margin,
            );

            let vertices_a = box_vertices(half_a, &pose_a);
            let vertices_b = box_vertices(half_b, &pose_b);
            let axes_a = [0, 1, 2].map(|axis| pose_a.transform_vector(Vec3::AXES[axis]));
            let axes_b = [0, 1, 2].map(|axis| pose_b.transform_vector(Vec3::AXES[axis]));
            let mut axes: Vec<Vec3> = axes_a.iter().chain(&axes_b).copied().collect();
            for axis_a in axes_a {
                for axis_b in axes_b {
                    let cross = axis_a.cross(axis_b);
                    if cross.length_squared() > 1e-6 {
                        axes.push(cross.normalize());
                    }
                }
            }
            let separation = axes
                .iter()
                .map(|&axis| {
                    gap_along(axis, &vertices_a, &vertices_b).max(gap_along(
                        -axis,
                        &vertices_a,
                        &vertices_b,
                    ))
                })
                .fold(f32::NEG_INFINITY, f32::max);
            if separation >= margin + 1e-4 {
                assert_eq!(out.count, 0, "apart by {separation}: {out:?}");
            }
            if separation < -0.01 {
                assert!(
                    out.count > 0,
                    "overlapping by {separation}: {half_a} {half_b} {pose_a:?} {pose_b:?}"
                );
            }
            if out.count == 0 {
                continue;
            }
            touching += 1;
            let normal = out.normal;
            assert!((normal.length() - 1.0).abs() < 1e-5);
            let overlap_along_normal = gap_along(normal, &vertices_a, &vertices_b);
            let ids = sorted_ids(&out);
            assert!(ids.windows(2).all(|pair| pair[0] != pair[1]), "{ids:?}");
            for point in out.points() {
                assert!(point.separation < margin);
                assert!(
                    point.separation >= overlap_along_normal - 1e-4,
                    "{point:?} {overlap_along_normal}"
                );
                let on_a = point.position + normal * (0.5 * point.separation);
                let on_b = point.position - normal * (0.5 * point.separation);
                let distance_a = box_distance(half_a, &pose_a, on_a);
                let distance_b = box_distance(half_b, &pose_b, on_b);
                assert!(
                    distance_a.abs() < 1e-4 && distance_b.abs() < 1e-4,
                    "{point:?}: {distance_a} {distance_b} {out:?} {half_a} {half_b} {pose_a:?} {pose_b:?}"
                );
            }
        }
        assert!(touching > 500, "{touching}");
    }
}
