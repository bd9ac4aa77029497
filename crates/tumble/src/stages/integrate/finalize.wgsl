// integrate::finalize_bodies on the device: the step's motion into the poses and the solved
// velocities into the bodies', in place, so the next step finds them here (stages/integrate/
// gpu.rs). Static and sleeping bodies (inverse mass 0) keep theirs, and every body keeps its own
// where `held` is 0: a step whose rows and solve were submitted on a guess, before the host
// read its collision, and guessed wrong; the host then solves it again
// (pipeline/gpu_stages/speculation.rs). glam's order of operations: position + delta,
// normalize(delta_rotation * rotation) as q (1 / sqrt(q · q)).
// Needs body.wgsl (quat_mul), solver_body.wgsl and body_count.wgsl.

@group(0) @binding(0) var<uniform> params: BodyCount;
@group(0) @binding(1) var<storage, read> bodies: array<SolverBody>;
@group(0) @binding(2) var<storage, read_write> poses: array<BodyPose>;
@group(0) @binding(3) var<storage, read_write> velocities: array<BodyVelocity>;
@group(0) @binding(4) var<storage, read> held: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn finalize_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.count || held[0] == 0u {
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
