// Stage 4: one workgroup per body sums its particles' forces and torques (a body's particles
// are contiguous: no atomics, the same sums on every run), then its first invocation
// integrates: semi-implicit Euler, the orientation by its angular velocity, renormalized.
// Lane l sums particles l, l + BODY_LANES, ... in order, then the lanes add up in halving
// strides; `rigid_cpu::step_body` adds in the same order. Injected: BODY_LANES.

@group(0) @binding(1) var<uniform> rigid: RigidParams;
@group(0) @binding(2) var<storage, read_write> bodies: array<RigidBody>;
@group(0) @binding(3) var<storage, read> infos: array<BodyInfo>;
@group(0) @binding(4) var<storage, read> offsets: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> forces: array<vec4<f32>>;

var<workgroup> lane_forces: array<vec3<f32>, BODY_LANES>;
var<workgroup> lane_torques: array<vec3<f32>, BODY_LANES>;

@compute @workgroup_size(BODY_LANES)
fn rigid_bodies(
    @builtin(local_invocation_index) lane: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups);
    if index >= rigid.body_count {
        return;
    }
    let body = bodies[index];
    let info = infos[index];
    let q = body.orientation;
    var lane_force = vec3<f32>(0.0);
    var lane_torque = vec3<f32>(0.0);
    let end = info.first_particle + info.particle_count;
    for (var particle = info.first_particle + lane; particle < end; particle += BODY_LANES) {
        let particle_force = forces[particle].xyz;
        let arm = rotate(q, offsets[particle].xyz);
        lane_force += particle_force;
        lane_torque += cross(arm, particle_force);
    }
    lane_forces[lane] = lane_force;
    lane_torques[lane] = lane_torque;
    workgroupBarrier();
    for (var stride = BODY_LANES / 2u; stride > 0u; stride >>= 1u) {
        if lane < stride {
            lane_forces[lane] += lane_forces[lane + stride];
            lane_torques[lane] += lane_torques[lane + stride];
        }
        workgroupBarrier();
    }
    if lane != 0u {
        return;
    }
    let force = lane_forces[0];
    let torque = lane_torques[0];
    let acceleration = force * info.inverse_mass + params.gravity;
    let velocity = body.linear_velocity.xyz + acceleration * params.dt;
    // I⁻¹ in the world: rotate the torque into the body frame and back.
    let local_torque = rotate(vec4<f32>(-q.xyz, q.w), torque);
    let columns = info.inverse_inertia;
    let local_acceleration = columns[0] * local_torque.x + columns[1] * local_torque.y
        + columns[2] * local_torque.z;
    let angular = body.angular_velocity.xyz + rotate(q, local_acceleration) * params.dt;
    let position = body.position.xyz + velocity * params.dt;
    // dq/dt = ½ (ω, 0) ⊗ q.
    let spin = vec4<f32>(angular * q.w + cross(angular, q.xyz), -dot(angular, q.xyz));
    let moved = q + spin * (0.5 * params.dt);
    let orientation = moved * (1.0 / sqrt(dot(moved, moved)));
    bodies[index] = RigidBody(
        vec4<f32>(position, 0.0),
        orientation,
        vec4<f32>(velocity, 0.0),
        vec4<f32>(angular, 0.0),
    );
}
