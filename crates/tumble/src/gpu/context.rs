//! The adapter, device and queue every GPU stage runs on.
//!
//! Picking an adapter: `WGPU_BACKEND` (wgpu's own variable: `vulkan`, `gl`, ...) restricts the
//! backends, `TUMBLE_ADAPTER` keeps only adapters whose name contains the given text
//! (case-insensitive). Among those left, a discrete GPU wins over an integrated, virtual or CPU
//! one, and Vulkan / Metal / DX12 win over GL; Mesa's CPU drivers (lavapipe, llvmpipe) are
//! accepted, which is how the tests run every kernel on a machine without a GPU.
//!
//! The device gets the adapter's own limits (not WebGPU's defaults, so large bindings work where
//! the hardware allows them) and the optional features the kernels can use: timestamp queries
//! for the GPU profiler and subgroups for faster variants. Baseline kernels need neither.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use crate::gpu::kernel::{KernelSource, PipelineCache};

/// Everything that can go wrong while talking to the GPU.
#[derive(Clone, Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (backends: {backends}); install a driver, or Mesa's CPU drivers \
         (`apt-get install mesa-vulkan-drivers` for lavapipe), or unset WGPU_BACKEND"
    )]
    NoAdapter { backends: String },
    #[error(
        "no GPU adapter name contains TUMBLE_ADAPTER={wanted:?}; available adapters: {available}"
    )]
    NoMatchingAdapter { wanted: String, available: String },
    #[error("the adapter {adapter:?} refused to create a device: {reason}")]
    RequestDevice { adapter: String, reason: String },
    #[error(
        "{what} needs {needed} bytes in one buffer, but this adapter allows at most {limit} bytes \
         there; use fewer elements or a larger GPU"
    )]
    BufferTooLarge {
        what: &'static str,
        needed: u64,
        limit: u64,
    },
    #[error("reading {what} back from the GPU failed: {reason}")]
    Readback { what: &'static str, reason: String },
    #[error("the GPU did not finish within {seconds} s (device lost or hung)")]
    Timeout { seconds: u64 },
    #[error(
        "the step submitted with the collision planned {what} otherwise than the step did \
         (a bug in tumble; the device's bodies have moved)"
    )]
    Unplanned { what: &'static str },
    #[error(
        "the host's bodies are older than the device's and would overwrite them: an earlier \
         read-back of the device's failed (see the error before this one), or a bug in tumble"
    )]
    StaleBodies,
}

/// How long a blocking wait for the GPU may take before it is reported as a hang. Generous,
/// because a CPU driver runs a large test dispatch in seconds.
pub const WAIT_TIMEOUT: Duration = Duration::from_secs(120);

/// A device and its queue, with what the kernels need to know about the adapter.
/// Cheap to clone: the handles inside are reference-counted.
#[derive(Clone, Debug)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: Arc<wgpu::AdapterInfo>,
    pub(crate) pipelines: Arc<Mutex<PipelineCache>>,
    /// Buffers and bind groups made on the device so far ([`Self::resources_made`]).
    resources_made: Arc<AtomicU64>,
    /// Whether the profilers time the passes on the device ([`Self::set_gpu_timing`]).
    gpu_timing: Arc<AtomicBool>,
}

