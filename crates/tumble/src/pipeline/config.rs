//! Step parameters: what the scene file sets and the tunables of the solver, with units.

use crate::math::Vec3;
use crate::stages::batching::Batcher;
use crate::stages::solver::SolverKind;

/// How the world steps. The first four fields come from the scene file; the rest are the
/// solver's tunables, with defaults that suit metre-sized bodies at 60 Hz.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConfig {
    /// m/s². Default (0, -9.81, 0).
    pub gravity: Vec3,
    /// Time advanced by one [`World::step`](crate::World::step) (s). Default 1/60.
    pub dt: f32,
    /// Solver sub-steps per step: collision runs once per step, then each sub-step integrates
    /// velocities, solves, integrates positions and relaxes (Box2D v3's soft step). More
    /// sub-steps make stacks and chains stiffer. Default 8.
    pub substeps: u32,
    /// Velocity iterations with position bias per sub-step (each sub-step also runs one relax
    /// iteration without bias). Default 1.
    pub solver_iterations: u32,
    /// Speculative contact distance (m): pairs closer than this get contact points, so resting
    /// contacts persist and an approaching body is stopped at the surface instead of inside it.
    /// Default 0.02.
    pub contact_margin: f32,
    /// Stiffness of contacts as a spring frequency (Hz), capped at a quarter of the sub-step
    /// rate. A resting contact overlaps by load / (effective mass · ω²): 60 Hz keeps a tower of
    /// 10 one-metre boxes within 7 mm of its height. Default 60.
    pub contact_hertz: f32,
    /// Damping ratio of the contact spring (1 = critical). Default 3: overlap is removed
    /// without bounce (10, Box2D's value, oscillated in a pyramid at 60 Hz).
    pub contact_damping_ratio: f32,
    /// Fastest speed at which overlap is pushed apart (m/s). Default 3.
    pub max_push_velocity: f32,
    /// Stiffness of joints (Hz) and its damping ratio. Defaults 60 and 2 (capped like contacts,
    /// at half the sub-step rate).
    pub joint_hertz: f32,
    pub joint_damping_ratio: f32,
    /// Approach speed above which restitution applies (m/s). Default 1 (DESIGN.md).
    pub restitution_threshold: f32,
    /// Extra margin of the broadphase's fat AABBs (m): larger re-inserts less often but finds
    /// more candidate pairs. Default 0.1.
    pub aabb_margin: f32,
    /// Whether resting islands go to sleep (see [`crate::dynamics::island`]). Default true;
    /// benchmarks turn it off to time the whole scene.
    pub sleeping: bool,
    /// How constraints are put into batches for the parallel solver (the talk's `d` key);
    /// both batchers give the same batches on the CPU and the GPU. Default
    /// [`Batcher::Colors`].
    pub batcher: Batcher,
    /// How the solver sweeps the constraints: batched projected Gauss-Seidel, or Jacobi for
    /// comparison (it needs more iterations for the same error, see
    /// [`jacobi`](crate::stages::solver::jacobi)). Default [`SolverKind::Pgs`].
    pub solver: SolverKind,
}

impl Default for StepConfig {
    fn default() -> Self {
        Self {
            gravity: Vec3::new(0.0, -9.81, 0.0),
            dt: 1.0 / 60.0,
            substeps: 8,
            solver_iterations: 1,
            contact_margin: 0.02,
            contact_hertz: 60.0,
            contact_damping_ratio: 3.0,
            max_push_velocity: 3.0,
            joint_hertz: 60.0,
            joint_damping_ratio: 2.0,
            restitution_threshold: 1.0,
            aabb_margin: 0.1,
            sleeping: true,
            batcher: Batcher::Colors,
            solver: SolverKind::Pgs,
        }
    }
}

/// Why a configuration was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("{field} must be finite")]
    NotFinite { field: &'static str },
    #[error("{field} must be > 0, got {value}")]
    NotPositive { field: &'static str, value: f64 },
    #[error("{field} must be >= 0, got {value}")]
    Negative { field: &'static str, value: f64 },
}

impl StepConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !self.gravity.is_finite() {
            return Err(ConfigError::NotFinite { field: "gravity" });
        }
        let positive = |field, value: f32| {
            if !value.is_finite() {
                Err(ConfigError::NotFinite { field })
            } else if value <= 0.0 {
                Err(ConfigError::NotPositive {
                    field,
                    value: value as f64,
                })
            } else {
                Ok(())
            }
        };
        let non_negative = |field, value: f32| {
            if !value.is_finite() {
                Err(ConfigError::NotFinite { field })
            } else if value < 0.0 {
                Err(ConfigError::Negative {
                    field,
                    value: value as f64,
                })
            } else {
                Ok(())
            }
        };
        positive("dt", self.dt)?;
        if self.substeps == 0 {
            return Err(ConfigError::NotPositive {
                field: "substeps",
                value: 0.0,
            });
        }
        non_negative("contact_margin", self.contact_margin)?;
        non_negative("contact_hertz", self.contact_hertz)?;
        non_negative("contact_damping_ratio", self.contact_damping_ratio)?;
        non_negative("max_push_velocity", self.max_push_velocity)?;
        non_negative("joint_hertz", self.joint_hertz)?;
        non_negative("joint_damping_ratio", self.joint_damping_ratio)?;
        non_negative("restitution_threshold", self.restitution_threshold)?;
        non_negative("aabb_margin", self.aabb_margin)
    }
}

/// A soft constraint as a spring-damper (Box2D v3's `b2Softness`): the velocity bias that
/// removes a position error C is `bias_rate · C`, the impulse is scaled by `mass_scale`, and
/// `impulse_scale` leaks a little of the accumulated impulse, which makes the constraint soft.
///
/// For frequency ω = 2π·hertz, damping ratio ζ and sub-step h:
/// `a1 = 2ζ + hω`, `a2 = hω·a1`, `a3 = 1/(1 + a2)`, bias_rate = ω/a1, mass_scale = a2·a3,
/// impulse_scale = a3.
///
/// repr(C) + Pod: a field of the contact constraints both executors solve (WGSL twin in
/// `stages/constraints/contact_constraint.wgsl`). 12 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Softness {
    pub bias_rate: f32,
    pub mass_scale: f32,
    pub impulse_scale: f32,
}

impl Softness {
    /// A rigid constraint: no bias, full mass.
    pub const RIGID: Self = Self {
        bias_rate: 0.0,
        mass_scale: 1.0,
        impulse_scale: 0.0,
    };

    pub fn new(hertz: f32, damping_ratio: f32, h: f32) -> Self {
        if hertz == 0.0 {
            return Self::RIGID;
        }
        let omega = 2.0 * std::f32::consts::PI * hertz;
        let a1 = 2.0 * damping_ratio + h * omega;
        let a2 = h * omega * a1;
        let a3 = 1.0 / (1.0 + a2);
        Self {
            bias_rate: omega / a1,
            mass_scale: a2 * a3,
            impulse_scale: a3,
        }
    }

    /// As a WGSL `vec4<f32>` of a uniform block: (bias_rate, mass_scale, impulse_scale, 0).
    pub fn words(self) -> [f32; 4] {
        [self.bias_rate, self.mass_scale, self.impulse_scale, 0.0]
    }
}
