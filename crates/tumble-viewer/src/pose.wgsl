// Instance models from the physics' device buffers, with no readback: each instance's body
// pose at the end of the step (its pose at the start of the step moved by the solver's motion,
// as the host's finalize_bodies does) times the instance's local matrix. Layouts: `BodyPose`
// (tumble's dynamics/body.rs), `SolverBody` (stages/solver), `PoseLink` and `Instance`
// (draw.rs). NO_BODY and WORKGROUP_SIZE are prepended by renderer.rs.

struct BodyPose {
    position: vec3<f32>,
    rotation: vec4<f32>,
};

struct SolverBody {
    linear_velocity: vec3<f32>,
    inverse_mass: f32,
    angular_velocity: vec3<f32>,
    delta_position: vec3<f32>,
    delta_rotation: vec4<f32>,
};

struct PoseLink {
    local: mat4x4<f32>,
    body: u32,
};

struct Instance {
    model: mat4x4<f32>,
    colour: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> start: array<BodyPose>;
@group(0) @binding(1) var<storage, read> motion: array<SolverBody>;
@group(0) @binding(2) var<storage, read> links: array<PoseLink>;
@group(0) @binding(3) var<storage, read_write> instances: array<Instance>;

// Quaternions are [x, y, z, w], as glam's: the rotation b, then a.
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}

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
    let pose = start[link.body];
    let moved = motion[link.body];
    var position = pose.position;
    var rotation = pose.rotation;
    // Static and sleeping bodies (inverse mass 0) keep their pose, as on the host.
    if (moved.inverse_mass != 0.0) {
        position += moved.delta_position;
        rotation = normalize(quat_mul(moved.delta_rotation, rotation));
    }
    instances[i].model = rotation_translation(rotation, position) * link.local;
}
