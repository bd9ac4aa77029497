//! The flags of `tumble bench`. Parsing rejects bad values with a message that names the flag;
//! [`BenchArgs::threads`] and the sweep resolve what is left (defaults, scene sizes).

use crate::engine::EngineKind;
use clap::builder::RangedU64ValueParser;
use std::path::PathBuf;
use tumble::stages::solver::SolverKind;

/// `tumble bench <scene...> [flags]`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Built-in scene names (`tumble scenes`) or JSON scene files, run one after the other.
    #[arg(required = true)]
    pub scenes: Vec<String>,
    /// Sizes of the built-in scenes (1 = the talk's size), e.g. `0.1,1,10`. Default: 1.
    #[arg(long, value_delimiter = ',', value_parser = parse_scale, conflicts_with = "bodies")]
    pub scales: Vec<f32>,
    /// Sizes given as dynamic body counts instead, e.g. `1000,3000,10000`: the scale of each is
    /// the count over the scene's count at scale 1 (3008 for falling-boxes).
    #[arg(long, value_delimiter = ',', value_parser = RangedU64ValueParser::<usize>::new().range(1..))]
    pub bodies: Vec<usize>,
    /// Engines (an engine on a device) to run each case on.
    #[arg(
        long,
        value_delimiter = ',',
        value_enum,
        default_value = "tumble-cpu,rapier"
    )]
    pub engines: Vec<EngineKind>,
    /// Rayon thread counts to run each case with, e.g. `1,16`. Default: 1 and all cores.
    #[arg(long, value_delimiter = ',', value_parser = parse_threads)]
    pub threads: Vec<usize>,
    /// Tumble's solver: `pgs` (batched projected Gauss-Seidel) or `jacobi` (the comparison);
    /// peers keep their own.
    #[arg(long, default_value = "pgs", value_parser = parse_solver)]
    pub solver: SolverKind,
    /// Velocity iterations per sub-step instead of each scene's own, for every engine (Jacobi
    /// needs more than PGS for the same error).
    #[arg(long, value_parser = RangedU64ValueParser::<u32>::new().range(1..))]
    pub iterations: Option<u32>,
    /// Untimed steps before the timed ones (caches, pair lists and warm starts fill up).
    #[arg(long, default_value_t = 30)]
    pub warmup: usize,
    /// Timed steps per case.
    #[arg(long, default_value_t = 100, value_parser = RangedU64ValueParser::<usize>::new().range(1..))]
    pub steps: usize,
    /// A step slower than this (ms) ends its case and skips the larger scales of its column.
    #[arg(long, default_value_t = 1000.0, value_parser = parse_time_limit)]
    pub time_limit_ms: f64,
    /// Write one row per case to this CSV file (columns: see BENCHMARKS.md).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Draw ms/step against body count (log-log), one line per engine and thread count.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// `broadphase` only: boxes in the scene.
    #[arg(long, default_value_t = 8192, value_parser = RangedU64ValueParser::<usize>::new().range(1..))]
    pub count: usize,
    /// `broadphase` only: fraction of the boxes (0..=1) that move each frame.
    #[arg(long, default_value_t = 0.1, value_parser = parse_fraction)]
    pub moving: f32,
    /// `broadphase` only: timed frames per broadphase.
    #[arg(long, default_value_t = 100, value_parser = RangedU64ValueParser::<usize>::new().range(1..))]
    pub frames: usize,
}

impl BenchArgs {
    /// Arguments for `scenes` with every flag at its default, as the command line would give.
    pub fn new(scenes: &[&str]) -> Self {
        Self {
            scenes: scenes.iter().map(|s| s.to_string()).collect(),
            scales: Vec::new(),
            bodies: Vec::new(),
            engines: vec![EngineKind::TumbleCpu, EngineKind::Rapier],
            threads: Vec::new(),
            solver: SolverKind::Pgs,
            iterations: None,
            warmup: 30,
            steps: 100,
            time_limit_ms: 1000.0,
            csv: None,
            png: None,
            count: 8192,
            moving: 0.1,
            frames: 100,
        }
    }

    /// The thread counts to run, in the order given, without repeats; by default 1 and every
    /// core the machine has.
    pub fn threads(&self) -> Vec<usize> {
        let mut threads = if self.threads.is_empty() {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            vec![1, cores]
        } else {
            self.threads.clone()
        };
        let mut seen = std::collections::HashSet::new();
        threads.retain(|t| seen.insert(*t));
        threads
    }
}

