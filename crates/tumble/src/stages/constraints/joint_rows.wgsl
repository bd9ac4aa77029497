// Joint rows on the GPU: the twin of build_joint_constraints in joint.rs (read its docs for
// what a row holds), and the gather of the rows into batch order for the solver.
//
// `build`: one thread per slot of the world's joint array. A live slot's row is written at the
// same index of `rows` (free and broken slots get none): the frame, the step-start rotations
// and centre offset, the masses, the world inverse inertias (in glam's order of operations, so
// the rows agree with the CPU's within a few roundings) and the warm-start impulses, which stay
// on the device from one step to the next (`impulses`, written back after the solve by
// batched.wgsl's read_joint_impulses). Which rows are solved, and in which order, is the host's
// list (joint_slots in joint.rs): it knows the masses too, and needs the bodies for the
// batching anyway, so no flag and scan run here. The drag's row, built on the host, sits in
// the slot past the last joint.
//
// `gather`: batched[i] = rows[order[i]] for the `count[0]` joints the solver sweeps.

struct JointRowParams {
    // Joint softness as (bias_rate, mass_scale, impulse_scale, unused).
    softness: vec4<f32>,
    slot_count: u32,
    // Infinity (WGSL has no literal for it): a joint's point impulse is not clamped.
    max_point_impulse: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: JointRowParams;
@group(0) @binding(1) var<storage, read> slots: array<JointSlot>;
@group(0) @binding(2) var<storage, read> impulses: array<BatchedJointImpulses>;
@group(0) @binding(3) var<storage, read> poses: array<BodyPose>;
@group(0) @binding(4) var<storage, read> masses: array<BodyMass>;
// One row per slot, plus the drag's.
@group(0) @binding(5) var<storage, read_write> rows: array<JointConstraint>;
// Word 0: how many joints the solver sweeps this step.
@group(0) @binding(6) var<storage, read> count: array<u32>;
// order[i]: the slot of the row at batched place i.
@group(0) @binding(7) var<storage, read> order: array<u32>;
@group(0) @binding(8) var<storage, read_write> batched: array<JointConstraint>;

fn thread_index(local: u32, workgroup: vec3<u32>, groups: vec3<u32>) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
}

// glam's Mat3 * Vec3: the columns weighted and summed left to right.
fn mat_vec3(m: mat3x3<f32>, v: vec3<f32>) -> vec3<f32> {
    return m[0] * v.x + m[1] * v.y + m[2] * v.z;
}

// world_inverse_inertia (contact.rs) of one body, R diag(d) Rᵀ, as glam computes it: R diag(d)
// scales R's columns (glam's product adds exact zeros to each), then each column of Rᵀ goes
// through it. Packed as a glam Mat3 (three columns, no padding).
fn world_inverse_inertia(body: u32) -> array<f32, 9> {
    let r = mat3_from_quat(poses[body].rotation);
    let d = masses[body].inverse_inertia;
    let scaled = mat3x3<f32>(r[0] * d.x, r[1] * d.y, r[2] * d.z);
    let r_t = transpose(r);
    let c0 = mat_vec3(scaled, r_t[0]);
    let c1 = mat_vec3(scaled, r_t[1]);
    let c2 = mat_vec3(scaled, r_t[2]);
    return array<f32, 9>(c0.x, c0.y, c0.z, c1.x, c1.y, c1.z, c2.x, c2.y, c2.z);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn build(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let slot = thread_index(local, workgroup, groups);
    if slot >= params.slot_count || slots[slot].live == 0u {
        return;
    }
    let joint = &slots[slot];
    let a = (*joint).body_a;
    let b = (*joint).body_b;
    let mass_a = masses[a].inverse_mass;
    let mass_b = masses[b].inverse_mass;
    var c: JointConstraint;
    c.frame = (*joint).frame;
    c.rotation_a = poses[a].rotation;
    c.rotation_b = poses[b].rotation;
    c.center_offset = poses[b].position - poses[a].position;
    c.inverse_mass_a = mass_a;
    c.point_impulse = impulses[slot].point;
    c.inverse_mass_b = mass_b;
    c.body_a = select(STATIC_BODY, a, mass_a > 0.0);
    c.body_b = select(STATIC_BODY, b, mass_b > 0.0);
    c.joint = slot;
    c.max_point_impulse = params.max_point_impulse;
    c.softness = Softness(params.softness.x, params.softness.y, params.softness.z);
    c.angular_impulse = impulses[slot].angular;
    c.inverse_inertia_a = world_inverse_inertia(a);
    c.inverse_inertia_b = world_inverse_inertia(b);
    rows[slot] = c;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn gather(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = thread_index(local, workgroup, groups);
    if index < count[0] {
        batched[index] = rows[order[index]];
    }
}
