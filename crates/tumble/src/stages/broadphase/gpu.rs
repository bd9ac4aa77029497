//! Broadphase on the GPU: linear BVHs (LBVH) and parallel stackless traversal, after the talk's
//! "GPU BVH" slides and Karras (2012).
//!
//! Per step: the dynamic bodies' tree is rebuilt from scratch (bounds of the AABB centres by a
//! two-level reduce, 30-bit Morton codes, stable radix sort of (code, body), Karras' binary
//! radix tree, bottom-up refit by atomic min / max, which is exact under WGSL's relaxed atomics
//! where visit counters are not: see `lbvh_build.wgsl`); the static bodies' tree is rebuilt
//! only when the static bodies or their AABBs change. One thread per dynamic body walks the
//! dynamic tree (only the subtrees holding leaves sorted after its own, so each pair is found
//! once) and the static tree, with either the talk's history flags or escape indices
//! ([`Traversal`]). Pair keys ([`pair_key`](crate::stages::pairs::pair_key)) are appended with
//! an atomic counter, then the whole key buffer is radix sorted (packed to 2 × the bits of a
//! body index, then unpacked), so the order never depends on which thread appended first.
//! Pairs that no tree can give (both bodies static to the trees: a sleeping body's resting
//! pairs) are appended the same way from a list the host keeps
//! ([`GpuBroadphase::set_extra_pairs`]), and the sort merges them in.
//!
//! Dispatches per step at 10 000 bodies (8 000 dynamic, 16 384 key slots): 17 for the dynamic
//! tree (bounds 2, codes 1, 4 sort passes of 3, build 2) and 24 for the pairs (2 fills, the
//! traversal, 4 sort passes of 5, unpacking), one more with extra pairs.
//!
//! The trees' body lists are made on the device from one bit a body
//! (`body_lists.rs`), when the mask of [`GpuBroadphase::set_bodies`] changes.
//!
//! Dispatch sizes: the traversal's thread count is the dynamic body count, known on the host
//! (the host counts the mask's bits); the only count produced on
//! the GPU is the pair count, and the stages after the traversal are sized by the key buffer's
//! *capacity* instead: slots past the count hold `u64::MAX`, which sorts last and which no
//! binary search for a real key matches (the GPU pair cache relies on this). That keeps the
//! radix sort unchanged and costs sorting the unused tail; an indirect dispatch would need
//! every primitive after it to read its count from a buffer.
//!
//! Invariants:
//! - After an encoded step has run, [`GpuBroadphase::keys`] holds `capacity` keys: the first
//!   `count` (in [`GpuBroadphase::count`]) are exactly the moving × moving and moving × static
//!   pairs whose AABBs overlap or touch ([`Aabb::overlaps`]), each once, ascending; the rest are
//!   `u64::MAX`. Static × static pairs are never reported.
//! - Nothing is dropped: a pair past the capacity is still counted. When
//!   [`GpuBroadphase::check_capacity`] finds count > capacity it grows the buffers and returns
//!   true, and the caller runs the stage again (the result of the overflowed run is partial).
//! - The trees and the keys are the same on every run on a device: the sorts are stable, the
//!   tree structure depends only on the sorted codes and positions, the refit's boxes are
//!   mins and maxes, whatever order the atomics land in, and the keys are sorted.
//! - The history-flag walk covers 32 levels; an internal node deeper than that has its subtree
//!   walked by escape indices, so any tree depth is handled (the test builds a 37-level tree).

use bytemuck::{Pod, Zeroable};

use super::body_lists::GpuBodyLists;
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::fill::fill_dispatch;
use crate::gpu::prims::radix_sort::RadixSort;
use crate::math::Aabb;

const CODES_WGSL: &str = include_str!("lbvh_codes.wgsl");
const BUILD_WGSL: &str = include_str!("lbvh_build.wgsl");
const TRAVERSE_WGSL: &str = include_str!("lbvh_traverse.wgsl");

/// Bits of a Morton code: 10 per axis.
const MORTON_BITS: u32 = 30;
/// Leaves reduced by one workgroup of `bounds_partial` (WORKGROUP_SIZE × its ITEMS_PER_THREAD).
const BOUNDS_BLOCK: u32 = WORKGROUP_SIZE * 4;
/// Key capacity before the first growth.
const INITIAL_CAPACITY: usize = 1024;

