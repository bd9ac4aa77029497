// Box–box: the twin of collision/contact/box_box.rs (its module docs explain the method and
// the feature ids). Same axes in the same order, same preferences and tie-breaks, same
// clipping order, so the same points carry the same ids. Everything runs in B's frame.

// A vertex of the polygon being clipped (reference frame), its clip feature and the line the
// polygon edge leaving it lies on (0..=3 incident edges, 4..=7 side planes).
struct ClipVertex {
    position: vec3<f32>,
    feature: u32,
    line: u32,
}

// Most vertices of a clipped box face: 4, and one more for each of the 4 side planes.
const BOX_POLYGON_CAPACITY: u32 = 8u;

// Two Sutherland–Hodgman polygons side by side: each clip reads one half and writes the other
// (as contact_hull.wgsl's), so no polygon is copied; drivers keep this array in memory.
var<private> box_polygons: array<ClipVertex, 2u * BOX_POLYGON_CAPACITY>;

fn box_box(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let half_a = a.xyz;
    let half_b = b.xyz;
    let rotation_a = mat3_from_quat(pose_a.rotation);
    let rotation_b = mat3_from_quat(pose_b.rotation);
    let to_b = transpose(rotation_b);
    // A in B's frame: axes the columns of `rotation`, centre `translation`.
    var rotation = mat_mat(to_b, rotation_a);
    let translation = mat_vec(to_b, pose_a.position - pose_b.position);
    var absolute = mat3x3<f32>(abs(rotation[0]), abs(rotation[1]), abs(rotation[2]));

    // B's face normals.
    let separations_b = abs(translation) - half_b - mat_vec(absolute, half_a);
    let axis_b = largest_component(separations_b);
    let separation_b = separations_b[axis_b];
    if separation_b >= margin {
        return;
    }
    // A's face normals.
    let rotation_transposed = transpose(rotation);
    let translation_in_a = mat_vec(rotation_transposed, translation);
    let separations_a = abs(translation_in_a) - half_a - mat_vec(transpose(absolute), half_b);
    let axis_a = largest_component(separations_a);
    let separation_a = separations_a[axis_a];
    if separation_a >= margin {
        return;
    }

    // Edge axes e_i × a_j in closed form from R (see box_box.rs).
    var edge_found = false;
    var edge_normal = vec3<f32>(0.0);
    var edge_separation = 0.0;
    var edge_axis_of_b = 0u;
    var edge_axis_of_a = 0u;
    for (var axis_of_b = 0u; axis_of_b < 3u; axis_of_b++) {
        let next_b = (axis_of_b + 1u) % 3u;
        let last_b = (axis_of_b + 2u) % 3u;
        for (var axis_of_a = 0u; axis_of_a < 3u; axis_of_a++) {
            let next_a = (axis_of_a + 1u) % 3u;
            let last_a = (axis_of_a + 2u) % 3u;
            let column = rotation[axis_of_a];
            let absolute_column = absolute[axis_of_a];
            let length_squared = column[next_b] * column[next_b] + column[last_b] * column[last_b];
            if length_squared <= PARALLEL_SINE_SQUARED {
                continue;
            }
            let along = translation[last_b] * column[next_b] - translation[next_b] * column[last_b];
            let reach_b = half_b[next_b] * absolute_column[last_b]
                + half_b[last_b] * absolute_column[next_b];
            let reach_a = half_a[next_a] * absolute[last_a][axis_of_b]
                + half_a[last_a] * absolute[next_a][axis_of_b];
            let inverse_length = 1.0 / sqrt(length_squared);
            let separation = (abs(along) - reach_a - reach_b) * inverse_length;
            if separation >= margin {
                return;
            }
            if !edge_found || separation > edge_separation {
                var normal = vec3<f32>(0.0);
                normal[next_b] = -column[last_b];
                normal[last_b] = column[next_b];
                edge_found = true;
                edge_normal = normal * (sign_or_positive(along) * inverse_length);
                edge_separation = separation;
                edge_axis_of_b = axis_of_b;
                edge_axis_of_a = axis_of_a;
            }
        }
    }

    let face_separation = max(separation_a, separation_b);
    if edge_found && clearly_greater(edge_separation, face_separation, EDGE_RELATIVE_TOLERANCE) {
        edge_contact(
            edge_normal,
            edge_axis_of_b,
            edge_axis_of_a,
            half_a,
            half_b,
            rotation,
            translation,
            rotation_b,
            pose_b.position,
            margin,
        );
        return;
    }

    var reference_is_a: bool;
    if clearly_greater(separation_a, separation_b, FACE_RELATIVE_TOLERANCE) {
        reference_is_a = true;
    } else if clearly_greater(separation_b, separation_a, FACE_RELATIVE_TOLERANCE) {
        reference_is_a = false;
    } else {
        reference_is_a = face_area(half_a, axis_a) > face_area(half_b, axis_b);
    }
    // The clipping runs in the reference box's frame.
    var reference_half: vec3<f32>;
    var face_axis: u32;
    var face_sign: f32;
    var incident_half: vec3<f32>;
    var incident_rotation: mat3x3<f32>;
    var incident_translation: vec3<f32>;
    var reference_rotation: mat3x3<f32>;
    var reference_position: vec3<f32>;
    if reference_is_a {
        // B's centre in A's frame is -R^T t; its axes there are the columns of R^T.
        reference_half = half_a;
        face_axis = axis_a;
        face_sign = sign_or_positive(-translation_in_a[axis_a]);
        incident_half = half_b;
        incident_rotation = rotation_transposed;
        incident_translation = -translation_in_a;
        reference_rotation = rotation_a;
        reference_position = pose_a.position;
    } else {
        reference_half = half_b;
        face_axis = axis_b;
        face_sign = sign_or_positive(translation[axis_b]);
        incident_half = half_a;
        incident_rotation = rotation;
        incident_translation = translation;
        reference_rotation = rotation_b;
        reference_position = pose_b.position;
    }
    let count = clip_incident_face(
        reference_half,
        face_axis,
        face_sign,
        incident_half,
        incident_rotation,
        incident_translation,
        margin,
    );
    let id_flag = select(0u, REFERENCE_IS_A_BIT, reference_is_a);
    for (var index = 0u; index < count; index++) {
        candidates[index].position = reference_position
            + mat_vec(reference_rotation, candidates[index].position);
        candidates[index].id |= id_flag;
    }
    // The reference normal points from the reference box to the incident one; the manifold's
    // from B to A.
    let reference_normal = mat_vec(reference_rotation, face_sign * axis_vector(face_axis));
    emit_candidates(count, select(reference_normal, -reference_normal, reference_is_a));
}

