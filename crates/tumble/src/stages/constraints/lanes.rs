//! The layout the GPU keeps contact constraints in: blocks of [`LANES`] constraints, word by
//! word. Word `w` of constraint `c` is
//!
//! ```text
//!   words[(c / LANES · WORDS + w) · LANES + c % LANES]
//! ```
//!
//! so the threads of a warp, a constraint each, read or write each 16-byte word of their
//! constraints in 512 contiguous bytes. A constraint's words hold its fields as `lanes.wgsl`
//! lists them: the header's in order, a point's arranged so that the four impulses a sweep
//! writes share one word (one store instead of four). Laid out as an array of
//! [`ContactConstraint`]s, the same access touched 32 cache lines 704 bytes apart: a memory instruction's worth of cache
//! traffic 8 times over, on the loads that bound the solver's sweeps and the stores that bound
//! the rows' build.
//!
//! The arrays the CPU builds and solves stay arrays of [`ContactConstraint`]: [`lay_out`] and
//! [`read_back`] convert them on their way to and from the device. There, the rows are built
//! in this layout (`rows.wgsl`), gathered into batch order in it (`gather_rows.wgsl`) and
//! swept in it (`solver.wgsl`), all through `lanes.wgsl`'s index.

use crate::collision::manifold::MAX_MANIFOLD_POINTS;
use crate::gpu::kernel::Source;
use crate::math::Vec3;
use crate::stages::constraints::{ContactConstraint, Row};

const WGSL: &str = include_str!("lanes.wgsl");

/// Constraints a block: a warp of NVIDIA's, half a wave of AMD's, four of lavapipe's subgroups.
pub const LANES: usize = 32;
const _: () = assert!(std::mem::offset_of!(ContactConstraint, points).is_multiple_of(16));
/// Words of the header, which come in the struct's order.
const HEADER_WORDS: usize = std::mem::offset_of!(ContactConstraint, points) / 16;
/// Words of a point on the device: its fields but the rows' `I⁻¹(r × d)`, which the sweeps
/// compute there (`Row::angular_a`).
const POINT_WORDS: usize = 4;
/// Where the impulse sums lie, past the points' words: see [`impulse_sums`].
const SUMS_WORD: usize = HEADER_WORDS + MAX_MANIFOLD_POINTS * POINT_WORDS;
/// 16-byte words of a constraint on the device: the header's, the points', then the three of
/// its [`impulse_sums`].
pub const WORDS: usize = SUMS_WORD + 3;
// `lanes.wgsl` names the header's eight words and a point's four (and `constraint_words` below
// fills them): a field added to either struct must be placed in both.
const _: () = assert!(HEADER_WORDS == 8 && WORDS == 27);

/// 16 bytes of a constraint.
pub type Word = [u32; 4];

/// Words that hold `constraints` constraints: whole blocks.
pub fn word_count(constraints: usize) -> usize {
    constraints.div_ceil(LANES) * LANES * WORDS
}

/// Where word `word` of constraint `constraint` lies.
pub fn word_index(constraint: usize, word: usize) -> usize {
    (constraint / LANES * WORDS + word) * LANES + constraint % LANES
}

/// `constraints` into `words`, laid out in blocks (the lanes past the last constraint zero).
pub fn lay_out(constraints: &[ContactConstraint], words: &mut Vec<Word>) {
    words.clear();
    words.resize(word_count(constraints.len()), [0; 4]);
    for (index, constraint) in constraints.iter().enumerate() {
        for (word, value) in constraint_words(constraint).iter().enumerate() {
            words[word_index(index, word)] = *value;
        }
    }
}

/// The constraints `words` holds back into `constraints` (as many as it has; the points past
/// each one's count come back zero).
pub fn read_back(words: &[Word], constraints: &mut [ContactConstraint]) {
    for (index, constraint) in constraints.iter_mut().enumerate() {
        let mut own = [[0; 4]; WORDS];
        for (word, value) in own.iter_mut().enumerate() {
            *value = words[word_index(index, word)];
        }
        *constraint = from_words(&own);
    }
}

