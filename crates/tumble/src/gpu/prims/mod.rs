//! Parallel primitives, each a WGSL file beside its Rust driver and a CPU twin that the parity
//! tests compare against: prefix scan, stream compaction, radix sort (u32 and u64 keys),
//! bitonic sort, reduce, fill and scatter.
//!
//! A driver builds its dispatches once for given buffers and sizes (pipelines, bind groups,
//! parameter blocks and scratch) and re-encodes them into the caller's compute pass; nothing
//! is read back, so a stage can chain primitives in one submission.

use crate::gpu::context::GpuContext;

pub mod bitonic_sort;
pub mod compact;
pub mod fill;
pub mod radix_sort;
pub mod reduce;
pub mod scan;
pub mod scatter;

/// The most tiles one dispatch of a look-back kernel (scan, radix sort) may hold; more are
/// split into windows, dispatched in order. On Mesa's CPU drivers a shader invocation may run
/// at most 65 535 loop iterations in all (gallivm's loop limiter, shared by every loop of the
/// invocation) and silently stops looping after that. They run a dispatch's workgroups in
/// parallel chunks, not in order, so a tile may find every tile back to its chunk's start
/// unpublished and count them itself, about 90 iterations each: a scan of 3M u32 came out
/// wrong from half-way on. A window's look-back stops at the window before it, whose tiles are
/// all published, so 128 tiles a window keeps it below 12 000 iterations. GPUs have no such
/// limit and keep one window per binding.
pub fn look_back_tiles(context: &GpuContext) -> usize {
    if context.is_cpu_driver() {
        128
    } else {
        usize::MAX
    }
}
