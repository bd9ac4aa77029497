// Pair finding: one thread per leaf of the dynamic tree (a dynamic body) walks the dynamic
// tree, keeping pairs whose other leaf comes later in sorted (Morton) order, so each pair is
// found once, and the static tree, keeping every overlap. Two stackless walks, picked by entry
// point:
//
// - `traverse_history`: the talk's history flags. 2 bits per tree level record which
//   children of the node on the current path were entered; climbing resets the level's bits,
//   and a node whose both bits are set is left for its parent. A vec2<u32> holds 32 levels; an
//   internal node deeper than that (degenerate trees can be deeper: a run of equal codes
//   below 30 levels of code bits) has its subtree walked by escapes instead, after which the
//   walk climbs on.
// - `traverse_ropes`: escape indices: overlap → first child, else (or after a leaf) → escape.
//
// Pairs are appended with an atomic counter; the order is fixed afterwards by sorting the keys.
// A walk keeps the pairs it finds and appends them FOUND_BUFFER at a time, with one atomic for
// all of them: with one atomic a pair, all on the same counter, `traverse_ropes` took 0.30 ms
// on an H100 for the 584k pairs of a settled pile of 100k boxes, this 0.20.
// `append_extra` appends given pairs the same way (the host's resting pairs, whose bodies are
// both static to the trees, so no walk finds them), which the sort then merges in.
// A pair past `capacity` is counted but not written: the host sees count > capacity, grows the
// buffer and runs the stage again.
//
// Appended keys are packed: (lower body << body_bits) | higher body, 2 × body_bits bits, so
// the radix sort looks at 2 × body_bits bits instead of 32 + body_bits (4 passes instead of 6
// at 10 000 bodies). Packing keeps the order of pair keys. The u64::MAX padding, cut to those
// bits, is all ones, above every packed key (a body index is never all ones: it is below the
// body count). `unpack_keys` turns the sorted packed keys into pair keys, padding into padding.