/// `xyz` and `w` as a word.
fn word(xyz: Vec3, w: f32) -> Word {
    [xyz.x, xyz.y, xyz.z, w].map(f32::to_bits)
}

fn xyz(word: Word) -> Vec3 {
    Vec3::new(
        f32::from_bits(word[0]),
        f32::from_bits(word[1]),
        f32::from_bits(word[2]),
    )
}

fn lane(word: Word, lane: usize) -> f32 {
    f32::from_bits(word[lane])
}

/// What a constraint's accumulated impulses do to its bodies, summed over its points' rows in
/// the sweeps' order (points 0 to count − 1; normal, then tangents): Σ d λ, and each side's
/// Σ I⁻¹(r × d) λ (the row by row products the sweeps apply, so that the sums round as close
/// to them as a sum can). Body A's warm start adds `inverse_mass_a · linear` and `angular_a` to
/// its velocities, B's subtracts `inverse_mass_b · linear` and `angular_b`. The device keeps
/// them beside the constraint (`lanes.wgsl`: the rows' build and the PGS relax sweep write
/// them), so that the warm start by body reads two words of each constraint instead of its
/// rows (`warm_start_bodies`); the CPU applies the rows one by one, which rounds differently.
pub fn impulse_sums(constraint: &ContactConstraint) -> [Vec3; 3] {
    let [mut linear, mut angular_a, mut angular_b] = [Vec3::ZERO; 3];
    let tangents = constraint.tangents();
    // `take`: a count past the points (which no built constraint has) sums them all.
    for p in constraint
        .points
        .iter()
        .take(constraint.point_count as usize)
    {
        let rows = [
            (p.normal, constraint.normal),
            (p.tangent[0], tangents[0]),
            (p.tangent[1], tangents[1]),
        ];
        for (row, direction) in rows {
            linear += direction * row.impulse;
            angular_a += row.angular_a * row.impulse;
            angular_b += row.angular_b * row.impulse;
        }
    }
    [linear, angular_a, angular_b]
}

/// A constraint's words, as `lanes.wgsl` lists them.
fn constraint_words(constraint: &ContactConstraint) -> [Word; WORDS] {
    let mut words = [[0; 4]; WORDS];
    let [linear, angular_a, angular_b] = impulse_sums(constraint);
    words[SUMS_WORD] = word(linear, 0.0);
    words[SUMS_WORD + 1] = word(angular_a, constraint.inverse_mass_a);
    words[SUMS_WORD + 2] = word(angular_b, constraint.inverse_mass_b);
    let bytes: &[Word] = bytemuck::cast_slice(std::slice::from_ref(constraint));
    words[..HEADER_WORDS].copy_from_slice(&bytes[..HEADER_WORDS]);
    for (k, p) in constraint.points.iter().enumerate() {
        let [normal, tangent1, tangent2] = [p.normal, p.tangent[0], p.tangent[1]];
        let point = &mut words[HEADER_WORDS + k * POINT_WORDS..][..POINT_WORDS];
        point[0] = word(p.anchor_a, p.adjusted_separation);
        point[1] = word(p.anchor_b, p.separation);
        point[2] = [
            normal.mass,
            tangent1.mass,
            tangent2.mass,
            p.approach_velocity,
        ]
        .map(f32::to_bits);
        point[3] = [
            normal.impulse,
            tangent1.impulse,
            tangent2.impulse,
            p.max_normal_impulse,
        ]
        .map(f32::to_bits);
    }
    words
}

