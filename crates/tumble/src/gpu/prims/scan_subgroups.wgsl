// The subgroup half of the scan: thread t is lane l of subgroup k with t = k × width + l (the
// workgroup is a whole number of subgroups of any power-of-two width up to 128, and drivers
// fill subgroups in order then). Subgroup k holds ITEMS_PER_THREAD rows of `width`
// consecutive elements of the tile, lane l the l-th of each, in registers: each row is summed
// and scanned by subgroup operations, the subgroups' sums are scanned over the workgroup, and
// the first subgroup looks back at `width` tiles at once. Keeping the tile out of workgroup
// memory (the baseline stages it there) leaves more workgroups resident and saves two
// barriers: on an H100, 64M u32 in 0.33 ms against 0.39 ms staged, 77 % of a compute copy.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) width: u32,
    @builtin(subgroup_id) subgroup: u32,
}

const_assert ITEMS_PER_THREAD == 15u;
@compute @workgroup_size(WORKGROUP_SIZE)
fn scan(ids: ThreadIds, @builtin(workgroup_id) workgroup: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let window_tile = flat_workgroup(workgroup, groups);
    if window_tile >= params.tile_count {
        return;
    }
    let tile = params.first_tile + window_tile;
    // Element `row` × width of this lane's rows. The rows' loads, sums and scans are written
    // out rather than looped: drivers do not unroll naga's loops (see `scan_baseline.wgsl`).
    let first = window_tile * TILE + ids.subgroup * ITEMS_PER_THREAD * ids.width + ids.lane;
    let item0 = tile_item(first, 0u * ids.width);
    let item1 = tile_item(first, 1u * ids.width);
    let item2 = tile_item(first, 2u * ids.width);
    let item3 = tile_item(first, 3u * ids.width);
    let item4 = tile_item(first, 4u * ids.width);
    let item5 = tile_item(first, 5u * ids.width);
    let item6 = tile_item(first, 6u * ids.width);
    let item7 = tile_item(first, 7u * ids.width);
    let item8 = tile_item(first, 8u * ids.width);
    let item9 = tile_item(first, 9u * ids.width);
    let item10 = tile_item(first, 10u * ids.width);
    let item11 = tile_item(first, 11u * ids.width);
    let item12 = tile_item(first, 12u * ids.width);
    let item13 = tile_item(first, 13u * ids.width);
    let item14 = tile_item(first, 14u * ids.width);
    // Each row's sum, and each element's prefix within its row...
    let row0 = subgroupAdd(item0);
    let row1 = subgroupAdd(item1);
    let row2 = subgroupAdd(item2);
    let row3 = subgroupAdd(item3);
    let row4 = subgroupAdd(item4);
    let row5 = subgroupAdd(item5);
    let row6 = subgroupAdd(item6);
    let row7 = subgroupAdd(item7);
    let row8 = subgroupAdd(item8);
    let row9 = subgroupAdd(item9);
    let row10 = subgroupAdd(item10);
    let row11 = subgroupAdd(item11);
    let row12 = subgroupAdd(item12);
    let row13 = subgroupAdd(item13);
    let row14 = subgroupAdd(item14);
    let lanes0 = subgroupExclusiveAdd(item0);
    let lanes1 = subgroupExclusiveAdd(item1);
    let lanes2 = subgroupExclusiveAdd(item2);
    let lanes3 = subgroupExclusiveAdd(item3);
    let lanes4 = subgroupExclusiveAdd(item4);
    let lanes5 = subgroupExclusiveAdd(item5);
    let lanes6 = subgroupExclusiveAdd(item6);
    let lanes7 = subgroupExclusiveAdd(item7);
    let lanes8 = subgroupExclusiveAdd(item8);
    let lanes9 = subgroupExclusiveAdd(item9);
    let lanes10 = subgroupExclusiveAdd(item10);
    let lanes11 = subgroupExclusiveAdd(item11);
    let lanes12 = subgroupExclusiveAdd(item12);
    let lanes13 = subgroupExclusiveAdd(item13);
    let lanes14 = subgroupExclusiveAdd(item14);
    // ...the subgroups' sums scanned over the tile (lane 0 brings its subgroup's)...
    let rows = row0 + row1 + row2 + row3 + row4 + row5 + row6 + row7 + row8 + row9 + row10 + row11 + row12 + row13 + row14;
    let scanned = tile_scan(ids, select(0u, rows, ids.lane == 0u));
    // ...the sum of all earlier tiles...
    var running = look_back(ids, tile, scanned.y) + subgroupBroadcastFirst(scanned.x);
    // ...and each row written from the sum of everything before it.
    let inclusive = params.inclusive != 0u;
    store(first + 0u * ids.width, running + lanes0 + select(0u, item0, inclusive));
    running += row0;
    store(first + 1u * ids.width, running + lanes1 + select(0u, item1, inclusive));
    running += row1;
    store(first + 2u * ids.width, running + lanes2 + select(0u, item2, inclusive));
    running += row2;
    store(first + 3u * ids.width, running + lanes3 + select(0u, item3, inclusive));
    running += row3;
    store(first + 4u * ids.width, running + lanes4 + select(0u, item4, inclusive));
    running += row4;
    store(first + 5u * ids.width, running + lanes5 + select(0u, item5, inclusive));
    running += row5;
    store(first + 6u * ids.width, running + lanes6 + select(0u, item6, inclusive));
    running += row6;
    store(first + 7u * ids.width, running + lanes7 + select(0u, item7, inclusive));
    running += row7;
    store(first + 8u * ids.width, running + lanes8 + select(0u, item8, inclusive));
    running += row8;
    store(first + 9u * ids.width, running + lanes9 + select(0u, item9, inclusive));
    running += row9;
    store(first + 10u * ids.width, running + lanes10 + select(0u, item10, inclusive));
    running += row10;
    store(first + 11u * ids.width, running + lanes11 + select(0u, item11, inclusive));
    running += row11;
    store(first + 12u * ids.width, running + lanes12 + select(0u, item12, inclusive));
    running += row12;
    store(first + 13u * ids.width, running + lanes13 + select(0u, item13, inclusive));
    running += row13;
    store(first + 14u * ids.width, running + lanes14 + select(0u, item14, inclusive));
}

