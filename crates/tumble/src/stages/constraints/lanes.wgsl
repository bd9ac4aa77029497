// Contact constraints on the GPU in blocks of CONSTRAINT_LANES, word by word
// (stages/constraints/lanes.rs): a thread per constraint, a warp reads or writes each word in
// contiguous memory. The fields are ContactConstraint's (stages/constraints/contact.rs), the
// header's in their order, a point's arranged so that what a sweep writes shares a word:
//   header word 0   body_a, body_b, pair, point_count (u32)
//               1   normal, friction
//               2   tangent1, restitution
//               3   tangent2, inverse_mass_a
//               4   inverse_mass_b, softness (bias_rate, mass_scale, impulse_scale)
//   point k, words HEADER_WORDS + k · POINT_WORDS + ...
//               0   normal.angular_a, normal.mass
//               1   normal.angular_b, tangent[0].mass
//               2   tangent[0].angular_a, tangent[1].mass
//               3   tangent[0].angular_b, approach_velocity
//               4   tangent[1].angular_a, 0
//               5   tangent[1].angular_b, 0
//               6   anchor_a, adjusted_separation
//               7   anchor_b, separation
//               8   the impulses: normal, tangent[0], tangent[1], max_normal_impulse
// So row r (0: normal, 1, 2: the tangents) is angular_a in word 2r, angular_b in word 2r + 1,
// its mass in word r's w and its impulse in lane r of word 8. Past the points, the impulse
// sums (impulse_sums in lanes.rs), which the warm start by body reads instead of the rows:
//   SUMS_WORD       Σ d λ over the points' rows, 0
//               1   Σ I⁻¹(r_a × d) λ, inverse_mass_a
//               2   Σ I⁻¹(r_b × d) λ, inverse_mass_b

const HEADER_IDS: u32 = 0u;
const HEADER_NORMAL: u32 = 1u;
const HEADER_TANGENT1: u32 = 2u;
const HEADER_TANGENT2: u32 = 3u;
const HEADER_MASSES: u32 = 4u;
const POINT_APPROACH: u32 = 3u;
const POINT_ANCHOR_A: u32 = 6u;
const POINT_ANCHOR_B: u32 = 7u;
const POINT_IMPULSES: u32 = 8u;

// A constraint's impulse sums, accumulated row by row (`add_row`) in the sweeps' order: Σ d λ,
// Σ I⁻¹(r_a × d) λ, Σ I⁻¹(r_b × d) λ (an array, not a struct: kept in registers as BodyPair is,
// and no struct without a Rust twin).
alias ImpulseSums = array<vec3<f32>, 3>;

// `sums` with a row along `direction` of arms `angular_a`, `angular_b` and impulse `impulse`.
fn add_row(sums: ImpulseSums, direction: vec3<f32>, angular_a: vec3<f32>,
           angular_b: vec3<f32>, impulse: f32) -> ImpulseSums {
    return ImpulseSums(sums[0] + direction * impulse, sums[1] + angular_a * impulse,
        sums[2] + angular_b * impulse);
}

// Where word `word` of constraint `index` lies.
fn lane_word(index: u32, word: u32) -> u32 {
    return ((index / CONSTRAINT_LANES) * CONSTRAINT_WORDS + word) * CONSTRAINT_LANES
        + index % CONSTRAINT_LANES;
}

// Where word `word` of point `k` of constraint `index` lies.
fn point_word(index: u32, k: u32, word: u32) -> u32 {
    return lane_word(index, HEADER_WORDS + k * POINT_WORDS + word);
}
