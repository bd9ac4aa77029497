// The warm start gathered by body (the GPU solver's, not the Jacobi solver's: their extra
// bindings differ): `warm_start_bodies` runs the gravity step and every warm start of a
// sub-step in one dispatch, over each body's constraints in batch order (adjacency.wgsl).
// Needs solver.wgsl.

// Body b's constraints: adjacency_entries[adjacency_starts[b] .. adjacency_starts[b + 1]],
// each 2 × (batch place) + side.
@group(0) @binding(6) var<storage, read> adjacency_starts: array<u32>;
@group(0) @binding(7) var<storage, read> adjacency_entries: array<u32>;

// Constraint `index`'s warm start on its side `side` (0: A, 1: B), the body of that side:
// the impulse sums the rows' build or the last relax sweep left (lanes.wgsl), two words where
// applying the rows to one side would read two a point (its anchor, the impulses) and five or
// six of the header (the directions, its inertia, its mass). The constraints come in any order
// here, a thread reading words of 32 different blocks, so each word read is a sector of its
// own. The sums round differently from the rows applied one by one (the batch sweeps' warm
// start, the CPU's).
fn warm_start_contact_side(index: u32, side: u32, body: SolverBody) -> SolverBody {
    let linear = contacts[lane_word(index, SUMS_WORD)].xyz;
    let angular = contacts[lane_word(index, SUMS_WORD + 1u + side)];
    var out = body;
    if side == 0u {
        out.linear_velocity += linear * angular.w;
        out.angular_velocity += angular.xyz;
    } else {
        out.linear_velocity -= linear * angular.w;
        out.angular_velocity -= angular.xyz;
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
