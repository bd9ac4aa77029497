//! `tumble view particles` and `tumble view bunnies`: the talk's particle demos (free
//! particles, in a window or headless; rigid bodies made of particles, headless). Each particle
//! is drawn as a sphere of its radius on the floor of its box, from positions read back after
//! each step; on `--device gpu` the particles step on the device the pictures are drawn on.

use std::path::PathBuf;

use glam::Vec3;
use tumble::World;
use tumble::math::Aabb;
use tumble::particles::{
    ParticleConfig, ParticleDevice, ParticleError, ParticleSystem, RigidConfig, RigidSystem,
};
use tumble::pipeline::world::DevicePoses;
use tumble::profile::ProfileReport;
use tumble::profile::Profiler;
use tumble::stages::batching::Batcher;

use crate::camera::Camera;
use crate::context::GpuContext;
use crate::draw::{DrawList, DrawSettings};
use crate::error::ViewError;
use crate::headless::Offscreen;
use crate::input::{Executor, PARTICLE_HELP};
use crate::overlay::{self, OverlayKind};
use crate::window::{self, Shown};
use crate::{ImageSize, StepDevice, ViewOptions};

/// Shows the particle demo of `config`, stepped on `options.device`: headless when `--png` or
/// `--frames` is given (writing those pictures), else in a window.
pub fn view_particles(config: ParticleConfig, options: &ViewOptions) -> Result<(), ViewError> {
    refuse_rigid_body_flags(options)?;
    if options.png.is_none() && options.frames.is_none() {
        return view_in_window(config, options);
    }
    view_headless(options, |device| {
        ParticleSystem::new(config, device).map(Demo::Particles)
    })
}

/// Steps the rigid particle bodies of `config` (the `bunnies` scene) as [`view_particles`]
/// does the demo, headless only.
pub fn view_bunnies(config: RigidConfig, options: &ViewOptions) -> Result<(), ViewError> {
    refuse_rigid_body_flags(options)?;
    if options.png.is_none() && options.frames.is_none() {
        return Err(ViewError::HeadlessOnly {
            scene: "bunnies".into(),
        });
    }
    view_headless(options, |device| {
        RigidSystem::new(&config, device).map(Demo::Rigid)
    })
}

/// Batch colours, contacts and joints come from a rigid-body world's solver; the particle
/// systems have none of them (their bodies' particles push by springs, with no constraints).
fn refuse_rigid_body_flags(options: &ViewOptions) -> Result<(), ViewError> {
    match (options.batches, options.contacts) {
        (true, _) => Err(ViewError::NotForParticles { flag: "--batches" }),
        (_, true) => Err(ViewError::NotForParticles { flag: "--contacts" }),
        _ => Ok(()),
    }
}

/// Either particle system, as the pictures need it.
enum Demo {
    Particles(ParticleSystem),
    Rigid(RigidSystem),
}

impl Demo {
    fn config(&self) -> &ParticleConfig {
        match self {
            Self::Particles(system) => system.config(),
            Self::Rigid(system) => system.config(),
        }
    }

    fn step(&mut self) -> Result<(), ParticleError> {
        match self {
            Self::Particles(system) => system.step(),
            Self::Rigid(system) => system.step(),
        }
    }

    fn positions(&mut self) -> Result<Vec<[f32; 3]>, ParticleError> {
        match self {
            Self::Particles(system) => system.positions(),
            Self::Rigid(system) => system.positions(),
        }
    }

    fn device_name(&self) -> String {
        match self {
            Self::Particles(system) => system.device_name(),
            Self::Rigid(system) => system.device_name(),
        }
    }

    fn profiler(&self) -> &Profiler {
        match self {
            Self::Particles(system) => system.profiler(),
            Self::Rigid(system) => system.profiler(),
        }
    }
}

