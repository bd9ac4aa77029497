//! The window: a winit event loop that steps what it shows (a rigid-body world, or the particle
//! demo: [`Shown`]), draws it into the window's surface and feeds keys and the mouse to
//! [`InputState`]. The profile overlay (`p`) is refreshed about
//! once a second, the help overlay (`h`) lists the keys, and a status line is kept in the window
//! title.

use std::sync::Arc;
use std::time::{Duration, Instant};

use tumble::World;
use tumble::pipeline::devices::StageDevices;
use tumble::pipeline::world::DevicePoses;
use tumble::scene::Scene;
use tumble::stages::batching::Batcher;
use winit::application::ApplicationHandler;
use winit::dpi::{LogicalSize, PhysicalPosition};
use winit::event::{ElementState, MouseButton as WinitButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key as WinitKey, NamedKey};
use winit::window::{Window, WindowId};

use crate::camera::Camera;
use crate::context::GpuContext;
use crate::draw::{DrawList, DrawSettings};
use crate::error::ViewError;
use crate::input::{Action, BatchView, Executor, HELP, InputState, Key, MouseButton};
use crate::overlay::{self, OverlayKind};
use crate::quality::Quality;
use crate::renderer::{Renderer, depth_view};
use crate::{ImageSize, StepDevice, ViewOptions};

/// How often the title's status line and the profile overlay are refreshed.
const STATUS_PERIOD: Duration = Duration::from_millis(500);
const PROFILE_PERIOD: Duration = Duration::from_secs(1);
/// Camera distance factor per mouse wheel line.
const WHEEL_ZOOM: f32 = 0.9;

/// What a window steps and draws: a rigid-body world ([`Rigid`]) or the particle demo
/// (particles.rs). The keys, the camera and the overlays are the window's; what a key means
/// for the simulation is asked of this.
pub(crate) trait Shown {
    /// Moves the GPU work onto the window's device (once it exists), where the renderer reads
    /// what the step leaves.
    fn use_device(&mut self, context: tumble::gpu::GpuContext) -> Result<(), ViewError>;
    /// Back to the start (space).
    fn reset(&mut self) -> Result<(), ViewError>;
    fn step(&mut self) -> Result<(), ViewError>;
    /// `u`: the solver (the particle demo: its whole step) on the CPU or the GPU.
    fn put_solver_on(&mut self, executor: Executor);
    /// `d`: the batcher from the next step.
    fn use_batcher(&mut self, batcher: Batcher);
    fn draw_list(&mut self, settings: DrawSettings) -> Result<DrawList, ViewError>;
    /// The step's pose buffers on the window's device, when the step runs there.
    fn device_poses(&self) -> Option<DevicePoses<'_>>;
    /// The profile overlay's lines for the steps since the last call, whose timings restart.
    fn take_profile(&mut self) -> Vec<String>;
    /// The title's counts, e.g. "286 bodies, 1328 contacts, 8 batches".
    fn status(&self) -> String;
    /// Constraint batches of the last step (for `b`).
    fn batch_count(&self) -> usize;
    /// The world whose bodies the mouse picks, if there is one.
    fn world(&mut self) -> Option<&mut World>;
    /// The help overlay's text (`h`): the keys that mean something here.
    fn help(&self) -> &'static str;
}

/// A rigid-body scene in a window.
struct Rigid<'a> {
    scene: &'a Scene,
    /// Where the step runs after a reset, before the `u` key moves the solver.
    device: StepDevice,
    world: World,
    /// The window's device, once it exists: a reset builds the world's GPU stages there.
    context: Option<tumble::gpu::GpuContext>,
}

