//! Tumble: a rigid-body physics engine whose step runs stage by stage on the CPU or the GPU,
//! after Bullet's GPU pipeline (Erwin Coumans, "OpenCL Game Physics").
//!
//! The step, in order (`pipeline/step.rs` walks it top to bottom): world AABBs → broadphase
//! (two dynamic AABB trees) → pair cache (added / removed / kept pairs) → narrowphase
//! (persistent manifolds) → constraint rows → batching (graph coloring) → projected
//! Gauss-Seidel → integration.

pub mod collision;
pub mod dynamics;
pub mod gpu;
pub mod math;
pub mod particles;
pub mod pipeline;
pub mod profile;
pub mod scene;
pub mod shape;
pub mod stages;

pub use dynamics::body::{BodyDesc, BodyError, BodyHandle};
pub use dynamics::joint::{JointDesc, JointError, JointHandle, JointKind, JointState, Motor};
pub use pipeline::config::{ConfigError, StepConfig};
pub use pipeline::query::{QueryError, QueryFilter, RayHit};
pub use pipeline::world::{StepStats, World};
pub use shape::Shape;
