//! Kernels: WGSL composed from named snippets, compiled once per (source, entry point).
//!
//! A kernel's source is built by [`Source`]: constants from Rust first (workgroup sizes and
//! the like, so each is written once), then snippets in order (`shared.wgsl`, struct
//! definitions, the kernel file). That is the whole "include" mechanism: concatenation of named
//! pieces, so a struct shared by several kernels is defined in one `.wgsl` file.
//!
//! Bind group layouts are explicit ([`Binding`] lists) rather than derived from the shader, so
//! a binding a kernel does not use still has a slot, and several entry points of one file share
//! one layout. Every kernel of a file binds a uniform block of parameters at binding 0.
//!
//! A stage's GPU work is a list of [`Dispatch`]es built once (pipelines, bind groups and
//! parameter blocks included) and re-encoded every step, so a step allocates nothing.

use std::collections::{HashMap, HashSet};
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::{Mutex, OnceLock};

use crate::gpu::context::GpuContext;
use crate::gpu::profiler::DispatchTimer;

/// Threads per workgroup of every baseline kernel. 256 is the most WebGPU guarantees
/// (`max_compute_invocations_per_workgroup`), and radix sort needs one thread per digit value.
pub const WORKGROUP_SIZE: u32 = 256;

/// Most workgroups in one dimension of a dispatch (WebGPU's guaranteed limit).
pub const MAX_GROUPS_PER_DIMENSION: u32 = 65535;

/// The snippets every kernel starts with.
pub const SHARED_WGSL: &str = include_str!("shared.wgsl");

/// WGSL source under construction: constants, then snippets.
#[derive(Clone, Debug, Default)]
#[must_use]
pub struct Source {
    text: String,
    /// See [`Source::every_loop_ends`].
    loops_end: bool,
}

impl Source {
    /// Starts with the constants every kernel uses and `shared.wgsl`.
    pub fn new() -> Self {
        Self::default()
            .constant_u32("WORKGROUP_SIZE", WORKGROUP_SIZE)
            .snippet("shared.wgsl", SHARED_WGSL)
    }

    /// Says that every loop of this source ends whatever its buffers hold: each counts up by
    /// one to a bound, or strides to a bound it cannot wrap past, or is capped. Its kernels
    /// are then compiled without naga's loop bounding (wgpu's `force_loop_bounding`), a
    /// 64-bit counter in every loop that exists only to keep a compiler from treating an
    /// endless loop as unreachable. The counters cost: without them, on an H100, the
    /// narrowphase's kernels took 15% less time on the settled 100k pile and the batching's
    /// 9% (BENCHMARKS.md, session 29).
    ///
    /// # Safety
    ///
    /// Every loop of the source, snippets included, must end whatever its buffers hold: a
    /// compiler may treat an endless loop as unreachable and miscompile what surrounds it.
    /// So not for a source that spins on another workgroup (the scans' look-backs) or walks
    /// links that corrupt data could close into a cycle (the trees, the islands).
    pub unsafe fn every_loop_ends(mut self) -> Self {
        self.loops_end = true;
        self
    }

    /// Adds `const NAME: u32 = value;`.
    pub fn constant_u32(mut self, name: &str, value: u32) -> Self {
        self.text += &format!("const {name}: u32 = {value}u;\n");
        self
    }

    /// Adds `const NAME: f32 = value;`, written in Rust's shortest round-trip form, so WGSL
    /// reads back exactly `value`.
    pub fn constant_f32(mut self, name: &str, value: f32) -> Self {
        self.text += &format!("const {name}: f32 = {value:e}f;\n");
        self
    }

    /// Adds a named snippet; the name is written as a comment so compiler messages can be
    /// traced back to the file.
    pub fn snippet(mut self, name: &str, text: &str) -> Self {
        self.text += &format!("// ---- {name} ----\n{text}\n");
        self
    }

    pub fn text(&self) -> &str {
        &self.text
    }
}