impl Shown for Rigid<'_> {
    fn use_device(&mut self, context: tumble::gpu::GpuContext) -> Result<(), ViewError> {
        self.world.set_gpu_context(context.clone())?;
        if self.device == StepDevice::Gpu {
            self.world
                .set_stage_devices(StageDevices::all(tumble::pipeline::devices::Executor::Gpu))?;
        }
        self.context = Some(context);
        Ok(())
    }

    fn reset(&mut self) -> Result<(), ViewError> {
        self.world = crate::build_world(self.scene, self.device, self.context.clone())?;
        Ok(())
    }

    fn step(&mut self) -> Result<(), ViewError> {
        self.world.step();
        Ok(())
    }

    /// The talk's `u` key: the solver stage on the CPU or the GPU (the other stages stay).
    fn put_solver_on(&mut self, executor: Executor) {
        let mut devices = self.world.stage_devices();
        let (on, name) = match executor {
            Executor::Cpu => (tumble::pipeline::devices::Executor::Cpu, "CPU"),
            Executor::Gpu => (tumble::pipeline::devices::Executor::Gpu, "GPU"),
        };
        devices.set(tumble::pipeline::devices::Stage::Batching, on);
        devices.set(tumble::pipeline::devices::Stage::Solver, on);
        match self.world.set_stage_devices(devices) {
            Ok(()) => println!("solver on the {name}"),
            Err(error) => println!("the solver stays where it was: {error}"),
        }
    }

    fn use_batcher(&mut self, batcher: Batcher) {
        let config = tumble::StepConfig {
            batcher,
            ..*self.world.config()
        };
        match self.world.set_config(config) {
            Ok(()) => println!("batcher: {batcher}"),
            Err(error) => println!("the batcher stays: {error}"),
        }
    }

    fn draw_list(&mut self, settings: DrawSettings) -> Result<DrawList, ViewError> {
        Ok(DrawList::build(&self.world, settings))
    }

    fn device_poses(&self) -> Option<DevicePoses<'_>> {
        self.world.device_poses()
    }

    fn take_profile(&mut self) -> Vec<String> {
        let lines = overlay::profile_lines(
            &self.world.profiler().report(),
            self.world.body_count(),
            self.world.stats(),
        );
        self.world.profiler_mut().reset();
        lines
    }

    fn status(&self) -> String {
        let stats = self.world.stats();
        format!(
            "{} bodies, {} contacts, {} batches",
            self.world.body_count(),
            stats.contacts,
            stats.batch_histogram.len()
        )
    }

    fn batch_count(&self) -> usize {
        self.world.stats().batch_histogram.len()
    }

    fn help(&self) -> &'static str {
        crate::input::HELP
    }

    fn world(&mut self) -> Option<&mut World> {
        Some(&mut self.world)
    }
}

/// Opens a window on `scene` and runs until it is closed or `q` is pressed.
pub fn run(name: &str, scene: &Scene, options: &ViewOptions) -> Result<(), ViewError> {
    let event_loop = event_loop(name)?;
    // Steps before the window opens run their GPU stages on the physics' shared device. With
    // none, the stages are made once, on the window's device (`use_device`): making them
    // compiles every kernel, 3.5 s on lavapipe (falling-boxes, --steps 0).
    let early = match options.steps {
        0 => StepDevice::Cpu,
        _ => options.device,
    };
    let mut world = crate::build_world(scene, early, None)?;
    for _ in 0..options.steps {
        world.step();
    }
    let aspect = options.size.width as f32 / options.size.height as f32;
    let camera = options
        .camera
        .unwrap_or_else(|| Camera::framing(&world, aspect));
    let rigid = Rigid {
        scene,
        device: options.device,
        world,
        context: None,
    };
    show(event_loop, name, Box::new(rigid), camera, options)
}

/// The event loop a window of the scene `name` opens in, made before anything is built or
/// stepped: where no window can open (no display, or one that does not answer), a clear error
/// comes at once.
pub(crate) fn event_loop(name: &str) -> Result<EventLoop<()>, ViewError> {
    let no_display = |reason: String| ViewError::NoDisplay {
        scene: name.to_owned(),
        reason,
    };
    if let Some(reason) = missing_display() {
        return Err(no_display(reason));
    }
    EventLoop::new().map_err(|e| no_display(e.to_string()))
}

/// Opens a window of `event_loop` on `shown` (stepped as far as `--steps` asks), seen from
/// `camera`, and runs until it is closed or `q` is pressed.
pub(crate) fn show(
    event_loop: EventLoop<()>,
    name: &str,
    shown: Box<dyn Shown + '_>,
    camera: Camera,
    options: &ViewOptions,
) -> Result<(), ViewError> {
    event_loop.set_control_flow(ControlFlow::Poll);
    // The display handle lets the GL backend present too (Vulkan does not need it).
    let descriptor = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(
        event_loop.owned_display_handle(),
    ));
    let backends = descriptor.backends;
    let instance = wgpu::Instance::new(descriptor);
    println!("{HELP}");
    // The window's size in pixels is known once it opens (`resumed`).
    let mut input = InputState::new(camera, (options.size.width, options.size.height));
    if options.device == StepDevice::Gpu {
        input.solver = Executor::Gpu;
    }
    // --overlay and --contacts open the window with them on, as if their key had been pressed.
    input.help = options.overlay == OverlayKind::Help;
    input.profile = options.overlay == OverlayKind::Profile;
    input.contacts = options.contacts;
    let mut app = App {
        name: name.to_owned(),
        shown,
        input,
        size: options.size,
        quality: options.quality.unwrap_or_default(),
        instance,
        backends,
        view: None,
        cursor: (0.0, 0.0),
        error: None,
        frames: 0,
        last_status: Instant::now(),
        last_profile: Instant::now(),
        profile_lines: Vec::new(),
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewError::Window(e.to_string()))?;
    app.error.map_or(Ok(()), Err)
}

