// The subgroup ranking (Onesweep's warp-level multisplit): subgroup k of width w holds the
// tile's elements k × ROUNDS × w .. (k + 1) × ROUNDS × w, round r being the w consecutive
// elements from (k × ROUNDS + r) × w, one a lane (thread t is lane l of subgroup k with
// t = k × w + l, as in `scan_subgroups.wgsl`). Eight ballots, one per digit bit, find the lanes
// holding the same digit; the lowest of them adds their number to the subgroup's count of that
// digit. No barrier until the last round; then each digit's counts are scanned over the
// subgroups, which are in element order, so the rank stays each element's position.

struct ThreadIds {
    @builtin(local_invocation_index) local: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) width: u32,
    @builtin(subgroup_id) subgroup: u32,
}

// Subgroup k's count of digit d so far in the low (d even) or high (d odd) 16 bits of word
// k × RADIX / 2 + d / 2 (at most ROUNDS × 128 elements); after the last round, the digit's
// count in the subgroups before k instead (at most TILE). Halves keep a width of 8 within 16 KiB
// of workgroup memory (lavapipe allows 32 KiB in all). SUBGROUPS (injected) = WORKGROUP_SIZE /
// the adapter's smallest subgroup width.
var<workgroup> subgroup_counts: array<atomic<u32>, SUBGROUPS * RADIX / 2u>;

fn counts_index(subgroup: u32, digit: u32) -> u32 {
    return subgroup * (RADIX / 2u) + digit / 2u;
}

fn count_shift(digit: u32) -> u32 {
    return 16u * (digit % 2u);
}

fn element_index(ids: ThreadIds, start: u32, round: u32) -> u32 {
    return start + (ids.subgroup * ROUNDS + round) * ids.width + ids.lane;
}

fn begin_ranking(ids: ThreadIds) {
    for (var word = ids.local; word < WORKGROUP_SIZE / ids.width * (RADIX / 2u); word += WORKGROUP_SIZE) {
        atomicStore(&subgroup_counts[word], 0u);
    }
    workgroupBarrier();
}

// Bits of the lanes below `lane` in a ballot.
fn lanes_below(lane: u32) -> vec4<u32> {
    let word = vec4<u32>(0u, 1u, 2u, 3u);
    let partial = (1u << (lane % 32u)) - 1u;
    let own_word = vec4<u32>(lane / 32u);
    return select(select(vec4<u32>(0u), vec4<u32>(0xffffffffu), word < own_word), vec4<u32>(partial), word == own_word);
}

fn count_lanes(ballot: vec4<u32>) -> u32 {
    return dot(countOneBits(ballot), vec4<u32>(1u));
}

// The lowest lane whose bit is set in a non-empty ballot.
fn lowest_lane(ballot: vec4<u32>) -> u32 {
    let first = firstTrailingBit(ballot);
    return select(select(select(96u + first.w, 64u + first.z, ballot.z != 0u), 32u + first.y, ballot.y != 0u), first.x, ballot.x != 0u);
}

// Whether bit `bit` of `digit` is set, and the lanes that agree with it.
fn agree(digit: u32, bit: u32) -> vec4<u32> {
    let is_set = ((digit >> bit) & 1u) != 0u;
    let voted = subgroupBallot(is_set);
    return select(~voted, voted, is_set);
}

// The rank of `element` (digit `digit`) among the subgroup's elements so far with that digit.
// Call from uniform control flow, round by round.
fn rank_element(ids: ThreadIds, element: u32, digit: u32) -> u32 {
    let valid = element < params.count;
    // The lanes in the input holding this lane's digit (this lane included when it is valid).
    let peers = subgroupBallot(valid) & agree(digit, 0u) & agree(digit, 1u) & agree(digit, 2u) & agree(digit, 3u) & agree(digit, 4u) & agree(digit, 5u) & agree(digit, 6u) & agree(digit, 7u);
    let before = count_lanes(peers & lanes_below(ids.lane));
    var base = 0u;
    if valid && before == 0u {
        let shift = count_shift(digit);
        base = atomicAdd(&subgroup_counts[counts_index(ids.subgroup, digit)], count_lanes(peers) << shift) >> shift;
    }
    // A lane past the input may have no peers: it reads its own (unused) base.
    let leader = select(ids.lane, lowest_lane(peers), any(peers != vec4<u32>(0u)));
    return (subgroupShuffle(base, leader) & 0xffffu) + before;
}

// After the last round: thread d turns digit d's counts per subgroup into the counts in the
// subgroups before each, and puts the tile's count in `digit_count`. Threads d and d + 1 share
// words: each adds the difference to its own half, which leaves the other half as it is.
fn finish_ranking(ids: ThreadIds) {
    workgroupBarrier();
    let shift = count_shift(ids.local);
    var total = 0u;
    for (var subgroup = 0u; subgroup < WORKGROUP_SIZE / ids.width; subgroup++) {
        let word = counts_index(subgroup, ids.local);
        let count = (atomicLoad(&subgroup_counts[word]) >> shift) & 0xffffu;
        atomicAdd(&subgroup_counts[word], (total << shift) - (count << shift));
        total += count;
    }
    digit_count[ids.local] = total;
    workgroupBarrier();
}

// The count of `digit` in the subgroups before this thread's.
fn rank_offset(ids: ThreadIds, digit: u32) -> u32 {
    return (atomicLoad(&subgroup_counts[counts_index(ids.subgroup, digit)]) >> count_shift(digit)) & 0xffffu;
}