// A quarter of the area of the faces normal to `axis` (m²): only compared.
fn face_area(half: vec3<f32>, axis: u32) -> f32 {
    return half[(axis + 1u) % 3u] * half[(axis + 2u) % 3u];
}

// 2 * axis + (1 if the normal is along -axis): the face's 3 bits of a feature id.
fn face_index(axis: u32, sign: f32) -> u32 {
    return 2u * axis + select(0u, 1u, sign < 0.0);
}

// One point between the two edges reaching furthest towards each other along the edge axis
// `normal` (B's frame). A is (rotation, translation) in B's frame; B is (world_rotation,
// world_position) in the world.
fn edge_contact(
    normal: vec3<f32>,
    axis_of_b: u32,
    axis_of_a: u32,
    half_a: vec3<f32>,
    half_b: vec3<f32>,
    rotation: mat3x3<f32>,
    translation: vec3<f32>,
    world_rotation: mat3x3<f32>,
    world_position: vec3<f32>,
    margin: f32,
) {
    var corner_b = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis++) {
        corner_b[axis] = sign_or_positive(normal[axis]) * half_b[axis];
    }
    corner_b[axis_of_b] = -half_b[axis_of_b];
    let delta_b = 2.0 * half_b[axis_of_b] * axis_vector(axis_of_b);
    let normal_in_a = mat_vec(transpose(rotation), normal);
    var corner_a = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis++) {
        corner_a[axis] = -sign_or_positive(normal_in_a[axis]) * half_a[axis];
    }
    corner_a[axis_of_a] = -half_a[axis_of_a];
    let start_a = translation + mat_vec(rotation, corner_a);
    var columns = rotation;
    let delta_a = 2.0 * half_a[axis_of_a] * columns[axis_of_a];

    let st = closest_parameters_between_segments(start_a, delta_a, corner_b, delta_b);
    let point_a = start_a + delta_a * st.x;
    let point_b = corner_b + delta_b * st.y;
    let separation = dot3(point_a - point_b, normal);
    if separation >= margin {
        return;
    }
    out.normal = mat_vec(world_rotation, normal);
    push_point(contact_point(
        world_position + mat_vec(world_rotation, 0.5 * (point_a + point_b)),
        separation,
        EDGE_CONTACT_BIT | edge_index(axis_of_b, corner_b)
            | (edge_index(axis_of_a, corner_a) << 4u),
    ));
}

fn edge_index(axis: u32, corner: vec3<f32>) -> u32 {
    return 4u * axis + select(0u, 1u, corner[(axis + 1u) % 3u] > 0.0)
        + select(0u, 2u, corner[(axis + 2u) % 3u] > 0.0);
}

