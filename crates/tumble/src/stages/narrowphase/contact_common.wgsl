// What every pair function of the GPU narrowphase shares: the manifold being built, the
// candidate points, float helpers that compute in the CPU's order, closest points on
// segments (collision/contact/segment.rs) and manifold reduction (collision/manifold.rs).
//
// The CPU code uses glam; where a decision (an axis, a clip side, a feature id) hangs on a
// comparison, the GPU must compute its operands the same way to agree near ties. So dot
// products, matrix products and quaternion rotations are spelled out here in glam's operation
// order rather than left to the builtins, whose order is the driver's. WGSL still allows a
// driver to fuse a * b + c into one rounding (FMA); on exact inputs (axis-aligned boxes, unit
// quaternions of right angles) fusing changes nothing, elsewhere it moves results by an ulp or
// two, which the parity tests' tolerance covers and which only matters at an exact tie.
//
// Constants (COINCIDENT_DISTANCE_SQUARED and the others) come from Rust: `contact::wgsl_constants`.

// The manifold of the pair this thread works on: reset by `collide`, filled by the pair
// functions (normal from B to A, as on the CPU).
var<private> out: Manifold;

// Candidate points before reduction: 8 box vertices, 8 clipped box vertices, or the clipped
// incident face of a hull pair (contact_hull.wgsl), of at most 2 * MAX_HULL_FACE_VERTICES;
// MAX_CANDIDATES (from Rust) is the most of the world's shape kinds.
var<private> candidates: array<ContactPoint, MAX_CANDIDATES>;

fn element_sum(v: vec3<f32>) -> f32 {
    return v.x + v.y + v.z;
}


// Transform::inverse_transform_point.
fn to_local(pose: BodyPose, point: vec3<f32>) -> vec3<f32> {
    return quat_rotate(quat_conjugate(pose.rotation), point - pose.position);
}

// glam's Mat3 * Vec3: the columns weighted by v, summed x, y, z.
fn mat_vec(m: mat3x3<f32>, v: vec3<f32>) -> vec3<f32> {
    return m[0] * v.x + m[1] * v.y + m[2] * v.z;
}

fn mat_mat(a: mat3x3<f32>, b: mat3x3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(mat_vec(a, b[0]), mat_vec(a, b[1]), mat_vec(a, b[2]));
}

fn axis_vector(axis: u32) -> vec3<f32> {
    var v = vec3<f32>(0.0);
    v[axis] = 1.0;
    return v;
}

// 1 for x >= 0 (zero included, so a centred body still picks a side), else -1.
fn sign_or_positive(x: f32) -> f32 {
    return select(-1.0, 1.0, x >= 0.0);
}

// See `clearly_greater` in collision/contact/mod.rs.
fn clearly_greater(candidate: f32, preferred: f32, relative_tolerance: f32) -> bool {
    return candidate > preferred + relative_tolerance * abs(preferred) + ABSOLUTE_TOLERANCE;
}

// Index of the largest component; the lower index on ties.
fn largest_component(v: vec3<f32>) -> u32 {
    var index = 0u;
    for (var axis = 1u; axis < 3u; axis++) {
        if v[axis] > v[index] {
            index = axis;
        }
    }
    return index;
}

fn contact_point(position: vec3<f32>, separation: f32, id: u32) -> ContactPoint {
    return ContactPoint(position, separation, vec3<f32>(0.0), id);
}

fn push_point(point: ContactPoint) {
    out.points[out.count] = point;
    out.count += 1u;
}

// The point whose surface point on A is `surface_a`; B's surface lies `separation` behind it
// along `normal`, so the midpoint is half that back.
fn push_contact(surface_a: vec3<f32>, normal: vec3<f32>, separation: f32, id: u32) {
    push_point(contact_point(surface_a - normal * (0.5 * separation), separation, id));
}

// The first `count` candidates into `out` with `normal`: all when they fit, else reduced.
fn emit_candidates(count: u32, normal: vec3<f32>) {
    out.normal = normal;
    if count > MAX_MANIFOLD_POINTS {
        reduce(count, normal);
        return;
    }
    for (var index = 0u; index < count; index++) {
        push_point(candidates[index]);
    }
}

