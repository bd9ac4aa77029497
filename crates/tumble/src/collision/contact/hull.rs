//! Pairs with a convex hull: box–hull and hull–hull by SAT and clipping, sphere–hull and
//! capsule–hull by SAT and nearest features, plane–hull by vertices.
//!
//! # Polyhedra (box–hull, hull–hull)
//!
//! A box is seen as a polyhedron like a hull (8 vertices, 6 quads, 12 edges; the tables below
//! with vertex `i` on the + side of x, y, z for bits 0, 1, 2 as in box–plane). The separating
//! axis test runs in A's frame over
//!
//! - A's face normals: separation `n · support_B(-n) - offset`;
//! - B's face normals, the same in B's frame;
//! - the cross products of an edge of A and an edge of B, only for the edge pairs that build a
//!   face of the Minkowski difference: their arcs on the Gauss map cross (Gregorius, "The
//!   Separating Axis Test between Convex Polyhedra", GDC 2013). Other edge pairs give axes
//!   that can never separate more than a face, so they are skipped. The axis is oriented away
//!   from A's centre (the hull frame's origin), and the separation is `axis · (p_B - p_A)`.
//!
//! Any separation `>= margin` ends the test with no contact. Otherwise faces are preferred as
//! in box–box (an edge must beat the best face by 5 % and 0.5 mm), so the choice does not
//! flicker between a face and an edge; between the two best faces the larger separation wins.
//!
//! Face contact: the incident face is the other polyhedron's face most anti-parallel to the
//! reference face. It is clipped against the reference face's side planes (Sutherland–Hodgman);
//! each clipped vertex below `margin` above the reference face is a point, midway between the
//! vertex and its projection. More than four go through [`reduce`]. Edge contact: one point,
//! midway between the closest points of the two edges.
//!
//! # Feature ids
//!
//! Face contact: bits 0–15 the clip feature — an incident vertex `k` (its position in the
//! incident loop) is `k`, a vertex cut by reference side plane `e` (the edge from loop vertex
//! `e` to `e + 1`) is `0x8000 | 2e | 1 if the polygon leaves the plane's inside there`; bits
//! 16–22 the reference face index, bits 23–29 the incident face index (both mod 128), bit 30
//! set when the reference face is A's. A convex polygon crosses a plane at most once each way,
//! so the ids are unique within a manifold. Edge contact: bit 31, A's edge index (mod 2^15)
//! `<< 15`, B's edge index (mod 2^15).
//!
//! # Spheres and capsules
//!
//! Their cores (a point, a segment) against the hull as capsule–box does against a box, with
//! no iteration, so that the GPU (`contact_hull.wgsl`) computes the same contacts in f32: the
//! separating-axis test over the hull's face normals and the cross products of the segment
//! with the hull's edges (those whose Gauss-map arc the segment's great circle crosses: the
//! faces of the Minkowski difference) gives the exact depth and normal when the cores overlap;
//! when they are apart (the best axis separates them), the nearest of each core end above a
//! face it projects into and of the core against each edge gives the exact distance, normal
//! (from the hull towards the core) and closest points. The separation is the core distance
//! minus the radius. A capsule lying along a face (its segment within 2° of parallel to the
//! face touched) gets two points, the ends of its segment clipped to the face (ids 0 and 1, as
//! for capsule–box), so it rests without rolling about one point; otherwise one point (id 0).
//!
//! (GJK with EPA, or the sampled penetration depth on the GPU, was the first design: on
//! prisms and barrels, whose many parallel faces make GJK's simplices degenerate, GJK in f32
//! on the GPU and in f64 on the CPU took different paths and stopped at different points,
//! 10 % apart, and the sampled depth's witness point depends on the ray that found the face.)
//!
//! Nothing here allocates except the clip buffers of polyhedron contacts (two small vectors).

use super::segment::closest_parameters_between_segments;
use super::{
    COINCIDENT_DISTANCE_SQUARED, EDGE_RELATIVE_TOLERANCE, PARALLEL_SINE_SQUARED, clearly_greater,
    push_contact,
};
use crate::collision::manifold::{ContactPoint, MAX_MANIFOLD_POINTS, Manifold, reduce};
use crate::math::{Mat3, Transform, Vec3};
use crate::shape::convex_hull::{HullEdge, HullFace};
use crate::shape::{Capsule, ConvexHull, Cuboid, Plane, Sphere};