/// Why no window can open here, if there is no display to open it on. winit would fail too,
/// but with a message that does not say what to do instead.
fn missing_display() -> Option<String> {
    if !cfg!(all(
        unix,
        not(target_os = "macos"),
        not(target_os = "android")
    )) {
        return None;
    }
    let set = |name: &str| std::env::var_os(name).is_some_and(|value| !value.is_empty());
    (!set("DISPLAY") && !set("WAYLAND_DISPLAY"))
        .then(|| "DISPLAY and WAYLAND_DISPLAY are not set".to_owned())
}

/// What exists once the window is open.
struct WindowView {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    context: GpuContext,
    renderer: Renderer,
    depth: wgpu::TextureView,
}

struct App<'a> {
    name: String,
    shown: Box<dyn Shown + 'a>,
    input: InputState,
    size: ImageSize,
    quality: Quality,
    instance: wgpu::Instance,
    backends: wgpu::Backends,
    view: Option<WindowView>,
    cursor: (f32, f32),
    /// The error that ended the event loop, returned by [`run`].
    error: Option<ViewError>,
    /// Frames drawn since the last status update.
    frames: u32,
    last_status: Instant,
    last_profile: Instant,
    /// The profile overlay's text, as of the last refresh.
    profile_lines: Vec<String>,
}

