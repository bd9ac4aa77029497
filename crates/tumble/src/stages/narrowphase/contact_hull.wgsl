// Pairs with a convex hull: the twin of collision/contact/hull.rs (its module docs explain the
// method and the feature ids). Box–hull and hull–hull by SAT and clipping, a box being the
// unit box polyhedron scaled by its half extents; hull–plane by vertices. Same faces, edges
// and loops in the same order as on the CPU (`pack_hulls` in gpu.rs copies `ConvexHull`'s
// arrays), the same queries in the same order, so the same features win and the same points
// carry the same ids.
//
// The polyhedra are read from `hulls` (storage) wherever they are indexed by a variable:
// only the clipped polygon lives in private memory.

// A polyhedron in `hulls`: where its arrays start and the scale of its vertices (a box's half
// extents; 1 for a hull).
struct Polyhedron {
    scale: vec3<f32>,
    is_box: bool,
    vertex_count: u32,
    face_count: u32,
    edge_count: u32,
    vertices_at: u32,
    faces_at: u32,
    edges_at: u32,
    loops_at: u32,
}

// Transform in math.rs: a rigid frame (position, unit quaternion).
struct Frame {
    position: vec3<f32>,
    rotation: vec4<f32>,
}

// A vertex of the polygon being clipped (reference frame) and its clip feature.
struct HullClipVertex {
    position: vec3<f32>,
    feature: u32,
}

// Two polygons of 2 * MAX_HULL_FACE_VERTICES vertices, side by side: each clip reads one and
// writes the other. An incident loop of at most MAX_HULL_FACE_VERTICES vertices gains at most
// one vertex per side plane, of which there are at most as many.
const HULL_POLYGON_CAPACITY: u32 = 2u * MAX_HULL_FACE_VERTICES;
var<private> hull_polygons: array<HullClipVertex, 2u * HULL_POLYGON_CAPACITY>;

fn polyhedron_at(record: u32, scale: vec3<f32>, is_box: bool) -> Polyhedron {
    let vertex_count = hulls[record];
    let face_count = hulls[record + 1u];
    let edge_count = hulls[record + 2u];
    let vertices_at = record + HULL_HEADER_WORDS;
    let faces_at = vertices_at + 3u * vertex_count;
    let edges_at = faces_at + HULL_FACE_WORDS * face_count;
    let loops_at = edges_at + HULL_EDGE_WORDS * edge_count;
    return Polyhedron(
        scale,
        is_box,
        vertex_count,
        face_count,
        edge_count,
        vertices_at,
        faces_at,
        edges_at,
        loops_at,
    );
}

// The unit box's record starts the table.
fn box_polyhedron(half_extents: vec3<f32>) -> Polyhedron {
    return polyhedron_at(0u, half_extents, true);
}

fn hull_polyhedron(body: u32) -> Polyhedron {
    return polyhedron_at(hulls[HULL_DIRECTORY + body], vec3<f32>(1.0), false);
}

fn hull_vec3(at: u32) -> vec3<f32> {
    return vec3<f32>(
        bitcast<f32>(hulls[at]),
        bitcast<f32>(hulls[at + 1u]),
        bitcast<f32>(hulls[at + 2u]),
    );
}

// BoxPolyhedron's corners are h * (±1, ±1, ±1), exactly this product.
fn vertex_of(p: Polyhedron, index: u32) -> vec3<f32> {
    return hull_vec3(p.vertices_at + 3u * index) * p.scale;
}

fn face_normal(p: Polyhedron, face: u32) -> vec3<f32> {
    return hull_vec3(p.faces_at + HULL_FACE_WORDS * face);
}

// A box face's offset is its half extent along the (axis-aligned) normal: exactly this sum.
fn face_offset(p: Polyhedron, face: u32) -> f32 {
    if p.is_box {
        let normal = face_normal(p, face);
        return dot3(abs(normal), p.scale);
    }
    return bitcast<f32>(hulls[p.faces_at + HULL_FACE_WORDS * face + 3u]);
}

