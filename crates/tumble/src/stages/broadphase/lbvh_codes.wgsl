// LBVH build, part 1: the bounds of the leaves' AABB centres (a two-level reduce), then one
// 30-bit Morton code per leaf, in those bounds, for the radix sort.
//
// `scene` holds the result at [0] (min) and [1] (max), and the per-workgroup partial results
// from [2]: partial p at [2 + 2p] (min) and [3 + 2p] (max). Min and max do not depend on the
// order of combination, so the bounds (and the codes) are the same every run.

struct CodeParams {
    leaf_count: u32,
    partial_count: u32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: CodeParams;
// Every body's AABB, 6 floats (min, max), indexed by body.
@group(0) @binding(1) var<storage, read> aabbs: array<f32>;
// The bodies of this tree, ascending.
@group(0) @binding(2) var<storage, read> bodies: array<u32>;
@group(0) @binding(3) var<storage, read_write> scene: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> codes: array<u32>;

const ITEMS_PER_THREAD: u32 = 4u;
const BLOCK: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;

var<workgroup> low: array<vec3<f32>, WORKGROUP_SIZE>;
var<workgroup> high: array<vec3<f32>, WORKGROUP_SIZE>;

fn infinity() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

fn centre(leaf: u32) -> vec3<f32> {
    let base = bodies[leaf] * 6u;
    let lo = vec3<f32>(aabbs[base], aabbs[base + 1u], aabbs[base + 2u]);
    let hi = vec3<f32>(aabbs[base + 3u], aabbs[base + 4u], aabbs[base + 5u]);
    return (lo + hi) * 0.5;
}

// Halving tree over the workgroup's partial bounds; thread 0 holds the result.
fn reduce_workgroup(local: u32) {
    workgroupBarrier();
    for (var stride = WORKGROUP_SIZE / 2u; stride > 0u; stride >>= 1u) {
        if local < stride {
            low[local] = min(low[local], low[local + stride]);
            high[local] = max(high[local], high[local + stride]);
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn bounds_partial(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    if block >= params.partial_count {
        return;
    }
    var lo = vec3<f32>(infinity());
    var hi = vec3<f32>(-infinity());
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let leaf = block * BLOCK + item * WORKGROUP_SIZE + local;
        if leaf < params.leaf_count {
            let c = centre(leaf);
            lo = min(lo, c);
            hi = max(hi, c);
        }
    }
    low[local] = lo;
    high[local] = hi;
    reduce_workgroup(local);
    if local == 0u {
        scene[2u + 2u * block] = vec4<f32>(low[0], 0.0);
        scene[3u + 2u * block] = vec4<f32>(high[0], 0.0);
    }
}

// One workgroup folds all partials.
@compute @workgroup_size(WORKGROUP_SIZE)
fn bounds_final(@builtin(local_invocation_index) local: u32) {
    var lo = vec3<f32>(infinity());
    var hi = vec3<f32>(-infinity());
    for (var partial = local; partial < params.partial_count; partial += WORKGROUP_SIZE) {
        lo = min(lo, scene[2u + 2u * partial].xyz);
        hi = max(hi, scene[3u + 2u * partial].xyz);
    }
    low[local] = lo;
    high[local] = hi;
    reduce_workgroup(local);
    if local == 0u {
        scene[0] = vec4<f32>(low[0], 0.0);
        scene[1] = vec4<f32>(high[0], 0.0);
    }
}

// The 10 low bits of v spread to every third bit.
fn spread_bits(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn morton(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let leaf = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if leaf >= params.leaf_count {
        return;
    }
    let lo = scene[0].xyz;
    let extent = scene[1].xyz - lo;
    // A flat axis (all centres equal on it) contributes 0 bits of order.
    let scale = select(vec3<f32>(1024.0) / extent, vec3<f32>(0.0), extent <= vec3<f32>(0.0));
    let cell = min(vec3<u32>(max((centre(leaf) - lo) * scale, vec3<f32>(0.0))), vec3<u32>(1023u));
    codes[leaf] = (spread_bits(cell.x) << 2u) | (spread_bits(cell.y) << 1u) | spread_bits(cell.z);
}
