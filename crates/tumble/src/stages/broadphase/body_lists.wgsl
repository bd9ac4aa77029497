// The trees' body lists from the static bits (stages/broadphase/gpu.rs, set_bodies): the
// dynamic bodies in index order for the moving tree, the static ones for the fixed tree. An
// exclusive scan of the dynamic flags gives each dynamic body its place; a static body's place
// is its index less the dynamic bodies before it.

struct ListParams {
    bodies: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: ListParams;
// Bit b % 32 of word b / 32: body b is static.
@group(0) @binding(1) var<storage, read> static_bits: array<u32>;
// Per body: 1 when dynamic (`flag_dynamic`), then the scan of those (`place_bodies`).
@group(0) @binding(2) var<storage, read_write> flags: array<u32>;
@group(0) @binding(3) var<storage, read_write> places: array<u32>;
@group(0) @binding(4) var<storage, read_write> dynamic_bodies: array<u32>;
@group(0) @binding(5) var<storage, read_write> static_bodies: array<u32>;

fn is_static(body: u32) -> bool {
    return ((static_bits[body >> 5u] >> (body & 31u)) & 1u) != 0u;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn flag_dynamic(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body < params.bodies {
        flags[body] = select(1u, 0u, is_static(body));
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn place_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let body = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if body >= params.bodies {
        return;
    }
    let place = places[body];
    if is_static(body) {
        static_bodies[body - place] = body;
    } else {
        dynamic_bodies[place] = body;
    }
}
