// Stage 3: each cell's run in the sorted array (a run starts where the key changes), and
// the particles copied into sorted order so that the search reads neighbours coherently.
// `cell_start` was filled with EMPTY_CELL just before.

@group(0) @binding(1) var<storage, read> sorted_keys: array<u32>;
@group(0) @binding(2) var<storage, read> sorted_ids: array<u32>;
@group(0) @binding(3) var<storage, read> particles: array<Particle>;
@group(0) @binding(4) var<storage, read_write> sorted_particles: array<Particle>;
@group(0) @binding(5) var<storage, read_write> cell_start: array<u32>;
@group(0) @binding(6) var<storage, read_write> cell_end: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn cell_bounds(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = particle_index(local, workgroup, groups);
    if index >= params.count {
        return;
    }
    let key = sorted_keys[index];
    if index == 0u || sorted_keys[index - 1u] != key {
        cell_start[key] = index;
    }
    if index + 1u == params.count || sorted_keys[index + 1u] != key {
        cell_end[key] = index + 1u;
    }
    sorted_particles[index] = particles[sorted_ids[index]];
}