/// `cos²` of 2°: a capsule whose segment is this close to parallel to the touched face rests
/// on it with two points.
pub(crate) const CAPSULE_FACE_COS_SQUARED: f32 = 0.998_782;

pub(super) const REFERENCE_IS_A_BIT: u32 = 1 << 30;
pub(super) const EDGE_CONTACT_BIT: u32 = 1 << 31;
pub(super) const CROSSING_BIT: u32 = 0x8000;

/// A convex polyhedron seen through slices: a hull, or a box through [`BoxPolyhedron`].
#[derive(Clone, Copy)]
pub(crate) struct Polyhedron<'a> {
    pub(super) vertices: &'a [Vec3],
    pub(super) faces: &'a [HullFace],
    pub(super) face_vertices: &'a [u32],
    pub(super) edges: &'a [HullEdge],
}

impl<'a> Polyhedron<'a> {
    pub(crate) fn of_hull(hull: &'a ConvexHull) -> Self {
        Self {
            vertices: hull.vertices(),
            faces: hull.faces(),
            face_vertices: hull.face_vertices(),
            edges: hull.edges(),
        }
    }

    /// Vertices, faces, face loops and edges: what the GPU narrowphase packs
    /// (`stages/narrowphase/gpu.rs`).
    pub(crate) fn parts(&self) -> (&'a [Vec3], &'a [HullFace], &'a [u32], &'a [HullEdge]) {
        (self.vertices, self.faces, self.face_vertices, self.edges)
    }

    #[inline]
    pub(super) fn support(&self, direction: Vec3) -> Vec3 {
        let mut best = self.vertices[0];
        let mut best_dot = best.dot(direction);
        for &v in &self.vertices[1..] {
            let d = v.dot(direction);
            if d > best_dot {
                best_dot = d;
                best = v;
            }
        }
        best
    }

    fn face_loop(&self, face: usize) -> &'a [u32] {
        let f = &self.faces[face];
        &self.face_vertices[f.first as usize..(f.first + f.count) as usize]
    }
}

/// A box's corners and faces: what varies with its size; loops and edges are the tables.
pub(crate) struct BoxPolyhedron {
    vertices: [Vec3; 8],
    faces: [HullFace; 6],
}

/// Faces `+x, -x, +y, -y, +z, -z`, each loop counter-clockwise seen from outside.
const BOX_FACE_VERTICES: [u32; 24] = [
    1, 3, 7, 5, 0, 4, 6, 2, 2, 6, 7, 3, 0, 1, 5, 4, 4, 5, 7, 6, 0, 2, 3, 1,
];

/// The 12 edges; `faces[0]` is the face whose loop runs from `vertices[0]` to `vertices[1]`.
const BOX_EDGES: [HullEdge; 12] = {
    const fn edge(a: u32, b: u32, f: u32, g: u32) -> HullEdge {
        HullEdge {
            vertices: [a, b],
            faces: [f, g],
        }
    }
    [
        edge(0, 1, 3, 5),
        edge(2, 3, 5, 2),
        edge(4, 5, 4, 3),
        edge(6, 7, 2, 4),
        edge(0, 2, 5, 1),
        edge(1, 3, 0, 5),
        edge(4, 6, 1, 4),
        edge(5, 7, 4, 0),
        edge(0, 4, 1, 3),
        edge(1, 5, 3, 0),
        edge(2, 6, 2, 1),
        edge(3, 7, 0, 2),
    ]
};

impl BoxPolyhedron {
    pub(crate) fn new(cuboid: &Cuboid) -> Self {
        let h = cuboid.half_extents;
        let vertices = std::array::from_fn(|i| {
            h * Vec3::new(
                [-1.0, 1.0][i & 1],
                [-1.0, 1.0][(i >> 1) & 1],
                [-1.0, 1.0][i >> 2],
            )
        });
        let faces = std::array::from_fn(|f| {
            let axis = f / 2;
            let sign = if f % 2 == 0 { 1.0 } else { -1.0 };
            HullFace {
                normal: Vec3::AXES[axis] * sign,
                offset: h[axis],
                first: 4 * f as u32,
                count: 4,
            }
        });
        Self { vertices, faces }
    }

