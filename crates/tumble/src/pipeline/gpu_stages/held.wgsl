// Whether a step whose rows, batching and solve were submitted with its collision, before the
// host read the collision's counts (pipeline/gpu_stages/speculation.rs), guessed them right,
// and the counts the host would have sent the batching and the solver: the rows' where it did,
// none where it did not (then they color and solve nothing, and the integration and the
// impulses' scatter write nothing).

// Words: the pairs whose keys the rows read (the collision copied no more), the constraints
// the rows have room for, 1 when the solve was recorded with the restitution sweep, else 0,
// and 1 when bodies sleep (the collision ran the wake test), else 0.
@group(0) @binding(0) var<storage, read> guess: array<u32>;
// Word 0: the pair count (the broadphase's).
@group(0) @binding(1) var<storage, read> pair_count: array<u32>;
// The collision's tally of the rows (stages/constraints/tally.wgsl): word 1 the rows, word 2
// those that bounce.
@group(0) @binding(2) var<storage, read> tally: array<u32>;
// finalize.wgsl's word: 1 where the step held, else 0.
@group(0) @binding(3) var<storage, read_write> held: array<u32>;
// The batching's tally (stages/batching/batching.wgsl): word 1 the constraints to color.
@group(0) @binding(4) var<storage, read_write> batching_tally: array<u32>;
// The batched solve's counts (stages/solver/batched.wgsl): word 0 the contact constraints.
@group(0) @binding(5) var<storage, read_write> batched_count: array<u32>;
// Not 0 where the wake test found an island that wakes (dynamics/wake.wgsl): it changes the
// masses the rows were built with.
@group(0) @binding(6) var<storage, read> wakers: array<u32>;

@compute @workgroup_size(1)
fn hold_step() {
    let rows = tally[1];
    let bounces = select(0u, 1u, tally[2] > 0u);
    let fits = pair_count[0] <= guess[0] && rows > 0u && rows <= guess[1];
    let wakes = guess[3] != 0u && wakers[0] != 0u;
    let ok = fits && bounces == guess[2] && !wakes;
    held[0] = select(0u, 1u, ok);
    let count = select(0u, rows, ok);
    batching_tally[1] = count;
    batched_count[0] = count;
}
