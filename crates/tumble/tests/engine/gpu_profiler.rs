//! GPU timestamps land in the hierarchical report as GPU lines when the adapter has them.

use crate::gpu_common;

use gpu_common::{Gpu, Random, context};
use tumble::gpu::prims::scan::{Scan, ScanKind};
use tumble::gpu::profiler::{GpuProfiler, record_copy};
use tumble::gpu::{GpuContext, GpuVec};
use tumble::profile::{Profiler, SpanKind};

/// A scan of 100 000 random values: several dispatches to profile.
struct ScanCase {
    /// The shared context and this test's turn on it.
    context: Gpu,
    source: GpuVec<u32>,
    destination: GpuVec<u32>,
    scan: Scan,
}

impl ScanCase {
    fn new(seed: u64) -> Self {
        let context = context();
        let input = Random::new(seed).u32s(100_000);
        Self {
            source: GpuVec::from_slice(&context, "scan input", &input).expect("upload"),
            destination: GpuVec::with_capacity(&context, "scan output", 0).expect("alloc"),
            scan: Scan::new(),
            context,
        }
    }

    fn encode(&mut self, pass: &mut wgpu::ComputePass<'_>, kind: ScanKind) {
        let Self {
            context,
            source,
            destination,
            scan,
        } = self;
        scan.encode(context, pass, source, destination, kind)
            .expect("encode");
    }
}

/// Passes get timestamps only while the device's context asks for them (a step that is not
/// profiled does not pay for the queries), where the adapter has them.
#[test]
fn passes_are_timed_only_when_asked() {
    let case = ScanCase::new(3);
    let context: GpuContext = (*case.context).clone();
    let mut gpu_profiler = GpuProfiler::new(&context, 4);
    let was = context.times_gpu();
    context.set_gpu_timing(false);
    assert!(!gpu_profiler.is_active());
    assert!(gpu_profiler.pass_timestamps(&["off"]).is_none());
    context.set_gpu_timing(true);
    assert_eq!(gpu_profiler.is_active(), context.has_timestamps());
    assert_eq!(
        gpu_profiler.pass_timestamps(&["on"]).is_some(),
        context.has_timestamps()
    );
    gpu_profiler.discard();
    context.set_gpu_timing(was);
}

#[test]
fn timestamps_and_copies_are_recorded_as_their_own_lines() {
    let mut case = ScanCase::new(1);
    let context: GpuContext = (*case.context).clone();
    context.set_gpu_timing(true);
    let mut gpu_profiler = GpuProfiler::new(&context, 4);
    let mut profiler = Profiler::new("frame");
    profiler.begin_frame();
    let mut encoder = context.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("scan"),
            timestamp_writes: gpu_profiler.pass_timestamps(&["scan"]),
        });
        case.encode(&mut pass, ScanKind::Exclusive);
    }
    gpu_profiler.resolve(&mut encoder);
    context.queue.submit([encoder.finish()]);
    gpu_profiler
        .collect(&context, &mut profiler)
        .expect("collect");
    let start = std::time::Instant::now();
    let _ = case.destination.download(&context).expect("download");
    record_copy(
        &mut profiler,
        &["download"],
        start.elapsed().as_secs_f64() * 1e3,
    );
    profiler.end_frame();
    let report = profiler.report();
    let lines: Vec<_> = report
        .root
        .children
        .iter()
        .map(|line| (line.name, line.kind))
        .collect();
    if context.has_timestamps() {
        assert_eq!(
            lines,
            [("scan", SpanKind::Gpu), ("download", SpanKind::Copy)]
        );
        assert!(report.root.children[0].ms_per_frame >= 0.0);
        assert!(report.to_string().contains("[gpu]"));
    } else {
        // No timestamp queries on this adapter (llvmpipe on GL): only the copy is measured.
        assert_eq!(lines, [("download", SpanKind::Copy)]);
    }
}

#[test]
fn each_dispatch_is_timed_under_its_kernel_when_asked() {
    let mut case = ScanCase::new(2);
    let context: GpuContext = (*case.context).clone();
    let mut gpu_profiler = GpuProfiler::new(&context, 4);
    if !gpu_profiler.time_each_dispatch(&context) {
        // No timestamps inside passes on this adapter (llvmpipe on GL): nothing to time.
        return;
    }
    let mut profiler = Profiler::new("frame");
    profiler.begin_frame();
    let mut encoder = context.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("scan"),
            timestamp_writes: gpu_profiler.pass_timestamps(&["scan"]),
        });
        gpu_profiler.timing_dispatches(|| case.encode(&mut pass, ScanKind::Exclusive));
    }
    // A pass encoded outside `timing_dispatches` is not timed dispatch by dispatch.
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        case.encode(&mut pass, ScanKind::Inclusive);
    }
    gpu_profiler.resolve(&mut encoder);
    context.queue.submit([encoder.finish()]);
    gpu_profiler
        .collect(&context, &mut profiler)
        .expect("collect");
    profiler.end_frame();
    let report = profiler.report();
    let dispatches = report
        .root
        .children
        .iter()
        .find(|line| line.name == "dispatches")
        .expect("a line for the dispatches");
    assert_eq!(dispatches.kind, SpanKind::Gpu);
    // A scan of 100 000 values is more than one dispatch; each is under its kernel's line.
    assert!(dispatches.calls_per_frame >= 2.0, "{report}");
    let kernels: f64 = dispatches.children.iter().map(|k| k.calls_per_frame).sum();
    assert_eq!(kernels, dispatches.calls_per_frame, "{report}");
    let kernel_ms: f64 = dispatches.children.iter().map(|k| k.ms_per_frame).sum();
    assert!(
        (kernel_ms - dispatches.ms_per_frame).abs() < 1e-9,
        "{report}"
    );
    assert!(
        dispatches
            .children
            .iter()
            .all(|k| k.kind == SpanKind::Gpu && !k.name.is_empty()),
        "{report}"
    );
}
