// integrate::finalize_bodies on the device: the step's motion into the poses and the solved
// velocities into the bodies', in place, so the next step finds them here (stages/integrate/
// gpu.rs). Static and sleeping bodies (inverse mass 0) keep theirs. glam's order of
// operations: position + delta, normalize(delta_rotation * rotation) as q (1 / sqrt(q · q)).
// Needs body.wgsl (quat_mul), solver_body.wgsl and body_count.wgsl.

@group(0) @binding(0) var<uniform> params: BodyCount;
@group(0) @binding(1) var<storage, read> bodies: array<SolverBody>;
@group(0) @binding(2) var<storage, read_write> poses: array<BodyPose>;
@group(0) @binding(3) var<storage, read_write> velocities: array<BodyVelocity>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn finalize_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.count {
        return;
    }
    let body = bodies[index];
    if body.inverse_mass == 0.0 {
        return;
    }
    velocities[index] = BodyVelocity(body.linear_velocity, 0.0, body.angular_velocity, 0.0);
    let pose = poses[index];
    let q = quat_mul(body.delta_rotation, pose.rotation);
    poses[index] = BodyPose(pose.position + body.delta_position, 0.0, q * (1.0 / sqrt(dot(q, q))));
}