/// Steps the system `build` makes on `options.device` and writes the pictures `--png` and
/// `--frames` ask for.
fn view_headless(
    options: &ViewOptions,
    build: impl FnOnce(ParticleDevice) -> Result<Demo, ParticleError>,
) -> Result<(), ViewError> {
    let context = GpuContext::headless()?;
    let device = match options.device {
        StepDevice::Cpu => ParticleDevice::Cpu,
        StepDevice::Gpu => ParticleDevice::Gpu(context.physics()),
    };
    let mut system = build(device)?;
    let container = container(system.config());
    let radius = system.config().radius;
    let ImageSize { width, height } = options.size;
    let quality = options.quality.unwrap_or_default();
    let mut offscreen = Offscreen::with_quality(&context, width, height, quality)?;
    // The whole box is framed, so frames of a video line up while the particles spread.
    let camera = options
        .camera
        .unwrap_or_else(|| Camera::framing_boxes(&[container], width as f32 / height as f32));
    let mut picture = |system: &mut Demo, path: PathBuf| {
        let positions = system.positions()?;
        let mut list = match system {
            Demo::Particles(_) => DrawList::particles(&positions, radius, container),
            // A body's particles in its colour.
            Demo::Rigid(rigid) => {
                let bodies = rigid.particle_bodies();
                let colour_of = |index: usize| bodies[index] as usize;
                DrawList::particles_coloured(&positions, colour_of, radius, container)
            }
        };
        list.overlay = match options.overlay {
            OverlayKind::Off => Vec::new(),
            OverlayKind::Help => overlay::lines_of(PARTICLE_HELP),
            OverlayKind::Profile => {
                profile_lines(&system.profiler().report(), system.config().count)
            }
        };
        offscreen
            .render_list(&context, &list, &camera, None)?
            .save_png(&path)
    };
    if let Some(dir) = &options.frames {
        std::fs::create_dir_all(dir).map_err(|e| ViewError::Write {
            path: dir.clone(),
            reason: e.to_string(),
        })?;
        picture(&mut system, dir.join("frame_00000.png"))?;
    }
    for step in 1..=options.steps {
        system.step()?;
        if let Some(dir) = &options.frames {
            picture(&mut system, dir.join(format!("frame_{step:05}.png")))?;
        }
    }
    if let Some(path) = &options.png {
        picture(&mut system, path.clone())?;
    }
    println!(
        "wrote {}: {width}x{height}, {} particles after {} steps on {}",
        options
            .png
            .iter()
            .chain(&options.frames)
            .map(|path| path.display().to_string())
            .collect::<Vec<_>>()
            .join(" and "),
        system.config().count,
        options.steps,
        system.device_name()
    );
    Ok(())
}

/// The demo's box: the grid of cells from its origin.
fn container(config: &ParticleConfig) -> Aabb {
    let min = Vec3::from(config.origin);
    let size = Vec3::new(
        config.grid[0] as f32,
        config.grid[1] as f32,
        config.grid[2] as f32,
    ) * config.cell_size();
    Aabb {
        min,
        max: min + size,
    }
}

/// The profile overlay of the demo: the step's time per frame, each stage's time and share.
fn profile_lines(report: &ProfileReport, particles: usize) -> Vec<String> {
    let mut lines = overlay::stage_report_lines(report);
    lines.push(format!("particles {particles}"));
    lines
}

/// Opens a window on the demo: the same keys as a rigid-body scene, where they mean something
/// here (`c`, `b` and `d` have no contacts or batches to show; `u` moves the whole step).
fn view_in_window(config: ParticleConfig, options: &ViewOptions) -> Result<(), ViewError> {
    let event_loop = window::event_loop("particles")?;
    let container = container(&config);
    // Until the window's device exists, a GPU step runs on the physics' shared device.
    let device = match options.device {
        StepDevice::Cpu => ParticleDevice::Cpu,
        StepDevice::Gpu => ParticleDevice::Gpu(tumble::gpu::GpuContext::shared()?),
    };
    let mut system = ParticleSystem::new(config.clone(), device)?;
    for _ in 0..options.steps {
        system.step()?;
    }
    let aspect = options.size.width as f32 / options.size.height as f32;
    let camera = options
        .camera
        .unwrap_or_else(|| Camera::framing_boxes(&[container], aspect));
    let shown = Particles {
        config,
        container,
        system,
        on: match options.device {
            StepDevice::Cpu => Executor::Cpu,
            StepDevice::Gpu => Executor::Gpu,
        },
        context: None,
    };
    window::show(event_loop, "particles", Box::new(shown), camera, options)
}

/// The particle demo in a window.
struct Particles {
    config: ParticleConfig,
    container: Aabb,
    system: ParticleSystem,
    /// Where the step runs now (`u` moves it).
    on: Executor,
    /// The window's device, once it exists: the GPU step runs there.
    context: Option<tumble::gpu::GpuContext>,
}

impl Particles {
    /// `executor` as a device to build a system on: the window's device for the GPU once the
    /// window is open, the physics' shared one before.
    fn device(&self, executor: Executor) -> Result<ParticleDevice, ViewError> {
        Ok(match (executor, &self.context) {
            (Executor::Cpu, _) => ParticleDevice::Cpu,
            (Executor::Gpu, Some(context)) => ParticleDevice::Gpu(context.clone()),
            (Executor::Gpu, None) => ParticleDevice::Gpu(tumble::gpu::GpuContext::shared()?),
        })
    }

    /// The same particles, stepping on `executor` from now on.
    fn move_to(&mut self, executor: Executor) -> Result<(), ViewError> {
        let device = self.device(executor)?;
        let particles = self.system.particles()?;
        self.system = ParticleSystem::with_particles(self.config.clone(), device, &particles)?;
        self.on = executor;
        Ok(())
    }
}

