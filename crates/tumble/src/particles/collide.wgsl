// Stage 4: search the 27 cells around each particle, summing pair forces as they are found
// (no neighbour list), then integrate. Reads only the sorted copy of the previous state and
// writes the particle array (Jacobi), so particles can be processed in any order.

@group(0) @binding(1) var<storage, read> sorted_particles: array<Particle>;
@group(0) @binding(2) var<storage, read> sorted_ids: array<u32>;
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;
@group(0) @binding(4) var<storage, read> cell_end: array<u32>;
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
    let cell = vec3<i32>(cell_of(position));
    let grid = vec3<i32>(params.grid);
    var force = vec3<f32>(0.0);
    // Neighbour cells in increasing id order (z, then y, then x), as the CPU twin.
    for (var dz = -1; dz <= 1; dz++) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let neighbour = cell + vec3<i32>(dx, dy, dz);
                if any(neighbour < vec3<i32>(0)) || any(neighbour >= grid) {
                    continue;
                }
                let neighbour_index = cell_index(vec3<u32>(neighbour));
                let start = cell_start[neighbour_index];
                if start == EMPTY_CELL {
                    continue;
                }
                let end = cell_end[neighbour_index];
                for (var other = start; other < end; other++) {
                    if other != index {
                        let them = sorted_particles[other];
                        force += pair_force(position, velocity, them.position.xyz, them.velocity.xyz);
                    }
                }
            }
        }
    }
    force += wall_force(position, velocity);
    particles[sorted_ids[index]] = integrate(position, velocity, force);
}
