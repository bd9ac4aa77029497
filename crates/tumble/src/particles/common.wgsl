// Data and arithmetic shared by the particle kernels; the CPU twin is `cpu.rs`, operation for
// operation. Injected: EMPTY_CELL.

struct Particle {
    position: vec4<f32>,
    velocity: vec4<f32>,
}

struct ParticleParams {
    origin: vec3<f32>,
    cell_size: f32,
    grid: vec3<u32>,
    count: u32,
    gravity: vec3<f32>,
    dt: f32,
    radius: f32,
    inverse_mass: f32,
    spring: f32,
    damping: f32,
    shear: f32,
    wall_spring: f32,
    wall_damping: f32,
    cell_count: u32,
    force_scale: f32,
    force_quantum: f32,
    padding0: u32,
    padding1: u32,
}

@group(0) @binding(0) var<uniform> params: ParticleParams;

fn particle_index(
    local: u32,
    workgroup: vec3<u32>,
    groups: vec3<u32>,
) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
}

// The cell holding `position`, clamped into the grid.
fn cell_of(position: vec3<f32>) -> vec3<u32> {
    let scaled = floor((position - params.origin) / params.cell_size);
    return vec3<u32>(clamp(scaled, vec3<f32>(0.0), vec3<f32>(params.grid - vec3<u32>(1u))));
}

// x fastest, then y, then z.
fn cell_index(cell: vec3<u32>) -> u32 {
    return (cell.z * params.grid.y + cell.y) * params.grid.x + cell.x;
}

// Force on the particle at (position, velocity) from the other one (N): spring on the
// overlap, damping of the normal relative velocity, shear damping of the tangential one.
fn pair_force(
    position: vec3<f32>,
    velocity: vec3<f32>,
    other_position: vec3<f32>,
    other_velocity: vec3<f32>,
) -> vec3<f32> {
    let offset = other_position - position;
    let distance_squared = dot(offset, offset);
    let contact = 2.0 * params.radius;
    if distance_squared >= contact * contact || distance_squared == 0.0 {
        return vec3<f32>(0.0);
    }
    let distance = sqrt(distance_squared);
    let normal = offset * (1.0 / distance);
    let relative = other_velocity - velocity;
    let normal_speed = dot(relative, normal);
    let tangential = relative - normal * normal_speed;
    return normal * (params.damping * normal_speed - params.spring * (contact - distance))
        + tangential * params.shear;
}

// Largest pair force in fixed point (quanta), so that sums of up to 32 cannot overflow.
const MAX_PAIR_QUANTA: f32 = 67108864.0;

// A pair force in fixed point: integer sums do not depend on the order of the additions.
fn quantize(force: vec3<f32>) -> vec3<i32> {
    let quanta = round(force * params.force_scale);
    return vec3<i32>(clamp(quanta, vec3<f32>(-MAX_PAIR_QUANTA), vec3<f32>(MAX_PAIR_QUANTA)));
}

// The six walls (the ground is the lower y wall), spring–dampers (N).
fn wall_force(position: vec3<f32>, velocity: vec3<f32>) -> vec3<f32> {
    var force = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis++) {
        let low = params.origin[axis] + params.radius;
        let high = params.origin[axis] + f32(params.grid[axis]) * params.cell_size - params.radius;
        let below = low - position[axis];
        if below > 0.0 {
            force[axis] += params.wall_spring * below - params.wall_damping * velocity[axis];
        }
        let above = position[axis] - high;
        if above > 0.0 {
            force[axis] -= params.wall_spring * above + params.wall_damping * velocity[axis];
        }
    }
    return force;
}

// Semi-implicit Euler: velocity first, then position with the new velocity.
fn integrate(position: vec3<f32>, velocity: vec3<f32>, force: vec3<f32>) -> Particle {
    let acceleration = force * params.inverse_mass + params.gravity;
    let new_velocity = velocity + acceleration * params.dt;
    let new_position = position + new_velocity * params.dt;
    return Particle(vec4<f32>(new_position, 0.0), vec4<f32>(new_velocity, 0.0));
}
