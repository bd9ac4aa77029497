// The Jacobi sweeps of the soft step: the GPU twin of stages/solver/jacobi.rs (which explains
// the method and the relaxation factor), in its order of operations. Needs solver.wgsl (the
// bindings 0..5, the row functions *_pair, the integration kernels) and, for the joint
// kernels, solver_joint.wgsl.
//
// A sweep is two or three dispatches, whatever the number of batches:
//   jacobi_<pass>_contacts   one thread per contact: solve it on copies of its two bodies as
//                            the sweep found them, relax, write the bodies' changes;
//   jacobi_<pass>_joints     the same for the joints (dispatched only when there are joints);
//   jacobi_apply             one thread per body: add its constraints' changes, summed in
//                            constraint order (its adjacency list), so no atomics and the
//                            same bits every run.

// A constraint's relaxed change of one body's velocities: slot 2c is constraint c's body A,
// 2c + 1 its body B (contacts 0..C, then joints C..C + J). VelocityDelta in Rust.
struct VelocityDelta {
    linear: vec3<f32>,
    angular: vec3<f32>,
}

// Word 0: the contacts C, word 1: the joints J (in a buffer, so the bind groups serve every
// step).
@group(0) @binding(6) var<storage, read> jacobi_counts: array<u32>;
// Body b's delta slots are adjacency[adjacency_offsets[b] .. adjacency_offsets[b + 1]], in
// constraint order; static bodies and bodies of zero inverse mass have none.
@group(0) @binding(7) var<storage, read> adjacency_offsets: array<u32>;
@group(0) @binding(8) var<storage, read> adjacency: array<u32>;
@group(0) @binding(9) var<storage, read_write> deltas: array<VelocityDelta>;

// Constraints on a body (0 for a static body).
fn constraints_on(body: u32) -> u32 {
    if body == STATIC_BODY {
        return 0u;
    }
    return adjacency_offsets[body + 1u] - adjacency_offsets[body];
}

// ω = 1 / max(n_a, n_b): see jacobi.rs.
fn relaxation(body_a: u32, body_b: u32) -> f32 {
    return 1.0 / f32(max(max(constraints_on(body_a), constraints_on(body_b)), 1u));
}

fn relax(old: f32, solved: f32, omega: f32) -> f32 {
    return old + omega * (solved - old);
}

fn store_deltas(slot: u32, start: BodyPair, end: BodyPair, omega: f32) {
    deltas[2u * slot] = VelocityDelta(
        (end[0].linear_velocity - start[0].linear_velocity) * omega,
        (end[0].angular_velocity - start[0].angular_velocity) * omega);
    deltas[2u * slot + 1u] = VelocityDelta(
        (end[1].linear_velocity - start[1].linear_velocity) * omega,
        (end[1].angular_velocity - start[1].angular_velocity) * omega);
}

// Phase 1 for contact `index` (kind: WARM_START, SOLVE or RESTITUTION of solver.wgsl).
fn jacobi_contact(kind: u32, index: u32) {
    let ids = load_ids(index);
    let start = BodyPair(load_body(ids.x), load_body(ids.y));
    if kind == WARM_START {
        store_deltas(index, start, warm_start_contact_pair(index, start), 1.0);
        return;
    }
    let omega = relaxation(ids.x, ids.y);
    // The impulses before the solve (a word a point: normal, tangents, largest normal), point
    // k in lane k.
    let before = array<vec4<f32>, 4>(impulses_of(index, 0u), impulses_of(index, 1u),
        impulses_of(index, 2u), impulses_of(index, 3u));
    let old_normal = vec4<f32>(before[0].x, before[1].x, before[2].x, before[3].x);
    let old_tangent1 = vec4<f32>(before[0].y, before[1].y, before[2].y, before[3].y);
    let old_tangent2 = vec4<f32>(before[0].z, before[1].z, before[2].z, before[3].z);
    let old_max = vec4<f32>(before[0].w, before[1].w, before[2].w, before[3].w);
    var end: BodyPair;
    if kind == SOLVE {
        // No impulse sums: the Jacobi warm start reads the rows (and they would be the
        // impulses before the relaxation below).
        end = solve_contact_pair(index, start, false);
    } else {
        end = restitution_contact_pair(index, start);
    }
    if omega != 1.0 {
        for (var k = 0u; k < ids.w; k++) {
            let solved = impulses_of(index, k);
            let normal = relax(old_normal[k], solved.x, omega);
            store_impulses(index, k, normal, relax(old_tangent1[k], solved.y, omega),
                relax(old_tangent2[k], solved.z, omega), max(old_max[k], normal));
        }
    }
    store_deltas(index, start, end, omega);
}

