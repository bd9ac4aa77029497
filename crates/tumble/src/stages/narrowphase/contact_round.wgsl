// Pairs with a sphere, a capsule or a plane: the twins of collision/contact/sphere.rs,
// capsule.rs and plane.rs (box–plane included), line for line in the same order.
// A shape's parameters are ColliderData.params: sphere (radius), capsule (radius,
// half_height), cuboid (half extents), plane (unit normal, offset).

// Ball A against ball B (world space); `fallback_normal` when the centres coincide.
fn ball_ball(
    center_a: vec3<f32>,
    radius_a: f32,
    center_b: vec3<f32>,
    radius_b: f32,
    fallback_normal: vec3<f32>,
    margin: f32,
) {
    let offset = center_a - center_b;
    let distance_squared = dot3(offset, offset);
    let radii = radius_a + radius_b;
    let reach = radii + margin;
    if distance_squared >= reach * reach {
        return;
    }
    var normal = fallback_normal;
    var distance = 0.0;
    if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        distance = sqrt(distance_squared);
        normal = offset / distance;
    }
    out.normal = normal;
    push_contact(center_a - normal * radius_a, normal, distance - radii, 0u);
}

fn sphere_sphere(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    // Concentric spheres have no preferred direction: push along world up.
    ball_ball(pose_a.position, a.x, pose_b.position, b.x, vec3<f32>(0.0, 1.0, 0.0), margin);
}

fn sphere_capsule(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let half_axis = quat_rotate(pose_b.rotation, vec3<f32>(0.0, b.y, 0.0));
    let start = pose_b.position - half_axis;
    let delta = 2.0 * half_axis;
    let t = closest_parameter_to_point(pose_a.position, start, delta);
    // A centre on the capsule's axis: sideways along the capsule's local x.
    let fallback_normal = quat_rotate(pose_b.rotation, vec3<f32>(1.0, 0.0, 0.0));
    ball_ball(pose_a.position, a.x, start + delta * t, b.x, fallback_normal, margin);
}

fn sphere_box(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let radius = a.x;
    let half = b.xyz;
    let center = to_local(pose_b, pose_a.position);
    let box_point = clamp(center, -half, half);
    let offset = center - box_point;
    let distance_squared = dot3(offset, offset);
    var normal_local: vec3<f32>;
    var separation: f32;
    if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        let reach = radius + margin;
        if distance_squared >= reach * reach {
            return;
        }
        let distance = sqrt(distance_squared);
        normal_local = offset / distance;
        separation = distance - radius;
    } else {
        // Inside the box: out through the face of least penetration.
        let depth = half - abs(center);
        var axis = 0u;
        for (var candidate = 1u; candidate < 3u; candidate++) {
            if depth[candidate] < depth[axis] {
                axis = candidate;
            }
        }
        separation = -depth[axis] - radius;
        if separation >= margin {
            return;
        }
        normal_local = sign_or_positive(center[axis]) * axis_vector(axis);
    }
    let normal = quat_rotate(pose_b.rotation, normal_local);
    out.normal = normal;
    push_contact(pose_a.position - normal * radius, normal, separation, 0u);
}

// The plane in world space: (unit normal, offset), solid where normal · x <= offset.
fn world_plane(plane: vec4<f32>, pose: BodyPose) -> vec4<f32> {
    let normal = quat_rotate(pose.rotation, plane.xyz);
    return vec4<f32>(normal, plane.w + dot3(normal, pose.position));
}

fn sphere_plane(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let plane = world_plane(b, pose_b);
    let normal = plane.xyz;
    let separation = dot3(normal, pose_a.position) - plane.w - a.x;
    if separation >= margin {
        return;
    }
    out.normal = normal;
    push_contact(pose_a.position - normal * a.x, normal, separation, 0u);
}

// One point per segment end (ids 0 and 1), one for a capsule with no straight part.
fn capsule_plane(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let plane = world_plane(b, pose_b);
    let normal = plane.xyz;
    out.normal = normal;
    let half_axis = quat_rotate(pose_a.rotation, vec3<f32>(0.0, a.y, 0.0));
    let end_count = select(2u, 1u, a.y <= POINT_SEGMENT_HALF_HEIGHT);
    let ends = array<vec3<f32>, 2>(pose_a.position - half_axis, pose_a.position + half_axis);
    for (var id = 0u; id < end_count; id++) {
        let separation = dot3(normal, ends[id]) - plane.w - a.x;
        if separation < margin {
            push_contact(ends[id] - normal * a.x, normal, separation, id);
        }
    }
}