/// What one binding of a kernel's bind group is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Binding {
    Uniform,
    /// A uniform block chosen at each dispatch by its offset in the buffer (a dynamic offset:
    /// [`UniformSlots::dynamic_binding`], [`Kernel::dispatch_at`]). One bind group then serves
    /// every block, where a kernel dispatched with many blocks would need one a block.
    UniformAt,
    StorageRead,
    StorageReadWrite,
}

/// A compiled entry point and the layout of its bind group 0.
#[derive(Clone, Debug)]
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
    /// "label / entry" (or the label alone when they are the same): its dispatches' line in a
    /// profile that times each dispatch ([`DispatchTimer`]).
    pub name: &'static str,
}

/// `name` as a `&'static str`, each distinct name leaked once: a process compiles a bounded
/// set of kernels and names a bounded set of dispatches (a kernel's, or a solver batch's,
/// [`Dispatch::named`]), and the profile's lines are named by `&'static str`.
pub(crate) fn intern(name: String) -> &'static str {
    static NAMES: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Mutex::default)
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(known) = names.get(name.as_str()) {
        return known;
    }
    let leaked: &'static str = Box::leak(name.into_boxed_str());
    names.insert(leaked);
    leaked
}

/// Compiled kernels of a context, keyed by a hash of (source, entry point, bindings).
#[derive(Debug, Default)]
pub struct PipelineCache {
    kernels: HashMap<u64, Kernel>,
    /// Each kernel compiled since [`GpuContext::record_kernel_sources`] was called, in order.
    pub(crate) sources: Option<Vec<KernelSource>>,
}

/// What a kernel was compiled from, for tools that compile it again outside wgpu (the
/// `kernel_stats` example asks the driver how many registers each kernel takes).
#[derive(Clone, Debug)]
pub struct KernelSource {
    pub label: String,
    pub entry: String,
    /// The composed WGSL ([`Source::text`]).
    pub wgsl: String,
}

impl Kernel {
    /// Compiles `entry` of `source`, or returns the cached kernel.
    pub fn new(
        context: &GpuContext,
        label: &str,
        source: &Source,
        entry: &str,
        bindings: &[Binding],
    ) -> Self {
        let mut hasher = DefaultHasher::new();
        (source.text(), source.loops_end, entry, bindings).hash(&mut hasher);
        let key = hasher.finish();
        // A poisoned lock only means another thread panicked while inserting; the map is
        // still a valid cache.
        let mut cache = context
            .pipelines
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(kernel) = cache.kernels.get(&key) {
            return kernel.clone();
        }
        if let Some(sources) = &mut cache.sources {
            sources.push(KernelSource {
                label: label.to_owned(),
                entry: entry.to_owned(),
                wgsl: source.text().to_owned(),
            });
        }
        let kernel = Self::compile(context, label, source, entry, bindings);
        cache.kernels.insert(key, kernel.clone());
        kernel
    }

