// The solver's bodies: the twin of SolverBody (stages/solver/mod.rs), and the integration
// helpers of stages/integrate, written in the CPU's order of operations so both executors
// round alike. Needs body.wgsl (quat_mul) and contact_constraint.wgsl (STATIC_BODY).

// Most a body may turn in one sub-step (rad): MAX_ROTATION_PER_STEP, injected from Rust.

struct SolverBody {
    linear_velocity: vec3<f32>,
    inverse_mass: f32,
    angular_velocity: vec3<f32>,
    _pad0: f32,
    delta_position: vec3<f32>,
    _pad1: f32,
    delta_rotation: vec4<f32>,
}

// A static body, or one that has not moved: zero velocity, identity delta.
fn static_solver_body() -> SolverBody {
    return SolverBody(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0,
        vec4<f32>(0.0, 0.0, 0.0, 1.0));
}

// integrate::clamp_rotation: ω scaled down to turn at most MAX_ROTATION_PER_STEP in dt.
fn clamp_rotation(angular_velocity: vec3<f32>, dt: f32) -> vec3<f32> {
    let angle = length(angular_velocity) * dt;
    if angle > MAX_ROTATION_PER_STEP {
        return angular_velocity * (MAX_ROTATION_PER_STEP / angle);
    }
    return angular_velocity;
}

// integrate::integrate_rotation: normalize(q + ½ dt (ω, 0) q), ω in the world frame.
fn integrate_rotation(rotation: vec4<f32>, angular_velocity: vec3<f32>, dt: f32) -> vec4<f32> {
    let spin = quat_mul(vec4<f32>(angular_velocity, 0.0), rotation);
    let q = rotation + spin * (0.5 * dt);
    return q * (1.0 / sqrt(dot(q, q)));
}
