// After the solve: each batched contact constraint's accumulated impulses into its pair's
// contact on the device (`pair` is its slot there), point by point up to its point count, as
// the host's store of the impulses does. So the next step's pair diff warm-starts from the
// device's own contacts, and the pair cache need not be uploaded (stages/solver/batched.rs).
// Only for rows built from the GPU narrowphase's output, whose slots are all pairs.

// Word 0: the number of contact constraints.
@group(0) @binding(0) var<storage, read> count: array<u32>;
@group(0) @binding(1) var<storage, read> batched: array<ContactConstraint>;
@group(0) @binding(2) var<storage, read_write> contacts: array<PairContact>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter_pair_impulses(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= count[0] {
        return;
    }
    // Through pointers, field by field (a loop-indexed copy would spill, see solver.wgsl).
    let c = &batched[index];
    let contact = &contacts[(*c).pair];
    for (var i = 0u; i < (*c).point_count; i++) {
        (*contact).impulses[i].normal = (*c).points[i].normal.impulse;
        (*contact).impulses[i].tangent[0] = (*c).points[i].tangent[0].impulse;
        (*contact).impulses[i].tangent[1] = (*c).points[i].tangent[1].impulse;
    }
}
