//! The trees' body lists on the device: the dynamic bodies in index order for the moving tree
//! and the static ones for the fixed tree, from one bit a body (`body_lists.wgsl`: flag, scan,
//! place). The host used to build both lists in a pass over every body and upload them, each
//! step that a body fell asleep or woke (most steps of a settling pile): 0.34 ms a step at 100k
//! bodies and 1.6 ms at 500k on an H200 machine (BENCHMARKS.md, session 13). It now sends the
//! bits, a sixteenth of the bytes, and the lists' lengths.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::gpu::prims::scan::{Scan, ScanKind};

const WGSL: &str = include_str!("body_lists.wgsl");
/// Parameters, static bits, flags, places, dynamic bodies, static bodies.
const BINDINGS: [Binding; 6] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `ListParams` in `body_lists.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct ListParams {
    bodies: u32,
    _pad: [u32; 3],
}

/// The buffers bound (bits, flags, places, dynamic and static lists) and the body count.
type Key = ([wgpu::Buffer; 5], usize);

/// Builds the two lists from the static bits, in the pass that builds the trees.
#[derive(Debug)]
pub(super) struct GpuBodyLists {
    flags: GpuVec<u32>,
    places: GpuVec<u32>,
    scan: Scan,
    cached: Option<(Key, [Dispatch; 2], UniformSlots)>,
}

impl GpuBodyLists {
    pub(super) fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            flags: GpuVec::with_capacity(context, "dynamic body flags", 0)?,
            places: GpuVec::with_capacity(context, "dynamic body places", 0)?,
            scan: Scan::new(),
            cached: None,
        })
    }

    /// Encodes the lists of the first `bodies` bodies of `static_bits` into `dynamic` and
    /// `fixed`, which must be as long as the host counted (their lengths are the trees').
    pub(super) fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        (static_bits, bodies): (&GpuVec<u32>, usize),
        (dynamic, fixed): (&GpuVec<u32>, &GpuVec<u32>),
    ) -> Result<(), GpuError> {
        if bodies == 0 {
            return Ok(());
        }
        self.flags.resize(context, bodies)?;
        self.places.resize(context, bodies)?;
        let buffers = [
            static_bits.buffer().clone(),
            self.flags.buffer().clone(),
            self.places.buffer().clone(),
            dynamic.buffer().clone(),
            fixed.buffer().clone(),
        ];
        let key = (buffers, bodies);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let params = ListParams {
                bodies: bodies as u32,
                _pad: [0; 3],
            };
            let uniform = UniformSlots::new(context, "body list params", &[params]);
            let source = Source::new().snippet("body_lists.wgsl", WGSL);
            let bindings = [
                uniform.binding(0),
                static_bits.whole(),
                self.flags.whole(),
                self.places.whole(),
                dynamic.whole(),
                fixed.whole(),
            ];
            let dispatch = |entry: &str| {
                let kernel = Kernel::new(context, entry, &source, entry, &BINDINGS);
                let group = kernel.bind(context, &bindings);
                kernel.dispatch(group, workgroups_for(bodies, WORKGROUP_SIZE))
            };
            let dispatches = [dispatch("flag_dynamic"), dispatch("place_bodies")];
            self.cached = Some((key, dispatches, uniform));
        }
        let Some((_, [flag, place], _)) = &self.cached else {
            unreachable!("cached above")
        };
        flag.encode(pass);
        let places = &mut self.places;
        self.scan
            .encode(context, pass, &self.flags, places, ScanKind::Exclusive)?;
        place.encode(pass);
        Ok(())
    }
}