// Signs of box vertex `index` along the local axes: bit 0, 1, 2 set → + side of x, y, z.
fn vertex_signs(index: u32) -> vec3<f32> {
    let bits = vec3<u32>(index) & vec3<u32>(1u, 2u, 4u);
    return select(vec3<f32>(-1.0), vec3<f32>(1.0), bits != vec3<u32>(0u));
}

// Every vertex below the margin is a candidate, id the vertex index; more than four reduced.
fn box_plane(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let plane = world_plane(b, pose_b);
    let normal = plane.xyz;
    let half = a.xyz;
    let rotation = mat3_from_quat(pose_a.rotation);
    let reach = mat_vec(transpose(rotation), normal) * half;
    let center_height = dot3(normal, pose_a.position) - plane.w;
    if center_height - element_sum(abs(reach)) >= margin {
        return;
    }
    var count = 0u;
    for (var index = 0u; index < 8u; index++) {
        let signs = vertex_signs(index);
        let separation = center_height + element_sum(signs * reach);
        if separation < margin {
            let vertex = pose_a.position + mat_vec(rotation, signs * half);
            let position = vertex - normal * (0.5 * separation);
            candidates[count] = contact_point(position, separation, index);
            count += 1u;
        }
    }
    emit_candidates(count, normal);
}

fn capsule_capsule(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let half_axis_a = quat_rotate(pose_a.rotation, vec3<f32>(0.0, a.y, 0.0));
    let start_a = pose_a.position - half_axis_a;
    let delta_a = 2.0 * half_axis_a;
    let half_axis_b = quat_rotate(pose_b.rotation, vec3<f32>(0.0, b.y, 0.0));
    let start_b = pose_b.position - half_axis_b;
    let delta_b = 2.0 * half_axis_b;
    let st = closest_parameters_between_segments(start_a, delta_a, start_b, delta_b);
    let closest_a = start_a + delta_a * st.x;
    let closest_b = start_b + delta_b * st.y;
    let radii = a.x + b.x;
    let offset = closest_a - closest_b;
    let distance_squared = dot3(offset, offset);
    let reach = radii + margin;
    if distance_squared >= reach * reach {
        return;
    }
    let axes_cross = cross(delta_a, delta_b);
    let length_a_squared = dot3(delta_a, delta_a);
    let length_b_squared = dot3(delta_b, delta_b);
    let cross_length_squared = dot3(axes_cross, axes_cross);
    var normal: vec3<f32>;
    if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        normal = offset / sqrt(distance_squared);
    } else if cross_length_squared
        > PARALLEL_SINE_SQUARED * length_a_squared * length_b_squared
            + COINCIDENT_DISTANCE_SQUARED {
        // Crossing axes: along their common normal, towards A.
        let across = axes_cross / sqrt(cross_length_squared);
        normal = across * sign_or_positive(dot3(across, pose_a.position - pose_b.position));
    } else if b.y > POINT_SEGMENT_HALF_HEIGHT {
        normal = quat_rotate(pose_b.rotation, vec3<f32>(1.0, 0.0, 0.0));
    } else {
        normal = quat_rotate(pose_a.rotation, vec3<f32>(1.0, 0.0, 0.0));
    }

    // Parallel capsules lying along each other: two points, the ends of the overlap.
    let parallel = a.y > POINT_SEGMENT_HALF_HEIGHT && b.y > POINT_SEGMENT_HALF_HEIGHT
        && cross_length_squared
            <= PARALLEL_CAPSULES_SINE_SQUARED * length_a_squared * length_b_squared;
    if parallel {
        let end_b_0 = dot3(start_b - start_a, delta_a) / length_a_squared;
        let end_b_1 = dot3(start_b + delta_b - start_a, delta_a) / length_a_squared;
        let low = max(min(end_b_0, end_b_1), 0.0);
        let high = min(max(end_b_0, end_b_1), 1.0);
        if (high - low) * sqrt(length_a_squared) > MINIMUM_OVERLAP {
            out.normal = normal;
            let parameters = array<f32, 2>(low, high);
            for (var id = 0u; id < 2u; id++) {
                let point_a = start_a + delta_a * parameters[id];
                let point_b = start_b
                    + delta_b * closest_parameter_to_point(point_a, start_b, delta_b);
                let separation = dot3(point_a - point_b, normal) - radii;
                if separation < margin {
                    push_contact(point_a - normal * a.x, normal, separation, id);
                }
            }
            return;
        }
    }
    out.normal = normal;
    push_contact(closest_a - normal * a.x, normal, dot3(offset, normal) - radii, 0u);
}

