//! `tumble bench prims`: the GPU building blocks on their own, for the goals — radix
//! sort (1M and 16M key-value pairs, Mkeys/s), prefix scan of 64M u32 against a device-to-device
//! copy of the same bytes (GB/s), and the particle demo at 1M particles (steps/s).
//!
//! The scan's ceiling is a compute kernel that copies the same bytes (one u32 per thread, read
//! once, written once, as the scan does); `copy_buffer_to_buffer` is printed too, but on
//! NVIDIA's Vulkan driver it reached less than half of that, so it would flatter the scan.
//!
//! Each measurement encodes the operation [`REPEATS`] times into one submission and waits once,
//! so the ~55 µs submit-and-wait round trip is spread over the repeats; the median of
//! [`SAMPLES`] such submissions is reported.

use std::time::Instant;
use tumble::gpu::kernel::encode_all;
use tumble::gpu::prims::fill::copy_dispatch;
use tumble::gpu::prims::radix_sort::{RadixSort, SortPath};
use tumble::gpu::prims::scan::{Scan, ScanKind, ScanPath};
use tumble::gpu::{GpuContext, GpuVec};
use tumble::particles::{ParticleConfig, ParticleDevice, ParticleSystem};
use tumble::profile::median;

/// Operations per submission.
const REPEATS: usize = 20;
/// Submissions timed (after one warm-up submission).
const SAMPLES: usize = 7;

/// One line of the report.
struct Line {
    what: String,
    ms: f64,
    rate: String,
}

/// `scale` multiplies every size (1 = the sizes above; smaller for a quick check on a CPU driver).
pub fn run(scale: f64) -> Result<(), String> {
    let sized = |count: usize| ((count as f64 * scale).round() as usize).max(1);
    let context = GpuContext::shared().map_err(|e| e.to_string())?;
    println!("# GPU primitives on {}", context.describe());
    let mut lines = Vec::new();
    for count in [sized(1 << 20), sized(1 << 24)] {
        for (path, name) in [
            (SortPath::best(&context), ""),
            (SortPath::Baseline, ", baseline path"),
        ] {
            let ms = radix_sort_ms(&context, count, path)?;
            lines.push(Line {
                what: format!("radix sort u32 key-value, {count} pairs{name}"),
                ms,
                rate: format!("{:.0} Mkeys/s", count as f64 / ms / 1e3),
            });
        }
    }
    let count = sized(1 << 26);
    let bytes = 2.0 * 4.0 * count as f64; // read and write every u32 once
    let scan = scan_ms(&context, count, ScanPath::best(&context))?;
    let baseline = scan_ms(&context, count, ScanPath::Baseline)?;
    let copy = copy_ms(&context, count)?;
    let kernel_copy = kernel_copy_ms(&context, count)?;
    lines.push(Line {
        what: format!("exclusive scan u32, {count}"),
        ms: scan,
        rate: format!("{:.0} GB/s", bytes / scan / 1e6),
    });
    lines.push(Line {
        what: format!("exclusive scan u32, {count}, baseline path"),
        ms: baseline,
        rate: format!("{:.0} GB/s", bytes / baseline / 1e6),
    });
    lines.push(Line {
        what: format!("compute copy kernel u32, {count}"),
        ms: kernel_copy,
        rate: format!("{:.0} GB/s", bytes / kernel_copy / 1e6),
    });
    lines.push(Line {
        what: format!("copy_buffer_to_buffer u32, {count}"),
        ms: copy,
        rate: format!("{:.0} GB/s", bytes / copy / 1e6),
    });
    let particle_count = sized(1_000_000);
    let particles = particles_ms(&context, particle_count)?;
    lines.push(Line {
        what: format!("particles, {particle_count}"),
        ms: particles,
        rate: format!("{:.0} steps/s", 1e3 / particles),
    });
    println!("{:44} {:>10} {:>14}", "operation", "ms", "rate");
    for line in &lines {
        println!("{:44} {:>10.4} {:>14}", line.what, line.ms, line.rate);
    }
    println!(
        "scan / compute copy throughput: {:.0} %",
        100.0 * kernel_copy / scan
    );
    Ok(())
}

/// Median ms per operation of `encode` repeated [`REPEATS`] times per submission.
fn time_repeated(
    context: &GpuContext,
    mut submit: impl FnMut() -> Result<(), String>,
) -> Result<f64, String> {
    submit()?;
    context.wait().map_err(|e| e.to_string())?;
    let mut samples = Vec::with_capacity(SAMPLES);
    for _ in 0..SAMPLES {
        let start = Instant::now();
        submit()?;
        context.wait().map_err(|e| e.to_string())?;
        samples.push(start.elapsed().as_secs_f64() * 1e3 / REPEATS as f64);
    }
    Ok(median(&samples))
}

