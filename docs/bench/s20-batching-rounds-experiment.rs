//! Session 20's experiment, kept as text: the rounds and colors of the colors batcher (JP,
//! checked against `color_constraints`) against a speculative batcher, on a scene's constraint
//! graph after one CPU step. The speculative batcher: each round every constraint left takes
//! the lowest color free on both its bodies (from the masks at the round's start) and claims
//! lock slot (body, color % k) with its priority; it wins when it holds both slots. k = 1 is
//! JP. To run: copy to crates/tumble/examples/, then
//! `cargo run --release -p tumble --example batching_rounds -- <scene or dump>`.
use std::path::Path;
use tumble::scene::Scene;
use tumble::stages::batching::{Batcher, Coloring, color_constraints, priority};

const NONE: u32 = u32::MAX;

fn jp(pairs: &[[u32; 2]], bodies: usize) -> (Vec<usize>, Vec<u32>) {
    let n = pairs.len();
    let mut colors = vec![NONE; n];
    let mut masks = vec![0u64; bodies];
    let mut locks = vec![u32::MAX; bodies];
    let mut remaining: Vec<u32> = (0..n as u32).collect();
    let mut left = Vec::new();
    while !remaining.is_empty() && left.len() < 64 {
        left.push(remaining.len());
        for &c in &remaining {
            for &b in &pairs[c as usize] {
                if b != NONE {
                    locks[b as usize] = locks[b as usize].min(priority(c, 0));
                }
            }
        }
        for &c in &remaining {
            let p = pairs[c as usize];
            if p.iter().all(|&b| b == NONE || locks[b as usize] == priority(c, 0)) {
                let used = p.iter().filter(|&&b| b != NONE).fold(0, |u, &b| u | masks[b as usize]);
                let t = (!used).trailing_zeros();
                for &b in &p {
                    if b != NONE {
                        masks[b as usize] |= 1 << t;
                    }
                }
                colors[c as usize] = t;
            }
        }
        for &c in &remaining {
            for &b in &pairs[c as usize] {
                if b != NONE {
                    locks[b as usize] = u32::MAX;
                }
            }
        }
        remaining.retain(|&c| colors[c as usize] == NONE);
    }
    (left, colors)
}

fn speculative(pairs: &[[u32; 2]], bodies: usize, k: usize) -> (Vec<usize>, Vec<u32>) {
    let n = pairs.len();
    let mut colors = vec![NONE; n];
    let mut tentative = vec![0u32; n];
    let mut masks = vec![0u64; bodies];
    let mut locks = vec![u32::MAX; bodies * k];
    let mut remaining: Vec<u32> = (0..n as u32).collect();
    let mut left = Vec::new();
    while !remaining.is_empty() && left.len() < 64 {
        left.push(remaining.len());
        for &c in &remaining {
            let p = pairs[c as usize];
            let used = p.iter().filter(|&&b| b != NONE).fold(0, |u, &b| u | masks[b as usize]);
            let t = (!used).trailing_zeros();
            tentative[c as usize] = t;
            for &b in &p {
                if b != NONE {
                    let slot = b as usize * k + t as usize % k;
                    locks[slot] = locks[slot].min(priority(c, 0));
                }
            }
        }
        for &c in &remaining {
            let p = pairs[c as usize];
            let t = tentative[c as usize];
            let won = p.iter().all(|&b| {
                b == NONE || locks[b as usize * k + t as usize % k] == priority(c, 0)
            });
            if won {
                for &b in &p {
                    if b != NONE {
                        masks[b as usize] |= 1 << t;
                    }
                }
                colors[c as usize] = t;
            }
        }
        for &c in &remaining {
            let t = tentative[c as usize];
            for &b in &pairs[c as usize] {
                if b != NONE {
                    locks[b as usize * k + t as usize % k] = u32::MAX;
                }
            }
        }
        remaining.retain(|&c| colors[c as usize] == NONE);
    }
    (left, colors)
}

fn histogram(colors: &[u32]) -> Vec<usize> {
    let top = colors.iter().copied().filter(|&c| c != NONE).max().unwrap_or(0) as usize;
    let mut h = vec![0; top + 1];
    for &c in colors {
        if c != NONE {
            h[c as usize] += 1;
        }
    }
    h
}

fn valid(pairs: &[[u32; 2]], colors: &[u32], bodies: usize) -> bool {
    let mut seen = vec![0u64; bodies];
    for (p, &c) in pairs.iter().zip(colors) {
        for &b in p {
            if b != NONE {
                if seen[b as usize] & (1 << c) != 0 {
                    return false;
                }
                seen[b as usize] |= 1 << c;
            }
        }
    }
    true
}

fn main() {
    let path = std::env::args().nth(1).expect("a scene file");
    let file = Scene::load(Path::new(&path)).expect("scene");
    let statics: Vec<bool> = file.bodies.iter().map(|b| b.is_static()).collect();
    let mut world = file.build().expect("world");
    world.step();
    let pairs: Vec<[u32; 2]> = world
        .contacts()
        .map(|(a, b, _)| {
            let body = |h: tumble::BodyHandle| {
                if statics[h.index() as usize] { NONE } else { h.index() }
            };
            [body(a), body(b)]
        })
        .collect();
    let bodies = statics.len();
    println!("{} bodies, {} constraints", bodies, pairs.len());
    let mut lib = Coloring::default();
    color_constraints(pairs.iter().map(|p| (p[0], p[1])), bodies, 0, Batcher::Colors, &mut lib);
    let (left, colors) = jp(&pairs, bodies);
    assert_eq!(colors.iter().map(|&c| c as u8).collect::<Vec<_>>(), lib.colors, "JP twin");
    println!("JP: {} rounds, {} colors {:?}", left.len(), histogram(&colors).len(), histogram(&colors));
    println!("  left at each round's start: {left:?}");
    for k in [1, 4, 8, 16, 64] {
        let (left, colors) = speculative(&pairs, bodies, k);
        assert!(valid(&pairs, &colors, bodies));
        println!("speculative k={k}: {} rounds, {} colors {:?}", left.len(), histogram(&colors).len(), histogram(&colors));
        println!("  left: {left:?}");
    }
}