    pub(crate) fn view(&self) -> Polyhedron<'_> {
        Polyhedron {
            vertices: &self.vertices,
            faces: &self.faces,
            face_vertices: &BOX_FACE_VERTICES,
            edges: &BOX_EDGES,
        }
    }
}

pub(super) fn box_hull(
    a: &Cuboid,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let box_a = BoxPolyhedron::new(a);
    polyhedra(
        box_a.view(),
        pose_a,
        Polyhedron::of_hull(b),
        pose_b,
        margin,
        out,
    );
}

pub(super) fn hull_hull(
    a: &ConvexHull,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    polyhedra(
        Polyhedron::of_hull(a),
        pose_a,
        Polyhedron::of_hull(b),
        pose_b,
        margin,
        out,
    );
}

/// The best face of `reference` against `other`: (separation, face index); `other_in_ref` is
/// `other`'s frame in `reference`'s.
pub(super) fn face_query(
    reference: &Polyhedron,
    other: &Polyhedron,
    other_in_ref: &Transform,
) -> (f32, usize) {
    let mut best = (f32::NEG_INFINITY, 0);
    for (i, face) in reference.faces.iter().enumerate() {
        let deepest = other_in_ref
            .transform_point(other.support(other_in_ref.inverse_transform_vector(-face.normal)));
        let separation = face.normal.dot(deepest) - face.offset;
        if separation > best.0 {
            best = (separation, i);
        }
    }
    best
}

/// Whether arcs `ab` and `cd` of the Gauss map cross; `bxa`, `dxc` are the arcs' plane normals
/// (Gregorius 2013: the arcs cross when c, d are on opposite sides of plane `bxa`, a, b on
/// opposite sides of `dxc`, and both on the same hemisphere).
#[inline]
fn arcs_cross(a: Vec3, b: Vec3, c: Vec3, d: Vec3, bxa: Vec3, dxc: Vec3) -> bool {
    let cba = c.dot(bxa);
    let dba = d.dot(bxa);
    let adc = a.dot(dxc);
    let bdc = b.dot(dxc);
    cba * dba < 0.0 && adc * bdc < 0.0 && cba * bdc > 0.0
}

/// The best edge pair (separation, A's edge, B's edge, axis from A towards B in A's frame).
fn edge_query(
    a: &Polyhedron,
    b: &Polyhedron,
    b_in_a: &Transform,
) -> Option<(f32, usize, usize, Vec3)> {
    let rotation = Mat3::from_quat(b_in_a.rotation);
    let mut best: Option<(f32, usize, usize, Vec3)> = None;
    for (j, edge_b) in b.edges.iter().enumerate() {
        // B's Gauss arc is negated: the Minkowski difference has -B's normals.
        let c = -(rotation * b.faces[edge_b.faces[0] as usize].normal);
        let d = -(rotation * b.faces[edge_b.faces[1] as usize].normal);
        let dxc = d.cross(c);
        let qb = b_in_a.transform_point(b.vertices[edge_b.vertices[0] as usize]);
        let eb = rotation
            * (b.vertices[edge_b.vertices[1] as usize] - b.vertices[edge_b.vertices[0] as usize]);
        for (i, edge_a) in a.edges.iter().enumerate() {
            let na = a.faces[edge_a.faces[0] as usize].normal;
            let nb = a.faces[edge_a.faces[1] as usize].normal;
            if !arcs_cross(na, nb, c, d, nb.cross(na), dxc) {
                continue;
            }
            let pa = a.vertices[edge_a.vertices[0] as usize];
            let ea = a.vertices[edge_a.vertices[1] as usize] - pa;
            let axis = ea.cross(eb);
            let length_squared = axis.length_squared();
            if length_squared <= PARALLEL_SINE_SQUARED * ea.length_squared() * eb.length_squared() {
                continue;
            }
            let mut axis = axis / length_squared.sqrt();
            if axis.dot(pa) < 0.0 {
                axis = -axis;
            }
            let separation = axis.dot(qb - pa);
            if best.is_none_or(|(s, ..)| separation > s) {
                best = Some((separation, i, j, axis));
            }
        }
    }
    best
}

