// Stage 3: the particle demo's 27-cell search, skipping particles of the same body, plus
// the walls with friction. Writes each particle's force at its body-order index, so that a
// body's forces are contiguous for the next stage.

// Needs search.wgsl (the sorted particles, the cell table, `neighbour_force`).
@group(0) @binding(5) var<storage, read_write> forces: array<vec4<f32>>;

// The walls' friction: a particle inside a wall has its tangential velocity damped (N).
fn wall_friction(position: vec3<f32>, velocity: vec3<f32>) -> vec3<f32> {
    var force = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis++) {
        let low = params.origin[axis] + params.radius;
        let high = params.origin[axis] + f32(params.grid[axis]) * params.cell_size - params.radius;
        if position[axis] < low || position[axis] > high {
            for (var other = 0u; other < 3u; other++) {
                if other != axis {
                    force[other] -= params.shear * velocity[other];
                }
            }
        }
    }
    return force;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn rigid_collide(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = particle_index(local, workgroup, groups);
    if index >= params.count {
        return;
    }
    let me = sorted_particles[index];
    let position = me.position.xyz;
    let velocity = me.velocity.xyz;
    var force = neighbour_force(index, true);
    force += wall_force(position, velocity);
    force += wall_friction(position, velocity);
    forces[sorted_ids[index]] = vec4<f32>(force, 0.0);
}
