// Contact rows as the kernels hold them: the twin of Softness (pipeline/config.rs), whose docs
// give each field's meaning and unit (tests/engine/gpu_layout.rs checks that the layouts
// agree). A ContactConstraint lies in device memory as words in blocks of lanes (lanes.wgsl),
// not as a struct, and a row there is its mass and impulse alone (contact.rs says why).

// Body index of a constraint's static side (STATIC_BODY in Rust).
const STATIC_BODY: u32 = 0xffffffffu;

// Spring-damper of a soft constraint (Box2D v3's b2Softness).
struct Softness {
    bias_rate: f32,
    mass_scale: f32,
    impulse_scale: f32,
}
