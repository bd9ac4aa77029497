// Stage 4: search the 27 cells around each particle, summing pair forces as they are found
// (no neighbour list), then integrate. Reads only the sorted copy of the previous state and
// writes the particle array (Jacobi), so particles can be processed in any order.

// Needs search.wgsl (the sorted particles, the cell table, `neighbour_force`).
@group(0) @binding(5) var<storage, read_write> particles: array<Particle>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn collide(
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
    var force = neighbour_force(index, false);
    force += wall_force(position, velocity);
    particles[sorted_ids[index]] = integrate(position, velocity, force);
}