impl GpuContext {
    /// Picks an adapter as described in the module docs and creates a device on it.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(|_| {}))
    }

    /// Like [`Self::new`], with the device's limits changed by `adjust` first: tests lower
    /// `max_storage_buffer_binding_size` to run the windowed primitives on many small windows,
    /// as an adapter with a small binding limit would.
    pub fn with_limits(adjust: impl FnOnce(&mut wgpu::Limits)) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(adjust))
    }

    async fn new_async(adjust: impl FnOnce(&mut wgpu::Limits)) -> Result<Self, GpuError> {
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        let backends = descriptor.backends;
        let instance = wgpu::Instance::new(descriptor);
        let mut adapters = instance.enumerate_adapters(backends).await;
        let infos: Vec<wgpu::AdapterInfo> = adapters.iter().map(wgpu::Adapter::get_info).collect();
        let wanted = std::env::var("TUMBLE_ADAPTER").ok();
        let index = pick_adapter(&infos, wanted.as_deref(), backends)?;
        let adapter = adapters.swap_remove(index);
        let info = adapter.get_info();
        let mut descriptor = Self::device_descriptor(&adapter);
        adjust(&mut descriptor.required_limits);
        let (device, queue) =
            adapter
                .request_device(&descriptor)
                .await
                .map_err(|error| GpuError::RequestDevice {
                    adapter: info.name.clone(),
                    reason: error.to_string(),
                })?;
        Ok(Self {
            device,
            queue,
            info: Arc::new(info),
            pipelines: Arc::default(),
            resources_made: Arc::default(),
            gpu_timing: Arc::default(),
        })
    }

    /// What the kernels want of a device on `adapter` (the module docs say why), for a caller
    /// that makes the device itself and hands it over with [`Self::from_device`].
    pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
        let optional = wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES
            | wgpu::Features::SUBGROUP;
        wgpu::DeviceDescriptor {
            label: Some("tumble"),
            required_features: adapter.features() & optional,
            required_limits: adapter.limits(),
            ..Default::default()
        }
    }

    /// A context on a device the caller made from [`Self::device_descriptor`], e.g. a viewer's
    /// that presents to a window: the GPU stages of a world given it
    /// ([`World::set_gpu_context`](crate::World::set_gpu_context)) keep their buffers where the
    /// viewer can draw from them.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> Self {
        Self {
            device,
            queue,
            info: Arc::new(info),
            pipelines: Arc::default(),
            resources_made: Arc::default(),
            gpu_timing: Arc::default(),
        }
    }

    /// One context per process, created on first use. Creating a device is slow on the CPU
    /// drivers (about a second on lavapipe), so tests and tools share this one.
    pub fn shared() -> Result<Self, GpuError> {
        static SHARED: OnceLock<Result<GpuContext, GpuError>> = OnceLock::new();
        SHARED.get_or_init(Self::new).clone()
    }

    /// From now on, keep the source of each kernel compiled on this context (none is kept
    /// otherwise), for [`Self::kernel_sources`].
    pub fn record_kernel_sources(&self) {
        self.pipelines
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .sources
            .get_or_insert_default();
    }

    /// The sources of the kernels compiled since [`Self::record_kernel_sources`], in order.
    pub fn kernel_sources(&self) -> Vec<KernelSource> {
        let cache = self
            .pipelines
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        cache.sources.clone().unwrap_or_default()
    }

    /// True for a driver that runs on the CPU (Mesa's lavapipe or llvmpipe): it runs every
    /// kernel, but slower than the CPU executors, so `--device auto` passes it over.
    pub fn is_cpu_driver(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// "name (backend, device type)", for reports.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// How many buffers and bind groups the crate made on this device so far: vectors and
    /// their growth, staging buffers, uniform blocks, a kernel's bindings made again. Commands
    /// recorded ahead of their submission still read the buffers they would be recorded with
    /// now if none was made since (no vector grew, no binding changed): see the solve that
    /// `GpuStages` encodes during the collision's wait.
    pub fn resources_made(&self) -> u64 {
        self.resources_made.load(Ordering::Relaxed)
    }

    /// Makes a buffer, counted by [`Self::resources_made`].
    pub(crate) fn create_buffer(&self, descriptor: &wgpu::BufferDescriptor) -> wgpu::Buffer {
        self.resources_made.fetch_add(1, Ordering::Relaxed);
        self.device.create_buffer(descriptor)
    }

    /// Makes a buffer with its contents, counted by [`Self::resources_made`].
    pub(crate) fn create_buffer_init(
        &self,
        descriptor: &wgpu::util::BufferInitDescriptor,
    ) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.resources_made.fetch_add(1, Ordering::Relaxed);
        self.device.create_buffer_init(descriptor)
    }

    /// Makes a bind group, counted by [`Self::resources_made`].
    pub(crate) fn create_bind_group(
        &self,
        descriptor: &wgpu::BindGroupDescriptor,
    ) -> wgpu::BindGroup {
        self.resources_made.fetch_add(1, Ordering::Relaxed);
        self.device.create_bind_group(descriptor)
    }

    /// Times the GPU stages' passes on the device from now on, or stops: the profiles' `[gpu]`
    /// lines, where the adapter has timestamp queries ([`Self::has_timestamps`]). For every
    /// user of this device (a clone shares the setting). Off at first: the queries and their
    /// read-back took about 0.1 ms of a step on an H100 (BENCHMARKS.md, session 25), which a
    /// step that is not being profiled need not pay.
    pub fn set_gpu_timing(&self, on: bool) {
        self.gpu_timing.store(on, Ordering::Relaxed);
    }

    /// Whether the passes are timed on the device: asked for ([`Self::set_gpu_timing`]) and
    /// possible.
    pub fn times_gpu(&self) -> bool {
        self.gpu_timing.load(Ordering::Relaxed) && self.has_timestamps()
    }

    pub fn has_timestamps(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Whether timestamps can be written between the dispatches of a pass (the profiler's
    /// dispatch timer).
    pub fn has_pass_timestamps(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES)
    }

    pub fn has_subgroups(&self) -> bool {
        self.device.features().contains(wgpu::Features::SUBGROUP)
    }

    /// Records one compute pass with `encode`, submits it and returns without waiting.
    pub fn submit_pass<R>(
        &self,
        label: &str,
        encode: impl FnOnce(&mut wgpu::ComputePass<'_>) -> R,
    ) -> R {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        let result = {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: None,
            });
            encode(&mut pass)
        };
        self.queue.submit([encoder.finish()]);
        result
    }

    /// Blocks until all submitted work is done, or reports a hang after [`WAIT_TIMEOUT`].
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(WAIT_TIMEOUT),
            })
            .map(|_| ())
            .map_err(|_| GpuError::Timeout {
                seconds: WAIT_TIMEOUT.as_secs(),
            })
    }
}