// The impulses of point `k` of contact `index`: normal, tangents, largest normal.
fn impulses_of(index: u32, k: u32) -> vec4<f32> {
    return contacts[point_word(index, k, POINT_IMPULSES)];
}

// Phase 1 for joint `index` (WARM_START or SOLVE).
fn jacobi_joint(kind: u32, index: u32) {
    let j = &joints[index];
    let slot = jacobi_counts[0] + index;
    let start = BodyPair(load_body((*j).body_a), load_body((*j).body_b));
    if kind == WARM_START {
        store_deltas(slot, start, warm_start_joint_pair(index, start), 1.0);
        return;
    }
    let omega = relaxation((*j).body_a, (*j).body_b);
    let old_point = (*j).point_impulse;
    let old_angular = (*j).angular_impulse;
    let end = solve_joint_pair(index, start);
    if omega != 1.0 {
        (*j).point_impulse = old_point + ((*j).point_impulse - old_point) * omega;
        (*j).angular_impulse[0] = relax(old_angular[0], (*j).angular_impulse[0], omega);
        (*j).angular_impulse[1] = relax(old_angular[1], (*j).angular_impulse[1], omega);
        (*j).angular_impulse[2] = relax(old_angular[2], (*j).angular_impulse[2], omega);
        (*j).angular_impulse[3] = relax(old_angular[3], (*j).angular_impulse[3], omega);
        (*j).angular_impulse[4] = relax(old_angular[4], (*j).angular_impulse[4], omega);
    }
    store_deltas(slot, start, end, omega);
}

fn contact_thread(kind: u32, thread: u32) {
    if thread < jacobi_counts[0] {
        jacobi_contact(kind, thread);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_warm_start_contacts(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    contact_thread(WARM_START, flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_solve_contacts(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    contact_thread(SOLVE, flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_restitution_contacts(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let thread = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    contact_thread(RESTITUTION, thread);
    // Joints do not bounce: their slots, which still hold the last sweep's changes, add
    // nothing to this one (the dispatch covers max(C, J) threads).
    if thread < jacobi_counts[1] {
        let slot = jacobi_counts[0] + thread;
        deltas[2u * slot] = VelocityDelta(vec3<f32>(0.0), vec3<f32>(0.0));
        deltas[2u * slot + 1u] = VelocityDelta(vec3<f32>(0.0), vec3<f32>(0.0));
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_warm_start_joints(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let thread = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if thread < jacobi_counts[1] {
        jacobi_joint(WARM_START, thread);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_solve_joints(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let thread = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if thread < jacobi_counts[1] {
        jacobi_joint(SOLVE, thread);
    }
}

// Phase 2: each body adds its constraints' changes, summed in constraint order first (as the
// CPU does).
@compute @workgroup_size(WORKGROUP_SIZE)
fn jacobi_apply(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body >= params.body_count {
        return;
    }
    let first = adjacency_offsets[body];
    let end = adjacency_offsets[body + 1u];
    if first == end {
        return;
    }
    var linear = vec3<f32>(0.0);
    var angular = vec3<f32>(0.0);
    for (var entry = first; entry < end; entry++) {
        let delta = deltas[adjacency[entry]];
        linear += delta.linear;
        angular += delta.angular;
    }
    bodies[body].linear_velocity += linear;
    bodies[body].angular_velocity += angular;
}
