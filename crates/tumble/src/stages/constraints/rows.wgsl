// Contact rows on the GPU: the twin of build_constraints in contact.rs (read its docs for the
// formulas). One thread per manifold slot (pairs, then children): `flag` marks the slots
// that get a constraint, an exclusive scan of the flags gives each one its place (the CPU's
// order), and `build` writes it there, in blocks of lanes (lanes.wgsl). The threads cover the
// slots' buffers (`slots`), which change size only when they grow, and the live slots are
// counted on the device (`count`): the dispatches stay the same from step to step while the
// pairs come and go.

// Softness as (bias_rate, mass_scale, impulse_scale, unused): a struct member of a uniform
// block would be padded to 16 bytes anyway.
struct RowParams {
    softness: vec4<f32>,
    static_softness: vec4<f32>,
    // Slots the dispatches cover, at least the live ones.
    slots: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: RowParams;
// Per slot: the pair key (body a in the high word, b in the low) and its manifold.
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> contacts: array<PairContact>;
@group(0) @binding(3) var<storage, read> masses: array<BodyMass>;
// `flag`: 1 where a slot gets a constraint (slots + 1 entries, 0 past the live slots). `build`:
// their exclusive scan, so entry `slots` is the number of constraints.
@group(0) @binding(4) var<storage, read_write> places: array<u32>;
@group(0) @binding(5) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(6) var<storage, read> velocities: array<BodyVelocity>;
@group(0) @binding(7) var<storage, read> colliders: array<ColliderData>;
// The constraints in blocks of lanes (lanes.wgsl), a vec4 a word.
@group(0) @binding(8) var<storage, read_write> constraints: array<vec4<f32>>;
// Per constraint: its bodies as the constraint has them, for a batching on the device.
@group(0) @binding(9) var<storage, read_write> row_bodies: array<vec2<u32>>;
// Word 0: the live slots.
@group(0) @binding(10) var<storage, read> count: array<u32>;

fn slot_index(id: vec3<u32>, workgroup: vec3<u32>, groups: vec3<u32>) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + id.x;
}

// Keys are u64 little-endian: word 0 is the low half (body b), word 1 the high (body a).
fn slot_bodies(slot: u32) -> vec2<u32> {
    let key = keys[slot];
    return vec2<u32>(key.y, key.x);
}