// Entry `k` of `face`'s loop (counter-clockwise seen from outside).
fn loop_vertex(p: Polyhedron, face: u32, k: u32) -> u32 {
    let first = hulls[p.faces_at + HULL_FACE_WORDS * face + 4u];
    return hulls[p.loops_at + first + k];
}

fn loop_length(p: Polyhedron, face: u32) -> u32 {
    return hulls[p.faces_at + HULL_FACE_WORDS * face + 5u];
}

// Word `k` of edge `edge`: its vertices (0, 1), then its faces (2, 3).
fn edge_word(p: Polyhedron, edge: u32, k: u32) -> u32 {
    return hulls[p.edges_at + HULL_EDGE_WORDS * edge + k];
}

// Polyhedron::support: the first vertex farthest along `direction`.
fn polyhedron_support(p: Polyhedron, direction: vec3<f32>) -> vec3<f32> {
    var best = vertex_of(p, 0u);
    var best_dot = dot3(best, direction);
    for (var index = 1u; index < p.vertex_count; index++) {
        let v = vertex_of(p, index);
        let d = dot3(v, direction);
        if d > best_dot {
            best_dot = d;
            best = v;
        }
    }
    return best;
}

fn frame_of(pose: BodyPose) -> Frame {
    return Frame(pose.position, pose.rotation);
}

fn frame_point(frame: Frame, p: vec3<f32>) -> vec3<f32> {
    return frame.position + quat_rotate(frame.rotation, p);
}

fn frame_vector(frame: Frame, v: vec3<f32>) -> vec3<f32> {
    return quat_rotate(frame.rotation, v);
}

fn frame_inverse_vector(frame: Frame, v: vec3<f32>) -> vec3<f32> {
    return quat_rotate(quat_conjugate(frame.rotation), v);
}

fn frame_inverse(frame: Frame) -> Frame {
    let rotation = quat_conjugate(frame.rotation);
    return Frame(quat_rotate(rotation, -frame.position), rotation);
}

// `a * b`: frame `b` (given in `a`'s frame) in `a`'s parent frame.
fn frame_mul(a: Frame, b: Frame) -> Frame {
    return Frame(frame_point(a, b.position), quat_mul(a.rotation, b.rotation));
}

// The best face of `reference` against another polyhedron.
struct FaceQuery {
    separation: f32,
    face: u32,
}

// hull.rs `face_query`; `other_in_ref` is `other`'s frame in `reference`'s.
fn face_query(reference: Polyhedron, other: Polyhedron, other_in_ref: Frame) -> FaceQuery {
    var best_separation = bitcast<f32>(0xff800000u);
    var best_face = 0u;
    for (var face = 0u; face < reference.face_count; face++) {
        let normal = face_normal(reference, face);
        let deepest = frame_point(
            other_in_ref,
            polyhedron_support(other, frame_inverse_vector(other_in_ref, -normal)),
        );
        let separation = dot3(normal, deepest) - face_offset(reference, face);
        if separation > best_separation {
            best_separation = separation;
            best_face = face;
        }
    }
    return FaceQuery(best_separation, best_face);
}

// Whether arcs ab and cd of the Gauss map cross (hull.rs `arcs_cross`).
fn arcs_cross(
    a: vec3<f32>,
    b: vec3<f32>,
    c: vec3<f32>,
    d: vec3<f32>,
    bxa: vec3<f32>,
    dxc: vec3<f32>,
) -> bool {
    let cba = dot3(c, bxa);
    let dba = dot3(d, bxa);
    let adc = dot3(a, dxc);
    let bdc = dot3(b, dxc);
    return cba * dba < 0.0 && adc * bdc < 0.0 && cba * bdc > 0.0;
}

// The best edge pair of hull.rs `edge_query`.
struct EdgeQuery {
    found: bool,
    separation: f32,
    edge_a: u32,
    edge_b: u32,
    // From A towards B, in A's frame.
    axis: vec3<f32>,
}

