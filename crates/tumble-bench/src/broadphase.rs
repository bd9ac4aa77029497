//! `tumble bench broadphase`: the broadphases of [`tumble::stages::broadphase::alternatives`]
//! side by side, in the spirit of Bullet's CDTestFramework.
//!
//! ```text
//! tumble bench broadphase [--count 8192] [--moving 0.1] [--frames 100] [--threads 1]
//! ```
//!
//! `--count` boxes scattered in a cube, `--moving` of them moving along smooth paths every
//! frame ([`MovingBoxes`]). Each broadphase replays the same frames: the first frame (building
//! from nothing) is timed on its own, then each of `--frames` frames is one timed
//! [`PairFinder::update`] (the new AABBs in, the sorted pairs out). Reported: median, fastest
//! and slowest ms per update and the pairs of the last frame. Brute force runs only up to
//! [`BRUTE_FORCE_MAX`] boxes. The DBVT's pair search runs on a rayon pool of the first
//! `--threads` count (default 1, as the others are sequential).

use crate::BenchError;
use crate::args::BenchArgs;
use std::time::Instant;
use tumble::math::Aabb;
use tumble::profile::median;
use tumble::stages::broadphase::alternatives::scene::MovingBoxes;
use tumble::stages::broadphase::alternatives::{
    BruteForce, DbvtFinder, PairFinder, SweepAndPrune, UniformGrid,
};

/// Above this many boxes brute force (n²/2 tests a frame) is left out.
pub const BRUTE_FORCE_MAX: usize = 10_000;

/// The scene's seed: every run and every broadphase sees the same boxes.
const SEED: u64 = 0xcd7e57;

/// One row of the table.
struct Row {
    name: &'static str,
    build_ms: f64,
    median_ms: f64,
    min_ms: f64,
    max_ms: f64,
    pairs: usize,
}

pub fn run(args: &BenchArgs) -> Result<(), BenchError> {
    let scene = MovingBoxes::new(args.count, args.moving, SEED).map_err(|e| BenchError::Flag {
        flag: "moving",
        message: e.to_string(),
    })?;
    let threads = args.threads.first().copied().unwrap_or(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| BenchError::ThreadPool {
            threads,
            message: e.to_string(),
        })?;
    let mut finders: Vec<Box<dyn PairFinder + Send>> = vec![
        Box::new(DbvtFinder::fat()),
        Box::new(DbvtFinder::exact()),
        Box::new(UniformGrid::new(None)),
        Box::new(SweepAndPrune::new()),
    ];
    if args.count <= BRUTE_FORCE_MAX {
        finders.push(Box::new(BruteForce));
    }
    println!(
        "# broadphase: {} boxes, {} moving per frame, {} frames, {threads} thread(s)",
        args.count,
        scene.moving(),
        args.frames
    );
    println!(
        "{:12} {:>10} {:>12} {:>10} {:>10} {:>10}",
        "broadphase", "build ms", "ms/update", "min ms", "max ms", "pairs"
    );
    for finder in &mut finders {
        let row = pool.install(|| measure(finder.as_mut(), scene.clone(), args.frames))?;
        println!(
            "{:12} {:>10.3} {:>12.3} {:>10.3} {:>10.3} {:>10}",
            row.name, row.build_ms, row.median_ms, row.min_ms, row.max_ms, row.pairs
        );
    }
    if args.count > BRUTE_FORCE_MAX {
        println!("(brute force left out above {BRUTE_FORCE_MAX} boxes)");
    }
    println!("dbvt: the step's fat margins (a superset of the pairs); the others: exact overlaps");
    Ok(())
}

fn measure(
    finder: &mut dyn PairFinder,
    mut scene: MovingBoxes,
    frames: usize,
) -> Result<Row, BenchError> {
    let mut aabbs: Vec<Aabb> = Vec::new();
    let mut pairs = Vec::new();
    let mut update = |finder: &mut dyn PairFinder, aabbs: &[Aabb]| {
        let start = Instant::now();
        finder.update(aabbs, &mut pairs)?;
        Ok::<f64, BenchError>(start.elapsed().as_secs_f64() * 1e3)
    };
    scene.aabbs(&mut aabbs);
    let build_ms = update(finder, &aabbs)?;
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        scene.advance();
        scene.aabbs(&mut aabbs);
        times.push(update(finder, &aabbs)?);
    }
    let fold = |init: f64, pick: fn(f64, f64) -> f64| times.iter().copied().fold(init, pick);
    Ok(Row {
        name: finder.name(),
        build_ms,
        median_ms: median(&times),
        min_ms: fold(f64::INFINITY, f64::min),
        max_ms: fold(0.0, f64::max),
        pairs: pairs.len(),
    })
}
