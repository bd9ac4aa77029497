// The rows' contact constraints into batch order (stages/solver/batched.rs), both in blocks of
// lanes (lanes.wgsl), a 16-byte word a thread: word `slot` of batched place `place` is word
// `slot` of row order[place]. A thread takes the word at its own index of the output, so a
// warp's stores are 512 contiguous bytes (its loads are those of 32 rows in any order). Words
// that no kernel reads stay behind (`swept`, and the points past a constraint's count).

// Word 0: the number of contact constraints.
@group(0) @binding(0) var<storage, read> count: array<u32>;
// order[i]: the constraint (in the rows' order) that goes to batched place i.
@group(0) @binding(1) var<storage, read> order: array<u32>;
@group(0) @binding(2) var<storage, read> rows: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read_write> batched: array<vec4<u32>>;

// BOUNCING (from Rust: 1 or 0) tells whether the solve has a restitution sweep, whose words
// are gathered only then (`swept`): the kernel is built twice, gather_words and
// gather_words_still.
@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_words(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let word = flat_workgroup(workgroup, groups) * WORKGROUP_SIZE + local;
    // The inverse of lane_word: block, word of the constraint, lane.
    let block = word / (CONSTRAINT_WORDS * CONSTRAINT_LANES);
    let within = word - block * CONSTRAINT_WORDS * CONSTRAINT_LANES;
    let slot = within / CONSTRAINT_LANES;
    let place = block * CONSTRAINT_LANES + within % CONSTRAINT_LANES;
    if place >= count[0] || !swept(slot) {
        return;
    }
    let row = order[place];
    // A point's words past the constraint's count hold nothing (the build leaves them), and
    // no kernel reads them: about half the point words of a pile's constraints. The count
    // word is the one each of the constraint's threads loads, so it mostly comes from cache.
    if slot >= HEADER_WORDS && slot < SUMS_WORD {
        let points = rows[lane_word(row, HEADER_IDS)].w;
        if (slot - HEADER_WORDS) / POINT_WORDS >= points {
            return;
        }
    }
    batched[word] = rows[lane_word(row, slot)];
}

// Whether a kernel reads word `slot` of a batched constraint. Not the header's second tangent
// and masses words, whose fields the sweeps take from elsewhere (load_header in solver.wgsl:
// the tangents from the normal, the inverse masses from the bodies, the softness from the
// parameters); and unless the step has a restitution sweep (BOUNCING), not the words it
// alone reads: the header's first tangent word (the restitution) and each point's masses
// word (the normal mass and the approach speed). Nothing reads the batched constraints back
// to the host.
fn swept(slot: u32) -> bool {
    if slot == HEADER_TANGENT2 || slot == HEADER_MASSES {
        return false;
    }
    let point_masses = slot >= HEADER_WORDS && slot < SUMS_WORD
        && (slot - HEADER_WORDS) % POINT_WORDS == POINT_MASSES;
    return BOUNCING == 1u || !(slot == HEADER_TANGENT1 || point_masses);
}
