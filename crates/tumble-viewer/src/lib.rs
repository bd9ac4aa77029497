//! `tumble view`: draws a [`tumble::World`] with wgpu, in a window (winit) or headless into
//! PNG files.
//!
//! The pieces, from the world to the pixels:
//! - [`draw::DrawList`] reads poses, shapes and contacts from the world into instance lists
//!   (model matrix + colour per body, grouped by mesh) and ground quads for planes;
//! - [`Renderer`] owns the pipelines and meshes on a device it is given and records a frame
//!   (a shadow map pass, then the scene and the [`overlay`] text drawn with the [`font`]);
//! - [`headless::Offscreen`] renders into a texture and reads it back; the window path
//!   (`window.rs`) renders into a surface and turns keys into [`input::InputState`] changes;
//! - [`pick`] turns a mouse drag on a body into the world's drag (a point constraint).
//!
//! Headless, the viewer draws on the physics' device ([`context::GpuContext`]): after a step
//! on the GPU (`--device gpu`) a compute pass builds the bodies' instance models from the
//! step's device buffers ([`tumble::pipeline::world::DevicePoses`]), with no readback. A
//! window makes the device and hands it to the world (context.rs says why), to the same end.

pub mod camera;
pub mod context;
pub mod draw;
mod error;
pub mod font;
pub mod headless;
pub mod input;
pub mod mesh;
pub mod overlay;
mod particles;
pub mod pick;
pub mod quality;
mod renderer;
mod timing;
mod window;

use crate::draw::DrawSettings;
use crate::input::BatchView;
use crate::overlay::OverlayKind;
use std::path::PathBuf;
use std::time::Instant;

use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::Scene;

pub use camera::Camera;
pub use context::GpuContext;
pub use error::ViewError;
pub use particles::{view_bunnies, view_particles};
pub use quality::Quality;
pub use renderer::{LIGHT_DIRECTION, Renderer};

/// A picture size `WIDTHxHEIGHT` in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSize {
    pub width: u32,
    pub height: u32,
}

impl std::str::FromStr for ImageSize {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let parse = |part: &str| part.trim().parse::<u32>().ok().filter(|&n| n > 0);
        match text.split_once(['x', 'X']) {
            Some((w, h)) => match (parse(w), parse(h)) {
                (Some(width), Some(height)) => Ok(Self { width, height }),
                _ => Err(format!(
                    "{text:?}: width and height must be whole numbers > 0"
                )),
            },
            None => Err(format!("{text:?} is not WIDTHxHEIGHT (e.g. 1280x720)")),
        }
    }
}

/// Options of `tumble view`, after the scene.
#[derive(clap::Args, Clone, Debug)]
pub struct ViewOptions {
    /// Steps to simulate before the first picture (headless) or before the window opens.
    #[arg(long, default_value_t = 0)]
    pub steps: u32,
    /// Render offscreen (no display needed) and write the last step's picture to this PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Render offscreen and write a PNG per step into this folder (frame_00000.png is the
    /// start, frame_NNNNN.png the state after N steps), e.g. for a video.
    #[arg(long)]
    pub frames: Option<PathBuf>,
    /// Picture or window size in pixels.
    #[arg(long, default_value = "1280x720")]
    pub size: ImageSize,
    /// Camera as eye_x,eye_y,eye_z,target_x,target_y,target_z (m); default: frame the bodies.
    #[arg(long, value_parser = camera::parse_camera, allow_hyphen_values = true)]
    pub camera: Option<Camera>,
    /// Headless: colour the bodies by constraint batch (the talk's "colored batches").
    #[arg(long)]
    pub batches: bool,
    /// Draw the contacts and constraints (contact points and normals, joints, the drag): in
    /// the pictures, or in a window as if `c` were pressed.
    #[arg(long)]
    pub contacts: bool,
    /// Draw an overlay over the top-left corner: the profile (stage times of the steps so far,
    /// counts, batch histogram) or the key list; in a window, as if `p` or `h` were pressed.
    #[arg(long, value_enum, default_value = "off")]
    pub overlay: OverlayKind,
    /// Where the step runs: every stage on the CPU, or every stage on the GPU (headless, the
    /// pictures are drawn on that same device).
    #[arg(long, value_enum, default_value = "cpu")]
    pub device: StepDevice,
    /// The renderer's cost knobs, to compare frame rates: `legacy` (the first renderer's
    /// choices) and/or comma-separated changes, `filter=gather4|taps9|tap1|off`,
    /// `shadow-size=TEXELS`, `order=front-to-back|submitted`, `prepass=on|off`. Default:
    /// filter=gather4,shadow-size=1024,order=front-to-back,prepass=off.
    #[arg(long)]
    pub quality: Option<Quality>,
}

/// `--device` of `tumble view`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum StepDevice {
    #[default]
    Cpu,
    Gpu,
}

/// The scene's world with its stages on `device`, the GPU ones on `context` when given (else
/// on the physics' shared device).
fn build_world(
    scene: &Scene,
    device: StepDevice,
    context: Option<tumble::gpu::GpuContext>,
) -> Result<tumble::World, ViewError> {
    let mut world = scene.build()?;
    if let Some(context) = context {
        world.set_gpu_context(context)?;
    }
    if device == StepDevice::Gpu {
        world.set_stage_devices(StageDevices::all(Executor::Gpu))?;
    }
    Ok(world)
}

/// Shows `scene` (named `name` in messages): headless when `--png` or `--frames` is given,
/// else in a window.
pub fn view(name: &str, scene: &Scene, options: &ViewOptions) -> Result<(), ViewError> {
    if options.png.is_some() || options.frames.is_some() {
        return render_headless(scene, options);
    }
    window::run(name, scene, options)
}

