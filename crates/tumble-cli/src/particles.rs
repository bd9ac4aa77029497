//! `tumble run particles`: the talk's uniform-grid particle demo on the GPU or the CPU.

use std::time::Instant;
use tumble::gpu::context::GpuContext;
use tumble::particles::{
    CellSort, NeighbourSearch, ParticleConfig, ParticleDevice, ParticleSystem, explain,
};

/// Particles at scale 1: the NVIDIA SDK demo's million.
const PARTICLES_AT_SCALE_1: f64 = 1_000_000.0;

/// What `tumble run particles` was asked for.
pub struct ParticleRun {
    /// `cpu`, `gpu` or `auto`.
    pub device: &'static str,
    pub scale: f32,
    pub steps: u32,
    pub profile: bool,
    pub json: bool,
    pub explain: bool,
    pub sort: CellSort,
    pub search: NeighbourSearch,
}

/// `--sort`'s names.
const SORTS: [(&str, CellSort); 2] = [("radix", CellSort::Radix), ("bitonic", CellSort::Bitonic)];

/// `--search`'s values: the cells each particle searches.
const SEARCHES: [(u32, NeighbourSearch); 2] = [
    (27, NeighbourSearch::Full27),
    (14, NeighbourSearch::Symmetric14),
];

pub fn parse_sort(name: &str) -> Result<CellSort, String> {
    SORTS
        .iter()
        .find(|(known, _)| *known == name)
        .map(|&(_, sort)| sort)
        .ok_or_else(|| format!("--sort: unknown sort {name:?}; sorts are radix, bitonic"))
}

pub fn parse_search(name: &str) -> Result<NeighbourSearch, String> {
    SEARCHES
        .iter()
        .find(|(cells, _)| name.parse() == Ok(*cells))
        .map(|&(_, search)| search)
        .ok_or_else(|| format!("--search: unknown search {name:?}; searches are 27, 14 (cells)"))
}

fn sort_name(sort: CellSort) -> &'static str {
    SORTS
        .iter()
        .find(|(_, known)| *known == sort)
        .expect("every sort has a name")
        .0
}

fn search_cells(search: NeighbourSearch) -> u32 {
    SEARCHES
        .iter()
        .find(|(_, known)| *known == search)
        .expect("every search has a value")
        .0
}

/// The demo at `--scale` (1: a million particles).
pub fn demo_config(scale: f32) -> Result<ParticleConfig, String> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(format!(
            "scale must be a positive finite number, got {scale}"
        ));
    }
    let count = ((PARTICLES_AT_SCALE_1 * scale as f64).round() as usize).max(1);
    Ok(ParticleConfig::demo(count))
}

pub fn run(request: &ParticleRun) -> Result<(), String> {
    if request.explain {
        print!("{}", explain::example_tables());
        return Ok(());
    }
    let config = ParticleConfig {
        sort: request.sort,
        search: request.search,
        ..demo_config(request.scale)?
    };
    let device = match request.device {
        "cpu" => ParticleDevice::Cpu,
        "gpu" => ParticleDevice::Gpu(GpuContext::shared().map_err(|e| e.to_string())?),
        // auto: a real GPU if there is one; Mesa's CPU drivers are slower than the CPU twin.
        _ => match GpuContext::shared() {
            Ok(context) if !context.is_cpu_driver() => ParticleDevice::Gpu(context),
            _ => ParticleDevice::Cpu,
        },
    };
    if let (ParticleDevice::Gpu(context), true) = (&device, request.profile) {
        // The profile's `[gpu]` lines.
        context.set_gpu_timing(true);
    }
    let device_label = if matches!(device, ParticleDevice::Cpu) {
        "cpu"
    } else {
        "gpu"
    };
    let count = config.count;
    let mut system = ParticleSystem::new(config, device).map_err(|e| e.to_string())?;
    system.set_gpu_timing(request.profile);
    let start = Instant::now();
    for _ in 0..request.steps {
        system.step().map_err(|e| e.to_string())?;
    }
    system.finish().map_err(|e| e.to_string())?;
    let ms_per_step = start.elapsed().as_secs_f64() * 1e3 / request.steps.max(1) as f64;
    let energy = system.kinetic_energy().map_err(|e| e.to_string())?;
    if request.profile {
        print!("{}", system.profiler().report());
    }
    let adapter = system.device_name();
    // What the system runs, as it reports it.
    let (sort, search) = (
        sort_name(system.config().sort),
        search_cells(system.config().search),
    );
    if request.json {
        let summary = serde_json::json!({
            "scene": "particles",
            // The contract's field (DESIGN.md), as for every scene; here a body is a particle.
            "bodies": count,
            "particles": count,
            "steps": request.steps,
            "device": device_label,
            "adapter": adapter,
            "ms_per_step": ms_per_step,
            "stage_ms": system.profiler().report().stage_ms().into_iter().map(|(n, ms)| (n.to_string(), serde_json::Value::from(ms))).collect::<serde_json::Map<_, _>>(),
            "kinetic_energy": energy,
            "sort": sort,
            "search": search,
        });
        println!("{summary}");
    } else {
        println!(
            "particles: {count} particles, {} steps on {device_label} ({adapter}), {sort} sort, {search}-cell search: {ms_per_step:.3} ms/step ({:.0} steps/s), kinetic energy {energy:.3e} J",
            request.steps,
            1e3 / ms_per_step
        );
    }
    Ok(())
}
