// One pass of a stable LSD radix sort: 8-bit digits, key-value pairs, keys of KEY_WORDS u32
// words (1: u32 keys; 2: u64 keys stored low word first). Injected: KEY_WORDS, ROUNDS.
//
// A tile is ROUNDS × WORKGROUP_SIZE consecutive elements, handled by one workgroup:
//
//   histogram: counts[digit × tile_count + tile] = elements of the tile with that digit
//   (scan):    counts → offsets, exclusive, digit-major: where each (digit, tile) run starts
//   scatter:   element → offsets[digit, tile] + its rank among equal digits of the tile
//
// The rank comes from per-digit bit masks of the round (bit t set when thread t has the
// digit): popcount of the bits below t. It depends only on positions, never on which thread
// ran first, so the sort is stable and deterministic without subgroups.

struct RadixParams {
    count: u32,
    // Bit offset of the digit inside the key word.
    shift: u32,
    // Which key word holds the digit.
    word: u32,
    tile_count: u32,
}

@group(0) @binding(0) var<uniform> params: RadixParams;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> values_out: array<u32>;
// Histogram: written by `histogram`. Offsets (its scan): read by `scatter`.
@group(0) @binding(5) var<storage, read_write> counts: array<u32>;

const RADIX: u32 = 256u;
const TILE: u32 = ROUNDS * WORKGROUP_SIZE;
// 32-bit mask words per digit: one bit per thread of a round.
const MASK_WORDS: u32 = WORKGROUP_SIZE / 32u;

var<workgroup> digit_counts: array<atomic<u32>, RADIX>;
var<workgroup> masks: array<atomic<u32>, RADIX * MASK_WORDS>;
var<workgroup> next_slot: array<u32, RADIX>;

fn digit_of(index: u32) -> u32 {
    return (keys_in[index * KEY_WORDS + params.word] >> params.shift) & (RADIX - 1u);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn histogram(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let tile = flat_workgroup(workgroup, groups);
    if tile >= params.tile_count {
        return;
    }
    // WORKGROUP_SIZE == RADIX (checked in Rust): thread `local` owns digit `local`.
    atomicStore(&digit_counts[local], 0u);
    workgroupBarrier();
    for (var round = 0u; round < ROUNDS; round++) {
        let index = tile * TILE + round * WORKGROUP_SIZE + local;
        if index < params.count {
            atomicAdd(&digit_counts[digit_of(index)], 1u);
        }
    }
    workgroupBarrier();
    counts[local * params.tile_count + tile] = atomicLoad(&digit_counts[local]);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let tile = flat_workgroup(workgroup, groups);
    if tile >= params.tile_count {
        return;
    }
    next_slot[local] = counts[local * params.tile_count + tile];
    let word = local / 32u;
    let below = (1u << (local % 32u)) - 1u;
    for (var round = 0u; round < ROUNDS; round++) {
        for (var mask = 0u; mask < MASK_WORDS; mask++) {
            atomicStore(&masks[local * MASK_WORDS + mask], 0u);
        }
        workgroupBarrier();
        let index = tile * TILE + round * WORKGROUP_SIZE + local;
        let valid = index < params.count;
        var digit = 0u;
        if valid {
            digit = digit_of(index);
            atomicOr(&masks[digit * MASK_WORDS + word], 1u << (local % 32u));
        }
        workgroupBarrier();
        if valid {
            var rank = countOneBits(atomicLoad(&masks[digit * MASK_WORDS + word]) & below);
            for (var mask = 0u; mask < word; mask++) {
                rank += countOneBits(atomicLoad(&masks[digit * MASK_WORDS + mask]));
            }
            let destination = next_slot[digit] + rank;
            for (var key_word = 0u; key_word < KEY_WORDS; key_word++) {
                keys_out[destination * KEY_WORDS + key_word] = keys_in[index * KEY_WORDS + key_word];
            }
            values_out[destination] = values_in[index];
        }
        workgroupBarrier();
        // Thread `local` advances digit `local` past this round's elements.
        var round_count = 0u;
        for (var mask = 0u; mask < MASK_WORDS; mask++) {
            round_count += countOneBits(atomicLoad(&masks[local * MASK_WORDS + mask]));
        }
        next_slot[local] += round_count;
        workgroupBarrier();
    }
}
