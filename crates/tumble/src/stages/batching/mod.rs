//! Stage 6: batching by graph coloring (the talk's "reordering constraint batches"), so that
//! the constraints of one batch share no dynamic body and can be solved in parallel. Contacts
//! and joints are colored together: a batch holds both kinds.
//!
//! Both batchers (the talk's `d` key, [`Batcher`]) work in rounds that a GPU runs as two
//! dispatches each, and the CPU executor here runs the same rounds, so both executors give
//! the same batches. In a round every constraint not yet batched claims its dynamic bodies,
//! and a constraint wins when it has the highest priority (the lowest [`priority`] value)
//! among the claims of each of them — the talk's per-body locks, made deterministic:
//! - [`Batcher::Rounds`] (the talk's `kSetupBatches`): a body has one lock, so winners share
//!   no body; round k's winners are batch k.
//! - [`Batcher::Colors`]: a constraint first takes, tentatively, the lowest color that none of
//!   its bodies has yet (per-body 64-bit masks, as Box2D v3's constraint graph, as they were
//!   at the round's start), and claims its bodies' lock slot for that color
//!   ([`LOCK_SLOTS`] a body): constraints that took different colors on one body win
//!   together, and a winner keeps its color. Winners on one body have different colors, so
//!   no batch shares a body. A joint claims every slot of its bodies, so joints keep one
//!   winner a body a round, before any contact there, as the sweeps need (below). Later
//!   rounds fill earlier batches, so this needs far fewer batches than `Rounds`, and about as
//!   many as greedy coloring in priority order (which is the one-slot case: when a constraint
//!   wins, every constraint before it on its bodies has a color), in about a round a color
//!   (a settled 100k pile on an H100: 13 rounds for 13 colors, where one lock a body took
//!   35).
//!
//! Contact priorities are a bijective hash of the constraint index: in index order (pair
//! keys, spatially sorted) chains of constraints sharing bodies would let one constraint in a
//! chain win per round; hashed, a round batches most of what it could. Joints come first in
//! index order (see [`priority`]): a ragdoll's joints then get their colors along the chain,
//! which its Gauss-Seidel sweeps need to settle (hashed, 6 ragdolls still moved with 2.4 J
//! after 5 s). A chain of more than [`MAX_ROUNDS`] joints overflows into the sequential batch.
//!
//! Guarantees: no two constraints of a normal batch share a dynamic body (static bodies,
//! [`STATIC_BODY`], never conflict); every constraint gets a batch; the result depends only on
//! the constraint order and the batcher. A constraint still unbatched after [`MAX_ROUNDS`]
//! rounds, or whose bodies have used all [`MAX_COLORS`] colors, goes to a final overflow
//! batch, which the solver walks sequentially (still Gauss-Seidel, just not parallel).

pub mod gpu;
pub mod layout;

use std::fmt;
use std::str::FromStr;

use crate::stages::constraints::STATIC_BODY;

/// Colors tracked per body (bits of a `u64` mask).
pub const MAX_COLORS: usize = 64;

/// Rounds before the constraints still unbatched go to the overflow batch. `Rounds` makes
/// one batch a round, so it is the same limit as [`MAX_COLORS`].
pub const MAX_ROUNDS: usize = MAX_COLORS;

/// Locks a body has in a round of the colors batcher: a constraint claims slot
/// `color % LOCK_SLOTS` of its bodies for its tentative color, so constraints that took
/// different colors on one body (but for every fourth) win together. Simulated on a settled
/// pile of 9k boxes (`docs/bench/s20-batching-rounds-experiment.rs`): 10 rounds for 10 colors
/// with 4 slots, as with 64, against 23 with one (one winner a body a round).
pub const LOCK_SLOTS: usize = 4;

/// How constraints are put into batches (the talk's `d` key).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Batcher {
    /// The talk's `kSetupBatches`: batch k holds round k's winners.
    Rounds,
    /// Greedy coloring with per-body color masks: a winner takes its bodies' lowest free color.
    #[default]
    Colors,
}