fn store(index: u32, value: u32) {
    if index < params.count {
        destination[index] = value;
    }
}

// (exclusive prefix of `own` over the tile's threads, the tile's total), to every thread.
// Call from uniform control flow.
fn tile_scan(ids: ThreadIds, own: u32) -> vec2<u32> {
    let inclusive = subgroupInclusiveAdd(own);
    if ids.lane == ids.width - 1u {
        partial[ids.subgroup] = inclusive;
    }
    workgroupBarrier();
    var before = 0u;
    var total = 0u;
    for (var subgroup = 0u; subgroup < WORKGROUP_SIZE / ids.width; subgroup++) {
        let sum = partial[subgroup];
        before += select(0u, sum, subgroup < ids.subgroup);
        total += sum;
    }
    workgroupBarrier();
    return vec2<u32>(before + inclusive - own, total);
}

// The lowest lane whose bit is set in a ballot, or 128 when none is.
fn first_lane(ballot: vec4<u32>) -> u32 {
    for (var word = 0u; word < 4u; word++) {
        if ballot[word] != 0u {
            return 32u * word + firstTrailingBit(ballot[word]);
        }
    }
    return 128u;
}

// The sum of tile `tile`'s input (one of this window's), summed by one subgroup (the
// look-back's fallback).
fn subgroup_reduce_tile(ids: ThreadIds, tile: u32) -> u32 {
    var sum = 0u;
    for (var slot = ids.lane; slot < TILE; slot += ids.width) {
        let index = tile_start(tile) + slot;
        if index < params.count {
            sum += source[index];
        }
    }
    return subgroupAdd(sum);
}

// The sum of all tiles before `tile` (uniform), to every thread; publishes the tile's PREFIX.
// Call from uniform control flow. Lane l of the first subgroup reads the status of the l-th
// tile back; the statuses up to the nearest PREFIX are summed at once, tiles that have not
// published after POLLS polls are summed from the input by the subgroup.
fn look_back(ids: ThreadIds, tile: u32, aggregate: u32) -> u32 {
    // A partial last tile looks back serially. On an H100 (driver 580) the subgroup look-back
    // of a tile whose looking subgroup holds positions past the input's end returned lane 0's
    // tile index (`tile - 1`) instead of the prefix: every other value of that tile was right
    // (a debug build that stored them showed it), no change to the walk's control flow helped,
    // and lavapipe's 8-wide subgroups never showed it, so we take it for a miscompile we could
    // not isolate further. One tile of a scan pays for the serial walk, nothing measurable.
    // tests/engine/gpu_scan.rs sweeps partial last tiles for this; run it on NVIDIA after changes here.
    if params.count - tile_start(tile) < TILE {
        return serial_look_back(ids.local, tile, aggregate);
    }
    if ids.local == 0u {
        publish(tile, select(FLAG_AGGREGATE, FLAG_PREFIX, tile == 0u), aggregate);
    }
    if tile == 0u {
        return 0u;
    }
    if ids.subgroup == 0u {
        var prefix = 0u;
        // Tiles [0, end) are still to be added.
        var end = tile;
        loop {
            let look = end - 1u - min(ids.lane, end - 1u);
            // Lanes past tile 0 add nothing and stop the walk like a PREFIX.
            var seen = vec2<u32>(FLAG_PREFIX, 0u);
            if ids.lane < end {
                seen = poll_status(look);
            }
            let nearest = first_lane(subgroupBallot(seen.x == FLAG_PREFIX));
            var stuck = subgroupBallot(seen.x == 0u && ids.lane < nearest);
            loop {
                let lane = first_lane(stuck);
                if lane >= ids.width {
                    break;
                }
                let sum = subgroup_reduce_tile(ids, subgroupShuffle(look, lane));
                if ids.lane == lane {
                    seen = vec2<u32>(FLAG_AGGREGATE, sum);
                }
                stuck[lane / 32u] &= ~(1u << (lane % 32u));
            }
            prefix += subgroupAdd(select(0u, seen.y, ids.lane <= nearest));
            if nearest < ids.width {
                break;
            }
            end -= ids.width;
        }
        if ids.lane == 0u {
            publish(tile, FLAG_PREFIX, prefix + aggregate);
            partial[0] = prefix;
        }
    }
    return workgroupUniformLoad(&partial[0]);
}
