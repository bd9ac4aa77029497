// Stage 4 on the GPU: the twin of `update_contacts` in mod.rs. Reads the pair keys (u64 as
// two words, low word first: the higher body index, then the lower), the bodies, last step's
// contacts through the old-index map, and writes this step's contacts. Three dispatches:
// `clear_misses`; `move_cached`, a thread per pair, which clears the pairs that get no
// contacts and moves the manifolds whose cache holds (mod.rs `cache_holds`), and lists the
// others; `update_contacts`, a thread per listed pair, which runs the pair function. The list
// keeps the pair functions' warps full: with nine pairs in ten moved, nearly every warp of
// one thread per pair would hold a pair to compute, and wait for it. A pair's contact depends
// on nothing but its own inputs, so the list's order (atomics) changes no result.
// The pair functions are in contact_round.wgsl, contact_box_box.wgsl and contact_hull.wgsl; a
// new pair type is one more function and one more arm of `collide_ordered`.

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
@group(0) @binding(3) var<storage, read> old_contacts: array<PairContact>;
@group(0) @binding(4) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(5) var<storage, read> velocities: array<BodyVelocity>;
@group(0) @binding(6) var<storage, read> colliders: array<ColliderData>;
// Sorted keys of pairs that get no contacts (jointed bodies).
@group(0) @binding(7) var<storage, read> skipped: array<vec2<u32>>;
// The colliders' polyhedra: `pack_hulls` in gpu.rs.
@group(0) @binding(8) var<storage, read> hulls: array<u32>;
@group(0) @binding(9) var<storage, read_write> contacts: array<PairContact>;
// The pairs left to the pair functions: their count, then their indices.
@group(0) @binding(10) var<storage, read_write> misses: array<atomic<u32>>;

// Whether the world holds shapes of each kind (SHAPE_KINDS, from the host, has bit k for kind
// k). The pair functions of absent kinds are behind constant-false branches, which the driver's
// compiler drops: a kernel's registers are those of its largest live pair function, and a pile
// of boxes then runs without the hulls' clipping.
const HAS_SPHERE = (SHAPE_KINDS & (1u << SHAPE_SPHERE)) != 0u;
const HAS_CAPSULE = (SHAPE_KINDS & (1u << SHAPE_CAPSULE)) != 0u;
const HAS_CUBOID = (SHAPE_KINDS & (1u << SHAPE_CUBOID)) != 0u;
const HAS_PLANE = (SHAPE_KINDS & (1u << SHAPE_PLANE)) != 0u;
const HAS_HULL = (SHAPE_KINDS & (1u << SHAPE_CONVEX_HULL)) != 0u;

