//! Stage 6: batching by graph coloring (the talk's "reordering constraint batches"), so that
//! the constraints of one batch share no dynamic body and can be solved in parallel. Contacts
//! and joints are colored together: a batch holds both kinds.
//!
//! Greedy coloring in constraint order: each constraint takes the lowest color that none of its
//! dynamic bodies has used yet (per-body 64-bit color masks, as Box2D v3's constraint graph).
//! This is exactly the talk's `kSetupBatches` scheme run deterministically: round k walks the
//! unassigned constraints in order and a constraint joins batch k when both its bodies are still
//! free in that round — by induction a constraint lands in round k iff k is the lowest color
//! unused by the earlier constraints on its bodies. Batch sizes therefore fall off like the
//! histograms on the talk's screens (0: 1064, 1: 909, ...).
//!
//! Guarantees: no two constraints of a normal batch share a dynamic body (static bodies,
//! [`STATIC_BODY`], never conflict); every constraint gets a batch; the result depends only on
//! the constraint order. A constraint whose bodies have used all [`MAX_COLORS`] colors goes to
//! a final overflow batch, which the solver walks sequentially (still Gauss-Seidel, just not
//! parallel).

use crate::stages::constraints::STATIC_BODY;

/// Colors tracked per body (bits of a `u64` mask).
pub const MAX_COLORS: usize = 64;

/// The color of every constraint, and how many constraints each color has.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Coloring {
    /// One color per constraint, in input order; [`MAX_COLORS`] marks the overflow batch.
    pub colors: Vec<u8>,
    /// Batches in solve order: colors `0..batch_count` (the last one is the overflow batch when
    /// `has_overflow`).
    pub batch_count: usize,
    pub has_overflow: bool,
    /// Constraints per batch: the talk's batch histogram.
    pub histogram: Vec<u32>,
    /// Per-body color mask, kept to avoid allocation per step.
    masks: Vec<u64>,
}

impl Coloring {
    /// The batch a color is solved in.
    #[inline]
    pub fn batch_of(&self, color: u8) -> usize {
        if color as usize == MAX_COLORS {
            self.batch_count - 1
        } else {
            color as usize
        }
    }
}

/// CPU executor: colors constraints given as (body A, body B) in solve order; bodies are
/// indexed below `body_count` or are [`STATIC_BODY`].
pub fn color_constraints(
    bodies: impl Iterator<Item = (u32, u32)>,
    body_count: usize,
    coloring: &mut Coloring,
) {
    coloring.masks.clear();
    coloring.masks.resize(body_count, 0);
    coloring.colors.clear();
    let mut counts = [0u32; MAX_COLORS + 1];
    let overflow = MAX_COLORS as u8;
    for (a, b) in bodies {
        let mask_of = |masks: &[u64], body: u32| {
            if body == STATIC_BODY {
                0
            } else {
                masks[body as usize]
            }
        };
        let used = mask_of(&coloring.masks, a) | mask_of(&coloring.masks, b);
        let color = if used == u64::MAX {
            overflow
        } else {
            (!used).trailing_zeros() as u8
        };
        if color != overflow {
            for body in [a, b] {
                if body != STATIC_BODY {
                    coloring.masks[body as usize] |= 1 << color;
                }
            }
        }
        coloring.colors.push(color);
        counts[color as usize] += 1;
    }
    let used_colors = counts[..MAX_COLORS]
        .iter()
        .rposition(|&n| n > 0)
        .map_or(0, |c| c + 1);
    coloring.has_overflow = counts[MAX_COLORS] > 0;
    coloring.batch_count = used_colors + coloring.has_overflow as usize;
    coloring.histogram.clear();
    coloring.histogram.extend_from_slice(&counts[..used_colors]);
    if coloring.has_overflow {
        coloring.histogram.push(counts[MAX_COLORS]);
    }
}

