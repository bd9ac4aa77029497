// Stream compaction, after an exclusive scan of the flags (0 or 1) into `positions`:
// kept values land at their position, in input order; the last thread writes the total.
// Past one storage binding, one dispatch per window of the input and window of the output
// (`gpu::prims::compact`): each writes the kept values whose position lies in its output window.

struct CompactParams {
    // Elements of this input window.
    count: u32,
    // The output window: the first position it holds, and how many.
    destination_first: u32,
    destination_count: u32,
    // 1 for the dispatch that writes the total: the last input window's first run.
    writes_total: u32,
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
    let position = positions[index];
    // Wrapping: positions before the window come out above its count.
    let slot = position - params.destination_first;
    if kept && slot < params.destination_count {
        compacted[slot] = values[index];
    }
    if params.writes_total != 0u && index == params.count - 1u {
        total[0] = positions[index] + select(0u, 1u, kept);
    }
}
