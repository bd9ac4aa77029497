// What the step needs of the contact rows before they are built (stages/constraints/tally.rs):
// over the pairs, how many touch (a manifold with points), how many of those get a row (one
// of the bodies moves, `has_constraint` in rows.wgsl), how many rows bounce, for the step's
// statistics the rows' points and the deepest penetration, and for the pair cache how many
// pairs were last step's too (the lookup found them). Each workgroup sums (and maxes) its pairs
// in shared memory and adds its results to the totals: integer sums and maxima, the same in
// any order. The totals' buffer has two more words past these, copied in after the pass so
// that one read-back brings every count: the wake test's candidates (dynamics/wake.rs) and
// the pairs the narrowphase computed (tally.rs).

// Word 0: the pair count (the broadphase's); the keys past it are padding.
@group(0) @binding(0) var<storage, read> count: array<u32>;
// Pair keys, u64 as two words, low word first: the higher body index, then the lower.
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
// Per pair: its point count and deepest penetration (stages/narrowphase/summary.wgsl).
@group(0) @binding(2) var<storage, read> summaries: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> masses: array<BodyMass>;
@group(0) @binding(4) var<storage, read> colliders: array<ColliderData>;
// Touching pairs, rows, bouncing rows, the rows' points, the deepest penetration (f32 bits, a
// depth being >= 0), pairs kept from last step, the wake test's candidates; zero before the
// dispatch.
@group(0) @binding(5) var<storage, read_write> totals: array<atomic<u32>, 7>;
// Per pair: its index among last step's pairs, or NONE (stages/pairs/pairs.wgsl).
@group(0) @binding(6) var<storage, read> old_index: array<u32>;

const NONE: u32 = 0xffffffffu;

var<workgroup> sums: array<vec4<u32>, WORKGROUP_SIZE>;
var<workgroup> deepest: array<u32, WORKGROUP_SIZE>;
var<workgroup> kept: array<u32, WORKGROUP_SIZE>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn tally_rows(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    var tally = vec4<u32>(0u);
    var depth = 0u;
    kept[local] = select(0u, 1u, index < count[0] && old_index[index] != NONE);
    if index < count[0] && summaries[index].x > 0u {
        let summary = summaries[index];
        tally.x = 1u;
        // A depth of -0 counts as 0, as on the host: the sign bit cleared.
        depth = summary.y & 0x7fffffffu;
        let key = keys[index];
        let a = key.y;
        let b = key.x;
        if masses[a].inverse_mass != 0.0 || masses[b].inverse_mass != 0.0 {
            tally.y = 1u;
            tally.w = summary.x;
            // The rows' restitution is the larger of the two.
            if max(colliders[a].restitution, colliders[b].restitution) > 0.0 {
                tally.z = 1u;
            }
        }
    }
    sums[local] = tally;
    deepest[local] = depth;
    workgroupBarrier();
    for (var stride = WORKGROUP_SIZE / 2u; stride > 0u; stride /= 2u) {
        if local < stride {
            sums[local] += sums[local + stride];
            deepest[local] = max(deepest[local], deepest[local + stride]);
            kept[local] += kept[local + stride];
        }
        workgroupBarrier();
    }
    if local == 0u && sums[0].x != 0u {
        atomicAdd(&totals[0], sums[0].x);
        atomicAdd(&totals[1], sums[0].y);
        atomicAdd(&totals[2], sums[0].z);
        atomicAdd(&totals[3], sums[0].w);
        atomicMax(&totals[4], deepest[0]);
    }
    if local == 0u && kept[0] != 0u {
        atomicAdd(&totals[5], kept[0]);
    }
}
