// Contact constraints on the GPU in blocks of CONSTRAINT_LANES, word by word
// (stages/constraints/lanes.rs): a thread per constraint, a warp reads or writes each word in
// contiguous memory. The fields are ContactConstraint's (stages/constraints/contact.rs), the
// header's in their order, a point's arranged so that what a sweep writes shares a word:
//   header word 0   body_a, body_b, pair, point_count (u32)
//               1   normal, friction
//               2   tangent1, restitution
//               3   tangent2, inverse_mass_a
//               4   inverse_mass_b, softness (bias_rate, mass_scale, impulse_scale)
//               5   inverse_inertia_a: diagonal, off_diagonal.x
//               6   inverse_inertia_a: off_diagonal.yz, inverse_inertia_b: diagonal.xy
//               7   inverse_inertia_b: diagonal.z, off_diagonal
//   point k, words HEADER_WORDS + k · POINT_WORDS + ...
//               0   anchor_a, adjusted_separation
//               1   anchor_b, separation
//               2   the rows' masses: normal, tangent[0], tangent[1]; approach_velocity
//               3   the impulses: normal, tangent[0], tangent[1], max_normal_impulse
// So row r (0: normal, 1, 2: the tangents) has its mass in lane r of word 2 and its impulse
// in lane r of word 3. A solve or warm-start sweep loads header words 0, 1 and 5 to 7 and point
// words 0, 1 and 3 alone: it takes the tangents from the normal, the inverse masses from the
// bodies and the softness from its parameters, and a solve computes the rows' masses
// (solver.wgsl's load_header says why); the
// restitution sweep reads word 2's restitution and point word 2. Past the points, the impulse
// sums (impulse_sums in lanes.rs), which the warm start by body reads instead of the rows:
//   SUMS_WORD       Σ d λ over the points' rows, 0
//               1   Σ I_a⁻¹(r_a × d) λ, inverse_mass_a
//               2   Σ I_b⁻¹(r_b × d) λ, inverse_mass_b

const HEADER_IDS: u32 = 0u;
const HEADER_NORMAL: u32 = 1u;
const HEADER_TANGENT1: u32 = 2u;
const HEADER_TANGENT2: u32 = 3u;
const HEADER_MASSES: u32 = 4u;
const HEADER_INERTIA: u32 = 5u;
const POINT_ANCHOR_A: u32 = 0u;
const POINT_ANCHOR_B: u32 = 1u;
const POINT_MASSES: u32 = 2u;
const POINT_IMPULSES: u32 = 3u;

// math.rs's SymmetricMat3: [0] the diagonal (xx, yy, zz), [1] the rest (xy, xz, yz). It lives
// in registers; in memory its 24 bytes are packed into the header's words (`inertias_of`).
// An array, not a struct: no struct without a Rust twin of the same layout (as ImpulseSums).
alias SymmetricMat3 = array<vec3<f32>, 2>;

// SymmetricMat3::mul_vec3, in its order.
fn symmetric_mul(m: SymmetricMat3, v: vec3<f32>) -> vec3<f32> {
    let d = m[0];
    let o = m[1];
    return vec3<f32>(d.x * v.x + o.x * v.y + o.y * v.z, o.x * v.x + d.y * v.y + o.z * v.z,
        o.y * v.x + o.z * v.y + d.z * v.z);
}

// A constraint's impulse sums, accumulated row by row (`add_row`) in the sweeps' order: Σ d λ,
// Σ I_a⁻¹(r_a × d) λ, Σ I_b⁻¹(r_b × d) λ (an array, not a struct: kept in registers as BodyPair
// is, and no struct without a Rust twin).
alias ImpulseSums = array<vec3<f32>, 3>;

// `sums` with a row along `direction` of moments `arm_a`, `arm_b` (r × d) and impulse
// `impulse`, on bodies of inverse inertias `inertias`.
fn add_row(sums: ImpulseSums, direction: vec3<f32>, arm_a: vec3<f32>, arm_b: vec3<f32>,
           inertias: array<SymmetricMat3, 2>, impulse: f32) -> ImpulseSums {
    return ImpulseSums(sums[0] + direction * impulse,
        sums[1] + symmetric_mul(inertias[0], arm_a) * impulse,
        sums[2] + symmetric_mul(inertias[1], arm_b) * impulse);
}

// The two inverse inertias, A's and B's, from a constraint's header words 5 to 7.
fn inertias_of(words: array<vec4<f32>, 3>) -> array<SymmetricMat3, 2> {
    let a = SymmetricMat3(words[0].xyz, vec3<f32>(words[0].w, words[1].xy));
    let b = SymmetricMat3(vec3<f32>(words[1].zw, words[2].x), words[2].yzw);
    return array<SymmetricMat3, 2>(a, b);
}

// The effective mass 1/K of the row along `direction` at a point with arms `r_a`, `r_b`, on
// bodies of inverse masses summing to `inverse_masses` (contact.rs; the rows' build and the
// solve sweep, which computes it rather than loading it).
fn row_mass(
    direction: vec3<f32>,
    r_a: vec3<f32>,
    r_b: vec3<f32>,
    inertias: array<SymmetricMat3, 2>,
    inverse_masses: f32,
) -> f32 {
    let arm_a = cross(r_a, direction);
    let arm_b = cross(r_b, direction);
    let k = inverse_masses + moment(arm_a, inertias[0]) + moment(arm_b, inertias[1]);
    return select(0.0, 1.0 / k, k > 0.0);
}

// arm · I⁻¹ arm, summed x, y, z (body.wgsl's dot3, which not every kernel with lanes has).
fn moment(arm: vec3<f32>, inertia: SymmetricMat3) -> f32 {
    let turn = symmetric_mul(inertia, arm);
    return arm.x * turn.x + arm.y * turn.y + arm.z * turn.z;
}

// Header words 5 to 7 holding `a` and `b` (`inertias_of` undone).
fn inertia_words(a: SymmetricMat3, b: SymmetricMat3) -> array<vec4<f32>, 3> {
    return array<vec4<f32>, 3>(vec4<f32>(a[0], a[1].x), vec4<f32>(a[1].yz, b[0].xy),
        vec4<f32>(b[0].z, b[1]));
}

// The words SUMS_WORD .. SUMS_WORD + 2 of a constraint whose rows add up to `sums`.
fn sums_words(sums: ImpulseSums, mass_a: f32, mass_b: f32) -> array<vec4<f32>, 3> {
    return array<vec4<f32>, 3>(vec4<f32>(sums[0], 0.0), vec4<f32>(sums[1], mass_a),
        vec4<f32>(sums[2], mass_b));
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