fn edge_query(a: Polyhedron, b: Polyhedron, b_in_a: Frame) -> EdgeQuery {
    let rotation = mat3_from_quat(b_in_a.rotation);
    var best = EdgeQuery(false, 0.0, 0u, 0u, vec3<f32>(0.0));
    for (var j = 0u; j < b.edge_count; j++) {
        // B's Gauss arc is negated: the Minkowski difference has -B's normals.
        let c = -mat_vec(rotation, face_normal(b, edge_word(b, j, 2u)));
        let d = -mat_vec(rotation, face_normal(b, edge_word(b, j, 3u)));
        let dxc = cross(d, c);
        let b0 = vertex_of(b, edge_word(b, j, 0u));
        let qb = frame_point(b_in_a, b0);
        let eb = mat_vec(rotation, vertex_of(b, edge_word(b, j, 1u)) - b0);
        for (var i = 0u; i < a.edge_count; i++) {
            let na = face_normal(a, edge_word(a, i, 2u));
            let nb = face_normal(a, edge_word(a, i, 3u));
            if !arcs_cross(na, nb, c, d, cross(nb, na), dxc) {
                continue;
            }
            let pa = vertex_of(a, edge_word(a, i, 0u));
            let ea = vertex_of(a, edge_word(a, i, 1u)) - pa;
            var axis = cross(ea, eb);
            let length_squared = dot3(axis, axis);
            if length_squared <= PARALLEL_SINE_SQUARED * dot3(ea, ea) * dot3(eb, eb) {
                continue;
            }
            axis = axis / sqrt(length_squared);
            if dot3(axis, pa) < 0.0 {
                axis = -axis;
            }
            let separation = dot3(axis, qb - pa);
            if !best.found || separation > best.separation {
                best = EdgeQuery(true, separation, i, j, axis);
            }
        }
    }
    return best;
}

fn box_hull(a: vec4<f32>, pose_a: BodyPose, b: u32, pose_b: BodyPose, margin: f32) {
    polyhedra(box_polyhedron(a.xyz), frame_of(pose_a), hull_polyhedron(b), frame_of(pose_b), margin);
}

fn hull_hull(a: u32, pose_a: BodyPose, b: u32, pose_b: BodyPose, margin: f32) {
    polyhedra(hull_polyhedron(a), frame_of(pose_a), hull_polyhedron(b), frame_of(pose_b), margin);
}

// SAT and clipping between two polyhedra (hull.rs `polyhedra`).
fn polyhedra(a: Polyhedron, pose_a: Frame, b: Polyhedron, pose_b: Frame, margin: f32) {
    let b_in_a = frame_mul(frame_inverse(pose_a), pose_b);
    let a_in_b = frame_inverse(b_in_a);
    let query_a = face_query(a, b, b_in_a);
    let separation_a = query_a.separation;
    if separation_a >= margin {
        return;
    }
    let query_b = face_query(b, a, a_in_b);
    let separation_b = query_b.separation;
    if separation_b >= margin {
        return;
    }
    let edge = edge_query(a, b, b_in_a);
    if edge.found && edge.separation >= margin {
        return;
    }
    let best_face = max(separation_a, separation_b);
    if edge.found && clearly_greater(edge.separation, best_face, EDGE_RELATIVE_TOLERANCE) {
        hull_edge_contact(a, pose_a, b, b_in_a, edge);
        return;
    }
    if separation_b > separation_a {
        hull_face_contact(b, pose_b, query_b.face, a, a_in_b, false, margin);
        // Points were made with B as the reference: normal from A to B; flip to B → A.
        out.normal = -out.normal;
    } else {
        hull_face_contact(a, pose_a, query_a.face, b, b_in_a, true, margin);
    }
}

