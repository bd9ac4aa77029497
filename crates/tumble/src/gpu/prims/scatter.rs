//! Scatter: `destination[indices[i]] = values[i]` on the device, for records of any `Pod`
//! type. An upload that changes a few thousand elements spread over a large array (the bodies
//! of islands that fell asleep or woke) writes the changed values and their indices, two
//! writes, and scatters them here: one queue write per run of neighbours cost more than the
//! whole array's upload once the runs were a few hundred.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::GpuContext;
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};

const WGSL: &str = include_str!("scatter.wgsl");
const BINDINGS: [Binding; 4] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `ScatterParams` in `scatter.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct ScatterParams {
    pub count: u32,
    pub words: u32,
    pub padding0: u32,
    pub padding1: u32,
}
const _: () = assert!(size_of::<ScatterParams>() == 16);

pub fn wgsl() -> Source {
    Source::new().snippet("scatter.wgsl", WGSL)
}

/// CPU twin.
pub fn scatter_cpu<T: Copy>(indices: &[u32], values: &[T], destination: &mut [T]) {
    assert_eq!(indices.len(), values.len(), "one value per index");
    for (&index, value) in indices.iter().zip(values) {
        destination[index as usize] = *value;
    }
}

/// What a recorded dispatch was built for: its buffers and parameters.
type Key = ([wgpu::Buffer; 3], ScatterParams);

/// The scatter kernel and the dispatch recorded for the last buffers and count.
pub struct GpuScatter {
    kernel: Kernel,
    /// The uniform slot lives as long as the dispatch whose bind group points into it.
    cached: Option<(Key, Dispatch, UniformSlots)>,
}

impl GpuScatter {
    pub fn new(context: &GpuContext) -> Self {
        Self {
            kernel: Kernel::new(context, "scatter", &wgsl(), "scatter", &BINDINGS),
            cached: None,
        }
    }

    /// Encodes `destination[indices[i]] = values[i]` for every i into `pass`. The indices must
    /// be distinct and below `destination.len()`.
    pub fn encode<T: Pod>(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        indices: &GpuVec<u32>,
        values: &GpuVec<T>,
        destination: &GpuVec<T>,
    ) {
        assert_eq!(indices.len(), values.len(), "one value per index");
        assert!(
            size_of::<T>().is_multiple_of(4),
            "records are whole 4-byte words"
        );
        if indices.is_empty() {
            return;
        }
        let params = ScatterParams {
            count: u32::try_from(indices.len()).expect("index count fits in u32"),
            words: (size_of::<T>() / 4) as u32,
            padding0: 0,
            padding1: 0,
        };
        let key = (
            [
                indices.buffer().clone(),
                values.buffer().clone(),
                destination.buffer().clone(),
            ],
            params,
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let slots = UniformSlots::new(context, "scatter params", &[params]);
            let group = self.kernel.bind(
                context,
                &[
                    slots.binding(0),
                    indices.whole(),
                    values.whole(),
                    destination.whole(),
                ],
            );
            let groups = workgroups_for(indices.len(), WORKGROUP_SIZE);
            self.cached = Some((key, self.kernel.dispatch(group, groups), slots));
        }
        if let Some((_, dispatch, _)) = &self.cached {
            dispatch.encode(pass);
        }
    }
}