    fn compile(
        context: &GpuContext,
        label: &str,
        source: &Source,
        entry: &str,
        bindings: &[Binding],
    ) -> Self {
        let device = &context.device;
        let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
            .iter()
            .enumerate()
            .map(|(index, binding)| wgpu::BindGroupLayoutEntry {
                binding: index as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: match binding {
                    Binding::Uniform | Binding::UniformAt => wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: *binding == Binding::UniformAt,
                        min_binding_size: None,
                    },
                    Binding::StorageRead | Binding::StorageReadWrite => wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage {
                            read_only: *binding == Binding::StorageRead,
                        },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                },
                count: None,
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &entries,
        });
        let descriptor = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.text().into()),
        };
        let module = if source.loops_end {
            let mut checks = wgpu::ShaderRuntimeChecks::checked();
            checks.force_loop_bounding = false;
            // SAFETY: every loop of the source ends for any buffer contents, as the caller of
            // `Source::every_loop_ends` promised; every other check stays.
            unsafe { device.create_shader_module_trusted(descriptor, checks) }
        } else {
            device.create_shader_module(descriptor)
        };
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
        let name = if label == entry {
            label.to_owned()
        } else {
            format!("{label} / {entry}")
        };
        Self {
            pipeline,
            layout,
            name: intern(name),
        }
    }

    /// A bind group for this kernel: one buffer binding per entry of its layout, in order.
    pub fn bind(
        &self,
        context: &GpuContext,
        buffers: &[wgpu::BufferBinding<'_>],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(index, buffer)| wgpu::BindGroupEntry {
                binding: index as u32,
                resource: wgpu::BindingResource::Buffer(buffer.clone()),
            })
            .collect();
        context.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// A dispatch of `workgroups` workgroups (split over x and y when there are more than one
    /// dimension allows) with `bind_group`.
    pub fn dispatch(&self, bind_group: wgpu::BindGroup, workgroups: u32) -> Dispatch {
        let (x, y) = dispatch_grid(workgroups);
        Dispatch {
            pipeline: self.pipeline.clone(),
            bind_group,
            uniform_offset: None,
            groups: [x, y, 1],
            name: self.name,
        }
    }

    /// [`Self::dispatch`] for a kernel whose uniform block is a [`Binding::UniformAt`]: the
    /// block at `uniform_offset` ([`UniformSlots::offset`]).
    pub fn dispatch_at(
        &self,
        bind_group: wgpu::BindGroup,
        workgroups: u32,
        uniform_offset: u32,
    ) -> Dispatch {
        Dispatch {
            uniform_offset: Some(uniform_offset),
            ..self.dispatch(bind_group, workgroups)
        }
    }
}

/// One recorded dispatch: built once, encoded every step.
#[derive(Clone, Debug)]
pub struct Dispatch {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// The uniform block's offset, for a kernel that binds it as [`Binding::UniformAt`].
    uniform_offset: Option<u32>,
    groups: [u32; 3],
    name: &'static str,
}

impl Dispatch {
    /// The dispatch under another line of a profile that times each dispatch
    /// ([`DispatchTimer`]): for one kernel's dispatches that differ in what they cover.
    pub fn named(self, name: &'static str) -> Self {
        Self { name, ..self }
    }

    /// Encodes the dispatch, between two timestamps when the pass is timed dispatch by
    /// dispatch ([`DispatchTimer`]).
    pub fn encode(&self, pass: &mut wgpu::ComputePass<'_>) {
        if self.groups.contains(&0) {
            return;
        }
        let timed = DispatchTimer::begin(pass, self.name);
        pass.set_pipeline(&self.pipeline);
        let offsets = self.uniform_offset.as_slice();
        pass.set_bind_group(0, &self.bind_group, offsets);
        pass.dispatch_workgroups(self.groups[0], self.groups[1], self.groups[2]);
        if let Some(timed) = timed {
            timed.end(pass);
        }
    }
}

/// What a stage recorded (bind groups, dispatches) for the last two keys of its inputs, the
/// newer first. The pairs' contacts alternate between two buffers from step to step (last
/// step's are read while this step's are written), so a stage that binds them finds either
/// key recorded instead of binding again every step. The older recording keeps its buffers
/// alive until a third key replaces it: after a buffer grew, the one it replaced lingers a
/// while.
#[derive(Debug)]
pub struct LastTwo<K, V> {
    slots: [Option<(K, V)>; 2],
}

impl<K, V> Default for LastTwo<K, V> {
    fn default() -> Self {
        Self {
            slots: [None, None],
        }
    }
}

impl<K: PartialEq, V> LastTwo<K, V> {
    /// The value recorded for `key`, else `make`'s, which takes the older slot's place.
    pub fn get_or_insert(&mut self, key: K, make: impl FnOnce() -> V) -> &mut V {
        let holds = |slot: &Option<(K, V)>| slot.as_ref().is_some_and(|(held, _)| *held == key);
        if holds(&self.slots[1]) {
            self.slots.swap(0, 1);
        } else if !holds(&self.slots[0]) {
            self.slots[1] = self.slots[0].take();
            self.slots[0] = Some((key, make()));
        }
        let (_, value) = self.slots[0].as_mut().expect("filled above");
        value
    }
}