impl Shown for Particles {
    fn use_device(&mut self, context: tumble::gpu::GpuContext) -> Result<(), ViewError> {
        self.context = Some(context);
        match self.on {
            Executor::Cpu => Ok(()),
            Executor::Gpu => self.move_to(Executor::Gpu),
        }
    }

    fn reset(&mut self) -> Result<(), ViewError> {
        self.system = ParticleSystem::new(self.config.clone(), self.device(self.on)?)?;
        Ok(())
    }

    fn step(&mut self) -> Result<(), ViewError> {
        Ok(self.system.step()?)
    }

    /// The demo's whole step moves: it has no solver of its own.
    fn put_solver_on(&mut self, executor: Executor) {
        if executor == self.on {
            return;
        }
        match self.move_to(executor) {
            Ok(()) => println!("particles step on {}", self.system.device_name()),
            Err(error) => println!("the particles stay where they were: {error}"),
        }
    }

    fn use_batcher(&mut self, _: Batcher) {
        println!("the particle demo has no constraints to batch");
    }

    fn draw_list(&mut self, settings: DrawSettings) -> Result<DrawList, ViewError> {
        let positions = self.system.positions()?;
        let mut list = DrawList::particles(&positions, self.config.radius, self.container);
        list.wireframe = settings.wireframe;
        Ok(list)
    }

    /// The positions are read back each frame: the demo's buffers are not the renderer's
    /// instance layout.
    fn device_poses(&self) -> Option<DevicePoses<'_>> {
        None
    }

    fn take_profile(&mut self) -> Vec<String> {
        let lines = profile_lines(&self.system.profiler().report(), self.config.count);
        self.system.profiler_mut().reset();
        lines
    }

    fn status(&self) -> String {
        format!(
            "{} particles on {}",
            self.config.count,
            self.system.device_name()
        )
    }

    fn batch_count(&self) -> usize {
        0
    }

    fn help(&self) -> &'static str {
        PARTICLE_HELP
    }

    fn world(&mut self) -> Option<&mut World> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on_the_cpu(count: usize) -> Particles {
        let config = ParticleConfig::demo(count);
        Particles {
            container: container(&config),
            system: ParticleSystem::new(config.clone(), ParticleDevice::Cpu).unwrap(),
            config,
            on: Executor::Cpu,
            context: None,
        }
    }

    #[test]
    fn u_moves_the_particles_between_cpu_and_gpu_as_they_are() {
        let mut shown = on_the_cpu(100);
        let start = shown.system.particles().unwrap();
        for _ in 0..5 {
            shown.step().unwrap();
        }
        let stepped = shown.system.particles().unwrap();
        assert_ne!(stepped, start);
        // The window's device: a CPU step stays where it is.
        shown
            .use_device(tumble::gpu::GpuContext::shared().unwrap())
            .unwrap();
        assert!(shown.status().ends_with(&format!(
            "on {}",
            ParticleSystem::new(ParticleConfig::demo(1), ParticleDevice::Cpu)
                .unwrap()
                .device_name()
        )));

        shown.put_solver_on(Executor::Gpu);
        assert_eq!(shown.on, Executor::Gpu);
        assert!(!shown.status().contains("on cpu"), "{}", shown.status());
        assert_eq!(shown.system.particles().unwrap(), stepped);
        shown.step().unwrap();
        let on_the_gpu = shown.system.particles().unwrap();
        assert_ne!(on_the_gpu, stepped);

        shown.put_solver_on(Executor::Cpu);
        assert_eq!(shown.on, Executor::Cpu);
        assert_eq!(shown.system.particles().unwrap(), on_the_gpu);

        // Space: back to the start, on the device the step is on.
        shown.reset().unwrap();
        assert_eq!(shown.system.particles().unwrap(), start);
        assert!(shown.status().starts_with("100 particles on cpu"));
    }

    #[test]
    fn the_demo_draws_a_sphere_per_particle_and_has_no_world() {
        let mut shown = on_the_cpu(10);
        shown.step().unwrap();
        let list = shown
            .draw_list(DrawSettings {
                wireframe: true,
                ..DrawSettings::default()
            })
            .unwrap();
        assert_eq!(list.instances[&crate::draw::MeshKey::Particle].len(), 10);
        assert!(list.wireframe);
        assert!(shown.world().is_none());
        assert!(shown.device_poses().is_none());
        assert_eq!(shown.batch_count(), 0);
        // Its help names the keys that do something here, and not contacts or batches.
        assert!(shown.help().contains("the whole step on CPU / GPU"));
        assert!(!shown.help().contains("contact") && !shown.help().contains("batch"));
        let profile = shown.take_profile();
        assert!(profile[0].contains("over 1 frames"), "{profile:?}");
        assert_eq!(profile.last().unwrap(), "particles 10");
        // The timings restart after each look.
        assert!(shown.take_profile()[0].contains("over 0 frames"));
    }
}
