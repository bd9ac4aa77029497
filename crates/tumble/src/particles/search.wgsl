// The 27-cell search of the particle demo and of the rigid particle bodies: the sorted
// particles and the cell table, and the sum of the pair forces on one particle, found as the
// cells are walked (no neighbour list).

@group(0) @binding(1) var<storage, read> sorted_particles: array<Particle>;
@group(0) @binding(2) var<storage, read> sorted_ids: array<u32>;
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;
@group(0) @binding(4) var<storage, read> cell_end: array<u32>;

// The pair forces on sorted particle `index` from the particles of the 27 cells around it,
// in increasing cell id order (z, then y, then x) as the CPU twins sum them. With
// `skip_own_body`, particles with the same `position.w` (a rigid body's index) are left out.
fn neighbour_force(index: u32, skip_own_body: bool) -> vec3<f32> {
    let me = sorted_particles[index];
    let position = me.position.xyz;
    let velocity = me.velocity.xyz;
    let cell = vec3<i32>(cell_of(position));
    let grid = vec3<i32>(params.grid);
    var force = vec3<f32>(0.0);
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
                    let them = sorted_particles[other];
                    let own_body = skip_own_body && them.position.w == me.position.w;
                    if other != index && !own_body {
                        force += pair_force(position, velocity, them.position.xyz, them.velocity.xyz);
                    }
                }
            }
        }
    }
    return force;
}