impl App<'_> {
    fn open(&self, event_loop: &ActiveEventLoop) -> Result<WindowView, ViewError> {
        let attributes = Window::default_attributes()
            .with_title(format!("tumble view {}", self.name))
            .with_inner_size(LogicalSize::new(self.size.width, self.size.height));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| ViewError::Window(e.to_string()))?,
        );
        let surface = self
            .instance
            .create_surface(window.clone())
            .map_err(|e| ViewError::Surface(e.to_string()))?;
        let (context, adapter) = pollster::block_on(GpuContext::for_surface(
            &self.instance,
            self.backends,
            &surface,
        ))?;
        let size = window.inner_size();
        let (width, height) = (size.width.max(1), size.height.max(1));
        let mut config = surface
            .get_default_config(&adapter, width, height)
            .ok_or_else(|| {
                ViewError::Surface(format!(
                    "the adapter {} cannot present to this window",
                    context.describe()
                ))
            })?;
        // The shaders write linear colour: an sRGB target encodes it for the screen.
        let capabilities = surface.get_capabilities(&adapter);
        if let Some(&srgb) = capabilities.formats.iter().find(|f| f.is_srgb()) {
            config.format = srgb;
        }
        config.present_mode = wgpu::PresentMode::AutoVsync;
        surface.configure(&context.device, &config);
        let renderer = Renderer::new(&context, config.format, self.quality)?;
        let depth = depth_view(&context.device, width, height);
        println!("drawing on {}", context.describe());
        Ok(WindowView {
            window,
            surface,
            config,
            context,
            renderer,
            depth,
        })
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, error: ViewError) {
        self.error = Some(error);
        event_loop.exit();
    }

    fn act(&mut self, event_loop: &ActiveEventLoop, action: Action) {
        let done = match action {
            Action::None => Ok(()),
            // The rebuilt simulation keeps the solver and batcher the keys chose.
            Action::Reset => self.shown.reset().map(|()| {
                self.shown.put_solver_on(self.input.solver);
                self.shown.use_batcher(self.input.batcher);
            }),
            Action::Solver(executor) => {
                self.shown.put_solver_on(executor);
                Ok(())
            }
            Action::Step => self.shown.step(),
            Action::Profile => {
                self.refresh_profile();
                Ok(())
            }
            Action::Batcher(batcher) => {
                self.shown.use_batcher(batcher);
                Ok(())
            }
            Action::Quit => {
                event_loop.exit();
                Ok(())
            }
        };
        if let Err(error) = done {
            self.fail(event_loop, error);
        }
    }

    /// The talk's profile screen: stage times, counts and the batch histogram. The timings
    /// restart after each refresh, so each covers the frames since the last.
    fn refresh_profile(&mut self) {
        self.profile_lines = self.shown.take_profile();
        self.last_profile = Instant::now();
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop) {
        if self.input.running
            && let Err(error) = self.shown.step()
        {
            self.fail(event_loop, error);
            return;
        }
        self.input.batch_count = self.shown.batch_count();
        let Some(view) = &mut self.view else {
            return;
        };
        let frame = match view.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame)
            | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            // Minimized or busy: skip this frame.
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return;
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                view.surface.configure(&view.context.device, &view.config);
                return;
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                let error = ViewError::Surface("the surface texture failed validation".into());
                self.fail(event_loop, error);
                return;
            }
        };
        let mut list = match self.shown.draw_list(self.input.draw_settings()) {
            Ok(list) => list,
            Err(error) => {
                self.fail(event_loop, error);
                return;
            }
        };
        if self.input.help {
            list.overlay = overlay::lines_of(self.shown.help());
        } else if self.input.profile {
            list.overlay.clone_from(&self.profile_lines);
        }
        let (width, height) = (view.config.width, view.config.height);
        // The step's GPU stages run on this device (resumed), so a GPU step is drawn from its
        // buffers.
        view.renderer.prepare(
            &list,
            &self.input.camera,
            (width, height),
            self.shown.device_poses(),
        );
        let target = frame.texture.create_view(&Default::default());
        let mut encoder = view
            .context
            .device
            .create_command_encoder(&Default::default());
        view.renderer.encode(&mut encoder, &target, &view.depth);
        view.context.queue.submit([encoder.finish()]);
        view.window.pre_present_notify();
        view.context.queue.present(frame);

        self.frames += 1;
        let elapsed = self.last_status.elapsed();
        if elapsed >= STATUS_PERIOD {
            let fps = self.frames as f32 / elapsed.as_secs_f32();
            view.window
                .set_title(&title(&self.name, &self.shown.status(), fps, &self.input));
            self.frames = 0;
            self.last_status = Instant::now();
        }
        if self.input.profile && self.last_profile.elapsed() >= PROFILE_PERIOD {
            self.refresh_profile();
        }
    }
}

/// The window's title: the scene, its counts, the frame rate, and what the keys and the mouse
/// changed that the picture does not say (paused, which single batch `b` shows, which body the
/// mouse drags; scripts/window-smoke.sh reads the last).
fn title(name: &str, status: &str, fps: f32, input: &InputState) -> String {
    let mut title = format!("tumble view {name}: {status}, {fps:.0} fps");
    if !input.running {
        title.push_str(", paused");
    }
    if let BatchView::One(batch) = input.batches {
        title.push_str(&format!(", batch {batch} of {} shown", input.batch_count));
    }
    if let Some(grab) = input.grab() {
        title.push_str(&format!(", dragging body {}", grab.body.index()));
    }
    title.push_str("  (h: help)");
    title
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.view.is_none() {
            // The world's GPU stages move to the window's device, where the renderer reads
            // the poses they leave, and time their passes there for the profile (`p`).
            let opened = self.open(event_loop).and_then(|view| {
                let physics = view.context.physics();
                physics.set_gpu_timing(true);
                self.shown.use_device(physics)?;
                Ok(view)
            });
            match opened {
                Ok(view) => {
                    self.input.viewport = (view.config.width, view.config.height);
                    self.view = Some(view);
                }
                Err(error) => self.fail(event_loop, error),
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let (Some(view), true) = (&mut self.view, size.width > 0 && size.height > 0) {
                    view.config.width = size.width;
                    view.config.height = size.height;
                    view.surface.configure(&view.context.device, &view.config);
                    view.depth = depth_view(&view.context.device, size.width, size.height);
                    self.input.viewport = (size.width, size.height);
                }
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                if let Some(key) = translate(&event.logical_key) {
                    let action = self.input.key(key);
                    self.act(event_loop, action);
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                if let Some(button) = translate_button(button) {
                    let pressed = state == ElementState::Pressed;
                    self.input
                        .mouse_button(button, pressed, self.cursor, self.shown.world());
                }
            }
            WindowEvent::CursorMoved {
                position: PhysicalPosition { x, y },
                ..
            } => {
                self.cursor = (x as f32, y as f32);
                self.input.cursor_moved(self.cursor, self.shown.world());
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, lines) => lines,
                    MouseScrollDelta::PixelDelta(pixels) => pixels.y as f32 / 40.0,
                };
                self.input.camera.zoom(WHEEL_ZOOM.powf(lines));
            }
            WindowEvent::RedrawRequested => self.redraw(event_loop),
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(view) = &self.view {
            view.window.request_redraw();
        }
    }
}

