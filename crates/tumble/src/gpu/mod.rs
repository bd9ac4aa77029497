//! GPU infrastructure shared by every GPU stage: the adapter and device ([`context`]), typed
//! growable buffers ([`buffer`]), kernel composition and caching ([`kernel`]), timestamp
//! profiling ([`profiler`]) and the parallel primitives ([`prims`]: scan, compaction, radix and
//! bitonic sort, reduce, fill), each with a CPU twin.

pub mod buffer;
pub mod context;
pub mod kernel;
pub mod prims;
pub mod profiler;

pub use buffer::GpuVec;
pub use context::{GpuContext, GpuError};
