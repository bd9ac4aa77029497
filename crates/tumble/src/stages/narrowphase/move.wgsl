// Stage 4's first kernels on the GPU (see narrowphase.wgsl): `clear_misses`, then
// `move_cached`, which settles the pairs that need no pair function and lists the others. The
// contacts are read and written as their 16 words of 16 bytes (CONTACT_WORDS, the layout of
// PairContact): a moved manifold changes its normal and its points' positions and separations,
// and copies the rest of what it uses a word at a time. On an H100, on a settled pile of 100k
// boxes, this kernel took 0.99 ms a step written with PairContact structs (a store per field,
// and the padding zeroed whole), 0.62 with the padding's count alone written, 0.53 in words,
// 0.35 with the words of unused point slots left alone.

@group(0) @binding(3) var<storage, read> old_contacts: array<vec4<u32>>;
@group(0) @binding(9) var<storage, read_write> contacts: array<vec4<u32>>;
@group(0) @binding(10) var<storage, read_write> misses: array<atomic<u32>>;

// Words of a PairContact (CONTACT_WORDS, from gpu.rs, which checks the layout): the manifold's
// normal and count, two a point from POINTS_WORD (position and separation, anchor and id), the
// impulses from IMPULSES_WORD, then the cache from CACHE_WORD (position and margin, rotation,
// normal and valid, separations).

@compute @workgroup_size(1)
fn clear_misses() {
    atomicStore(&misses[0], 0u);
}

var<workgroup> group_misses: atomic<u32>;
var<workgroup> group_start: u32;

@compute @workgroup_size(WORKGROUP_SIZE)
fn move_cached(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if local == 0u {
        atomicStore(&group_misses, 0u);
    }
    workgroupBarrier();
    let missed = index < params.pair_count && !settle_without_pair_function(index);
    var slot = 0u;
    if missed {
        slot = atomicAdd(&group_misses, 1u);
    }
    // One global atomic a workgroup: its misses take consecutive entries.
    workgroupBarrier();
    if local == 0u {
        group_start = atomicAdd(&misses[0], atomicLoad(&group_misses));
    }
    workgroupBarrier();
    let start = group_start;
    if missed {
        atomicStore(&misses[1u + start + slot], index);
    }
}

// Whether pair `index` got its contact here: none (padding, a jointed pair) or its manifold
// moved from last step's.
fn settle_without_pair_function(index: u32) -> bool {
    let key = keys[index];
    // Padding past the GPU broadphase's pair count (its keys come in their whole buffer): no
    // points is all a later kernel reads there (half a million slots on a pile of 100k boxes).
    if all(key == vec2<u32>(0xffffffffu, 0xffffffffu)) {
        contacts[index * CONTACT_WORDS] = vec4<u32>(0u);
        return true;
    }
    if is_skipped(key) {
        for (var word = 0u; word < CONTACT_WORDS; word++) {
            contacts[index * CONTACT_WORDS + word] = vec4<u32>(0u);
        }
        return true;
    }
    let a = key.y;
    let b = key.x;
    let old = old_index[index];
    if old == NEW_PAIR || !cacheable(a, b) {
        return false;
    }
    let pose_a = poses[a];
    let relative = relative_pose(pose_a, poses[b]);
    let margin = params.margin + params.dt * closing_speed_bound(a, b);
    let cache = load_cache(old);
    if !cache_holds(cache, relative, margin, a, b) {
        return false;
    }
    rebuild(index, old, cache, pose_a, relative);
    return true;
}

// ManifoldCache of last step's contact `old`.
fn load_cache(old: u32) -> ManifoldCache {
    let at = old * CONTACT_WORDS + CACHE_WORD;
    let position = bitcast<vec4<f32>>(old_contacts[at]);
    let normal = bitcast<vec4<f32>>(old_contacts[at + 2u]);
    return ManifoldCache(
        position.xyz,
        position.w,
        bitcast<vec4<f32>>(old_contacts[at + 1u]),
        normal.xyz,
        old_contacts[at + 2u].w,
        bitcast<vec4<f32>>(old_contacts[at + 3u]),
    );
}

