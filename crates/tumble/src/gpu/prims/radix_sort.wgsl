// Stable LSD radix sort of key-value pairs, 8-bit digits, one dispatch per digit in the manner
// of Onesweep (Adinets & Merrill, 2022): the digit counts of the whole input are taken once, up
// front, and each pass finds where its tile's runs go by a decoupled look-back over the tiles
// before it. Keys are KEY_WORDS u32 words (1: u32 keys; 2: u64 keys, low word first).
// Injected: KEY_WORDS, ROUNDS, HISTOGRAM_ITEMS, POLLS (and SUBGROUPS on the subgroup path).
// `gpu::prims::radix_sort` zeroes `counts` and `status` before each sort.
//
//   histogram:  counts[pass][digit] = elements of the input with that digit, all passes
//   scatter:    one pass; per tile of TILE = ROUNDS × WORKGROUP_SIZE elements (the workgroup
//               id's tile: see `scan.wgsl` on why no ticket is taken):
//     1. rank: each element's position among the tile's equal digits;
//     2. publish the tile's digit counts (AGGREGATE), look back for the counts of all earlier
//        tiles (counting a tile's digits itself when that tile is slow to publish: see
//        `look_back`), publish those plus its own (PREFIX);
//     3. place the elements in the tile's workgroup memory sorted by digit, then write them out
//        in that order: each digit's elements go out as one contiguous run.
//
// The rank of an element is its position among the tile's elements with the same digit, so
// it depends only on positions, never on which thread ran first: the sort is stable and
// deterministic. Two ways to find it, each in its own file (`radix_rank_*.wgsl`): per-digit
// bit masks in workgroup memory (any adapter), or subgroup ballots and a count per subgroup and
// digit (Onesweep's warp-level multisplit). Each file says which thread holds which element.
//
// Windows: arrays larger than one storage binding are bound a window at a time
// (`gpu::buffer::windows`). The histogram runs once per input window. A pass runs once per
// (input window, output window), in order: tiles are numbered over the whole input, so a
// window's look-back walks into earlier windows, whose tiles have all published their PREFIX
// (it never falls back to input outside its window); each run writes the elements whose place
// lies in its output window. The first run of an input window publishes its tiles' statuses;
// the later ones (`replay`) read their tile's own PREFIX instead of looking back.

struct RadixParams {
    // Elements of this input window.
    count: u32,
    // The digit this scatter sorts by: digit p is bits 8(p mod 4).. of key word p / 4.
    pass_index: u32,
    // Digits the histogram counts (passes of the whole sort).
    passes: u32,
    // Tiles of this input window; workgroups past it (a 2D grid rounds up) do nothing.
    tile_count: u32,
    // The window's first tile, numbered over the whole input.
    first_tile: u32,
    // The output window: the first place it holds, and how many.
    destination_first: u32,
    destination_count: u32,
    // 1: an earlier run of this pass and input window published the tiles' statuses.
    replay: u32,
}

@group(0) @binding(0) var<uniform> params: RadixParams;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> values_out: array<u32>;
// [pass × RADIX + digit]: digit counts of the input.
@group(0) @binding(5) var<storage, read_write> counts: array<atomic<u32>>;
// This pass's [tile × RADIX + digit]: a tile's count of a digit, with a flag in the top two
// bits (counts stay below 2^30, checked in Rust).
@group(0) @binding(6) var<storage, read_write> status: array<atomic<u32>>;

const RADIX: u32 = 256u;
const MAX_PASSES: u32 = 4u * KEY_WORDS;
const TILE: u32 = ROUNDS * WORKGROUP_SIZE;
const FLAG_AGGREGATE: u32 = 1u << 30u;
const FLAG_PREFIX: u32 = 2u << 30u;
const COUNT_MASK: u32 = FLAG_AGGREGATE - 1u;