/// Encodes `dispatches` in order. wgpu places a barrier between dispatches of one pass that
/// touch the same buffer, so each sees the previous one's writes.
pub fn encode_all(pass: &mut wgpu::ComputePass<'_>, dispatches: &[Dispatch]) {
    for dispatch in dispatches {
        dispatch.encode(pass);
    }
}

/// Splits `workgroups` over (x, y) so that neither passes [`MAX_GROUPS_PER_DIMENSION`].
/// x·y may exceed `workgroups`: kernels compute the flat index with `flat_workgroup` and return
/// when it is past the end.
pub fn dispatch_grid(workgroups: u32) -> (u32, u32) {
    if workgroups <= MAX_GROUPS_PER_DIMENSION {
        return (workgroups, 1);
    }
    let rows = workgroups.div_ceil(MAX_GROUPS_PER_DIMENSION);
    (workgroups.div_ceil(rows), rows)
}

/// Workgroups needed for `items` items at `per_workgroup` items each.
pub fn workgroups_for(items: usize, per_workgroup: u32) -> u32 {
    // Item counts are bounded by buffer sizes (≤ 4 Gi elements), so the quotient fits in u32.
    items.div_ceil(per_workgroup as usize) as u32
}

/// Parameter blocks for a list of dispatches: one uniform buffer, one aligned slot per block,
/// written once when the buffer is created (so encoding the same dispatches twice in one
/// submission sees the same parameters).
#[derive(Debug)]
pub struct UniformSlots {
    buffer: wgpu::Buffer,
    stride: u64,
    size: u64,
}

impl UniformSlots {
    /// `blocks` are `#[repr(C)]` structs whose size is a multiple of 16 bytes (WGSL's uniform
    /// layout rule).
    pub fn new<T: bytemuck::Pod>(context: &GpuContext, label: &str, blocks: &[T]) -> Self {
        let size = size_of::<T>() as u64;
        debug_assert!(
            size.is_multiple_of(16),
            "uniform blocks are multiples of 16 bytes"
        );
        let alignment = u64::from(context.device.limits().min_uniform_buffer_offset_alignment);
        let stride = size.div_ceil(alignment) * alignment;
        let mut bytes = vec![0u8; (stride * blocks.len().max(1) as u64) as usize];
        for (slot, block) in blocks.iter().enumerate() {
            let start = slot * stride as usize;
            bytes[start..start + size as usize].copy_from_slice(bytemuck::bytes_of(block));
        }
        let buffer = context.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        Self {
            buffer,
            stride,
            size,
        }
    }

    /// The binding of block `slot`.
    pub fn binding(&self, slot: usize) -> wgpu::BufferBinding<'_> {
        wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: slot as u64 * self.stride,
            size: wgpu::BufferSize::new(self.size),
        }
    }

    /// The binding of any block, for a [`Binding::UniformAt`]: each dispatch names its block
    /// by [`Self::offset`].
    pub fn dynamic_binding(&self) -> wgpu::BufferBinding<'_> {
        self.binding(0)
    }

    /// Block `slot`'s offset in the buffer, for [`Kernel::dispatch_at`].
    pub fn offset(&self, slot: usize) -> u32 {
        u32::try_from(slot as u64 * self.stride).expect("uniform blocks fit in 4 GiB")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_covers_every_workgroup_within_the_limit() {
        for workgroups in [0, 1, 65535, 65536, 200_000, 4_000_000, u32::MAX / 2] {
            let (x, y) = dispatch_grid(workgroups);
            assert!(x <= MAX_GROUPS_PER_DIMENSION && y <= MAX_GROUPS_PER_DIMENSION);
            assert!(u64::from(x) * u64::from(y) >= u64::from(workgroups));
            // Less than one row is wasted.
            assert!(u64::from(x) * u64::from(y) < u64::from(workgroups) + u64::from(x.max(1)));
        }
    }
}