// mod.rs `cache_holds`, with `cache_radius`: whether `cache` may move its manifold to
// `relative` for `margin`, bodies `a` and `b` (a plane's points near the other body may lie
// anywhere: no bound from its side).
fn cache_holds(cache: ManifoldCache, relative: BodyPose, margin: f32, a: u32, b: u32) -> bool {
    // Negated as the CPU writes it, so that a NaN margin holds on neither.
    if cache.valid == 0u || !(margin <= cache.margin + CACHE_TOLERANCE) {
        return false;
    }
    let turn = quat_mul(relative.rotation, quat_conjugate(cache.rotation));
    let chord = 2.0 * sqrt(dot3(turn.xyz, turn.xyz));
    var moved = 3.40282347e38;
    let collider_b = colliders[b];
    if collider_b.kind != SHAPE_PLANE {
        let offset = relative.position - cache.position;
        moved = min(moved, sqrt(dot3(offset, offset)) + chord * collider_b.bounding_radius);
    }
    let collider_a = colliders[a];
    if collider_a.kind != SHAPE_PLANE {
        let now = quat_rotate(quat_conjugate(relative.rotation), relative.position);
        let then = quat_rotate(quat_conjugate(cache.rotation), cache.position);
        let offset = then - now;
        moved = min(moved, sqrt(dot3(offset, offset)) + chord * collider_a.bounding_radius);
    }
    return moved <= CACHE_TOLERANCE;
}

// mod.rs `rebuild`: last step's contact `old` moved to the bodies' poses into contacts[index],
// each point's side on A fixed in A and its side on B in B. Only the words that hold the
// manifold's points are read and written: the normal and count, the points, their impulses
// and the cache. The point slots past the count and their impulses are left as the buffer had
// them, since no kernel reads them (the host zeroes them when it reads the contacts back,
// `PairContact::clear_unused`). Half the pairs of a pile have no points: copying their whole
// contacts took 0.53 ms a step on an H100 at 100k boxes, this 0.35.
fn rebuild(index: u32, old: u32, cache: ManifoldCache, pose_a: BodyPose, relative: BodyPose) {
    let old_first = old * CONTACT_WORDS;
    let first = index * CONTACT_WORDS;
    let count = min(old_contacts[old_first].w, MAX_MANIFOLD_POINTS);
    let normal = quat_rotate(pose_a.rotation, cache.normal);
    contacts[first] = vec4<u32>(bitcast<vec3<u32>>(normal), count);
    let inverse = quat_conjugate(cache.rotation);
    for (var point = 0u; point < count; point++) {
        let at = POINTS_WORD + 2u * point;
        let anchor_id = old_contacts[old_first + at + 1u];
        let anchor = bitcast<vec3<f32>>(anchor_id.xyz);
        let half = cache.normal * (0.5 * cache.separations[point]);
        let on_a = anchor + half;
        let on_b_in_b = quat_rotate(inverse, anchor - half - cache.position);
        let on_b = relative.position + quat_rotate(relative.rotation, on_b_in_b);
        let moved = pose_a.position + quat_rotate(pose_a.rotation, (on_a + on_b) * 0.5);
        let separation = dot3(on_a - on_b, cache.normal);
        contacts[first + at] = bitcast<vec4<u32>>(vec4<f32>(moved, separation));
        contacts[first + at + 1u] = anchor_id;
    }
    // The impulses of the points (12 bytes each, packed in 16-byte words) and the cache, as
    // they were.
    let impulse_words = (3u * count + 3u) / 4u;
    for (var word = IMPULSES_WORD; word < IMPULSES_WORD + impulse_words; word++) {
        contacts[first + word] = old_contacts[old_first + word];
    }
    for (var word = CACHE_WORD; word < CONTACT_WORDS; word++) {
        contacts[first + word] = old_contacts[old_first + word];
    }
}
