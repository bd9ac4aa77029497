//! Engines under test behind one trait, so the measuring loop treats them all alike.
//!
//! An [`EngineKind`] is an engine on a device (`tumble-cpu`, `tumble-gpu`, `rapier`), and every
//! column, table and chart takes each kind alike.

use crate::rapier::{RapierSimulation, SolverSettings};
use tumble::World;
use tumble::math::Vec3;
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::Scene;

/// An engine on a device, as named on the command line and in the CSV.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum EngineKind {
    /// Tumble's step on the CPU (rayon).
    #[value(name = "tumble-cpu", alias = "tumble")]
    TumbleCpu,
    /// Tumble's step on the GPU (wgpu).
    #[value(name = "tumble-gpu")]
    TumbleGpu,
    /// rapier3d with Tumble's solver settings: the same sub-steps, sweeps and contact softness.
    #[value(name = "rapier")]
    Rapier,
    /// rapier3d with its own default solver settings, as a rapier user gets it.
    #[value(name = "rapier-default")]
    RapierDefault,
}

/// Why an engine does not run a scene.
#[derive(Clone, Debug, PartialEq)]
pub enum BuildError {
    /// The engine cannot run on this machine or build (e.g. no GPU).
    NotAvailable(String),
    /// The engine lacks something the scene uses (e.g. a kind of joint), so it could not run
    /// the same scene.
    Unsupported(String),
}

/// Contact figures after a step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactSample {
    pub pairs: usize,
    pub contacts: usize,
    /// Deepest overlap of any contact point (m, ≥ 0).
    pub max_penetration: f32,
}

/// A dynamic body's state at the end of a run, for the drift figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyState {
    pub position: Vec3,
    pub linear_velocity: Vec3,
}

/// What the benchmark needs from an engine holding a scene.
pub trait Simulation {
    /// Advances by the scene's `dt` (all its sub-steps).
    fn step(&mut self);
    fn contact_sample(&self) -> ContactSample;
    /// The dynamic bodies, in the scene's order.
    fn dynamic_states(&self) -> Vec<BodyState>;
    /// ½mv² + ½ω·Iω over all bodies (J).
    fn kinetic_energy(&self) -> f64;
    /// Forgets stage timings (after the warm-up).
    fn reset_stage_timers(&mut self);
    /// Mean ms per step of each stage since the last reset, in step order.
    fn stage_ms(&self) -> Vec<(String, f64)>;
}

impl EngineKind {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            EngineKind::TumbleCpu => "tumble-cpu",
            EngineKind::TumbleGpu => "tumble-gpu",
            EngineKind::Rapier => "rapier",
            EngineKind::RapierDefault => "rapier-default",
        }
    }

    /// The scene loaded into this engine, or why this engine cannot run it.
    pub fn build(self, scene: &Scene) -> Result<Box<dyn Simulation>, BuildError> {
        match self {
            EngineKind::TumbleCpu | EngineKind::TumbleGpu => {
                let unavailable =
                    |e: &dyn std::fmt::Display| BuildError::NotAvailable(e.to_string());
                let mut world = scene.build().map_err(|e| unavailable(&e))?;
                // Sleeping is off in benchmarks, as on the peers: a settled pile is timed
                // solving, not asleep.
                let config = tumble::StepConfig {
                    sleeping: false,
                    ..*world.config()
                };
                world.set_config(config).map_err(|e| unavailable(&e))?;
                if self == EngineKind::TumbleGpu {
                    world
                        .set_stage_devices(StageDevices::all(Executor::Gpu))
                        .map_err(|e| unavailable(&e))?;
                }
                Ok(Box::new(TumbleSimulation { world }))
            }
            EngineKind::Rapier | EngineKind::RapierDefault => {
                let settings = if self == EngineKind::Rapier {
                    SolverSettings::Matched
                } else {
                    SolverSettings::RapierDefault
                };
                let simulation =
                    RapierSimulation::new(scene, settings).map_err(BuildError::Unsupported)?;
                Ok(Box::new(simulation))
            }
        }
    }
}

/// Tumble's [`World`]; its stage breakdown comes from the world's own profiler.
pub struct TumbleSimulation {
    world: World,
}

impl Simulation for TumbleSimulation {
    fn step(&mut self) {
        self.world.step();
    }

    fn contact_sample(&self) -> ContactSample {
        let stats = self.world.stats();
        ContactSample {
            pairs: stats.pairs,
            contacts: stats.contacts,
            max_penetration: stats.max_penetration,
        }
    }

    fn dynamic_states(&self) -> Vec<BodyState> {
        self.world
            .bodies()
            .filter(|&body| self.world.is_dynamic(body).unwrap_or(false))
            .filter_map(|body| {
                Some(BodyState {
                    position: self.world.pose(body).ok()?.position,
                    linear_velocity: self.world.linear_velocity(body).ok()?,
                })
            })
            .collect()
    }

    fn kinetic_energy(&self) -> f64 {
        self.world.kinetic_energy()
    }

    fn reset_stage_timers(&mut self) {
        self.world.profiler_mut().reset();
    }

    fn stage_ms(&self) -> Vec<(String, f64)> {
        self.world
            .profiler()
            .report()
            .stage_ms()
            .into_iter()
            .map(|(name, ms)| (name.to_string(), ms))
            .collect()
    }
}