/// SAT and clipping between two polyhedra (see the module docs).
fn polyhedra(
    a: Polyhedron,
    pose_a: &Transform,
    b: Polyhedron,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let b_in_a = pose_a.inverse().mul_transform(pose_b);
    let a_in_b = b_in_a.inverse();
    let (separation_a, face_a) = face_query(&a, &b, &b_in_a);
    if separation_a >= margin {
        return;
    }
    let (separation_b, face_b) = face_query(&b, &a, &a_in_b);
    if separation_b >= margin {
        return;
    }
    let edge = edge_query(&a, &b, &b_in_a);
    if let Some((separation, ..)) = edge
        && separation >= margin
    {
        return;
    }
    let best_face = separation_a.max(separation_b);
    if let Some((separation, edge_a, edge_b, axis)) = edge
        && clearly_greater(separation, best_face, EDGE_RELATIVE_TOLERANCE)
    {
        edge_contact(&a, pose_a, &b, &b_in_a, (edge_a, edge_b, axis), out);
        return;
    }
    // The larger face separation gives the reference, with no preference for A or B: the same
    // pair in the other order then picks the same face (hulls have no fixed face order to
    // break ties by, as boxes do with face sizes).
    if separation_b > separation_a {
        face_contact(&b, pose_b, face_b, &a, &a_in_b, false, margin, out);
        // Points were made with B as the reference: normal from A to B; flip to B → A.
        *out = out.flipped();
    } else {
        face_contact(&a, pose_a, face_a, &b, &b_in_a, true, margin, out);
    }
}

/// A point of the incident polygon being clipped: its position (reference frame) and clip
/// feature (see the module docs).
type ClipVertex = (Vec3, u32);

/// Clips `incident` (of polyhedron `other`) against `reference`'s face `face`, filling `out` with
/// normal from the reference face outwards — the caller flips it when the reference is B.
#[allow(clippy::too_many_arguments)]
pub(super) fn face_contact(
    reference: &Polyhedron,
    pose_reference: &Transform,
    face: usize,
    other: &Polyhedron,
    other_in_ref: &Transform,
    reference_is_a: bool,
    margin: f32,
    out: &mut Manifold,
) {
    let ref_face = reference.faces[face];
    // The incident face: the other's face most anti-parallel to the reference normal.
    let normal_in_other = other_in_ref.inverse_transform_vector(ref_face.normal);
    let mut incident = 0;
    let mut lowest = f32::INFINITY;
    for (i, f) in other.faces.iter().enumerate() {
        let d = f.normal.dot(normal_in_other);
        if d < lowest {
            lowest = d;
            incident = i;
        }
    }
    let mut polygon: Vec<ClipVertex> = other
        .face_loop(incident)
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            (
                other_in_ref.transform_point(other.vertices[v as usize]),
                k as u32,
            )
        })
        .collect();
    let mut clipped: Vec<ClipVertex> = Vec::with_capacity(polygon.len() + 4);
    let ref_loop = reference.face_loop(face);
    for (e, &v) in ref_loop.iter().enumerate() {
        let p = reference.vertices[v as usize];
        let q = reference.vertices[ref_loop[(e + 1) % ref_loop.len()] as usize];
        // Side plane through the edge, normal pointing out of the face (the loop is
        // counter-clockwise about the face normal).
        let side = (q - p).cross(ref_face.normal);
        let side_offset = side.dot(p);
        clip(&polygon, side, side_offset, e as u32, &mut clipped);
        std::mem::swap(&mut polygon, &mut clipped);
        if polygon.is_empty() {
            return;
        }
    }

    let world_normal = pose_reference.transform_vector(ref_face.normal);
    let face_bits = ((face as u32 & 0x7F) << 16)
        | ((incident as u32 & 0x7F) << 23)
        | if reference_is_a {
            REFERENCE_IS_A_BIT
        } else {
            0
        };
    let mut candidates: Vec<ContactPoint> = Vec::with_capacity(polygon.len());
    for &(point, feature) in &polygon {
        let separation = ref_face.normal.dot(point) - ref_face.offset;
        if separation < margin {
            // Midway between the incident vertex and its projection on the reference face.
            let midpoint = point - ref_face.normal * (0.5 * separation);
            candidates.push(ContactPoint::new(
                pose_reference.transform_point(midpoint),
                separation,
                feature | face_bits,
            ));
        }
    }
    // The normal runs from the other body to the reference one: reversed reference normal.
    let normal = -world_normal;
    if candidates.len() > MAX_MANIFOLD_POINTS {
        *out = reduce(&candidates, normal);
    } else {
        out.normal = normal;
        for candidate in &candidates {
            out.push(*candidate);
        }
    }
}