// hull.rs `face_contact`: clips the incident face of `other` against `reference`'s face
// `face`; the normal from the reference face outwards (the caller flips it when the reference
// is B).
fn hull_face_contact(
    reference: Polyhedron,
    pose_reference: Frame,
    face: u32,
    other: Polyhedron,
    other_in_ref: Frame,
    reference_is_a: bool,
    margin: f32,
) {
    let normal = face_normal(reference, face);
    let offset = face_offset(reference, face);
    // The incident face: the other's face most anti-parallel to the reference normal.
    let normal_in_other = frame_inverse_vector(other_in_ref, normal);
    var incident = 0u;
    var lowest = bitcast<f32>(0x7f800000u);
    for (var index = 0u; index < other.face_count; index++) {
        let d = dot3(face_normal(other, index), normal_in_other);
        if d < lowest {
            lowest = d;
            incident = index;
        }
    }
    var count = loop_length(other, incident);
    for (var k = 0u; k < count; k++) {
        let v = vertex_of(other, loop_vertex(other, incident, k));
        hull_polygons[k] = HullClipVertex(frame_point(other_in_ref, v), k);
    }
    // The polygon is in the half `source` of `hull_polygons`; each clip moves it to the other.
    var source = 0u;
    let side_count = loop_length(reference, face);
    for (var e = 0u; e < side_count; e++) {
        let p = vertex_of(reference, loop_vertex(reference, face, e));
        let q = vertex_of(reference, loop_vertex(reference, face, (e + 1u) % side_count));
        // Side plane through the edge, normal pointing out of the face.
        let side = cross(q - p, normal);
        count = clip_hull_polygon(source, count, side, dot3(side, p), e);
        source = 1u - source;
        if count == 0u {
            return;
        }
    }

    let world_normal = frame_vector(pose_reference, normal);
    let face_bits = ((face & 0x7Fu) << 16u) | ((incident & 0x7Fu) << 23u)
        | select(0u, HULL_REFERENCE_IS_A_BIT, reference_is_a);
    var candidate_count = 0u;
    for (var k = 0u; k < count; k++) {
        let vertex = hull_polygons[source * HULL_POLYGON_CAPACITY + k];
        let separation = dot3(normal, vertex.position) - offset;
        if separation < margin {
            // Midway between the incident vertex and its projection on the reference face.
            let midpoint = vertex.position - normal * (0.5 * separation);
            candidates[candidate_count] = contact_point(
                frame_point(pose_reference, midpoint),
                separation,
                vertex.feature | face_bits,
            );
            candidate_count += 1u;
        }
    }
    // The normal runs from the other body to the reference one.
    emit_candidates(candidate_count, -world_normal);
}

// One Sutherland–Hodgman pass (hull.rs `clip`): the part of polygon `source` (`count`
// vertices) with side · x <= offset into the other half; returns its vertex count.
fn clip_hull_polygon(source: u32, count: u32, side: vec3<f32>, offset: f32, plane: u32) -> u32 {
    let read_at = source * HULL_POLYGON_CAPACITY;
    let write_at = (1u - source) * HULL_POLYGON_CAPACITY;
    var written = 0u;
    var previous = hull_polygons[read_at + count - 1u];
    var previous_distance = dot3(side, previous.position) - offset;
    for (var k = 0u; k < count; k++) {
        let current = hull_polygons[read_at + k];
        let distance = dot3(side, current.position) - offset;
        if (previous_distance <= 0.0) != (distance <= 0.0) {
            let t = previous_distance / (previous_distance - distance);
            let leaving = select(0u, 1u, previous_distance <= 0.0);
            written = push_hull_clipped(
                write_at,
                written,
                HullClipVertex(
                    previous.position + (current.position - previous.position) * t,
                    HULL_CROSSING_BIT | (plane << 1u) | leaving,
                ),
            );
        }
        if distance <= 0.0 {
            written = push_hull_clipped(write_at, written, current);
        }
        previous = current;
        previous_distance = distance;
    }
    return written;
}

// Appends `vertex` to the polygon at `write_at` holding `count` vertices; returns the new
// count. A convex polygon gains at most one vertex per side plane, so a vertex past the
// capacity could only come from rounding (a polygon made locally concave by it): left out.
fn push_hull_clipped(write_at: u32, count: u32, vertex: HullClipVertex) -> u32 {
    if count == HULL_POLYGON_CAPACITY {
        return count;
    }
    hull_polygons[write_at + count] = vertex;
    return count + 1u;
}

