// The wake test's pass over the pairs, on the device (dynamics/wake.rs): flags each touching
// pair (a manifold with points) with a sleeping body, the only pairs that can wake an island.
// The compaction of the flags (gpu/prims/compact) then lists them in pair order, as the host's
// filter does.

struct WakeParams {
    // Pair slots flagged: the broadphase's capacity, what the compaction scans.
    slots: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(5) var<uniform> params: WakeParams;
// Word 0: the pair count (the broadphase's); the keys past it are padding.
@group(0) @binding(0) var<storage, read> count: array<u32>;
// Pair keys, u64 as two words, low word first: the higher body index, then the lower.
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
// Per pair: its point count and deepest penetration (stages/narrowphase/summary.wgsl).
@group(0) @binding(2) var<storage, read> summaries: array<vec2<u32>>;
// Bit b % 32 of word b / 32: body b sleeps (Islands::asleep_bits).
@group(0) @binding(3) var<storage, read> asleep: array<u32>;
// Per pair slot up to the capacity: 1 for a candidate, else 0.
@group(0) @binding(4) var<storage, read_write> flags: array<u32>;
@group(0) @binding(6) var<storage, read> masses: array<BodyMass>;
// Set where a candidate wakes an island at once: a body that moves (a sleeping one has no
// mass) touches a sleeping one, as the first round of World::wake_touched finds; zero before
// the dispatch. A step submitted before the host read the collision holds only where none
// did (pipeline/gpu_stages/held.wgsl).
@group(0) @binding(7) var<storage, read_write> wakers: array<atomic<u32>, 1>;

fn is_asleep(body: u32) -> bool {
    return ((asleep[body >> 5u] >> (body & 31u)) & 1u) != 0u;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn flag_wake_candidates(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.slots {
        return;
    }
    var flag = 0u;
    // The point count first: most pairs of a pile have none.
    if index < count[0] && summaries[index].x > 0u {
        let key = keys[index];
        flag = select(0u, 1u, is_asleep(key.x) || is_asleep(key.y));
        let moves = vec2<bool>(masses[key.x].inverse_mass > 0.0, masses[key.y].inverse_mass > 0.0);
        if (moves.x && is_asleep(key.y)) || (moves.y && is_asleep(key.x)) {
            atomicMax(&wakers[0], 1u);
        }
    }
    flags[index] = flag;
}
