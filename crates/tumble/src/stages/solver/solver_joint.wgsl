// Joint rows in the solver: the twins of stages/solver/joint.rs and of the row building of
// stages/constraints/joint.rs (JointConstraint::angular_rows), in the CPU's order of
// operations. The point part is one 3×3 block; the angular rows are rebuilt from the current
// rotations (step-start rotation composed with the delta rotation) each time they are solved.
// Needs solver.wgsl (bodies, joints, BodyPair, bias_terms) and joint_constraint.wgsl.

// AngularRow::kind (RowKind in Rust); zero, the default, is an unused slot.
const ROW_UNUSED: u32 = 0u;
const ROW_EQUALITY: u32 = 1u;
const ROW_LIMIT: u32 = 2u;
const ROW_MOTOR: u32 = 3u;

// One angular row at the current rotations (AngularRow in Rust, RowKind's fields flattened).
struct AngularRow {
    kind: u32,
    // Unit direction, world frame.
    direction: vec3<f32>,
    // Position error (rad) or distance to the limit.
    error: f32,
    target_speed: f32,
    max_impulse: f32,
}

fn angular_row(kind: u32, direction: vec3<f32>, error: f32) -> AngularRow {
    return AngularRow(kind, direction, error, 0.0, 0.0);
}

// A glam Mat3 as WGSL reads it (packed columns) into a mat3x3.
fn packed_mat(m: array<f32, 9>) -> mat3x3<f32> {
    return mat3x3<f32>(vec3<f32>(m[0], m[1], m[2]), vec3<f32>(m[3], m[4], m[5]),
        vec3<f32>(m[6], m[7], m[8]));
}

// glam's Mat3 * Vec3.
fn mat_vec3(m: mat3x3<f32>, v: vec3<f32>) -> vec3<f32> {
    return m[0] * v.x + m[1] * v.y + m[2] * v.z;
}

// glam's Mat3 * Mat3: each column of b through a.
fn mat_mat3(a: mat3x3<f32>, b: mat3x3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(mat_vec3(a, b[0]), mat_vec3(a, b[1]), mat_vec3(a, b[2]));
}

// glam's Vec3::cross.
fn cross3(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}

// skew (constraints/joint.rs): [v]× u = v × u.
fn skew(v: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(vec3<f32>(0.0, v.z, -v.y), vec3<f32>(-v.z, 0.0, v.x),
        vec3<f32>(v.y, -v.x, 0.0));
}

// glam's Mat3::determinant: x · (y × z).
fn determinant3(m: mat3x3<f32>) -> f32 {
    return dot3(m[0], cross3(m[1], m[2]));
}

// glam's Mat3::inverse: the cofactor columns over the determinant, transposed.
fn inverse3(m: mat3x3<f32>) -> mat3x3<f32> {
    let tmp0 = cross3(m[1], m[2]);
    let tmp1 = cross3(m[2], m[0]);
    let tmp2 = cross3(m[0], m[1]);
    let inverse_determinant = 1.0 / dot3(m[0], tmp0);
    return transpose(mat3x3<f32>(tmp0 * inverse_determinant, tmp1 * inverse_determinant,
        tmp2 * inverse_determinant));
}

