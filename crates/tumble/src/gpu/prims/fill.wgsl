// Element-wise fill and copy of 4-byte words, one thread per word.

struct FillParams {
    count: u32,
    // Bit pattern written by `fill` (a u32, or the bits of an f32 / i32).
    value: u32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: FillParams;
@group(0) @binding(1) var<storage, read> source: array<u32>;
@group(0) @binding(2) var<storage, read_write> destination: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn fill(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index < params.count {
        destination[index] = params.value;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn copy(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index < params.count {
        destination[index] = source[index];
    }
}
