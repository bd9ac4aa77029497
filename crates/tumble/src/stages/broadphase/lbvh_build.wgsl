// LBVH build, part 2, after the radix sort of (Morton code, body) pairs: Karras' binary radix
// tree (2012, "Maximizing parallelism in the construction of BVHs, octrees and k-d trees"),
// then a bottom-up refit of the node boxes and the escape ("rope") of every node.
//
// Nodes: n leaves, n - 1 internal nodes. Internal node i is node i (the root is node 0);
// sorted leaf k is node n - 1 + k (with one leaf, the root is that leaf). `nodes` holds 4
// words per node: internal (left child, right child, parent, escape); leaf (body, 0, parent,
// escape). The escape is the next node of a depth-first, left-first walk once the node's
// subtree is done (NONE after the last). `bounds` holds 8 words per node: min xyz, 0, max xyz,
// 0, each float in the order-preserving u32 code of `ordered` (decoded by the traversal).
// `ends` holds, per internal node, the other end of its leaf range (the node's index is one).
//
// Equal codes are ordered by leaf position (the sort is stable and its input ascends by body),
// and `prefix` breaks their ties by position, so every split is well defined and the tree is
// the same every run.
//
// The refit climbs from every leaf with atomicMin / atomicMax on the ordered codes, rather than
// handing finished child boxes to the second visitor of a node through a visit counter: WGSL's
// atomics are relaxed (naga emits no memory semantics), so a counter does not order the first
// visitor's box writes before the second visitor's reads on every device. Min and max need no
// ordering: each word ends as the min (max) over its subtree whatever the interleaving, so the
// boxes are exact and the same every run. A thread stops pushing a word as soon as the node
// already held a value at least as tight: the thread that put it there climbs on with it.

struct BuildParams {
    leaf_count: u32,
    padding0: u32,
    padding1: u32,
    padding2: u32,
}

@group(0) @binding(0) var<uniform> params: BuildParams;
@group(0) @binding(1) var<storage, read> aabbs: array<f32>;
@group(0) @binding(2) var<storage, read> sorted_codes: array<u32>;
@group(0) @binding(3) var<storage, read> sorted_bodies: array<u32>;
@group(0) @binding(4) var<storage, read_write> nodes: array<u32>;
@group(0) @binding(5) var<storage, read_write> bounds: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> ends: array<u32>;

const NONE: u32 = 0xffffffffu;

// Length of the common prefix of the (code, position) keys of leaves i and j; -1 when j is
// outside the leaves.
fn prefix(i: i32, j: i32) -> i32 {
    if j < 0 || j >= i32(params.leaf_count) {
        return -1;
    }
    let a = sorted_codes[i];
    let b = sorted_codes[j];
    if a == b {
        return 32 + i32(countLeadingZeros(u32(i) ^ u32(j)));
    }
    return i32(countLeadingZeros(a ^ b));
}

// One thread per internal node: its leaf range and split (Karras, section 4).
@compute @workgroup_size(WORKGROUP_SIZE)
fn build_internal(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let node = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    let internal_count = params.leaf_count - 1u;
    if params.leaf_count < 2u || node >= internal_count {
        return;
    }
    let i = i32(node);
    // Direction of the range: towards the neighbour sharing the longer prefix.
    let d = select(-1, 1, prefix(i, i + 1) > prefix(i, i - 1));
    let shortest = prefix(i, i - d);
    // Upper bound of the range's length, then its exact length by binary search.
    var bound = 2;
    while prefix(i, i + bound * d) > shortest {
        bound *= 2;
    }
    var length = 0;
    for (var half = bound / 2; half >= 1; half /= 2) {
        if prefix(i, i + (length + half) * d) > shortest {
            length += half;
        }
    }
    let j = i + length * d;
    // The split: the last leaf sharing more than the node's prefix with i.
    let node_prefix = prefix(i, j);
    var split = 0;
    var step = length;
    loop {
        step = (step + 1) / 2;
        if prefix(i, i + (split + step) * d) > node_prefix {
            split += step;
        }
        if step <= 1 {
            break;
        }
    }
    let gamma = u32(i + split * d + min(d, 0));
    let first = u32(min(i, j));
    let last = u32(max(i, j));
    let left = select(gamma, internal_count + gamma, first == gamma);
    let right = select(gamma + 1u, internal_count + gamma + 1u, last == gamma + 1u);
    nodes[4u * node] = left;
    nodes[4u * node + 1u] = right;
    nodes[4u * left + 2u] = node;
    nodes[4u * right + 2u] = node;
    if node == 0u {
        nodes[2u] = NONE;
    }
    ends[node] = u32(j);
    // The identities of min and max, which the refit's leaves tighten.
    for (var axis = 0u; axis < 3u; axis++) {
        atomicStore(&bounds[8u * node + axis], 0xffffffffu);
        atomicStore(&bounds[8u * node + 4u + axis], 0u);
    }
}