/// [`constraint_words`] undone. The points past the count come back zero, as the CPU builds
/// them: the device does not write their words (`rows.wgsl`), so they hold whatever the
/// buffer had.
fn from_words(words: &[Word; WORDS]) -> ContactConstraint {
    let mut constraint = ContactConstraint::default();
    let bytes: &mut [Word] = bytemuck::cast_slice_mut(std::slice::from_mut(&mut constraint));
    bytes[..HEADER_WORDS].copy_from_slice(&words[..HEADER_WORDS]);
    let count = constraint.point_count as usize;
    // The header alone (its directions and inertias), for the rows' I⁻¹(r × d).
    let header = constraint;
    for (k, p) in constraint.points.iter_mut().enumerate().take(count) {
        let point = &words[HEADER_WORDS + k * POINT_WORDS..][..POINT_WORDS];
        p.anchor_a = xyz(point[0]);
        p.adjusted_separation = lane(point[0], 3);
        p.anchor_b = xyz(point[1]);
        p.separation = lane(point[1], 3);
        p.approach_velocity = lane(point[2], 3);
        p.max_normal_impulse = lane(point[3], 3);
        let [t1, t2] = header.tangents();
        let row = |r: usize, direction: Vec3| {
            let (angular_a, angular_b) = header.angular(p.arms(direction));
            Row {
                angular_a,
                mass: lane(point[2], r),
                angular_b,
                impulse: lane(point[3], r),
            }
        };
        let normal = row(0, header.normal);
        let tangent = [row(1, t1), row(2, t2)];
        (p.normal, p.tangent) = (normal, tangent);
    }
    constraint
}