// Appends `vertex` to the polygon at `write_at` holding `count` vertices; returns the new
// count. A ninth vertex could only be a rounding duplicate: left out, as on the CPU.
fn push_clipped(write_at: u32, count: u32, vertex: ClipVertex) -> u32 {
    if count >= BOX_POLYGON_CAPACITY {
        return count;
    }
    box_polygons[write_at + count] = vertex;
    return count + 1u;
}

// The polygon in half `source` of `box_polygons` (`count` vertices), its part where
// sign * x[axis] <= limit written to the other half; returns its vertex count. Cut vertices
// get feature 4 + 4 * line + plane.
fn clip_polygon(source: u32, count: u32, axis: u32, sign: f32, limit: f32, plane: u32) -> u32 {
    if count == 0u {
        return 0u;
    }
    let read_at = source * BOX_POLYGON_CAPACITY;
    let write_at = (1u - source) * BOX_POLYGON_CAPACITY;
    var written = 0u;
    var previous = box_polygons[read_at + count - 1u];
    var previous_distance = sign * previous.position[axis] - limit;
    for (var index = 0u; index < count; index++) {
        let current = box_polygons[read_at + index];
        let current_distance = sign * current.position[axis] - limit;
        // Where the edge crosses the plane; used only when the distances have opposite signs,
        // so the division is safe where it matters.
        let crossing = previous.position
            + (current.position - previous.position)
                * (previous_distance / (previous_distance - current_distance));
        let feature = 4u + 4u * previous.line + plane;
        if current_distance <= 0.0 {
            if previous_distance > 0.0 {
                // Entering: the rest of the edge continues on its line.
                written = push_clipped(write_at, written,
                    ClipVertex(crossing, feature, previous.line));
            }
            written = push_clipped(write_at, written, current);
        } else if previous_distance <= 0.0 {
            // Leaving: the polygon runs along the side plane until it re-enters.
            written = push_clipped(write_at, written, ClipVertex(crossing, feature, 4u + plane));
        }
        previous = current;
        previous_distance = current_distance;
    }
    return written;
}

// Clips the incident box's face most anti-parallel to the reference face (axis, sign) against
// the reference face's side planes; writes the clipped vertices below `margin` into
// `candidates` (reference frame, ids without the reference-is-A bit). Returns how many.
fn clip_incident_face(
    reference_half: vec3<f32>,
    face_axis: u32,
    face_sign: f32,
    half: vec3<f32>,
    rotation: mat3x3<f32>,
    translation: vec3<f32>,
    margin: f32,
) -> u32 {
    let reference_normal = face_sign * axis_vector(face_axis);
    let cosines = mat_vec(transpose(rotation), reference_normal);
    let incident_axis = largest_component(abs(cosines));
    let incident_sign = -sign_or_positive(cosines[incident_axis]);

    // The incident face's vertices in winding order (+u, +v), (-u, +v), (-u, -v), (+u, -v).
    let u = (incident_axis + 1u) % 3u;
    let v = (incident_axis + 2u) % 3u;
    let signs_u = array<f32, 4>(1.0, -1.0, -1.0, 1.0);
    let signs_v = array<f32, 4>(1.0, 1.0, -1.0, -1.0);
    for (var index = 0u; index < 4u; index++) {
        var corner = vec3<f32>(0.0);
        corner[incident_axis] = incident_sign * half[incident_axis];
        corner[u] = signs_u[index] * half[u];
        corner[v] = signs_v[index] * half[v];
        box_polygons[index] = ClipVertex(translation + mat_vec(rotation, corner), index, index);
    }

    // Side planes +u, -u, +v, -v of the reference face: from half 0 to 1 and back, twice.
    let side_u = (face_axis + 1u) % 3u;
    let side_v = (face_axis + 2u) % 3u;
    var polygon_count = clip_polygon(0u, 4u, side_u, 1.0, reference_half[side_u], 0u);
    polygon_count = clip_polygon(1u, polygon_count, side_u, -1.0, reference_half[side_u], 1u);
    polygon_count = clip_polygon(0u, polygon_count, side_v, 1.0, reference_half[side_v], 2u);
    polygon_count = clip_polygon(1u, polygon_count, side_v, -1.0, reference_half[side_v], 3u);

    let id_base = (face_index(face_axis, face_sign) << 6u)
        | (face_index(incident_axis, incident_sign) << 9u);
    var count = 0u;
    for (var index = 0u; index < polygon_count; index++) {
        let vertex = box_polygons[index];
        let separation = face_sign * vertex.position[face_axis] - reference_half[face_axis];
        if separation < margin {
            candidates[count] = contact_point(
                vertex.position - reference_normal * (0.5 * separation),
                separation,
                id_base | vertex.feature,
            );
            count += 1u;
        }
    }
    return count;
}
