// The batch layout on the device: `batch_order` (stages/batching/mod.rs) as kernels, a stable
// counting sort of the constraints by color. Batch k is color k, the overflow batch is
// MAX_COLORS (empty batches are empty ranges), so the batches keep the host's solve order.
//
// `count_blocks` counts each block's colors (a block is a workgroup's WORKGROUP_SIZE
// constraints) into `block_counts`, batch-major, so that its exclusive scan (`starts`, scanned
// by the scan primitive) is, for batch k and block b, where block b's constraints of batch k
// start. `scatter` puts each constraint at its start plus its rank among the earlier ones of
// its block and batch, which keeps the input order within a batch. `batch_offsets` writes
// each batch's offset.
//
// Constants from Rust: LAYOUT_BATCHES (MAX_COLORS + 1).

// The batching's tally (batching.wgsl): `count` is the constraint count.
struct Tally {
    batched: u32,
    count: u32,
    rounds: u32,
    listable_from: u32,
}

struct LayoutParams {
    // Blocks the dispatches cover (for the constraint capacity): block_counts has
    // LAYOUT_BATCHES rows of this many.
    blocks: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: LayoutParams;
@group(0) @binding(1) var<storage, read> tally: Tally;
@group(0) @binding(2) var<storage, read> colors: array<u32>;
// LAYOUT_BATCHES × blocks words, batch-major.
@group(0) @binding(3) var<storage, read_write> block_counts: array<u32>;
@group(0) @binding(4) var<storage, read> starts: array<u32>;
@group(0) @binding(5) var<storage, read_write> order: array<u32>;
// LAYOUT_BATCHES + 2 words: batch k is order[offsets[k]..offsets[k + 1]], then the end of the
// batches that hold a constraint.
@group(0) @binding(6) var<storage, read_write> offsets: array<u32>;

var<workgroup> tile_counts: array<atomic<u32>, LAYOUT_BATCHES>;
var<workgroup> tile_colors: array<u32, WORKGROUP_SIZE>;


@compute @workgroup_size(WORKGROUP_SIZE)
fn count_blocks(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    for (var k = local; k < LAYOUT_BATCHES; k += WORKGROUP_SIZE) {
        atomicStore(&tile_counts[k], 0u);
    }
    workgroupBarrier();
    let i = block * WORKGROUP_SIZE + local;
    if i < tally.count {
        atomicAdd(&tile_counts[colors[i]], 1u);
    }
    workgroupBarrier();
    let blocks = params.blocks;
    if block >= blocks {
        return;
    }
    for (var k = local; k < LAYOUT_BATCHES; k += WORKGROUP_SIZE) {
        block_counts[k * blocks + block] = atomicLoad(&tile_counts[k]);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    let i = block * WORKGROUP_SIZE + local;
    var color = LAYOUT_BATCHES;
    if i < tally.count {
        color = colors[i];
    }
    tile_colors[local] = color;
    workgroupBarrier();
    if i >= tally.count {
        return;
    }
    var rank = 0u;
    for (var j = 0u; j < local; j++) {
        rank += u32(tile_colors[j] == color);
    }
    order[starts[color * params.blocks + block] + rank] = i;
}

// One workgroup: thread k writes batch k's offset; entry LAYOUT_BATCHES + 1 is the end of the
// batches that hold a constraint (one past the last), where a walk over them may stop.
@compute @workgroup_size(WORKGROUP_SIZE)
fn batch_offsets(@builtin(local_invocation_index) local: u32) {
    let count = tally.count;
    for (var k = local; k <= LAYOUT_BATCHES; k += WORKGROUP_SIZE) {
        var start = count;
        if k < LAYOUT_BATCHES && count > 0u {
            start = starts[k * params.blocks];
        }
        offsets[k] = start;
    }
    if local == 0u {
        var end = LAYOUT_BATCHES;
        while end > 0u && (count == 0u || starts[(end - 1u) * params.blocks] == count) {
            end -= 1u;
        }
        offsets[LAYOUT_BATCHES + 1u] = end;
    }
}
