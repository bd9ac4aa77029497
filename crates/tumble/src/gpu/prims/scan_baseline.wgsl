// The baseline half of the scan (no subgroups): thread t is local invocation t, the thread
// sums are scanned in workgroup memory, and one thread looks back one tile at a time.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
}

// The tile, kept from load to write-out: thread t's run of ITEMS_PER_THREAD consecutive
// elements starts at word t × ITEMS_PER_THREAD; an odd ITEMS_PER_THREAD puts the 32 runs a
// subgroup reads at once in 32 different banks.
var<workgroup> exchange: array<u32, TILE>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn scan(ids: ThreadIds, @builtin(workgroup_id) workgroup: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let window_tile = flat_workgroup(workgroup, groups);
    if window_tile >= params.tile_count {
        return;
    }
    let tile = params.first_tile + window_tile;
    let start = window_tile * TILE;
    load_tile(start, ids.local);
    workgroupBarrier();
    // Each thread sums its run of ITEMS_PER_THREAD consecutive elements...
    let first = ids.local * ITEMS_PER_THREAD;
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

// (exclusive prefix of `own` over the tile's threads, the tile's total), to every thread
// (Hillis–Steele, inclusive, in place). Call from uniform control flow.
fn tile_scan(ids: ThreadIds, own: u32) -> vec2<u32> {
    let local = ids.local;
    partial[local] = own;
    workgroupBarrier();
    for (var offset = 1u; offset < WORKGROUP_SIZE; offset <<= 1u) {
        var before = 0u;
        if local >= offset {
            before = partial[local - offset];
        }
        workgroupBarrier();
        partial[local] += before;
        workgroupBarrier();
    }
    let result = vec2<u32>(partial[local] - own, partial[WORKGROUP_SIZE - 1u]);
    workgroupBarrier();
    return result;
}

// The sum of all tiles before `tile` (uniform), to every thread; publishes the tile's PREFIX.
// Call from uniform control flow.
fn look_back(ids: ThreadIds, tile: u32, aggregate: u32) -> u32 {
    return serial_look_back(ids.local, tile, aggregate);
}
