//! Convex shapes against one triangle of a mesh: sphere and capsule by closest points, box by
//! the separating-axis test and clipping. The triangle is body B: the normal points from the
//! triangle to the convex shape.
//!
//! # Sides
//!
//! Triangles are two-sided: the normal of a face contact points to whichever side of the
//! triangle's plane the shape is on. Internal-edge correction (below) applies only on the front
//! side, where the mesh's active edges were judged (`shape::trimesh`).
//!
//! # Internal edges
//!
//! A contact whose closest triangle feature is an inactive edge, or a vertex whose two edges in
//! this triangle are inactive, takes the triangle's face normal instead of its own: on a flat
//! or concave seam the neighbouring triangle's face holds the shape, and a normal tilted
//! towards the seam would bump it sideways. Box contacts on such features are recomputed with
//! the triangle face as the reference face, so their points and separations belong to the
//! face normal. A corrected sphere or capsule point keeps its true distance as separation (never
//! less than the distance to the plane, so the correction cannot invent penetration).
//!
//! # Feature ids (unique within one triangle's manifold)
//!
//! | pair | ids |
//! |---|---|
//! | sphere | `0` |
//! | capsule | `0`, `1`: the ends of the part of the segment over the face, `0` towards the `-half_height` end; `2`: one point at the closest points |
//! | box, triangle face reference | clip feature (bits 0–6) · incident box face `<< 7` |
//! | box, box face reference | clip feature (bits 0–6) · reference box face `<< 7` · `1 << 10` |
//! | box, edge–edge | `1 << 11` · box edge axis `<< 2` · triangle edge |
//!
//! A clip feature is `0..=3` for an unclipped polygon vertex, else `8 + 8 · line + plane` for a
//! vertex cut by side plane `plane` on the polygon edge lying on `line` (polygon edges first,
//! then the side planes, numbered after them).

use super::segment::closest_parameters_between_segments;
use super::{
    EDGE_RELATIVE_TOLERANCE, Face, PARALLEL_SINE_SQUARED, clearly_greater, push_contact,
    sign_or_positive,
};
use crate::collision::manifold::{ContactPoint, Manifold, reduce};
use crate::math::{Transform, Vec3};
use crate::shape::Cuboid;
use crate::shape::trimesh::Triangle;

/// The box's face is the reference only if its separation beats the triangle face's by this
/// fraction (see `clearly_greater`): the triangle face gives steadier manifolds on a mesh.
pub(super) const FACE_RELATIVE_TOLERANCE: f32 = 0.02;

/// Distance (m) under which the closest points coincide: no direction, the face normal is used.
const COINCIDENT_DISTANCE: f32 = 1.0e-6;

/// Segment parameters closer than this give one capsule point, not two.
const COINCIDENT_PARAMETER: f32 = 1.0e-4;

/// Most vertices of a clipped polygon: a quadrilateral cut by three half-planes has at most 7,
/// a triangle cut by four at most 7.
const MAX_CLIPPED_VERTICES: usize = 8;

/// Bit 10 of a box id: the reference face is the box's.
const BOX_REFERENCE_BIT: u32 = 1 << 10;

/// Bit 11 of a box id: an edge–edge contact.
const EDGE_CONTACT_BIT: u32 = 1 << 11;

/// The part of a triangle a point is closest to. Edge `e` runs from vertex `e` to `(e + 1) % 3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Feature {
    Face,
    Edge(usize),
    Vertex(usize),
}

/// Closest point of the triangle to `point`, and its feature (Ericson, "Real-Time Collision
/// Detection", 5.1.5: Voronoi regions by barycentric tests, no division by a zero area).
pub(crate) fn closest_point_on_triangle(point: Vec3, vertices: &[Vec3; 3]) -> (Vec3, Feature) {
    let [a, b, c] = *vertices;
    let ab = b - a;
    let ac = c - a;
    let ap = point - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, Feature::Vertex(0));
    }
    let bp = point - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (a + ab * (d1 / (d1 - d3)), Feature::Edge(0));
    }
    let cp = point - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (a + ac * (d2 / (d2 - d6)), Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return (
            b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))),
            Feature::Edge(1),
        );
    }
    let denominator = 1.0 / (va + vb + vc);
    (
        a + ab * (vb * denominator) + ac * (vc * denominator),
        Feature::Face,
    )
}

