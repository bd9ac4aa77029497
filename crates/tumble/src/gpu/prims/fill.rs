//! Fill a buffer with one 4-byte value, or copy words between buffers, inside a compute pass
//! (so a stage needs no copy command between its dispatches).

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
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

fn dispatch(
    context: &GpuContext,
    entry: &str,
    source: &wgpu::Buffer,
    destination: &wgpu::Buffer,
    words: usize,
    value: u32,
) -> Dispatch {
    let kernel = Kernel::new(context, entry, &wgsl(), entry, &BINDINGS);
    let slots = UniformSlots::new(
        context,
        "fill params",
        &[FillParams {
            count: words as u32,
            value,
            padding0: 0,
            padding1: 0,
        }],
    );
    let bind_group = kernel.bind(
        context,
        &[
            slots.binding(0),
            source.as_entire_buffer_binding(),
            destination.as_entire_buffer_binding(),
        ],
    );
    kernel.dispatch(bind_group, workgroups_for(words, WORKGROUP_SIZE))
}

/// Writes `value` to the first `words` 4-byte words of `destination`.
pub fn fill_dispatch(
    context: &GpuContext,
    destination: &wgpu::Buffer,
    words: usize,
    value: u32,
) -> Result<Dispatch, GpuError> {
    // The fill kernel never reads `source`; a small buffer fills the slot.
    let unused = GpuVec::<u32>::with_capacity(context, "fill unused source", 1)?;
    Ok(dispatch(
        context,
        "fill",
        unused.buffer(),
        destination,
        words,
        value,
    ))
}

/// Copies the first `words` 4-byte words of `source` to `destination` (distinct buffers).
pub fn copy_dispatch(
    context: &GpuContext,
    source: &wgpu::Buffer,
    destination: &wgpu::Buffer,
    words: usize,
) -> Dispatch {
    dispatch(context, "copy", source, destination, words, 0)
}

/// Fills a whole vector (its `len` elements) with `value`; a 4-byte element type.
pub fn fill_vec_dispatch<T: Pod>(
    context: &GpuContext,
    destination: &GpuVec<T>,
    value: T,
) -> Result<Dispatch, GpuError> {
    const { assert!(size_of::<T>() == 4, "fill writes 4-byte elements") };
    fill_dispatch(
        context,
        destination.buffer(),
        destination.len(),
        bytemuck::cast(value),
    )
}
