//! `tumble`: run, list and benchmark (and later view) scenes. See DESIGN.md's CLI contract.

mod particles;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use tumble::scene::{BUILTIN_SCENES, RayFan, Scene, builtin};

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
    /// Where the step runs; `auto` picks the GPU when there is one.
    #[arg(long, value_enum, default_value = "auto")]
    device: Device,
    /// Per-stage devices, e.g. `broadphase=gpu,solver=cpu` (overrides --device per stage).
    #[arg(long)]
    stages: Option<String>,
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
}

/// Stage names a `--stages` list may assign.
const STAGES: &[&str] = &[
    "aabb",
    "broadphase",
    "pairs",
    "narrowphase",
    "constraints",
    "batching",
    "solver",
    "integrate",
];

fn main() -> ExitCode {
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
            Ok(())
        }
        Command::View(args) => load_scene(&args.scene, args.scale).and_then(|scene| {
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

fn load_scene(name: &str, scale: f32) -> Result<Scene, String> {
    let path = Path::new(name);
    if name.ends_with(".json") || path.exists() {
        Scene::load(path).map_err(|e| e.to_string())
    } else {
        builtin(name, scale).map_err(|e| e.to_string())
    }
}

/// The device the step runs on, after `--device` and `--stages`. The GPU step does not exist
/// yet, so asking for it is a clear error and `auto` means the CPU.
fn resolve_device(args: &RunArgs) -> Result<&'static str, String> {
    const NO_GPU: &str =
        "the GPU step is not implemented yet (see the GPU issues); run with --device cpu";
    if let Some(stages) = &args.stages {
        for assignment in stages.split(',').filter(|s| !s.is_empty()) {
            let (stage, device) = assignment.split_once('=').ok_or_else(|| {
                format!("--stages: {assignment:?} is not stage=device (e.g. broadphase=cpu)")
            })?;
            if !STAGES.contains(&stage) {
                return Err(format!(
                    "--stages: unknown stage {stage:?}; stages are {}",
                    STAGES.join(", ")
                ));
            }
            match device {
                "cpu" => {}
                "gpu" => return Err(format!("--stages {stage}=gpu: {NO_GPU}")),
                other => {
                    return Err(format!(
                        "--stages: unknown device {other:?} for {stage}; use cpu or gpu"
                    ));
                }
            }
        }
    }
    match args.device {
        Device::Gpu => Err(NO_GPU.to_string()),
        Device::Cpu | Device::Auto => Ok("cpu"),
    }
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
        };
        return particles::run(&request);
    }
    if args.explain {
        return Err("--explain is for the particles scene".into());
    }
    let device = resolve_device(args)?;
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
    // The raycast scene casts its fan after every step, inside the step's profiler frame.
    let mut fan = RayFan::for_scene(&args.scene, args.scale);
    for _ in 0..args.steps {
        match fan.as_mut() {
            Some(fan) => {
                world.step_then(|world| fan.cast(world));
            }
            None => world.step(),
        }
    }
    let rays = fan.as_ref().map(RayFan::stats);
    let report = world.profiler().report();
    let stats = world.stats().clone();
    let ms_per_step = world.profiler().median_frame_ms();
    let threads = rayon::current_num_threads();
    if args.profile {
        print!("{report}");
        println!(
            "# bodies = {}  # pairs = {} (+{} -{})  # manifolds = {}  # contacts = {}  max penetration = {:.4} m",
            world.body_count(),
            stats.pairs,
            stats.pairs_added,
            stats.pairs_removed,
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
            "batches on {device} ({} constraints per batch):",
            stats.batch_histogram.len()
        );
        for (batch, count) in stats.batch_histogram.iter().enumerate() {
            println!("{batch:4} : {count}");
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
            "adapter": serde_json::Value::Null,
            "threads": threads,
            "ms_per_step": ms_per_step,
            "stage_ms": stage_ms,
            "pairs": stats.pairs,
            "contacts": stats.contacts,
            "max_penetration": stats.max_penetration,
            "kinetic_energy": world.kinetic_energy(),
            "batches": stats.batch_histogram.len(),
        });
        if let Some(rays) = rays {
            summary["rays"] = rays.rays.into();
            summary["ray_hits"] = rays.hits.into();
            summary["us_per_ray"] = rays.us_per_ray.into();
        }
        println!("{summary}");
    } else if !args.profile {
        println!(
            "{}: {} bodies, {} steps on {device} ({threads} threads): {ms_per_step:.3} ms/step (median); {} pairs, {} contacts, {} batches, max penetration {:.4} m",
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