/// Deterministic pseudo-random keys (xorshift), so every run sorts the same input.
/// The arrays are windowed, so that sizes past one storage binding (128 MiB on Mesa's CPU
/// drivers) run by windows instead of failing.
fn windowed(
    context: &GpuContext,
    label: &'static str,
    data: &[u32],
) -> Result<GpuVec<u32>, tumble::gpu::GpuError> {
    let mut vector = GpuVec::windowed(context, label, data.len())?;
    vector.upload(context, data)?;
    Ok(vector)
}

fn keys(count: usize) -> Vec<u32> {
    let mut state = 0x9e37_79b9u32;
    (0..count)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        })
        .collect()
}

fn radix_sort_ms(context: &GpuContext, count: usize, path: SortPath) -> Result<f64, String> {
    let error = |e: tumble::gpu::GpuError| e.to_string();
    let keys_in = windowed(context, "bench keys", &keys(count)).map_err(error)?;
    let values_in = windowed(
        context,
        "bench values",
        &(0..count as u32).collect::<Vec<_>>(),
    )
    .map_err(error)?;
    let mut keys_out = GpuVec::<u32>::windowed(context, "bench keys out", count).map_err(error)?;
    let mut values_out =
        GpuVec::<u32>::windowed(context, "bench values out", count).map_err(error)?;
    let mut sort = RadixSort::on(path);
    time_repeated(context, || {
        context.submit_pass("bench radix sort", |pass| {
            for _ in 0..REPEATS {
                sort.encode(
                    context,
                    pass,
                    (&keys_in, &values_in),
                    (&mut keys_out, &mut values_out),
                    32,
                )
                .map_err(error)?;
            }
            Ok(())
        })
    })
}

fn scan_ms(context: &GpuContext, count: usize, path: ScanPath) -> Result<f64, String> {
    let error = |e: tumble::gpu::GpuError| e.to_string();
    let input = windowed(context, "bench scan in", &vec![1u32; count]).map_err(error)?;
    let mut output = GpuVec::<u32>::windowed(context, "bench scan out", count).map_err(error)?;
    let mut scan = Scan::on(path);
    time_repeated(context, || {
        context.submit_pass("bench scan", |pass| {
            for _ in 0..REPEATS {
                scan.encode(context, pass, &input, &mut output, ScanKind::Exclusive)
                    .map_err(error)?;
            }
            Ok(())
        })
    })
}

fn copy_ms(context: &GpuContext, count: usize) -> Result<f64, String> {
    let error = |e: tumble::gpu::GpuError| e.to_string();
    let source = windowed(context, "bench copy in", &vec![1u32; count]).map_err(error)?;
    let destination = GpuVec::<u32>::windowed(context, "bench copy out", count).map_err(error)?;
    let bytes = (count * 4) as u64;
    time_repeated(context, || {
        let mut encoder = context.device.create_command_encoder(&Default::default());
        for _ in 0..REPEATS {
            encoder.copy_buffer_to_buffer(source.buffer(), 0, destination.buffer(), 0, bytes);
        }
        context.queue.submit([encoder.finish()]);
        Ok(())
    })
}

fn kernel_copy_ms(context: &GpuContext, count: usize) -> Result<f64, String> {
    let error = |e: tumble::gpu::GpuError| e.to_string();
    let source = windowed(context, "bench copy in", &vec![1u32; count]).map_err(error)?;
    let destination = GpuVec::<u32>::windowed(context, "bench copy out", count).map_err(error)?;
    let copy =
        copy_dispatch(context, source.buffer(), destination.buffer(), count).map_err(error)?;
    time_repeated(context, || {
        context.submit_pass("bench compute copy", |pass| {
            for _ in 0..REPEATS {
                encode_all(pass, &copy);
            }
        });
        Ok(())
    })
}

fn particles_ms(context: &GpuContext, count: usize) -> Result<f64, String> {
    let error = |e: tumble::particles::ParticleError| e.to_string();
    let mut system = ParticleSystem::new(
        ParticleConfig::demo(count),
        ParticleDevice::Gpu(context.clone()),
    )
    .map_err(error)?;
    // Settle past the first steps, whose cell sort is the most ordered.
    for _ in 0..50 {
        system.step().map_err(error)?;
    }
    system.finish().map_err(error)?;
    time_repeated(context, || {
        for _ in 0..REPEATS {
            system.step().map_err(error)?;
        }
        Ok(())
    })
}