// In turn: the baseline ranking's bit masks (RADIX × WORKGROUP_SIZE bits ≤ TILE words, checked
// in Rust), the scan of the digit counts, the tile in sorted order.
var<workgroup> exchange: array<atomic<u32>, TILE>;
// Per digit: elements of the tile seen so far (after ranking: the tile's count).
var<workgroup> digit_count: array<u32, RADIX>;
// Per digit: where its run starts in the sorted tile.
var<workgroup> digit_start: array<u32, RADIX>;
// Per digit: output index minus slot in the sorted tile.
var<workgroup> digit_offset: array<u32, RADIX>;
// The look-back's latest stuck tile + 1 (0: none), and its copy for a uniform read.
var<workgroup> stuck_tile: atomic<u32>;
var<workgroup> stuck_tile_read: u32;
// Per pass: the input's digit counts (histogram only).
var<workgroup> pass_counts: array<atomic<u32>, MAX_PASSES * RADIX>;

fn digit_of(key_word: u32, pass_index: u32) -> u32 {
    return (key_word >> (8u * (pass_index % 4u))) & (RADIX - 1u);
}

// Adds word `word` of a key to the digit counts of the passes that read that word.
fn count_word(word: u32, key_word: u32, valid: bool) {
    if !valid {
        return;
    }
    for (var pass_index = 4u * word; pass_index < min(params.passes, 4u * word + 4u); pass_index++) {
        atomicAdd(&pass_counts[pass_index * RADIX + digit_of(key_word, pass_index)], 1u);
    }
}

// Word `word` of the key of element `index` (clamped to the input: callers skip the rest).
fn key_word_at(index: u32, word: u32) -> u32 {
    return keys_in[min(index, params.count - 1u) * KEY_WORDS + word];
}

// The digit counts of HISTOGRAM_ITEMS × WORKGROUP_SIZE elements, every pass at once. The items'
// loads are written out rather than looped: drivers do not unroll naga's loops, and a loop
// whose load feeds an atomic keeps one load in flight per thread.
const_assert HISTOGRAM_ITEMS == 16u;
@compute @workgroup_size(WORKGROUP_SIZE)
fn histogram(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) workgroup: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let start = flat_workgroup(workgroup, groups) * HISTOGRAM_ITEMS * WORKGROUP_SIZE;
    if start >= params.count {
        return;
    }
    for (var pass_index = 0u; pass_index < params.passes; pass_index++) {
        atomicStore(&pass_counts[pass_index * RADIX + local], 0u);
    }
    workgroupBarrier();
    for (var word = 0u; word < (params.passes + 3u) / 4u; word++) {
        let key0 = key_word_at(start + 0u * WORKGROUP_SIZE + local, word);
        let key1 = key_word_at(start + 1u * WORKGROUP_SIZE + local, word);
        let key2 = key_word_at(start + 2u * WORKGROUP_SIZE + local, word);
        let key3 = key_word_at(start + 3u * WORKGROUP_SIZE + local, word);
        let key4 = key_word_at(start + 4u * WORKGROUP_SIZE + local, word);
        let key5 = key_word_at(start + 5u * WORKGROUP_SIZE + local, word);
        let key6 = key_word_at(start + 6u * WORKGROUP_SIZE + local, word);
        let key7 = key_word_at(start + 7u * WORKGROUP_SIZE + local, word);
        let key8 = key_word_at(start + 8u * WORKGROUP_SIZE + local, word);
        let key9 = key_word_at(start + 9u * WORKGROUP_SIZE + local, word);
        let key10 = key_word_at(start + 10u * WORKGROUP_SIZE + local, word);
        let key11 = key_word_at(start + 11u * WORKGROUP_SIZE + local, word);
        let key12 = key_word_at(start + 12u * WORKGROUP_SIZE + local, word);
        let key13 = key_word_at(start + 13u * WORKGROUP_SIZE + local, word);
        let key14 = key_word_at(start + 14u * WORKGROUP_SIZE + local, word);
        let key15 = key_word_at(start + 15u * WORKGROUP_SIZE + local, word);
        count_word(word, key0, start + 0u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key1, start + 1u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key2, start + 2u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key3, start + 3u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key4, start + 4u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key5, start + 5u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key6, start + 6u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key7, start + 7u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key8, start + 8u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key9, start + 9u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key10, start + 10u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key11, start + 11u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key12, start + 12u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key13, start + 13u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key14, start + 14u * WORKGROUP_SIZE + local < params.count);
        count_word(word, key15, start + 15u * WORKGROUP_SIZE + local < params.count);
    }
    workgroupBarrier();
    for (var pass_index = 0u; pass_index < params.passes; pass_index++) {
        let count = atomicLoad(&pass_counts[pass_index * RADIX + local]);
        if count != 0u {
            atomicAdd(&counts[pass_index * RADIX + local], count);
        }
    }
}