/// How the pair-finding threads walk the trees; both give the same pairs. Ropes are the
/// default: on an H100 (`tumble bench broadphase`, traversal and key sort alone) they took
/// 0.147 against 0.208 ms for 8192 boxes and 0.192 against 0.281 ms for 65536.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Traversal {
    /// The talk's stackless walk with 2 history bits per level and parent links.
    HistoryFlags,
    /// Stackless walk along precomputed escape indices ("ropes").
    #[default]
    Ropes,
}

impl Traversal {
    fn entry(self) -> &'static str {
        match self {
            Traversal::HistoryFlags => "traverse_history",
            Traversal::Ropes => "traverse_ropes",
        }
    }
}

/// Mirrors `CodeParams` in `lbvh_codes.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CodeParams {
    pub leaf_count: u32,
    pub partial_count: u32,
    pub padding0: u32,
    pub padding1: u32,
}

/// Mirrors `BuildParams` in `lbvh_build.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BuildParams {
    pub leaf_count: u32,
    pub padding0: u32,
    pub padding1: u32,
    pub padding2: u32,
}

/// Mirrors `TraverseParams` in `lbvh_traverse.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TraverseParams {
    pub dynamic_leaves: u32,
    pub static_leaves: u32,
    pub capacity: u32,
    /// Bits of a body index: the bit length of the body count.
    pub body_bits: u32,
    /// Keys `append_extra` or `append_resting` reads ([`GpuBroadphase::set_extra_pairs`],
    /// [`GpuBroadphase::set_resting_pairs_from`]).
    pub extra_count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// The kernel files' sources, for the pipelines and the layout test: codes, build, traverse.
pub fn wgsl() -> [Source; 3] {
    [
        Source::new().snippet("lbvh_codes.wgsl", CODES_WGSL),
        Source::new().snippet("lbvh_build.wgsl", BUILD_WGSL),
        Source::new().snippet("lbvh_traverse.wgsl", TRAVERSE_WGSL),
    ]
}

const CODES_BINDINGS: [Binding; 5] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];
const BUILD_BINDINGS: [Binding; 7] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];
const TRAVERSE_BINDINGS: [Binding; 11] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageRead,
];

/// How many steps in a row the dynamic tree keeps the leaf order of its last build, its boxes
/// refit to the bodies' new ones, before the Morton codes are sorted again. The pairs are the
/// same either way (the boxes are exact); a tree of an older order only walks more nodes as
/// the bodies move. Each step between two builds skips the codes and their sort, a dozen
/// dispatches: on an H100 the trees' pass went from 0.214 to 0.117 ms a step at falling-boxes'
/// 3k bodies, and from 0.302 to 0.249 on a settled pile of 100k (where the walk did not slow).
const REFITS_PER_BUILD: u32 = 3;

/// One LBVH over a fixed list of bodies; layout in `lbvh_build.wgsl`.
#[derive(Debug)]
struct Lbvh {
    /// The tree's bodies, ascending (the tie order of equal codes).
    bodies: GpuVec<u32>,
    /// Scene bounds of the centres, then the partial bounds.
    scene: GpuVec<[f32; 4]>,
    codes: GpuVec<u32>,
    sorted_codes: GpuVec<u32>,
    sorted_bodies: GpuVec<u32>,
    /// 4 words per node.
    nodes: GpuVec<u32>,
    /// (min, max) per node, as order-preserving u32 codes of the floats.
    bounds: GpuVec<[u32; 4]>,
    /// Per internal node: the other end of its leaf range.
    ends: GpuVec<u32>,
    sort: RadixSort,
    /// Dispatches before and after the sort, and the AABB buffer they read.
    cached: Option<(wgpu::Buffer, Vec<Dispatch>, Vec<Dispatch>)>,
    /// Encodes since the last whole build that only refit the tree ([`REFITS_PER_BUILD`]).
    refits: u32,
    /// The codes' kernels (bounds, fold, Morton) and the build's (internal nodes, refit),
    /// compiled once: the dispatches are built again for each new leaf count.
    kernels: [Kernel; 5],
}