/// Index in `adapters` of the one to use: among those whose name contains `wanted`
/// (case-insensitive), if given, the best by [`adapter_rank`]; the first of equals. Pure, so
/// that the choice is tested without the adapters (`backends` is only for the message).
/// The viewer picks among the adapters that can draw to its window with it.
pub fn pick_adapter(
    adapters: &[wgpu::AdapterInfo],
    wanted: Option<&str>,
    backends: wgpu::Backends,
) -> Result<usize, GpuError> {
    let wanted_lowercase = wanted.map(str::to_lowercase);
    let best = adapters
        .iter()
        .enumerate()
        .filter(|(_, info)| {
            wanted_lowercase
                .as_deref()
                .is_none_or(|text| info.name.to_lowercase().contains(text))
        })
        .min_by_key(|(_, info)| adapter_rank(info))
        .map(|(index, _)| index);
    match (best, wanted) {
        (Some(index), _) => Ok(index),
        (None, Some(text)) if !adapters.is_empty() => Err(GpuError::NoMatchingAdapter {
            wanted: text.to_owned(),
            available: adapters
                .iter()
                .map(|info| format!("{} ({:?})", info.name, info.backend))
                .collect::<Vec<_>>()
                .join(", "),
        }),
        (None, _) => Err(GpuError::NoAdapter {
            backends: format!("{backends:?}"),
        }),
    }
}

/// Preference of an adapter, lower first: discrete > integrated > virtual > CPU, then
/// Vulkan / Metal / DX12 > GL.
fn adapter_rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    (device_rank(info.device_type), backend_rank(info.backend))
}