fn parse_scale(text: &str) -> Result<f32, String> {
    match text.trim().parse::<f32>() {
        Ok(scale) if scale.is_finite() && scale > 0.0 => Ok(scale),
        Ok(scale) => Err(format!("a scale must be a positive number, got {scale}")),
        Err(_) => Err(format!("{text:?} is not a number (e.g. 0.1,1,10)")),
    }
}

fn parse_solver(text: &str) -> Result<SolverKind, String> {
    text.trim()
        .parse()
        .map_err(|e: tumble::stages::solver::UnknownSolver| e.to_string())
}

fn parse_fraction(text: &str) -> Result<f32, String> {
    match text.trim().parse::<f32>() {
        Ok(fraction) if (0.0..=1.0).contains(&fraction) => Ok(fraction),
        Ok(fraction) => Err(format!("a fraction is in 0..=1, got {fraction}")),
        Err(_) => Err(format!("{text:?} is not a number (e.g. 0.1)")),
    }
}

fn parse_threads(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(threads) if threads >= 1 => Ok(threads),
        _ => Err(format!(
            "a thread count is a whole number of at least 1, got {text:?}"
        )),
    }
}

fn parse_time_limit(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(ms) if ms.is_finite() && ms > 0.0 => Ok(ms),
        Ok(ms) => Err(format!(
            "the time limit must be a positive number of ms, got {ms}"
        )),
        Err(_) => Err(format!("{text:?} is not a number of milliseconds")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Command {
        #[command(flatten)]
        bench: BenchArgs,
    }

    fn parse(line: &[&str]) -> Result<BenchArgs, String> {
        Command::try_parse_from(std::iter::once("bench").chain(line.iter().copied()))
            .map(|command| command.bench)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn good_flags_parse() {
        let args = parse(&[
            "falling-boxes",
            "stacked-boxes",
            "--scales",
            "0.1,1,10",
            "--engines",
            "tumble,rapier,tumble-gpu",
            "--threads",
            "1,16,1",
            "--warmup",
            "0",
            "--steps",
            "5",
            "--time-limit-ms",
            "0.5",
        ])
        .unwrap();
        assert_eq!(args.scenes, ["falling-boxes", "stacked-boxes"]);
        assert_eq!(args.scales, [0.1, 1.0, 10.0]);
        assert_eq!(
            args.engines,
            [
                EngineKind::TumbleCpu,
                EngineKind::Rapier,
                EngineKind::TumbleGpu
            ]
        );
        assert_eq!(args.threads(), [1, 16]);
        assert_eq!((args.warmup, args.steps, args.time_limit_ms), (0, 5, 0.5));
        let defaults = parse(&["falling-boxes"]).unwrap();
        assert_eq!(defaults.engines, BenchArgs::new(&["falling-boxes"]).engines);
        assert_eq!(defaults.threads()[0], 1);
        assert_eq!(
            (defaults.solver, defaults.iterations),
            (SolverKind::Pgs, None)
        );
        let jacobi = parse(&["stacked-boxes", "--solver", "jacobi", "--iterations", "4"]).unwrap();
        assert_eq!(
            (jacobi.solver, jacobi.iterations),
            (SolverKind::Jacobi, Some(4))
        );
    }

    #[test]
    fn bad_flags_say_what_is_wrong() {
        let cases: &[(&[&str], &str)] = &[
            (&["falling-boxes", "--threads", "0"], "at least 1"),
            (
                &["falling-boxes", "--threads", "1,x"],
                "at least 1, got \"x\"",
            ),
            (&["falling-boxes", "--engines", "bullet"], "bullet"),
            (&["falling-boxes", "--scales", "1,-2"], "positive"),
            (&["falling-boxes", "--scales", "big"], "not a number"),
            (
                &["falling-boxes", "--scales", "1", "--bodies", "10"],
                "--bodies",
            ),
            (&["falling-boxes", "--steps", "0"], "--steps"),
            (
                &["falling-boxes", "--solver", "sor"],
                "solvers are pgs, jacobi",
            ),
            (&["falling-boxes", "--iterations", "0"], "--iterations"),
            (&["falling-boxes", "--time-limit-ms", "0"], "positive"),
            (&["falling-boxes", "--warmup", "many"], "--warmup"),
            (&["broadphase", "--moving", "1.5"], "0..=1"),
            (&["broadphase", "--count", "0"], "--count"),
            (&["broadphase", "--frames", "0"], "--frames"),
            (&[], "<SCENES>"),
        ];
        for (line, expected) in cases {
            let error = parse(line).expect_err(&format!("{line:?} should be refused"));
            assert!(
                error.contains(expected),
                "{line:?}: {expected:?} not in {error}"
            );
        }
    }
}