impl Lbvh {
    fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let empty = |label| GpuVec::<u32>::with_capacity(context, label, 0);
        let [codes_source, build_source, _] = wgsl();
        let code_kernel =
            |entry| Kernel::new(context, entry, &codes_source, entry, &CODES_BINDINGS);
        let build_kernel =
            |entry| Kernel::new(context, entry, &build_source, entry, &BUILD_BINDINGS);
        let [partial, fold, morton] = ["bounds_partial", "bounds_final", "morton"].map(code_kernel);
        let [internal, refit] = ["build_internal", "refit"].map(build_kernel);
        Ok(Self {
            kernels: [partial, fold, morton, internal, refit],
            bodies: empty("lbvh bodies")?,
            scene: GpuVec::with_capacity(context, "lbvh scene bounds", 0)?,
            codes: empty("lbvh codes")?,
            sorted_codes: empty("lbvh sorted codes")?,
            sorted_bodies: empty("lbvh sorted bodies")?,
            nodes: empty("lbvh nodes")?,
            bounds: GpuVec::with_capacity(context, "lbvh bounds", 0)?,
            ends: empty("lbvh range ends")?,
            sort: RadixSort::new(),
            cached: None,
            refits: 0,
        })
    }

    fn leaves(&self) -> usize {
        self.bodies.len()
    }

    /// Sizes the buffers for `leaves` bodies, which [`GpuBodyLists`] then writes (ascending)
    /// into `bodies`.
    fn set_body_count(&mut self, context: &GpuContext, leaves: usize) -> Result<(), GpuError> {
        let nodes = (2 * leaves).saturating_sub(1);
        // The old list is written over: nothing to keep if the buffer grows.
        self.bodies.resize(context, 0)?;
        self.bodies.resize(context, leaves)?;
        self.scene
            .resize(context, 2 + 2 * leaves.div_ceil(BOUNDS_BLOCK as usize))?;
        self.codes.resize(context, leaves)?;
        self.nodes.resize(context, 4 * nodes)?;
        self.bounds.resize(context, 2 * nodes)?;
        self.ends.resize(context, leaves.saturating_sub(1))?;
        self.cached = None;
        Ok(())
    }

    /// Encodes the build from `aabbs` (indexed by body): the whole build, or, for the
    /// [`REFITS_PER_BUILD`] encodes after one, the tree of the last build's order refit to
    /// `aabbs`.
    fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        aabbs: &GpuVec<Aabb>,
    ) -> Result<(), GpuError> {
        if self.leaves() == 0 {
            return Ok(());
        }
        // New dispatches (new bodies, buffers or AABBs) sort the codes again.
        let mut whole = self.refits >= REFITS_PER_BUILD;
        if self
            .cached
            .as_ref()
            .is_none_or(|(buffer, ..)| buffer != aabbs.buffer())
        {
            let (codes, build) = self.dispatches(context, aabbs)?;
            self.cached = Some((aabbs.buffer().clone(), codes, build));
            whole = true;
        }
        let Some((_, codes, build)) = &self.cached else {
            unreachable!("built above")
        };
        if whole {
            encode_all(pass, codes);
            self.sort.encode(
                context,
                pass,
                (&self.codes, &self.bodies),
                (&mut self.sorted_codes, &mut self.sorted_bodies),
                MORTON_BITS,
            )?;
            self.refits = 0;
        } else {
            self.refits += 1;
        }
        // From the sorted codes, the same nodes again (and their boxes reset), refit.
        encode_all(pass, build);
        Ok(())
    }

    fn dispatches(
        &mut self,
        context: &GpuContext,
        aabbs: &GpuVec<Aabb>,
    ) -> Result<(Vec<Dispatch>, Vec<Dispatch>), GpuError> {
        let leaves = self.leaves();
        // The sort writes its outputs at their length: size them now so the build's bind
        // groups see the buffers the sort will write.
        self.sorted_codes.resize(context, leaves)?;
        self.sorted_bodies.resize(context, leaves)?;
        let [partial, fold, morton, internal, refit] = &self.kernels;
        let partials = workgroups_for(leaves, BOUNDS_BLOCK);
        let code_slots = UniformSlots::new(
            context,
            "lbvh code params",
            &[CodeParams {
                leaf_count: leaves as u32,
                partial_count: partials,
                padding0: 0,
                padding1: 0,
            }],
        );
        let code_group = |kernel: &Kernel| {
            kernel.bind(
                context,
                &[
                    code_slots.binding(0),
                    aabbs.whole(),
                    self.bodies.whole(),
                    self.scene.whole(),
                    self.codes.whole(),
                ],
            )
        };
        let codes = vec![
            partial.dispatch(code_group(partial), partials),
            fold.dispatch(code_group(fold), 1),
            morton.dispatch(code_group(morton), workgroups_for(leaves, WORKGROUP_SIZE)),
        ];
        let build_slots = UniformSlots::new(
            context,
            "lbvh build params",
            &[BuildParams {
                leaf_count: leaves as u32,
                padding0: 0,
                padding1: 0,
                padding2: 0,
            }],
        );
        let build_group = |kernel: &Kernel| {
            kernel.bind(
                context,
                &[
                    build_slots.binding(0),
                    aabbs.whole(),
                    self.sorted_codes.whole(),
                    self.sorted_bodies.whole(),
                    self.nodes.whole(),
                    self.bounds.whole(),
                    self.ends.whole(),
                ],
            )
        };
        let build = vec![
            internal.dispatch(
                build_group(internal),
                workgroups_for(leaves - 1, WORKGROUP_SIZE),
            ),
            refit.dispatch(build_group(refit), workgroups_for(leaves, WORKGROUP_SIZE)),
        ];
        Ok((codes, build))
    }

    /// Depth of the deepest leaf (the root has depth 0), from the parent links read back.
    fn depth(&mut self, context: &GpuContext) -> Result<usize, GpuError> {
        let leaves = self.leaves();
        let nodes = self.nodes.download(context)?;
        Ok((0..leaves)
            .map(|leaf| {
                let mut node = leaves - 1 + leaf;
                let mut depth = 0;
                while node != 0 {
                    node = nodes[4 * node + 2] as usize;
                    depth += 1;
                }
                depth
            })
            .max()
            .unwrap_or(0))
    }
}