fn capsule_box(a: vec4<f32>, pose_a: BodyPose, b: vec4<f32>, pose_b: BodyPose, margin: f32) {
    let radius = a.x;
    if a.y <= POINT_SEGMENT_HALF_HEIGHT {
        sphere_box(a, pose_a, b, pose_b, margin);
        return;
    }
    let half = b.xyz;
    let center = to_local(pose_b, pose_a.position);
    let half_axis = quat_rotate(
        quat_conjugate(pose_b.rotation),
        quat_rotate(pose_a.rotation, vec3<f32>(0.0, a.y, 0.0)),
    );
    let start = center - half_axis;
    let delta = 2.0 * half_axis;
    let t = closest_parameter_segment_box(start, delta, half);
    let point = start + delta * t;
    let box_point = clamp(point, -half, half);
    let offset = point - box_point;
    let distance_squared = dot3(offset, offset);
    let reach = radius + margin;
    if distance_squared >= reach * reach {
        return;
    }
    if distance_squared > COINCIDENT_DISTANCE_SQUARED {
        let outside = abs(point) > half;
        if u32(outside.x) + u32(outside.y) + u32(outside.z) == 1u {
            // Over one face: the part of the segment over it rests on it.
            let axis = select(select(2u, 1u, outside.y), 0u, outside.x);
            let face_sign = sign_or_positive(point[axis]);
            capsule_on_face(start, delta, radius, half, axis, face_sign, t, margin, pose_b);
        } else {
            // Beside an edge or a corner: one point.
            let distance = sqrt(distance_squared);
            let normal_local = offset / distance;
            let normal = quat_rotate(pose_b.rotation, normal_local);
            out.normal = normal;
            let surface_a = pose_b.position
                + quat_rotate(pose_b.rotation, point - normal_local * radius);
            push_contact(surface_a, normal, distance - radius, 0u);
        }
        return;
    }
    capsule_in_box(start, delta, t, radius, half, margin, pose_b);
}

// The segment reaches into the box: least penetration over the box's faces and the edge
// axes (segment × box axis), faces preferred.
fn capsule_in_box(
    start: vec3<f32>,
    delta: vec3<f32>,
    parameter: f32,
    radius: f32,
    half: vec3<f32>,
    margin: f32,
    pose_b: BodyPose,
) {
    let center = start + 0.5 * delta;
    let half_delta = 0.5 * delta;
    let face_separations = abs(center) - abs(half_delta) - half;
    var face_axis = 0u;
    for (var axis = 1u; axis < 3u; axis++) {
        if face_separations[axis] > face_separations[face_axis] {
            face_axis = axis;
        }
    }
    let face_separation = face_separations[face_axis];

    var edge_found = false;
    var edge_normal = vec3<f32>(0.0);
    var edge_separation = 0.0;
    var edge_axis = 0u;
    let length_squared = dot3(delta, delta);
    for (var box_axis = 0u; box_axis < 3u; box_axis++) {
        var axis = cross(delta, axis_vector(box_axis));
        let axis_length_squared = dot3(axis, axis);
        if axis_length_squared <= PARALLEL_SINE_SQUARED * length_squared {
            continue;
        }
        axis = axis / sqrt(axis_length_squared);
        let along = dot3(center, axis);
        let separation = abs(along) - element_sum(half * abs(axis));
        if !edge_found || separation > edge_separation {
            edge_found = true;
            edge_normal = axis * sign_or_positive(along);
            edge_separation = separation;
            edge_axis = box_axis;
        }
    }

    if edge_found && clearly_greater(edge_separation, face_separation, EDGE_RELATIVE_TOLERANCE) {
        if edge_separation - radius >= margin {
            return;
        }
        var edge_start = vec3<f32>(0.0);
        for (var axis = 0u; axis < 3u; axis++) {
            edge_start[axis] = sign_or_positive(edge_normal[axis]) * half[axis];
        }
        edge_start[edge_axis] = -half[edge_axis];
        let edge_delta = 2.0 * half[edge_axis] * axis_vector(edge_axis);
        let st = closest_parameters_between_segments(start, delta, edge_start, edge_delta);
        let point = start + delta * st.x;
        let separation = dot3(point - (edge_start + edge_delta * st.y), edge_normal) - radius;
        let normal = quat_rotate(pose_b.rotation, edge_normal);
        out.normal = normal;
        let surface_a = pose_b.position + quat_rotate(pose_b.rotation, point - edge_normal * radius);
        push_contact(surface_a, normal, separation, 0u);
        return;
    }
    if face_separation - radius >= margin {
        return;
    }
    let face_sign = sign_or_positive(center[face_axis]);
    capsule_on_face(start, delta, radius, half, face_axis, face_sign, parameter, margin, pose_b);
}

