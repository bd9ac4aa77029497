// Stage 1: each particle's world position and velocity from its body's state. `w` of the
// position is the body's index (from the offset's `w`): the collide stage skips its own body.

@group(0) @binding(1) var<storage, read> bodies: array<RigidBody>;
@group(0) @binding(2) var<storage, read> offsets: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> particles: array<Particle>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn rigid_world(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = particle_index(local, workgroup, groups);
    if index >= params.count {
        return;
    }
    let offset = offsets[index];
    let body = bodies[u32(offset.w)];
    let arm = rotate(body.orientation, offset.xyz);
    let position = body.position.xyz + arm;
    let velocity = body.linear_velocity.xyz + cross(body.angular_velocity.xyz, arm);
    particles[index] = Particle(vec4<f32>(position, offset.w), vec4<f32>(velocity, 0.0));
}