impl Batcher {
    pub const ALL: [Batcher; 2] = [Batcher::Rounds, Batcher::Colors];

    pub fn name(self) -> &'static str {
        match self {
            Batcher::Rounds => "rounds",
            Batcher::Colors => "colors",
        }
    }

    /// The other batcher (the viewer's `d` key).
    pub fn next(self) -> Self {
        match self {
            Batcher::Rounds => Batcher::Colors,
            Batcher::Colors => Batcher::Rounds,
        }
    }
}

impl fmt::Display for Batcher {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A batcher name that is none of [`Batcher::ALL`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown batcher {0:?}; batchers are rounds, colors")]
pub struct UnknownBatcher(pub String);

impl FromStr for Batcher {
    type Err = UnknownBatcher;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Batcher::ALL
            .into_iter()
            .find(|batcher| batcher.name() == name)
            .ok_or_else(|| UnknownBatcher(name.to_owned()))
    }
}

/// A constraint's priority in the rounds (lower wins), unique to it. The first `ordered`
/// constraints (the joints) win in index order, before every other: joint chains converge
/// best solved along the chain, as they are listed. The rest rank by a bijective 31-bit hash
/// of their index (xor-shifts and odd multipliers modulo 2³¹, each invertible) above 2³¹. The
/// WGSL twin is `priority` in `batching.wgsl`.
#[inline]
pub fn priority(index: u32, ordered: u32) -> u32 {
    const LOW_31: u32 = 0x7fff_ffff;
    if index < ordered {
        return index;
    }
    let mut x = index & LOW_31;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d) & LOW_31;
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b) & LOW_31;
    x ^= x >> 16;
    0x8000_0000 | x
}

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
    /// Rounds that found a constraint left to batch: how many a GPU batching has to encode
    /// to finish without a second pass (see `GpuStages::color_constraints`), unless some
    /// constraint is left for the overflow batch after the last round.
    pub rounds: usize,
    /// Scratch kept to avoid allocation per step: the constraints' bodies, the per-body
    /// color masks and lock slots, the constraints not yet batched and their tentative colors.
    bodies: Vec<[u32; 2]>,
    masks: Vec<u64>,
    locks: Vec<u32>,
    remaining: Vec<u32>,
    tentative: Vec<u8>,
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

    /// Sets the batch count, overflow flag and histogram from `colors` (whichever executor
    /// wrote them). Colors below [`MAX_COLORS`] are used without gaps: both batchers only
    /// ever take color k when some constraint already has color k − 1.
    pub fn count_batches(&mut self) {
        let mut counts = [0u32; MAX_COLORS + 1];
        for &color in &self.colors {
            counts[color as usize] += 1;
        }
        self.set_batch_sizes(&counts);
    }

    /// Sets the batch count, overflow flag and histogram from the constraints of each color
    /// (`counts[MAX_COLORS]`: the overflow batch's), as a device's batch layout has them.
    pub fn set_batch_sizes(&mut self, counts: &[u32]) {
        assert_eq!(
            counts.len(),
            MAX_COLORS + 1,
            "a count per color and the overflow"
        );
        let used_colors = counts[..MAX_COLORS]
            .iter()
            .rposition(|&n| n > 0)
            .map_or(0, |c| c + 1);
        debug_assert!(counts[..used_colors].iter().all(|&n| n > 0), "a color gap");
        self.has_overflow = counts[MAX_COLORS] > 0;
        self.batch_count = used_colors + self.has_overflow as usize;
        self.histogram.clear();
        self.histogram.extend_from_slice(&counts[..used_colors]);
        if self.has_overflow {
            self.histogram.push(counts[MAX_COLORS]);
        }
    }
}

