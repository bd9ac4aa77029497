// Bodies and colliders as every rigid-body kernel reads them: the twins of the #[repr(C)]
// structs in dynamics/body.rs (tests/gpu_layout.rs checks that the layouts agree).

// Values of ColliderData.kind: shape/mod.rs ShapeKind, in its order.
const SHAPE_SPHERE: u32 = 0u;
const SHAPE_CAPSULE: u32 = 1u;
const SHAPE_CUBOID: u32 = 2u;
const SHAPE_PLANE: u32 = 3u;
// The GPU narrowphase reads neither hulls nor meshes yet; the values keep the kinds in step
// with Rust.
const SHAPE_CONVEX_HULL: u32 = 4u;
const SHAPE_TRIMESH: u32 = 5u;

// Position and orientation of a body frame; rotation is a unit quaternion (x, y, z, w).
struct BodyPose {
    position: vec3<f32>,
    _pad: f32,
    rotation: vec4<f32>,
}

// Linear (m/s) and angular (rad/s, world frame) velocity.
struct BodyVelocity {
    linear: vec3<f32>,
    _pad0: f32,
    angular: vec3<f32>,
    _pad1: f32,
}

// Inverse principal inertia (body axes) and inverse mass; zero for static bodies.
struct BodyMass {
    inverse_inertia: vec3<f32>,
    inverse_mass: f32,
}

// A collider: shape kind, material and parameters (see ColliderData in body.rs).
struct ColliderData {
    kind: u32,
    friction: f32,
    restitution: f32,
    bounding_radius: f32,
    params: vec4<f32>,
}

// v rotated by the unit quaternion q.
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

// v rotated by the inverse of the unit quaternion q.
fn quat_rotate_inverse(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return quat_rotate(vec4<f32>(-q.xyz, q.w), v);
}

// The product a * b (b applied first).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz),
        a.w * b.w - dot(a.xyz, b.xyz),
    );
}
