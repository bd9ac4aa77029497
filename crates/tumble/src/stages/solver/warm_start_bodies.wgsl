// The warm start gathered by body (the GPU solver's, not the Jacobi solver's: their extra
// bindings differ): `warm_start_bodies` runs the gravity step and every warm start of a
// sub-step in one dispatch, over each body's constraints in batch order (adjacency.wgsl).
// Needs solver.wgsl.

// Body b's constraints: adjacency_entries[adjacency_starts[b] .. adjacency_starts[b + 1]],
// each 2 × (batch place) + side.
@group(0) @binding(6) var<storage, read> adjacency_starts: array<u32>;
@group(0) @binding(7) var<storage, read> adjacency_entries: array<u32>;

// What the warm start of one side of a point reads: I⁻¹(r × d) of that side's body for each row
// (normal, tangents) and the point's impulses (lanes.wgsl): four words of the point's nine.
struct SidePoint {
    normal: vec3<f32>,
    tangent1: vec3<f32>,
    tangent2: vec3<f32>,
    impulses: vec4<f32>,
}

// Point `k` of constraint `index` as side `side` (0: A, 1: B) sees it; nothing past its count.
fn load_side_point(index: u32, k: u32, count: u32, side: u32) -> SidePoint {
    if k >= count {
        return SidePoint(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec4<f32>(0.0));
    }
    return SidePoint(contacts[point_word(index, k, side)].xyz,
        contacts[point_word(index, k, 2u + side)].xyz,
        contacts[point_word(index, k, 4u + side)].xyz,
        contacts[point_word(index, k, POINT_IMPULSES)]);
}

// `apply` for one side of a row, `angular` that side's I⁻¹(r × d) (0: A, 1: B): the same
// operations.
fn apply_side(angular: vec3<f32>, direction: vec3<f32>, impulse: f32, mass: f32, side: u32,
              body: SolverBody) -> SolverBody {
    var out = body;
    if side == 0u {
        out.linear_velocity += direction * (impulse * mass);
        out.angular_velocity += angular * impulse;
    } else {
        out.linear_velocity -= direction * (impulse * mass);
        out.angular_velocity -= angular * impulse;
    }
    return out;
}

// `warm_start_point` for one side, the body that side moves: its rows in the same order.
fn warm_start_side(h: ConstraintHeader, point: SidePoint, side: u32, body: SolverBody)
    -> SolverBody {
    let mass = select(h.mass_b, h.mass_a, side == 0u);
    var out = apply_side(point.normal, h.normal, point.impulses.x, mass, side, body);
    out = apply_side(point.tangent1, h.tangent1, point.impulses.y, mass, side, out);
    return apply_side(point.tangent2, h.tangent2, point.impulses.z, mass, side, out);
}

// Constraint `index`'s warm start on its side `side`, the body of that side. Only that side's
// words of each point: the constraints come in any order here, a thread reading words of
// 32 different blocks, so each word read is a sector of its own.
fn warm_start_contact_side(index: u32, side: u32, body: SolverBody) -> SolverBody {
    let count = load_ids(index).w;
    let h = load_header(index);
    let p0 = load_side_point(index, 0u, count, side);
    let p1 = load_side_point(index, 1u, count, side);
    let p2 = load_side_point(index, 2u, count, side);
    let p3 = load_side_point(index, 3u, count, side);
    var out = body;
    if count > 0u {
        out = warm_start_side(h, p0, side, out);
    }
    if count > 1u {
        out = warm_start_side(h, p1, side, out);
    }
    if count > 2u {
        out = warm_start_side(h, p2, side, out);
    }
    if count > 3u {
        out = warm_start_side(h, p3, side, out);
    }
    return out;
}

// `integrate_velocities` and the warm start in one dispatch, a thread per body: gravity, then
// each of the body's constraints' warm start on it, in batch order, as the batch sweeps would
// apply them (contacts only: a device layout's batches hold no joints).
@compute @workgroup_size(SOLVER_WORKGROUP)
fn warm_start_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local;
    if index >= params.body_count {
        return;
    }
    var body = bodies[index];
    if body.inverse_mass > 0.0 {
        body.linear_velocity += params.gravity * params.h;
    }
    for (var e = adjacency_starts[index]; e < adjacency_starts[index + 1u]; e++) {
        let entry = adjacency_entries[e];
        body = warm_start_contact_side(entry >> 1u, entry & 1u, body);
    }
    bodies[index] = body;
}