/// CPU executor: colors constraints given as (body A, body B) in solve order, the first
/// `ordered` of them (the joints) ranked by index (see [`priority`]); bodies are indexed below
/// `body_count` or are [`STATIC_BODY`]. The rounds of the module docs, one
/// after the other; within a round the winners are independent, so walking them in order
/// gives what the GPU's parallel threads give.
pub fn color_constraints(
    bodies: impl Iterator<Item = (u32, u32)>,
    body_count: usize,
    ordered: usize,
    batcher: Batcher,
    coloring: &mut Coloring,
) {
    const UNBATCHED: u8 = u8::MAX;
    const OVERFLOW: u8 = MAX_COLORS as u8;
    let Coloring {
        colors,
        bodies: pairs,
        masks,
        locks,
        remaining,
        tentative,
        ..
    } = coloring;
    pairs.clear();
    pairs.extend(bodies.map(|(a, b)| [a, b]));
    colors.clear();
    colors.resize(pairs.len(), UNBATCHED);
    masks.clear();
    masks.resize(body_count, 0);
    locks.clear();
    locks.resize(body_count * LOCK_SLOTS, u32::MAX);
    remaining.clear();
    remaining.extend(0..pairs.len() as u32);
    tentative.clear();
    tentative.resize(pairs.len(), 0);
    let dynamic = |pair: [u32; 2]| pair.into_iter().filter(|&body| body != STATIC_BODY);
    let ordered = ordered as u32;
    // Body `body`'s lock for `color` (`lock_index` in batching.wgsl).
    let lock = |body: u32, color: u8| {
        let slot = match batcher {
            Batcher::Rounds => 0,
            Batcher::Colors => color as usize % LOCK_SLOTS,
        };
        body as usize * LOCK_SLOTS + slot
    };

    coloring.rounds = 0;
    for round in 0..MAX_ROUNDS {
        if remaining.is_empty() {
            break;
        }
        coloring.rounds = round + 1;
        // The claims, from the masks as the last round left them.
        for &c in remaining.iter() {
            let pair = pairs[c as usize];
            let color = match batcher {
                Batcher::Rounds => round as u8,
                Batcher::Colors => {
                    let used = dynamic(pair).fold(0, |used, body| used | masks[body as usize]);
                    if used == u64::MAX {
                        OVERFLOW
                    } else {
                        (!used).trailing_zeros() as u8
                    }
                }
            };
            tentative[c as usize] = color;
            // A joint claims every slot: on its bodies no contact, and no later joint, wins
            // before it, as with one lock a body.
            let p = priority(c, ordered);
            for body in dynamic(pair) {
                let first = body as usize * LOCK_SLOTS;
                let slots = if c < ordered {
                    first..first + LOCK_SLOTS
                } else {
                    let slot = lock(body, color);
                    slot..slot + 1
                };
                for slot in &mut locks[slots] {
                    *slot = (*slot).min(p);
                }
            }
        }
        for &c in remaining.iter() {
            let (pair, color) = (pairs[c as usize], tentative[c as usize]);
            if !dynamic(pair).all(|body| locks[lock(body, color)] == priority(c, ordered)) {
                continue;
            }
            // Both batchers record each body's colors: the colors batcher chooses by them,
            // and the solver's warm start finds a body's constraints by them.
            if color != OVERFLOW {
                for body in dynamic(pair) {
                    masks[body as usize] |= 1 << color;
                }
            }
            colors[c as usize] = color;
        }
        for &c in remaining.iter() {
            for body in dynamic(pairs[c as usize]) {
                let first = body as usize * LOCK_SLOTS;
                locks[first..first + LOCK_SLOTS].fill(u32::MAX);
            }
        }
        remaining.retain(|&c| colors[c as usize] == UNBATCHED);
    }
    for &c in remaining.iter() {
        colors[c as usize] = OVERFLOW;
    }
    coloring.count_batches();
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
    batch_starts(colors, coloring, offsets);
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

/// [`group_by_batch`] of the indices `0..colors.len()`: `order[k]` is the item that goes to
/// place k (what a device gathers by).
pub fn batch_order(
    colors: &[u8],
    coloring: &Coloring,
    order: &mut Vec<u32>,
    offsets: &mut Vec<u32>,
) {
    batch_starts(colors, coloring, offsets);
    order.clear();
    order.resize(colors.len(), 0);
    for (item, &color) in colors.iter().enumerate() {
        let slot = &mut offsets[coloring.batch_of(color) + 1];
        order[*slot as usize] = item as u32;
        *slot += 1;
    }
}

/// Counting sort without scratch, first half: `offsets[b + 1]` first counts batch b, then is
/// set to its start, to serve as the write cursor that ends at its end = the start of b + 1.
fn batch_starts(colors: &[u8], coloring: &Coloring, offsets: &mut Vec<u32>) {
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
        // The order a device gathers by is the same layout.
        let (mut order, mut order_offsets) = (Vec::new(), Vec::new());
        batch_order(&coloring.colors, coloring, &mut order, &mut order_offsets);
        assert_eq!(order_offsets, offsets);
        assert!(order.iter().zip(&out).all(|(&a, &b)| a as usize == b));
        offsets
            .windows(2)
            .map(|w| out[w[0] as usize..w[1] as usize].to_vec())
            .collect()
    }

    fn random_edges(state: &mut u64, bodies: usize, count: usize) -> Vec<(u32, u32)> {
        (0..count)
            .map(|_| {
                let a = (next(state) % bodies as u64) as u32;
                // A quarter of the constraints are against a static body; none of a body with itself.
                let b = (next(state) % bodies as u64) as u32;
                if next(state).is_multiple_of(4) || a == b {
                    (a, STATIC_BODY)
                } else {
                    (a, b)
                }
            })
            .collect()
    }

    #[test]
    fn talk_example_four_bodies() {
        // The slide: constraints 1 (A,B), 2 (B,C), 3 (C,D), 4 (A,D) → batches {1,3} and {2,4}.
        let edges = [(0, 1), (1, 2), (2, 3), (0, 3)];
        let mut coloring = Coloring::default();
        color_constraints(edges.into_iter(), 4, 0, Batcher::Colors, &mut coloring);
        assert_eq!(batches_of(&coloring), [vec![0, 2], vec![1, 3]]);
        assert_eq!(coloring.histogram, [2, 2]);
    }

    #[test]
    fn priorities_are_distinct() {
        for ordered in [0, 1000] {
            let mut seen: Vec<u32> = (0..1 << 20).map(|c| priority(c, ordered)).collect();
            assert!(
                (0..ordered).all(|c| seen[c as usize] == c),
                "joints keep their order"
            );
            seen.sort_unstable();
            assert!(seen.windows(2).all(|w| w[0] < w[1]));
        }
    }

    /// `count` random constraints among `bodies` (the first `ordered` of them joints), and their
    /// colors by the colors batcher.
    fn colored_random_graph(
        state: &mut u64,
        bodies: usize,
        count: usize,
        ordered: usize,
    ) -> (Vec<(u32, u32)>, Coloring) {
        let edges = random_edges(state, bodies, count);
        let mut coloring = Coloring::default();
        let constraints = edges.iter().copied();
        color_constraints(constraints, bodies, ordered, Batcher::Colors, &mut coloring);
        (edges, coloring)
    }

    /// `Colors` is a first-fit coloring when nothing overflows: every color below a
    /// constraint's is taken on one of its bodies by another constraint (it had those when the
    /// constraint won, and keeps them).
    #[test]
    fn colors_are_first_fit() {
        let mut state = 0x2545_f491_4f6c_dd1d;
        for &(bodies, count) in &[(10usize, 30usize), (1000, 3000), (5000, 20_000)] {
            let (edges, coloring) = colored_random_graph(&mut state, bodies, count, 7);
            assert!(!coloring.has_overflow);
            let mut taken = vec![Vec::new(); bodies];
            for (c, &(a, b)) in edges.iter().enumerate() {
                for body in [a, b].into_iter().filter(|&body| body != STATIC_BODY) {
                    taken[body as usize].push((c, coloring.colors[c]));
                }
            }
            for (c, &(a, b)) in edges.iter().enumerate() {
                let on = |body: u32, color: u8| {
                    body != STATIC_BODY
                        && taken[body as usize]
                            .iter()
                            .any(|&(d, k)| d != c && k == color)
                };
                for color in 0..coloring.colors[c] {
                    assert!(
                        on(a, color) || on(b, color),
                        "constraint {c}, color {color}"
                    );
                }
            }
        }
    }

    /// With [`LOCK_SLOTS`] slots a body, the colors batcher takes about a round a color on
    /// random graphs: 14, 18 and 14 rounds for as many colors on these, where one lock a body
    /// (greedy coloring in priority order, the same colors' count) took 21, 30 and 23.
    #[test]
    fn lock_slots_take_about_a_round_a_color() {
        let mut state = 0x2545_f491_4f6c_dd1d;
        for &(bodies, count) in &[(1000usize, 3000usize), (5000, 20_000), (20_000, 50_000)] {
            let (_, coloring) = colored_random_graph(&mut state, bodies, count, 0);
            assert!(
                coloring.rounds <= coloring.batch_count + 2,
                "{bodies} bodies: {} rounds for {} colors",
                coloring.rounds,
                coloring.batch_count
            );
        }
    }

    #[test]
    fn random_graphs_batches_share_no_dynamic_body() {
        let mut state = 0x9e37_79b9_7f4a_7c15;
        for batcher in Batcher::ALL {
            for &(bodies, count) in &[
                (1usize, 0usize),
                (2, 1),
                (10, 200),
                (1000, 5000),
                (20_000, 100_000),
                (200_000, 1_000_000),
            ] {
                let edges = random_edges(&mut state, bodies, count);
                let mut coloring = Coloring::default();
                color_constraints(
                    edges.iter().copied(),
                    bodies,
                    count / 10,
                    batcher,
                    &mut coloring,
                );
                check_batches(&edges, &coloring);
            }
        }
    }

    /// The guarantees of the module docs, for any coloring of `edges`.
    fn check_batches(edges: &[(u32, u32)], coloring: &Coloring) {
        let batches = batches_of(coloring);
        assert_eq!(
            batches.iter().map(Vec::len).collect::<Vec<_>>(),
            coloring
                .histogram
                .iter()
                .map(|&n| n as usize)
                .collect::<Vec<_>>()
        );
        let mut seen = vec![false; edges.len()];
        for (batch, members) in batches.iter().enumerate() {
            assert!(!members.is_empty(), "batch {batch} is empty");
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

    #[test]
    fn a_body_with_more_than_64_constraints_overflows_into_a_sequential_batch() {
        // All 70 share body 0: one wins each round, and the 6 of lowest priority are left.
        let edges: Vec<(u32, u32)> = (1..=70).map(|other| (0, other)).collect();
        let mut by_priority: Vec<usize> = (0..70).collect();
        by_priority.sort_by_key(|&c| priority(c as u32, 0));
        let mut last_six = by_priority[64..].to_vec();
        last_six.sort_unstable();
        for batcher in Batcher::ALL {
            let mut coloring = Coloring::default();
            color_constraints(edges.iter().copied(), 71, 0, batcher, &mut coloring);
            assert!(coloring.has_overflow);
            assert_eq!(coloring.batch_count, 65);
            assert_eq!(coloring.histogram.iter().sum::<u32>(), 70);
            assert_eq!(batches_of(&coloring)[64], last_six);
            check_batches(&edges, &coloring);
        }
    }

    #[test]
    fn colors_need_fewer_batches_than_rounds() {
        let mut state = 0x1234_5678_9abc_def1;
        let edges = random_edges(&mut state, 20_000, 100_000);
        let batches = |batcher| {
            let mut coloring = Coloring::default();
            color_constraints(edges.iter().copied(), 20_000, 0, batcher, &mut coloring);
            coloring.batch_count
        };
        let (rounds, colors) = (batches(Batcher::Rounds), batches(Batcher::Colors));
        assert!(colors < rounds, "colors {colors}, rounds {rounds}");
    }

    #[test]
    fn batcher_names_round_trip() {
        for batcher in Batcher::ALL {
            assert_eq!(batcher.name().parse(), Ok(batcher));
            assert_ne!(batcher.next(), batcher);
        }
        assert!("greedy".parse::<Batcher>().is_err());
    }
}
