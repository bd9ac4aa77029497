//! The sweep: every scene × scale × engine × thread count, smallest scale first, a column
//! stopped at the first step over the time limit. Rows stream to stdout and to the CSV as
//! cases finish, so a run cut short still leaves its results behind.

use crate::args::BenchArgs;
use crate::engine::EngineKind;
use crate::measure::{CaseKey, CaseResult, Schedule, Status, run_case};
use crate::{BenchError, chart, report};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::HashSet;
use std::path::Path;
use tumble::scene::{Scene, builtin};

/// Runs `tumble bench`: the table on stdout, then the CSV and PNG files asked for.
pub fn run(args: &BenchArgs) -> Result<(), BenchError> {
    // Unwritable output paths are found now, not after a long run: the CSV starts as its
    // header; the chart's folder must exist.
    if let Some(path) = &args.csv {
        report::write_csv(path, &[])?;
    }
    if let Some(path) = &args.png {
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
        if folder.is_some_and(|folder| !folder.is_dir()) {
            return Err(BenchError::Write {
                path: path.display().to_string(),
                message: "its folder does not exist".into(),
            });
        }
    }
    let results = sweep(args, ProgressDrawTarget::stderr(), &|results| {
        if results.len() == 1 {
            println!("tumble solver: {}", args.solver);
            println!("{}", report::table_header());
        }
        if let Some(last) = results.last() {
            println!("{}", report::table_row(last));
        }
        match &args.csv {
            Some(path) => report::write_csv(path, results),
            None => Ok(()),
        }
    })?;
    if let Some(path) = &args.png {
        chart::draw(path, &results)?;
    }
    Ok(())
}

/// Where a scene comes from.
enum SceneSource {
    Builtin(String),
    /// A scene file has one size: it runs once, reported at scale 1.
    File(Scene),
}

/// Runs every case. After each, `on_case` gets the results so far, the new one last.
pub fn sweep(
    args: &BenchArgs,
    progress_target: ProgressDrawTarget,
    on_case: &dyn Fn(&[CaseResult]) -> Result<(), BenchError>,
) -> Result<Vec<CaseResult>, BenchError> {
    // Everything that can be wrong with the input is checked before the first case runs.
    let mut scenes = Vec::with_capacity(args.scenes.len());
    for name in &args.scenes {
        let source = load(name)?;
        let scales = scales_for(&source, args)?;
        scenes.push((name.as_str(), source, scales));
    }
    let threads = args.threads();
    let mut pools = Vec::with_capacity(threads.len());
    for &count in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(count)
            .build()
            .map_err(|e| BenchError::ThreadPool {
                threads: count,
                message: e.to_string(),
            })?;
        pools.push((count, pool));
    }
    let schedule = Schedule {
        warmup: args.warmup,
        steps: args.steps,
        time_limit_ms: args.time_limit_ms,
    };

    let steps_per_case = (args.warmup + args.steps) as u64;
    let cases: usize = scenes
        .iter()
        .map(|(_, _, scales)| scales.len())
        .sum::<usize>()
        * args.engines.len()
        * pools.len();
    let bar = ProgressBar::with_draw_target(Some(cases as u64 * steps_per_case), progress_target);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {percent}% {msg} (eta {eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }

    let mut results: Vec<CaseResult> = Vec::with_capacity(cases);
    // (scene, engine, threads) columns that hit the time limit.
    let mut stopped: HashSet<(usize, EngineKind, usize)> = HashSet::new();
    for (scene_index, (name, source, scales)) in scenes.iter().enumerate() {
        for &scale in scales {
            let mut scene = match source {
                SceneSource::Builtin(name) => builtin(name, scale)?,
                SceneSource::File(scene) => scene.clone(),
            };
            scene.config.solver = args.solver;
            if let Some(iterations) = args.iterations {
                scene.config.solver_iterations = iterations;
            }
            let bodies = dynamic_bodies(&scene);
            for &engine in &args.engines {
                for (threads, pool) in &pools {
                    let key = CaseKey {
                        scene: name.to_string(),
                        scale,
                        bodies,
                        engine,
                        threads: *threads,
                    };
                    let column = (scene_index, engine, *threads);
                    bar.set_message(format!(
                        "{name} ×{scale:.3} ({bodies} bodies) {} {threads}t",
                        engine.name()
                    ));
                    let result = if stopped.contains(&column) {
                        CaseResult::not_run(key, &scene, Status::Skipped)
                    } else {
                        let start = bar.position();
                        let result =
                            pool.install(|| run_case(key, &scene, schedule, &|| bar.inc(1)));
                        bar.set_position(start + steps_per_case);
                        result
                    };
                    if result.status == Status::TimeLimit {
                        stopped.insert(column);
                    }
                    results.push(result);
                    bar.suspend(|| on_case(&results))?;
                }
            }
        }
    }
    bar.finish_and_clear();
    Ok(results)
}

fn load(name: &str) -> Result<SceneSource, BenchError> {
    let path = Path::new(name);
    if name.ends_with(".json") || path.exists() {
        Ok(SceneSource::File(Scene::load(path)?))
    } else {
        // Builds the scene at scale 1 only to check the name before any case runs.
        builtin(name, 1.0)?;
        Ok(SceneSource::Builtin(name.to_string()))
    }
}

