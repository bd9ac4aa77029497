//! Session 30's experiment, kept as text: what the colors batcher would do if each contact kept
//! last step's color (Box2D v3's persistent constraint graph). Each step of a CPU world, the
//! contacts with points are colored twice: afresh (`color_constraints`, what the engine does)
//! and with hints: a contact whose pair had a constraint last step on the same bodies (the same
//! static sides) keeps that color, and the rounds color the rest around them. Prints, per
//! window of steps, the rounds each needs, the colors, and how many contacts kept a color.
//! LIMIT keeps hints only below that color; every PERIOD steps none is kept (a fresh coloring).
//! To run: copy to crates/tumble/examples/persistent_colors.rs, then `cargo run --release -p
//! tumble --example persistent_colors -- SCENE SCALE STEPS WINDOW [LIMIT [PERIOD]]`. Output of
//! session 30's runs: s30-persistent-colors.txt.
use std::collections::HashMap;
use tumble::scene::builtin;
use tumble::stages::batching::{Batcher, Coloring, LOCK_SLOTS, MAX_COLORS, color_constraints, priority};
use tumble::stages::constraints::STATIC_BODY;
use tumble::stages::pairs::pair_key;

const UNBATCHED: u8 = u8::MAX;
const OVERFLOW: u8 = MAX_COLORS as u8;

/// The colors batcher's rounds (`color_constraints`, one slot a color modulo LOCK_SLOTS, no
/// joints) from `colors` where hinted, the masks holding the hinted colors. Returns the rounds.
fn color_with_hints(pairs: &[[u32; 2]], bodies: usize, colors: &mut [u8]) -> usize {
    let dynamic = |p: [u32; 2]| p.into_iter().filter(|&b| b != STATIC_BODY);
    let mut masks = vec![0u64; bodies];
    for (c, &p) in pairs.iter().enumerate() {
        if colors[c] != UNBATCHED {
            for b in dynamic(p) {
                assert_eq!(masks[b as usize] & (1 << colors[c]), 0, "hints conflict");
                masks[b as usize] |= 1 << colors[c];
            }
        }
    }
    let mut locks = vec![u32::MAX; bodies * LOCK_SLOTS];
    let mut tentative = vec![0u8; pairs.len()];
    let mut remaining: Vec<u32> = (0..pairs.len() as u32).filter(|&c| colors[c as usize] == UNBATCHED).collect();
    let lock = |b: u32, color: u8| b as usize * LOCK_SLOTS + color as usize % LOCK_SLOTS;
    let mut rounds = 0;
    while !remaining.is_empty() && rounds < MAX_COLORS {
        rounds += 1;
        for &c in &remaining {
            let p = pairs[c as usize];
            let used = dynamic(p).fold(0, |u, b| u | masks[b as usize]);
            let color = if used == u64::MAX { OVERFLOW } else { (!used).trailing_zeros() as u8 };
            tentative[c as usize] = color;
            for b in dynamic(p) {
                let slot = &mut locks[lock(b, color)];
                *slot = (*slot).min(priority(c, 0));
            }
        }
        for &c in &remaining {
            let (p, color) = (pairs[c as usize], tentative[c as usize]);
            if dynamic(p).all(|b| locks[lock(b, color)] == priority(c, 0)) {
                if color != OVERFLOW {
                    for b in dynamic(p) {
                        masks[b as usize] |= 1 << color;
                    }
                }
                colors[c as usize] = color;
            }
        }
        for &c in &remaining {
            for b in dynamic(pairs[c as usize]) {
                locks[b as usize * LOCK_SLOTS..(b as usize + 1) * LOCK_SLOTS].fill(u32::MAX);
            }
        }
        remaining.retain(|&c| colors[c as usize] == UNBATCHED);
    }
    for &c in &remaining {
        colors[c as usize] = OVERFLOW;
    }
    rounds
}

fn histogram(colors: &[u8]) -> Vec<u32> {
    let mut counts = vec![0u32; MAX_COLORS + 1];
    for &c in colors {
        counts[c as usize] += 1;
    }
    let used = counts.iter().rposition(|&n| n > 0).map_or(0, |c| c + 1);
    counts.truncate(used);
    counts
}