impl Triangle {
    /// True when a contact on `feature` may have a normal other than the face's.
    pub(super) fn feature_is_active(&self, feature: Feature) -> bool {
        match feature {
            Feature::Face => false,
            Feature::Edge(edge) => self.edge_is_active(edge),
            Feature::Vertex(vertex) => self.vertex_is_active(vertex),
        }
    }

    /// How far (m) past each edge the contacts of a body on the front side (`front`) or the
    /// back reach: `margin` past a concave edge seen from the front (`shape::trimesh`, concave
    /// edges), 0 past the others.
    fn edge_reach(&self, margin: f32, front: bool) -> [f32; 3] {
        std::array::from_fn(|edge| {
            if front && self.edge_is_concave(edge) {
                margin.max(0.0)
            } else {
                0.0
            }
        })
    }

    /// Signed height of `point` over the triangle's plane (m), > 0 on the front side.
    fn height(&self, point: Vec3) -> f32 {
        self.normal.dot(point - self.vertices[0])
    }
}

/// Sphere (A) at `center` (mesh frame) against the triangle (B). Fills `out` in the mesh frame.
pub(crate) fn sphere_triangle(
    center: Vec3,
    radius: f32,
    triangle: &Triangle,
    margin: f32,
    out: &mut Manifold,
) {
    let (closest, feature) = closest_point_on_triangle(center, &triangle.vertices);
    let offset = center - closest;
    let distance = offset.length();
    let separation = distance - radius;
    if separation >= margin {
        return;
    }
    let height = triangle.height(center);
    let face_normal = sign_or_positive(height) * triangle.normal;
    let use_face = feature == Feature::Face
        || distance <= COINCIDENT_DISTANCE
        || (height >= 0.0 && !triangle.feature_is_active(feature));
    let normal = if use_face {
        face_normal
    } else {
        offset / distance
    };
    out.normal = normal;
    push_contact(out, center - normal * radius, normal, separation, 0);
}

/// Capsule (A) with segment `start → end` (mesh frame; `start` is the `-half_height` end) and
/// `radius`, against the triangle (B). Fills `out` in the mesh frame.
pub(crate) fn capsule_triangle(
    start: Vec3,
    end: Vec3,
    radius: f32,
    triangle: &Triangle,
    margin: f32,
    out: &mut Manifold,
) {
    let delta = end - start;
    let vertices = &triangle.vertices;
    // Closest points of the segment and the triangle: the segment piercing the face, an end
    // over the face, or the segment against an edge.
    let (mut segment_point, mut triangle_point, mut feature) = {
        let (point, feature) = closest_point_on_triangle(start, vertices);
        (start, point, feature)
    };
    let mut best = segment_point.distance_squared(triangle_point);
    let mut consider = |segment: Vec3, on_triangle: Vec3, candidate: Feature| {
        let distance_squared = segment.distance_squared(on_triangle);
        if distance_squared < best {
            best = distance_squared;
            (segment_point, triangle_point, feature) = (segment, on_triangle, candidate);
        }
    };
    let (point, candidate) = closest_point_on_triangle(end, vertices);
    consider(end, point, candidate);
    for edge in 0..3 {
        let edge_start = vertices[edge];
        let edge_delta = vertices[(edge + 1) % 3] - edge_start;
        let (s, t) = closest_parameters_between_segments(start, delta, edge_start, edge_delta);
        let on_edge = match t {
            0.0 => Feature::Vertex(edge),
            1.0 => Feature::Vertex((edge + 1) % 3),
            _ => Feature::Edge(edge),
        };
        consider(start + delta * s, edge_start + edge_delta * t, on_edge);
    }
    let (height_start, height_end) = (triangle.height(start), triangle.height(end));
    if height_start * height_end < 0.0 {
        // The segment crosses the plane: where, and is that inside the triangle?
        let crossing = start + delta * (height_start / (height_start - height_end));
        let (point, candidate) = closest_point_on_triangle(crossing, vertices);
        if candidate == Feature::Face {
            consider(crossing, point, Feature::Face);
        }
    }

    let distance = best.sqrt();
    if distance - radius >= margin {
        return;
    }
    // The side the capsule is on: that of its deeper end's farther-out twin, i.e. of the
    // segment's middle, so a capsule piercing the face is pushed out the way it mostly is.
    let middle_height = 0.5 * (height_start + height_end);
    let face_normal = sign_or_positive(middle_height) * triangle.normal;
    let use_face = feature == Feature::Face
        || distance <= COINCIDENT_DISTANCE
        || (middle_height >= 0.0 && !triangle.feature_is_active(feature));
    if !use_face {
        let normal = (segment_point - triangle_point) / distance;
        out.normal = normal;
        push_contact(
            out,
            segment_point - normal * radius,
            normal,
            distance - radius,
            2,
        );
        return;
    }
    // Face normal: the part of the segment standing over the face rests on it at both its
    // ends (a capsule lying flat gets two points, as on a box face); with no part over the
    // face, one point at the closest points.
    out.normal = face_normal;
    let side = sign_or_positive(middle_height);
    let reach = triangle.edge_reach(margin, side > 0.0);
    if let Some((low, high)) = clip_segment_to_prism(start, delta, triangle, reach) {
        for (id, parameter) in [(0, low), (1, high)] {
            if id == 1 && high - low <= COINCIDENT_PARAMETER {
                break;
            }
            let point = start + delta * parameter;
            let separation = side * triangle.height(point) - radius;
            if separation < margin {
                push_contact(
                    out,
                    point - face_normal * radius,
                    face_normal,
                    separation,
                    id,
                );
            }
        }
    }
    if out.count == 0 {
        let separation = if feature == Feature::Face {
            // Pierced (or touching) inside the face: how deep the nearer end reaches below the
            // side the capsule is on, so the push is along the face normal.
            (side * height_start).min(side * height_end).min(0.0) - radius
        } else {
            distance - radius
        };
        push_contact(
            out,
            segment_point - face_normal * radius,
            face_normal,
            separation,
            2,
        );
    }
}