// hull.rs `edge_contact`: one point midway between the closest points of A's and B's edges.
fn hull_edge_contact(a: Polyhedron, pose_a: Frame, b: Polyhedron, b_in_a: Frame, edge: EdgeQuery) {
    let a0 = vertex_of(a, edge_word(a, edge.edge_a, 0u));
    let a1 = vertex_of(a, edge_word(a, edge.edge_a, 1u));
    let b0 = frame_point(b_in_a, vertex_of(b, edge_word(b, edge.edge_b, 0u)));
    let b1 = frame_point(b_in_a, vertex_of(b, edge_word(b, edge.edge_b, 1u)));
    let st = closest_parameters_between_segments(a0, a1 - a0, b0, b1 - b0);
    let on_a = a0 + (a1 - a0) * st.x;
    let on_b = b0 + (b1 - b0) * st.y;
    let separation = dot3(edge.axis, on_b - on_a);
    let normal = -frame_vector(pose_a, edge.axis);
    out.normal = normal;
    push_contact(
        frame_point(pose_a, on_a),
        normal,
        separation,
        HULL_EDGE_CONTACT_BIT | ((edge.edge_a & 0x7FFFu) << 15u) | (edge.edge_b & 0x7FFFu),
    );
}

// hull.rs `hull_plane`, hull A against plane B: every vertex below `margin` (id = vertex
// index), reduced to four by `reduce` streaming over the vertices, so that a hull of any size
// needs no candidate array.
fn hull_plane(a: u32, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let hull = hull_polyhedron(a);
    let frame_a = frame_of(pose_a);
    let plane = world_plane(b, pose_b);
    let normal = plane.xyz;
    let local_normal = frame_inverse_vector(frame_a, normal);
    let centre_height = dot3(normal, pose_a.position) - plane.w;
    // ConvexHull::support: the first vertex farthest along -normal.
    let lowest = dot3(local_normal, polyhedron_support(hull, -local_normal));
    if centre_height + lowest >= margin {
        return;
    }
    let context = PlaneCandidates(hull, frame_a, normal, local_normal, centre_height);
    out.normal = normal;

    // Fewer than five candidates: all, in vertex order.
    var count = 0u;
    for (var index = 0u; index < hull.vertex_count; index++) {
        if plane_candidate_separation(context, index) < margin {
            count += 1u;
        }
    }
    if count <= MAX_MANIFOLD_POINTS {
        for (var index = 0u; index < hull.vertex_count; index++) {
            if plane_candidate_separation(context, index) < margin {
                push_point(plane_candidate(context, index));
            }
        }
        return;
    }

    // collision/manifold.rs `reduce` (as `reduce` in contact_common.wgsl) over the
    // candidates in vertex order: deepest, farthest from it, widest triangle, largest
    // quadrilateral.
    var deepest = 0xffffffffu;
    var deepest_separation = 0.0;
    for (var index = 0u; index < hull.vertex_count; index++) {
        let separation = plane_candidate_separation(context, index);
        if separation < margin && (deepest == 0xffffffffu || separation < deepest_separation) {
            deepest = index;
            deepest_separation = separation;
        }
    }
    let first = plane_candidate(context, deepest).position;

    var farthest = 0xffffffffu;
    var best = 0.0;
    for (var index = 0u; index < hull.vertex_count; index++) {
        if index == deepest || plane_candidate_separation(context, index) >= margin {
            continue;
        }
        let offset = plane_candidate(context, index).position - first;
        let along_normal = dot3(offset, normal);
        let score = dot3(offset, offset) - along_normal * along_normal;
        if farthest == 0xffffffffu || beats(score, best) {
            farthest = index;
            best = score;
        }
    }
    let second = plane_candidate(context, farthest).position;

    var widest = 0xffffffffu;
    for (var index = 0u; index < hull.vertex_count; index++) {
        if index == deepest || index == farthest
            || plane_candidate_separation(context, index) >= margin {
            continue;
        }
        let score = abs(triangle_area(first, second, plane_candidate(context, index).position, normal));
        if widest == 0xffffffffu || beats(score, best) {
            widest = index;
            best = score;
        }
    }
    let third = plane_candidate(context, widest).position;

    let winding = select(-1.0, 1.0, triangle_area(first, second, third, normal) >= 0.0);
    var fourth = 0xffffffffu;
    for (var index = 0u; index < hull.vertex_count; index++) {
        if index == deepest || index == farthest || index == widest
            || plane_candidate_separation(context, index) >= margin {
            continue;
        }
        let p = plane_candidate(context, index).position;
        let score = max(
            max(
                quadrilateral_area(first, p, second, third, normal, winding),
                quadrilateral_area(first, second, p, third, normal, winding),
            ),
            quadrilateral_area(first, second, third, p, normal, winding),
        );
        if fourth == 0xffffffffu || beats(score, best) {
            fourth = index;
            best = score;
        }
    }

    push_point(plane_candidate(context, deepest));
    push_point(plane_candidate(context, farthest));
    push_point(plane_candidate(context, widest));
    push_point(plane_candidate(context, fourth));
}

