// Stage 4 on the GPU: the twin of `update_contacts` in mod.rs. Reads the pair keys (u64 as
// two words, low word first: the higher body index, then the lower), the bodies, last step's
// contacts through the old-index map, and writes this step's contacts. Three dispatches:
// `clear_misses`; `move_cached`, a thread per pair, which clears the pairs that get no
// contacts and moves the manifolds whose cache holds (mod.rs `cache_holds`), and lists the
// others; `update_contacts`, over the listed pairs, which runs their pair functions. The list
// keeps the pair functions' warps full: with nine pairs in ten moved, nearly every warp of
// one thread per pair would hold a pair to compute, and wait for it. A pair's contact depends
// on nothing but its own inputs, so the list's order (atomics) changes no result.
// `update_contacts` is in collide.wgsl, the pair functions in contact_round.wgsl,
// contact_box_box.wgsl and contact_hull.wgsl; a new pair type is one more function and one
// more arm of `collide_ordered`.

struct NarrowphaseParams {
    pair_count: u32,
    skipped_count: u32,
    // Speculative distance at rest (m).
    margin: f32,
    // Step length (s).
    dt: f32,
}

@group(0) @binding(0) var<uniform> params: NarrowphaseParams;
@group(0) @binding(1) var<storage, read> keys: array<vec2<u32>>;
// Index of each pair in last step's contacts, or NEW_PAIR.
@group(0) @binding(2) var<storage, read> old_index: array<u32>;
// Binding 3, last step's contacts, and 9, this step's: in move.wgsl as words, in collide.wgsl
// as PairContact.
@group(0) @binding(4) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(5) var<storage, read> velocities: array<BodyVelocity>;
@group(0) @binding(6) var<storage, read> colliders: array<ColliderData>;
// Sorted keys of pairs that get no contacts (jointed bodies).
@group(0) @binding(7) var<storage, read> skipped: array<vec2<u32>>;
// The colliders' polyhedra: `pack_hulls` in gpu.rs.
@group(0) @binding(8) var<storage, read> hulls: array<u32>;
// Binding 10, the pairs left to the pair functions (their count, then their indices): atomic
// in move.wgsl, which makes the list, plain in collide.wgsl, which reads it.

const NEW_PAIR: u32 = 0xffffffffu;

// mod.rs `cacheable`: pairs of two polyhedra keep a ManifoldCache.
fn cacheable(a: u32, b: u32) -> bool {
    return polyhedron(colliders[a].kind) && polyhedron(colliders[b].kind);
}

fn polyhedron(kind: u32) -> bool {
    return kind == SHAPE_CUBOID || kind == SHAPE_PLANE || kind == SHAPE_CONVEX_HULL;
}

// mod.rs `relative_pose`: body B's pose in body A's frame.
fn relative_pose(pose_a: BodyPose, pose_b: BodyPose) -> BodyPose {
    let inverse = quat_conjugate(pose_a.rotation);
    return BodyPose(
        quat_rotate(inverse, pose_b.position - pose_a.position),
        0.0,
        quat_mul(inverse, pose_b.rotation),
    );
}

// Binary search of `skipped`, comparing keys as u64 (high word, the lower body, first).
fn is_skipped(key: vec2<u32>) -> bool {
    var low = 0u;
    var high = params.skipped_count;
    while low < high {
        let middle = low + (high - low) / 2u;
        let probe = skipped[middle];
        if probe.y < key.y || (probe.y == key.y && probe.x < key.x) {
            low = middle + 1u;
        } else {
            high = middle;
        }
    }
    return low < params.skipped_count && all(skipped[low] == key);
}

// mod.rs `closing_speed_bound`: relative speed of the centres plus each spin times its
// shape's bounding radius (m/s).
fn closing_speed_bound(a: u32, b: u32) -> f32 {
    let velocity_a = velocities[a];
    let velocity_b = velocities[b];
    let relative = velocity_a.linear - velocity_b.linear;
    return sqrt(dot3(relative, relative))
        + sqrt(dot3(velocity_a.angular, velocity_a.angular)) * colliders[a].bounding_radius
        + sqrt(dot3(velocity_b.angular, velocity_b.angular)) * colliders[b].bounding_radius;
}
