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
//!
//! Where there is a GPU, the step's GPU broadphase (linear BVH rebuilt every frame, the talk's
//! history-flag traversal or the stackless rope walk, pairs sorted) runs the same frames with
//! every box in its moving tree, so it finds the exact set too. Its rows time a whole round
//! trip (upload the AABBs, build, traverse, sort, read the keys back), as a CPU step that runs
//! only its broadphase on the GPU pays; a second table gives the GPU time alone of the build
//! and of the traversal and sort, [`GPU_REPEATS`] updates encoded in one submission.

use crate::BenchError;
use crate::args::BenchArgs;
use std::time::Instant;
use tumble::gpu::{GpuContext, GpuError, GpuVec};
use tumble::math::Aabb;
use tumble::profile::median;
use tumble::stages::broadphase::alternatives::scene::MovingBoxes;
use tumble::stages::broadphase::alternatives::{
    BruteForce, DbvtFinder, PairFinder, SweepAndPrune, UniformGrid,
};
use tumble::stages::broadphase::gpu::{GpuBroadphase, Traversal};

/// Above this many boxes brute force (n²/2 tests a frame) is left out.
pub const BRUTE_FORCE_MAX: usize = 10_000;

/// The scene's seed: every run and every broadphase sees the same boxes.
const SEED: u64 = 0xcd7e57;

/// Updates per submission when the GPU stages are timed alone.
const GPU_REPEATS: usize = 20;

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
    let print = |row: Row| {
        println!(
            "{:12} {:>10.3} {:>12.3} {:>10.3} {:>10.3} {:>10}",
            row.name, row.build_ms, row.median_ms, row.min_ms, row.max_ms, row.pairs
        );
    };
    for finder in &mut finders {
        let name = finder.name();
        let update = |aabbs: &[Aabb], pairs: &mut Vec<u64>| Ok(finder.update(aabbs, pairs)?);
        print(pool.install(|| measure(name, update, scene.clone(), args.frames))?);
    }
    let gpu = GpuContext::shared().ok();
    let traversals = [
        ("lbvh-history", Traversal::HistoryFlags),
        ("lbvh-ropes", Traversal::Ropes),
    ];
    if let Some(context) = &gpu {
        for (name, traversal) in traversals {
            let mut broadphase = GpuBroadphase::new(context).map_err(gpu_error)?;
            broadphase.set_traversal(traversal);
            let update = |aabbs: &[Aabb], pairs: &mut Vec<u64>| {
                let moving = vec![false; aabbs.len()];
                *pairs = broadphase
                    .find_pairs(context, aabbs, &moving)
                    .map_err(gpu_error)?;
                Ok(())
            };
            print(measure(name, update, scene.clone(), args.frames)?);
        }
    }
    if args.count > BRUTE_FORCE_MAX {
        println!("(brute force left out above {BRUTE_FORCE_MAX} boxes)");
    }
    println!("dbvt: the step's fat margins (a superset of the pairs); the others: exact overlaps");
    match &gpu {
        Some(context) => {
            println!(
                "# GPU time alone on {} (last frame, {GPU_REPEATS} updates a submission)",
                context.describe()
            );
            println!(
                "{:12} {:>10} {:>16}",
                "traversal", "build ms", "traverse+sort ms"
            );
            let mut aabbs = Vec::new();
            let mut last = scene.clone();
            for _ in 0..args.frames {
                last.advance();
            }
            last.aabbs(&mut aabbs);
            for (name, traversal) in traversals {
                let (build, pairs) = gpu_stage_ms(context, &aabbs, traversal).map_err(gpu_error)?;
                println!("{name:12} {build:>10.3} {pairs:>16.3}");
            }
        }
        None => println!("(no GPU adapter: the GPU broadphase left out)"),
    }
    Ok(())
}

fn gpu_error(error: GpuError) -> BenchError {
    BenchError::Gpu(error.to_string())
}

/// Median ms of the GPU broadphase's tree build and of its traversal and sort on `aabbs`,
/// each encoded [`GPU_REPEATS`] times per submission (after a run that sizes the buffers).
fn gpu_stage_ms(
    context: &GpuContext,
    aabbs: &[Aabb],
    traversal: Traversal,
) -> Result<(f64, f64), GpuError> {
    let mut broadphase = GpuBroadphase::new(context)?;
    broadphase.set_traversal(traversal);
    let moving = vec![false; aabbs.len()];
    broadphase.find_pairs(context, aabbs, &moving)?;
    let uploaded = GpuVec::from_slice(context, "bench aabbs", aabbs)?;
    let time = |stage: &mut dyn FnMut(&mut wgpu::ComputePass<'_>) -> Result<(), GpuError>| {
        let mut samples = Vec::new();
        for _ in 0..8 {
            let start = Instant::now();
            context.submit_pass("bench broadphase", |pass| {
                (0..GPU_REPEATS).try_for_each(|_| stage(pass))
            })?;
            context.wait()?;
            samples.push(start.elapsed().as_secs_f64() * 1e3 / GPU_REPEATS as f64);
        }
        // The first submission compiles and grows: left out.
        Ok::<f64, GpuError>(median(&samples[1..]))
    };
    let build = time(&mut |pass| broadphase.encode_trees(context, pass, &uploaded))?;
    let pairs = time(&mut |pass| broadphase.encode_pairs(context, pass))?;
    Ok((build, pairs))
}

/// Times `update` (this frame's AABBs in, the sorted pairs out) over the scene's frames.
fn measure(
    name: &'static str,
    mut update: impl FnMut(&[Aabb], &mut Vec<u64>) -> Result<(), BenchError>,
    mut scene: MovingBoxes,
    frames: usize,
) -> Result<Row, BenchError> {
    let mut aabbs: Vec<Aabb> = Vec::new();
    let mut pairs = Vec::new();
    let mut timed = |aabbs: &[Aabb]| {
        let start = Instant::now();
        update(aabbs, &mut pairs)?;
        Ok::<f64, BenchError>(start.elapsed().as_secs_f64() * 1e3)
    };
    scene.aabbs(&mut aabbs);
    let build_ms = timed(&aabbs)?;
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        scene.advance();
        scene.aabbs(&mut aabbs);
        times.push(timed(&aabbs)?);
    }
    let fold = |init: f64, pick: fn(f64, f64) -> f64| times.iter().copied().fold(init, pick);
    Ok(Row {
        name,
        build_ms,
        median_ms: median(&times),
        min_ms: fold(f64::INFINITY, f64::min),
        max_ms: fold(0.0, f64::max),
        pairs: pairs.len(),
    })
}
