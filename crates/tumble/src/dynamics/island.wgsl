// The islands' links on the device (dynamics/island_gpu.rs): the union-find of Islands::link
// over this step's touching pairs (a manifold with points) between two awake dynamic bodies,
// with the host's rule, the higher root linked under the lower. Each body therefore ends under
// its island's lowest body in any order of the links, as on the host: the same parents.

struct IslandParams {
    // Body slots.
    bodies: u32,
    // Pair slots covered: the broadphase's capacity; the count says how many are pairs.
    slots: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: IslandParams;
// Word 0: the pair count (the broadphase's).
@group(0) @binding(1) var<storage, read> count: array<u32>;
// Pair keys, u64 as two words: the two bodies.
@group(0) @binding(2) var<storage, read> keys: array<vec2<u32>>;
// Per pair: its point count and deepest penetration (stages/narrowphase/summary.wgsl).
@group(0) @binding(3) var<storage, read> summaries: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> masses: array<BodyMass>;
// Each body's parent in the union-find forest; after `flatten`, its island's lowest body.
@group(0) @binding(5) var<storage, read_write> parent: array<atomic<u32>>;

// The root of `start`, halving the path on the way. Parents only move to lower bodies of the
// same tree, so a parent read while another thread changes it is still an ancestor.
fn root(start: u32) -> u32 {
    var body = start;
    var up = atomicLoad(&parent[body]);
    while up != body {
        let grandparent = atomicLoad(&parent[up]);
        if grandparent != up {
            // Fails when another thread moved the parent already: either is an ancestor.
            _ = atomicCompareExchangeWeak(&parent[body], up, grandparent);
        }
        body = grandparent;
        up = atomicLoad(&parent[body]);
    }
    return body;
}

// Joins the trees of `a` and `b`, the higher root under the lower; retried from the new roots
// when another thread linked one of them first (or the weak exchange failed).
fn join(a: u32, b: u32) {
    var ends = vec2<u32>(a, b);
    loop {
        let root_a = root(ends.x);
        let root_b = root(ends.y);
        if root_a == root_b {
            break;
        }
        let high = max(root_a, root_b);
        if atomicCompareExchangeWeak(&parent[high], high, min(root_a, root_b)).exchanged {
            break;
        }
        ends = vec2<u32>(root_a, root_b);
    }
}

fn awake(body: u32) -> bool {
    return masses[body].inverse_mass > 0.0;
}

// Every body on its own.
@compute @workgroup_size(WORKGROUP_SIZE)
fn unlink(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body < params.bodies {
        atomicStore(&parent[body], body);
    }
}

// A thread a pair slot.
@compute @workgroup_size(WORKGROUP_SIZE)
fn link(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    // The point count first: most pairs of a pile have none.
    if index >= params.slots || index >= count[0] || summaries[index].x == 0u {
        return;
    }
    let key = keys[index];
    if awake(key.x) && awake(key.y) {
        join(key.x, key.y);
    }
}

// Every body straight under its root, once every link is made (a dispatch later): roots no
// longer change, so each body's last store is its root.
@compute @workgroup_size(WORKGROUP_SIZE)
fn flatten(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body < params.bodies {
        atomicStore(&parent[body], root(body));
    }
}
