// Batching rounds (see `stages/batching/mod.rs`): in each round every unbatched constraint
// takes its tentative color and claims its dynamic bodies' lock slots for that color with its
// priority (atomicMin into the round's half of `locks`), then the constraints that hold all
// their slots are batched. The constants MAX_COLORS, STATIC_BODY, UNBATCHED, LOCK_SLOTS and
// the batcher ids come from Rust.

struct BatchParams {
    body_count: u32,
    round: u32,
    batcher: u32,
    // The first `ordered` constraints (joints) rank by index.
    ordered: u32,
}

// The constraint count lives in a buffer, not in the parameters, so the dispatches (sized for
// the buffers' capacity) are built once and serve every step.
struct Tally {
    // How many constraints have a batch: the rounds stop working once all have one.
    batched: atomic<u32>,
    count: u32,
    // Rounds that found a constraint left to batch (written by thread 0 of each claim), so
    // that the host encodes no more of them than the next steps need.
    rounds: u32,
    // The first round that started with at most REST_LIST constraints left (NO_ROUND until
    // one did), from which `rest_rounds` runs the rounds in one workgroup about as fast as
    // their dispatches: the host dispatches rounds up to about there.
    listable_from: u32,
}

@group(0) @binding(0) var<uniform> params: BatchParams;
// Per constraint: its two bodies (STATIC_BODY for a static one).
@group(0) @binding(1) var<storage, read> bodies: array<vec2<u32>>;
// Per constraint: its color, UNBATCHED until a round batches it, MAX_COLORS for overflow.
@group(0) @binding(2) var<storage, read_write> colors: array<u32>;
// Two halves of LOCK_SLOTS locks a body (body-major): round r claims half r % 2 and resets the
// other half for round r + 1, so no dispatch both claims and clears one lock.
@group(0) @binding(3) var<storage, read_write> locks: array<atomic<u32>>;
// Per body: the colors its constraints have (words 2b and 2b + 1: low, high), overflow aside.
// Atomic: a round's winners on one body (of different colors) set their bits together.
@group(0) @binding(4) var<storage, read_write> masks: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> tally: Tally;
// Per constraint: the color its claim of this round took, which its commit reads.
@group(0) @binding(6) var<storage, read_write> tentative: array<u32>;

const NO_LOCK: u32 = 0xffffffffu;
const NO_ROUND: u32 = 0xffffffffu;

// Twin of `priority` in `mod.rs`: joints by index, then a bijective 31-bit hash above 2^31.
fn priority(index: u32) -> u32 {
    if index < params.ordered {
        return index;
    }
    let low_31 = 0x7fffffffu;
    var x = index & low_31;
    x ^= x >> 16u;
    x = (x * 0x7feb352du) & low_31;
    x ^= x >> 15u;
    x = (x * 0x846ca68bu) & low_31;
    x ^= x >> 16u;
    return 0x80000000u | x;
}

fn thread_index(id: vec3<u32>, workgroup: vec3<u32>, groups: vec3<u32>) -> u32 {
    return flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + id.x;
}