/// What the cached traversal dispatches were built for: the buffers bound, the sizes, and
/// whether the extra pairs are last step's resting ones.
type PairsKey = (Traversal, [wgpu::Buffer; 10], [usize; 5], bool);

/// Where the pairs that no tree finds come from.
#[derive(Clone, Debug)]
enum Extra {
    /// The host's list, in `extra` ([`GpuBroadphase::set_extra_pairs`]).
    Host,
    /// Last step's keys on the device, `len` of them (padding included), of which those of
    /// two static bodies ([`GpuBroadphase::set_resting_pairs_from`]).
    Resting { keys: wgpu::Buffer, len: usize },
}

/// The GPU broadphase; see the module documentation.
#[derive(Debug)]
pub struct GpuBroadphase {
    traversal: Traversal,
    dynamic: Lbvh,
    fixed: Lbvh,
    /// Whether the static tree must be rebuilt at the next encode.
    fixed_stale: bool,
    /// The mask of the last [`Self::set_bodies`]; the trees' body lists made from it on the
    /// device, and whether they are still to be made at the next encode.
    is_static: Vec<bool>,
    body_lists: GpuBodyLists,
    lists_stale: bool,
    /// [`Self::find_pairs`]: the static AABBs the static tree was built from, and the AABBs.
    static_aabbs: Vec<Aabb>,
    aabbs: Option<GpuVec<Aabb>>,
    /// Appended keys in the packed form (`capacity` long), and the sort's values, which carry
    /// nothing.
    appended: GpuVec<u64>,
    appended_values: GpuVec<u32>,
    sorted_packed: GpuVec<u64>,
    sorted_values: GpuVec<u32>,
    /// The sorted keys as pair keys.
    sorted_keys: GpuVec<u64>,
    /// One word: pairs found by the last run, including any past the capacity.
    count: GpuVec<u32>,
    /// The count read back, reused.
    count_host: Vec<u32>,
    /// Pairs appended to the trees' ([`Self::set_extra_pairs`]).
    extra: GpuVec<u64>,
    extra_source: Extra,
    /// `is_static` a bit a body (bit b % 32 of word b / 32), for `append_resting`, and the
    /// host's words, kept from call to call.
    static_bits: GpuVec<u32>,
    static_words: Vec<u32>,
    sort: RadixSort,
    /// Dispatches before the key sort (fills, traversal) and after it (unpacking).
    cached: Option<(PairsKey, Vec<Dispatch>, Vec<Dispatch>)>,
}

