//! Fill a buffer with one 4-byte value, or copy words between buffers, inside a compute pass
//! (so a stage needs no copy command between its dispatches).

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::{GpuVec, windows};
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};

const WGSL: &str = include_str!("fill.wgsl");
const BINDINGS: [Binding; 3] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `FillParams` in `fill.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FillParams {
    pub count: u32,
    pub value: u32,
    pub padding0: u32,
    pub padding1: u32,
}
const _: () = assert!(size_of::<FillParams>() == 16);

pub fn wgsl() -> Source {
    Source::new().snippet("fill.wgsl", WGSL)
}

/// CPU twin.
pub fn fill_cpu<T: Pod>(destination: &mut [T], value: T) {
    destination.fill(value);
}

/// The dispatches of `entry` over `words` words, a window of `destination` (and of `source`,
/// when `windowed_source`) at a time.
fn dispatches(
    context: &GpuContext,
    entry: &str,
    (source, windowed_source): (&wgpu::Buffer, bool),
    destination: &wgpu::Buffer,
    words: usize,
    value: u32,
) -> Result<Vec<Dispatch>, GpuError> {
    let kernel = Kernel::new(context, entry, &wgsl(), entry, &BINDINGS);
    let windows = windows(context, words, 4, WORKGROUP_SIZE as usize)?;
    let blocks: Vec<FillParams> = windows
        .iter()
        .map(|window| FillParams {
            count: window.len as u32,
            value,
            padding0: 0,
            padding1: 0,
        })
        .collect();
    let slots = UniformSlots::new(context, "fill params", &blocks);
    Ok(windows
        .iter()
        .enumerate()
        .map(|(slot, window)| {
            let source = if windowed_source {
                window.binding(source, 4)
            } else {
                source.as_entire_buffer_binding()
            };
            let bind_group = kernel.bind(
                context,
                &[slots.binding(slot), source, window.binding(destination, 4)],
            );
            kernel.dispatch(bind_group, workgroups_for(window.len, WORKGROUP_SIZE))
        })
        .collect())
}

/// Writes `value` to the first `words` 4-byte words of `destination`.
pub fn fill_dispatch(
    context: &GpuContext,
    destination: &wgpu::Buffer,
    words: usize,
    value: u32,
) -> Result<Vec<Dispatch>, GpuError> {
    // The fill kernel never reads `source`; a small buffer fills the slot.
    let unused = GpuVec::<u32>::with_capacity(context, "fill unused source", 1)?;
    dispatches(
        context,
        "fill",
        (unused.buffer(), false),
        destination,
        words,
        value,
    )
}

/// Copies the first `words` 4-byte words of `source` to `destination` (distinct buffers).
pub fn copy_dispatch(
    context: &GpuContext,
    source: &wgpu::Buffer,
    destination: &wgpu::Buffer,
    words: usize,
) -> Result<Vec<Dispatch>, GpuError> {
    dispatches(context, "copy", (source, true), destination, words, 0)
}

/// Fills a whole vector (its `len` elements) with `value`; a 4-byte element type.
pub fn fill_vec_dispatch<T: Pod>(
    context: &GpuContext,
    destination: &GpuVec<T>,
    value: T,
) -> Result<Vec<Dispatch>, GpuError> {
    const { assert!(size_of::<T>() == 4, "fill writes 4-byte elements") };
    fill_dispatch(
        context,
        destination.buffer(),
        destination.len(),
        bytemuck::cast(value),
    )
}
