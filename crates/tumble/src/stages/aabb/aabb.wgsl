// Stage 1 on the GPU: one thread per body slot writes the world AABB of its collider, grown by
// the contact margin and swept by linear_velocity · dt, as `compute_aabbs` in mod.rs does.
// Injected before this file: body.wgsl, PLANE_AABB_EXTENT. The arithmetic follows glam's
// (Mat3::from_quat, Quat * Vec3) term by term so that the two executors round alike; the GPU
// may still fuse multiply-adds, hence the parity test's tolerance.

struct AabbParams {
    count: u32,
    margin: f32,
    dt: f32,
    padding: u32,
}

@group(0) @binding(0) var<uniform> params: AabbParams;
@group(0) @binding(1) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(2) var<storage, read> velocities: array<BodyVelocity>;
@group(0) @binding(3) var<storage, read> colliders: array<ColliderData>;
// math::Aabb is (min, max) of three f32 each, 24 bytes with no padding: 6 floats per body.
@group(0) @binding(4) var<storage, read_write> aabbs: array<f32>;

// Half extents along the world axes of a box with `half` extents rotated by q: the absolute
// columns of glam's Mat3::from_quat weighted by the half extents.
fn box_extent(q: vec4<f32>, half: vec3<f32>) -> vec3<f32> {
    let m = mat3_from_quat(q);
    return abs(m[0]) * half.x + abs(m[1]) * half.y + abs(m[2]) * half.z;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn world_aabbs(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body >= params.count {
        return;
    }
    let pose = poses[body];
    let collider = colliders[body];
    let q = pose.rotation;
    var low: vec3<f32>;
    var high: vec3<f32>;
    switch collider.kind {
        case SHAPE_SPHERE: {
            let extent = vec3<f32>(collider.params.x);
            low = pose.position - extent;
            high = pose.position + extent;
        }
        case SHAPE_CAPSULE: {
            let axis = quat_rotate(q, vec3<f32>(0.0, collider.params.y, 0.0));
            let extent = abs(axis) + vec3<f32>(collider.params.x);
            low = pose.position - extent;
            high = pose.position + extent;
        }
        // Hulls, meshes and compounds upload the half extents of a box about the body origin
        // that holds them (`Collider::data`): their box turned, a bound of the CPU's.
        case SHAPE_CUBOID, SHAPE_CONVEX_HULL, SHAPE_TRIMESH, SHAPE_COMPOUND: {
            let extent = box_extent(q, collider.params.xyz);
            low = pose.position - extent;
            high = pose.position + extent;
        }
        default: {
            // SHAPE_PLANE: a huge box, bounded on an axis the normal is aligned with.
            let n = quat_rotate(q, collider.params.xyz);
            let point_on_plane = pose.position + n * collider.params.w;
            low = vec3<f32>(-PLANE_AABB_EXTENT);
            high = vec3<f32>(PLANE_AABB_EXTENT);
            for (var axis = 0u; axis < 3u; axis++) {
                if abs(abs(n[axis]) - 1.0) <= 1e-6 {
                    if n[axis] > 0.0 {
                        high[axis] = point_on_plane[axis];
                    } else {
                        low[axis] = point_on_plane[axis];
                    }
                }
            }
        }
    }
    low -= vec3<f32>(params.margin);
    high += vec3<f32>(params.margin);
    let motion = velocities[body].linear * params.dt;
    low = min(low, low + motion);
    high = max(high, high + motion);
    aabbs[body * 6u + 0u] = low.x;
    aabbs[body * 6u + 1u] = low.y;
    aabbs[body * 6u + 2u] = low.z;
    aabbs[body * 6u + 3u] = high.x;
    aabbs[body * 6u + 4u] = high.y;
    aabbs[body * 6u + 5u] = high.z;
}
