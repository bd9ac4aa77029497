// Instance models from the physics' device buffers, with no readback: each instance's body
// pose at the end of the step (the step integrated on the device) times the instance's local
// matrix. Layouts: `BodyPose` (tumble's dynamics/body.rs), `PoseLink` and `Instance`
// (draw.rs). NO_BODY and WORKGROUP_SIZE are prepended by renderer.rs.

struct BodyPose {
    position: vec3<f32>,
    rotation: vec4<f32>,
};

struct PoseLink {
    local: mat4x4<f32>,
    body: u32,
};

struct Instance {
    model: mat4x4<f32>,
    colour: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(1) var<storage, read> links: array<PoseLink>;
@group(0) @binding(2) var<storage, read_write> instances: array<Instance>;

// Quaternions are [x, y, z, w], as glam's.
fn rotation_translation(q: vec4<f32>, t: vec3<f32>) -> mat4x4<f32> {
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    return mat4x4<f32>(
        vec4<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y), 0.0),
        vec4<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x), 0.0),
        vec4<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y), 0.0),
        vec4<f32>(t, 1.0),
    );
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= arrayLength(&links)) {
        return;
    }
    let link = links[i];
    if (link.body == NO_BODY) {
        return;
    }
    let pose = poses[link.body];
    instances[i].model = rotation_translation(pose.rotation, pose.position) * link.local;
}