/// One Sutherland–Hodgman pass: keeps the part of `polygon` with `side · x <= offset`.
fn clip(polygon: &[ClipVertex], side: Vec3, offset: f32, plane: u32, out: &mut Vec<ClipVertex>) {
    out.clear();
    let Some(&last) = polygon.last() else { return };
    let mut previous = last;
    let mut previous_distance = side.dot(previous.0) - offset;
    for &current in polygon {
        let distance = side.dot(current.0) - offset;
        if (previous_distance <= 0.0) != (distance <= 0.0) {
            let t = previous_distance / (previous_distance - distance);
            let leaving = u32::from(previous_distance <= 0.0);
            out.push((
                previous.0 + (current.0 - previous.0) * t,
                CROSSING_BIT | (plane << 1) | leaving,
            ));
        }
        if distance <= 0.0 {
            out.push(current);
        }
        previous = current;
        previous_distance = distance;
    }
}

/// One point midway between the closest points of A's and B's edges (`axis` in A's frame,
/// from A towards B).
pub(super) fn edge_contact(
    a: &Polyhedron,
    pose_a: &Transform,
    b: &Polyhedron,
    b_in_a: &Transform,
    (edge_a, edge_b, axis): (usize, usize, Vec3),
    out: &mut Manifold,
) {
    let [a0, a1] = a.edges[edge_a].vertices.map(|v| a.vertices[v as usize]);
    let [b0, b1] = b.edges[edge_b]
        .vertices
        .map(|v| b_in_a.transform_point(b.vertices[v as usize]));
    let (s, t) = closest_parameters_between_segments(a0, a1 - a0, b0, b1 - b0);
    let on_a = a0 + (a1 - a0) * s;
    let on_b = b0 + (b1 - b0) * t;
    let separation = axis.dot(on_b - on_a);
    let normal = -pose_a.transform_vector(axis);
    out.normal = normal;
    push_contact(
        out,
        pose_a.transform_point(on_a),
        normal,
        separation,
        EDGE_CONTACT_BIT | ((edge_a as u32 & 0x7FFF) << 15) | (edge_b as u32 & 0x7FFF),
    );
}

/// Normal (B → A, world), separation and the surface point on A of a round shape against
/// hull B (see the module docs), for A's core the segment from `-half_height` to `+half_height`
/// along A's y (a point when 0) swept by `radius`; `None` when apart by `margin` or more.
/// Computed in B's frame.
fn core_contact(
    half_height: f32,
    radius: f32,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    margin: f32,
) -> Option<(Vec3, f32, Vec3)> {
    let centre = pose_b.inverse_transform_point(pose_a.position);
    let half_axis =
        pose_b.inverse_transform_vector(pose_a.transform_vector(Vec3::new(0.0, half_height, 0.0)));
    let start = centre - half_axis;
    let delta = 2.0 * half_axis;
    let (separation, normal, core_point) = match core_sat(b, start, delta) {
        // Every axis is a lower bound of the distance: this one is already too far.
        (separation, ..) if separation - radius >= margin => return None,
        // Apart: the nearest features, exactly (touching within rounding: the axis).
        sat if sat.0 > 0.0 => core_closest(b, start, delta).unwrap_or(sat),
        overlapping => overlapping,
    };
    if separation - radius >= margin {
        return None;
    }
    let normal_world = pose_b.transform_vector(normal);
    let surface_a = pose_b.transform_point(core_point - normal * radius);
    Some((normal_world, separation - radius, surface_a))
}