impl GpuBroadphase {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let mut broadphase = Self {
            traversal: Traversal::default(),
            dynamic: Lbvh::new(context)?,
            fixed: Lbvh::new(context)?,
            fixed_stale: true,
            is_static: Vec::new(),
            body_lists: GpuBodyLists::new(context)?,
            lists_stale: false,
            static_aabbs: Vec::new(),
            aabbs: None,
            appended: GpuVec::with_capacity(context, "pair keys", 0)?,
            appended_values: GpuVec::with_capacity(context, "pair sort values", 0)?,
            sorted_packed: GpuVec::with_capacity(context, "sorted packed keys", 0)?,
            sorted_values: GpuVec::with_capacity(context, "sorted pair values", 0)?,
            sorted_keys: GpuVec::with_capacity(context, "sorted pair keys", 0)?,
            count: GpuVec::from_slice(context, "pair count", &[0])?,
            count_host: Vec::with_capacity(1),
            extra: GpuVec::with_capacity(context, "extra pair keys", 0)?,
            extra_source: Extra::Host,
            static_bits: GpuVec::from_slice(context, "static body bits", &[0])?,
            static_words: Vec::new(),
            sort: RadixSort::new(),
            cached: None,
        };
        broadphase.set_capacity(context, INITIAL_CAPACITY)?;
        Ok(broadphase)
    }

    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    pub fn set_traversal(&mut self, traversal: Traversal) {
        self.traversal = traversal;
    }

    /// Keys the buffers hold before they must grow.
    pub fn capacity(&self) -> usize {
        self.appended.len()
    }

    /// Reallocates the key buffers for `capacity` keys (contents are lost: call between runs).
    pub fn set_capacity(&mut self, context: &GpuContext, capacity: usize) -> Result<(), GpuError> {
        let capacity = capacity.max(1);
        self.appended = GpuVec::with_capacity(context, "pair keys", capacity)?;
        self.appended_values = GpuVec::with_capacity(context, "pair sort values", capacity)?;
        self.appended.resize(context, capacity)?;
        self.appended_values.resize(context, capacity)?;
        self.sorted_packed = GpuVec::with_capacity(context, "sorted packed keys", capacity)?;
        self.sorted_values = GpuVec::with_capacity(context, "sorted pair values", capacity)?;
        self.sorted_keys = GpuVec::with_capacity(context, "sorted pair keys", capacity)?;
        self.sorted_keys.resize(context, capacity)?;
        self.cached = None;
        Ok(())
    }

    /// Which body slots are static (the rest are dynamic). A changed mask makes the trees' body
    /// lists (`body_lists.rs`) and rebuilds the static tree at the next encode.
    pub fn set_bodies(&mut self, context: &GpuContext, is_static: &[bool]) -> Result<(), GpuError> {
        if is_static == self.is_static {
            return Ok(());
        }
        assert!(
            u32::try_from(is_static.len()).is_ok_and(|count| count < u32::MAX),
            "body indices fit below u32::MAX"
        );
        // Forgotten until the lists are sized and the bits sent: a failure on the way leaves
        // the next call to make them again.
        self.is_static.clear();
        // In a settling pile islands sleep or wake, and so change this, at most steps: the
        // host packs the bits and counts them, the device makes the lists.
        let words = &mut self.static_words;
        words.clear();
        words.extend(is_static.chunks(32).map(|bodies| {
            let bits = bodies.iter().enumerate();
            bits.fold(0u32, |word, (bit, &fixed)| word | u32::from(fixed) << bit)
        }));
        let fixed = words
            .iter()
            .map(|word| word.count_ones() as usize)
            .sum::<usize>();
        // A binding cannot be empty.
        if words.is_empty() {
            words.push(0);
        }
        self.dynamic
            .set_body_count(context, is_static.len() - fixed)?;
        self.fixed.set_body_count(context, fixed)?;
        self.static_bits.upload(context, words)?;
        self.is_static.extend_from_slice(is_static);
        self.lists_stale = true;
        self.fixed_stale = true;
        self.cached = None;
        Ok(())
    }

    /// Forgets the mask, so that the next [`Self::set_bodies`] makes the lists again: after a
    /// submission that failed, whose lists may not have been made.
    pub fn forget_bodies(&mut self) {
        self.is_static.clear();
    }

    /// Sorted pair keys that the stage reports besides the trees' pairs, from the next encode
    /// on: pairs whose bodies are both static to the trees (a sleeping body's resting pairs,
    /// which the host keeps), so none is found twice. Empty by default.
    pub fn set_extra_pairs(&mut self, context: &GpuContext, keys: &[u64]) -> Result<(), GpuError> {
        debug_assert!(keys.windows(2).all(|w| w[0] < w[1]), "sorted, distinct");
        self.extra_source = Extra::Host;
        if keys.is_empty() && self.extra.is_empty() {
            return Ok(());
        }
        self.extra.upload(context, keys)
    }

    /// The extra pairs are, from the next encode on, those of `keys` (last step's pair keys,
    /// sorted, padded with `u64::MAX`, as this stage left them) whose bodies are both static
    /// to the trees ([`Self::set_bodies`]): a sleeping body's resting pairs, found on the
    /// device instead of sent by the host. The same pairs as the host's list when every body
    /// slot is live (a free slot is static too, and its pairs are the host's to drop).
    pub fn set_resting_pairs_from(&mut self, keys: &GpuVec<u64>) {
        self.extra_source = Extra::Resting {
            keys: keys.buffer().clone(),
            len: keys.len(),
        };
    }

    /// Rebuilds the static tree at the next encode (static bodies moved).
    pub fn invalidate_static_tree(&mut self) {
        self.fixed_stale = true;
    }

    /// The sorted keys, `capacity` long, `u64::MAX` past the count (see the invariants).
    pub fn keys(&self) -> &GpuVec<u64> {
        &self.sorted_keys
    }

    /// One word: the pair count of the last run (more than the capacity after an overflow).
    pub fn count(&self) -> &GpuVec<u32> {
        &self.count
    }

    /// Encodes the whole stage on `aabbs` (indexed by body slot, as many as the mask of
    /// [`Self::set_bodies`]). Nothing is read back.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        aabbs: &GpuVec<Aabb>,
    ) -> Result<(), GpuError> {
        self.encode_trees(context, pass, aabbs)?;
        self.encode_pairs(context, pass)
    }

    /// The first half of [`Self::encode`]: rebuilds the dynamic tree, and the static tree when
    /// it is stale.
    pub fn encode_trees(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        aabbs: &GpuVec<Aabb>,
    ) -> Result<(), GpuError> {
        debug_assert_eq!(aabbs.len(), self.is_static.len(), "one AABB per body slot");
        if self.lists_stale {
            let bits = (&self.static_bits, self.is_static.len());
            let lists = (&self.dynamic.bodies, &self.fixed.bodies);
            self.body_lists.encode(context, pass, bits, lists)?;
            self.lists_stale = false;
        }
        self.dynamic.encode(context, pass, aabbs)?;
        if self.fixed_stale {
            self.fixed.encode(context, pass, aabbs)?;
            self.fixed_stale = false;
        }
        Ok(())
    }

    /// The second half of [`Self::encode`]: traversal and key sort on the trees as the last
    /// [`Self::encode_trees`] left them (so the traversal can be timed alone).
    pub fn encode_pairs(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
    ) -> Result<(), GpuError> {
        let (extra, extra_len) = self.extra_keys();
        let key = (
            self.traversal,
            [
                self.dynamic.nodes.buffer().clone(),
                self.dynamic.bounds.buffer().clone(),
                self.fixed.nodes.buffer().clone(),
                self.fixed.bounds.buffer().clone(),
                self.appended.buffer().clone(),
                self.count.buffer().clone(),
                self.sorted_packed.buffer().clone(),
                self.sorted_keys.buffer().clone(),
                extra.clone(),
                self.static_bits.buffer().clone(),
            ],
            [
                self.dynamic.leaves(),
                self.fixed.leaves(),
                self.capacity(),
                self.is_static.len(),
                extra_len,
            ],
            matches!(self.extra_source, Extra::Resting { .. }),
        );
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let (search, unpack) = self.pair_dispatches(context)?;
            self.cached = Some((key, search, unpack));
        }
        let key_bits = 2 * self.body_bits();
        let Some((_, search, unpack)) = &self.cached else {
            unreachable!("built above")
        };
        encode_all(pass, search);
        // Only the packed key's 2 × body_bits bits are sorted on (see `lbvh_traverse.wgsl`).
        self.sort.encode(
            context,
            pass,
            (&self.appended, &self.appended_values),
            (&mut self.sorted_packed, &mut self.sorted_values),
            key_bits,
        )?;
        encode_all(pass, unpack);
        Ok(())
    }

    /// The buffer of keys the extra pairs come from, and how many it holds.
    fn extra_keys(&self) -> (&wgpu::Buffer, usize) {
        match &self.extra_source {
            Extra::Host => (self.extra.buffer(), self.extra.len()),
            Extra::Resting { keys, len } => (keys, *len),
        }
    }

    /// Bit length of the body count: every body index fits in it, and all ones does not
    /// occur as an index (indices are below the count). At least 1, as the kernels expect.
    fn body_bits(&self) -> u32 {
        (u32::BITS - (self.is_static.len() as u32).leading_zeros()).max(1)
    }

    fn pair_dispatches(
        &self,
        context: &GpuContext,
    ) -> Result<(Vec<Dispatch>, Vec<Dispatch>), GpuError> {
        let [_, _, source] = wgsl();
        let (extra, extra_len) = self.extra_keys();
        let slots = UniformSlots::new(
            context,
            "traverse params",
            &[TraverseParams {
                dynamic_leaves: self.dynamic.leaves() as u32,
                static_leaves: self.fixed.leaves() as u32,
                capacity: self.capacity() as u32,
                body_bits: self.body_bits(),
                extra_count: extra_len as u32,
                _pad0: 0,
                _pad1: 0,
                _pad2: 0,
            }],
        );
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &TRAVERSE_BINDINGS);
        let append_entry = match self.extra_source {
            Extra::Host => "append_extra",
            Extra::Resting { .. } => "append_resting",
        };
        let [traverse, append, unpack] =
            [self.traversal.entry(), append_entry, "unpack_keys"].map(kernel);
        let bind = |kernel: &Kernel| {
            kernel.bind(
                context,
                &[
                    slots.binding(0),
                    self.dynamic.nodes.whole(),
                    self.dynamic.bounds.whole(),
                    self.fixed.nodes.whole(),
                    self.fixed.bounds.whole(),
                    self.appended.whole(),
                    self.count.whole(),
                    self.sorted_packed.whole(),
                    self.sorted_keys.whole(),
                    extra.as_entire_buffer_binding(),
                    self.static_bits.whole(),
                ],
            )
        };
        let mut search = fill_dispatch(
            context,
            self.appended.buffer(),
            2 * self.capacity(),
            u32::MAX,
        )?;
        search.extend(fill_dispatch(context, self.count.buffer(), 1, 0)?);
        search.push(traverse.dispatch(
            bind(&traverse),
            workgroups_for(self.dynamic.leaves(), WORKGROUP_SIZE),
        ));
        if extra_len > 0 {
            search.push(append.dispatch(bind(&append), workgroups_for(extra_len, WORKGROUP_SIZE)));
        }
        let unpack = vec![unpack.dispatch(
            bind(&unpack),
            workgroups_for(self.capacity(), WORKGROUP_SIZE),
        )];
        Ok((search, unpack))
    }

    /// Reads the pair count back (a round trip). When the last run found more pairs than the
    /// buffers hold, grows them to fit and returns true: the caller must run the stage again.
    pub fn check_capacity(&mut self, context: &GpuContext) -> Result<bool, GpuError> {
        let count = self.pair_count(context)?;
        self.grow_for(context, count)
    }

    /// Upload, encode, submit, read back: the sorted pair keys of `aabbs` (one per body slot)
    /// with `is_static` saying which slots are static. For parity tests and for a CPU step
    /// that runs only this stage on the GPU. The static tree is rebuilt only when the static
    /// bodies or their AABBs differ from the last call's.
    pub fn find_pairs(
        &mut self,
        context: &GpuContext,
        aabbs: &[Aabb],
        is_static: &[bool],
    ) -> Result<Vec<u64>, GpuError> {
        assert_eq!(aabbs.len(), is_static.len(), "one AABB per body slot");
        self.set_bodies(context, is_static)?;
        let static_aabbs: Vec<Aabb> = aabbs
            .iter()
            .zip(is_static)
            .filter(|&(_, &fixed)| fixed)
            .map(|(aabb, _)| *aabb)
            .collect();
        if static_aabbs != self.static_aabbs {
            self.static_aabbs = static_aabbs;
            self.fixed_stale = true;
        }
        let mut uploaded = self.aabbs.take().map_or_else(
            || GpuVec::with_capacity(context, "broadphase aabbs", aabbs.len()),
            Ok,
        )?;
        uploaded.upload(context, aabbs)?;
        let result = loop {
            let run =
                context.submit_pass("broadphase", |pass| self.encode(context, pass, &uploaded));
            match run.and_then(|()| self.check_capacity(context)) {
                Ok(true) => continue,
                other => break other,
            }
        };
        // Kept for the next call, so the cached dispatches stay valid.
        self.aabbs = Some(uploaded);
        if result.is_err() {
            // Its submission may not have run: the trees' body lists are made again.
            self.forget_bodies();
        }
        result?;
        self.download_keys(context)
    }

    /// Reads back the pair count of the last run (a round trip; more than the capacity after
    /// an overflow).
    pub fn pair_count(&mut self, context: &GpuContext) -> Result<usize, GpuError> {
        self.count.download_into(context, &mut self.count_host)?;
        Ok(self.count_host[0] as usize)
    }

    /// Records the copy of the pair count into its staging buffer at the end of `encoder`, so
    /// that it comes back with the submission's other read-backs
    /// ([`Self::read_encoded_count`] after the submission).
    pub fn encode_count_download(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        self.count.encode_download(context, encoder);
    }

    /// The pair count [`Self::encode_count_download`] copied.
    pub fn read_encoded_count(&mut self, context: &GpuContext) -> Result<usize, GpuError> {
        self.count.read_download(context, &mut self.count_host)?;
        Ok(self.last_pair_count())
    }

    /// Grows the key buffers when `count` pairs do not fit (the run must be done again);
    /// whether they grew.
    pub fn grow_for(&mut self, context: &GpuContext, count: usize) -> Result<bool, GpuError> {
        if count <= self.capacity() {
            return Ok(false);
        }
        // A quarter more than the count, not the next power of two: the pair search, its sort,
        // the pair diff and the narrowphase all pass over the whole capacity, padding included
        // (a settled pile of 100k boxes has 584k pairs, which the next power of two would
        // pad to 1M).
        self.set_capacity(context, (count + count / 4).next_multiple_of(64))?;
        Ok(true)
    }

    /// The pair count that [`Self::pair_count`] (or [`Self::check_capacity`]) last read.
    pub fn last_pair_count(&self) -> usize {
        self.count_host.first().map_or(0, |&count| count as usize)
    }

    /// Reads back the last run's sorted keys, without the padding (the run must not have
    /// overflowed: see [`Self::check_capacity`]).
    pub fn download_keys(&mut self, context: &GpuContext) -> Result<Vec<u64>, GpuError> {
        let mut keys = Vec::new();
        self.download_keys_into(context, &mut keys)?;
        Ok(keys)
    }

    /// [`Self::download_keys`] into a vector the caller reuses (no allocation per step).
    pub fn download_keys_into(
        &mut self,
        context: &GpuContext,
        keys: &mut Vec<u64>,
    ) -> Result<(), GpuError> {
        let count = self.pair_count(context)?;
        debug_assert!(count <= self.capacity(), "the run overflowed");
        self.sorted_keys.download_into(context, keys)?;
        keys.truncate(count);
        Ok(())
    }

    /// Depth of the dynamic tree's deepest leaf (root: 0), read back: for tests and stats.
    pub fn dynamic_tree_depth(&mut self, context: &GpuContext) -> Result<usize, GpuError> {
        self.dynamic.depth(context)
    }
}
