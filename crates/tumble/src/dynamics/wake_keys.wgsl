// The keys of the wake test's candidates (dynamics/wake.rs): the compaction lists their pair
// indices, and the host wants their bodies, which it no longer has every pair's key to look up
// (the keys stay on the device with the contacts).

// Word 0: how many candidates the compaction listed.
@group(0) @binding(0) var<storage, read> total: array<u32>;
// Pair keys, u64 as two words (wake.wgsl).
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
// The candidates' pair indices, in pair order.
@group(0) @binding(2) var<storage, read> listed: array<u32>;
// Their keys, in the same order.
@group(0) @binding(3) var<storage, read_write> listed_keys: array<vec2<u32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn wake_candidate_keys(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index < total[0] {
        listed_keys[index] = keys[listed[index]];
    }
}