fn device_rank(device_type: wgpu::DeviceType) -> u8 {
    match device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

fn backend_rank(backend: wgpu::Backend) -> u8 {
    match backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::{AdapterInfo, Backend, Backends, DeviceType};

    fn adapter(name: &str, device_type: DeviceType, backend: Backend) -> AdapterInfo {
        AdapterInfo {
            name: name.to_owned(),
            ..AdapterInfo::new(device_type, backend)
        }
    }

    /// A machine with every kind of adapter, listed worst first so that order cannot win.
    fn machine() -> Vec<AdapterInfo> {
        vec![
            adapter(
                "llvmpipe (LLVM 19.1.7, 256 bits)",
                DeviceType::Cpu,
                Backend::Gl,
            ),
            adapter(
                "llvmpipe (LLVM 19.1.7, 256 bits)",
                DeviceType::Cpu,
                Backend::Vulkan,
            ),
            adapter("Virtio-GPU Venus", DeviceType::VirtualGpu, Backend::Vulkan),
            adapter(
                "Intel(R) UHD Graphics 770",
                DeviceType::IntegratedGpu,
                Backend::Gl,
            ),
            adapter(
                "Intel(R) UHD Graphics 770",
                DeviceType::IntegratedGpu,
                Backend::Vulkan,
            ),
            adapter("NVIDIA H200", DeviceType::DiscreteGpu, Backend::Gl),
            adapter("NVIDIA H200", DeviceType::DiscreteGpu, Backend::Vulkan),
        ]
    }

    fn pick(adapters: &[AdapterInfo], wanted: Option<&str>) -> Result<usize, GpuError> {
        pick_adapter(adapters, wanted, Backends::all())
    }

    #[test]
    fn discrete_beats_integrated_beats_virtual_beats_cpu_and_vulkan_beats_gl() {
        let mut adapters = machine();
        let mut picked = Vec::new();
        while !adapters.is_empty() {
            let index = pick(&adapters, None).unwrap();
            let info = adapters.remove(index);
            picked.push((info.device_type, info.backend));
        }
        assert_eq!(
            picked,
            [
                (DeviceType::DiscreteGpu, Backend::Vulkan),
                (DeviceType::DiscreteGpu, Backend::Gl),
                (DeviceType::IntegratedGpu, Backend::Vulkan),
                (DeviceType::IntegratedGpu, Backend::Gl),
                (DeviceType::VirtualGpu, Backend::Vulkan),
                (DeviceType::Cpu, Backend::Vulkan),
                (DeviceType::Cpu, Backend::Gl),
            ]
        );
    }

    #[test]
    fn equal_adapters_keep_the_enumeration_order() {
        let adapters = [
            adapter("first", DeviceType::DiscreteGpu, Backend::Vulkan),
            adapter("second", DeviceType::DiscreteGpu, Backend::Vulkan),
        ];
        assert_eq!(pick(&adapters, None).unwrap(), 0);
    }

    #[test]
    fn tumble_adapter_keeps_names_containing_it_ignoring_case() {
        let adapters = machine();
        // Only the CPU driver matches: it is chosen over the GPUs, on Vulkan over GL.
        let index = pick(&adapters, Some("LLVMpipe")).unwrap();
        assert_eq!(
            (adapters[index].device_type, adapters[index].backend),
            (DeviceType::Cpu, Backend::Vulkan)
        );
        let index = pick(&adapters, Some("uhd")).unwrap();
        assert_eq!(adapters[index].device_type, DeviceType::IntegratedGpu);
        assert_eq!(
            pick(&adapters, Some("")).unwrap(),
            6,
            "every name contains \"\""
        );
    }

    #[test]
    fn no_matching_adapter_names_what_was_wanted_and_what_there_is() {
        let adapters = machine();
        let error = pick(&adapters[3..5], Some("radeon")).unwrap_err();
        assert!(
            matches!(&error, GpuError::NoMatchingAdapter { wanted, .. } if wanted == "radeon"),
            "{error:?}"
        );
        assert_eq!(
            error.to_string(),
            "no GPU adapter name contains TUMBLE_ADAPTER=\"radeon\"; available adapters: \
             Intel(R) UHD Graphics 770 (Gl), Intel(R) UHD Graphics 770 (Vulkan)"
        );
    }

    /// No adapter at all (no driver, or `WGPU_BACKEND` naming a backend without one): the
    /// message names the backends searched and how to get an adapter, with or without
    /// `TUMBLE_ADAPTER` (there is nothing for it to match).
    #[test]
    fn no_adapter_says_which_backends_and_how_to_get_one() {
        for wanted in [None, Some("nvidia")] {
            let error = pick_adapter(&[], wanted, Backends::GL).unwrap_err();
            assert!(matches!(error, GpuError::NoAdapter { .. }), "{error:?}");
            let message = error.to_string();
            assert!(
                message.starts_with("no GPU adapter found (backends: Backends(GL))")
                    && message.contains("mesa-vulkan-drivers")
                    && message.contains("WGPU_BACKEND"),
                "{message}"
            );
        }
    }
}
