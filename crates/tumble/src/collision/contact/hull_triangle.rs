//! A convex hull (A) against one triangle of a mesh (B), by the separating-axis test and face
//! clipping of `hull.rs`: the triangle is a flat polyhedron with two faces (front and back, the
//! same loop both ways) and three edges, so hull–hull's face queries and clipping apply as they
//! are. The normal points from the triangle to the hull; triangles are two-sided, as in
//! `triangle.rs`.
//!
//! # Axes
//!
//! - the triangle's normal, either way (the side with the larger separation);
//! - the hull's face normals;
//! - edge pairs whose Gauss-map arcs cross (Gregorius, GDC 2013, as in `hull.rs`). A flat
//!   triangle's faces are antipodal, so the arc of its edge `e` is not the short arc between
//!   them but the half circle from `n` through the edge's outward direction `m_e` to `-n`.
//!   In the Minkowski difference hull − triangle that half circle is negated: the directions
//!   `p` with `p · d_e = 0` (`d_e` the edge direction) and `p · m_e < 0`. The hull edge's arc
//!   from face normal `n1` to `n2` meets the great circle `p · d_e = 0` where `s1 = n1 · d_e` and
//!   `s2 = n2 · d_e` change sign, at `p = n1 |s2| + n2 |s1|`; that point is the axis itself
//!   (it is normal to both edges), oriented from the hull towards the triangle, and the
//!   separation is `p · (triangle edge point − hull edge point)` with no support search.
//!
//! Faces are preferred as for box–triangle: the triangle's face unless the hull's beats it by
//! 2 % (steadier manifolds on a mesh, and the face that coplanar triangles merge on), then an
//! edge pair only if it beats the best face by 5 % and 0.5 mm.
//!
//! A face contact clips the other polyhedron's face most anti-parallel to the reference face
//! against the reference's side planes (`hull.rs`). That face can lie beside the reference
//! face while another part of the polyhedron overlaps it; when the clip leaves nothing, the
//! other's deepest vertex along the axis is the one point, so an overlap the axes found is
//! never dropped.
//!
//! # Internal edges
//!
//! As for boxes (`triangle.rs`): on the front side, when the chosen axis is not the triangle's
//! face and every point lies on an inactive edge or vertex of the triangle, the contact is
//! recomputed with the triangle's front face as the reference, so a hull crossing a flat or
//! concave seam is held by the face and not bumped sideways. An edge pair's point is on its
//! triangle edge; a point clipped from the triangle against a hull face has its feature read
//! from its position on the triangle (in the hull's frame, where the clip computed it), as
//! hull–hull's clip ids do not say which triangle edge a cut lies on.
//!
//! # Feature ids (bits 0–11, unique within one triangle's manifold for face loops up to 32
//! vertices; the child cache puts the triangle above bit 12)
//!
//! | contact | ids |
//! |---|---|
//! | triangle face reference | clip feature (bits 0–5) · hull incident face mod 16 `<< 6` |
//! | hull face reference | clip feature (bits 0–5) · hull reference face mod 16 `<< 6` · `1 << 10` |
//! | edge–edge | `2 << 10` · hull edge mod 256 `<< 2` · triangle edge |
//!
//! A clip feature is the incident loop position `k < 32` of an unclipped vertex, else
//! `32 | (2 · side plane + 1 if leaving) mod 32` for a cut (`hull.rs`'s clip ids, shortened),
//! or `63` with the reference face in bits 6–9 for the single deepest vertex of a face contact
//! whose clip left nothing.

use super::hull::{
    CROSSING_BIT, EDGE_CONTACT_BIT, Polyhedron, REFERENCE_IS_A_BIT, edge_contact, face_contact,
    face_query,
};
use super::triangle::{
    FACE_RELATIVE_TOLERANCE, Feature, face_over_inactive_features, push_from_frame,
    triangle_in_frame,
};
use super::{EDGE_RELATIVE_TOLERANCE, PARALLEL_SINE_SQUARED, clearly_greater, push_contact};
use crate::collision::manifold::Manifold;
use crate::math::{Transform, Vec3};
use crate::shape::ConvexHull;
use crate::shape::convex_hull::{HullEdge, HullFace};
use crate::shape::trimesh::Triangle;

