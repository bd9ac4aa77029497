//! `tumble view particles` and `tumble view bunnies`: pictures of the talk's particle demos
//! (free particles; rigid bodies made of particles), headless. Each particle is drawn as a
//! sphere of its radius on the floor of its box, from positions read back after the steps; on
//! `--device gpu` the particles step on the device the pictures are drawn on.

use std::path::PathBuf;

use glam::Vec3;
use tumble::math::Aabb;
use tumble::particles::{
    ParticleConfig, ParticleDevice, ParticleError, ParticleSystem, RigidConfig, RigidSystem,
};

use crate::camera::Camera;
use crate::context::GpuContext;
use crate::draw::DrawList;
use crate::error::ViewError;
use crate::headless::Offscreen;
use crate::overlay::OverlayKind;
use crate::{ImageSize, StepDevice, ViewOptions};

/// Steps the particle demo of `config` on `options.device` and writes the pictures `--png`
/// and `--frames` ask for (a window is not offered for the demo).
pub fn view_particles(config: ParticleConfig, options: &ViewOptions) -> Result<(), ViewError> {
    view_demo("particles", options, |device| {
        ParticleSystem::new(config, device).map(Demo::Particles)
    })
}

/// Steps the rigid particle bodies of `config` (the `bunnies` scene) as
/// [`view_particles`] does the demo.
pub fn view_bunnies(config: RigidConfig, options: &ViewOptions) -> Result<(), ViewError> {
    view_demo("bunnies", options, |device| {
        RigidSystem::new(&config, device).map(Demo::Rigid)
    })
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
}

fn view_demo(
    scene: &str,
    options: &ViewOptions,
    build: impl FnOnce(ParticleDevice) -> Result<Demo, ParticleError>,
) -> Result<(), ViewError> {
    if options.png.is_none() && options.frames.is_none() {
        return Err(ViewError::HeadlessOnly {
            scene: scene.into(),
        });
    }
    // Overlays and batch colours come from a rigid-body world; the demo has neither.
    let unsupported = [
        (options.overlay != OverlayKind::Off, "--overlay"),
        (options.batches, "--batches"),
    ];
    if let Some(&(_, flag)) = unsupported.iter().find(|(given, _)| *given) {
        return Err(ViewError::NotForParticles { flag });
    }
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
        let list = match system {
            Demo::Particles(_) => DrawList::particles(&positions, radius, container),
            // A body's particles in its colour.
            Demo::Rigid(rigid) => {
                let bodies = rigid.particle_bodies();
                let colour_of = |index: usize| bodies[index] as usize;
                DrawList::particles_coloured(&positions, colour_of, radius, container)
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