/// The parameter interval `[low, high]` of the segment `start + s · delta`, `s ∈ [0, 1]`, that
/// lies over the triangle (inside the prism its edges sweep along its normal, each side moved
/// out by its `reach`, m); `None` when no part does.
fn clip_segment_to_prism(
    start: Vec3,
    delta: Vec3,
    triangle: &Triangle,
    reach: [f32; 3],
) -> Option<(f32, f32)> {
    let (mut low, mut high) = (0.0f32, 1.0f32);
    let vertices = &triangle.vertices;
    for edge in 0..3 {
        let edge_start = vertices[edge];
        let inward = triangle.normal.cross(vertices[(edge + 1) % 3] - edge_start);
        // inward · (start + s delta − edge_start) ≥ -reach |inward|.
        let at_start = inward.dot(start - edge_start) + reach[edge] * inward.length();
        let rate = inward.dot(delta);
        if rate.abs() <= f32::EPSILON * inward.length() * delta.length() {
            if at_start < 0.0 {
                return None;
            }
            continue;
        }
        let crossing = -at_start / rate;
        if rate > 0.0 {
            low = low.max(crossing);
        } else {
            high = high.min(crossing);
        }
        if low > high {
            return None;
        }
    }
    Some((low, high))
}

/// The axis the separating-axis test settled on.
#[derive(Clone, Copy, Debug)]
enum Axis {
    /// The triangle's normal, oriented from the triangle to the box.
    TriangleFace,
    /// A face normal of the box: the normal from the triangle to the box is `-face` normal.
    BoxFace(Face),
    /// Box edge along `axis` × triangle edge `edge`.
    Edges { axis: usize, edge: usize },
}

