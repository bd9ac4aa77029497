// The subgroup half of the scan: thread t is lane l of subgroup k with t = k × width + l (the
// workgroup is a whole number of subgroups of any power-of-two width up to 128, and drivers
// fill subgroups in order then), the thread sums are scanned by subgroup operations, and the
// first subgroup looks back at `width` tiles at once.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) width: u32,
    @builtin(subgroup_id) subgroup: u32,
}

fn thread_position(ids: ThreadIds) -> u32 {
    return ids.subgroup * ids.width + ids.lane;
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

// The sum of tile `tile`'s input, summed by one subgroup (the look-back's fallback).
fn subgroup_reduce_tile(ids: ThreadIds, tile: u32) -> u32 {
    var sum = 0u;
    for (var slot = ids.lane; slot < TILE; slot += ids.width) {
        let index = tile * TILE + slot;
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