// The node after the subtree whose leaf range ends at leaf `last`: the right sibling of the
// deepest left child on the way up, which is the node whose range starts at last + 1 and is a
// right child. Right children are internal node γ + 1 or leaf γ + 1 of their parent's split
// γ = last; internal node last + 1 is that child exactly when its range extends to the right
// of it (otherwise it ends at last + 1 and is a left child elsewhere).
fn escape_after(last: u32) -> u32 {
    let n = params.leaf_count;
    if last + 1u >= n {
        return NONE;
    }
    let next = last + 1u;
    if next < n - 1u && ends[next] > next {
        return next;
    }
    return n - 1u + next;
}

// f32 → u32 keeping the order (for non-NaN values): flip all bits of a negative float, only
// the sign bit of a positive one.
fn ordered(value: vec3<f32>) -> vec3<u32> {
    let bits = bitcast<vec3<u32>>(value);
    return select(bits | vec3<u32>(0x80000000u), ~bits, (bits & vec3<u32>(0x80000000u)) != vec3<u32>(0u));
}

// One thread per leaf: writes the leaf and the escapes of leaf k and internal node k, then
// climbs, tightening each ancestor's box word by word until none of its six words tightens.
@compute @workgroup_size(WORKGROUP_SIZE)
fn refit(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let leaf = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    let n = params.leaf_count;
    if leaf >= n {
        return;
    }
    let node = n - 1u + leaf;
    let body = sorted_bodies[leaf];
    let base = body * 6u;
    let low = ordered(vec3<f32>(aabbs[base], aabbs[base + 1u], aabbs[base + 2u]));
    let high = ordered(vec3<f32>(aabbs[base + 3u], aabbs[base + 4u], aabbs[base + 5u]));
    for (var axis = 0u; axis < 3u; axis++) {
        atomicStore(&bounds[8u * node + axis], low[axis]);
        atomicStore(&bounds[8u * node + 4u + axis], high[axis]);
    }
    nodes[4u * node] = body;
    nodes[4u * node + 1u] = 0u;
    nodes[4u * node + 3u] = escape_after(leaf);
    if n == 1u {
        // The leaf is the root.
        nodes[2u] = NONE;
        return;
    }
    if leaf < n - 1u {
        nodes[4u * leaf + 3u] = escape_after(max(leaf, ends[leaf]));
    }
    // Bit w set: word w (min x, y, z, max x, y, z) still tightens the ancestors.
    var open = 0x3fu;
    var current = nodes[4u * node + 2u];
    loop {
        for (var axis = 0u; axis < 3u; axis++) {
            if (open & (1u << axis)) != 0u
                && atomicMin(&bounds[8u * current + axis], low[axis]) <= low[axis] {
                open &= ~(1u << axis);
            }
            if (open & (8u << axis)) != 0u
                && atomicMax(&bounds[8u * current + 4u + axis], high[axis]) >= high[axis] {
                open &= ~(8u << axis);
            }
        }
        if open == 0u || current == 0u {
            return;
        }
        current = nodes[4u * current + 2u];
    }
}
