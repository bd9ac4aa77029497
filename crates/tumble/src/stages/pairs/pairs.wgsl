// The pair cache's diff on the GPU: both key lists are sorted ascending (u64 keys as
// (low word, high word)); either may end in u64::MAX padding (the broadphase's unused slots),
// which is never a pair. Thread i looks up new key i among the old keys (its old index, or
// NONE: added) and old key i among the new keys (flagged when absent: removed), by binary
// search, so the result does not depend on thread order.

struct DiffParams {
    new_count: u32,
    old_count: u32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: DiffParams;
@group(0) @binding(1) var<storage, read> old_keys: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> new_keys: array<vec2<u32>>;
// Per new key: index of the same key among the old keys, or NONE.
@group(0) @binding(3) var<storage, read_write> old_index: array<u32>;
// Per new key: 1 when added. Per old key: 1 when removed.
@group(0) @binding(4) var<storage, read_write> added_flags: array<u32>;
@group(0) @binding(5) var<storage, read_write> removed_flags: array<u32>;

const NONE: u32 = 0xffffffffu;

fn is_padding(key: vec2<u32>) -> bool {
    return all(key == vec2<u32>(NONE));
}

fn less(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}

// Index of `key` among the first `count` old keys (new keys when !in_old), or NONE.
fn find(key: vec2<u32>, in_old: bool, count: u32) -> u32 {
    var low = 0u;
    var high = count;
    while low < high {
        let middle = low + (high - low) / 2u;
        var probe: vec2<u32>;
        if in_old {
            probe = old_keys[middle];
        } else {
            probe = new_keys[middle];
        }
        if less(probe, key) {
            low = middle + 1u;
        } else {
            high = middle;
        }
    }
    if low < count {
        var found: vec2<u32>;
        if in_old {
            found = old_keys[low];
        } else {
            found = new_keys[low];
        }
        if all(found == key) {
            return low;
        }
    }
    return NONE;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn diff_keys(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index < params.new_count {
        let key = new_keys[index];
        var previous = NONE;
        if !is_padding(key) {
            previous = find(key, true, params.old_count);
        }
        old_index[index] = previous;
        added_flags[index] = select(0u, 1u, previous == NONE && !is_padding(key));
    }
    if index < params.old_count {
        let key = old_keys[index];
        removed_flags[index] = select(
            0u,
            1u,
            !is_padding(key) && find(key, false, params.new_count) == NONE,
        );
    }
}