/// The scales to run `source` at, ascending (a column stops at the first too slow).
fn scales_for(source: &SceneSource, args: &BenchArgs) -> Result<Vec<f32>, BenchError> {
    let name = match source {
        SceneSource::File(_) => return Ok(vec![1.0]),
        SceneSource::Builtin(name) => name,
    };
    let mut scales = if !args.bodies.is_empty() {
        let at_scale_one = dynamic_bodies(&builtin(name, 1.0)?);
        if at_scale_one == 0 {
            return Err(BenchError::Flag {
                flag: "bodies",
                message: format!("{name} has no dynamic bodies to count; use --scales"),
            });
        }
        args.bodies
            .iter()
            .map(|&count| count as f32 / at_scale_one as f32)
            .collect()
    } else if !args.scales.is_empty() {
        args.scales.clone()
    } else {
        vec![1.0]
    };
    scales.sort_by(f32::total_cmp);
    scales.dedup();
    Ok(scales)
}

fn dynamic_bodies(scene: &Scene) -> usize {
    scene.bodies.iter().filter(|desc| !desc.is_static()).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quiet_sweep(args: &BenchArgs) -> Result<Vec<CaseResult>, BenchError> {
        sweep(args, ProgressDrawTarget::hidden(), &|_| Ok(()))
    }

    #[test]
    fn a_tiny_time_limit_ends_each_column_cleanly() {
        let mut args = BenchArgs::new(&["falling-boxes"]);
        args.bodies = vec![64, 8, 27];
        args.engines = vec![EngineKind::TumbleCpu, EngineKind::Rapier];
        args.threads = vec![1];
        args.warmup = 1;
        args.steps = 3;
        args.time_limit_ms = 1e-6;
        let results = quiet_sweep(&args).unwrap();
        // With no warm-up, the limit strikes at the second timed step.
        args.warmup = 0;
        let no_warmup = quiet_sweep(&args).unwrap();
        assert_eq!(no_warmup[0].status, Status::TimeLimit);
        let figures = no_warmup[0].figures.as_ref().unwrap();
        assert_eq!((figures.warmup_steps, figures.timed_steps), (0, 2));
        assert_eq!(results.len(), 6);
        for engine in [EngineKind::TumbleCpu, EngineKind::Rapier] {
            let column: Vec<_> = results.iter().filter(|r| r.key.engine == engine).collect();
            let bodies: Vec<_> = column.iter().map(|r| r.key.bodies).collect();
            assert!(bodies.is_sorted(), "smallest first: {bodies:?}");
            // The first step is exempt; the second, the first timed one, ends the case.
            assert_eq!(column[0].status, Status::TimeLimit);
            let figures = column[0].figures.as_ref().unwrap();
            assert_eq!((figures.warmup_steps, figures.timed_steps), (1, 1));
            assert!(figures.step_ms.is_some());
            assert!(column[1..].iter().all(|r| r.status == Status::Skipped));
            assert!(column[1..].iter().all(|r| r.figures.is_none()));
        }
    }

    #[test]
    fn a_generous_limit_runs_every_case_on_every_engine() {
        let mut args = BenchArgs::new(&["stacked-boxes"]);
        args.scales = vec![0.01];
        args.engines = vec![
            EngineKind::TumbleCpu,
            EngineKind::TumbleGpu,
            EngineKind::Rapier,
        ];
        args.threads = vec![1, 2];
        args.warmup = 2;
        args.steps = 4;
        // Generous on a loaded CPU driver too: the GPU step with six GPU stages took 0.64 to
        // 1.5 s a step on lavapipe while other builds ran (the test is of the sweep, not speed).
        args.time_limit_ms = 60_000.0;
        let results = quiet_sweep(&args).unwrap();
        assert_eq!(results.len(), 6);
        // tumble-gpu runs on whatever adapter is there (Mesa's CPU drivers in CI).
        for result in &results {
            assert_eq!(result.status, Status::Ok, "{result:?}");
            let figures = result.figures.as_ref().unwrap();
            assert_eq!((figures.warmup_steps, figures.timed_steps), (2, 4));
            let spread = figures.step_ms.unwrap();
            assert!(spread.min <= spread.p10 && spread.p10 <= spread.median);
            assert!(spread.median <= spread.p90 && spread.p90 <= spread.max);
            assert!(!figures.stage_ms.is_empty());
        }
    }

    #[test]
    fn unwritable_outputs_are_errors_before_any_case_runs() {
        let mut args = BenchArgs::new(&["falling-boxes"]);
        args.csv = Some("/no-such-folder/out.csv".into());
        let error = run(&args).unwrap_err().to_string();
        assert!(
            error.starts_with("cannot write /no-such-folder/out.csv"),
            "{error}"
        );
        args.csv = None;
        args.png = Some("/no-such-folder/out.png".into());
        let error = run(&args).unwrap_err().to_string();
        assert_eq!(
            error,
            "cannot write /no-such-folder/out.png: its folder does not exist"
        );
    }

    #[test]
    fn bad_scene_names_and_files_are_errors_before_any_case_runs() {
        let error = quiet_sweep(&BenchArgs::new(&["falling-boxes", "nope"])).unwrap_err();
        assert!(
            error.to_string().contains("unknown scene \"nope\""),
            "{error}"
        );
        let error = quiet_sweep(&BenchArgs::new(&["missing.json"])).unwrap_err();
        assert!(error.to_string().contains("missing.json"), "{error}");
    }
}