/// A point lies on a triangle edge when it is within this fraction of the edge's length of the
/// edge's line: well above the rounding of a clip (about 1e-7 of the coordinates, which are
/// within a few edge lengths of the hull), well below any feature of interest.
const ON_EDGE_FRACTION: f32 = 1.0e-4;

/// Bits 10–11 of an id: which axis made the contact (module docs).
const HULL_REFERENCE_KIND: u32 = 1 << 10;
const EDGE_KIND: u32 = 2 << 10;

/// Clip feature of the single point made when clipping leaves none (see `contact_on_axis`):
/// one no clip makes for a triangle reference, and the only point of its manifold.
const DEEPEST_VERTEX_FEATURE: u32 = 63;

/// Face 0 runs `0 → 1 → 2` about the front normal, face 1 the other way about the back one.
const TRIANGLE_FACE_VERTICES: [u32; 6] = [0, 1, 2, 0, 2, 1];

/// Edge `e` runs from vertex `e` to `(e + 1) % 3` on the front face's loop (as
/// [`HullEdge`] wants of `faces[0]`) and back on the back face's.
const TRIANGLE_EDGES: [HullEdge; 3] = [
    HullEdge {
        vertices: [0, 1],
        faces: [0, 1],
    },
    HullEdge {
        vertices: [1, 2],
        faces: [0, 1],
    },
    HullEdge {
        vertices: [2, 0],
        faces: [0, 1],
    },
];

/// A triangle as a polyhedron for `hull.rs`: its corners and its two faces.
struct FlatTriangle {
    vertices: [Vec3; 3],
    faces: [HullFace; 2],
}

impl FlatTriangle {
    fn new(triangle: &Triangle) -> Self {
        let normal = triangle.normal;
        let offset = normal.dot(triangle.vertices[0]);
        Self {
            vertices: triangle.vertices,
            faces: [
                HullFace {
                    normal,
                    offset,
                    first: 0,
                    count: 3,
                },
                HullFace {
                    normal: -normal,
                    offset: -offset,
                    first: 3,
                    count: 3,
                },
            ],
        }
    }

    fn view(&self) -> Polyhedron<'_> {
        Polyhedron {
            vertices: &self.vertices,
            faces: &self.faces,
            face_vertices: &TRIANGLE_FACE_VERTICES,
            edges: &TRIANGLE_EDGES,
        }
    }
}

/// The axis the separating-axis test settled on.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Axis {
    /// Face 0 (front) or 1 (back) of the triangle.
    TriangleFace(usize),
    HullFace(usize),
    /// Hull edge, triangle edge, and the axis from the hull towards the triangle.
    Edges(usize, usize, Vec3),
}

/// Hull (A) at `hull_pose` against the triangle (B), both in the same frame (the mesh's).
/// Fills `out` in that frame.
pub(crate) fn hull_triangle(
    hull: &ConvexHull,
    hull_pose: &Transform,
    triangle: &Triangle,
    margin: f32,
    out: &mut Manifold,
) {
    // Work in the hull's frame: its vertices, faces and edges stay as stored.
    let local = triangle_in_frame(triangle, hull_pose);
    let flat = FlatTriangle::new(&local);
    let (hull_view, triangle_view) = (Polyhedron::of_hull(hull), flat.view());
    let Some(axis) = separating_axis(&hull_view, &triangle_view, &local, margin) else {
        return;
    };
    let mut local_out = Manifold::default();
    contact_on_axis(&hull_view, &triangle_view, axis, margin, &mut local_out);
    let normal = local_out.normal;
    face_over_inactive_features(
        &local,
        matches!(axis, Axis::TriangleFace(_)),
        &mut local_out,
        |point| match axis {
            // As for boxes, an edge pair's point counts as on the edge, even at its end.
            Axis::Edges(_, triangle_edge, _) => Feature::Edge(triangle_edge),
            // The point's twin on the triangle: B's surface lies `separation` behind A's.
            _ => triangle_feature(&local, point.position - normal * (0.5 * point.separation)),
        },
        |face_out| {
            let deepest = hull_view.support(-local.normal);
            if local.normal.dot(deepest - local.vertices[0]) < margin {
                contact_on_axis(
                    &hull_view,
                    &triangle_view,
                    Axis::TriangleFace(0),
                    margin,
                    face_out,
                );
            }
        },
    );
    push_from_frame(&local_out, hull_pose, out);
}

