//! The public face of the engine: [`World`], its [`StepConfig`], scene queries, and the step
//! that walks the stages in order.

pub mod config;
pub mod devices;
mod gpu_stages;
pub(crate) mod parallel;
pub mod query;
mod step;
pub mod world;
