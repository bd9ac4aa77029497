// Contact constraints on the GPU in blocks of CONSTRAINT_LANES, word by word
// (stages/constraints/lanes.rs): a thread per constraint, a warp reads or writes each word in
// contiguous memory. The words of a constraint are those of ContactConstraint
// (contact_constraint.wgsl):
//   header word 0   body_a, body_b, pair, point_count (u32)
//               1   normal, friction
//               2   tangent1, restitution
//               3   tangent2, inverse_mass_a
//               4   inverse_mass_b, softness (bias_rate, mass_scale, impulse_scale)
//   point k, words HEADER_WORDS + k · POINT_WORDS + ...
//               0, 1   normal row: angular_a, mass; angular_b, impulse
//               2, 3   tangent[0] row, the same
//               4, 5   tangent[1] row
//               6      anchor_a, adjusted_separation
//               7      anchor_b, separation
//               8      approach_velocity, max_normal_impulse, padding

const HEADER_IDS: u32 = 0u;
const HEADER_NORMAL: u32 = 1u;
const HEADER_TANGENT1: u32 = 2u;
const HEADER_TANGENT2: u32 = 3u;
const HEADER_MASSES: u32 = 4u;
const POINT_NORMAL: u32 = 0u;
const POINT_TANGENT1: u32 = 2u;
const POINT_TANGENT2: u32 = 4u;
const POINT_ANCHOR_A: u32 = 6u;
const POINT_ANCHOR_B: u32 = 7u;
const POINT_EXTRA: u32 = 8u;

// Where word `word` of constraint `index` lies.
fn lane_word(index: u32, word: u32) -> u32 {
    return ((index / CONSTRAINT_LANES) * CONSTRAINT_WORDS + word) * CONSTRAINT_LANES
        + index % CONSTRAINT_LANES;
}

// Where word `word` of point `k` of constraint `index` lies.
fn point_word(index: u32, k: u32, word: u32) -> u32 {
    return lane_word(index, HEADER_WORDS + k * POINT_WORDS + word);
}