/// Lays `items` out batch after batch (a stable counting sort by batch): batch `i` becomes
/// `out[offsets[i]..offsets[i + 1]]`, in input order inside the batch. `colors[i]` is item `i`'s.
pub fn group_by_batch<T: Copy>(
    items: &[T],
    colors: &[u8],
    coloring: &Coloring,
    out: &mut Vec<T>,
    offsets: &mut Vec<u32>,
) {
    debug_assert_eq!(items.len(), colors.len());
    // Counting sort without scratch: `offsets[b + 1]` first counts batch b, then holds its
    // start and serves as the write cursor, ending at its end = the start of batch b + 1.
    offsets.clear();
    offsets.resize(coloring.batch_count + 1, 0);
    for &color in colors {
        offsets[coloring.batch_of(color) + 1] += 1;
    }
    let mut start = 0;
    for batch in 0..coloring.batch_count {
        let count = offsets[batch + 1];
        offsets[batch + 1] = start;
        start += count;
    }
    out.clear();
    if items.is_empty() {
        return;
    }
    out.resize(items.len(), items[0]);
    for (item, &color) in items.iter().zip(colors) {
        let slot = &mut offsets[coloring.batch_of(color) + 1];
        out[*slot as usize] = *item;
        *slot += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers for tests (xorshift).
    fn next(state: &mut u64) -> u64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        *state
    }

    fn batches_of(coloring: &Coloring) -> Vec<Vec<usize>> {
        let indices: Vec<usize> = (0..coloring.colors.len()).collect();
        let (mut out, mut offsets) = (Vec::new(), Vec::new());
        group_by_batch(&indices, &coloring.colors, coloring, &mut out, &mut offsets);
        offsets
            .windows(2)
            .map(|w| out[w[0] as usize..w[1] as usize].to_vec())
            .collect()
    }

    #[test]
    fn talk_example_four_bodies() {
        // The slide: constraints 1 (A,B), 2 (B,C), 3 (C,D), 4 (A,D) → batches {1,3} and {2,4}.
        let edges = [(0, 1), (1, 2), (2, 3), (0, 3)];
        let mut coloring = Coloring::default();
        color_constraints(edges.into_iter(), 4, &mut coloring);
        assert_eq!(batches_of(&coloring), [vec![0, 2], vec![1, 3]]);
        assert_eq!(coloring.histogram, [2, 2]);
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
            (200_000, 1_000_000),
        ] {
            let edges: Vec<(u32, u32)> = (0..count)
                .map(|_| {
                    let a = (next(&mut state) % bodies as u64) as u32;
                    // A quarter of the constraints are against a static body; none of a body with itself.
                    let b = (next(&mut state) % bodies as u64) as u32;
                    if next(&mut state).is_multiple_of(4) || a == b {
                        (a, STATIC_BODY)
                    } else {
                        (a, b)
                    }
                })
                .collect();
            let mut coloring = Coloring::default();
            color_constraints(edges.iter().copied(), bodies, &mut coloring);
            let batches = batches_of(&coloring);
            assert_eq!(
                batches.iter().map(Vec::len).collect::<Vec<_>>(),
                coloring
                    .histogram
                    .iter()
                    .map(|&n| n as usize)
                    .collect::<Vec<_>>()
            );
            let mut seen = vec![false; count];
            for (batch, members) in batches.iter().enumerate() {
                let is_overflow = coloring.has_overflow && batch + 1 == batches.len();
                let mut used = std::collections::HashSet::new();
                for &c in members {
                    assert!(!seen[c], "constraint in two batches");
                    seen[c] = true;
                    for body in [edges[c].0, edges[c].1] {
                        assert!(
                            is_overflow || body == STATIC_BODY || used.insert(body),
                            "body {body} twice in batch {batch}"
                        );
                    }
                }
                assert!(
                    members.windows(2).all(|w| w[0] < w[1]),
                    "a batch keeps constraint order"
                );
            }
            assert!(seen.iter().all(|&s| s), "every constraint gets a batch");
        }
    }

    #[test]
    fn a_body_with_more_than_64_constraints_overflows_into_a_sequential_batch() {
        let edges: Vec<(u32, u32)> = (1..=70).map(|other| (0, other)).collect();
        let mut coloring = Coloring::default();
        color_constraints(edges.into_iter(), 71, &mut coloring);
        assert!(coloring.has_overflow);
        assert_eq!(coloring.batch_count, 65);
        assert_eq!(coloring.histogram.iter().sum::<u32>(), 70);
        assert_eq!(batches_of(&coloring)[64], [64, 65, 66, 67, 68, 69]);
    }
}