/// Box (A) at `box_pose` against the triangle (B), both in the same frame (the mesh's). Fills
/// `out` in that frame.
pub(crate) fn box_triangle(
    cuboid: &Cuboid,
    box_pose: &Transform,
    triangle: &Triangle,
    margin: f32,
    out: &mut Manifold,
) {
    // Work in the box frame: the box is axis aligned at the origin.
    let local = triangle_in_frame(triangle, box_pose);
    let half = cuboid.half_extents;
    let Some((axis, normal)) = separating_axis(half, &local, margin) else {
        return;
    };
    let mut local_out = Manifold::default();
    box_triangle_points(half, &local, axis, normal, margin, &mut local_out);
    let front = local.normal.dot(-local.vertices[0]) >= 0.0;
    // Apart (or touching) across an edge pair, the box rests one point on the triangle's edge,
    // and its face nearly parallel to the triangle swings onto it within the step: measured
    // on the landscape, a box tumbling at 2.4 rad/s put a corner 15 mm into a triangle whose
    // only contact was that edge point. While nothing overlaps, the points of the box face
    // clipped to the triangle are at their true heights over it (a box reaching over and
    // under the face would cross it and overlap), so they are speculative contacts that push
    // nothing early; the edge point's own distance is among them (where the clip meets the
    // triangle's edge).
    if front
        && matches!(axis, Axis::Edges { .. })
        && axis_separation(half, &local, normal).0 >= 0.0
        && axis_separation(half, &local, local.normal).0 < margin
    {
        let mut face_out = Manifold::default();
        box_triangle_points(
            half,
            &local,
            Axis::TriangleFace,
            local.normal,
            margin,
            &mut face_out,
        );
        if face_out.count > 0 {
            local_out = face_out;
        }
    }
    face_over_inactive_features(
        &local,
        matches!(axis, Axis::TriangleFace),
        &mut local_out,
        |point| triangle_feature(point.id),
        |face_out| {
            let (face_separation, _) = axis_separation(half, &local, local.normal);
            if face_separation < margin {
                box_triangle_points(
                    half,
                    &local,
                    Axis::TriangleFace,
                    local.normal,
                    margin,
                    face_out,
                );
            }
        },
    );
    push_from_frame(&local_out, box_pose, out);
}

/// `triangle` moved into the frame of `pose` (a box's or a hull's), where the polyhedral pairs
/// work.
pub(super) fn triangle_in_frame(triangle: &Triangle, pose: &Transform) -> Triangle {
    Triangle {
        vertices: triangle.vertices.map(|v| pose.inverse_transform_point(v)),
        normal: pose.inverse_transform_vector(triangle.normal),
        ..*triangle
    }
}

/// Appends `local` (a manifold in the frame of `pose`) to `out`, moved back out of that frame.
pub(super) fn push_from_frame(local: &Manifold, pose: &Transform, out: &mut Manifold) {
    out.normal = pose.transform_vector(local.normal);
    for point in local.points() {
        out.push(ContactPoint::new(
            pose.transform_point(point.position),
            point.separation,
            point.id,
        ));
    }
}

/// Internal edges for the polyhedral pairs (box and hull against a triangle; module docs): on
/// the triangle's front side, a contact `out` found on an axis other than the triangle's face
/// (`on_triangle_face` false) whose every point lies on an inactive edge or vertex is a
/// sideways normal from a seam, and is replaced by what `face_contact` makes with the
/// triangle's front face as the reference (nothing when that face separates them by the
/// margin). `feature_of` names the triangle feature a point of `out` lies on. All in the
/// shape's frame, where `local` is the triangle and the shape sits at the origin.
pub(super) fn face_over_inactive_features(
    local: &Triangle,
    on_triangle_face: bool,
    out: &mut Manifold,
    feature_of: impl Fn(&ContactPoint) -> Feature,
    face_contact: impl FnOnce(&mut Manifold),
) {
    // The shape (at the origin) is on the front side of the triangle's plane.
    let front = local.normal.dot(-local.vertices[0]) >= 0.0;
    if !front || on_triangle_face || out.count == 0 {
        return;
    }
    let on_inactive_features = out.points().iter().all(|point| {
        let feature = feature_of(point);
        feature != Feature::Face && !local.feature_is_active(feature)
    });
    if on_inactive_features {
        *out = Manifold::default();
        face_contact(out);
    }
}

/// The triangle feature a box point with a box-face or edge–edge `id` lies on, read from the
/// id (module docs) rather than from the point's position, where rounding could put a point
/// on an edge just inside the face. Box-face reference: an unclipped triangle vertex, a cut on
/// a triangle edge (its polygon line 0..=2), or a cut by a box side plane (inside the face).
fn triangle_feature(id: u32) -> Feature {
    if id & EDGE_CONTACT_BIT != 0 {
        return Feature::Edge((id & 3) as usize);
    }
    let clip_feature = id & 0x7f;
    if clip_feature < 8 {
        return Feature::Vertex(clip_feature as usize);
    }
    match (clip_feature - 8) / 8 {
        line @ 0..=2 => Feature::Edge(line as usize),
        _ => Feature::Face,
    }
}

