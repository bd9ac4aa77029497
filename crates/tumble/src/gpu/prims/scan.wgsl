// Prefix sum of u32 (wrapping) in one pass over the data: a chained scan with decoupled
// look-back (Merrill & Garland, "Single-pass Parallel Prefix Scan with Decoupled Look-back",
// 2016) and decoupled fallback (Smith, Levien & Owens, "Decoupled Fallback", 2025).
// Injected: ITEMS_PER_THREAD, POLLS. `gpu::prims::scan` zeroes `status` before each scan.
// The thread sums and the look-back come in two halves, `scan_baseline.wgsl` (any adapter)
// and `scan_subgroups.wgsl` (adapters with subgroups).
//
// A tile is TILE = WORKGROUP_SIZE × ITEMS_PER_THREAD consecutive elements; workgroup k scans
// tile k. Each workgroup
//   1. loads its tile, sums it, publishes the sum as AGGREGATE;
//   2. walks back over earlier tiles, adding AGGREGATEs until it meets a PREFIX (the sum of
//      everything up to and including that tile), and publishes its own PREFIX;
//   3. scans its tile starting from the sum of all earlier tiles and writes it.
//
// Fallback: a tile that has not published after POLLS polls is summed from the input by the
// waiting workgroup itself. Nothing ever waits unboundedly, which matters on Mesa's CPU
// drivers: they run workgroups on a thread pool the OS may deschedule for milliseconds, and
// llvmpipe ends a shader's loops after 65535 iterations in all, so a spin-wait there would
// silently give up. On a GPU the fallback is rare (the tile is usually published by then).
// It also makes the order in which workgroups start irrelevant to progress, so the tile is the
// workgroup id rather than a ticket from an atomic counter, which would delay every tile's
// loads by one round trip to memory (on an H100: 64M u32 0.390 → 0.385 ms; the radix sort of
// 1M pairs 0.163 → 0.149 ms).
//
// Status of tile k: two words, the low and the high 16 bits of its sum, each with the flag
// in its own high 16 bits (WGSL has no 64-bit atomics on the baseline, and a sum needs all 32
// bits). A reader takes the pair only when both halves carry the same flag, so it never mixes
// an AGGREGATE half with a PREFIX half.

struct ScanParams {
    // Elements to scan.
    count: u32,
    // 1: inclusive (element i included), 0: exclusive.
    inclusive: u32,
    // Tiles of this scan; workgroups past it (a 2D grid rounds up) do nothing.
    tile_count: u32,
    padding: u32,
}

@group(0) @binding(0) var<uniform> params: ScanParams;
@group(0) @binding(1) var<storage, read> source: array<u32>;
@group(0) @binding(2) var<storage, read_write> destination: array<u32>;
// [2k], [2k + 1]: status of tile k (low, high half).
@group(0) @binding(3) var<storage, read_write> status: array<atomic<u32>>;

const TILE: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;
const FLAG_AGGREGATE: u32 = 1u;
const FLAG_PREFIX: u32 = 2u;
const HALF_MASK: u32 = 0xffffu;

// The tile, kept from load to write-out: thread t's run of ITEMS_PER_THREAD consecutive
// elements starts at word t × ITEMS_PER_THREAD; an odd ITEMS_PER_THREAD puts the 32 runs a
// subgroup reads at once in 32 different banks.
var<workgroup> exchange: array<u32, TILE>;
// The scan of the thread sums, the look-back's status and the fallback's sum.
var<workgroup> partial: array<u32, WORKGROUP_SIZE>;

// Status words are written with atomicExchange and read with atomicOr(0): naga's GLSL output
// turns atomicStore and atomicLoad into plain accesses, which llvmpipe's compiler may hoist out
// of a poll loop or delay, so other tiles would never see a status (and always fall back).
// On an H100 through Vulkan they are also faster here than atomicStore and atomicLoad
// (the whole scan: 0.39 against 0.46 ms for 64M u32).
fn publish(tile: u32, flag: u32, sum: u32) {
    atomicExchange(&status[2u * tile], (flag << 16u) | (sum & HALF_MASK));
    atomicExchange(&status[2u * tile + 1u], (flag << 16u) | (sum >> 16u));
}

// (flag, sum) of tile `tile`; flag 0 while it has not published, or published only one half.
fn status_of(tile: u32) -> vec2<u32> {
    let low = atomicOr(&status[2u * tile], 0u);
    let high = atomicOr(&status[2u * tile + 1u], 0u);
    if (low >> 16u) != (high >> 16u) {
        return vec2<u32>(0u, 0u);
    }
    return vec2<u32>(low >> 16u, (high << 16u) | (low & HALF_MASK));
}