fn status_index(tile: u32, digit: u32) -> u32 {
    return tile * RADIX + digit;
}

// Status of (tile, digit), polled up to POLLS times; 0 if it has not been published.
// Status words are written with atomicExchange and read with atomicOr(0): naga's GLSL output
// turns atomicStore and atomicLoad into plain accesses, which llvmpipe's compiler may hoist out
// of a poll loop or delay, so other tiles would never see a status (and always fall back).
fn poll_status(tile: u32, digit: u32) -> u32 {
    var seen = atomicOr(&status[status_index(tile, digit)], 0u);
    for (var poll = 1u; poll < POLLS && seen == 0u; poll++) {
        seen = atomicOr(&status[status_index(tile, digit)], 0u);
    }
    return seen;
}

// The count of digit `local` in tile `tile` (one of this window's), from the input (the
// look-back's fallback); call from uniform control flow with `exchange` free.
fn count_tile_digits(tile: u32, local: u32) -> u32 {
    atomicStore(&exchange[local], 0u);
    workgroupBarrier();
    for (var round = 0u; round < ROUNDS; round++) {
        let index = (tile - params.first_tile) * TILE + round * WORKGROUP_SIZE + local;
        if index < params.count {
            let key_word = keys_in[index * KEY_WORDS + params.pass_index / 4u];
            atomicAdd(&exchange[digit_of(key_word, params.pass_index)], 1u);
        }
    }
    workgroupBarrier();
    let count = atomicLoad(&exchange[local]);
    workgroupBarrier();
    return count;
}

// Thread d: the count of digit d in all tiles before `tile` (uniform). Each digit walks back
// alone, adding AGGREGATEs until a PREFIX. A tile that has not published after POLLS polls is
// not waited for: the workgroup counts its digits from the input itself (the decoupled
// fallback of Smith, Levien & Owens, 2025), latest stuck tile first. So no workgroup waits on
// another unboundedly, which Mesa's CPU drivers need: their thread pool may be descheduled
// for milliseconds, and llvmpipe ends a shader's loops after 65535 iterations in all.
// Call from uniform control flow with `exchange` free.
fn look_back(tile: u32, local: u32) -> u32 {
    var earlier = 0u;
    // Tiles before `previous` are still to be added.
    var previous = tile;
    var done = tile == 0u;
    loop {
        if !done {
            loop {
                let seen = poll_status(previous - 1u, local);
                if seen == 0u {
                    break;
                }
                earlier += seen & COUNT_MASK;
                previous -= 1u;
                if (seen & FLAG_PREFIX) != 0u {
                    done = true;
                    break;
                }
            }
            if !done {
                atomicMax(&stuck_tile, previous);
            }
        }
        workgroupBarrier();
        if local == 0u {
            stuck_tile_read = atomicExchange(&stuck_tile, 0u);
        }
        let stuck = workgroupUniformLoad(&stuck_tile_read);
        if stuck == 0u {
            break;
        }
        let count = count_tile_digits(stuck - 1u, local);
        if !done && previous == stuck {
            earlier += count;
            previous -= 1u;
            // Tile 0's counts are its PREFIX.
            done = previous == 0u;
        }
    }
    return earlier;
}

// The digit this pass sorts element `element` by (meaningless past the end of the input,
// where it is never used).
fn load_digit(element: u32) -> u32 {
    return digit_of(key_word_at(element, params.pass_index / 4u), params.pass_index);
}

// Word `word` of element `element`: a key word, or the value after the last key word.
fn load_word(element: u32, word: u32) -> u32 {
    let index = min(element, params.count - 1u);
    if word < KEY_WORDS {
        return keys_in[index * KEY_WORDS + word];
    }
    return values_in[index];
}

// Puts `word` in slot `slot` of the sorted tile, for elements in the input.
fn place(element: u32, slot: u32, word: u32) {
    if element < params.count {
        atomicStore(&exchange[slot], word);
    }
}

