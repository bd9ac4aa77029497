// Scatter of records of `words` 4-byte words: record i of `values` to record indices[i] of
// `destination`, one thread per record. The indices are distinct, so no two threads write one
// word.

struct ScatterParams {
    count: u32,
    words: u32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: ScatterParams;
@group(0) @binding(1) var<storage, read> indices: array<u32>;
@group(0) @binding(2) var<storage, read> values: array<u32>;
@group(0) @binding(3) var<storage, read_write> destination: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.count {
        return;
    }
    let target_first = indices[index] * params.words;
    let value_first = index * params.words;
    for (var word = 0u; word < params.words; word++) {
        destination[target_first + word] = values[value_first + word];
    }
}
