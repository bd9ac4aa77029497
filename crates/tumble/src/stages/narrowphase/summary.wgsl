// Per pair, what the host's step reads of a contact when the contacts stay on the device
// (stages/narrowphase/summary.rs): the point count and the deepest penetration (m, >= 0, as
// f32 bits), the max over the points of -separation, as the host's stats fold it.

// Word 0: the pair count (the broadphase's).
@group(0) @binding(0) var<storage, read> count: array<u32>;
@group(0) @binding(1) var<storage, read> contacts: array<PairContact>;
@group(0) @binding(2) var<storage, read_write> summaries: array<vec2<u32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn summarize(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= count[0] {
        return;
    }
    let manifold = &contacts[index].manifold;
    var depth = 0.0;
    for (var i = 0u; i < (*manifold).count; i++) {
        depth = max(depth, -(*manifold).points[i].separation);
    }
    summaries[index] = vec2<u32>((*manifold).count, bitcast<u32>(depth));
}
