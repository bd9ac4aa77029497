// The batches on the device, for a step whose rows, batching and solver all run on the GPU
// (stages/solver/batched.rs): `gather_rows.wgsl` lays the rows' constraints out in batch order
// (the host sends the order: a counting sort of the colors, group_by_batch's twin), and after
// the solve `read_impulses` copies each batched constraint's accumulated impulses into a small
// record, and `read_joint_impulses` each joint's, so the host reads 48 bytes a contact
// constraint and 32 a joint for its warm start and break test instead of the whole
// constraints; the joints' also go to their slots, where the next step's GPU joint rows read
// their warm start.

// Per batched constraint: the accumulated impulse of each point (x, y, z, w = points 0..3)
// along the normal and the two tangents. Unused points are 0.
struct BatchedImpulses {
    normal: vec4<f32>,
    tangent1: vec4<f32>,
    tangent2: vec4<f32>,
}

// Word 0: the number of contact constraints, word 1: the number of joints (in a buffer, so
// the dispatches serve every step).
@group(0) @binding(0) var<storage, read> count: array<u32>;
// Bindings 1 and 2, the batch order and the rows, are gather_rows.wgsl's.
// The contact constraints in batch order, in blocks of lanes (lanes.wgsl).
@group(0) @binding(3) var<storage, read_write> batched: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> impulses: array<BatchedImpulses>;
// The joints in batch order, as the solver left them.
@group(0) @binding(5) var<storage, read> joints: array<JointConstraint>;
@group(0) @binding(6) var<storage, read_write> joint_impulses: array<BatchedJointImpulses>;
// The GPU joint rows' warm start, by joint slot (stages/constraints/joint_gpu.rs).
@group(0) @binding(7) var<storage, read_write> slot_impulses: array<BatchedJointImpulses>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn read_impulses(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= count[0] {
        return;
    }
    let points = bitcast<u32>(batched[lane_word(index, HEADER_IDS)].w);
    var out = BatchedImpulses(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    for (var k = 0u; k < points; k++) {
        let impulses = batched[point_word(index, k, POINT_IMPULSES)];
        out.normal[k] = impulses.x;
        out.tangent1[k] = impulses.y;
        out.tangent2[k] = impulses.z;
    }
    impulses[index] = out;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn read_joint_impulses(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= count[1] {
        return;
    }
    // Field by field through a pointer (no copy of the whole joint).
    let j = &joints[index];
    joint_impulses[index].point = (*j).point_impulse;
    joint_impulses[index].angular = (*j).angular_impulse;
    // And to the joint's slot, for the next step's rows (the drag's warm start is the host's).
    let slot = (*j).joint;
    if slot != DRAG_JOINT {
        slot_impulses[slot].point = (*j).point_impulse;
        slot_impulses[slot].angular = (*j).angular_impulse;
    }
}
