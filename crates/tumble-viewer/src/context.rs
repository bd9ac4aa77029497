//! The viewer's own adapter, device and queue.
//!
//! The renderer only borrows a `wgpu::Device` and `wgpu::Queue` (see [`crate::Renderer::new`]),
//! so once the physics step runs on the GPU this context can be swapped for the physics one and
//! poses drawn straight from its buffers.
//!
//! Picking an adapter, as the engine's tests do (DESIGN.md, Testing): `WGPU_BACKEND` restricts
//! the backends, `TUMBLE_ADAPTER` keeps adapters whose name contains the text
//! (case-insensitive). Among those left, a discrete GPU beats an integrated, virtual or CPU one,
//! and Vulkan / Metal / DX12 beat GL. Mesa's CPU driver (lavapipe) is accepted, so pictures can be
//! made on a machine with no GPU.

use crate::error::ViewError;

/// A device and queue for rendering, with the adapter's description for messages.
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// A context for offscreen rendering (no window system needed).
    pub fn headless() -> Result<Self, ViewError> {
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        let backends = descriptor.backends;
        let instance = wgpu::Instance::new(descriptor);
        pollster::block_on(Self::with_instance(&instance, backends, None))
    }

    /// A context on `instance`'s adapters of `backends` that can present to `surface`, when one
    /// is given.
    pub async fn with_instance(
        instance: &wgpu::Instance,
        backends: wgpu::Backends,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self, ViewError> {
        let adapters: Vec<wgpu::Adapter> = instance
            .enumerate_adapters(backends)
            .await
            .into_iter()
            .filter(|adapter| surface.is_none_or(|surface| adapter.is_surface_supported(surface)))
            .collect();
        let wanted = std::env::var("TUMBLE_ADAPTER").ok();
        let adapter = pick_adapter(adapters, wanted.as_deref(), backends)?;
        let info = adapter.get_info();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("tumble-viewer"),
                required_limits: wgpu::Limits::downlevel_defaults()
                    .using_resolution(adapter.limits()),
                ..Default::default()
            })
            .await
            .map_err(|error| ViewError::RequestDevice {
                adapter: info.name.clone(),
                reason: error.to_string(),
            })?;
        Ok(Self {
            adapter,
            device,
            queue,
            info,
        })
    }

    /// "name (backend, device type)", for messages.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }
}

/// Best adapter by device type, then backend; `wanted` filters by name first.
fn pick_adapter(
    adapters: Vec<wgpu::Adapter>,
    wanted: Option<&str>,
    backends: wgpu::Backends,
) -> Result<wgpu::Adapter, ViewError> {
    let available: Vec<String> = adapters
        .iter()
        .map(|adapter| {
            let info = adapter.get_info();
            format!("{} ({:?})", info.name, info.backend)
        })
        .collect();
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
    if let (Some(text), true) = (wanted, candidates.is_empty() && !available.is_empty()) {
        return Err(ViewError::NoMatchingAdapter {
            wanted: text.to_owned(),
            available: available.join(", "),
        });
    }
    candidates
        .into_iter()
        .min_by_key(|adapter| tumble::gpu::context::adapter_rank(&adapter.get_info()))
        .ok_or_else(|| ViewError::NoAdapter {
            backends: format!("{backends:?}"),
        })
}