/// Separation (m) of the box and triangle along unit `axis`, oriented so the box is on the
/// positive side of the returned direction (the orientation with the larger separation).
fn axis_separation(half: Vec3, triangle: &Triangle, axis: Vec3) -> (f32, Vec3) {
    let box_radius = half.dot(axis.abs());
    let projections = triangle.vertices.map(|v| v.dot(axis));
    let (low, high) = (
        projections[0].min(projections[1]).min(projections[2]),
        projections[0].max(projections[1]).max(projections[2]),
    );
    // Box above the triangle along +axis, or below it (along -axis).
    let above = -box_radius - high;
    let below = low - box_radius;
    if above >= below {
        (above, axis)
    } else {
        (below, -axis)
    }
}

/// The 13 axes: triangle normal, 3 box faces, 9 edge crosses. Returns the chosen axis and the
/// normal from the triangle to the box, or `None` when some axis separates them by `margin` or
/// more. Faces are preferred (see `clearly_greater`): the triangle's, then the box's, then
/// edges.
fn separating_axis(half: Vec3, triangle: &Triangle, margin: f32) -> Option<(Axis, Vec3)> {
    let (face_separation, face_normal) = axis_separation(half, triangle, triangle.normal);
    if face_separation >= margin {
        return None;
    }
    let mut best = (face_separation, Axis::TriangleFace, face_normal);
    let mut best_box_face: Option<(f32, Axis, Vec3)> = None;
    for axis in 0..3 {
        let (separation, normal) = axis_separation(half, triangle, Vec3::AXES[axis]);
        if separation >= margin {
            return None;
        }
        if best_box_face.is_none_or(|(s, _, _)| separation > s) {
            let face = Face {
                axis,
                // The box face facing the triangle is opposite the normal.
                sign: -sign_or_positive(normal[axis]),
            };
            best_box_face = Some((separation, Axis::BoxFace(face), normal));
        }
    }
    if let Some(candidate) = best_box_face
        && clearly_greater(candidate.0, best.0, FACE_RELATIVE_TOLERANCE)
    {
        best = candidate;
    }
    let best_face_separation = best.0;
    let mut best_edge: Option<(f32, Axis, Vec3)> = None;
    for axis in 0..3 {
        for edge in 0..3 {
            let direction = triangle.vertices[(edge + 1) % 3] - triangle.vertices[edge];
            let cross = Vec3::AXES[axis].cross(direction);
            if cross.length_squared() <= PARALLEL_SINE_SQUARED * direction.length_squared() {
                continue;
            }
            let (separation, normal) = axis_separation(half, triangle, cross.normalize());
            if separation >= margin {
                return None;
            }
            if best_edge.is_none_or(|(s, _, _)| separation > s) {
                best_edge = Some((separation, Axis::Edges { axis, edge }, normal));
            }
        }
    }
    if let Some(candidate) = best_edge
        && clearly_greater(candidate.0, best_face_separation, EDGE_RELATIVE_TOLERANCE)
    {
        best = candidate;
    }
    Some((best.1, best.2))
}