// The part of the segment over box face (axis, sign): its two ends (ids 0, 1), or the point
// at `fallback_parameter` when no part of it is over the face.
fn capsule_on_face(
    start: vec3<f32>,
    delta: vec3<f32>,
    radius: f32,
    half: vec3<f32>,
    face_axis: u32,
    face_sign: f32,
    fallback_parameter: f32,
    margin: f32,
    pose_b: BodyPose,
) {
    var low = 0.0;
    var high = 1.0;
    let sides = array<u32, 2>((face_axis + 1u) % 3u, (face_axis + 2u) % 3u);
    for (var side = 0u; side < 2u; side++) {
        let axis = sides[side];
        if delta[axis] != 0.0 {
            let enter = (-half[axis] - start[axis]) / delta[axis];
            let leave = (half[axis] - start[axis]) / delta[axis];
            low = max(low, min(enter, leave));
            high = min(high, max(enter, leave));
        }
    }
    if low > high {
        low = fallback_parameter;
        high = fallback_parameter;
    }
    let normal_local = face_sign * axis_vector(face_axis);
    let normal = quat_rotate(pose_b.rotation, normal_local);
    out.normal = normal;
    let parameters = array<f32, 2>(low, high);
    let count = select(1u, 2u, high > low);
    for (var id = 0u; id < count; id++) {
        let point = start + delta * parameters[id];
        let separation = face_sign * point[face_axis] - half[face_axis] - radius;
        if separation < margin {
            let surface_a = pose_b.position
                + quat_rotate(pose_b.rotation, point - normal_local * radius);
            push_contact(surface_a, normal, separation, id);
        }
    }
}

// Parameter of the segment point closest to the box (half extents `half`, at the origin):
// the squared distance is a convex quadratic on each piece between the face-plane crossings.
fn closest_parameter_segment_box(start: vec3<f32>, delta: vec3<f32>, half: vec3<f32>) -> f32 {
    var breaks: array<f32, 8>;
    breaks[0] = 0.0;
    var count = 1u;
    for (var axis = 0u; axis < 3u; axis++) {
        if delta[axis] == 0.0 {
            continue;
        }
        let planes = array<f32, 2>(-half[axis], half[axis]);
        for (var side = 0u; side < 2u; side++) {
            let t = (planes[side] - start[axis]) / delta[axis];
            if t > 0.0 && t < 1.0 {
                breaks[count] = t;
                count += 1u;
            }
        }
    }
    breaks[count] = 1.0;
    count += 1u;
    // Ascending, as the CPU sorts them: each value goes to its rank (equal values by index).
    // Not an in-place sort: llvmpipe's GL compiler miscompiled an insertion sort of this local
    // array (a shifted element was written where the saved one belonged).
    var sorted: array<f32, 8>;
    for (var index = 0u; index < count; index++) {
        var rank = 0u;
        for (var other = 0u; other < count; other++) {
            if breaks[other] < breaks[index] || (breaks[other] == breaks[index] && other < index) {
                rank += 1u;
            }
        }
        sorted[rank] = breaks[index];
    }

    var best = 0.0;
    var best_distance_squared = segment_box_distance_squared(start, delta, half, 0.0);
    for (var piece = 0u; piece + 1u < count; piece++) {
        let low = sorted[piece];
        let high = sorted[piece + 1u];
        let middle = start + delta * (0.5 * (low + high));
        var offset_times_slope = 0.0;
        var slope_squared = 0.0;
        for (var axis = 0u; axis < 3u; axis++) {
            var offset: f32;
            var slope: f32;
            if middle[axis] > half[axis] {
                offset = start[axis] - half[axis];
                slope = delta[axis];
            } else if middle[axis] < -half[axis] {
                offset = -start[axis] - half[axis];
                slope = -delta[axis];
            } else {
                continue;
            }
            offset_times_slope += offset * slope;
            slope_squared += slope * slope;
        }
        var t = low;
        if slope_squared > 0.0 {
            t = clamp(-offset_times_slope / slope_squared, low, high);
        }
        let candidate = segment_box_distance_squared(start, delta, half, t);
        if candidate < best_distance_squared {
            best = t;
            best_distance_squared = candidate;
        }
    }
    return best;
}

fn segment_box_distance_squared(
    start: vec3<f32>,
    delta: vec3<f32>,
    half: vec3<f32>,
    t: f32,
) -> f32 {
    let point = start + delta * t;
    let offset = point - clamp(point, -half, half);
    return dot3(offset, offset);
}
