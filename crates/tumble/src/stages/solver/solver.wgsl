// The soft step's kernels (stages/solver/mod.rs explains the step; contact.rs holds the CPU
// twins of the contact functions here, joint.rs those of solver_joint.wgsl, in the same order
// of operations).
//
// Constraints lie batch after batch: batch b is contact constraints offsets[b] .. offsets[b + 1]
// (in lanes.wgsl's layout) and joints[joint_offsets[b] .. joint_offsets[b + 1]]. A dispatch
// covers the batches first_batch .. end_batch:
//   - parallel (sequential == 0): one batch, one thread per constraint (its contacts, then
//     its joints). The batch's constraints share no dynamic body, so no two threads touch the
//     same body.
//   - sequential == 1: one workgroup walks a run of small batches in order, its threads
//     sharing each batch, a storage barrier after each (same results as one dispatch each);
//     its thread 0 alone takes the overflow batch when the run holds it (overflow_batch:
//     a device layout's batches are all walked, sizes unknown to the host);
//   - sequential == 2: thread 0 alone solves the overflow batch in order, contacts first.
// Dispatches whose batches hold no joint run the contact-only kernels (warm_start, solve,
// restitution; a walk their *_walk twins, in a larger workgroup); the others their *_mixed
// twins (see sweep_mixed).