/// Contact points for the chosen axis, in the box frame. `normal` points from the triangle to
/// the box.
fn box_triangle_points(
    half: Vec3,
    triangle: &Triangle,
    axis: Axis,
    normal: Vec3,
    margin: f32,
    out: &mut Manifold,
) {
    let mut candidates = [ContactPoint::default(); MAX_CLIPPED_VERTICES];
    let mut count = 0;
    match axis {
        Axis::TriangleFace => {
            // Incident: the box face most anti-parallel to the normal.
            let (incident_axis, _) = largest_component(normal.abs());
            let incident = Face {
                axis: incident_axis,
                sign: -sign_or_positive(normal[incident_axis]),
            };
            let (u, v) = ((incident_axis + 1) % 3, (incident_axis + 2) % 3);
            let mut polygon = Polygon::default();
            for (index, (sign_u, sign_v)) in [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
                .into_iter()
                .enumerate()
            {
                let mut corner = Vec3::ZERO;
                corner[incident_axis] = incident.sign * half[incident_axis];
                corner[u] = sign_u * half[u];
                corner[v] = sign_v * half[v];
                polygon.push(ClipVertex {
                    position: corner,
                    feature: index as u8,
                    line: index as u8,
                });
            }
            // Side planes of the triangle, inward: front normal × edge direction (either side
            // of the triangle sees the same inside).
            for edge in 0..3 {
                let start = triangle.vertices[edge];
                let direction = triangle.vertices[(edge + 1) % 3] - start;
                let inward = triangle.normal.cross(direction);
                polygon = polygon.clipped(inward, inward.dot(start), 4, edge as u8);
            }
            let id_base = incident.index() << 7;
            let origin = triangle.vertices[0];
            for vertex in polygon.vertices() {
                let point_separation = normal.dot(vertex.position - origin);
                if point_separation < margin && count < MAX_CLIPPED_VERTICES {
                    candidates[count] = ContactPoint::new(
                        vertex.position - normal * (0.5 * point_separation),
                        point_separation,
                        id_base | u32::from(vertex.feature),
                    );
                    count += 1;
                }
            }
        }
        Axis::BoxFace(face) => {
            let face_normal = face.sign * Vec3::AXES[face.axis];
            let mut polygon = Polygon::default();
            for (index, &vertex) in triangle.vertices.iter().enumerate() {
                polygon.push(ClipVertex {
                    position: vertex,
                    feature: index as u8,
                    line: index as u8,
                });
            }
            let (u, v) = ((face.axis + 1) % 3, (face.axis + 2) % 3);
            for (plane, (axis, sign)) in [(u, 1.0), (u, -1.0), (v, 1.0), (v, -1.0)]
                .into_iter()
                .enumerate()
            {
                // Keep sign · x[axis] <= half[axis], i.e. inward · x >= -half[axis].
                let inward = -sign * Vec3::AXES[axis];
                polygon = polygon.clipped(inward, -half[axis], 3, plane as u8);
            }
            let id_base = BOX_REFERENCE_BIT | (face.index() << 7);
            for vertex in polygon.vertices() {
                // How far the triangle point lies outside the box face (m, < 0 inside).
                let point_separation = face_normal.dot(vertex.position) - half[face.axis];
                if point_separation < margin && count < MAX_CLIPPED_VERTICES {
                    let on_box = vertex.position - face_normal * point_separation;
                    candidates[count] = ContactPoint::new(
                        on_box - normal * (0.5 * point_separation),
                        point_separation,
                        id_base | u32::from(vertex.feature),
                    );
                    count += 1;
                }
            }
        }
        Axis::Edges { axis, edge } => {
            // The box edge along `axis` reaching furthest towards the triangle (along -normal).
            let mut box_start = Vec3::ZERO;
            for other in [(axis + 1) % 3, (axis + 2) % 3] {
                box_start[other] = -sign_or_positive(normal[other]) * half[other];
            }
            box_start[axis] = -half[axis];
            let mut box_delta = Vec3::ZERO;
            box_delta[axis] = 2.0 * half[axis];
            let edge_start = triangle.vertices[edge];
            let edge_delta = triangle.vertices[(edge + 1) % 3] - edge_start;
            let (s, t) =
                closest_parameters_between_segments(box_start, box_delta, edge_start, edge_delta);
            let on_box = box_start + box_delta * s;
            let on_triangle = edge_start + edge_delta * t;
            let point_separation = normal.dot(on_box - on_triangle);
            if point_separation < margin {
                out.normal = normal;
                push_contact(
                    out,
                    on_box,
                    normal,
                    point_separation,
                    EDGE_CONTACT_BIT | ((axis as u32) << 2) | edge as u32,
                );
            }
            return;
        }
    }
    *out = reduce(&candidates[..count], normal);
}

/// Index and value of the largest component.
fn largest_component(values: Vec3) -> (usize, f32) {
    let mut best = 0;
    for axis in 1..3 {
        if values[axis] > values[best] {
            best = axis;
        }
    }
    (best, values[best])
}

/// A vertex of a polygon being clipped: its clip feature (module docs) and the line the
/// polygon edge leaving it lies on.
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
    fn vertices(&self) -> &[ClipVertex] {
        &self.vertices[..self.count]
    }

    /// A vertex past [`MAX_CLIPPED_VERTICES`] can only be a rounding duplicate on a plane:
    /// left out.
    fn push(&mut self, vertex: ClipVertex) {
        if self.count < MAX_CLIPPED_VERTICES {
            self.vertices[self.count] = vertex;
            self.count += 1;
        }
    }

    /// The part where `inward · x >= offset` (Sutherland–Hodgman). Side planes are numbered
    /// `plane`, and as lines `first_plane_line + plane`.
    fn clipped(&self, inward: Vec3, offset: f32, first_plane_line: u8, plane: u8) -> Polygon {
        let mut output = Polygon::default();
        if self.count == 0 {
            return output;
        }
        // > 0 outside.
        let distance = |position: Vec3| offset - inward.dot(position);
        let mut previous = self.vertices[self.count - 1];
        let mut previous_distance = distance(previous.position);
        for &current in self.vertices() {
            let current_distance = distance(current.position);
            // Opposite signs when the edge crosses the plane, so the division is safe.
            let crossing = |line_after: u8| ClipVertex {
                position: previous.position
                    + (current.position - previous.position)
                        * (previous_distance / (previous_distance - current_distance)),
                feature: 8 + 8 * previous.line + plane,
                line: line_after,
            };
            if current_distance <= 0.0 {
                if previous_distance > 0.0 {
                    output.push(crossing(previous.line));
                }
                output.push(current);
            } else if previous_distance <= 0.0 {
                output.push(crossing(first_plane_line + plane));
            }
            previous = current;
            previous_distance = current_distance;
        }
        output
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};

    /// A triangle in the plane y = 0 facing +y, around the origin, with the given active edges.
    fn floor_triangle(active_edges: u8) -> Triangle {
        Triangle {
            vertices: [
                vec3(-2.0, 0.0, -2.0),
                vec3(0.0, 0.0, 3.0),
                vec3(3.0, 0.0, -2.0),
            ],
            normal: Vec3::Y,
            active_edges,
            concave_edges: 0,
        }
    }

    #[test]
    fn closest_point_features() {
        let vertices = floor_triangle(0).vertices;
        let (point, feature) = closest_point_on_triangle(vec3(0.0, 1.0, 0.0), &vertices);
        assert_eq!(feature, Feature::Face);
        assert!(point.length() < 1e-6);
        let (point, feature) = closest_point_on_triangle(vec3(-5.0, 1.0, -5.0), &vertices);
        assert_eq!((point, feature), (vertices[0], Feature::Vertex(0)));
        // Below edge 2 (vertex 2 → vertex 0, along z = -2).
        let (point, feature) = closest_point_on_triangle(vec3(0.5, -1.0, -4.0), &vertices);
        assert_eq!((point, feature), (vec3(0.5, 0.0, -2.0), Feature::Edge(2)));
    }

    #[test]
    fn sphere_over_the_face_and_beside_an_edge() {
        let mut out = Manifold::default();
        sphere_triangle(
            vec3(0.5, 0.4, 0.0),
            0.5,
            &floor_triangle(0b111),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 1);
        assert_eq!(out.normal, Vec3::Y);
        assert!((out.points[0].separation + 0.1).abs() < 1e-6);
        // Midway between the surfaces: 0.05 below the sphere's lowest point.
        assert!((out.points[0].position - vec3(0.5, -0.05, 0.0)).length() < 1e-6);

        // Beside edge 2 (z = -2), 0.3 out and 0.3 up: the normal points from the edge at 45°
        // when the edge is active, straight up when it is not.
        let center = vec3(0.5, 0.3, -2.3);
        let mut out = Manifold::default();
        sphere_triangle(center, 0.5, &floor_triangle(0b111), 0.02, &mut out);
        let diagonal = vec3(0.0, 1.0, -1.0).normalize();
        assert!((out.normal - diagonal).length() < 1e-6);
        let distance = 0.3 * std::f32::consts::SQRT_2;
        assert!((out.points[0].separation - (distance - 0.5)).abs() < 1e-6);
        let mut out = Manifold::default();
        sphere_triangle(center, 0.5, &floor_triangle(0b011), 0.02, &mut out);
        assert_eq!(out.normal, Vec3::Y);
        assert!((out.points[0].separation - (distance - 0.5)).abs() < 1e-6);

        // Beyond the margin: nothing.
        let mut out = Manifold::default();
        sphere_triangle(
            vec3(0.0, 0.53, 0.0),
            0.5,
            &floor_triangle(0),
            0.02,
            &mut out,
        );
        assert_eq!(out.count, 0);
    }

    #[test]
    fn capsule_lying_on_the_face_rests_on_both_ends() {
        let mut out = Manifold::default();
        let (start, end) = (vec3(-0.5, 0.29, 0.0), vec3(1.0, 0.29, 0.0));
        capsule_triangle(start, end, 0.3, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 2);
        assert_eq!(out.normal, Vec3::Y);
        for (point, expected_x) in out.points().iter().zip([-0.5, 1.0]) {
            assert!((point.separation + 0.01).abs() < 1e-6);
            assert!((point.position - vec3(expected_x, -0.005, 0.0)).length() < 1e-6);
        }
        // Hanging over edge 2 (z = -2): the part over the face ends at the edge.
        let mut out = Manifold::default();
        let (start, end) = (vec3(0.0, 0.29, -1.0), vec3(0.0, 0.29, -3.0));
        capsule_triangle(start, end, 0.3, &floor_triangle(0b011), 0.02, &mut out);
        assert_eq!(out.count, 2);
        assert!((out.points[1].position.z + 2.0).abs() < 1e-6);
    }

    #[test]
    fn box_resting_on_a_big_triangle_touches_at_its_four_corners() {
        let cuboid = Cuboid {
            half_extents: vec3(0.5, 0.25, 0.4),
        };
        let pose = Transform::new(vec3(0.3, 0.24, -0.5), Quat::from_rotation_y(0.3));
        let mut out = Manifold::default();
        box_triangle(&cuboid, &pose, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 4);
        assert!((out.normal - Vec3::Y).length() < 1e-6);
        for point in out.points() {
            assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
            assert!((point.position.y + 0.005).abs() < 1e-5);
        }
    }

    #[test]
    fn box_over_a_seam_takes_the_face_normal_when_the_edge_is_inactive() {
        // A box standing just past edge 2 (z = -2), its bottom face overlapping the triangle
        // by a 2 mm strip and sunk 10 mm: the separating-axis test prefers the sideways axis
        // (2 mm < 10 mm). On an active edge that is the contact; on an inactive one (a flat
        // seam) the face normal is used, with the strip's points.
        let cuboid = Cuboid {
            half_extents: vec3(0.5, 0.25, 0.5),
        };
        let pose = Transform::from_position(vec3(0.5, 0.24, -2.498));
        let mut active = Manifold::default();
        box_triangle(&cuboid, &pose, &floor_triangle(0b111), 0.02, &mut active);
        assert!(active.count > 0);
        assert!(
            active.normal.y.abs() < 1e-3,
            "sideways: {:?}",
            active.normal
        );
        let mut inactive = Manifold::default();
        box_triangle(&cuboid, &pose, &floor_triangle(0b011), 0.02, &mut inactive);
        assert!((inactive.normal - Vec3::Y).length() < 1e-6);
        assert!(inactive.count >= 2);
        for point in inactive.points() {
            assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
            assert!(point.position.z >= -2.0 - 1e-5 && point.position.z <= -1.996 + 1e-5);
        }
    }

    #[test]
    fn box_standing_on_an_edge_touches_at_both_ends_of_it() {
        let cuboid = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        let half_diagonal = 0.5 * std::f32::consts::SQRT_2;
        // Turned 45° about z: its lowest edge runs along z at x = 0.5, 10 mm into the face.
        let pose = Transform::new(
            vec3(0.5, half_diagonal - 0.01, 0.0),
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
        );
        let mut out = Manifold::default();
        box_triangle(&cuboid, &pose, &floor_triangle(0b111), 0.02, &mut out);
        assert!((out.normal - Vec3::Y).length() < 1e-5, "{:?}", out.normal);
        assert_eq!(out.count, 2, "the lowest edge touches at both its ends");
        for point in out.points() {
            assert!((point.separation + 0.01).abs() < 1e-5);
            assert!((point.position.x - 0.5).abs() < 1e-4);
        }
    }
}
