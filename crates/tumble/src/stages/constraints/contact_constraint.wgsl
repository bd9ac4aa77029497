// Contact rows as the kernels hold them: the twins of Softness (pipeline/config.rs) and Row
// (stages/constraints/contact.rs), whose docs give each field's meaning and unit
// (tests/engine/gpu_layout.rs checks that the layouts agree). A ContactConstraint lies in device
// memory as words in blocks of lanes (lanes.wgsl), not as a struct.

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
