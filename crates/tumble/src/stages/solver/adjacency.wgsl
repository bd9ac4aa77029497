// Each body's constraints, in batch order, for the warm start that gathers by body
// (`warm_start_bodies` in solver.wgsl) rather than sweeping batch by batch. From a device batch
// layout (stages/batching/layout.wgsl) and the batching's per-body color masks: a body has at
// most one constraint of each color, and the batches are the colors in order, so the rank of
// its constraint of color c among its constraints is the number of its colors below c. Its
// overflow constraints (which may share it) come after, in batch order, ranked by one thread.
//
// An entry is 2 p + side: the constraint at batch place p, the body its side A (0) or B (1).
// Constants from Rust: MAX_COLORS (the overflow batch), STATIC_BODY.

struct AdjacencyParams {
    body_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: AdjacencyParams;
// Per body: the colors of its constraints, overflow aside (batching.wgsl).
@group(0) @binding(1) var<storage, read> masks: array<vec2<u32>>;
// Per row: its color; per batch place: its row; per row: its bodies.
@group(0) @binding(2) var<storage, read> colors: array<u32>;
@group(0) @binding(3) var<storage, read> order: array<u32>;
@group(0) @binding(4) var<storage, read> row_bodies: array<vec2<u32>>;
// The layout's batch offsets.
@group(0) @binding(5) var<storage, read> offsets: array<u32>;
// Per body: its overflow constraints, counted by `overflow_ranks` and set back to zero by
// `count_bodies` (zero between steps).
@group(0) @binding(6) var<storage, read_write> overflow_counts: array<u32>;
// Per batch place in the overflow batch: each side's rank among its body's overflow ones.
@group(0) @binding(7) var<storage, read_write> side_ranks: array<vec2<u32>>;
// Per body (and a closing 0): its constraint count; their exclusive scan, its first entry.
@group(0) @binding(8) var<storage, read_write> counts: array<u32>;
@group(0) @binding(9) var<storage, read> starts: array<u32>;
@group(0) @binding(10) var<storage, read_write> entries: array<u32>;

fn thread_index(local: u32, workgroup: vec3<u32>, groups: vec3<u32>) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
}

// One thread, in batch order: the overflow batch is small (what 64 colors could not hold).
@compute @workgroup_size(1)
fn overflow_ranks() {
    for (var p = offsets[MAX_COLORS]; p < offsets[MAX_COLORS + 1u]; p++) {
        let bodies = row_bodies[order[p]];
        var ranks = vec2<u32>(0u);
        for (var k = 0u; k < 2u; k++) {
            if bodies[k] != STATIC_BODY {
                ranks[k] = overflow_counts[bodies[k]];
                overflow_counts[bodies[k]] += 1u;
            }
        }
        side_ranks[p] = ranks;
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn count_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = thread_index(local, workgroup, groups);
    if body < params.body_count {
        let mask = masks[body];
        counts[body] = countOneBits(mask.x) + countOneBits(mask.y) + overflow_counts[body];
        overflow_counts[body] = 0u;
    } else if body == params.body_count {
        counts[body] = 0u;
    }
}

// The colors of `mask` below `color` (< MAX_COLORS).
fn colors_below(mask: vec2<u32>, color: u32) -> u32 {
    if color < 32u {
        return countOneBits(mask.x & ((1u << color) - 1u));
    }
    return countOneBits(mask.x) + countOneBits(mask.y & ((1u << (color - 32u)) - 1u));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn fill(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let p = thread_index(local, workgroup, groups);
    if p >= offsets[MAX_COLORS + 1u] {
        return;
    }
    let row = order[p];
    let color = colors[row];
    let bodies = row_bodies[row];
    for (var k = 0u; k < 2u; k++) {
        let body = bodies[k];
        if body == STATIC_BODY {
            continue;
        }
        let mask = masks[body];
        var rank = 0u;
        if color < MAX_COLORS {
            rank = colors_below(mask, color);
        } else {
            rank = countOneBits(mask.x) + countOneBits(mask.y) + side_ranks[p][k];
        }
        entries[starts[body] + rank] = 2u * p + k;
    }
}
