// Stage 1: (cell id, particle id) for every particle.

@group(0) @binding(1) var<storage, read> particles: array<Particle>;
@group(0) @binding(2) var<storage, read_write> cell_keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> particle_ids: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn hash(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = particle_index(local, workgroup, groups);
    if index >= params.count {
        return;
    }
    cell_keys[index] = cell_index(cell_of(particles[index].position.xyz));
    particle_ids[index] = index;
}
