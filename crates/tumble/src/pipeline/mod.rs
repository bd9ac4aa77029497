//! The public face of the engine: [`World`], its [`StepConfig`], and the step that walks the
//! stages in order.

pub mod config;
pub mod devices;
mod gpu_stages;
mod step;
pub mod world;