// A manifold with points where at least one body moves (a sleeping body has no mass).
fn has_constraint(slot: u32) -> bool {
    let bodies = slot_bodies(slot);
    let resting = masses[bodies.x].inverse_mass == 0.0 && masses[bodies.y].inverse_mass == 0.0;
    return contacts[slot].manifold.count > 0u && !resting;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn flag(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let slot = slot_index(id, workgroup, groups);
    if slot <= params.slots {
        places[slot] = select(0u, 1u, slot < count[0] && has_constraint(slot));
    }
}

// R diag(inverse_inertia) Rᵀ: the world-frame inverse inertia (zero for static bodies), by
// its upper triangle (SymmetricMat3::from_upper).
fn world_inverse_inertia(body: u32) -> SymmetricMat3 {
    let r = mat3_from_quat(poses[body].rotation);
    let d = masses[body].inverse_inertia;
    let scaled = mat3x3<f32>(r[0] * d.x, r[1] * d.y, r[2] * d.z);
    let m = scaled * transpose(r);
    return SymmetricMat3(vec3<f32>(m[0].x, m[1].y, m[2].z), vec3<f32>(m[1].x, m[2].x, m[2].y));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn build(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let slot = slot_index(id, workgroup, groups);
    if slot >= count[0] || !has_constraint(slot) {
        return;
    }
    let bodies = slot_bodies(slot);
    let a = bodies.x;
    let b = bodies.y;
    // Through pointers, a point at a time: a copy of the whole contact indexed by the loop
    // variable would be spilled to local memory at every index (see solver.wgsl).
    let contact = &contacts[slot];
    let mass_a = masses[a].inverse_mass;
    let mass_b = masses[b].inverse_mass;
    let normal = (*contact).manifold.normal;
    let tangents = tangent_basis(normal);
    let body_a = select(STATIC_BODY, a, mass_a > 0.0);
    let body_b = select(STATIC_BODY, b, mass_b > 0.0);
    let point_count = (*contact).manifold.count;
    var softness = params.softness;
    if mass_a == 0.0 || mass_b == 0.0 {
        softness = params.static_softness;
    }
    // The header, word by word (ContactConstraint's fields in order, see lanes.wgsl).
    let place = places[slot];
    row_bodies[place] = vec2<u32>(body_a, body_b);
    constraints[lane_word(place, HEADER_IDS)] =
        bitcast<vec4<f32>>(vec4<u32>(body_a, body_b, slot, point_count));
    constraints[lane_word(place, HEADER_NORMAL)] =
        vec4<f32>(normal, sqrt(colliders[a].friction * colliders[b].friction));
    constraints[lane_word(place, HEADER_TANGENT1)] =
        vec4<f32>(tangents[0], max(colliders[a].restitution, colliders[b].restitution));
    constraints[lane_word(place, HEADER_TANGENT2)] = vec4<f32>(tangents[1], mass_a);
    constraints[lane_word(place, HEADER_MASSES)] = vec4<f32>(mass_b, softness.xyz);
    let center_a = poses[a].position;
    let center_b = poses[b].position;
    let inertias = array<SymmetricMat3, 2>(world_inverse_inertia(a), world_inverse_inertia(b));
    // Word by word, not in a loop: an array indexed by a loop variable goes to local memory.
    let inertia = inertia_words(inertias[0], inertias[1]);
    constraints[lane_word(place, HEADER_INERTIA)] = inertia[0];
    constraints[lane_word(place, HEADER_INERTIA + 1u)] = inertia[1];
    constraints[lane_word(place, HEADER_INERTIA + 2u)] = inertia[2];
    let va = velocities[a];
    let vb = velocities[b];
    // What the warm start applies, for the warm start by body (lanes.wgsl).
    var sums = ImpulseSums();
    // The points up to the count. No kernel uses a point's words past it (the Jacobi sweep
    // reads all four impulse words, and uses the count's), so they are not written (zeroing
    // them was about half the stores of a pile's build); the host's read-back zeroes them
    // (lanes.rs).
    for (var i = 0u; i < min(point_count, MAX_MANIFOLD_POINTS); i++) {
        let point = (*contact).manifold.points[i];
        let warm = (*contact).impulses[i];
        let r_a = point.position - center_a;
        let r_b = point.position - center_b;
        let masses_ab = mass_a + mass_b;
        let n = row_mass(normal, r_a, r_b, inertias, masses_ab);
        let t1 = row_mass(tangents[0], r_a, r_b, inertias, masses_ab);
        let t2 = row_mass(tangents[1], r_a, r_b, inertias, masses_ab);
        let approach = dot3(normal, va.linear - vb.linear)
            + dot3(cross(r_a, normal), va.angular) - dot3(cross(r_b, normal), vb.angular);
        let adjusted_separation = point.separation - dot3(normal, r_a - r_b);
        // The point's words (lanes.wgsl); the largest normal impulse so far is none.
        constraints[point_word(place, i, POINT_ANCHOR_A)] = vec4<f32>(r_a, adjusted_separation);
        constraints[point_word(place, i, POINT_ANCHOR_B)] = vec4<f32>(r_b, point.separation);
        constraints[point_word(place, i, POINT_MASSES)] =
            vec4<f32>(n, t1, t2, approach);
        constraints[point_word(place, i, POINT_IMPULSES)] =
            vec4<f32>(warm.normal, warm.tangent[0], warm.tangent[1], 0.0);
        sums = add_row(sums, normal, cross(r_a, normal), cross(r_b, normal), inertias,
            warm.normal);
        sums = add_row(sums, tangents[0], cross(r_a, tangents[0]), cross(r_b, tangents[0]),
            inertias, warm.tangent[0]);
        sums = add_row(sums, tangents[1], cross(r_a, tangents[1]), cross(r_b, tangents[1]),
            inertias, warm.tangent[1]);
    }
    let sum_words = sums_words(sums, mass_a, mass_b);
    constraints[lane_word(place, SUMS_WORD)] = sum_words[0];
    constraints[lane_word(place, SUMS_WORD + 1u)] = sum_words[1];
    constraints[lane_word(place, SUMS_WORD + 2u)] = sum_words[2];
}