// Every round's kernels return at once when all constraints have a batch: the rounds are
// encoded up to MAX_ROUNDS, most of them usually find nothing left.
fn all_batched() -> bool {
    return atomicLoad(&tally.batched) == tally.count;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn start(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = thread_index(id, workgroup, groups);
    if i < tally.count {
        colors[i] = UNBATCHED;
    }
    if i < params.body_count {
        for (var slot = 0u; slot < LOCK_SLOTS; slot++) {
            atomicStore(&locks[i * LOCK_SLOTS + slot], NO_LOCK);
            atomicStore(&locks[(params.body_count + i) * LOCK_SLOTS + slot], NO_LOCK);
        }
        atomicStore(&masks[2u * i], 0u);
        atomicStore(&masks[2u * i + 1u], 0u);
    }
    if i == 0u {
        atomicStore(&tally.batched, 0u);
        tally.rounds = 0u;
        tally.listable_from = NO_ROUND;
    }
}

// Round `round`'s claim by constraint `i`, which also counts the round if `i` is 0.
fn claim_one(i: u32, round: u32) {
    // Commits happen after every claim of the round: no claim changes what another sees here.
    if i == 0u {
        let left = tally.count - atomicLoad(&tally.batched);
        if left > 0u {
            tally.rounds = round + 1u;
        }
        if left <= REST_LIST && tally.listable_from == NO_ROUND {
            tally.listable_from = round;
        }
    }
    claim_constraint(i, round);
}

// The lock of `body` for color `color` in the half that starts at body `half`: the colors
// batcher's slot `color % LOCK_SLOTS`, the rounds batcher's only slot (its color is the
// round's).
fn lock_index(half: u32, body: u32, color: u32) -> u32 {
    let slot = select(0u, color % LOCK_SLOTS, params.batcher == BATCHER_COLORS);
    return (half + body) * LOCK_SLOTS + slot;
}

// Round `round`'s claim by constraint `i`: its tentative color (the lowest free on its bodies,
// or the round's), and its priority into its dynamic bodies' locks for that color.
fn claim_constraint(i: u32, round: u32) {
    if all_batched() || i >= tally.count || colors[i] != UNBATCHED {
        return;
    }
    let half = (round % 2u) * params.body_count;
    let pair = bodies[i];
    var color = round;
    if params.batcher == BATCHER_COLORS {
        // The masks as the last round's commit left them: this round's commit changes them
        // only after every claim.
        var used = vec2<u32>(0u);
        for (var k = 0u; k < 2u; k++) {
            if pair[k] != STATIC_BODY {
                used |= vec2<u32>(atomicLoad(&masks[2u * pair[k]]),
                    atomicLoad(&masks[2u * pair[k] + 1u]));
            }
        }
        color = lowest_free_color(used);
    }
    tentative[i] = color;
    let p = priority(i);
    // A joint (ranked by index) claims every slot: on its bodies no contact, and no later
    // joint, wins before it, as with one lock a body (the module docs of mod.rs say why).
    let ordered = i < params.ordered;
    for (var k = 0u; k < 2u; k++) {
        if pair[k] != STATIC_BODY {
            if ordered {
                for (var slot = 0u; slot < LOCK_SLOTS; slot++) {
                    atomicMin(&locks[(half + pair[k]) * LOCK_SLOTS + slot], p);
                }
            } else {
                atomicMin(&locks[lock_index(half, pair[k], color)], p);
            }
        }
    }
}

// The claim dispatch's threads cover the constraints and the bodies: thread `i` claims for
// constraint i and clears body i's locks in the half round + 1 claims, which no kernel of this
// round reads or writes (round − 1's commit was the last to read it). Body by body and
// coalesced, once a body: each commit cleared its bodies' slots instead, a body's once for
// each of its constraints still unbatched (about five a box on a pile), with scattered stores.
@compute @workgroup_size(WORKGROUP_SIZE)
fn claim(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = thread_index(id, workgroup, groups);
    claim_one(i, params.round);
    if i < params.body_count && !all_batched() {
        let next_half = params.body_count - (params.round % 2u) * params.body_count;
        clear_locks(next_half, i);
    }
}

// Body `body`'s locks in the half that starts at body `half`: free for the next round's claims.
fn clear_locks(half: u32, body: u32) {
    for (var slot = 0u; slot < LOCK_SLOTS; slot++) {
        atomicStore(&locks[(half + body) * LOCK_SLOTS + slot], NO_LOCK);
    }
}

// The lowest color in neither mask, or MAX_COLORS when all 64 are taken.
fn lowest_free_color(used: vec2<u32>) -> u32 {
    if used.x != 0xffffffffu {
        return firstTrailingBit(~used.x);
    }
    if used.y != 0xffffffffu {
        return 32u + firstTrailingBit(~used.y);
    }
    return MAX_COLORS;
}

// Round `round`'s commit by constraint `i`: batched, with its tentative color, when it holds
// all its bodies' locks for that color (whether it did is returned; the caller counts it in
// `tally.batched`). Winners on one body have different colors. With `clear_next`, it clears
// its bodies' locks in the next round's half (`rest_rounds`, whose rounds have no claim
// dispatch to do it).
fn commit_one(i: u32, round: u32, clear_next: bool) -> bool {
    if all_batched() || i >= tally.count || colors[i] != UNBATCHED {
        return false;
    }
    let half = (round % 2u) * params.body_count;
    let next_half = params.body_count - half;
    let pair = bodies[i];
    let p = priority(i);
    let color = tentative[i];
    var won = true;
    for (var k = 0u; k < 2u; k++) {
        if pair[k] != STATIC_BODY {
            won = won && atomicLoad(&locks[lock_index(half, pair[k], color)]) == p;
            if clear_next {
                clear_locks(next_half, pair[k]);
            }
        }
    }
    if !won {
        return false;
    }
    // Both batchers record each body's colors: the colors batcher chooses by them, and the
    // solver's warm start finds a body's constraints by them (`adjacency.wgsl`).
    if color < MAX_COLORS {
        for (var k = 0u; k < 2u; k++) {
            if pair[k] != STATIC_BODY {
                atomicOr(&masks[2u * pair[k] + color / 32u], 1u << (color % 32u));
            }
        }
    }
    colors[i] = color;
    return true;
}

// The commit's winners of one workgroup, added to `tally.batched` once: a global atomic a
// winner made the commits of a pile's first rounds wait on one address (hundreds of thousands
// of adds on it a round).
var<workgroup> group_batched: atomic<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn commit(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    if id.x == 0u {
        atomicStore(&group_batched, 0u);
    }
    workgroupBarrier();
    if commit_one(thread_index(id, workgroup, groups), params.round, false) {
        atomicAdd(&group_batched, 1u);
    }
    workgroupBarrier();
    if id.x == 0u {
        let won = atomicLoad(&group_batched);
        if won > 0u {
            atomicAdd(&tally.batched, won);
        }
    }
}

// Constraint `i`'s commit in `rest_rounds`, counted at once (one workgroup: few adds).
fn commit_and_count(i: u32, round: u32) {
    if commit_one(i, round, true) {
        atomicAdd(&tally.batched, 1u);
    }
}

var<workgroup> rest_done: u32;
// The constraints still unbatched when `rest_rounds` starts, if no more than REST_LIST (from
// Rust).
var<workgroup> rest_list: array<u32, REST_LIST>;
var<workgroup> rest_count: atomic<u32>;
var<workgroup> rest_listed: u32;

// Rounds params.round to MAX_ROUNDS − 1 in one workgroup, a barrier between each claim and
// commit: the same rounds as their dispatches, for the few constraints a step's encoded
// rounds left unbatched (usually none: it returns at once). One dispatch whatever is left,
// so no host has to read back whether anything was. The constraints left are listed first
// (one pass over all of them), so that each round goes over those alone: going over all of
// them in each round (a claim pass and a commit pass), this dispatch took 0.17 ms a step on
// average on an H100 (a settled pile of 100k boxes, 250k constraints). More than REST_LIST
// left, each round goes over all of them.
@compute @workgroup_size(WORKGROUP_SIZE)
fn rest_rounds(@builtin(local_invocation_index) local: u32) {
    if local == 0u {
        rest_done = u32(all_batched());
        atomicStore(&rest_count, 0u);
        if rest_done != 0u && tally.listable_from == NO_ROUND {
            tally.listable_from = params.round;
        }
    }
    if workgroupUniformLoad(&rest_done) != 0u {
        return;
    }
    let count = tally.count;
    for (var i = local; i < count; i += WORKGROUP_SIZE) {
        if colors[i] == UNBATCHED {
            let slot = atomicAdd(&rest_count, 1u);
            if slot < REST_LIST {
                rest_list[slot] = i;
            }
        }
        if ends_stride(i, count) {
            break;
        }
    }
    workgroupBarrier();
    if local == 0u {
        rest_listed = atomicLoad(&rest_count);
        if rest_listed <= REST_LIST && tally.listable_from == NO_ROUND {
            tally.listable_from = params.round;
        }
    }
    let listed = workgroupUniformLoad(&rest_listed);
    if listed > REST_LIST {
        rest_rounds_over_all(local, count);
        return;
    }
    // Which constraint a thread takes changes no color: a round's claims are minima, and its
    // winners share no body.
    for (var round = params.round; round < MAX_ROUNDS; round++) {
        if local == 0u {
            rest_done = u32(all_batched());
            // The count of the rounds, which claim_one leaves to constraint 0 (not listed
            // once batched).
            if rest_done == 0u {
                tally.rounds = round + 1u;
            }
        }
        if workgroupUniformLoad(&rest_done) != 0u {
            break;
        }
        for (var j = local; j < listed; j += WORKGROUP_SIZE) {
            claim_constraint(rest_list[j], round);
        }
        storageBarrier();
        for (var j = local; j < listed; j += WORKGROUP_SIZE) {
            commit_and_count(rest_list[j], round);
        }
        storageBarrier();
    }
}

// Whether index `i` of a loop over 0..count by strides of WORKGROUP_SIZE is its last: the loop
// stops there rather than step past u32::MAX, so it ends whatever `count` holds (the
// kernels' source promises that every loop ends: gpu.rs).
fn ends_stride(i: u32, count: u32) -> bool {
    return count - i <= WORKGROUP_SIZE;
}

// `rest_rounds` over every one of the `count` constraints, round by round.
fn rest_rounds_over_all(local: u32, count: u32) {
    for (var round = params.round; round < MAX_ROUNDS; round++) {
        if local == 0u {
            rest_done = u32(all_batched());
        }
        if workgroupUniformLoad(&rest_done) != 0u {
            break;
        }
        for (var i = local; i < count; i += WORKGROUP_SIZE) {
            claim_one(i, round);
            if ends_stride(i, count) {
                break;
            }
        }
        storageBarrier();
        for (var i = local; i < count; i += WORKGROUP_SIZE) {
            commit_and_count(i, round);
            if ends_stride(i, count) {
                break;
            }
        }
        storageBarrier();
    }
}

// After the last round: what is left goes to the overflow batch.
@compute @workgroup_size(WORKGROUP_SIZE)
fn finish(
    @builtin(local_invocation_id) id: vec3<u32>,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = thread_index(id, workgroup, groups);
    if i >= tally.count || colors[i] != UNBATCHED {
        return;
    }
    colors[i] = MAX_COLORS;
}