/// The separating-axis test of the core `start + t delta` (t in [0, 1], B's frame) against
/// hull B: the largest separation (m, < 0 when the core cuts into the hull) over B's face
/// normals and the cross products of the core with B's edges, with its axis (from B towards
/// the core) and the core's deepest point along it. Edges count only where the core's great
/// circle on the Gauss map crosses the edge's arc (the axis is then a face normal of the
/// Minkowski difference and the edge is B's support along it), and only when clearly better
/// than the best face, as in [`polyhedra`], so near ties give the face on both executors.
fn core_sat(b: &ConvexHull, start: Vec3, delta: Vec3) -> (f32, Vec3, Vec3) {
    let end = start + delta;
    let mut best = (f32::NEG_INFINITY, Vec3::Y, start);
    for face in b.faces() {
        let (height_start, height_end) = (
            face.normal.dot(start) - face.offset,
            face.normal.dot(end) - face.offset,
        );
        // The deeper end; the start on ties.
        let deepest = if height_end < height_start {
            (height_end, end)
        } else {
            (height_start, start)
        };
        if deepest.0 > best.0 {
            best = (deepest.0, face.normal, deepest.1);
        }
    }
    // Separation, axis, and the edge as a start and a direction.
    let mut best_edge: Option<(f32, Vec3, Vec3, Vec3)> = None;
    for edge in b.edges() {
        let [n1, n2] = edge.faces.map(|f| b.faces()[f as usize].normal);
        let (side1, side2) = (n1.dot(delta), n2.dot(delta));
        if side1 * side2 >= 0.0 {
            continue;
        }
        let p = b.vertices()[edge.vertices[0] as usize];
        let e = b.vertices()[edge.vertices[1] as usize] - p;
        let axis = e.cross(delta);
        let length_squared = axis.length_squared();
        if length_squared <= PARALLEL_SINE_SQUARED * e.length_squared() * delta.length_squared() {
            continue;
        }
        let mut axis = axis / length_squared.sqrt();
        // The orientation on the edge's arc, between its faces' normals.
        if axis.dot(n1 + n2) < 0.0 {
            axis = -axis;
        }
        let separation = axis.dot(start - p);
        if best_edge.is_none_or(|(s, ..)| separation > s) {
            best_edge = Some((separation, axis, p, e));
        }
    }
    match best_edge {
        Some((separation, axis, p, e))
            if clearly_greater(separation, best.0, EDGE_RELATIVE_TOLERANCE) =>
        {
            // The core's point across from the edge.
            let (s, _) = closest_parameters_between_segments(start, delta, p, e);
            (separation, axis, start + delta * s)
        }
        _ => best,
    }
}

/// Distance (m, > 0), unit normal (from B towards the core) and core point of the nearest
/// points of the core `start + t delta` and hull B, the core lying outside: the nearest of
/// each core end over each face it projects into, and of the core against each edge (the
/// first found on ties; near a tie the candidates agree, so either executor's pick is close).
/// `None` when every candidate is closer than rounding can give a direction to.
fn core_closest(b: &ConvexHull, start: Vec3, delta: Vec3) -> Option<(f32, Vec3, Vec3)> {
    let end = start + delta;
    let mut best = (f32::INFINITY, Vec3::Y, start);
    let ends: &[Vec3] = if delta == Vec3::ZERO {
        &[start]
    } else {
        &[start, end]
    };
    for face in b.faces() {
        for &point in ends {
            let height = face.normal.dot(point) - face.offset;
            if height > 0.0 && height < best.0 && over_face(b, face, point) {
                best = (height, face.normal, point);
            }
        }
    }
    for edge in b.edges() {
        let p = b.vertices()[edge.vertices[0] as usize];
        let e = b.vertices()[edge.vertices[1] as usize] - p;
        let (s, t) = closest_parameters_between_segments(start, delta, p, e);
        let on_core = start + delta * s;
        let offset = on_core - (p + e * t);
        let distance_squared = offset.length_squared();
        if distance_squared < best.0 * best.0 && distance_squared > COINCIDENT_DISTANCE_SQUARED {
            let distance = distance_squared.sqrt();
            best = (distance, offset / distance, on_core);
        }
    }
    best.0.is_finite().then_some(best)
}

/// Whether `point` (B's frame) lies within the side planes of `face` of hull B.
fn over_face(b: &ConvexHull, face: &HullFace, point: Vec3) -> bool {
    let face_loop = b.face_loop(face);
    (0..face_loop.len()).all(|k| {
        let p = b.vertices()[face_loop[k] as usize];
        let q = b.vertices()[face_loop[(k + 1) % face_loop.len()] as usize];
        (q - p).cross(face.normal).dot(point - p) <= 0.0
    })
}

pub(super) fn sphere_hull(
    a: &Sphere,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    if let Some((normal, separation, surface_a)) =
        core_contact(0.0, a.radius, pose_a, b, pose_b, margin)
    {
        out.normal = normal;
        push_contact(out, surface_a, normal, separation, 0);
    }
}

