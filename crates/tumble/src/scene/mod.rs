//! Scenes: the JSON scene format v1 (DESIGN.md), loading into a [`World`], dumping a world back
//! to a scene that continues the run, and the built-in scenes of the talk.

pub mod builtin;
pub mod format;
pub mod landscape;
pub mod ragdoll;
pub mod raycast;

pub use builtin::{BUILTIN_SCENES, barrel_points, builtin};
pub use format::{Scene, SceneError, SceneFile};
pub use raycast::RayFan;