// Writes slot `round` × WORKGROUP_SIZE + local of the sorted tile (word `word` of its element)
// to its place in the output, `destination`, if the output window holds that place.
fn write_out(round: u32, local: u32, filled: u32, destination: u32, word: u32) {
    let slot = round * WORKGROUP_SIZE + local;
    // Wrapping: places before the window come out above its count.
    let place = destination - params.destination_first;
    if slot < filled && place < params.destination_count {
        let moved = atomicLoad(&exchange[slot]);
        if word < KEY_WORDS {
            keys_out[place * KEY_WORDS + word] = moved;
        } else {
            values_out[place] = moved;
        }
    }
}

// The ROUNDS rounds are written out rather than looped, for the same reason as the
// histogram's items: each round's loads are issued together.
const_assert ROUNDS == 8u;
@compute @workgroup_size(WORKGROUP_SIZE)
fn scatter(ids: ThreadIds, @builtin(workgroup_id) workgroup: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let local = ids.local;
    let window_tile = flat_workgroup(workgroup, groups);
    if window_tile >= params.tile_count {
        return;
    }
    if local == 0u {
        atomicStore(&stuck_tile, 0u);
    }
    let tile = params.first_tile + window_tile;
    let start = window_tile * TILE;

    // 1. Rank: each thread's ROUNDS elements, in the order the path lays them out.
    let element0 = element_index(ids, start, 0u);
    let element1 = element_index(ids, start, 1u);
    let element2 = element_index(ids, start, 2u);
    let element3 = element_index(ids, start, 3u);
    let element4 = element_index(ids, start, 4u);
    let element5 = element_index(ids, start, 5u);
    let element6 = element_index(ids, start, 6u);
    let element7 = element_index(ids, start, 7u);
    let digit0 = load_digit(element0);
    let digit1 = load_digit(element1);
    let digit2 = load_digit(element2);
    let digit3 = load_digit(element3);
    let digit4 = load_digit(element4);
    let digit5 = load_digit(element5);
    let digit6 = load_digit(element6);
    let digit7 = load_digit(element7);
    begin_ranking(ids);
    let rank0 = rank_element(ids, element0, digit0);
    let rank1 = rank_element(ids, element1, digit1);
    let rank2 = rank_element(ids, element2, digit2);
    let rank3 = rank_element(ids, element3, digit3);
    let rank4 = rank_element(ids, element4, digit4);
    let rank5 = rank_element(ids, element5, digit5);
    let rank6 = rank_element(ids, element6, digit6);
    let rank7 = rank_element(ids, element7, digit7);
    finish_ranking(ids);
    // 2. Thread d handles digit d: publish the tile's count...
    let tile_digits = digit_count[local];
    let own_status = status_index(tile, local);
    if params.replay == 0u {
        atomicExchange(&status[own_status], select(FLAG_AGGREGATE, FLAG_PREFIX, tile == 0u) | tile_digits);
    }
    // ...scan (tile count, input count) over the digits, exclusive: where the digit's run
    // starts in the sorted tile and in the output (Hillis–Steele, ping-ponging between
    // exchange[0..2W] and exchange[2W..4W], a pair of words per digit)...
    let own = vec2<u32>(tile_digits, atomicLoad(&counts[params.pass_index * RADIX + local]));
    atomicStore(&exchange[2u * local], own.x);
    atomicStore(&exchange[2u * local + 1u], own.y);
    workgroupBarrier();
    var read_half = 0u;
    for (var offset = 1u; offset < RADIX; offset <<= 1u) {
        var sum = vec2<u32>(atomicLoad(&exchange[read_half + 2u * local]), atomicLoad(&exchange[read_half + 2u * local + 1u]));
        if local >= offset {
            let other = read_half + 2u * (local - offset);
            sum += vec2<u32>(atomicLoad(&exchange[other]), atomicLoad(&exchange[other + 1u]));
        }
        read_half = 2u * RADIX - read_half;
        atomicStore(&exchange[read_half + 2u * local], sum.x);
        atomicStore(&exchange[read_half + 2u * local + 1u], sum.y);
        workgroupBarrier();
    }
    let before = vec2<u32>(atomicLoad(&exchange[read_half + 2u * local]), atomicLoad(&exchange[read_half + 2u * local + 1u])) - own;
    // ...and look back: the digit's count in all earlier tiles of this pass (a replay has
    // it in its own PREFIX).
    var earlier = 0u;
    if params.replay == 0u {
        earlier = look_back(tile, local);
        if tile > 0u {
            atomicExchange(&status[own_status], FLAG_PREFIX | (earlier + tile_digits));
        }
    } else {
        earlier = (atomicOr(&status[own_status], 0u) & COUNT_MASK) - tile_digits;
    }
    digit_start[local] = before.x;
    digit_offset[local] = before.y + earlier - before.x;
    workgroupBarrier();

    // 3. Through workgroup memory in sorted order: first each slot's output index, then each
    // key word and the value. Slots below `filled` hold the tile's elements.
    let filled = min(TILE, params.count - start);
    let slot0 = digit_start[digit0] + rank_offset(ids, digit0) + rank0;
    let slot1 = digit_start[digit1] + rank_offset(ids, digit1) + rank1;
    let slot2 = digit_start[digit2] + rank_offset(ids, digit2) + rank2;
    let slot3 = digit_start[digit3] + rank_offset(ids, digit3) + rank3;
    let slot4 = digit_start[digit4] + rank_offset(ids, digit4) + rank4;
    let slot5 = digit_start[digit5] + rank_offset(ids, digit5) + rank5;
    let slot6 = digit_start[digit6] + rank_offset(ids, digit6) + rank6;
    let slot7 = digit_start[digit7] + rank_offset(ids, digit7) + rank7;
    place(element0, slot0, digit_offset[digit0] + slot0);
    place(element1, slot1, digit_offset[digit1] + slot1);
    place(element2, slot2, digit_offset[digit2] + slot2);
    place(element3, slot3, digit_offset[digit3] + slot3);
    place(element4, slot4, digit_offset[digit4] + slot4);
    place(element5, slot5, digit_offset[digit5] + slot5);
    place(element6, slot6, digit_offset[digit6] + slot6);
    place(element7, slot7, digit_offset[digit7] + slot7);
    workgroupBarrier();
    let destination0 = atomicLoad(&exchange[0u * WORKGROUP_SIZE + local]);
    let destination1 = atomicLoad(&exchange[1u * WORKGROUP_SIZE + local]);
    let destination2 = atomicLoad(&exchange[2u * WORKGROUP_SIZE + local]);
    let destination3 = atomicLoad(&exchange[3u * WORKGROUP_SIZE + local]);
    let destination4 = atomicLoad(&exchange[4u * WORKGROUP_SIZE + local]);
    let destination5 = atomicLoad(&exchange[5u * WORKGROUP_SIZE + local]);
    let destination6 = atomicLoad(&exchange[6u * WORKGROUP_SIZE + local]);
    let destination7 = atomicLoad(&exchange[7u * WORKGROUP_SIZE + local]);
    for (var word = 0u; word <= KEY_WORDS; word++) {
        let word0 = load_word(element0, word);
        let word1 = load_word(element1, word);
        let word2 = load_word(element2, word);
        let word3 = load_word(element3, word);
        let word4 = load_word(element4, word);
        let word5 = load_word(element5, word);
        let word6 = load_word(element6, word);
        let word7 = load_word(element7, word);
        workgroupBarrier();
        place(element0, slot0, word0);
        place(element1, slot1, word1);
        place(element2, slot2, word2);
        place(element3, slot3, word3);
        place(element4, slot4, word4);
        place(element5, slot5, word5);
        place(element6, slot6, word6);
        place(element7, slot7, word7);
        workgroupBarrier();
        write_out(0u, local, filled, destination0, word);
        write_out(1u, local, filled, destination1, word);
        write_out(2u, local, filled, destination2, word);
        write_out(3u, local, filled, destination3, word);
        write_out(4u, local, filled, destination4, word);
        write_out(5u, local, filled, destination5, word);
        write_out(6u, local, filled, destination6, word);
        write_out(7u, local, filled, destination7, word);
    }
}
