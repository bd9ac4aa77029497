// Reduction of `count` scalars to one per block of BLOCK = WORKGROUP_SIZE × ITEMS_PER_THREAD.
// Injected before this file: `alias Scalar`, `fn identity() -> Scalar`,
// `fn combine(a: Scalar, b: Scalar) -> Scalar`. The order of combination is fixed (thread t
// folds items t, t + WORKGROUP_SIZE, …, then a halving tree), so a float sum is the same every
// run, and the CPU twin repeats it exactly.

struct ReduceParams {
    // Values of this window.
    count: u32,
    // The window's first block, numbered over the whole level: where its results go.
    first_block: u32,
    padding1: u32,
    padding2: u32,
}

@group(0) @binding(0) var<uniform> params: ReduceParams;
@group(0) @binding(1) var<storage, read> source: array<Scalar>;
@group(0) @binding(2) var<storage, read_write> destination: array<Scalar>;

const BLOCK: u32 = WORKGROUP_SIZE * ITEMS_PER_THREAD;

var<workgroup> partial: array<Scalar, WORKGROUP_SIZE>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn reduce(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = flat_workgroup(workgroup, groups);
    // An empty input still gets one block, which writes the identity.
    if block * BLOCK >= max(params.count, 1u) {
        return;
    }
    var accumulated = identity();
    for (var item = 0u; item < ITEMS_PER_THREAD; item++) {
        let index = block * BLOCK + item * WORKGROUP_SIZE + local;
        if index < params.count {
            accumulated = combine(accumulated, source[index]);
        }
    }
    partial[local] = accumulated;
    workgroupBarrier();
    for (var stride = WORKGROUP_SIZE / 2u; stride > 0u; stride >>= 1u) {
        if local < stride {
            partial[local] = combine(partial[local], partial[local + stride]);
        }
        workgroupBarrier();
    }
    if local == 0u {
        destination[params.first_block + block] = partial[0];
    }
}
