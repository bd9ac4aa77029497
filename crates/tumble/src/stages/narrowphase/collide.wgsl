// Stage 4's pair functions on the GPU (see narrowphase.wgsl): `update_contacts`, over the pairs
// that `move_cached` listed, runs each pair's function, carries last step's impulses and makes
// the pair's cache.

@group(0) @binding(3) var<storage, read> old_contacts: array<PairContact>;
@group(0) @binding(9) var<storage, read_write> contacts: array<PairContact>;
// Read without atomics (the list was made by an earlier dispatch): every thread reads the
// count, and atomic loads of one word would wait on each other.
@group(0) @binding(10) var<storage, read_write> misses: array<u32>;

// Whether the world holds shapes of each kind (SHAPE_KINDS, from the host, has bit k for kind
// k). The pair functions of absent kinds are behind constant-false branches, which the driver's
// compiler drops: a kernel's registers are those of its largest live pair function, and a pile
// of boxes then runs without the hulls' clipping.
const HAS_SPHERE = (SHAPE_KINDS & (1u << SHAPE_SPHERE)) != 0u;
const HAS_CAPSULE = (SHAPE_KINDS & (1u << SHAPE_CAPSULE)) != 0u;
const HAS_CUBOID = (SHAPE_KINDS & (1u << SHAPE_CUBOID)) != 0u;
const HAS_PLANE = (SHAPE_KINDS & (1u << SHAPE_PLANE)) != 0u;
const HAS_HULL = (SHAPE_KINDS & (1u << SHAPE_CONVEX_HULL)) != 0u;

// No old point chosen yet.
const NO_POINT: u32 = 0xffffffffu;

// At most PAIR_FUNCTION_GROUPS workgroups of PAIR_FUNCTION_WORKGROUP threads (gpu.rs says
// why), each thread taking every stride-th listed pair.
@compute @workgroup_size(PAIR_FUNCTION_WORKGROUP)
fn update_contacts(
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let first = flat_workgroup(workgroup, groups) * PAIR_FUNCTION_WORKGROUP + local;
    let stride = groups.x * groups.y * PAIR_FUNCTION_WORKGROUP;
    let count = misses[0];
    for (var slot = first; slot < count; slot += stride) {
        update_pair(misses[1u + slot]);
        // Never past u32::MAX, whatever the count: the loop ends (gpu.rs, every_loop_ends).
        if count - slot <= stride {
            break;
        }
    }
}

// Pair `index`'s contact: its pair function, last step's impulses, its cache.
fn update_pair(index: u32) {
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
// variables were kept in local memory, 192 bytes each a thread (before the contact had a
// cache).
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
