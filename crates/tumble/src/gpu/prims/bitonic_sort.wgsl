// Bitonic sort of (key, value) pairs, ascending by key then value, in the "flip" form: every
// compare-exchange puts the smaller pair at the lower index, so positions past `count` act
// as +∞ and are never touched (no padding to a power of two in memory).
//
//   flip(k):          pairs (i, i') mirrored inside blocks of k: offset o ↔ k − 1 − o
//   half_cleaner(j):  pairs (i, i + j) inside blocks of 2j
//   sort of blocks of k = 2, 4, …: flip(k), then half_cleaner(k/4), …, half_cleaner(1)
//
// Steps whose pairs stay inside LOCAL_BLOCK = 2 × WORKGROUP_SIZE elements run in workgroup
// memory (sort_local, merge_local); longer ones run one step per dispatch (merge_global).

struct BitonicParams {
    count: u32,
    // Block size k of the flip, or 0 for a half-cleaner step.
    flip_block: u32,
    // Distance j of a half-cleaner step.
    distance: u32,
    padding: u32,
}

@group(0) @binding(0) var<uniform> params: BitonicParams;
@group(0) @binding(1) var<storage, read_write> keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> values: array<u32>;

const LOCAL_BLOCK: u32 = 2u * WORKGROUP_SIZE;
const SENTINEL: u32 = 0xffffffffu;

var<workgroup> local_keys: array<u32, LOCAL_BLOCK>;
var<workgroup> local_values: array<u32, LOCAL_BLOCK>;

fn is_greater(key_a: u32, value_a: u32, key_b: u32, value_b: u32) -> bool {
    return key_a > key_b || (key_a == key_b && value_a > value_b);
}

// The pair (a, b), a < b, that thread `thread` compares in step (flip_block, distance).
fn pair_of(thread: u32, flip_block: u32, distance: u32) -> vec2<u32> {
    if flip_block != 0u {
        let half = flip_block / 2u;
        let start = (thread / half) * flip_block;
        let offset = thread % half;
        return vec2<u32>(start + offset, start + flip_block - 1u - offset);
    }
    let a = (thread / distance) * 2u * distance + thread % distance;
    return vec2<u32>(a, a + distance);
}

fn exchange_local(pair: vec2<u32>) {
    let key_a = local_keys[pair.x];
    let key_b = local_keys[pair.y];
    let value_a = local_values[pair.x];
    let value_b = local_values[pair.y];
    if is_greater(key_a, value_a, key_b, value_b) {
        local_keys[pair.x] = key_b;
        local_keys[pair.y] = key_a;
        local_values[pair.x] = value_b;
        local_values[pair.y] = value_a;
    }
}

fn load_block(base: u32, local: u32) {
    for (var half = 0u; half < 2u; half++) {
        let slot = half * WORKGROUP_SIZE + local;
        let index = base + slot;
        if index < params.count {
            local_keys[slot] = keys[index];
            local_values[slot] = values[index];
        } else {
            local_keys[slot] = SENTINEL;
            local_values[slot] = SENTINEL;
        }
    }
    workgroupBarrier();
}

fn store_block(base: u32, local: u32) {
    workgroupBarrier();
    for (var half = 0u; half < 2u; half++) {
        let slot = half * WORKGROUP_SIZE + local;
        if base + slot < params.count {
            keys[base + slot] = local_keys[slot];
            values[base + slot] = local_values[slot];
        }
    }
}

// Sorts each block of LOCAL_BLOCK elements.
@compute @workgroup_size(WORKGROUP_SIZE)
fn sort_local(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let base = flat_workgroup(workgroup, groups) * LOCAL_BLOCK;
    if base >= params.count {
        return;
    }
    load_block(base, local);
    for (var block = 2u; block <= LOCAL_BLOCK; block <<= 1u) {
        exchange_local(pair_of(local, block, 0u));
        workgroupBarrier();
        for (var distance = block / 4u; distance > 0u; distance >>= 1u) {
            exchange_local(pair_of(local, 0u, distance));
            workgroupBarrier();
        }
    }
    store_block(base, local);
}

// Half-cleaner steps of distance LOCAL_BLOCK / 2 down to 1.
@compute @workgroup_size(WORKGROUP_SIZE)
fn merge_local(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let base = flat_workgroup(workgroup, groups) * LOCAL_BLOCK;
    if base >= params.count {
        return;
    }
    load_block(base, local);
    for (var distance = LOCAL_BLOCK / 2u; distance > 0u; distance >>= 1u) {
        exchange_local(pair_of(local, 0u, distance));
        workgroupBarrier();
    }
    store_block(base, local);
}

// One step (flip or half-cleaner) over the whole array, one pair per thread.
@compute @workgroup_size(WORKGROUP_SIZE)
fn merge_global(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let thread = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    let pair = pair_of(thread, params.flip_block, params.distance);
    // Past `count` is +∞: nothing to exchange.
    if pair.y >= params.count {
        return;
    }
    let key_a = keys[pair.x];
    let key_b = keys[pair.y];
    let value_a = values[pair.x];
    let value_b = values[pair.y];
    if is_greater(key_a, value_a, key_b, value_b) {
        keys[pair.x] = key_b;
        keys[pair.y] = key_a;
        values[pair.x] = value_b;
        values[pair.y] = value_a;
    }
}
