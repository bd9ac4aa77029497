//! Step parameters: what the scene file sets and the tunables of the solver, with units.

use crate::math::Vec3;

/// How the world steps. The first five fields come from the scene file; the rest are the
/// solver's tunables, with defaults that suit metre-sized bodies at 60 Hz.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepConfig {
    /// m/s². Default (0, -9.81, 0).
    pub gravity: Vec3,
    /// Time advanced by one [`World::step`](crate::World::step) (s). Default 1/60.
    pub dt: f32,
    /// Each step runs this many full sub-steps (collision included) of `dt / substeps`.
    /// Default 1.
    pub substeps: u32,
    /// Velocity iterations of the solver per sub-step. Default 10.
    pub solver_iterations: u32,
    /// Speculative contact distance (m): pairs closer than this get contact points, so resting
    /// contacts persist and an approaching body is stopped at the surface instead of inside it.
    /// Default 0.02.
    pub contact_margin: f32,
    /// Penetration left uncorrected (m), so resting contacts do not flicker. Default 0.005.
    pub penetration_slop: f32,
    /// Fraction of the penetration beyond the slop removed per sub-step by the split impulse
    /// (0..1). Higher corrects faster but can make stacks jitter. Default 0.2.
    pub push_factor: f32,
    /// Cap on the correction speed of the split impulse (m/s), so deep overlaps separate
    /// gently. Default 2.
    pub max_push_velocity: f32,
    /// Approach speed above which restitution applies (m/s). Default 1 (DESIGN.md).
    pub restitution_threshold: f32,
    /// Extra margin of the broadphase's fat AABBs (m): larger re-inserts less often but finds
    /// more candidate pairs. Default 0.1.
    pub aabb_margin: f32,
}

impl Default for StepConfig {
    fn default() -> Self {
        Self {
            gravity: Vec3::new(0.0, -9.81, 0.0),
            dt: 1.0 / 60.0,
            substeps: 1,
            solver_iterations: 10,
            contact_margin: 0.02,
            penetration_slop: 0.005,
            push_factor: 0.2,
            max_push_velocity: 2.0,
            restitution_threshold: 1.0,
            aabb_margin: 0.1,
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
        non_negative("penetration_slop", self.penetration_slop)?;
        non_negative("push_factor", self.push_factor)?;
        non_negative("max_push_velocity", self.max_push_velocity)?;
        non_negative("restitution_threshold", self.restitution_threshold)?;
        non_negative("aabb_margin", self.aabb_margin)
    }
}
