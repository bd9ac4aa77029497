//! The device and queue the viewer draws with.
//!
//! Headless, the viewer draws on the physics' own device
//! ([`tumble::gpu::GpuContext::shared`]): one device per process, so when the step runs on the
//! GPU (`--device gpu`) the renderer reads the poses from the step's buffers. The renderer draws
//! on the device and queue of the context it is given (see [`crate::Renderer::new`]).
//!
//! A window needs an adapter that can present to its surface, and the surface must come from
//! the same `wgpu::Instance` as the device; the physics' shared context makes its own instance
//! and keeps no adapter. So the window makes the device ([`GpuContext::for_surface`], with the
//! limits and features the physics asks for) and hands it to the world
//! ([`tumble::World::set_gpu_context`]): there too, a GPU step is drawn from its buffers.
//!
//! Picking an adapter, as the engine does ([`tumble::gpu::context::pick_adapter`], here over the
//! adapters that can present to the window; DESIGN.md, Testing): `WGPU_BACKEND` restricts
//! the backends, `TUMBLE_ADAPTER` keeps adapters whose name contains the text
//! (case-insensitive). Among those left, a discrete GPU beats an integrated, virtual or CPU one,
//! and Vulkan / Metal / DX12 beat GL. Mesa's CPU driver (lavapipe) is accepted, so pictures can be
//! made on a machine with no GPU.

use crate::error::ViewError;

/// A device and queue for rendering, with the adapter's description for messages.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// A context for offscreen rendering (no window system needed): the physics' shared device.
    pub fn headless() -> Result<Self, ViewError> {
        let physics = tumble::gpu::GpuContext::shared()?;
        Ok(Self {
            device: physics.device,
            queue: physics.queue,
            info: (*physics.info).clone(),
        })
    }

    /// A context on `instance`'s adapters of `backends` that can present to `surface`, and the
    /// adapter it is on (for the surface's configuration).
    pub async fn for_surface(
        instance: &wgpu::Instance,
        backends: wgpu::Backends,
        surface: &wgpu::Surface<'_>,
    ) -> Result<(Self, wgpu::Adapter), ViewError> {
        let mut adapters: Vec<wgpu::Adapter> = instance
            .enumerate_adapters(backends)
            .await
            .into_iter()
            .filter(|adapter| adapter.is_surface_supported(surface))
            .collect();
        let infos: Vec<wgpu::AdapterInfo> = adapters.iter().map(wgpu::Adapter::get_info).collect();
        let wanted = std::env::var("TUMBLE_ADAPTER").ok();
        let index = tumble::gpu::context::pick_adapter(&infos, wanted.as_deref(), backends)?;
        let adapter = adapters.swap_remove(index);
        let info = adapter.get_info();
        // The physics' limits and features: the world's GPU stages will run on this device.
        let (device, queue) = adapter
            .request_device(&tumble::gpu::GpuContext::device_descriptor(&adapter))
            .await
            .map_err(|error| ViewError::RequestDevice {
                adapter: info.name.clone(),
                reason: error.to_string(),
            })?;
        Ok((
            Self {
                device,
                queue,
                info,
            },
            adapter,
        ))
    }

    /// This device as a physics context, for [`tumble::World::set_gpu_context`].
    pub fn physics(&self) -> tumble::gpu::GpuContext {
        tumble::gpu::GpuContext::from_device(
            self.device.clone(),
            self.queue.clone(),
            self.info.clone(),
        )
    }

    /// Runs `make` (creating textures, buffers, shaders, pipelines), turning every error the
    /// device reports meanwhile into [`ViewError::CreateRenderer`] instead of wgpu's default
    /// handler, which panics.
    pub(crate) fn creating<T>(&self, make: impl FnOnce() -> T) -> Result<T, ViewError> {
        use wgpu::ErrorFilter;
        let scopes = [
            ErrorFilter::Validation,
            ErrorFilter::OutOfMemory,
            ErrorFilter::Internal,
        ]
        .map(|filter| self.device.push_error_scope(filter));
        let made = make();
        // Scopes pop in the reverse order of their pushes.
        let errors: Vec<wgpu::Error> = scopes
            .into_iter()
            .rev()
            .filter_map(|scope| pollster::block_on(scope.pop()))
            .collect();
        match errors.first() {
            None => Ok(made),
            Some(error) => Err(ViewError::CreateRenderer {
                adapter: self.describe(),
                reason: error.to_string(),
            }),
        }
    }

    /// "name (backend, device type)", for messages.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }
}