/// The axis of least penetration with the preferences of the module docs, or `None` when some
/// axis separates the two by `margin` or more.
fn separating_axis(
    hull: &Polyhedron,
    triangle: &Polyhedron,
    local: &Triangle,
    margin: f32,
) -> Option<Axis> {
    let same_frame = Transform::IDENTITY;
    let (triangle_separation, triangle_face) = face_query(triangle, hull, &same_frame);
    if triangle_separation >= margin {
        return None;
    }
    let (hull_separation, hull_face) = face_query(hull, triangle, &same_frame);
    if hull_separation >= margin {
        return None;
    }
    let edge = edge_query(hull, local);
    if let Some((separation, ..)) = edge
        && separation >= margin
    {
        return None;
    }
    let (mut best_separation, mut best) = (triangle_separation, Axis::TriangleFace(triangle_face));
    if clearly_greater(
        hull_separation,
        triangle_separation,
        FACE_RELATIVE_TOLERANCE,
    ) {
        (best_separation, best) = (hull_separation, Axis::HullFace(hull_face));
    }
    if let Some((separation, hull_edge, triangle_edge, axis)) = edge
        && clearly_greater(separation, best_separation, EDGE_RELATIVE_TOLERANCE)
    {
        best = Axis::Edges(hull_edge, triangle_edge, axis);
    }
    Some(best)
}

/// The best edge pair whose Gauss-map arcs cross (module docs): (separation, hull edge,
/// triangle edge, unit axis from the hull towards the triangle), all in the hull's frame.
fn edge_query(hull: &Polyhedron, triangle: &Triangle) -> Option<(f32, usize, usize, Vec3)> {
    let mut best: Option<(f32, usize, usize, Vec3)> = None;
    for triangle_edge in 0..3 {
        let start = triangle.vertices[triangle_edge];
        let direction = triangle.vertices[(triangle_edge + 1) % 3] - start;
        let outward = direction.cross(triangle.normal);
        for (hull_edge, edge) in hull.edges.iter().enumerate() {
            let n1 = hull.faces[edge.faces[0] as usize].normal;
            let n2 = hull.faces[edge.faces[1] as usize].normal;
            let (s1, s2) = (n1.dot(direction), n2.dot(direction));
            // Same sign: the hull edge's arc stays on one side of the great circle.
            if s1 * s2 >= 0.0 {
                continue;
            }
            let crossing = n1 * s2.abs() + n2 * s1.abs();
            // On the triangle's own half circle, not the Minkowski difference's.
            if crossing.dot(outward) >= 0.0 {
                continue;
            }
            // Nearly parallel edges: s1 and s2 are rounding, and so is the axis.
            let length_squared = crossing.length_squared();
            if length_squared <= PARALLEL_SINE_SQUARED * direction.length_squared() {
                continue;
            }
            let axis = crossing / length_squared.sqrt();
            let on_hull = hull.vertices[edge.vertices[0] as usize];
            let separation = axis.dot(start - on_hull);
            if best.is_none_or(|(s, ..)| separation > s) {
                best = Some((separation, hull_edge, triangle_edge, axis));
            }
        }
    }
    best
}

