// The rest timers and the sleep test on the device (dynamics/rest_gpu.rs): Islands::update_timers
// over the velocities the step solved, and whether Islands::fall_asleep could put an island to
// sleep, so that the host reads the timers and runs it only then. Lengths are summed in glam's
// order (dot3), as the host's; a GPU may still round the square root differently, which can
// move a body's rest by a step only where its speed is the threshold to rounding.
// Needs body.wgsl (ColliderData, dot3) and solver_body.wgsl; SLEEP_SPEED and TIME_TO_SLEEP.

struct RestParams {
    bodies: u32,
    // The step (s): what a resting body's timer gains.
    dt: f32,
    // 1 where this step's islands were linked on the device (`roots`): then the test runs.
    test: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: RestParams;
// The step's held word (stages/integrate/finalize.wgsl): 0 where the step did not hold and is
// solved again, so its timers must not move.
@group(0) @binding(1) var<storage, read> held: array<u32>;
// The step's solved bodies: velocities, and inverse mass 0 for static and sleeping bodies.
@group(0) @binding(2) var<storage, read> bodies: array<SolverBody>;
@group(0) @binding(3) var<storage, read> colliders: array<ColliderData>;
@group(0) @binding(4) var<storage, read_write> timers: array<f32>;
// Word 0: the largest rest time of an awake dynamic body, as bits (non-negative floats order
// as their bits); 1: how many have rested TIME_TO_SLEEP; 2: how many of those are in an island
// nothing holds awake (the test's). Zeroed before the kernels.
@group(0) @binding(5) var<storage, read_write> tally: array<atomic<u32>>;
// Each body's island root (dynamics/island.wgsl after `flatten`), read where `test` is 1.
@group(0) @binding(6) var<storage, read> roots: array<u32>;
// Per root: not 0 where an awake body that has not rested holds its island. Zeroed before.
@group(0) @binding(7) var<storage, read_write> holds: array<atomic<u32>>;

var<workgroup> group_max: atomic<u32>;
var<workgroup> group_rested: atomic<u32>;

// A thread a body: its timer, the tally (summed in the workgroup first: one word takes every
// body's maximum), and the hold of its root where it has not rested.
@compute @workgroup_size(WORKGROUP_SIZE)
fn rest(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if local == 0u {
        atomicStore(&group_max, 0u);
        atomicStore(&group_rested, 0u);
    }
    workgroupBarrier();
    if index < params.bodies && held[0] != 0u && bodies[index].inverse_mass != 0.0 {
        let body = bodies[index];
        let linear = sqrt(dot3(body.linear_velocity, body.linear_velocity));
        let angular = sqrt(dot3(body.angular_velocity, body.angular_velocity));
        // As on the host: a body whose centre alone moves at SLEEP_SPEED is not resting.
        let resting = linear < SLEEP_SPEED
            && linear + colliders[index].bounding_radius * angular < SLEEP_SPEED;
        var timer = 0.0;
        if resting {
            timer = timers[index] + params.dt;
        }
        timers[index] = timer;
        atomicMax(&group_max, bitcast<u32>(timer));
        if timer >= TIME_TO_SLEEP {
            atomicAdd(&group_rested, 1u);
        } else if params.test != 0u {
            atomicStore(&holds[roots[index]], 1u);
        }
    }
    workgroupBarrier();
    if local == 0u {
        let rested = atomicLoad(&group_rested);
        // An empty workgroup's maximum is 0, no rest time: it changes nothing.
        atomicMax(&tally[0], atomicLoad(&group_max));
        if rested != 0u {
            atomicAdd(&tally[1], rested);
        }
    }
}

// A thread a body, a dispatch after `rest` (every hold made): counts the rested bodies whose
// island nothing holds, those Islands::fall_asleep would put to sleep. The device's islands
// join the contacts only, not the joints, and nothing here keeps the dragged body awake: its
// islands are the host's or smaller, so it counts at least the host's sleepers, and 0 means
// none.
@compute @workgroup_size(WORKGROUP_SIZE)
fn sleepers(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    if index >= params.bodies || held[0] == 0u || bodies[index].inverse_mass == 0.0 {
        return;
    }
    if timers[index] >= TIME_TO_SLEEP && atomicLoad(&holds[roots[index]]) == 0u {
        atomicAdd(&tally[2], 1u);
    }
}
