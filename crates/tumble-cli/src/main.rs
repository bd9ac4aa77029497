//! `tumble`: run, list and benchmark (and later view) scenes. See DESIGN.md's CLI contract.

mod bunnies;
mod particles;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::{BUILTIN_SCENES, RayFan, Scene, builtin};
use tumble::stages::batching::Batcher;
use tumble::stages::solver::SolverKind;

#[derive(Parser)]
#[command(
    name = "tumble",
    version,
    about = "Rigid-body physics on the GPU or the CPU, after Bullet's GPU pipeline"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Runs a scene (a built-in name or a JSON scene file) and reports timings.
    Run(RunArgs),
    /// Lists the built-in scenes.
    Scenes,
    /// Shows a scene in a window, or headless with --png / --frames.
    View(ViewArgs),
    /// Times scenes on Tumble and on peer engines across sizes and thread counts.
    Bench(tumble_bench::BenchArgs),
}

#[derive(clap::Args)]
struct ViewArgs {
    /// Built-in scene name (`tumble scenes`) or path to a JSON scene file.
    scene: String,
    /// Size of a built-in scene (1 = the talk's size).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    scale: f32,
    /// The solver: `pgs` (batched projected Gauss-Seidel) or `jacobi` (for comparison).
    #[arg(long, default_value = "pgs")]
    solver: String,
    #[command(flatten)]
    options: tumble_viewer::ViewOptions,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Device {
    Cpu,
    Gpu,
    Auto,
}

#[derive(clap::Args)]
struct RunArgs {
    /// Built-in scene name (`tumble scenes`) or path to a JSON scene file.
    scene: String,
    /// Where the step runs; `auto` picks a hardware GPU for scenes of 100 bodies or more.
    #[arg(long, value_enum, default_value = "auto")]
    device: Device,
    /// Per-stage devices, e.g. `broadphase=gpu,solver=cpu` (overrides --device per stage).
    #[arg(long)]
    stages: Option<String>,
    /// How constraints are batched for the solver: `colors` (greedy coloring) or `rounds`
    /// (the talk's kSetupBatches); both give the same batches on the CPU and the GPU.
    #[arg(long, default_value = "colors")]
    batcher: String,
    /// The solver: `pgs` (batched projected Gauss-Seidel) or `jacobi` (every constraint of a
    /// sweep from the same velocities, no batches; needs more iterations for the same error).
    #[arg(long, default_value = "pgs")]
    solver: String,
    /// Steps to run.
    #[arg(long, default_value_t = 300)]
    steps: u32,
    /// Size of a built-in scene (1 = the talk's size).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    scale: f32,
    /// CPU worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Print the hierarchical stage profile, pair and contact counts and the batch histogram.
    #[arg(long)]
    profile: bool,
    /// Print one JSON object with the results last.
    #[arg(long)]
    json: bool,
    /// Write the final state as a scene file that loads and continues the run.
    #[arg(long)]
    dump: Option<PathBuf>,
    /// For `particles`: print the talk's uniform-grid tables for its six-particle example.
    #[arg(long)]
    explain: bool,
    /// For `particles`: the sort by cell, `radix` (default) or `bitonic` (the talk's
    /// alternative, in the same order; the CPU twin has one sort, which gives that order).
    #[arg(long)]
    sort: Option<String>,
    /// For `particles`: the neighbour search, `27` cells (default) or `14` (symmetric: each
    /// pair once, forces summed in fixed point).
    #[arg(long)]
    search: Option<String>,
}

fn main() -> ExitCode {
    end_quietly_on_a_closed_pipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run(&args),
        Command::Scenes => {
            for (name, about) in BUILTIN_SCENES {
                println!("{name:16} {about}");
            }
            println!(
                "{:16} the uniform-grid particle demo: 1M particles at scale 1 (use --scale 0.05 on a CPU)",
                "particles"
            );
            println!(
                "{:16} rigid bodies made of particles: 4096 voxelized bunnies (238 particles each) falling into a box at scale 1 (use --scale 0.01 on a CPU)",
                "bunnies"
            );
            Ok(())
        }
        Command::View(args) if args.scene == "particles" => particles::demo_config(args.scale)
            .and_then(|config| {
                tumble_viewer::view_particles(config, &args.options).map_err(|e| e.to_string())
            }),
        Command::View(args) if args.scene == "bunnies" => bunnies::pile_config(args.scale)
            .and_then(|config| {
                tumble_viewer::view_bunnies(config, &args.options).map_err(|e| e.to_string())
            }),
        Command::View(args) => parse_solver(&args.solver)
            .and_then(|solver| {
                let mut scene = load_scene(&args.scene, args.scale)?;
                scene.config.solver = solver;
                Ok(scene)
            })
            .and_then(|scene| {
                tumble_viewer::view(&args.scene, &scene, &args.options).map_err(|e| e.to_string())
            }),
        Command::Bench(args) => tumble_bench::run(&args).map_err(|e| e.to_string()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("tumble: error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// Rust ignores SIGPIPE, so a write to a pipe whose reader is gone (`tumble run ... | head -1`)
/// is an error, and `println!` panics on it. Unix tools end quietly there: SIGPIPE's default
/// action, given back here, ends the process at that write, before it can panic.
fn end_quietly_on_a_closed_pipe() {
    // SAFETY: first thing in `main`, before any other thread exists; SIG_DFL is a valid action
    // for SIGPIPE.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn parse_solver(name: &str) -> Result<SolverKind, String> {
    name.parse().map_err(|e| format!("--solver: {e}"))
}

fn load_scene(name: &str, scale: f32) -> Result<Scene, String> {
    let path = Path::new(name);
    if name.ends_with(".json") || path.exists() {
        Scene::load(path).map_err(|e| e.to_string())
    } else {
        builtin(name, scale).map_err(|e| e.to_string())
    }
}

/// Bodies from which `--device auto` runs the step on a hardware GPU. Measured on an H100
/// machine (BENCHMARKS.md, session 25; `tumble bench` against 16 CPU threads, ms a step): the
/// GPU step's fixed cost, about 0.9 ms, loses only to the smallest scenes (66 ragdoll bodies:
/// 2.1 against 1.6) and wins from about a hundred (153 falling boxes: 0.85 against 1.32, 126
/// stacked boxes: 2.4 against 4.5, 165 ragdoll bodies: 2.5 against 3.6, 3k falling boxes: 1.2
/// against 4.4). Session 14's GPU step, which waited for the device between stages, lost up
/// to 10k bodies.
const AUTO_GPU_BODIES: usize = 100;

/// The executor of each stage, after `--device` and then `--stages`. `auto` is every stage on
/// a hardware GPU for scenes of at least [`AUTO_GPU_BODIES`] bodies, else the CPU (Mesa's CPU
/// drivers run the kernels slower than the CPU step).
fn stage_devices(args: &RunArgs, bodies: usize) -> Result<StageDevices, String> {
    let assignments = args.stages.as_deref().unwrap_or("");
    let assign = |base: StageDevices| {
        base.with_assignments(assignments)
            .map_err(|e| format!("--stages: {e}"))
    };
    // Checked first: a bad --stages is reported before any adapter is probed.
    assign(StageDevices::default())?;
    let base = match args.device {
        Device::Gpu => StageDevices::all(Executor::Gpu),
        Device::Cpu => StageDevices::default(),
        Device::Auto if bodies < AUTO_GPU_BODIES => StageDevices::default(),
        Device::Auto => match tumble::gpu::GpuContext::shared() {
            Ok(context) if !context.is_cpu_driver() => StageDevices::all(Executor::Gpu),
            _ => StageDevices::default(),
        },
    };
    assign(base)
}

fn run(args: &RunArgs) -> Result<(), String> {
    if args.scene == "particles" {
        let device = match args.device {
            Device::Cpu => "cpu",
            Device::Gpu => "gpu",
            Device::Auto => "auto",
        };
        let request = particles::ParticleRun {
            device,
            scale: args.scale,
            steps: args.steps,
            profile: args.profile,
            json: args.json,
            explain: args.explain,
            sort: particles::parse_sort(args.sort.as_deref().unwrap_or("radix"))?,
            search: particles::parse_search(args.search.as_deref().unwrap_or("27"))?,
        };
        return particles::run(&request);
    }
    for (flag, given) in [
        ("--explain", args.explain),
        ("--sort", args.sort.is_some()),
        ("--search", args.search.is_some()),
    ] {
        if given {
            return Err(format!("{flag} is for the particles scene"));
        }
    }
    if args.scene == "bunnies" {
        let request = bunnies::BunnyRun {
            device: match args.device {
                Device::Cpu => "cpu",
                Device::Gpu => "gpu",
                Device::Auto => "auto",
            },
            scale: args.scale,
            steps: args.steps,
            profile: args.profile,
            json: args.json,
        };
        return bunnies::run(&request);
    }
    let batcher: Batcher = args
        .batcher
        .parse()
        .map_err(|e| format!("--batcher: {e}"))?;
    let solver = parse_solver(&args.solver)?;
    if let Some(threads) = args.threads {
        if threads == 0 {
            return Err("--threads must be at least 1".into());
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .map_err(|e| e.to_string())?;
    }
    let scene = load_scene(&args.scene, args.scale)?;
    let mut world = scene.build().map_err(|e| e.to_string())?;
    // After the scene: bad input is reported before any adapter is probed.
    let devices = stage_devices(args, world.body_count())?;
    world
        .set_stage_devices(devices)
        .map_err(|e| e.to_string())?;
    let config = tumble::StepConfig {
        batcher,
        solver,
        ..*world.config()
    };
    world.set_config(config).map_err(|e| e.to_string())?;
    let device = if devices.any_gpu() {
        devices.to_string()
    } else {
        "cpu".to_string()
    };
    if args.profile && devices.any_gpu() {
        // The profile's `[gpu]` lines; the other runs (and `--json`'s median) leave the
        // device's timestamps off.
        let context = tumble::gpu::GpuContext::shared().map_err(|e| e.to_string())?;
        context.set_gpu_timing(true);
    }
    // The raycast scene casts its fan after every step, inside the step's profiler frame.
    let mut fan = RayFan::for_scene(&args.scene, args.scale);
    let mut first_step_ms = None;
    for step in 0..args.steps {
        match fan.as_mut() {
            Some(fan) => world.try_step_then(|world| {
                fan.cast(world);
            }),
            None => world.try_step(),
        }
        .map_err(|e| e.to_string())?;
        // The first step compiles the GPU kernels and grows every buffer: it is reported on its
        // own line, and the profile and the median are of the steps after it.
        if step == 0 && args.steps > 1 {
            first_step_ms = Some(world.profiler().median_frame_ms());
            world.profiler_mut().reset();
        }
    }
    let rays = fan.as_ref().map(RayFan::stats);
    let report = world.profiler().report();
    let stats = world.stats().clone();
    let ms_per_step = world.profiler().median_frame_ms();
    let threads = rayon::current_num_threads();
    if args.profile {
        if let Some(ms) = first_step_ms {
            println!(
                "first step: {ms:.3} ms (kernel compilation, buffer growth), not in the profile below"
            );
        }
        print!("{report}");
        println!(
            "# bodies = {} ({} asleep)  # pairs = {} (+{} -{}, {} computed)  # manifolds = {}  # contacts = {}  max penetration = {:.4} m",
            world.body_count(),
            stats.sleeping,
            stats.pairs,
            stats.pairs_added,
            stats.pairs_removed,
            stats.pairs_computed,
            stats.manifolds,
            stats.contacts,
            stats.max_penetration
        );
        if let Some(rays) = rays {
            println!(
                "# rays = {}  # hits = {}  time per ray = {:.3} us (median step)",
                rays.rays, rays.hits, rays.us_per_ray
            );
        }
        println!(
            "solver: {solver}, {} iterations x {} sub-steps",
            config.solver_iterations, config.substeps
        );
        if solver == SolverKind::Jacobi {
            println!("no coloring: the Jacobi solver sweeps every constraint at once");
        } else {
            println!(
                "{} batches by {} in {} rounds on {device} (constraints per batch):",
                stats.batch_histogram.len(),
                batcher,
                stats.batching_rounds
            );
            for (batch, count) in stats.batch_histogram.iter().enumerate() {
                println!("{batch:4} : {count}");
            }
        }
    }
    if let Some(path) = &args.dump {
        Scene::from_world(&world)
            .save(path)
            .map_err(|e| e.to_string())?;
    }
    if args.json {
        let stage_ms: serde_json::Map<String, serde_json::Value> = report
            .stage_ms()
            .into_iter()
            .map(|(name, ms)| (name.to_string(), ms.into()))
            .collect();
        let mut summary = serde_json::json!({
            "scene": args.scene,
            "bodies": world.body_count(),
            "steps": args.steps,
            "device": device,
            "adapter": world.gpu_adapter(),
            "threads": threads,
            "ms_per_step": ms_per_step,
            "stage_ms": stage_ms,
            "pairs": stats.pairs,
            "pairs_computed": stats.pairs_computed,
            "contacts": stats.contacts,
            "sleeping": stats.sleeping,
            "max_penetration": stats.max_penetration,
            "kinetic_energy": world.kinetic_energy(),
            "batches": stats.batch_histogram.len(),
            "batching_rounds": stats.batching_rounds,
            "batcher": batcher.to_string(),
            "solver": solver.to_string(),
        });
        if let Some(rays) = rays {
            summary["rays"] = rays.rays.into();
            summary["ray_hits"] = rays.hits.into();
            summary["us_per_ray"] = rays.us_per_ray.into();
        }
        println!("{summary}");
    } else if !args.profile {
        println!(
            "{}: {} bodies, {} steps on {device} ({threads} threads, {solver} solver): {ms_per_step:.3} ms/step (median); {} pairs, {} contacts, {} batches, max penetration {:.4} m",
            args.scene,
            world.body_count(),
            args.steps,
            stats.pairs,
            stats.contacts,
            stats.batch_histogram.len(),
            stats.max_penetration
        );
    }
    Ok(())
}