/// The contact points for `axis`, in the hull's frame, normal from the triangle to the hull,
/// with the ids of the module docs.
fn contact_on_axis(
    hull: &Polyhedron,
    triangle: &Polyhedron,
    axis: Axis,
    margin: f32,
    out: &mut Manifold,
) {
    let same_frame = Transform::IDENTITY;
    // (reference, its face, the other polyhedron) of a face contact.
    let (reference, face, other) = match axis {
        Axis::TriangleFace(face) => {
            face_contact(
                triangle,
                &same_frame,
                face,
                hull,
                &same_frame,
                false,
                margin,
                out,
            );
            // Made with B as the reference: normal from A to B; flip to B → A.
            *out = out.flipped();
            (triangle, face, hull)
        }
        Axis::HullFace(face) => {
            face_contact(
                hull,
                &same_frame,
                face,
                triangle,
                &same_frame,
                true,
                margin,
                out,
            );
            (hull, face, triangle)
        }
        Axis::Edges(hull_edge, triangle_edge, axis) => {
            edge_contact(
                hull,
                &same_frame,
                triangle,
                &same_frame,
                (hull_edge, triangle_edge, axis),
                out,
            );
            (hull, 0, triangle)
        }
    };
    let count = out.count as usize;
    for point in &mut out.points[..count] {
        point.id = compact_id(point.id);
    }
    if count > 0 || matches!(axis, Axis::Edges(..)) {
        return;
    }
    // The incident face (the other's face most anti-parallel to the reference) can miss the
    // reference face's prism while another part of the other polyhedron overlaps it: clipping
    // leaves nothing though the axis says they overlap. The other's deepest vertex along the
    // axis then gives one point at the axis's separation (on the axis of least penetration it
    // lies over the reference face: the origin projects inside the closest face of the
    // Minkowski difference).
    let reference_face = reference.faces[face];
    let deepest = other.support(-reference_face.normal);
    let separation = reference_face.normal.dot(deepest) - reference_face.offset;
    if separation >= margin {
        return;
    }
    // Normal from the triangle to the hull: the reference face's normal when it is the
    // triangle's, its opposite when it is the hull's.
    let (normal, on_hull, kind) = match axis {
        Axis::TriangleFace(_) => (reference_face.normal, deepest, 0),
        _ => (
            -reference_face.normal,
            deepest - reference_face.normal * separation,
            HULL_REFERENCE_KIND,
        ),
    };
    out.normal = normal;
    push_contact(
        out,
        on_hull,
        normal,
        separation,
        kind | (((face as u32) & 15) << 6) | DEEPEST_VERTEX_FEATURE,
    );
}

/// The triangle feature `point` (on the triangle) lies on, within [`ON_EDGE_FRACTION`].
fn triangle_feature(triangle: &Triangle, point: Vec3) -> Feature {
    let mut on_edges = [false; 3];
    for (edge, on) in on_edges.iter_mut().enumerate() {
        let start = triangle.vertices[edge];
        let direction = triangle.vertices[(edge + 1) % 3] - start;
        // |inward| = |direction|: the unit normal is perpendicular to the edge.
        let inward = triangle.normal.cross(direction);
        let length_squared = direction.length_squared();
        *on = inward.dot(point - start) <= ON_EDGE_FRACTION * length_squared;
    }
    match on_edges {
        [false, false, false] => Feature::Face,
        [true, false, false] => Feature::Edge(0),
        [false, true, false] => Feature::Edge(1),
        [false, false, true] => Feature::Edge(2),
        // Two edges meet at the vertex they share: edge e starts at vertex e.
        [true, true, false] => Feature::Vertex(1),
        [false, true, true] => Feature::Vertex(2),
        [true, false, true] => Feature::Vertex(0),
        // Only a sliver of a triangle is that close to all three edges: no edge to prefer.
        [true, true, true] => Feature::Face,
    }
}