fn valid(pairs: &[[u32; 2]], colors: &[u8], bodies: usize) -> bool {
    let mut masks = vec![0u64; bodies];
    pairs.iter().zip(colors).all(|(p, &c)| {
        c == OVERFLOW
            || p.iter().filter(|&&b| b != STATIC_BODY).all(|&b| {
                let free = masks[b as usize] & (1 << c) == 0;
                masks[b as usize] |= 1 << c;
                free
            })
    })
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = args.get(1).map_or("falling-boxes", String::as_str);
    let scale: f32 = args.get(2).map_or(1.0, |s| s.parse().unwrap());
    let steps: usize = args.get(3).map_or(300, |s| s.parse().unwrap());
    let window: usize = args.get(4).map_or(20, |s| s.parse().unwrap());
    // Hints only for colors below `limit`; every `period` steps, none (a fresh coloring).
    let limit: u8 = args.get(5).map_or(OVERFLOW, |s| s.parse().unwrap());
    let period: usize = args.get(6).map_or(usize::MAX, |s| s.parse().unwrap());
    let mut world = builtin(scene, scale).unwrap().build().unwrap();
    println!("{scene} at scale {scale}: hints below color {limit}, none every {period} steps");
    let handles: Vec<_> = world.bodies().collect();
    let bodies = handles.len();
    let mut last: HashMap<u64, ([u32; 2], u8)> = HashMap::new();
    let mut coloring = Coloring::default();
    let (mut fresh_rounds, mut kept_rounds, mut kept, mut total) = (0, 0, 0, 0);
    let (mut fresh_max, mut kept_max) = (0, 0);
    for step in 1..=steps {
        world.step();
        let marked = |h: tumble::BodyHandle| {
            if world.is_dynamic(h).unwrap() && !world.is_sleeping(h).unwrap() { h.index() } else { STATIC_BODY }
        };
        let mut keys = Vec::new();
        let mut pairs = Vec::new();
        for (a, b, _) in world.contacts() {
            let p = [marked(a), marked(b)];
            if p == [STATIC_BODY, STATIC_BODY] {
                continue;
            }
            keys.push(pair_key(a.index(), b.index()));
            pairs.push(p);
        }
        color_constraints(pairs.iter().map(|p| (p[0], p[1])), bodies, 0, Batcher::Colors, &mut coloring);
        let mut colors: Vec<u8> = keys
            .iter()
            .zip(&pairs)
            .map(|(k, p)| match last.get(k) {
                Some(&(q, color)) if q == *p && color < limit && step % period != 0 => color,
                _ => UNBATCHED,
            })
            .collect();
        let hinted = colors.iter().filter(|&&c| c != UNBATCHED).count();
        let rounds = color_with_hints(&pairs, bodies, &mut colors);
        assert!(valid(&pairs, &colors, bodies), "step {step}: a conflict");
        let kept_hist = histogram(&colors);
        last = keys.iter().zip(&pairs).zip(&colors).map(|((&k, &p), &c)| (k, (p, c))).collect();
        fresh_rounds += coloring.rounds;
        kept_rounds += rounds;
        kept += hinted;
        total += pairs.len();
        fresh_max = fresh_max.max(coloring.histogram.len());
        kept_max = kept_max.max(kept_hist.len());
        if step % window == 0 {
            let gaps = kept_hist.iter().filter(|&&n| n == 0).count();
            println!(
                "steps {:4}-{:4}: {:6} contacts, kept {:5.1}%; rounds a step fresh {:5.2}, kept {:5.2}; \
                 colors fresh {:2} (max {:2}), kept {:2} (max {:2}, {} empty)\n  fresh {:?}\n  kept  {:?}",
                step + 1 - window,
                step,
                pairs.len(),
                100.0 * kept as f64 / total.max(1) as f64,
                fresh_rounds as f64 / window as f64,
                kept_rounds as f64 / window as f64,
                coloring.histogram.len(),
                fresh_max,
                kept_hist.len(),
                kept_max,
                gaps,
                coloring.histogram,
                kept_hist,
            );
            (fresh_rounds, kept_rounds, kept, total, fresh_max, kept_max) = (0, 0, 0, 0, 0, 0);
        }
    }
}
