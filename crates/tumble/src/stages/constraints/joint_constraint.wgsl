// Joint rows as both executors solve them: the twins of JointFrame, JointConstraint and
// JointSlot (stages/constraints/joint.rs), whose docs give each field's meaning and unit, and
// of BatchedJointImpulses (stages/solver/batched.rs).
// tests/engine/gpu_layout.rs checks that the layouts agree. Needs contact_constraint.wgsl (Softness).

// JointFrame::kind (JOINT_* in Rust).
const JOINT_POINT: u32 = 0u;
const JOINT_HINGE: u32 = 1u;
const JOINT_CONE_TWIST: u32 = 2u;
const JOINT_FIXED: u32 = 3u;
// JointConstraint::joint of the drag, which is no joint of the world (DRAG_JOINT in Rust).
const DRAG_JOINT: u32 = 0xffffffffu;
// JointFrame::flags (HAS_* in Rust).
const HAS_LIMITS: u32 = 1u;
const HAS_MOTOR: u32 = 2u;

struct JointFrame {
    local_anchor_a: vec3<f32>,
    kind: u32,
    local_anchor_b: vec3<f32>,
    flags: u32,
    local_axis_a: vec3<f32>,
    lower: f32,
    local_axis_b: vec3<f32>,
    upper: f32,
    local_reference_a: vec3<f32>,
    swing_limit: f32,
    local_reference_b: vec3<f32>,
    target_speed: f32,
    relative_rotation: vec4<f32>,
    max_torque: f32,
    _pad: array<f32, 3>,
}

struct JointConstraint {
    frame: JointFrame,
    rotation_a: vec4<f32>,
    rotation_b: vec4<f32>,
    center_offset: vec3<f32>,
    inverse_mass_a: f32,
    point_impulse: vec3<f32>,
    inverse_mass_b: f32,
    body_a: u32,
    body_b: u32,
    joint: u32,
    max_point_impulse: f32,
    softness: Softness,
    angular_impulse: array<f32, 5>,
    // glam Mat3s: three packed columns (a WGSL mat3x3 would pad each to 16 bytes).
    inverse_inertia_a: array<f32, 9>,
    inverse_inertia_b: array<f32, 9>,
    _pad: array<f32, 2>,
}

// A slot of the world's joint array (JointSlot in Rust): live 0 is a free or broken slot.
struct JointSlot {
    frame: JointFrame,
    body_a: u32,
    body_b: u32,
    live: u32,
    _pad: u32,
}

// A joint's accumulated impulses (JointConstraint::point_impulse and angular_impulse): what
// the solver reads back after a solve, and what the GPU rows keep per slot for the next
// step's warm start.
struct BatchedJointImpulses {
    point: vec3<f32>,
    angular: array<f32, 5>,
}