// What hull–plane's candidates are computed from.
struct PlaneCandidates {
    hull: Polyhedron,
    pose: Frame,
    // The plane's world normal, and in the hull's frame.
    normal: vec3<f32>,
    local_normal: vec3<f32>,
    // Height of the hull's origin above the plane (m).
    centre_height: f32,
}

fn plane_candidate_separation(c: PlaneCandidates, index: u32) -> f32 {
    return c.centre_height + dot3(c.local_normal, vertex_of(c.hull, index));
}

fn plane_candidate(c: PlaneCandidates, index: u32) -> ContactPoint {
    let v = vertex_of(c.hull, index);
    let separation = c.centre_height + dot3(c.local_normal, v);
    return contact_point(frame_point(c.pose, v) - c.normal * (0.5 * separation), separation, index);
}

// A contact of a round shape's core with a hull: separation of the cores (m), normal (from the
// hull towards the core) and the core's point, in the hull's frame.
struct CoreFeature {
    separation: f32,
    normal: vec3<f32>,
    point: vec3<f32>,
}

// hull.rs `core_contact`: normal (B → A, world), separation and A's surface point of A's core,
// the segment from -half_height to +half_height along A's y (a point when 0) swept by
// `radius`, against hull `b`; `found` false when apart by `margin` or more.
struct CoreContact {
    found: bool,
    normal: vec3<f32>,
    separation: f32,
    surface_a: vec3<f32>,
}

fn core_contact(
    half_height: f32,
    radius: f32,
    pose_a: Frame,
    b: Polyhedron,
    pose_b: Frame,
    margin: f32,
) -> CoreContact {
    let none = CoreContact(false, vec3<f32>(0.0), 0.0, vec3<f32>(0.0));
    let centre = frame_inverse_point(pose_b, pose_a.position);
    let half_axis = frame_inverse_vector(pose_b, frame_vector(pose_a, vec3<f32>(0.0, half_height, 0.0)));
    let start = centre - half_axis;
    let delta = 2.0 * half_axis;
    var feature = core_sat(b, start, delta);
    // Every axis is a lower bound of the distance: this one is already too far.
    if feature.separation - radius >= margin {
        return none;
    }
    if feature.separation > 0.0 {
        // Apart: the nearest features, exactly (touching within rounding: the axis).
        let closest = core_closest(b, start, delta);
        if closest.separation < bitcast<f32>(0x7f800000u) {
            feature = closest;
        }
    }
    if feature.separation - radius >= margin {
        return none;
    }
    let normal_world = frame_vector(pose_b, feature.normal);
    let surface_a = frame_point(pose_b, feature.point - feature.normal * radius);
    return CoreContact(true, normal_world, feature.separation - radius, surface_a);
}

