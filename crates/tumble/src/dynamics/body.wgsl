// Bodies and colliders as every rigid-body kernel reads them: the twins of the #[repr(C)]
// structs in dynamics/body.rs (tests/engine/gpu_layout.rs checks that the layouts agree).

// Values of ColliderData.kind: shape/mod.rs ShapeKind, in its order.
const SHAPE_SPHERE: u32 = 0u;
const SHAPE_CAPSULE: u32 = 1u;
const SHAPE_CUBOID: u32 = 2u;
const SHAPE_PLANE: u32 = 3u;
// The GPU narrowphase reads a hull's polyhedron from its own table (`pack_hulls`), and no
// meshes or compounds; the AABB kernel bounds all three by a box, `ColliderData.params`.
const SHAPE_CONVEX_HULL: u32 = 4u;
const SHAPE_TRIMESH: u32 = 5u;
const SHAPE_COMPOUND: u32 = 6u;

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

// Quaternion and dot-product helpers written in glam's order of operations, so that a kernel
// rounds as the CPU stage it twins (WGSL's dot may sum in another order).

// a · b summed x, y, z.
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// glam's Quat * Vec3: v (w² - b·b) + b (2 v·b) + (b × v)(2 w), b = q.xyz.
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let b = q.xyz;
    return v * (q.w * q.w - dot3(b, b)) + b * (dot3(v, b) * 2.0) + cross(b, v) * (q.w * 2.0);
}

// The inverse rotation of a unit quaternion.
fn quat_conjugate(q: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(-q.xyz, q.w);
}

// glam's Mat3::from_quat.
fn mat3_from_quat(q: vec4<f32>) -> mat3x3<f32> {
    let x2 = q.x + q.x;
    let y2 = q.y + q.y;
    let z2 = q.z + q.z;
    let xx = q.x * x2;
    let xy = q.x * y2;
    let xz = q.x * z2;
    let yy = q.y * y2;
    let yz = q.y * z2;
    let zz = q.z * z2;
    let wx = q.w * x2;
    let wy = q.w * y2;
    let wz = q.w * z2;
    return mat3x3<f32>(
        vec3<f32>(1.0 - (yy + zz), xy + wz, xz - wy),
        vec3<f32>(xy - wz, 1.0 - (xx + zz), yz + wx),
        vec3<f32>(xz + wy, yz - wx, 1.0 - (xx + yy)),
    );
}

// The product a * b (b applied first).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz),
        a.w * b.w - dot(a.xyz, b.xyz),
    );
}

// Twin of math.rs tangent_basis (Duff et al. 2017).
fn tangent_basis(n: vec3<f32>) -> array<vec3<f32>, 2> {
    // copysign(1, n.z): -0 counts as negative, as in Rust.
    let sign = select(1.0, -1.0, (bitcast<u32>(n.z) & 0x80000000u) != 0u);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return array<vec3<f32>, 2>(
        vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3<f32>(b, sign + n.y * n.y * a, -n.y),
    );
}