/// `hull.rs`'s 32-bit id of a hull–triangle point in the 12 bits of the module docs.
fn compact_id(id: u32) -> u32 {
    if id & EDGE_CONTACT_BIT != 0 {
        let hull_edge = (id >> 15) & 0x7FFF;
        let triangle_edge = id & 0x3;
        return EDGE_KIND | ((hull_edge & 0xFF) << 2) | triangle_edge;
    }
    let clip = id & 0xFFFF;
    let clip_feature = if clip & CROSSING_BIT != 0 {
        32 | (clip & 31)
    } else {
        clip & 31
    };
    if id & REFERENCE_IS_A_BIT != 0 {
        // The hull's face is the reference (bits 16–22 of hull.rs's id).
        HULL_REFERENCE_KIND | (((id >> 16) & 15) << 6) | clip_feature
    } else {
        // The triangle's face is the reference; the hull's incident face is bits 23–29.
        (((id >> 23) & 15) << 6) | clip_feature
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};
    use crate::scene::barrel_points;

    /// A triangle in the plane y = 0 facing +y, around the origin, with the given active edges
    /// (edge 2 runs along z = -2).
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

    fn cube_hull(half: Vec3) -> ConvexHull {
        let corners: Vec<Vec3> = (0..8)
            .map(|i| {
                half * vec3(
                    [-1.0, 1.0][i & 1],
                    [-1.0, 1.0][(i >> 1) & 1],
                    [-1.0, 1.0][i >> 2],
                )
            })
            .collect();
        ConvexHull::new(&corners).unwrap()
    }

    fn assert_unique_ids(out: &Manifold) {
        for (i, point) in out.points().iter().enumerate() {
            assert!(point.id < 1 << 12, "{point:?}");
            assert!(out.points()[..i].iter().all(|other| other.id != point.id));
        }
    }

    /// The barrel standing on its square cap (4 points at radius 0.3, y = -0.5), sunk 10 mm
    /// into a big triangle and turned: 4 points at the cap's corners, each 10 mm deep, midway
    /// between the surfaces.
    #[test]
    fn barrel_on_its_cap_touches_at_the_four_corners() {
        let barrel = ConvexHull::new(&barrel_points()).unwrap();
        let pose = Transform::new(vec3(0.3, 0.49, -0.5), Quat::from_rotation_y(0.3));
        let mut out = Manifold::default();
        hull_triangle(&barrel, &pose, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 4);
        assert!((out.normal - Vec3::Y).length() < 1e-6, "{:?}", out.normal);
        for point in out.points() {
            assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
            assert!((point.position.y + 0.005).abs() < 1e-5);
            let radius = (point.position - vec3(0.3, point.position.y, -0.5)).length();
            assert!((radius - 0.3).abs() < 1e-5, "{point:?}");
        }
        assert_unique_ids(&out);

        // 5 mm above the face: the same corners within the 20 mm margin, 5 mm apart; 25 mm
        // above: nothing.
        let above = Transform::new(vec3(0.3, 0.505, -0.5), Quat::from_rotation_y(0.3));
        let mut out = Manifold::default();
        hull_triangle(&barrel, &above, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 4);
        assert!(
            out.points()
                .iter()
                .all(|p| (p.separation - 0.005).abs() < 1e-5)
        );
        let far = Transform::from_position(vec3(0.3, 0.525, -0.5));
        let mut out = Manifold::default();
        hull_triangle(&barrel, &far, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 0);
    }

    /// Below the triangle (its back side) the normal points down: triangles are two-sided.
    #[test]
    fn hull_below_the_triangle_is_pushed_down() {
        let cube = cube_hull(Vec3::splat(0.5));
        let pose = Transform::from_position(vec3(0.2, -0.49, -0.3));
        let mut out = Manifold::default();
        hull_triangle(&cube, &pose, &floor_triangle(0b111), 0.02, &mut out);
        assert_eq!(out.count, 4);
        assert!((out.normal + Vec3::Y).length() < 1e-6);
        assert!(
            out.points()
                .iter()
                .all(|p| (p.separation + 0.01).abs() < 1e-5)
        );
    }

    /// A box-shaped hull standing just past edge 2 (z = -2), its bottom overlapping the
    /// triangle by a 2 mm strip and sunk 10 mm: the least penetration is sideways (2 mm < 10
    /// mm), along the hull's side face. On an active edge that is the contact; on an inactive
    /// one (a flat seam) the face normal holds the hull, with the strip's points 10 mm deep.
    #[test]
    fn hull_over_a_seam_takes_the_face_normal_when_the_edge_is_inactive() {
        let cube = cube_hull(vec3(0.5, 0.25, 0.5));
        let pose = Transform::from_position(vec3(0.5, 0.24, -2.498));
        let mut active = Manifold::default();
        hull_triangle(&cube, &pose, &floor_triangle(0b111), 0.02, &mut active);
        assert!(active.count > 0);
        assert!(
            (active.normal + Vec3::Z).length() < 1e-5,
            "{:?}",
            active.normal
        );
        assert!(
            active
                .points()
                .iter()
                .all(|p| (p.separation + 0.002).abs() < 1e-5)
        );
        let mut inactive = Manifold::default();
        hull_triangle(&cube, &pose, &floor_triangle(0b011), 0.02, &mut inactive);
        assert!((inactive.normal - Vec3::Y).length() < 1e-6);
        assert!(inactive.count >= 2);
        for point in inactive.points() {
            assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
            assert!(point.position.z >= -2.0 - 1e-5 && point.position.z <= -1.998 + 1e-5);
        }
        assert_unique_ids(&inactive);
    }

    /// A cube turned 45° about z presses its lowest edge (along z) 10 mm down onto the
    /// horizontal top edge (along x) of an upright triangle: one edge–edge point at the
    /// crossing, normal +y. Every face axis overlaps far more (the cube straddles the
    /// triangle's plane). When the top edge is inactive (a wall continuing upwards), the
    /// triangle's face holds the cube instead.
    #[test]
    fn cube_edge_across_a_triangle_edge() {
        let wall = |active_edges| Triangle {
            vertices: [
                vec3(-2.0, 0.0, 0.0),
                vec3(0.0, -3.0, 0.0),
                vec3(2.0, 0.0, 0.0),
            ],
            normal: Vec3::Z,
            active_edges,
            concave_edges: 0,
        };
        // Edge 2 runs from (2, 0, 0) to (-2, 0, 0): the top.
        let cube = cube_hull(Vec3::splat(0.5));
        let half_diagonal = 0.5 * std::f32::consts::SQRT_2;
        let pose = Transform::new(
            vec3(0.3, half_diagonal - 0.01, 0.1),
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
        );
        let mut out = Manifold::default();
        hull_triangle(&cube, &pose, &wall(0b111), 0.02, &mut out);
        assert_eq!(out.count, 1);
        assert!((out.normal - Vec3::Y).length() < 1e-5, "{:?}", out.normal);
        let point = out.points[0];
        assert!((point.separation + 0.01).abs() < 1e-5, "{point:?}");
        assert!((point.position - vec3(0.3, -0.005, 0.0)).length() < 1e-5);
        assert_eq!(point.id >> 10, 2, "an edge–edge id");

        let mut out = Manifold::default();
        hull_triangle(&cube, &pose, &wall(0b011), 0.02, &mut out);
        assert!((out.normal - Vec3::Z).length() < 1e-6, "{:?}", out.normal);
        // The cube reaches 0.4 m behind the wall's plane (its centre is 0.1 m in front).
        let deepest = out
            .points()
            .iter()
            .map(|p| p.separation)
            .fold(f32::INFINITY, f32::min);
        assert!((deepest + 0.4).abs() < 1e-4, "{deepest}");
    }

    #[test]
    fn features_from_positions() {
        let triangle = floor_triangle(0);
        assert_eq!(
            triangle_feature(&triangle, vec3(0.0, 0.0, 0.0)),
            Feature::Face
        );
        assert_eq!(
            triangle_feature(&triangle, vec3(0.5, 0.0, -2.0)),
            Feature::Edge(2)
        );
        assert_eq!(
            triangle_feature(&triangle, triangle.vertices[1]),
            Feature::Vertex(1)
        );
        assert_eq!(
            triangle_feature(&triangle, triangle.vertices[0]),
            Feature::Vertex(0)
        );
        // 1 mm inside edge 2 is inside the face.
        assert_eq!(
            triangle_feature(&triangle, vec3(0.5, 0.0, -1.999)),
            Feature::Face
        );
    }
}
