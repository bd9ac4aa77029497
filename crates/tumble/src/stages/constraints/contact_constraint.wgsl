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

// One scalar direction d at one point: 1/K and the impulse (the solver computes r × d from
// the point's anchors, and I⁻¹(r × d) from the constraint's inverse inertias, lanes.wgsl).
struct Row {
    mass: f32,
    impulse: f32,
}
