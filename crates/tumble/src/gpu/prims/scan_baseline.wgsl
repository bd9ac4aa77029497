// The baseline half of the scan (no subgroups): thread t is local invocation t, the thread
// sums are scanned in workgroup memory, and one thread looks back one tile at a time.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
}

fn thread_position(ids: ThreadIds) -> u32 {
    return ids.local;
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

// The sum of tile `tile`'s input, to every thread (the fallback); call from uniform control
// flow with `exchange` free.
fn reduce_tile(tile: u32, local: u32) -> u32 {
    var sum = 0u;
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let index = tile * TILE + item * WORKGROUP_SIZE + local;
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
// Call from uniform control flow with `exchange` free.
fn look_back(ids: ThreadIds, tile: u32, aggregate: u32) -> u32 {
    let local = ids.local;
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

