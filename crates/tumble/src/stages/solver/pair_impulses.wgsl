// After the solve: each batched contact constraint's accumulated impulses into its pair's
// contact on the device (`pair` is its slot there), point by point up to its point count, as
// the host's store of the impulses does. So the next step's pair diff warm-starts from the
// device's own contacts, and the pair cache need not be uploaded (stages/solver/batched.rs).
// Only for rows built from the GPU narrowphase's output, whose slots are all pairs.

// Word 0: the number of contact constraints.
@group(0) @binding(0) var<storage, read> count: array<u32>;
// The contact constraints in batch order, in blocks of lanes (lanes.wgsl).
@group(0) @binding(1) var<storage, read> batched: array<vec4<f32>>;
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
    let ids = bitcast<vec4<u32>>(batched[lane_word(index, HEADER_IDS)]);
    // Through a pointer, field by field (a loop-indexed copy would spill, see solver.wgsl).
    let contact = &contacts[ids.z];
    for (var k = 0u; k < ids.w; k++) {
        let impulses = batched[point_word(index, k, POINT_IMPULSES)];
        (*contact).impulses[k].normal = impulses.x;
        (*contact).impulses[k].tangent[0] = impulses.y;
        (*contact).impulses[k].tangent[1] = impulses.z;
    }
}