// hull.rs `core_sat`: the separating-axis test of the core `start + t delta` against hull `b`
// over its face normals and the crossing edges' axes (edges only when clearly better).
fn core_sat(b: Polyhedron, start: vec3<f32>, delta: vec3<f32>) -> CoreFeature {
    let end = start + delta;
    var best = CoreFeature(bitcast<f32>(0xff800000u), vec3<f32>(0.0, 1.0, 0.0), start);
    for (var face = 0u; face < b.face_count; face++) {
        let normal = face_normal(b, face);
        let offset = face_offset(b, face);
        let height_start = dot3(normal, start) - offset;
        let height_end = dot3(normal, end) - offset;
        // The deeper end; the start on ties.
        var deepest = CoreFeature(height_start, normal, start);
        if height_end < height_start {
            deepest = CoreFeature(height_end, normal, end);
        }
        if deepest.separation > best.separation {
            best = deepest;
        }
    }
    var edge_found = false;
    var edge_separation = 0.0;
    var edge_axis = vec3<f32>(0.0);
    var edge_start = vec3<f32>(0.0);
    var edge_delta = vec3<f32>(0.0);
    for (var edge = 0u; edge < b.edge_count; edge++) {
        let n1 = face_normal(b, edge_word(b, edge, 2u));
        let n2 = face_normal(b, edge_word(b, edge, 3u));
        let side1 = dot3(n1, delta);
        let side2 = dot3(n2, delta);
        if side1 * side2 >= 0.0 {
            continue;
        }
        let p = vertex_of(b, edge_word(b, edge, 0u));
        let e = vertex_of(b, edge_word(b, edge, 1u)) - p;
        var axis = cross(e, delta);
        let length_squared = dot3(axis, axis);
        if length_squared <= PARALLEL_SINE_SQUARED * dot3(e, e) * dot3(delta, delta) {
            continue;
        }
        axis = axis / sqrt(length_squared);
        // The orientation on the edge's arc, between its faces' normals.
        if dot3(axis, n1 + n2) < 0.0 {
            axis = -axis;
        }
        let separation = dot3(axis, start - p);
        if !edge_found || separation > edge_separation {
            edge_found = true;
            edge_separation = separation;
            edge_axis = axis;
            edge_start = p;
            edge_delta = e;
        }
    }
    if edge_found && clearly_greater(edge_separation, best.separation, EDGE_RELATIVE_TOLERANCE) {
        // The core's point across from the edge.
        let st = closest_parameters_between_segments(start, delta, edge_start, edge_delta);
        return CoreFeature(edge_separation, edge_axis, start + delta * st.x);
    }
    return best;
}

// hull.rs `core_closest`: the nearest points of the core (outside the hull) and hull `b`;
// separation infinite when every candidate is closer than rounding gives a direction to.
fn core_closest(b: Polyhedron, start: vec3<f32>, delta: vec3<f32>) -> CoreFeature {
    let end = start + delta;
    var best = CoreFeature(bitcast<f32>(0x7f800000u), vec3<f32>(0.0, 1.0, 0.0), start);
    let end_count = select(2u, 1u, all(delta == vec3<f32>(0.0)));
    for (var face = 0u; face < b.face_count; face++) {
        let normal = face_normal(b, face);
        let offset = face_offset(b, face);
        for (var k = 0u; k < end_count; k++) {
            let point = select(start, end, k == 1u);
            let height = dot3(normal, point) - offset;
            if height > 0.0 && height < best.separation && over_face(b, face, normal, point) {
                best = CoreFeature(height, normal, point);
            }
        }
    }
    for (var edge = 0u; edge < b.edge_count; edge++) {
        let p = vertex_of(b, edge_word(b, edge, 0u));
        let e = vertex_of(b, edge_word(b, edge, 1u)) - p;
        let st = closest_parameters_between_segments(start, delta, p, e);
        let on_core = start + delta * st.x;
        let offset = on_core - (p + e * st.y);
        let distance_squared = dot3(offset, offset);
        if distance_squared < best.separation * best.separation
            && distance_squared > COINCIDENT_DISTANCE_SQUARED {
            let distance = sqrt(distance_squared);
            best = CoreFeature(distance, offset / distance, on_core);
        }
    }
    return best;
}

// hull.rs `over_face`: whether `point` lies within the side planes of `face` (of `normal`).
fn over_face(b: Polyhedron, face: u32, normal: vec3<f32>, point: vec3<f32>) -> bool {
    let side_count = loop_length(b, face);
    for (var k = 0u; k < side_count; k++) {
        let p = vertex_of(b, loop_vertex(b, face, k));
        let q = vertex_of(b, loop_vertex(b, face, (k + 1u) % side_count));
        if dot3(cross(q - p, normal), point - p) > 0.0 {
            return false;
        }
    }
    return true;
}

