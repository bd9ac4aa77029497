// Stream compaction, after an exclusive scan of the flags (0 or 1) into `positions`:
// kept values land at their position, in input order; the last thread writes the total.

struct CompactParams {
    count: u32,
    padding0: u32,
    padding1: u32,
    padding2: u32,
}

@group(0) @binding(0) var<uniform> params: CompactParams;
@group(0) @binding(1) var<storage, read> flags: array<u32>;
@group(0) @binding(2) var<storage, read> positions: array<u32>;
@group(0) @binding(3) var<storage, read> values: array<u32>;
@group(0) @binding(4) var<storage, read_write> compacted: array<u32>;
@group(0) @binding(5) var<storage, read_write> total: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter_kept(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.count {
        return;
    }
    let kept = flags[index] != 0u;
    if kept {
        compacted[positions[index]] = values[index];
    }
    if index == params.count - 1u {
        total[0] = positions[index] + select(0u, 1u, kept);
    }
}
