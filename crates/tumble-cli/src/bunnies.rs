//! `tumble run bunnies`: rigid bodies made of particles (the talk's second particle demo) on
//! the GPU or the CPU.

use std::time::Instant;
use tumble::gpu::context::GpuContext;
use tumble::particles::{ParticleDevice, RigidConfig, RigidSystem};

/// Bunnies at scale 1: about 4k bunnies of 238 particles, a million particles, sized for a
/// GPU.
const BUNNIES_AT_SCALE_1: f64 = 4096.0;

/// What `tumble run bunnies` was asked for.
pub struct BunnyRun {
    /// `cpu`, `gpu` or `auto`.
    pub device: &'static str,
    pub scale: f32,
    pub steps: u32,
    pub profile: bool,
    pub json: bool,
}

/// The pile at `--scale` (1: 4096 bunnies).
pub fn pile_config(scale: f32) -> Result<RigidConfig, String> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(format!(
            "scale must be a positive finite number, got {scale}"
        ));
    }
    let count = ((BUNNIES_AT_SCALE_1 * scale as f64).round() as usize).max(1);
    RigidConfig::bunny_pile(count).map_err(|e| e.to_string())
}

pub fn run(request: &BunnyRun) -> Result<(), String> {
    let config = pile_config(request.scale)?;
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
    let mut system = RigidSystem::new(&config, device).map_err(|e| e.to_string())?;
    let (bodies, particles) = (system.body_count(), system.config().count);
    system.set_gpu_timing(request.profile);
    // The first step compiles the kernels: timed on its own, and the time per step and the
    // profile are of the steps after it (when there are any).
    let start = Instant::now();
    let mut first_step_ms = None;
    if request.steps > 1 {
        system.step().map_err(|e| e.to_string())?;
        system.finish().map_err(|e| e.to_string())?;
        first_step_ms = Some(start.elapsed().as_secs_f64() * 1e3);
        system.profiler_mut().reset();
    }
    let timed = request.steps - u32::from(first_step_ms.is_some());
    let start = Instant::now();
    for _ in 0..timed {
        system.step().map_err(|e| e.to_string())?;
    }
    system.finish().map_err(|e| e.to_string())?;
    let ms_per_step = start.elapsed().as_secs_f64() * 1e3 / timed.max(1) as f64;
    let energy = system.kinetic_energy().map_err(|e| e.to_string())?;
    if request.profile {
        if let Some(ms) = first_step_ms {
            println!("first step: {ms:.3} ms (kernel compilation), not in the profile below");
        }
        print!("{}", system.profiler().report());
    }
    let adapter = system.device_name();
    if request.json {
        let stage_ms: serde_json::Map<String, serde_json::Value> = system
            .profiler()
            .report()
            .stage_ms()
            .into_iter()
            .map(|(name, ms)| (name.to_string(), ms.into()))
            .collect();
        let summary = serde_json::json!({
            "scene": "bunnies",
            "bodies": bodies,
            "particles": particles,
            "steps": request.steps,
            "device": device_label,
            "adapter": adapter,
            "ms_per_step": ms_per_step,
            "first_step_ms": first_step_ms,
            "stage_ms": stage_ms,
            "kinetic_energy": energy,
        });
        println!("{summary}");
    } else {
        println!(
            "bunnies: {bodies} bunnies of {particles} particles, {} steps on {device_label} ({adapter}): {ms_per_step:.3} ms/step{} ({:.0} steps/s), kinetic energy {energy:.3e} J",
            request.steps,
            if first_step_ms.is_some() {
                " after the first"
            } else {
                ""
            },
            1e3 / ms_per_step
        );
    }
    Ok(())
}
