//! Parallel primitives, each a WGSL file beside its Rust driver and a CPU twin that the parity
//! tests compare against: prefix scan, stream compaction, radix sort (u32 and u64 keys),
//! bitonic sort, reduce and fill.
//!
//! A driver builds its dispatches once for given buffers and sizes (pipelines, bind groups,
//! parameter blocks and scratch) and re-encodes them into the caller's compute pass; nothing
//! is read back, so a stage can chain primitives in one submission.

pub mod bitonic_sort;
pub mod compact;
pub mod fill;
pub mod radix_sort;
pub mod reduce;
pub mod scan;
