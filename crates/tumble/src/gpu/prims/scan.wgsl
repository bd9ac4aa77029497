// Prefix sum of u32 (wrapping) in one pass over the data: a chained scan with decoupled
// look-back (Merrill & Garland, "Single-pass Parallel Prefix Scan with Decoupled Look-back",
// 2016) and decoupled fallback (Smith, Levien & Owens, "Decoupled Fallback", 2025).
// Injected: ITEMS_PER_THREAD, POLLS. `gpu::prims::scan` zeroes `status` before each scan.
// The tile's scan and the look-back come in two halves, `scan_baseline.wgsl` (any adapter)
// and `scan_subgroups.wgsl` (adapters with subgroups), each with its entry point.
//
// A tile is TILE = WORKGROUP_SIZE × ITEMS_PER_THREAD consecutive elements; workgroup k scans
// tile k. Each workgroup
//   1. loads its tile, sums it, publishes the sum as AGGREGATE;
//   2. walks back over earlier tiles, adding AGGREGATEs until it meets a PREFIX (the sum of
//      everything up to and including that tile), and publishes its own PREFIX;
//   3. scans its tile starting from the sum of all earlier tiles and writes it.
// The baseline stages the tile in workgroup memory so that a thread scans consecutive
// elements; the subgroup half keeps it in registers, a row of `width` consecutive elements
// per subgroup operation.
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
// Windows: an array larger than one storage binding is scanned a window at a time, one
// dispatch each, in order (`gpu::buffer::windows`). Tiles are numbered over the whole array, so
// a window's first tile looks back into the windows before it; every tile there has published
// its PREFIX before this dispatch began, so the walk stops at the tile before the window and
// never falls back to reading input outside it.
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
    // Tiles of this window; workgroups past it (a 2D grid rounds up) do nothing.
    tile_count: u32,
    // The window's first tile, numbered over the whole array.
    first_tile: u32,
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

// Where tile `tile` (one of this window's) starts in the window.
fn tile_start(tile: u32) -> u32 {
    return (tile - params.first_tile) * TILE;
}

// Element `slot` of the tile starting at `start`, 0 past the end of the input.
fn tile_item(start: u32, slot: u32) -> u32 {
    let index = start + slot;
    return select(0u, source[min(index, params.count - 1u)], index < params.count);
}

// The sum of tile `tile`'s input (one of this window's), to every thread (the fallback); call
// from uniform control flow.
fn reduce_tile(tile: u32, local: u32) -> u32 {
    var sum = 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let index = tile_start(tile) + item * WORKGROUP_SIZE + local;
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
    let total = partial[0];
    workgroupBarrier();
    return total;
}

// The sum of all tiles before `tile` (uniform), to every thread; publishes the tile's PREFIX.
// Call from uniform control flow. Invocation 0 polls one tile at a time: the baseline's
// look-back, and the subgroup half's for a partial last tile.
fn serial_look_back(local: u32, tile: u32, aggregate: u32) -> u32 {
    if tile == 0u {
        if local == 0u {
            publish(tile, FLAG_PREFIX, aggregate);
        }
        return 0u;
    }
    if local == 0u {
        publish(tile, FLAG_AGGREGATE, aggregate);
    }
    var prefix = 0u;
    var previous = tile - 1u;
    loop {
        if local == 0u {
            let seen = poll_status(previous);
            partial[0] = seen.x;
            partial[1] = seen.y;
        }
        var flag = workgroupUniformLoad(&partial[0]);
        var sum = partial[1];
        workgroupBarrier();
        if flag == 0u {
            sum = reduce_tile(previous, local);
            // Tile 0's sum is its PREFIX: the walk must stop there.
            flag = select(FLAG_AGGREGATE, FLAG_PREFIX, previous == 0u);
        }
        prefix += sum;
        if flag == FLAG_PREFIX {
            break;
        }
        previous -= 1u;
    }
    if local == 0u {
        publish(tile, FLAG_PREFIX, prefix + aggregate);
    }
    return prefix;
}