/// `source` with the layout's constants and `lanes.wgsl`'s index functions.
pub fn with_lanes(source: Source) -> Source {
    source
        .constant_u32("CONSTRAINT_LANES", LANES as u32)
        .constant_u32("CONSTRAINT_WORDS", WORDS as u32)
        .constant_u32("HEADER_WORDS", HEADER_WORDS as u32)
        .constant_u32("POINT_WORDS", POINT_WORDS as u32)
        .constant_u32("SUMS_WORD", SUMS_WORD as u32)
        .snippet("lanes.wgsl", WGSL)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::constraints::ConstraintPoint;

    /// Constraint `index` with every byte telling which constraint and byte it is, but the
    /// points' padding, which does not travel.
    fn numbered(index: usize) -> ContactConstraint {
        let mut constraint = ContactConstraint::default();
        let bytes: &mut [u8] = bytemuck::bytes_of_mut(&mut constraint);
        for (byte, value) in bytes.iter_mut().enumerate() {
            *value = (index * 7 + byte) as u8;
        }
        for point in &mut constraint.points {
            point._pad = [0.0; 2];
        }
        constraint
    }

    /// `constraint` without its rows' I⁻¹(r × d), which do not travel either: the read-back
    /// computes them from the header and the anchors (checked on finite values by
    /// `the_rows_angular_terms_come_back_as_built`; from numbered bytes they are NaN as often
    /// as not, whose payloads depend on how the compiler ordered the operands).
    fn without_angular(mut constraint: ContactConstraint) -> ContactConstraint {
        for point in &mut constraint.points {
            let [tangent1, tangent2] = &mut point.tangent;
            for row in [&mut point.normal, tangent1, tangent2] {
                (row.angular_a, row.angular_b) = (Vec3::ZERO, Vec3::ZERO);
            }
        }
        constraint
    }

    /// Random constraints with each row's I⁻¹(r × d) computed as the build does: the
    /// read-back, which does not receive them, computes the same bits.
    #[test]
    fn the_rows_angular_terms_come_back_as_built() {
        use crate::collision::dbvt::tests::TestRng;
        use crate::math::SymmetricMat3;
        let mut rng = TestRng::new(11);
        let constraints: Vec<ContactConstraint> = (0..70)
            .map(|index| {
                let normal = rng.vec3(-1.0, 1.0).normalize();
                let (tangent1, tangent2) = crate::math::tangent_basis(normal);
                let mut inertia = || SymmetricMat3 {
                    diagonal: rng.vec3(0.0, 2.0),
                    off_diagonal: rng.vec3(-0.5, 0.5),
                };
                let mut c = ContactConstraint {
                    point_count: index % 5,
                    normal,
                    tangent1,
                    tangent2,
                    inverse_inertia_a: inertia(),
                    inverse_inertia_b: inertia(),
                    ..ContactConstraint::default()
                };
                let header = c;
                for point in &mut c.points[..c.point_count as usize] {
                    (point.anchor_a, point.anchor_b) = (rng.vec3(-1.0, 1.0), rng.vec3(-1.0, 1.0));
                    let [n, t1, t2] = [normal, tangent1, tangent2]
                        .map(|direction| header.angular(point.arms(direction)));
                    (point.normal.angular_a, point.normal.angular_b) = n;
                    (point.tangent[0].angular_a, point.tangent[0].angular_b) = t1;
                    (point.tangent[1].angular_a, point.tangent[1].angular_b) = t2;
                }
                c
            })
            .collect();
        let mut words = Vec::new();
        lay_out(&constraints, &mut words);
        let mut back = vec![ContactConstraint::default(); constraints.len()];
        read_back(&words, &mut back);
        assert!(back == constraints);
    }

    #[test]
    fn every_word_has_its_own_place() {
        for count in [1, 31, 32, 33, 100] {
            let mut seen = vec![false; word_count(count)];
            for constraint in 0..count {
                for word in 0..WORDS {
                    let place = word_index(constraint, word);
                    assert!(
                        !seen[place],
                        "{count} constraints: word {word} of {constraint}"
                    );
                    seen[place] = true;
                }
            }
            // Only the lanes past the last constraint stay free.
            let free = seen.iter().filter(|taken| !**taken).count();
            assert_eq!(free, (count.div_ceil(LANES) * LANES - count) * WORDS);
        }
    }

    #[test]
    fn a_warp_reads_a_word_from_contiguous_bytes() {
        let places: Vec<usize> = (32..64).map(|c| word_index(c, 7)).collect();
        assert!(places.windows(2).all(|w| w[1] == w[0] + 1), "{places:?}");
    }

    /// The device writes no word of a point past the count: what the buffer held there comes
    /// back as zero points, as the CPU builds them.
    #[test]
    fn points_past_the_count_come_back_zero() {
        for count in 0..=4 {
            let mut constraint = numbered(3);
            constraint.point_count = count;
            let mut words = Vec::new();
            lay_out(&[constraint], &mut words);
            let mut back = [ContactConstraint::default()];
            read_back(&words, &mut back);
            let count = count as usize;
            // Bytes, not floats: the numbering makes some of them NaN.
            let bytes = |p: &[ConstraintPoint]| bytemuck::cast_slice::<_, u8>(p).to_vec();
            let (back, constraint) = (without_angular(back[0]), without_angular(constraint));
            assert!(bytes(&back.points[..count]) == bytes(&constraint.points[..count]));
            assert!(
                back.points[count..]
                    .iter()
                    .all(|p| *p == ConstraintPoint::default()),
                "{count} points"
            );
        }
    }

    #[test]
    fn constraints_come_back_as_they_went() {
        for count in [0, 1, 2, 31, 32, 33, 65, 1000] {
            let constraints: Vec<_> = (0..count).map(numbered).collect();
            let mut words = Vec::new();
            lay_out(&constraints, &mut words);
            assert_eq!(words.len(), word_count(count));
            let mut back = vec![ContactConstraint::default(); count];
            read_back(&words, &mut back);
            // Bytes, not floats: the numbering makes some of them NaN.
            let bytes = |c: &[ContactConstraint]| {
                let c: Vec<_> = c.iter().copied().map(without_angular).collect();
                bytemuck::cast_slice::<_, u8>(&c).to_vec()
            };
            assert!(bytes(&back) == bytes(&constraints), "{count} constraints");
        }
    }
}
