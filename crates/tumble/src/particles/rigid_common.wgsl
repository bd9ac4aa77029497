// Data and arithmetic shared by the rigid particle kernels (after `common.wgsl`); the CPU
// twin is `rigid_cpu.rs` (and `rotate`, `cross` in `rigid.rs`), operation for operation.

struct RigidBody {
    position: vec4<f32>,
    orientation: vec4<f32>,
    linear_velocity: vec4<f32>,
    angular_velocity: vec4<f32>,
}

struct BodyInfo {
    first_particle: u32,
    particle_count: u32,
    inverse_mass: f32,
    padding: u32,
    inverse_inertia: mat3x3<f32>,
}

struct RigidParams {
    body_count: u32,
    padding0: u32,
    padding1: u32,
    padding2: u32,
}

// `v` rotated by the unit quaternion `q` (x, y, z, w).
fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = cross(q.xyz, v) * 2.0;
    let u = cross(q.xyz, t);
    return v + q.w * t + u;
}
