// integrate::prepare_bodies on the device: the solver's bodies at the start of the step, from
// the bodies' velocities and masses already there (stages/integrate/gpu.rs), so the step
// uploads no solver body. Dynamic bodies keep their velocities, the rest get none; no motion
// yet. Needs body.wgsl, solver_body.wgsl and body_count.wgsl.

@group(0) @binding(0) var<uniform> params: BodyCount;
@group(0) @binding(1) var<storage, read> velocities: array<BodyVelocity>;
@group(0) @binding(2) var<storage, read> masses: array<BodyMass>;
@group(0) @binding(3) var<storage, read_write> bodies: array<SolverBody>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn prepare_bodies(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.count {
        return;
    }
    let inverse_mass = masses[index].inverse_mass;
    let dynamic = inverse_mass > 0.0;
    var body = static_solver_body();
    body.linear_velocity = select(vec3<f32>(0.0), velocities[index].linear, dynamic);
    body.inverse_mass = inverse_mass;
    body.angular_velocity = select(vec3<f32>(0.0), velocities[index].angular, dynamic);
    bodies[index] = body;
}
