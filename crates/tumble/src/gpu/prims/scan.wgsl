// Prefix sum of u32 (wrapping), reduce-then-scan over blocks of BLOCK = WORKGROUP_SIZE ×
// ITEMS_PER_THREAD elements. `gpu::prims::scan` drives it level by level:
//
//   level 0:  source ──reduce_blocks──▶ block sums (level 1) ──…──▶ one block
//             top level: scan_blocks, no parent
//   going down: scan_blocks(level k) adds the scanned sum of its block from level k + 1.
//
// No workgroup waits for another (no look-back), so it is correct on any adapter.

struct ScanParams {
    // Elements at this level.
    count: u32,
    // 1: inclusive (element i included), 0: exclusive. Upper levels are always exclusive.
    inclusive: u32,
    // 1 when `parent` holds the scanned block sums of the level above.
    has_parent: u32,
    padding: u32,
}

@group(0) @binding(0) var<uniform> params: ScanParams;
@group(0) @binding(1) var<storage, read> source: array<u32>;
@group(0) @binding(2) var<storage, read_write> destination: array<u32>;
@group(0) @binding(3) var<storage, read> parent: array<u32>;

const BLOCK: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;

var<workgroup> tile: array<u32, BLOCK>;
var<workgroup> partial: array<u32, WORKGROUP_SIZE>;

// destination[block] = sum of the block's elements (tree order, fixed).
@compute @workgroup_size(WORKGROUP_SIZE)
fn reduce_blocks(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    if block * BLOCK >= params.count {
        return;
    }
    var sum = 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let index = block * BLOCK + item * WORKGROUP_SIZE + local;
        if index < params.count {
            sum += source[index];
        }
    }
    partial[local] = sum;
    workgroupBarrier();
    for (var stride = WORKGROUP_SIZE / 2u; stride > 0u; stride >>= 1u) {
        if local < stride {
            partial[local] += partial[local + stride];
        }
        workgroupBarrier();
    }
    if local == 0u {
        destination[block] = partial[0];
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn scan_blocks(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    if block * BLOCK >= params.count {
        return;
    }
    // Coalesced load: thread t reads t, t + WORKGROUP_SIZE, ...
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let slot = item * WORKGROUP_SIZE + local;
        let index = block * BLOCK + slot;
        tile[slot] = select(0u, source[min(index, params.count - 1u)], index < params.count);
    }
    workgroupBarrier();
    // Each thread sums its ITEMS_PER_THREAD consecutive elements...
    let first = local * ITEMS_PER_THREAD;
    var own = 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        own += tile[first + item];
    }
    partial[local] = own;
    workgroupBarrier();
    // ...then the thread sums are scanned (Hillis–Steele, inclusive)...
    for (var offset = 1u; offset < WORKGROUP_SIZE; offset <<= 1u) {
        var before = 0u;
        if local >= offset {
            before = partial[local - offset];
        }
        workgroupBarrier();
        partial[local] += before;
        workgroupBarrier();
    }
    // ...and each thread writes its elements from its exclusive prefix.
    var running = partial[local] - own;
    if params.has_parent != 0u {
        running += parent[block];
    }
    let inclusive = params.inclusive != 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let value = tile[first + item];
        tile[first + item] = select(running, running + value, inclusive);
        running += value;
    }
    workgroupBarrier();
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let slot = item * WORKGROUP_SIZE + local;
        let index = block * BLOCK + slot;
        if index < params.count {
            destination[index] = tile[slot];
        }
    }
}