// glam's Quat::from_rotation_arc: the shortest rotation taking unit `start` onto unit `end`.
fn quat_from_rotation_arc(start: vec3<f32>, end: vec3<f32>) -> vec4<f32> {
    let one_minus_epsilon = 1.0 - 2.0 * 1.1920929e-7;
    let d = dot3(start, end);
    if d > one_minus_epsilon {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    if d < -one_minus_epsilon {
        // Half a turn about any axis ⊥ start (glam's any_orthonormal_vector; its signum(±0)
        // is ±1). Unreachable from twist_angle, whose callers skip opposite axes.
        let sign = select(1.0, -1.0, (bitcast<u32>(start.z) & 0x80000000u) != 0u);
        let a = -1.0 / (sign + start.z);
        let b = start.x * start.y * a;
        // from_axis_angle(axis, π): (axis sin(π/2), cos(π/2)), as f32 rounds them.
        return vec4<f32>(b, sign + start.y * start.y * a, -start.y, cos(1.5707964));
    }
    let q = vec4<f32>(cross3(start, end), 1.0 + d);
    return q * (1.0 / sqrt(dot(q, q)));
}

// Not a NaN nor an infinity (WGSL has no isFinite).
fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

// twist_angle: rotation of B relative to A about the axis (rad, in (−π, π]).
fn twist_angle(f: JointFrame, q_a: vec4<f32>, q_b: vec4<f32>, axis_a: vec3<f32>,
               axis_b: vec3<f32>) -> f32 {
    let reference_a = quat_rotate(q_a, f.local_reference_a);
    let reference_b = quat_rotate(quat_from_rotation_arc(axis_b, axis_a),
        quat_rotate(q_b, f.local_reference_b));
    return atan2(dot3(cross3(reference_a, reference_b), axis_a), dot3(reference_a, reference_b));
}

// twist_limit_rows: the lower and upper twist limit rows, or two unused rows where the twist
// is undefined (the axes opposite). constraints/joint.rs derives the direction and scale.
fn twist_limit_rows(f: JointFrame, q_a: vec4<f32>, q_b: vec4<f32>, axis_a: vec3<f32>,
                    axis_b: vec3<f32>) -> array<AngularRow, 2> {
    var rows: array<AngularRow, 2>;
    let one_plus_cos = 1.0 + dot3(axis_a, axis_b);
    if one_plus_cos < 1e-3 {
        return rows;
    }
    let bisector = axis_a + axis_b;
    let bisector_length = sqrt(dot3(bisector, bisector));
    let direction = bisector / bisector_length;
    let rate = bisector_length / one_plus_cos;
    let angle = twist_angle(f, q_a, q_b, axis_a, axis_b);
    rows[0] = angular_row(ROW_LIMIT, direction, (angle - f.lower) / rate);
    rows[1] = angular_row(ROW_LIMIT, -direction, (f.upper - angle) / rate);
    return rows;
}

// JointConstraint::angular_rows at rotations q_a, q_b.
fn angular_rows(f: JointFrame, q_a: vec4<f32>, q_b: vec4<f32>) -> array<AngularRow, 5> {
    var rows: array<AngularRow, 5>;
    let axis_a = quat_rotate(q_a, f.local_axis_a);
    let axis_b = quat_rotate(q_b, f.local_axis_b);
    switch f.kind {
        case JOINT_FIXED: {
            var rotation_error = quat_mul(q_b, quat_conjugate(quat_mul(q_a,
                f.relative_rotation)));
            if rotation_error.w < 0.0 {
                rotation_error = -rotation_error;
            }
            let angle = 2.0 * rotation_error.xyz;
            rows[0] = angular_row(ROW_EQUALITY, vec3<f32>(1.0, 0.0, 0.0), angle.x);
            rows[1] = angular_row(ROW_EQUALITY, vec3<f32>(0.0, 1.0, 0.0), angle.y);
            rows[2] = angular_row(ROW_EQUALITY, vec3<f32>(0.0, 0.0, 1.0), angle.z);
        }
        case JOINT_HINGE: {
            let basis = tangent_basis(axis_b);
            rows[0] = angular_row(ROW_EQUALITY, cross3(basis[0], axis_a), dot3(axis_a, basis[0]));
            rows[1] = angular_row(ROW_EQUALITY, cross3(basis[1], axis_a), dot3(axis_a, basis[1]));
            // The motor before the limits (constraints/joint.rs says why).
            if (f.flags & HAS_MOTOR) != 0u {
                rows[2] = AngularRow(ROW_MOTOR, axis_a, 0.0, f.target_speed,
                    f.max_torque * params.h);
            }
            if (f.flags & HAS_LIMITS) != 0u {
                let limits = twist_limit_rows(f, q_a, q_b, axis_a, axis_b);
                rows[3] = limits[0];
                rows[4] = limits[1];
            }
        }
        case JOINT_CONE_TWIST: {
            let swing_axis = cross3(axis_a, axis_b);
            let sin_swing = sqrt(dot3(swing_axis, swing_axis));
            if sin_swing > 1e-6 {
                let swing = atan2(sin_swing, dot3(axis_a, axis_b));
                // Swinging further turns B's axis away from A's about a × b.
                rows[0] = angular_row(ROW_LIMIT, -swing_axis / sin_swing, f.swing_limit - swing);
            }
            let limits = twist_limit_rows(f, q_a, q_b, axis_a, axis_b);
            rows[1] = limits[0];
            rows[2] = limits[1];
        }
        default: {
            // JOINT_POINT: the point part alone.
        }
    }
    return rows;
}

// A joint's rotations and world arms at the bodies' current rotations.
struct JointPose {
    q_a: vec4<f32>,
    q_b: vec4<f32>,
    arm_a: vec3<f32>,
    arm_b: vec3<f32>,
}

fn joint_pose(frame: JointFrame, rotation_a: vec4<f32>, rotation_b: vec4<f32>,
              pair: BodyPair) -> JointPose {
    let q_a = quat_mul(pair[0].delta_rotation, rotation_a);
    let q_b = quat_mul(pair[1].delta_rotation, rotation_b);
    return JointPose(q_a, q_b, quat_rotate(q_a, frame.local_anchor_a),
        quat_rotate(q_b, frame.local_anchor_b));
}

// The inverse masses (1/kg) and world inverse inertias of a joint's bodies.
struct JointMasses {
    mass_a: f32,
    mass_b: f32,
    inertia_a: mat3x3<f32>,
    inertia_b: mat3x3<f32>,
}

// The point impulse (+ to B at arm_b, − to A at arm_a).
fn apply_point(masses: JointMasses, pose: JointPose, impulse: vec3<f32>,
               pair: BodyPair) -> BodyPair {
    var out = pair;
    out[0].linear_velocity -= impulse * masses.mass_a;
    out[0].angular_velocity -= mat_vec3(masses.inertia_a, cross3(pose.arm_a, impulse));
    out[1].linear_velocity += impulse * masses.mass_b;
    out[1].angular_velocity += mat_vec3(masses.inertia_b, cross3(pose.arm_b, impulse));
    return out;
}

// An angular impulse along `direction` (+ to B, − to A).
fn apply_angular(masses: JointMasses, direction: vec3<f32>, impulse: f32,
                 pair: BodyPair) -> BodyPair {
    var out = pair;
    out[0].angular_velocity -= mat_vec3(masses.inertia_a, direction) * impulse;
    out[1].angular_velocity += mat_vec3(masses.inertia_b, direction) * impulse;
    return out;
}

// The joint is read through a pointer into `joints` and its rows are handled slot by slot
// with constant indices: a copy indexed by a loop variable is spilled to local memory at
// every access (see the contact functions in solver.wgsl).

fn joint_masses(index: u32) -> JointMasses {
    let j = &joints[index];
    return JointMasses((*j).inverse_mass_a, (*j).inverse_mass_b,
        packed_mat((*j).inverse_inertia_a), packed_mat((*j).inverse_inertia_b));
}

fn warm_start_row(index: u32, slot: u32, row: AngularRow, masses: JointMasses,
                  pair: BodyPair) -> BodyPair {
    if row.kind == ROW_UNUSED {
        return pair;
    }
    return apply_angular(masses, row.direction, joints[index].angular_impulse[slot], pair);
}

fn warm_start_joint(index: u32) {
    let j = &joints[index];
    let pair = warm_start_joint_pair(index,
        BodyPair(load_body((*j).body_a), load_body((*j).body_b)));
    store_body((*j).body_a, pair[0]);
    store_body((*j).body_b, pair[1]);
}

// warm_start_joint on the two bodies `start`, returned moved (see solve_contact_pair).
fn warm_start_joint_pair(index: u32, start: BodyPair) -> BodyPair {
    let j = &joints[index];
    let frame = (*j).frame;
    let masses = joint_masses(index);
    var pair = start;
    let pose = joint_pose(frame, (*j).rotation_a, (*j).rotation_b, pair);
    let rows = angular_rows(frame, pose.q_a, pose.q_b);
    pair = apply_point(masses, pose, (*j).point_impulse, pair);
    pair = warm_start_row(index, 0u, rows[0], masses, pair);
    pair = warm_start_row(index, 1u, rows[1], masses, pair);
    pair = warm_start_row(index, 2u, rows[2], masses, pair);
    pair = warm_start_row(index, 3u, rows[3], masses, pair);
    pair = warm_start_row(index, 4u, rows[4], masses, pair);
    return pair;
}

// One angular row of joint `index`, in slot `slot` (joint.rs solve_joint's row loop).
fn solve_row(index: u32, slot: u32, row: AngularRow, masses: JointMasses,
             pair: BodyPair) -> BodyPair {
    let d = row.direction;
    let k = dot3(d, mat_vec3(masses.inertia_a, d)) + dot3(d, mat_vec3(masses.inertia_b, d));
    if row.kind == ROW_UNUSED || k <= 0.0 {
        return pair;
    }
    let softness = joints[index].softness;
    let mass = 1.0 / k;
    let velocity = dot3(d, pair[1].angular_velocity - pair[0].angular_velocity);
    let accumulated = joints[index].angular_impulse[slot];
    var total: f32;
    if row.kind == ROW_EQUALITY {
        var bias = 0.0;
        var mass_scale = 1.0;
        var impulse_scale = 0.0;
        if params.use_bias != 0u {
            bias = softness.bias_rate * row.error;
            mass_scale = softness.mass_scale;
            impulse_scale = softness.impulse_scale;
        }
        total = accumulated - mass * mass_scale * (velocity + bias) - impulse_scale * accumulated;
    } else if row.kind == ROW_LIMIT {
        let terms = bias_terms(row.error, softness);
        total = max(accumulated - mass * terms.y * (velocity + terms.x) - terms.z * accumulated,
            0.0);
    } else {
        total = clamp(accumulated - mass * (velocity - row.target_speed), -row.max_impulse,
            row.max_impulse);
    }
    joints[index].angular_impulse[slot] = total;
    return apply_angular(masses, d, total - accumulated, pair);
}

fn solve_joint(index: u32) {
    let j = &joints[index];
    let pair = solve_joint_pair(index, BodyPair(load_body((*j).body_a), load_body((*j).body_b)));
    store_body((*j).body_a, pair[0]);
    store_body((*j).body_b, pair[1]);
}

fn solve_joint_pair(index: u32, start: BodyPair) -> BodyPair {
    let j = &joints[index];
    let frame = (*j).frame;
    let masses = joint_masses(index);
    var pair = start;
    let pose = joint_pose(frame, (*j).rotation_a, (*j).rotation_b, pair);
    let rows = angular_rows(frame, pose.q_a, pose.q_b);
    let a = pair[0];
    let b = pair[1];

    // Point part: the anchors move together; the gap between them is removed softly.
    let gap = (b.delta_position - a.delta_position) + (pose.arm_b - pose.arm_a)
        + (*j).center_offset;
    let skew_a = skew(pose.arm_a);
    let skew_b = skew(pose.arm_b);
    let mass_sum = masses.mass_a + masses.mass_b;
    let k = mat3x3<f32>(vec3<f32>(mass_sum, 0.0, 0.0), vec3<f32>(0.0, mass_sum, 0.0),
        vec3<f32>(0.0, 0.0, mass_sum))
        - mat_mat3(mat_mat3(skew_a, masses.inertia_a), skew_a)
        - mat_mat3(mat_mat3(skew_b, masses.inertia_b), skew_b);
    let velocity = b.linear_velocity + cross3(b.angular_velocity, pose.arm_b)
        - a.linear_velocity - cross3(a.angular_velocity, pose.arm_a);
    let softness = (*j).softness;
    var bias = vec3<f32>(0.0);
    var mass_scale = 1.0;
    var impulse_scale = 0.0;
    // A drag stays soft in the relax sweeps too (see solve_joint in joint.rs).
    if params.use_bias != 0u || is_finite((*j).max_point_impulse) {
        bias = gap * softness.bias_rate;
        mass_scale = softness.mass_scale;
        impulse_scale = softness.impulse_scale;
    }
    // f32::MIN_POSITIVE, as on the CPU.
    if abs(determinant3(k)) > 1.17549435e-38 {
        let accumulated = (*j).point_impulse;
        var impulse = -mat_vec3(inverse3(k), velocity + bias) * mass_scale
            - accumulated * impulse_scale;
        let max_impulse = (*j).max_point_impulse;
        if is_finite(max_impulse) {
            // A drag pulls with a bounded force: clamp the accumulated impulse (glam's
            // clamp_length_max).
            var total = accumulated + impulse;
            let length_squared = dot3(total, total);
            if length_squared > max_impulse * max_impulse {
                total = max_impulse * (total / sqrt(length_squared));
            }
            impulse = total - accumulated;
        }
        (*j).point_impulse = accumulated + impulse;
        pair = apply_point(masses, pose, impulse, pair);
    }

    pair = solve_row(index, 0u, rows[0], masses, pair);
    pair = solve_row(index, 1u, rows[1], masses, pair);
    pair = solve_row(index, 2u, rows[2], masses, pair);
    pair = solve_row(index, 3u, rows[3], masses, pair);
    pair = solve_row(index, 4u, rows[4], masses, pair);
    return pair;
}
