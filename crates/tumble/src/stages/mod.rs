//! The stages of the step, one module each: its data, its CPU code and (later) its GPU driver
//! and kernel, side by side.

pub mod aabb;
pub mod batching;
pub mod broadphase;
pub mod constraints;
pub mod integrate;
pub mod narrowphase;
pub mod pairs;
pub mod solver;
