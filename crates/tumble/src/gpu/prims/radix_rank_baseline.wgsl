// The baseline ranking: any adapter. Round r of a tile is WORKGROUP_SIZE consecutive elements,
// one a thread; within a round, per-digit bit masks in workgroup memory (thread t sets bit t of
// its digit's mask) give each element the popcount of the bits below its own, plus its digit's
// count in earlier rounds. Three barriers a round.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
}

// 32-bit mask words per digit: one bit per thread of a round.
const MASK_WORDS: u32 = WORKGROUP_SIZE / 32u;

fn element_index(ids: ThreadIds, start: u32, round: u32) -> u32 {
    return start + round * WORKGROUP_SIZE + ids.local;
}

fn begin_ranking(ids: ThreadIds) {
    digit_count[ids.local] = 0u;
}

// The rank of `element` (digit `digit`) among the tile's elements so far with that digit;
// adds the round's counts to `digit_count`. Call from uniform control flow, round by round.
fn rank_element(ids: ThreadIds, element: u32, digit: u32) -> u32 {
    let local = ids.local;
    let own_mask = local / 32u;
    let own_bit = 1u << (local % 32u);
    // Thread t clears (and below, counts) the masks of digit t.
    for (var mask = 0u; mask < MASK_WORDS; mask++) {
        atomicStore(&exchange[local * MASK_WORDS + mask], 0u);
    }
    workgroupBarrier();
    if element < params.count {
        atomicOr(&exchange[digit * MASK_WORDS + own_mask], own_bit);
    }
    workgroupBarrier();
    // (Meaningless past the end of the input; never used there.)
    var rank = digit_count[digit] + countOneBits(atomicLoad(&exchange[digit * MASK_WORDS + own_mask]) & (own_bit - 1u));
    for (var mask = 0u; mask < own_mask; mask++) {
        rank += countOneBits(atomicLoad(&exchange[digit * MASK_WORDS + mask]));
    }
    workgroupBarrier();
    var round_count = 0u;
    for (var mask = 0u; mask < MASK_WORDS; mask++) {
        round_count += countOneBits(atomicLoad(&exchange[local * MASK_WORDS + mask]));
    }
    digit_count[local] += round_count;
    return rank;
}

// After the last round: `digit_count` holds the tile's counts and `exchange` is free.
fn finish_ranking(ids: ThreadIds) {
    workgroupBarrier();
}

// The ranks above are already tile-wide.
fn rank_offset(ids: ThreadIds, digit: u32) -> u32 {
    return 0u;
}