/// winit's logical key to the viewer's (layout-aware: `z` is where the user's layout puts it).
fn translate(key: &WinitKey) -> Option<Key> {
    match key {
        WinitKey::Named(NamedKey::Space) => Some(Key::Space),
        WinitKey::Named(NamedKey::Escape) => Some(Key::Escape),
        WinitKey::Named(NamedKey::ArrowLeft) => Some(Key::Left),
        WinitKey::Named(NamedKey::ArrowRight) => Some(Key::Right),
        WinitKey::Named(NamedKey::ArrowUp) => Some(Key::Up),
        WinitKey::Named(NamedKey::ArrowDown) => Some(Key::Down),
        WinitKey::Character(text) => text
            .chars()
            .next()
            .map(|c| Key::Char(c.to_ascii_lowercase())),
        _ => None,
    }
}

fn translate_button(button: WinitButton) -> Option<MouseButton> {
    match button {
        WinitButton::Left => Some(MouseButton::Left),
        WinitButton::Right => Some(MouseButton::Right),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn winit_keys_translate_to_viewer_keys() {
        assert_eq!(
            translate(&WinitKey::Character("Z".into())),
            Some(Key::Char('z'))
        );
        assert_eq!(
            translate(&WinitKey::Character("b".into())),
            Some(Key::Char('b'))
        );
        assert_eq!(
            translate(&WinitKey::Named(NamedKey::Space)),
            Some(Key::Space)
        );
        assert_eq!(
            translate(&WinitKey::Named(NamedKey::ArrowUp)),
            Some(Key::Up)
        );
        assert_eq!(
            translate(&WinitKey::Named(NamedKey::Escape)),
            Some(Key::Escape)
        );
        assert_eq!(translate(&WinitKey::Named(NamedKey::Shift)), None);
    }

    #[test]
    fn the_title_says_what_the_picture_does_not() {
        let camera = Camera::look_at(glam::Vec3::new(0.0, 2.0, 10.0), glam::Vec3::ZERO);
        let mut input = InputState::new(camera, (800, 600));
        let status = "2 bodies, 4 contacts, 3 batches";
        assert_eq!(
            title("cube", status, 59.6, &input),
            "tumble view cube: 2 bodies, 4 contacts, 3 batches, 60 fps  (h: help)"
        );
        input.key(Key::Char('i'));
        input.batch_count = 3;
        input.key(Key::Char('b'));
        input.key(Key::Char('b'));
        input.key(Key::Char('b'));
        assert_eq!(
            title("cube", status, 12.0, &input),
            "tumble view cube: 2 bodies, 4 contacts, 3 batches, 12 fps, paused, batch 1 of 3 \
             shown  (h: help)"
        );

        // A box in front of the camera, picked at the centre of the window.
        let mut world = tumble::World::new(tumble::StepConfig::default()).unwrap();
        let cube = world
            .add_body(tumble::BodyDesc::dynamic(tumble::Shape::cuboid(
                glam::Vec3::splat(0.5),
            )))
            .unwrap();
        input.mouse_button(MouseButton::Left, true, (400.0, 300.0), Some(&mut world));
        assert!(
            title("cube", status, 12.0, &input)
                .ends_with(&format!(", dragging body {}  (h: help)", cube.index())),
            "{}",
            title("cube", status, 12.0, &input)
        );
    }

    #[test]
    fn winit_buttons_translate_to_viewer_buttons() {
        assert_eq!(translate_button(WinitButton::Left), Some(MouseButton::Left));
        assert_eq!(
            translate_button(WinitButton::Right),
            Some(MouseButton::Right)
        );
        assert_eq!(translate_button(WinitButton::Middle), None);
    }
}