// collision/manifold.rs `reduce` for count > 4: deepest, farthest from it, widest triangle,
// largest quadrilateral, measured in the contact plane; ties (equal depths, scores within
// REDUCE_TIE_RELATIVE, which absorbs rounding differences) to the lower index.
fn reduce(count: u32, normal: vec3<f32>) {
    var deepest = 0u;
    for (var index = 0u; index < count; index++) {
        if candidates[index].separation < candidates[deepest].separation {
            deepest = index;
        }
    }
    let first = candidates[deepest].position;

    var farthest = 0xffffffffu;
    var best = 0.0;
    for (var index = 0u; index < count; index++) {
        if index == deepest {
            continue;
        }
        let offset = candidates[index].position - first;
        let along_normal = dot3(offset, normal);
        let score = dot3(offset, offset) - along_normal * along_normal;
        if farthest == 0xffffffffu || beats(score, best) {
            farthest = index;
            best = score;
        }
    }
    let second = candidates[farthest].position;

    var widest = 0xffffffffu;
    for (var index = 0u; index < count; index++) {
        if index == deepest || index == farthest {
            continue;
        }
        let score = abs(triangle_area(first, second, candidates[index].position, normal));
        if widest == 0xffffffffu || beats(score, best) {
            widest = index;
            best = score;
        }
    }
    let third = candidates[widest].position;

    let winding = select(-1.0, 1.0, triangle_area(first, second, third, normal) >= 0.0);
    var fourth = 0xffffffffu;
    for (var index = 0u; index < count; index++) {
        if index == deepest || index == farthest || index == widest {
            continue;
        }
        let p = candidates[index].position;
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

    out.count = 0u;
    push_point(candidates[deepest]);
    push_point(candidates[farthest]);
    push_point(candidates[widest]);
    push_point(candidates[fourth]);
}

// A score of `reduce` clearly above the best so far.
fn beats(score: f32, best: f32) -> bool {
    return score > best + REDUCE_TIE_RELATIVE * abs(best);
}

// Twice the area of triangle (first, second, p) projected on the contact plane, signed.
fn triangle_area(first: vec3<f32>, second: vec3<f32>, p: vec3<f32>, normal: vec3<f32>) -> f32 {
    return dot3(cross(second - first, p - first), normal);
}

fn quadrilateral_area(
    p0: vec3<f32>,
    p1: vec3<f32>,
    p2: vec3<f32>,
    p3: vec3<f32>,
    normal: vec3<f32>,
    winding: f32,
) -> f32 {
    return winding * dot3(cross(p2 - p0, p3 - p1), normal);
}

// collision/contact/segment.rs: parameter of the point of start + t delta closest to `point`.
fn closest_parameter_to_point(point: vec3<f32>, start: vec3<f32>, delta: vec3<f32>) -> f32 {
    let length_squared = dot3(delta, delta);
    if length_squared <= DEGENERATE_LENGTH_SQUARED {
        return 0.0;
    }
    return clamp(dot3(point - start, delta) / length_squared, 0.0, 1.0);
}

// collision/contact/segment.rs: parameters (s, t) of the closest points of two segments.
fn closest_parameters_between_segments(
    start_a: vec3<f32>,
    delta_a: vec3<f32>,
    start_b: vec3<f32>,
    delta_b: vec3<f32>,
) -> vec2<f32> {
    let length_a_squared = dot3(delta_a, delta_a);
    let length_b_squared = dot3(delta_b, delta_b);
    let start_offset = start_a - start_b;
    let along_b = dot3(delta_b, start_offset);
    if length_a_squared <= DEGENERATE_LENGTH_SQUARED {
        if length_b_squared <= DEGENERATE_LENGTH_SQUARED {
            return vec2<f32>(0.0);
        }
        return vec2<f32>(0.0, clamp(along_b / length_b_squared, 0.0, 1.0));
    }
    let along_a = dot3(delta_a, start_offset);
    if length_b_squared <= DEGENERATE_LENGTH_SQUARED {
        return vec2<f32>(clamp(-along_a / length_a_squared, 0.0, 1.0), 0.0);
    }
    let cosine_term = dot3(delta_a, delta_b);
    let determinant = length_a_squared * length_b_squared - cosine_term * cosine_term;
    var s = 0.0;
    if determinant > SEGMENT_PARALLEL_SINE_SQUARED * length_a_squared * length_b_squared {
        s = clamp((cosine_term * along_b - along_a * length_b_squared) / determinant, 0.0, 1.0);
    }
    var t = (cosine_term * s + along_b) / length_b_squared;
    if t < 0.0 {
        t = 0.0;
        s = clamp(-along_a / length_a_squared, 0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = clamp((cosine_term - along_a) / length_a_squared, 0.0, 1.0);
    }
    return vec2<f32>(s, t);
}
