// Stage 4, symmetric variant: each pair of particles in neighbouring cells is visited once
// (own cell: later particles; then the 13 neighbour cells with smaller ids) and its force is
// added to both particles in fixed point with atomics, which makes the sums independent of
// thread order (principle 4). Then `integrate_forces` converts the sums back and integrates.

@group(0) @binding(1) var<storage, read> sorted_particles: array<Particle>;
@group(0) @binding(2) var<storage, read> sorted_ids: array<u32>;
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;
@group(0) @binding(4) var<storage, read> cell_end: array<u32>;
@group(0) @binding(5) var<storage, read_write> particles: array<Particle>;
// Three fixed-point force components per sorted particle, zeroed before the stage.
@group(0) @binding(6) var<storage, read_write> forces: array<atomic<i32>>;

fn add_pair(index: u32, other: u32, position: vec3<f32>, velocity: vec3<f32>) {
    let them = sorted_particles[other];
    let quanta = quantize(pair_force(position, velocity, them.position.xyz, them.velocity.xyz));
    if all(quanta == vec3<i32>(0)) {
        return;
    }
    for (var axis = 0u; axis < 3u; axis++) {
        atomicAdd(&forces[3u * index + axis], quanta[axis]);
        atomicAdd(&forces[3u * other + axis], -quanta[axis]);
    }
}

fn run_of(cell: u32) -> vec2<u32> {
    let start = cell_start[cell];
    if start == EMPTY_CELL {
        return vec2<u32>(0u, 0u);
    }
    return vec2<u32>(start, cell_end[cell]);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn collide_pairs(
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
    let cell = cell_of(position);
    let own = run_of(cell_index(cell));
    for (var other = index + 1u; other < own.y; other++) {
        add_pair(index, other, position, velocity);
    }
    // The 13 neighbours before the own cell in (z, y, x) order: the first half of the 27.
    let cell_signed = vec3<i32>(cell);
    let grid = vec3<i32>(params.grid);
    for (var offset = 0; offset < 13; offset++) {
        let neighbour = cell_signed + vec3<i32>(offset % 3 - 1, (offset / 3) % 3 - 1, offset / 9 - 1);
        if any(neighbour < vec3<i32>(0)) || any(neighbour >= grid) {
            continue;
        }
        let run = run_of(cell_index(vec3<u32>(neighbour)));
        for (var other = run.x; other < run.y; other++) {
            add_pair(index, other, position, velocity);
        }
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn integrate_forces(
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
    let quanta = vec3<i32>(
        atomicLoad(&forces[3u * index]),
        atomicLoad(&forces[3u * index + 1u]),
        atomicLoad(&forces[3u * index + 2u]),
    );
    let force = vec3<f32>(quanta) * params.force_quantum + wall_force(position, velocity);
    particles[sorted_ids[index]] = integrate(position, velocity, force);
}