// (flag, sum) of tile `tile`, polled up to POLLS times; flag 0 if it has not published.
fn poll_status(tile: u32) -> vec2<u32> {
    var seen = status_of(tile);
    for (var poll = 1u; poll < POLLS && seen.x == 0u; poll++) {
        seen = status_of(tile);
    }
    return seen;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn scan(ids: ThreadIds, @builtin(workgroup_id) workgroup: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let tile = flat_workgroup(workgroup, groups);
    if tile >= params.tile_count {
        return;
    }
    let start = tile * TILE;
    load_tile(start, ids.local);
    workgroupBarrier();
    // Each thread sums its run of ITEMS_PER_THREAD consecutive elements...
    let first = thread_position(ids) * ITEMS_PER_THREAD;
    var own = 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        own += exchange[first + item];
    }
    // ...the thread sums are scanned over the tile...
    let scanned = tile_scan(ids, own);
    var running = scanned.x;
    // ...the sum of all earlier tiles is found...
    running += look_back(ids, tile, scanned.y);
    // ...and each thread rewrites its run from its exclusive prefix.
    let inclusive = params.inclusive != 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let value = exchange[first + item];
        exchange[first + item] = select(running, running + value, inclusive);
        running += value;
    }
    workgroupBarrier();
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let slot = item * WORKGROUP_SIZE + ids.local;
        let index = start + slot;
        if index < params.count {
            destination[index] = exchange[slot];
        }
    }
}

// Element `slot` of the tile starting at `start`, 0 past the end of the input.
fn tile_item(start: u32, slot: u32) -> u32 {
    let index = start + slot;
    return select(0u, source[min(index, params.count - 1u)], index < params.count);
}

// Copies the tile starting at `start` into `exchange`, coalesced: invocation i reads i,
// i + WORKGROUP_SIZE, ... Written out rather than looped: drivers do not unroll naga's loops,
// and a loop whose load feeds a store keeps one load in flight per thread (on an H100 the
// whole scan took 1.7× as long that way).
const_assert ITEMS_PER_THREAD == 15u;
fn load_tile(start: u32, local: u32) {
    let item0 = tile_item(start, 0u * WORKGROUP_SIZE + local);
    let item1 = tile_item(start, 1u * WORKGROUP_SIZE + local);
    let item2 = tile_item(start, 2u * WORKGROUP_SIZE + local);
    let item3 = tile_item(start, 3u * WORKGROUP_SIZE + local);
    let item4 = tile_item(start, 4u * WORKGROUP_SIZE + local);
    let item5 = tile_item(start, 5u * WORKGROUP_SIZE + local);
    let item6 = tile_item(start, 6u * WORKGROUP_SIZE + local);
    let item7 = tile_item(start, 7u * WORKGROUP_SIZE + local);
    let item8 = tile_item(start, 8u * WORKGROUP_SIZE + local);
    let item9 = tile_item(start, 9u * WORKGROUP_SIZE + local);
    let item10 = tile_item(start, 10u * WORKGROUP_SIZE + local);
    let item11 = tile_item(start, 11u * WORKGROUP_SIZE + local);
    let item12 = tile_item(start, 12u * WORKGROUP_SIZE + local);
    let item13 = tile_item(start, 13u * WORKGROUP_SIZE + local);
    let item14 = tile_item(start, 14u * WORKGROUP_SIZE + local);
    exchange[0u * WORKGROUP_SIZE + local] = item0;
    exchange[1u * WORKGROUP_SIZE + local] = item1;
    exchange[2u * WORKGROUP_SIZE + local] = item2;
    exchange[3u * WORKGROUP_SIZE + local] = item3;
    exchange[4u * WORKGROUP_SIZE + local] = item4;
    exchange[5u * WORKGROUP_SIZE + local] = item5;
    exchange[6u * WORKGROUP_SIZE + local] = item6;
    exchange[7u * WORKGROUP_SIZE + local] = item7;
    exchange[8u * WORKGROUP_SIZE + local] = item8;
    exchange[9u * WORKGROUP_SIZE + local] = item9;
    exchange[10u * WORKGROUP_SIZE + local] = item10;
    exchange[11u * WORKGROUP_SIZE + local] = item11;
    exchange[12u * WORKGROUP_SIZE + local] = item12;
    exchange[13u * WORKGROUP_SIZE + local] = item13;
    exchange[14u * WORKGROUP_SIZE + local] = item14;
}