pub(super) fn capsule_hull(
    a: &Capsule,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let Some((normal, separation, surface_a)) =
        core_contact(a.half_height, a.radius, pose_a, b, pose_b, margin)
    else {
        return;
    };
    // Along a face: clip the segment to the face's side planes, one point per end.
    let normal_b = pose_b.inverse_transform_vector(normal);
    let face = b
        .faces()
        .iter()
        .max_by(|f, g| f.normal.dot(normal_b).total_cmp(&g.normal.dot(normal_b)))
        .copied();
    let axis = pose_b.inverse_transform_vector(pose_a.transform_vector(Vec3::Y));
    if let Some(face) = face
        && a.half_height > 0.0
        && face.normal.dot(normal_b).powi(2) >= CAPSULE_FACE_COS_SQUARED
        && axis.dot(face.normal).powi(2) <= 1.0 - CAPSULE_FACE_COS_SQUARED
        && capsule_on_face(a, pose_a, b, pose_b, &face, margin, out)
    {
        return;
    }
    out.normal = normal;
    push_contact(out, surface_a, normal, separation, 0);
}

/// The capsule's segment clipped to the side planes of `face` of hull B, one point per end
/// below `margin` (ids 0 and 1 for the `-half_height` and `+half_height` ends); false if none.
fn capsule_on_face(
    a: &Capsule,
    pose_a: &Transform,
    b: &ConvexHull,
    pose_b: &Transform,
    face: &HullFace,
    margin: f32,
    out: &mut Manifold,
) -> bool {
    let centre = pose_b.inverse_transform_point(pose_a.position);
    let axis = pose_b.inverse_transform_vector(pose_a.transform_vector(Vec3::Y));
    let (mut t0, mut t1) = (-a.half_height, a.half_height);
    let face_loop = b.face_loop(face);
    for (e, &v) in face_loop.iter().enumerate() {
        let p = b.vertices()[v as usize];
        let q = b.vertices()[face_loop[(e + 1) % face_loop.len()] as usize];
        // Keep side · (centre + t axis - p) <= 0: a bound on t from each side plane.
        let side = (q - p).cross(face.normal);
        let start = side.dot(centre - p);
        let rate = side.dot(axis);
        if rate == 0.0 {
            if start > 0.0 {
                return false;
            }
        } else if rate > 0.0 {
            t1 = t1.min(-start / rate);
        } else {
            t0 = t0.max(-start / rate);
        }
    }
    if t0 >= t1 {
        return false;
    }
    let normal = pose_b.transform_vector(face.normal);
    out.normal = normal;
    for (id, t) in [(0, t0), (1, t1)] {
        let point = centre + axis * t - face.normal * a.radius;
        let separation = face.normal.dot(point) - face.offset;
        if separation < margin {
            push_contact(out, pose_b.transform_point(point), normal, separation, id);
        }
    }
    out.count > 0
}