fn sphere_hull(a: vec4<f32>, pose_a: BodyPose, b: u32, pose_b: BodyPose, margin: f32) {
    let contact = core_contact(0.0, a.x, frame_of(pose_a), hull_polyhedron(b), frame_of(pose_b), margin);
    if contact.found {
        out.normal = contact.normal;
        push_contact(contact.surface_a, contact.normal, contact.separation, 0u);
    }
}

// hull.rs `capsule_hull`: one point, or two when the segment lies along the face touched.
fn capsule_hull(a: vec4<f32>, pose_a: BodyPose, b: u32, pose_b: BodyPose, margin: f32) {
    let frame_a = frame_of(pose_a);
    let frame_b = frame_of(pose_b);
    let hull = hull_polyhedron(b);
    let contact = core_contact(a.y, a.x, frame_a, hull, frame_b, margin);
    if !contact.found {
        return;
    }
    // Along a face: clip the segment to the face's side planes, one point per end. The face
    // most parallel to the normal, the last on ties (Iterator::max_by).
    let normal_b = frame_inverse_vector(frame_b, contact.normal);
    var face = 0u;
    var face_dot = dot3(face_normal(hull, 0u), normal_b);
    for (var index = 1u; index < hull.face_count; index++) {
        let d = dot3(face_normal(hull, index), normal_b);
        if d >= face_dot {
            face = index;
            face_dot = d;
        }
    }
    let axis = frame_inverse_vector(frame_b, frame_vector(frame_a, vec3<f32>(0.0, 1.0, 0.0)));
    let axis_dot = dot3(axis, face_normal(hull, face));
    if a.y > 0.0 && face_dot * face_dot >= CAPSULE_FACE_COS_SQUARED
        && axis_dot * axis_dot <= 1.0 - CAPSULE_FACE_COS_SQUARED
        && capsule_on_hull_face(a, frame_a, hull, frame_b, face, margin) {
        return;
    }
    out.normal = contact.normal;
    push_contact(contact.surface_a, contact.normal, contact.separation, 0u);
}

// hull.rs `capsule_on_face`: the segment clipped to the side planes of `face` of `hull`, one
// point per end below `margin` (ids 0 and 1 for the -half_height and +half_height ends);
// false if none.
fn capsule_on_hull_face(
    a: vec4<f32>,
    pose_a: Frame,
    hull: Polyhedron,
    pose_b: Frame,
    face: u32,
    margin: f32,
) -> bool {
    let radius = a.x;
    let half_height = a.y;
    let normal = face_normal(hull, face);
    let centre = frame_inverse_point(pose_b, pose_a.position);
    let axis = frame_inverse_vector(pose_b, frame_vector(pose_a, vec3<f32>(0.0, 1.0, 0.0)));
    var t0 = -half_height;
    var t1 = half_height;
    let side_count = loop_length(hull, face);
    for (var e = 0u; e < side_count; e++) {
        let p = vertex_of(hull, loop_vertex(hull, face, e));
        let q = vertex_of(hull, loop_vertex(hull, face, (e + 1u) % side_count));
        // Keep side · (centre + t axis - p) <= 0: a bound on t from each side plane.
        let side = cross(q - p, normal);
        let start = dot3(side, centre - p);
        let rate = dot3(side, axis);
        if rate == 0.0 {
            if start > 0.0 {
                return false;
            }
        } else if rate > 0.0 {
            t1 = min(t1, -start / rate);
        } else {
            t0 = max(t0, -start / rate);
        }
    }
    if t0 >= t1 {
        return false;
    }
    let world_normal = frame_vector(pose_b, normal);
    let offset = face_offset(hull, face);
    out.normal = world_normal;
    for (var id = 0u; id < 2u; id++) {
        let t = select(t1, t0, id == 0u);
        let point = centre + axis * t - normal * radius;
        let separation = dot3(normal, point) - offset;
        if separation < margin {
            push_contact(frame_point(pose_b, point), world_normal, separation, id);
        }
    }
    return out.count > 0u;
}

// Transform::inverse_transform_point.
fn frame_inverse_point(frame: Frame, p: vec3<f32>) -> vec3<f32> {
    return quat_rotate(quat_conjugate(frame.rotation), p - frame.position);
}
