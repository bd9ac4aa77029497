//! `tumble bench`: scenes timed side by side on Tumble and on peer engines, at several sizes and
//! thread counts, with quality figures, written as a table, a CSV file and a PNG chart.
//!
//! ```text
//! tumble bench falling-boxes --bodies 1000,3000,10000 --engines tumble-cpu,rapier --threads 1,16 \
//!     --warmup 30 --steps 100 --time-limit-ms 1000 --csv out.csv --png out.png
//! ```
//!
//! A *case* is one scene at one scale on one engine with one thread count: it builds the scene,
//! runs `--warmup` steps, then `--steps` timed steps, each timed alone with a wall clock around
//! the engine's step call. A *column* is one scene on one engine with one thread count across
//! the scales, smallest first: when a step of a case takes longer than `--time-limit-ms`, that
//! case ends there (status `time-limit`, its figures from the steps it ran) and the larger scales
//! of its column are `skipped`. The first step, which builds the engines' acceleration
//! structures from nothing, is exempt.
//!
//! Engines (`--engines`), each an engine on a device:
//! - `tumble-cpu`: Tumble's CPU step on a rayon pool of `--threads` threads;
//! - `tumble-gpu`: Tumble with every stage on the GPU (`StageDevices::all(Executor::Gpu)`),
//!   each stage's inputs uploaded and outputs read back around it for now;
//! - `rapier`: rapier3d 0.36 with Tumble's solver settings — the same sub-steps, sweeps and
//!   contact and joint softness (see [`rapier`] for the translation, joints included; a scene
//!   using what rapier lacks, a breakable joint, is reported `unsupported`);
//! - `rapier-default`: rapier3d with its own default solver settings.
//!
//! Both engines run their step inside a rayon pool of `--threads` threads: Tumble's stages use
//! the pool they are called from, and rapier 0.36 (feature `parallel`) runs on the pool of the
//! calling thread unless it was given one.
//!
//! # Quality figures
//!
//! - `max_penetration_m`: the deepest overlap of any contact point over the timed steps (m).
//! - drift, over the dynamic bodies, at the end of the run: for scenes that start at rest and
//!   should stay so (`stacked-boxes`), the displacement from the start position (m); for the
//!   others (`falling-boxes`, scene files), which should come to rest, the linear speed (m/s).
//!   `drift_kind` says which.
//! - `kinetic_energy_j`: ½mv² + ½ω·Iω summed over the bodies at the end (J).
//! - `pairs`: broadphase candidate pairs (Tumble: fat AABBs overlap; rapier: pairs in its
//!   narrowphase graph); `contacts`: contact points, speculative ones within the contact margin
//!   included, after the last step.
//!
//! # CSV columns
//!
//! One row per case, in this order ([`report::CSV_COLUMNS`]; BENCHMARKS.md has the same list):
//!
//! | column | meaning |
//! |---|---|
//! | `scene` | built-in name or scene file |
//! | `scale` | the scene's size parameter (1 = the talk's size) |
//! | `bodies` | dynamic bodies |
//! | `engine` | `tumble-cpu`, `tumble-gpu`, `rapier`, `rapier-default` |
//! | `threads` | rayon threads the step ran on |
//! | `status` | `ok`, `time-limit`, `skipped`, `not available: <why>`, `unsupported: <why>` |
//! | `warmup_steps` | warm-up steps run |
//! | `timed_steps` | timed steps run |
//! | `ms_median` | median wall time of a timed step (ms) |
//! | `ms_p10`, `ms_p90` | 10th and 90th percentiles (nearest rank) of the step time (ms) |
//! | `ms_min`, `ms_max` | fastest and slowest timed step (ms) |
//! | `stage_ms` | mean ms per step of each stage, `name=ms` joined by `;`, in step order |
//! | `max_penetration_m` | deepest contact overlap over the timed steps (m) |
//! | `drift_kind` | `displacement_m` or `speed_m_per_s` |
//! | `drift_mean`, `drift_max` | mean and max drift over the dynamic bodies |
//! | `kinetic_energy_j` | kinetic energy at the end (J) |
//! | `pairs` | broadphase pairs after the last step |
//! | `contacts` | contact points after the last step |
//! | `dt` | time step (s) |
//! | `solver_iterations` | the scene's velocity iterations per sub-step |
//! | `substeps` | the scene's sub-steps per step |
//! | `solver` | Tumble's solver, `pgs` or `jacobi` (`--solver`); empty for the peers |
//!
//! Figures a case did not produce (skipped, not available, unsupported) are empty cells.

pub mod args;
pub mod broadphase;
pub mod chart;
pub mod engine;
pub mod measure;
pub mod prims;
pub mod rapier;
pub mod report;
pub mod sweep;

pub use args::BenchArgs;

/// `tumble bench`: `prims` runs the GPU primitive benchmarks ([`prims`]), `broadphase` the
/// broadphase comparison ([`broadphase`]); anything else is a list of scenes to sweep
/// ([`sweep::run`]).
pub fn run(args: &BenchArgs) -> Result<(), BenchError> {
    if args.scenes.len() == 1 && args.scenes[0] == "broadphase" {
        return broadphase::run(args);
    }
    if args.scenes.len() == 1 && args.scenes[0] == "prims" {
        let scale = args.scales.first().copied().unwrap_or(1.0);
        return prims::run(scale as f64).map_err(BenchError::Gpu);
    }
    sweep::run(args)
}

/// Why a benchmark could not run. Messages say what was wrong and how to fix it.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Scene(#[from] tumble::scene::SceneError),
    #[error("--{flag}: {message}")]
    Flag { flag: &'static str, message: String },
    #[error("cannot start a pool of {threads} threads: {message}")]
    ThreadPool { threads: usize, message: String },
    #[error("cannot write {path}: {message}")]
    Write { path: String, message: String },
    #[error("broadphase benchmark: {0}")]
    Broadphase(#[from] tumble::stages::broadphase::alternatives::AabbError),
    #[error("GPU benchmark: {0}")]
    Gpu(String),
}