/// Steps the scene and writes the pictures `--png` and `--frames` ask for.
fn render_headless(scene: &Scene, options: &ViewOptions) -> Result<(), ViewError> {
    if options.overlay == OverlayKind::Profile {
        // The profile's `[gpu]` lines.
        tumble::gpu::GpuContext::shared()?.set_gpu_timing(true);
    }
    let mut world = build_world(scene, options.device, None)?;
    let context = GpuContext::headless()?;
    let ImageSize { width, height } = options.size;
    let quality = options.quality.unwrap_or_default();
    let mut offscreen = headless::Offscreen::with_quality(&context, width, height, quality)?;
    // The camera frames the bodies as they are in the first picture, and then stays put so
    // that frames of a video line up.
    let mut camera = options.camera;
    let settings = DrawSettings {
        contacts: options.contacts,
        batches: if options.batches {
            BatchView::All
        } else {
            BatchView::Off
        },
        ..DrawSettings::default()
    };
    // Frame times, PNG writing left out: a step and a draw are what a window spends per frame;
    // the read-back is the headless picture's own cost.
    let (mut step_ms, mut draw_ms, mut read_back_ms) = (Vec::new(), Vec::new(), Vec::new());
    // Each pass's GPU times, in the order the passes first ran; `None`: no timestamp queries.
    let mut pass_ms: Option<Vec<(&'static str, Vec<f64>)>> = Some(Vec::new());
    let mut picture = |world: &tumble::World, path: PathBuf| {
        let camera =
            *camera.get_or_insert_with(|| Camera::framing(world, width as f32 / height as f32));
        let overlay = match options.overlay {
            OverlayKind::Off => Vec::new(),
            OverlayKind::Help => overlay::help_lines(),
            OverlayKind::Profile => overlay::profile_lines(
                &world.profiler().report(),
                world.body_count(),
                world.stats(),
            ),
        };
        let image = offscreen.render(&context, world, &camera, settings, &overlay)?;
        let times = &offscreen.last_times;
        draw_ms.push(times.draw_ms);
        read_back_ms.push(times.read_back_ms);
        match (&mut pass_ms, &times.gpu_passes) {
            (Some(passes), Some(frame)) => {
                let known = |passes: &[(&str, Vec<f64>)], name: &str| {
                    passes.iter().position(|(seen, _)| *seen == name)
                };
                for (index, &(name, ms)) in frame.iter().enumerate() {
                    match known(passes, name) {
                        Some(at) => passes[at].1.push(ms),
                        // A pass new in this frame (the pose pass after the first step) goes
                        // before those that follow it here: the line keeps the frame's order.
                        None => {
                            let at = frame[index + 1..]
                                .iter()
                                .filter_map(|&(next, _)| known(passes, next))
                                .min()
                                .unwrap_or(passes.len());
                            passes.insert(at, (name, vec![ms]));
                        }
                    }
                }
            }
            (passes, _) => *passes = None,
        }
        image.save_png(&path)
    };
    if let Some(dir) = &options.frames {
        std::fs::create_dir_all(dir).map_err(|e| ViewError::Write {
            path: dir.clone(),
            reason: e.to_string(),
        })?;
        picture(&world, dir.join("frame_00000.png"))?;
    }
    for step in 1..=options.steps {
        let start = Instant::now();
        world.step();
        step_ms.push(start.elapsed().as_secs_f64() * 1e3);
        if let Some(dir) = &options.frames {
            picture(&world, dir.join(format!("frame_{step:05}.png")))?;
        }
    }
    if let Some(path) = &options.png {
        picture(&world, path.clone())?;
    }
    let mut written = Vec::new();
    if let Some(png) = &options.png {
        written.push(png.display().to_string());
    }
    if let Some(dir) = &options.frames {
        written.push(format!("{} frames in {}", options.steps + 1, dir.display()));
    }
    println!(
        "wrote {}: {width}x{height}, {} bodies after {} steps, on {}",
        written.join(" and "),
        world.body_count(),
        options.steps,
        context.describe()
    );
    if options.frames.is_some() && options.steps > 0 {
        let step = median(&mut step_ms);
        let draw = median(&mut draw_ms);
        println!(
            "per frame (medians): step {step:.2} ms, draw {draw:.2} ms ({:.0} frames/s as a \
             window would run), read back {:.2} ms (headless only; PNG writing not timed)",
            1e3 / (step + draw),
            median(&mut read_back_ms)
        );
        println!("{}", pass_line(pass_ms.as_mut(), &quality));
    }
    Ok(())
}

/// "GPU per pass (medians, quality ...): shadow 0.41 ms, meshes 2.10 ms, ...", or why there are
/// no timestamps.
fn pass_line(passes: Option<&mut Vec<(&'static str, Vec<f64>)>>, quality: &Quality) -> String {
    match passes {
        Some(passes) => {
            let times: Vec<String> = passes
                .iter_mut()
                .map(|(name, samples)| format!("{name} {:.3} ms", median(samples)))
                .collect();
            format!(
                "GPU per pass (medians, quality {quality}): {}",
                times.join(", ")
            )
        }
        None => format!(
            "GPU per pass (quality {quality}): no timestamps (the adapter has no \
             TIMESTAMP_QUERY)"
        ),
    }
}

/// The median of `samples` (sorted in place; the upper middle of an even count); 0 for none.
fn median(samples: &mut [f64]) -> f64 {
    samples.sort_by(f64::total_cmp);
    samples.get(samples.len() / 2).copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_frame_times() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0]), 4.0);
        assert_eq!(median(&mut []), 0.0);
    }
}
