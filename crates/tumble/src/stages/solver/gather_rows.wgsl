// The rows' contact constraints into batch order (stages/solver/batched.rs), both in blocks of
// lanes (lanes.wgsl), a 16-byte word a thread: word `slot` of batched place `place` is word
// `slot` of row order[place]. A thread takes the word at its own index of the output, so a
// warp's stores are 512 contiguous bytes (its loads are those of 32 rows in any order).

// Word 0: the number of contact constraints.
@group(0) @binding(0) var<storage, read> count: array<u32>;
// order[i]: the constraint (in the rows' order) that goes to batched place i.
@group(0) @binding(1) var<storage, read> order: array<u32>;
@group(0) @binding(2) var<storage, read> rows: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read_write> batched: array<vec4<u32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_words(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let word = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    // The inverse of lane_word: block, word of the constraint, lane.
    let block = word / (CONSTRAINT_WORDS * CONSTRAINT_LANES);
    let within = word - block * CONSTRAINT_WORDS * CONSTRAINT_LANES;
    let slot = within / CONSTRAINT_LANES;
    let place = block * CONSTRAINT_LANES + within % CONSTRAINT_LANES;
    if place >= count[0] {
        return;
    }
    batched[word] = rows[lane_word(order[place], slot)];
}