struct TraverseParams {
    dynamic_leaves: u32,
    static_leaves: u32,
    capacity: u32,
    // Bit length of the body count, 1 to 32.
    body_bits: u32,
    // Pair keys in `extra`.
    extra_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: TraverseParams;
@group(0) @binding(1) var<storage, read> dynamic_nodes: array<u32>;
// Node boxes as (min, max) in the refit's order-preserving u32 codes (`lbvh_build.wgsl`).
@group(0) @binding(2) var<storage, read> dynamic_bounds: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> static_nodes: array<u32>;
@group(0) @binding(4) var<storage, read> static_bounds: array<vec4<u32>>;
// Packed u64 keys as (low word, high word).
@group(0) @binding(5) var<storage, read_write> keys: array<u32>;
@group(0) @binding(6) var<storage, read_write> count: array<atomic<u32>>;
// `unpack_keys`: sorted packed keys in, pair keys (higher body, lower body) out.
@group(0) @binding(7) var<storage, read> sorted_packed: array<u32>;
@group(0) @binding(8) var<storage, read_write> sorted_keys: array<u32>;
// `append_extra`: pair keys as (low word: higher body, high word: lower body); for
// `append_resting`, last step's keys, padded with NONE.
@group(0) @binding(9) var<storage, read> extra: array<vec2<u32>>;
// `append_resting`: bit b % 32 of word b / 32 is set when body b is static to the trees.
@group(0) @binding(10) var<storage, read> static_bits: array<u32>;

const NONE: u32 = 0xffffffffu;
const DYNAMIC: u32 = 0u;
const STATIC: u32 = 1u;
// Levels the history flags cover: 2 bits each in 64 bits.
const HISTORY_LEVELS: u32 = 32u;

// The thread's query: its dynamic body's box, index and sorted leaf position.
var<private> query_low: vec3<f32>;
var<private> query_high: vec3<f32>;
var<private> query_body: u32;
var<private> query_leaf: u32;

fn node_word(tree: u32, index: u32) -> u32 {
    if tree == DYNAMIC {
        return dynamic_nodes[index];
    }
    return static_nodes[index];
}

fn left_child(tree: u32, node: u32) -> u32 {
    return node_word(tree, 4u * node);
}

fn right_child(tree: u32, node: u32) -> u32 {
    return node_word(tree, 4u * node + 1u);
}

fn parent(tree: u32, node: u32) -> u32 {
    return node_word(tree, 4u * node + 2u);
}

fn escape(tree: u32, node: u32) -> u32 {
    return node_word(tree, 4u * node + 3u);
}

// The float of an order-preserving code: the inverse of `ordered` in lbvh_build.wgsl.
fn unordered(code: vec3<u32>) -> vec3<f32> {
    let sign = vec3<u32>(0x80000000u);
    return bitcast<vec3<f32>>(select(~code, code ^ sign, (code & sign) != vec3<u32>(0u)));
}

// Sorted position of the last leaf under `node` in the dynamic tree. The node after the
// subtree (its escape) starts at the next leaf: escapes are right children, whose index is the
// first leaf of their range (internal) or n - 1 + that leaf (leaf).
fn last_dynamic_leaf(node: u32) -> u32 {
    // n - 1: the index of leaf 0's node, and the position of the last leaf.
    let last = params.dynamic_leaves - 1u;
    let next = dynamic_nodes[4u * node + 3u];
    if next == NONE {
        return last;
    }
    return select(next, next - last, next >= last) - 1u;
}

// Whether the walk enters `node`: its box overlaps or touches the query's (as Aabb::overlaps)
// and, in the dynamic tree, its subtree holds a leaf sorted after the query's. So a dynamic
// pair is found from its first leaf only, never with the query itself, and the subtrees of
// earlier leaves (about half the tree) are skipped.
fn enters(tree: u32, node: u32) -> bool {
    if tree == DYNAMIC && last_dynamic_leaf(node) <= query_leaf {
        return false;
    }
    var low: vec3<f32>;
    var high: vec3<f32>;
    if tree == DYNAMIC {
        low = unordered(dynamic_bounds[2u * node].xyz);
        high = unordered(dynamic_bounds[2u * node + 1u].xyz);
    } else {
        low = unordered(static_bounds[2u * node].xyz);
        high = unordered(static_bounds[2u * node + 1u].xyz);
    }
    return all(low <= query_high) && all(query_low <= high);
}

// The other bodies of the query's pairs not yet appended: a walk appends them
// FOUND_BUFFER at a time, with one atomic for all of them.
const FOUND_BUFFER: u32 = 16u;
var<private> found: array<u32, FOUND_BUFFER>;
var<private> found_count: u32;

// A leaf the walk entered: its pair with the query.
fn report(tree: u32, node: u32) {
    found[found_count] = left_child(tree, node);
    found_count += 1u;
    if found_count == FOUND_BUFFER {
        flush_found();
    }
}

// Appends the query's found pairs.
fn flush_found() {
    if found_count == 0u {
        return;
    }
    let start = atomicAdd(&count[0], found_count);
    for (var i = 0u; i < found_count; i++) {
        let other = found[i];
        write_key(start + i, min(other, query_body), max(other, query_body));
    }
    found_count = 0u;
}

// Appends the pair of bodies `low` < `high`, packed, when it fits (it is counted either way).
fn append(low: u32, high: u32) {
    write_key(atomicAdd(&count[0], 1u), low, high);
}

// The pair of bodies `low` < `high`, packed, into key `slot` when it fits.
fn write_key(slot: u32, low: u32, high: u32) {
    if slot < params.capacity {
        if params.body_bits == 32u {
            keys[2u * slot] = high;
            keys[2u * slot + 1u] = low;
        } else {
            keys[2u * slot] = (low << params.body_bits) | high;
            keys[2u * slot + 1u] = low >> (32u - params.body_bits);
        }
    }
}

fn leaf_count(tree: u32) -> u32 {
    return select(params.static_leaves, params.dynamic_leaves, tree == DYNAMIC);
}

// The escape walk of the nodes from `start` until `stop` (exclusive).
fn walk_ropes(tree: u32, start: u32, stop: u32) {
    let first_leaf = leaf_count(tree) - 1u;
    var node = start;
    while node != stop {
        if enters(tree, node) {
            if node >= first_leaf {
                report(tree, node);
                node = escape(tree, node);
            } else {
                node = left_child(tree, node);
            }
        } else {
            node = escape(tree, node);
        }
    }
}

fn history_bits(history: vec2<u32>, level: u32) -> u32 {
    return (history[level / 16u] >> (2u * (level % 16u))) & 3u;
}

fn with_history_bit(history: vec2<u32>, level: u32, bit: u32) -> vec2<u32> {
    var updated = history;
    updated[level / 16u] |= bit << (2u * (level % 16u));
    return updated;
}

fn without_history_bits(history: vec2<u32>, level: u32) -> vec2<u32> {
    var updated = history;
    updated[level / 16u] &= ~(3u << (2u * (level % 16u)));
    return updated;
}

fn walk_history(tree: u32) {
    let first_leaf = leaf_count(tree) - 1u;
    var node = 0u;
    var level = 0u;
    var history = vec2<u32>(0u);
    loop {
        // A node at HISTORY_LEVELS is never descended from, so it has no bits (and the
        // vector no word for them).
        var bits = 0u;
        if level < HISTORY_LEVELS {
            bits = history_bits(history, level);
        }
        var descend = NONE;
        if bits == 0u {
            // Arrived from the parent.
            if enters(tree, node) {
                if node >= first_leaf {
                    report(tree, node);
                } else if level == HISTORY_LEVELS {
                    // No bits left for this node's children: walk its subtree by escapes.
                    walk_ropes(tree, left_child(tree, node), escape(tree, node));
                } else {
                    history = with_history_bit(history, level, 1u);
                    descend = left_child(tree, node);
                }
            }
        } else if bits == 1u {
            history = with_history_bit(history, level, 2u);
            descend = right_child(tree, node);
        }
        if descend != NONE {
            node = descend;
            level += 1u;
            continue;
        }
        // Both children done (or none to enter): reset this level and climb.
        if level < HISTORY_LEVELS {
            history = without_history_bits(history, level);
        }
        if level == 0u {
            return;
        }
        node = parent(tree, node);
        level -= 1u;
    }
}

fn set_query(leaf: u32) {
    let node = params.dynamic_leaves - 1u + leaf;
    query_low = unordered(dynamic_bounds[2u * node].xyz);
    query_high = unordered(dynamic_bounds[2u * node + 1u].xyz);
    query_body = dynamic_nodes[4u * node];
    query_leaf = leaf;
}

fn query_index(workgroup: vec3<u32>, groups: vec3<u32>, local: u32) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn traverse_history(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let leaf = query_index(workgroup, groups, local);
    if leaf >= params.dynamic_leaves {
        return;
    }
    set_query(leaf);
    walk_history(DYNAMIC);
    if params.static_leaves > 0u {
        walk_history(STATIC);
    }
    flush_found();
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn traverse_ropes(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let leaf = query_index(workgroup, groups, local);
    if leaf >= params.dynamic_leaves {
        return;
    }
    set_query(leaf);
    walk_ropes(DYNAMIC, 0u, NONE);
    if params.static_leaves > 0u {
        walk_ropes(STATIC, 0u, NONE);
    }
    flush_found();
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn append_extra(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = query_index(workgroup, groups, local);
    if index < params.extra_count {
        let key = extra[index];
        append(key.y, key.x);
    }
}

fn is_static_body(body: u32) -> bool {
    return ((static_bits[body >> 5u] >> (body & 31u)) & 1u) != 0u;
}

// Last step's pairs of two bodies static to the trees (sleeping bodies' resting pairs, which
// no tree walk finds), appended as `append_extra` appends the host's list of them.
@compute @workgroup_size(WORKGROUP_SIZE)
fn append_resting(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = query_index(workgroup, groups, local);
    if index < params.extra_count {
        let key = extra[index];
        // Padding is NONE in both words, never a body.
        if key.y != NONE && is_static_body(key.y) && is_static_body(key.x) {
            append(key.y, key.x);
        }
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn unpack_keys(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let slot = query_index(workgroup, groups, local);
    if slot >= params.capacity {
        return;
    }
    let word0 = sorted_packed[2u * slot];
    let word1 = sorted_packed[2u * slot + 1u];
    var low = word1;
    var high = word0;
    if word0 == NONE && word1 == NONE {
        // Padding stays u64::MAX.
    } else if params.body_bits < 32u {
        let bits = params.body_bits;
        high = word0 & ((1u << bits) - 1u);
        low = (word0 >> bits) | (word1 << (32u - bits));
    }
    sorted_keys[2u * slot] = high;
    sorted_keys[2u * slot + 1u] = low;
}