/// Hull (A) against a plane (B): every vertex below `margin`, id = vertex index.
pub(super) fn hull_plane(
    a: &ConvexHull,
    pose_a: &Transform,
    b: &Plane,
    pose_b: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    let normal = pose_b.transform_vector(b.normal);
    let offset = b.offset + normal.dot(pose_b.position);
    let local_normal = pose_a.inverse_transform_vector(normal);
    let centre_height = normal.dot(pose_a.position) - offset;
    let lowest = local_normal.dot(a.support(-local_normal));
    if centre_height + lowest >= margin {
        return;
    }
    let mut candidates: Vec<ContactPoint> = Vec::new();
    for (index, &v) in a.vertices().iter().enumerate() {
        let separation = centre_height + local_normal.dot(v);
        if separation < margin {
            candidates.push(ContactPoint::new(
                pose_a.transform_point(v) - normal * (0.5 * separation),
                separation,
                index as u32,
            ));
        }
    }
    *out = reduce(&candidates, normal);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Quat;

    fn cube() -> ConvexHull {
        let corners: Vec<Vec3> = (0..8)
            .map(|i| {
                Vec3::new(
                    [-0.5, 0.5][i & 1],
                    [-0.5, 0.5][(i >> 1) & 1],
                    [-0.5, 0.5][i >> 2],
                )
            })
            .collect();
        ConvexHull::new(&corners).unwrap()
    }

    fn assert_contact(out: &Manifold, normal: Vec3, separation: f32) {
        assert_eq!(out.count, 1, "{out:?}");
        assert!((out.normal - normal).length() < 1e-5, "{out:?}");
        assert!(
            (out.points[0].separation - separation).abs() < 1e-5,
            "{out:?}"
        );
    }

    /// A sphere over a face, beyond an edge and beyond a corner of a unit cube hull, 0.05 m
    /// from touching, and one whose centre is 0.1 m inside the +x face.
    #[test]
    fn sphere_hull_closed_forms() {
        let (hull, ball) = (cube(), Sphere { radius: 0.25 });
        let diagonal = |n: Vec3, reach: f32| n * 0.5 + n.normalize() * reach;
        for (centre, normal, separation) in [
            (Vec3::new(0.1, 0.8, 0.2), Vec3::Y, 0.05),
            (
                diagonal(Vec3::new(1.0, 1.0, 0.0), 0.3),
                Vec3::new(1.0, 1.0, 0.0).normalize(),
                0.05,
            ),
            (diagonal(Vec3::ONE, 0.3), Vec3::ONE.normalize(), 0.05),
            (Vec3::new(0.4, 0.0, 0.05), Vec3::X, -0.35),
        ] {
            let mut out = Manifold::default();
            let pose = Transform::from_position(centre);
            sphere_hull(&ball, &pose, &hull, &Transform::IDENTITY, 0.1, &mut out);
            assert_contact(&out, normal, separation);
            let expected = centre - normal * (0.25 + 0.5 * separation);
            assert!((out.points[0].position - expected).length() < 1e-5);
        }
    }

    /// A capsule across the cube's edge at x = y = 0.5, its segment 0.02 m deep along the
    /// edge's bisector: the edge axis beats every face; and parallel to that edge just outside
    /// it, where the nearest points are the edge and the segment.
    #[test]
    fn capsule_hull_edge_closed_forms() {
        let (hull, capsule) = (
            cube(),
            Capsule {
                radius: 0.1,
                half_height: 0.3,
            },
        );
        let bisector = Vec3::new(1.0, 1.0, 0.0).normalize();
        for (position, rotation, separation) in [
            (
                Vec3::new(0.48, 0.48, 0.1),
                Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
                -0.02 * 2.0f32.sqrt() - 0.1,
            ),
            (
                Vec3::new(0.55, 0.55, 0.1),
                Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
                0.05 * 2.0f32.sqrt() - 0.1,
            ),
        ] {
            let mut out = Manifold::default();
            let pose = Transform::new(position, rotation);
            capsule_hull(&capsule, &pose, &hull, &Transform::IDENTITY, 0.1, &mut out);
            assert_contact(&out, bisector, separation);
        }
    }

    /// The box tables agree with the hull built from the box's corners.
    #[test]
    fn box_tables_match_the_hull_of_the_corners() {
        let cuboid = Cuboid {
            half_extents: Vec3::new(1.0, 0.5, 0.25),
        };
        let boxed = BoxPolyhedron::new(&cuboid);
        let view = boxed.view();
        let hull = ConvexHull::new(&boxed.vertices).unwrap();
        assert_eq!(hull.vertices(), &boxed.vertices[..]);
        for f in 0..6 {
            let face = view.faces[f];
            let matching = hull
                .faces()
                .iter()
                .find(|g| (g.normal - face.normal).length() < 1e-6)
                .unwrap();
            let mut ours = view.face_loop(f).to_vec();
            let mut theirs = hull.face_loop(matching).to_vec();
            // Same cycle: rotate both to start at their lowest vertex.
            let rotate = |l: &mut Vec<u32>| {
                let k = (0..l.len()).min_by_key(|&k| l[k]).unwrap();
                l.rotate_left(k);
            };
            rotate(&mut ours);
            rotate(&mut theirs);
            assert_eq!(ours, theirs, "face {f}");
            assert!((matching.offset - face.offset).abs() < 1e-6);
        }
        for edge in &BOX_EDGES {
            let [v0, v1] = edge.vertices;
            let runs = |f: u32, from: u32, to: u32| {
                let l = view.face_loop(f as usize);
                (0..l.len()).any(|k| l[k] == from && l[(k + 1) % l.len()] == to)
            };
            assert!(runs(edge.faces[0], v0, v1) && runs(edge.faces[1], v1, v0));
        }
    }
}
