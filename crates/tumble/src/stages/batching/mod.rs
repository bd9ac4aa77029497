//! Stage 6: batching by graph coloring (the talk's "reordering constraint batches"), so that
//! the constraints of one batch share no dynamic body and can be solved in parallel.
//!
//! Greedy coloring in constraint order: each constraint takes the lowest color that none of its
//! dynamic bodies has used yet (per-body 64-bit color masks, as Box2D v3's constraint graph).
//! This is exactly the talk's `kSetupBatches` scheme run deterministically: round k walks the
//! unassigned constraints in order and a constraint joins batch k when both its bodies are still
//! free in that round — by induction a constraint lands in round k iff k is the lowest color
//! unused by the earlier constraints on its bodies. Batch sizes therefore fall off like the
//! histograms on the talk's screens (0: 1064, 1: 909, ...).
//!
//! Guarantees: no two constraints of a normal batch share a dynamic body (static bodies never
//! conflict); every constraint gets a batch; the result depends only on the constraint order.
//! A constraint whose bodies have used all [`MAX_COLORS`] colors goes to a final overflow batch,
//! which the solver walks sequentially (still Gauss-Seidel, just not parallel).

use crate::stages::constraints::{ContactConstraint, STATIC_BODY};

/// Colors tracked per body (bits of a `u64` mask).
pub const MAX_COLORS: usize = 64;

/// Constraints grouped by batch.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batches {
    /// Batch `i` is `order[offsets[i]..offsets[i + 1]]` (constraint indices, ascending).
    pub order: Vec<u32>,
    pub offsets: Vec<u32>,
    /// True when the last batch is the overflow batch (may share bodies; solve in order).
    pub has_overflow: bool,
    /// Per-body color mask, kept to avoid allocation per step.
    masks: Vec<u64>,
    colors: Vec<u8>,
    counts: Vec<u32>,
}

impl Batches {
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Constraint indices of batch `i`.
    pub fn batch(&self, i: usize) -> &[u32] {
        &self.order[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Number of constraints in each batch: the talk's batch histogram.
    pub fn histogram(&self) -> Vec<u32> {
        self.offsets.windows(2).map(|w| w[1] - w[0]).collect()
    }
}

/// CPU executor: colors `constraints` (bodies indexed below `body_count`).
pub fn color_constraints(
    constraints: &[ContactConstraint],
    body_count: usize,
    batches: &mut Batches,
) {
    batches.masks.clear();
    batches.masks.resize(body_count, 0);
    batches.colors.clear();
    batches.counts.clear();
    batches.counts.resize(MAX_COLORS + 1, 0);
    let overflow = MAX_COLORS as u8;
    for constraint in constraints {
        let mask_of = |masks: &[u64], body: u32| {
            if body == STATIC_BODY {
                0
            } else {
                masks[body as usize]
            }
        };
        let used =
            mask_of(&batches.masks, constraint.body_a) | mask_of(&batches.masks, constraint.body_b);
        let color = if used == u64::MAX {
            overflow
        } else {
            (!used).trailing_zeros() as u8
        };
        if color != overflow {
            for body in [constraint.body_a, constraint.body_b] {
                if body != STATIC_BODY {
                    batches.masks[body as usize] |= 1 << color;
                }
            }
        }
        batches.colors.push(color);
        batches.counts[color as usize] += 1;
    }
    // Counting sort by color keeps constraint order inside each batch.
    let used_colors = batches.counts[..MAX_COLORS]
        .iter()
        .rposition(|&n| n > 0)
        .map_or(0, |c| c + 1);
    batches.has_overflow = batches.counts[MAX_COLORS] > 0;
    batches.offsets.clear();
    batches.offsets.push(0);
    let mut total = 0;
    for color in (0..used_colors).chain(batches.has_overflow.then_some(MAX_COLORS)) {
        total += batches.counts[color];
        batches.offsets.push(total);
    }
    // Reuse `counts` as each color's write cursor.
    let mut cursor = 0;
    for color in 0..=MAX_COLORS {
        let n = batches.counts[color];
        batches.counts[color] = cursor;
        cursor += n;
    }
    batches.order.clear();
    batches.order.resize(constraints.len(), 0);
    for (index, &color) in batches.colors.iter().enumerate() {
        let slot = &mut batches.counts[color as usize];
        batches.order[*slot as usize] = index as u32;
        *slot += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constraint(a: u32, b: u32) -> ContactConstraint {
        ContactConstraint {
            body_a: a,
            body_b: b,
            ..Default::default()
        }
    }

    /// Deterministic pseudo-random numbers for tests (xorshift).
    fn next(state: &mut u64) -> u64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        *state
    }

    #[test]
    fn talk_example_four_bodies() {
        // The slide: constraints 1 (A,B), 2 (B,C), 3 (C,D), 4 (A,D) → batches {1,3} and {2,4}.
        let constraints = [
            constraint(0, 1),
            constraint(1, 2),
            constraint(2, 3),
            constraint(0, 3),
        ];
        let mut batches = Batches::default();
        color_constraints(&constraints, 4, &mut batches);
        assert_eq!(batches.len(), 2);
        assert_eq!(batches.batch(0), [0, 2]);
        assert_eq!(batches.batch(1), [1, 3]);
    }

    #[test]
    fn random_graphs_batches_share_no_dynamic_body() {
        let mut state = 0x9e37_79b9_7f4a_7c15;
        for &(bodies, count) in &[
            (1usize, 0usize),
            (2, 1),
            (10, 200),
            (1000, 5000),
            (20_000, 100_000),
        ] {
            let constraints: Vec<_> = (0..count)
                .map(|_| {
                    let a = (next(&mut state) % bodies as u64) as u32;
                    // Some constraints are against a static body.
                    let b = if next(&mut state) % 4 == 0 {
                        STATIC_BODY
                    } else {
                        (next(&mut state) % bodies as u64) as u32
                    };
                    constraint(a, b)
                })
                .collect();
            let mut batches = Batches::default();
            color_constraints(&constraints, bodies, &mut batches);
            let mut seen = vec![false; count];
            for batch in 0..batches.len() {
                let is_overflow = batches.has_overflow && batch + 1 == batches.len();
                let mut used = std::collections::HashSet::new();
                for &c in batches.batch(batch) {
                    assert!(!seen[c as usize], "constraint in two batches");
                    seen[c as usize] = true;
                    let constraint = &constraints[c as usize];
                    // A constraint of a body with itself cannot exist; skip the check for those.
                    if !is_overflow && constraint.body_a != constraint.body_b {
                        for body in [constraint.body_a, constraint.body_b] {
                            assert!(
                                body == STATIC_BODY || used.insert(body),
                                "body {body} twice in batch {batch}"
                            );
                        }
                    }
                }
                assert!(
                    batches.batch(batch).windows(2).all(|w| w[0] < w[1]),
                    "batch keeps constraint order"
                );
            }
            assert!(seen.iter().all(|&s| s), "every constraint gets a batch");
        }
    }

    #[test]
    fn a_body_with_more_than_64_constraints_overflows_into_a_sequential_batch() {
        let constraints: Vec<_> = (1..=70).map(|other| constraint(0, other)).collect();
        let mut batches = Batches::default();
        color_constraints(&constraints, 71, &mut batches);
        assert!(batches.has_overflow);
        assert_eq!(batches.len(), 65);
        assert_eq!(batches.histogram().iter().sum::<u32>(), 70);
        assert_eq!(batches.batch(64), [64, 65, 66, 67, 68, 69]);
    }
}
