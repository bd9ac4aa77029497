//! The stages of the step, one module each: its data, its CPU code and (later) its GPU driver
//! and kernel, side by side.

pub mod broadphase;
pub mod pairs;
