//! Offscreen rendering: draw into a texture, read it back, write PNGs. Needs no window system,
//! so it runs on a server with Mesa's lavapipe.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use tumble::World;
use tumble::pipeline::world::DevicePoses;

use crate::camera::Camera;
use crate::context::GpuContext;
use crate::draw::{DrawList, DrawSettings};
use crate::error::ViewError;
use crate::quality::Quality;
use crate::renderer::{Renderer, depth_view};

/// sRGB, so the hardware encodes the linear shading for the PNG (which is sRGB by default).
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// A picture read back from the GPU: `width` × `height` RGBA8 (sRGB), rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel in column `x`, row `y` (0 = top).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    pub fn save_png(&self, path: &Path) -> Result<(), ViewError> {
        let error = |reason: String| ViewError::Write {
            path: path.to_path_buf(),
            reason,
        };
        let file = File::create(path).map_err(|e| error(e.to_string()))?;
        let mut encoder = png::Encoder::new(BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| error(e.to_string()))?;
        writer
            .write_image_data(&self.rgba)
            .map_err(|e| error(e.to_string()))?;
        writer.finish().map_err(|e| error(e.to_string()))
    }
}

/// A renderer with its own colour and depth targets and a buffer to read the colour back.
pub struct Offscreen {
    renderer: Renderer,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth: wgpu::TextureView,
    readback: wgpu::Buffer,
    /// Bytes per row in `readback`: a row of pixels padded to wgpu's copy alignment.
    padded_row: u32,
    width: u32,
    height: u32,
    /// How long the last picture took, for frame-rate reports.
    pub last_times: FrameTimes,
}

/// The two parts of a headless picture's time (ms): drawing it (from building the GPU work to
/// the GPU being done), which a window spends too, and reading it back (copying the picture
/// into a buffer the host can map, waiting for that, and copying it out of mapped memory),
/// which a window does not; and the GPU time of each of the drawing's passes.
#[derive(Clone, Debug, Default)]
pub struct FrameTimes {
    pub draw_ms: f64,
    pub read_back_ms: f64,
    /// Each pass's name and GPU time (ms), in the order they ran; `None` where the device has
    /// no timestamp queries.
    pub gpu_passes: Option<Vec<(&'static str, f64)>>,
}

impl Offscreen {
    /// An offscreen target of `width` x `height` pixels drawn with the default [`Quality`].
    pub fn new(context: &GpuContext, width: u32, height: u32) -> Result<Self, ViewError> {
        Self::with_quality(context, width, height, Quality::default())
    }

    /// An offscreen target drawn with `quality`'s choices; [`ViewError::TooLarge`] past the
    /// device's largest texture, and an error too where the device cannot make the renderer
    /// or the targets ([`Renderer::new`]).
    pub fn with_quality(
        context: &GpuContext,
        width: u32,
        height: u32,
        quality: Quality,
    ) -> Result<Self, ViewError> {
        let limit = context.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > limit || height > limit {
            return Err(ViewError::TooLarge {
                adapter: context.describe(),
                width,
                height,
                limit,
            });
        }
        let mut renderer = Renderer::new(context, FORMAT, quality)?;
        renderer.time_passes();
        let device = &context.device;
        let padded_row = (4 * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        // Within the largest texture, a picture may still be more memory than the device has.
        let (color, depth, readback) = context.creating(|| {
            let color = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("offscreen colour"),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("offscreen readback"),
                size: u64::from(padded_row) * u64::from(height),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            (color, depth_view(device, width, height), readback)
        })?;
        Ok(Self {
            last_times: FrameTimes::default(),
            renderer,
            color_view: color.create_view(&Default::default()),
            color,
            depth,
            readback,
            padded_row,
            width,
            height,
        })
    }

    /// Draws `world` as `camera` sees it, with the `overlay` lines (none: no overlay) over the
    /// top-left corner, and reads the picture back. When the world's last step ran on the GPU,
    /// the bodies are drawn from the step's device buffers ([`World::device_poses`]), which
    /// must be on `context`'s device (the world's GPU stages run on
    /// [`GpuContext::headless`]'s unless it was given another).
    pub fn render(
        &mut self,
        context: &GpuContext,
        world: &World,
        camera: &Camera,
        settings: DrawSettings,
        overlay: &[String],
    ) -> Result<Image, ViewError> {
        let mut list = DrawList::build(world, settings);
        list.overlay = overlay.to_vec();
        self.render_list(context, &list, camera, world.device_poses())
    }

    /// Draws `list` as `camera` sees it, the bodies at `device_poses` when given (buffers on
    /// `context`'s device), and reads the picture back.
    pub fn render_list(
        &mut self,
        context: &GpuContext,
        list: &DrawList,
        camera: &Camera,
        device_poses: Option<DevicePoses>,
    ) -> Result<Image, ViewError> {
        let start = std::time::Instant::now();
        let device = &context.device;
        // Validation errors (an adapter that cannot do what we ask) become an error value
        // instead of wgpu's default panic.
        let validated = |scope: wgpu::ErrorScopeGuard| match pollster::block_on(scope.pop()) {
            Some(error) => Err(ViewError::Render {
                adapter: context.describe(),
                reason: error.to_string(),
            }),
            None => Ok(()),
        };
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        self.renderer
            .prepare(list, camera, (self.width, self.height), device_poses);
        let mut encoder = device.create_command_encoder(&Default::default());
        self.renderer
            .encode(&mut encoder, &self.color_view, &self.depth);
        context.queue.submit([encoder.finish()]);
        validated(scope)?;
        // The drawing is waited for on its own, so that its time is what a window's frame
        // spends, without the picture's copy to host memory (8 MB at 1920x1080).
        device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(std::time::Duration::from_secs(60)),
            })
            .map_err(|e| ViewError::Readback(e.to_string()))?;
        let draw_ms = start.elapsed().as_secs_f64() * 1e3;
        let gpu_passes = self.renderer.pass_times()?;

        let read_back = std::time::Instant::now();
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            self.color.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
        context.queue.submit([encoder.finish()]);
        validated(scope)?;
        let image = self.read_back(device)?;
        self.last_times = FrameTimes {
            draw_ms,
            read_back_ms: read_back.elapsed().as_secs_f64() * 1e3,
            gpu_passes,
        };
        Ok(image)
    }

    /// Waits for the picture's copy and copies the picture out.
    fn read_back(&mut self, device: &wgpu::Device) -> Result<Image, ViewError> {
        let slice = self.readback.slice(..);
        map_and_wait(device, &slice)?;
        let mut rgba = Vec::with_capacity(4 * self.width as usize * self.height as usize);
        {
            let mapped = slice
                .get_mapped_range()
                .map_err(|e| ViewError::Readback(e.to_string()))?;
            for row in mapped.chunks_exact(self.padded_row as usize) {
                rgba.extend_from_slice(&row[..4 * self.width as usize]);
            }
        }
        self.readback.unmap();
        Ok(Image {
            width: self.width,
            height: self.height,
            rgba,
        })
    }
}

/// Maps `slice` for reading and waits for the device until it is mapped (or 60 s).
pub(crate) fn map_and_wait(
    device: &wgpu::Device,
    slice: &wgpu::BufferSlice,
) -> Result<(), ViewError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |result| {
        // The receiver lives until after the poll below; a failed send cannot happen.
        let _ = sender.send(result);
    });
    device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: Some(std::time::Duration::from_secs(60)),
        })
        .map_err(|e| ViewError::Readback(e.to_string()))?;
    receiver
        .recv()
        .map_err(|e| ViewError::Readback(e.to_string()))?
        .map_err(|e| ViewError::Readback(e.to_string()))
}