struct SolverParams {
    gravity: vec3<f32>,
    // Sub-step length (s).
    h: f32,
    first_batch: u32,
    end_batch: u32,
    sequential: u32,
    // Remove position errors (solve) or not (relax); 1 or 0.
    use_bias: u32,
    max_push_velocity: f32,
    restitution_threshold: f32,
    body_count: u32,
    // The overflow batch when a walk may hold it, else 0xffffffff.
    overflow_batch: u32,
    // The contact rows' softness between dynamic bodies and against a static one, as
    // (bias_rate, mass_scale, impulse_scale, unused): load_header takes it from here.
    softness: vec4<f32>,
    static_softness: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: SolverParams;
@group(0) @binding(1) var<storage, read_write> bodies: array<SolverBody>;
// The contact constraints in blocks of lanes (lanes.wgsl), a vec4 a word.
@group(0) @binding(2) var<storage, read_write> contacts: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read_write> joints: array<JointConstraint>;
@group(0) @binding(5) var<storage, read> joint_offsets: array<u32>;

fn load_body(index: u32) -> SolverBody {
    if index == STATIC_BODY {
        return static_solver_body();
    }
    return bodies[index];
}

// The velocities of `body` into body `index`: a sweep changes nothing else of a body (its
// delta position and rotation are the integrator's), and the sweeps are bound by their memory
// traffic, of which writing whole bodies was about a fifth of a constraint's bytes.
fn store_body(index: u32, body: SolverBody) {
    if index != STATIC_BODY {
        bodies[index].linear_velocity = body.linear_velocity;
        bodies[index].angular_velocity = body.angular_velocity;
    }
}

// The two bodies a constraint moves, [0] = A and [1] = B, passed through the row functions
// by value: kept in registers rather than in private variables, with which lavapipe ran
// tests/engine/gpu_solver.rs in 401 s instead of 1.9 s.
alias BodyPair = array<SolverBody, 2>;

// The moments of a row's direction d at a point, r × d for each side: [0] A's, [1] B's.
alias Arms = array<vec3<f32>, 2>;

fn arms_of(point: PointRows, direction: vec3<f32>) -> Arms {
    return Arms(cross(point.anchor_a, direction), cross(point.anchor_b, direction));
}

// How fast A moves away from B along `direction` at a point with moments `arms` (m/s).
fn row_velocity(direction: vec3<f32>, arms: Arms, pair: BodyPair) -> f32 {
    return dot(direction, pair[0].linear_velocity - pair[1].linear_velocity)
        + dot(arms[0], pair[0].angular_velocity) - dot(arms[1], pair[1].angular_velocity);
}

// `impulse` along a row of direction `direction` and moments `arms`: +impulse to A, −impulse
// to B. The rows keep no I⁻¹(r × d): three multiply-adds a component cost less than reading
// them (lanes.wgsl; contact.rs says why).
fn apply(h: ConstraintHeader, direction: vec3<f32>, arms: Arms, impulse: f32, pair: BodyPair)
    -> BodyPair {
    var out = pair;
    out[0].linear_velocity += direction * (impulse * h.mass_a);
    out[0].angular_velocity += symmetric_mul(h.inertias[0], arms[0]) * impulse;
    out[1].linear_velocity -= direction * (impulse * h.mass_b);
    out[1].angular_velocity -= symmetric_mul(h.inertias[1], arms[1]) * impulse;
    return out;
}

// A constraint's point data is loaded into registers before the rows are solved and stored
// after them, with the four point slots written out (guarded by the point count) rather than
// looped over. Drivers do not unroll naga's loops, and a store into `contacts` inside a loop
// keeps the next iteration's loads from being issued before it: the per-point loop made a
// constraint a chain of a memory round trip per point and pass, the latency that bounds
// these kernels, which have a thread per constraint and few threads. Copying a whole
// constraint indexed by a loop variable is no way out either: it is spilled to local memory
// at every such index (1 KB each time), which made each dispatch on an H100 take about
// 100 µs instead of a few. The order of operations is the CPU's (contact.rs): points 0 to
// count − 1, normal rows, then friction rows.

// The rows and state of one point as the sweeps read and write them: its words (lanes.wgsl)
// but the one of masses, which a solve sweep computes, and the separation, which it computes
// from the bodies' motion (`solve_normal`).
struct PointRows {
    anchor_a: vec3<f32>,
    adjusted_separation: f32,
    anchor_b: vec3<f32>,
    // The rows' masses: normal, tangent 1, tangent 2. Computed by the solve sweep from the
    // anchors and the header (`point_masses`), not loaded: see `load_header`.
    masses: vec3<f32>,
    // The rows' impulses (normal, tangents) and the largest normal impulse.
    impulses: vec4<f32>,
}

fn no_point() -> PointRows {
    return PointRows(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec4<f32>(0.0));
}

// Body A, body B, the pair slot and the point count of constraint `index`.
fn load_ids(index: u32) -> vec4<u32> {
    return bitcast<vec4<u32>>(contacts[lane_word(index, HEADER_IDS)]);
}

// Point `k` of constraint `index` except its rows' masses, or no point past its count (then
// never used).
fn load_point(index: u32, k: u32, count: u32) -> PointRows {
    if k >= count {
        return no_point();
    }
    let anchor_a = contacts[point_word(index, k, POINT_ANCHOR_A)];
    let anchor_b = contacts[point_word(index, k, POINT_ANCHOR_B)];
    let impulses = contacts[point_word(index, k, POINT_IMPULSES)];
    return PointRows(anchor_a.xyz, anchor_a.w, anchor_b.xyz, vec3<f32>(0.0), impulses);
}

// Stores the impulses of point `k` of constraint `index`: the rows' and the largest normal
// one, in one word.
fn store_impulses(index: u32, k: u32, normal: f32, tangent1: f32, tangent2: f32, max_normal: f32) {
    contacts[point_word(index, k, POINT_IMPULSES)] =
        vec4<f32>(normal, tangent1, tangent2, max_normal);
}

// Stores what a solve sweep changed of point `k`: its impulses.
fn store_point(index: u32, k: u32, count: u32, point: PointRows) {
    if k >= count {
        return;
    }
    contacts[point_word(index, k, POINT_IMPULSES)] = point.impulses;
}

// The manifold-wide data of a constraint.
struct ConstraintHeader {
    normal: vec3<f32>,
    tangent1: vec3<f32>,
    tangent2: vec3<f32>,
    mass_a: f32,
    mass_b: f32,
    friction: f32,
    softness: Softness,
    // The world-frame inverse inertias, A's and B's.
    inertias: array<SymmetricMat3, 2>,
}

// The header of constraint `index` on bodies `pair`, from 4 of its 8 words (the ids, word 0,
// come apart). A sweep's time grows with the bytes it loads (0.3 ns a constraint on an H100,
// about half the sweeps' time on the settled 100k pile and three quarters at 500k), so what
// the other words hold comes from elsewhere: the tangents from the normal (tangent_basis, as
// the rows' build makes them), the inverse masses from the bodies (prepare_bodies and the rows
// read the same masses; a static side is 0 in both), the softness from the parameters (the
// rows' two, chosen as the build chooses: by a zero inverse mass), and the restitution, which
// the restitution sweep alone needs, from its word there. A solve sweep also computes the rows'
// masses (`point_masses`) instead of loading a word a point. For rows the device built, each
// is the arithmetic that made the value it replaces (the results were bitwise the same on
// lavapipe and an H100); for rows the host built, they agree to rounding, as the executors do.
fn load_header(index: u32, pair: BodyPair) -> ConstraintHeader {
    let normal = contacts[lane_word(index, HEADER_NORMAL)];
    var softness = params.softness;
    if pair[0].inverse_mass == 0.0 || pair[1].inverse_mass == 0.0 {
        softness = params.static_softness;
    }
    let inertias = inertias_of(array<vec4<f32>, 3>(contacts[lane_word(index, HEADER_INERTIA)],
        contacts[lane_word(index, HEADER_INERTIA + 1u)],
        contacts[lane_word(index, HEADER_INERTIA + 2u)]));
    let tangents = tangent_basis(normal.xyz);
    return ConstraintHeader(normal.xyz, tangents[0], tangents[1], pair[0].inverse_mass,
        pair[1].inverse_mass, normal.w, Softness(softness.x, softness.y, softness.z), inertias);
}

fn warm_start_contact(index: u32) {
    let ids = load_ids(index);
    let pair = warm_start_contact_pair(index, BodyPair(load_body(ids.x), load_body(ids.y)));
    store_body(ids.x, pair[0]);
    store_body(ids.y, pair[1]);
}

fn warm_start_point(h: ConstraintHeader, point: PointRows, pair: BodyPair) -> BodyPair {
    let impulses = point.impulses;
    var out = apply(h, h.normal, arms_of(point, h.normal), impulses.x, pair);
    out = apply(h, h.tangent1, arms_of(point, h.tangent1), impulses.y, out);
    return apply(h, h.tangent2, arms_of(point, h.tangent2), impulses.z, out);
}

// The row functions take the two bodies and return them moved, wherever they come from: the
// PGS sweeps load and store them in `bodies`, the Jacobi sweeps (jacobi.wgsl) keep copies.
fn warm_start_contact_pair(index: u32, start: BodyPair) -> BodyPair {
    let count = load_ids(index).w;
    let h = load_header(index, start);
    let p0 = load_point(index, 0u, count);
    let p1 = load_point(index, 1u, count);
    let p2 = load_point(index, 2u, count);
    let p3 = load_point(index, 3u, count);
    var pair = start;
    if count > 0u {
        pair = warm_start_point(h, p0, pair);
    }
    if count > 1u {
        pair = warm_start_point(h, p1, pair);
    }
    if count > 2u {
        pair = warm_start_point(h, p2, pair);
    }
    if count > 3u {
        pair = warm_start_point(h, p3, pair);
    }
    return pair;
}

// Bias, mass scale and impulse scale of a row with separation `error` (bias_terms on the CPU).
fn bias_terms(error: f32, softness: Softness) -> vec3<f32> {
    if error > 0.0 {
        return vec3<f32>(error / params.h, 1.0, 0.0);
    }
    if params.use_bias != 0u {
        return vec3<f32>(max(softness.bias_rate * error, -params.max_push_velocity),
            softness.mass_scale, softness.impulse_scale);
    }
    return vec3<f32>(0.0, 1.0, 0.0);
}

fn solve_contact(index: u32) {
    let ids = load_ids(index);
    // The relax sweep is the sub-step's last: the next sub-step's warm start by body reads
    // what its impulses add up to.
    let store_sums = params.use_bias == 0u;
    let pair = solve_contact_pair(index, BodyPair(load_body(ids.x), load_body(ids.y)),
        store_sums);
    store_body(ids.x, pair[0]);
    store_body(ids.y, pair[1]);
}

// The bodies with one point's non-penetration row solved; `point` gets its new impulse. The
// separation is computed from the bodies' motion in every sweep, where the CPU computes it
// only after the positions moved and keeps it in the constraint (contact.rs, `Sweep::moved`):
// the same value to the bit (the same arithmetic on the same motion). Storing it cost more
// than the arithmetic: each point's store dirtied a word of its own in 9 of a step's 16
// sweeps, and without the stores the settled 100k pile's sweeps took 2.332 ms a step on an
// H100 against 2.362. So the device's rows keep the separation the rows' build gave them.
fn solve_normal(h: ConstraintHeader, point: ptr<function, PointRows>, pair: BodyPair)
    -> BodyPair {
    let moved = (pair[0].delta_position + quat_rotate(pair[0].delta_rotation,
        (*point).anchor_a)) - (pair[1].delta_position
        + quat_rotate(pair[1].delta_rotation, (*point).anchor_b));
    let separation = dot(h.normal, moved) + (*point).adjusted_separation;
    let terms = bias_terms(separation, h.softness);
    let arms = arms_of(*point, h.normal);
    let velocity = row_velocity(h.normal, arms, pair);
    let mass = (*point).masses.x;
    let old = (*point).impulses.x;
    let impulse = -mass * terms.y * (velocity + terms.x) - terms.z * old;
    let total = max(old + impulse, 0.0);
    let delta = total - old;
    (*point).impulses.x = total;
    (*point).impulses.w = max((*point).impulses.w, total);
    return apply(h, h.normal, arms, delta, pair);
}

// The bodies with one point's friction rows solved, clamped to the circle |λ_t| ≤ μ λ_n (see
// contact.rs); `point` gets its new tangent impulses.
fn solve_friction(h: ConstraintHeader, point: ptr<function, PointRows>, pair: BodyPair)
    -> BodyPair {
    let arms1 = arms_of(*point, h.tangent1);
    let arms2 = arms_of(*point, h.tangent2);
    let old1 = (*point).impulses.y;
    let old2 = (*point).impulses.z;
    let want1 = old1 - row_velocity(h.tangent1, arms1, pair) * (*point).masses.y;
    let want2 = old2 - row_velocity(h.tangent2, arms2, pair) * (*point).masses.z;
    let limit = h.friction * (*point).impulses.x;
    let length_squared = want1 * want1 + want2 * want2;
    var scale = 1.0;
    if length_squared > limit * limit {
        scale = limit / sqrt(length_squared);
    }
    let total1 = want1 * scale;
    let total2 = want2 * scale;
    var out = apply(h, h.tangent1, arms1, total1 - old1, pair);
    out = apply(h, h.tangent2, arms2, total2 - old2, out);
    (*point).impulses.y = total1;
    (*point).impulses.z = total2;
    return out;
}

// The rows' masses of `point` (normal, tangents), as the rows' build computed them.
fn point_masses(h: ConstraintHeader, point: PointRows) -> vec3<f32> {
    let masses = h.mass_a + h.mass_b;
    return vec3<f32>(row_mass(h.normal, point.anchor_a, point.anchor_b, h.inertias, masses),
        row_mass(h.tangent1, point.anchor_a, point.anchor_b, h.inertias, masses),
        row_mass(h.tangent2, point.anchor_a, point.anchor_b, h.inertias, masses));
}

// With `store_sums`, it also stores what the impulses add up to (lanes.wgsl's impulse sums).
fn solve_contact_pair(index: u32, start: BodyPair, store_sums: bool) -> BodyPair {
    let count = load_ids(index).w;
    let h = load_header(index, start);
    var p0 = load_point(index, 0u, count);
    var p1 = load_point(index, 1u, count);
    var p2 = load_point(index, 2u, count);
    var p3 = load_point(index, 3u, count);
    var pair = start;
    if count > 0u {
        p0.masses = point_masses(h, p0);
        pair = solve_normal(h, &p0, pair);
    }
    if count > 1u {
        p1.masses = point_masses(h, p1);
        pair = solve_normal(h, &p1, pair);
    }
    if count > 2u {
        p2.masses = point_masses(h, p2);
        pair = solve_normal(h, &p2, pair);
    }
    if count > 3u {
        p3.masses = point_masses(h, p3);
        pair = solve_normal(h, &p3, pair);
    }
    if count > 0u {
        pair = solve_friction(h, &p0, pair);
    }
    if count > 1u {
        pair = solve_friction(h, &p1, pair);
    }
    if count > 2u {
        pair = solve_friction(h, &p2, pair);
    }
    if count > 3u {
        pair = solve_friction(h, &p3, pair);
    }
    store_point(index, 0u, count, p0);
    store_point(index, 1u, count, p1);
    store_point(index, 2u, count, p2);
    store_point(index, 3u, count, p3);
    if store_sums {
        var sums = ImpulseSums();
        if count > 0u {
            sums = add_point(h, p0, sums);
        }
        if count > 1u {
            sums = add_point(h, p1, sums);
        }
        if count > 2u {
            sums = add_point(h, p2, sums);
        }
        if count > 3u {
            sums = add_point(h, p3, sums);
        }
        let words = sums_words(sums, h.mass_a, h.mass_b);
        contacts[lane_word(index, SUMS_WORD)] = words[0];
        contacts[lane_word(index, SUMS_WORD + 1u)] = words[1];
        contacts[lane_word(index, SUMS_WORD + 2u)] = words[2];
    }
    return pair;
}

// `sums` with a point's three rows, in the warm start's order.
fn add_point(h: ConstraintHeader, point: PointRows, sums: ImpulseSums) -> ImpulseSums {
    let normal = arms_of(point, h.normal);
    let tangent1 = arms_of(point, h.tangent1);
    let tangent2 = arms_of(point, h.tangent2);
    var out = add_row(sums, h.normal, normal[0], normal[1], h.inertias, point.impulses.x);
    out = add_row(out, h.tangent1, tangent1[0], tangent1[1], h.inertias, point.impulses.y);
    return add_row(out, h.tangent2, tangent2[0], tangent2[1], h.inertias, point.impulses.z);
}

fn restitution_contact(index: u32) {
    // The restitution, alone (most constraints have none).
    if contacts[lane_word(index, HEADER_TANGENT1)].w == 0.0 {
        return;
    }
    let ids = load_ids(index);
    let pair = restitution_contact_pair(index, BodyPair(load_body(ids.x), load_body(ids.y)));
    store_body(ids.x, pair[0]);
    store_body(ids.y, pair[1]);
}

fn restitution_contact_pair(index: u32, start: BodyPair) -> BodyPair {
    let restitution = contacts[lane_word(index, HEADER_TANGENT1)].w;
    if restitution == 0.0 {
        return start;
    }
    let h = load_header(index, start);
    var pair = start;
    let count = load_ids(index).w;
    for (var k = 0u; k < count; k++) {
        // The anchors only for a point that bounces (most do not).
        let masses = contacts[point_word(index, k, POINT_MASSES)];
        let approach = masses.w;
        let impulses = contacts[point_word(index, k, POINT_IMPULSES)];
        if approach > -params.restitution_threshold || impulses.w == 0.0 {
            continue;
        }
        let arms = Arms(cross(contacts[point_word(index, k, POINT_ANCHOR_A)].xyz, h.normal),
            cross(contacts[point_word(index, k, POINT_ANCHOR_B)].xyz, h.normal));
        let velocity = row_velocity(h.normal, arms, pair);
        let total = max(impulses.x - (velocity + restitution * approach) * masses.x, 0.0);
        let delta = total - impulses.x;
        store_impulses(index, k, total, impulses.y, impulses.z, max(impulses.w, total));
        pair = apply(h, h.normal, arms, delta, pair);
    }
    return pair;
}

const WALK: u32 = 1u;

// The end of a walk's batches, for all its threads (see `sweep`).
var<workgroup> walk_end: u32;

// What a sweep does to each of its constraints.
const WARM_START: u32 = 0u;
const SOLVE: u32 = 1u;
const RESTITUTION: u32 = 2u;

fn apply_sweep(kind: u32, index: u32) {
    switch kind {
        case WARM_START: {
            warm_start_contact(index);
        }
        case SOLVE: {
            solve_contact(index);
        }
        default: {
            restitution_contact(index);
        }
    }
}

// One sweep of this dispatch's batches' contacts (see the top of the file), by thread `local`
// of its workgroup, `thread` of the dispatch's `threads` (a walk's workgroup is the dispatch). For dispatches without joints, and
// for the restitution sweep (joints do not bounce). Every mode goes through the one loop
// below, so the constraint's function is inlined once: with a loop a mode it was inlined four
// times, which made the solve kernel four times as long (RADV's compiler, `kernel_stats`).
fn sweep(kind: u32, local: u32, thread: u32, threads: u32) {
    let walk = params.sequential == WALK;
    var end_batch = params.first_batch + 1u;
    if walk {
        // A device layout's walk ends at the last batch that holds a constraint (its offsets
        // say which): it covers every batch up to the overflow batch, most of them empty, and
        // a barrier each would cost.
        if local == 0u {
            var end = params.end_batch;
            if params.overflow_batch != NO_BATCH {
                end = min(end, offsets[LAYOUT_USED_END]);
            }
            walk_end = end;
        }
        end_batch = workgroupUniformLoad(&walk_end);
    }
    for (var batch = params.first_batch; batch < end_batch; batch++) {
        var index = offsets[batch];
        var end = offsets[batch + 1u];
        var step = 1u;
        if (walk && batch == params.overflow_batch) || (!walk && params.sequential != 0u) {
            // The overflow batch, whose constraints may share bodies: thread 0 alone, in
            // order (a walk is one workgroup, so its thread 0 is the dispatch's).
            if thread != 0u {
                end = index;
            }
        } else {
            // A constraint a thread. A walk's workgroup is the dispatch, its threads taking
            // every `threads`-th constraint of each batch; so do those of a parallel dispatch
            // sized for a device layout's expected size when the batch grew past it.
            // Constraints of one batch share no body, so it changes no result.
            index += thread;
            step = threads;
        }
        for (; index < end; index += step) {
            apply_sweep(kind, index);
        }
        if walk {
            storageBarrier();
        }
    }
}

// Constraints (contacts, then joints) of batch `batch`.
fn batch_size(batch: u32) -> u32 {
    return offsets[batch + 1u] - offsets[batch] + joint_offsets[batch + 1u]
        - joint_offsets[batch];
}

// Item `item` of batch `batch`: its contact `item`, or its joint `item` − (its contacts).
fn apply_mixed(kind: u32, batch: u32, item: u32) {
    let contact_count = offsets[batch + 1u] - offsets[batch];
    if item < contact_count {
        apply_sweep(kind, offsets[batch] + item);
    } else if kind == SOLVE {
        solve_joint(joint_offsets[batch] + item - contact_count);
    } else {
        warm_start_joint(joint_offsets[batch] + item - contact_count);
    }
}

// `sweep` for dispatches whose batches hold joints (warm start and solve): items are a
// batch's contacts, then its joints, the CPU's order within a batch. Each of the row
// functions is called from one place only: lavapipe's LLVM took minutes to compile the kernel
// with the joint rows inlined at three call sites. The contact-only kernels stay apart, since
// lavapipe runs both sides of a branch that differs between lanes: its contact-only scenes
// ran 18× slower with the joint rows in their kernels.
fn sweep_mixed(kind: u32, local: u32, thread: u32) {
    for (var batch = params.first_batch; batch < params.end_batch; batch++) {
        let size = batch_size(batch);
        var start = 0u;
        var stop = size;
        var step = 1u;
        if params.sequential == WALK {
            start = local;
            step = SOLVER_WORKGROUP;
        } else if params.sequential == 0u {
            start = thread;
            stop = min(thread + 1u, size);
        } else if thread != 0u {
            // The overflow batch: thread 0 alone, in order.
            stop = 0u;
        }
        for (var item = start; item < stop; item += step) {
            apply_mixed(kind, batch, item);
        }
        if params.sequential == WALK {
            storageBarrier();
        }
    }
}

@compute @workgroup_size(SOLVER_WORKGROUP)
fn warm_start(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    sweep(WARM_START, local, flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local,
        groups.x * groups.y * SOLVER_WORKGROUP);
}

@compute @workgroup_size(SOLVER_WORKGROUP)
fn solve(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    sweep(SOLVE, local, flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local,
        groups.x * groups.y * SOLVER_WORKGROUP);
}

@compute @workgroup_size(SOLVER_WORKGROUP)
fn restitution(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    sweep(RESTITUTION, local, flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local,
        groups.x * groups.y * SOLVER_WORKGROUP);
}

// The walks of contact-only batches: a dispatch of one workgroup of WALK_WORKGROUP threads (a
// walk's batches are small, so each is a round or two of its threads), where a parallel
// batch's dispatch is many workgroups of SOLVER_WORKGROUP (gpu.rs says why each).
@compute @workgroup_size(WALK_WORKGROUP)
fn warm_start_walk(@builtin(local_invocation_index) local: u32) {
    sweep(WARM_START, local, local, WALK_WORKGROUP);
}

@compute @workgroup_size(WALK_WORKGROUP)
fn solve_walk(@builtin(local_invocation_index) local: u32) {
    sweep(SOLVE, local, local, WALK_WORKGROUP);
}

@compute @workgroup_size(WALK_WORKGROUP)
fn restitution_walk(@builtin(local_invocation_index) local: u32) {
    sweep(RESTITUTION, local, local, WALK_WORKGROUP);
}

@compute @workgroup_size(SOLVER_WORKGROUP)
fn warm_start_mixed(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    sweep_mixed(WARM_START, local, flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local);
}

@compute @workgroup_size(SOLVER_WORKGROUP)
fn solve_mixed(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    sweep_mixed(SOLVE, local, flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local);
}

// Gravity into the velocities of the dynamic bodies.
@compute @workgroup_size(SOLVER_WORKGROUP)
fn integrate_velocities(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local;
    if index < params.body_count && bodies[index].inverse_mass > 0.0 {
        bodies[index].linear_velocity += params.gravity * params.h;
    }
}

// The velocities of the dynamic bodies into their delta positions and rotations.
@compute @workgroup_size(SOLVER_WORKGROUP)
fn integrate_positions(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let index = flat_workgroup(workgroup, groups) * SOLVER_WORKGROUP + local;
    if index >= params.body_count {
        return;
    }
    var body = bodies[index];
    if body.inverse_mass > 0.0 {
        body.angular_velocity = clamp_rotation(body.angular_velocity, params.h);
        body.delta_position += body.linear_velocity * params.h;
        body.delta_rotation = integrate_rotation(body.delta_rotation, body.angular_velocity,
            params.h);
        bodies[index] = body;
    }
}
