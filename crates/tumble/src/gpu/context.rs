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

use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use crate::gpu::kernel::PipelineCache;

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
         per storage binding; use fewer elements or a larger GPU"
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
}

impl GpuContext {
    /// Picks an adapter as described in the module docs and creates a device on it.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<Self, GpuError> {
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        let backends = descriptor.backends;
        let instance = wgpu::Instance::new(descriptor);
        let adapters = instance.enumerate_adapters(backends).await;
        let wanted = std::env::var("TUMBLE_ADAPTER").ok();
        let adapter = pick_adapter(adapters, wanted.as_deref(), backends)?;
        let info = adapter.get_info();
        let (device, queue) = adapter
            .request_device(&Self::device_descriptor(&adapter))
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
        })
    }

    /// What the kernels want of a device on `adapter` (the module docs say why), for a caller
    /// that makes the device itself and hands it over with [`Self::from_device`].
    pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
        let optional = wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
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
        }
    }

    /// One context per process, created on first use. Creating a device is slow on the CPU
    /// drivers (about a second on lavapipe), so tests and tools share this one.
    pub fn shared() -> Result<Self, GpuError> {
        static SHARED: OnceLock<Result<GpuContext, GpuError>> = OnceLock::new();
        SHARED.get_or_init(Self::new).clone()
    }

    /// "name (backend, device type)", for reports.
    /// True for a driver that runs on the CPU (Mesa's lavapipe or llvmpipe): it runs every
    /// kernel, but slower than the CPU executors, so `--device auto` passes it over.
    pub fn is_cpu_driver(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    pub fn has_timestamps(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
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

/// Best adapter by device type, then backend; `wanted` filters by name first.
fn pick_adapter(
    adapters: Vec<wgpu::Adapter>,
    wanted: Option<&str>,
    backends: wgpu::Backends,
) -> Result<wgpu::Adapter, GpuError> {
    let names = || {
        let list: Vec<String> = adapters
            .iter()
            .map(|adapter| {
                let info = adapter.get_info();
                format!("{} ({:?})", info.name, info.backend)
            })
            .collect();
        if list.is_empty() {
            "none".to_owned()
        } else {
            list.join(", ")
        }
    };
    let available = names();
    let candidates: Vec<wgpu::Adapter> = match wanted {
        Some(text) => {
            let text = text.to_lowercase();
            adapters
                .into_iter()
                .filter(|adapter| adapter.get_info().name.to_lowercase().contains(&text))
                .collect()
        }
        None => adapters,
    };
    if let (Some(text), true) = (wanted, candidates.is_empty()) {
        return Err(GpuError::NoMatchingAdapter {
            wanted: text.to_owned(),
            available,
        });
    }
    candidates
        .into_iter()
        .min_by_key(|adapter| adapter_rank(&adapter.get_info()))
        .ok_or_else(|| GpuError::NoAdapter {
            backends: format!("{backends:?}"),
        })
}

/// Preference of an adapter, lower first: discrete > integrated > virtual > CPU, then
/// Vulkan / Metal / DX12 > GL. The viewer ranks the adapters that can draw to its window with it.
pub fn adapter_rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
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
