// Contact rows as both executors solve them: the twins of Softness (pipeline/config.rs), Row,
// ConstraintPoint and ContactConstraint (stages/constraints/contact.rs), whose docs give each
// field's meaning and unit. tests/engine/gpu_layout.rs checks that the layouts agree.

// Body index of a constraint's static side (STATIC_BODY in Rust).
const STATIC_BODY: u32 = 0xffffffffu;

// Spring-damper of a soft constraint (Box2D v3's b2Softness).
struct Softness {
    bias_rate: f32,
    mass_scale: f32,
    impulse_scale: f32,
}

// One scalar direction d at one point: I⁻¹(r × d) for both bodies, 1/K, impulse (the
// solver computes r × d from the point's anchors).
struct Row {
    angular_a: vec3<f32>,
    mass: f32,
    angular_b: vec3<f32>,
    impulse: f32,
}

struct ConstraintPoint {
    normal: Row,
    tangent: array<Row, 2>,
    anchor_a: vec3<f32>,
    adjusted_separation: f32,
    anchor_b: vec3<f32>,
    separation: f32,
    approach_velocity: f32,
    max_normal_impulse: f32,
    _pad: array<f32, 2>,
}

// One manifold's rows: up to 4 points sharing the normal (from B to A) and the material.
struct ContactConstraint {
    body_a: u32,
    body_b: u32,
    pair: u32,
    point_count: u32,
    normal: vec3<f32>,
    friction: f32,
    tangent1: vec3<f32>,
    restitution: f32,
    tangent2: vec3<f32>,
    inverse_mass_a: f32,
    inverse_mass_b: f32,
    softness: Softness,
    points: array<ConstraintPoint, 4>,
}