const NEW_PAIR: u32 = 0xffffffffu;
// No old point chosen yet.
const NO_POINT: u32 = 0xffffffffu;

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
    // Padding past the GPU broadphase's pair count (its keys come in their whole buffer).
    if all(key == vec2<u32>(0xffffffffu, 0xffffffffu)) || is_skipped(key) {
        contacts[index] = PairContact();
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
    if !cache_holds(old, relative, margin, a, b) {
        return false;
    }
    rebuild(index, old, pose_a, relative);
    return true;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn update_contacts(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let slot = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if slot >= atomicLoad(&misses[0]) {
        return;
    }
    let index = atomicLoad(&misses[1u + slot]);
    let key = keys[index];
    let a = key.y;
    let b = key.x;
    let margin = params.margin + params.dt * closing_speed_bound(a, b);
    collide(a, b, margin);
    let pose_a = poses[a];
    for (var point = 0u; point < out.count; point++) {
        out.points[point].anchor = to_local(pose_a, out.points[point].position);
    }
    store_carrying_impulses(index, old_index[index]);
    if cacheable(a, b) {
        store_cache(index, pose_a, relative_pose(pose_a, poses[b]), margin);
    } else {
        contacts[index].cache = ManifoldCache();
    }
}

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

// mod.rs `cache_holds`, with `cache_radius`: whether last step's contact `old` may be moved to
// `relative` for `margin`, bodies `a` and `b` (a plane's points near the other body may lie
// anywhere: no bound from its side).
fn cache_holds(old: u32, relative: BodyPose, margin: f32, a: u32, b: u32) -> bool {
    let cache = old_contacts[old].cache;
    if cache.valid == 0u || margin > cache.margin + CACHE_TOLERANCE {
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
// each point's side on A fixed in A and its side on B fixed in B.
fn rebuild(index: u32, old: u32, pose_a: BodyPose, relative: BodyPose) {
    var contact = old_contacts[old];
    let normal = contact.cache.normal;
    contact.manifold.normal = quat_rotate(pose_a.rotation, normal);
    let inverse = quat_conjugate(contact.cache.rotation);
    for (var i = 0u; i < contact.manifold.count; i++) {
        let anchor = contact.manifold.points[i].anchor;
        let half = normal * (0.5 * contact.cache.separations[i]);
        let on_a = anchor + half;
        let on_b_in_b = quat_rotate(inverse, anchor - half - contact.cache.position);
        let on_b = relative.position + quat_rotate(relative.rotation, on_b_in_b);
        contact.manifold.points[i].separation = dot3(on_a - on_b, normal);
        contact.manifold.points[i].position =
            pose_a.position + quat_rotate(pose_a.rotation, (on_a + on_b) * 0.5);
    }
    contacts[index] = contact;
}

// mod.rs `cache_of`: the cache of `out`, computed at `relative` for `margin`.
fn store_cache(index: u32, pose_a: BodyPose, relative: BodyPose, margin: f32) {
    var separations = vec4<f32>(0.0);
    for (var i = 0u; i < out.count; i++) {
        separations[i] = out.points[i].separation;
    }
    contacts[index].cache = ManifoldCache(
        relative.position,
        margin,
        relative.rotation,
        quat_rotate(quat_conjugate(pose_a.rotation), out.normal),
        1u,
        separations,
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

// collision/contact/mod.rs `collide`: each pair function exists for kind(a) <= kind(b); the
// other order is the same contact with the normal flipped.
// Bodies `a` and `b`.
fn collide(a: u32, b: u32, margin: f32) {
    out = Manifold();
    if colliders[a].kind <= colliders[b].kind {
        collide_ordered(a, b, margin);
    } else {
        collide_ordered(b, a, margin);
        out.normal = -out.normal;
    }
}

// Bodies `body_a` and `body_b`, the second of the larger kind.
fn collide_ordered(body_a: u32, body_b: u32, margin: f32) {
    let a = colliders[body_a];
    let b = colliders[body_b];
    let pose_a = poses[body_a];
    let pose_b = poses[body_b];
    if HAS_HULL && b.kind == SHAPE_CONVEX_HULL {
        switch a.kind {
            case SHAPE_CUBOID: {
                if HAS_CUBOID { box_hull(a.params, pose_a, body_b, pose_b, margin); }
            }
            case SHAPE_PLANE: {
                if HAS_PLANE {
                    // The hull–plane function has the plane as B: swap, then flip the normal
                    // back.
                    hull_plane(body_b, pose_b, a.params, pose_a, margin);
                    out.normal = -out.normal;
                }
            }
            case SHAPE_CONVEX_HULL: { hull_hull(body_a, pose_a, body_b, pose_b, margin); }
            case SHAPE_SPHERE: {
                if HAS_SPHERE { sphere_hull(a.params, pose_a, body_b, pose_b, margin); }
            }
            case SHAPE_CAPSULE: {
                if HAS_CAPSULE { capsule_hull(a.params, pose_a, body_b, pose_b, margin); }
            }
            default: {}
        }
        return;
    }
    // Meshes and compounds are host work; without this their kinds would alias primitive
    // pairs below (sphere–mesh, 0 * 4 + 5, is capsule–capsule's 5; sphere–compound,
    // 0 * 4 + 6, is capsule–box's 6).
    if b.kind > SHAPE_PLANE {
        return;
    }
    let pair = a.kind * 4u + b.kind;
    switch pair {
        case 0u: {
            if HAS_SPHERE { sphere_sphere(a.params, pose_a, b.params, pose_b, margin); }
        }
        case 1u: {
            if HAS_SPHERE && HAS_CAPSULE {
                sphere_capsule(a.params, pose_a, b.params, pose_b, margin);
            }
        }
        case 2u: {
            if HAS_SPHERE && HAS_CUBOID { sphere_box(a.params, pose_a, b.params, pose_b, margin); }
        }
        case 3u: {
            if HAS_SPHERE && HAS_PLANE { sphere_plane(a.params, pose_a, b.params, pose_b, margin); }
        }
        case 5u: {
            if HAS_CAPSULE { capsule_capsule(a.params, pose_a, b.params, pose_b, margin); }
        }
        case 6u: {
            if HAS_CAPSULE && HAS_CUBOID {
                capsule_box(a.params, pose_a, b.params, pose_b, margin);
            }
        }
        case 7u: {
            if HAS_CAPSULE && HAS_PLANE {
                capsule_plane(a.params, pose_a, b.params, pose_b, margin);
            }
        }
        case 10u: {
            if HAS_CUBOID { box_box(a.params, pose_a, b.params, pose_b, margin); }
        }
        case 11u: {
            if HAS_CUBOID && HAS_PLANE { box_plane(a.params, pose_a, b.params, pose_b, margin); }
        }
        // Plane–plane: two static half-spaces need no contact.
        default: {}
    }
}

// mod.rs `carry_impulses`: `out` into contacts[index], with the impulses of last step's points
// old_contacts[old] (none for NEW_PAIR), by feature id first, then the nearest unclaimed old
// anchor within MATCH_DISTANCE (first on ties). Both pair contacts are read and written where
// they lie, and the claimed and matched points are bit masks: copies of them indexed by loop
// variables were kept in local memory, 192 bytes each a thread.
fn store_carrying_impulses(index: u32, old: u32) {
    contacts[index].manifold = out;
    for (var i = 0u; i < MAX_MANIFOLD_POINTS; i++) {
        contacts[index].impulses[i] = PointImpulse();
    }
    if old == NEW_PAIR {
        return;
    }
    let previous = &old_contacts[old];
    let old_count = (*previous).manifold.count;
    var claimed = 0u;
    var matched = 0u;
    for (var i = 0u; i < out.count; i++) {
        for (var j = 0u; j < old_count; j++) {
            let unclaimed = (claimed & (1u << j)) == 0u;
            if unclaimed && (*previous).manifold.points[j].id == out.points[i].id {
                contacts[index].impulses[i] = (*previous).impulses[j];
                claimed |= 1u << j;
                matched |= 1u << i;
                break;
            }
        }
    }
    for (var i = 0u; i < out.count; i++) {
        if (matched & (1u << i)) != 0u {
            continue;
        }
        var nearest = NO_POINT;
        var nearest_distance_squared = 0.0;
        for (var j = 0u; j < old_count; j++) {
            if (claimed & (1u << j)) != 0u {
                continue;
            }
            let offset = out.points[i].anchor - (*previous).manifold.points[j].anchor;
            let distance_squared = dot3(offset, offset);
            if distance_squared < MATCH_DISTANCE * MATCH_DISTANCE
                && (nearest == NO_POINT || distance_squared < nearest_distance_squared) {
                nearest = j;
                nearest_distance_squared = distance_squared;
            }
        }
        if nearest != NO_POINT {
            contacts[index].impulses[i] = (*previous).impulses[nearest];
            claimed |= 1u << nearest;
        }
    }
}
