//! Stable key-value LSD radix sort on the GPU (8-bit digits), for u32 keys and for u64 keys
//! (the broadphase's pair keys, two u32 words, low word first), with its CPU twin.
//!
//! Onesweep-style (see `radix_sort.wgsl`): one dispatch zeroes the sort's state, one counts
//! the digits of every pass over the whole input, then one dispatch per pass ranks each tile,
//! finds its place by a decoupled look-back and writes each digit's elements as one run. A
//! 32-bit key takes 4 passes, fewer when the caller says how many key bits are used (cell ids
//! of a 64³ grid need 18 bits: 3 passes). The sort reads the input buffers and writes the
//! output buffers, ping-ponging through its own scratch so the last pass always lands in the
//! output; the input is left as it was.
//!
//! Two ways to rank a tile's elements by digit ([`SortPath`]): bit masks in workgroup memory
//! (any adapter) or subgroup ballots (adapters with subgroups).
//!
//! Past one storage binding ([`GpuVec::windowed`] buffers) the sort binds a window at a time:
//! the histogram runs once per input window, each pass once per (input window, output window),
//! each run writing the elements whose place lies in its output window (`radix_sort.wgsl`).
//! On Mesa's CPU drivers input windows are also short enough for their loop limit
//! ([`look_back_tiles`]). A pass's tile statuses must fit one binding: a quarter of the input
//! keys' bytes for u32 keys and an eighth for u64, so up to 4 GiB of keys on a 1 GiB binding
//! limit.
//!
//! Stability: equal keys keep their input order (the rank inside a tile is the position among
//! equal digits, tiles are laid out in order by the look-back), so sorting (key, index) pairs
//! gives the same result on every device and every run.

use bytemuck::{Pod, Zeroable};

use crate::gpu::buffer::{GpuVec, Window, windows, windows_at_most};
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::gpu::prims::fill::fill_dispatch;
use crate::gpu::prims::look_back_tiles;

/// Values per digit.
const RADIX: u32 = 256;
const _: () = assert!(WORKGROUP_SIZE == RADIX, "a thread per digit value");
/// Elements per thread of a tile: more, fewer tiles to look back over and longer runs per
/// digit in the output. At least 8, so that the baseline's rank masks (RADIX × WORKGROUP_SIZE
/// bits) fit in the tile's workgroup memory.
const ROUNDS: u32 = 8;
const _: () = assert!(ROUNDS * WORKGROUP_SIZE >= RADIX * WORKGROUP_SIZE / 32);
/// Elements per tile (one workgroup of a pass).
pub const RADIX_TILE: u32 = ROUNDS * WORKGROUP_SIZE;
/// Elements each thread of the histogram counts.
const HISTOGRAM_ITEMS: u32 = 16;
/// Times a look-back polls an earlier tile's status before counting that tile's digits itself.
const POLLS: u32 = 64;
/// The status words hold counts below 2^30 (two flag bits above).
const MAX_COUNT: usize = (1 << 30) - 1;

const WGSL: &str = include_str!("radix_sort.wgsl");
const WGSL_BASELINE: &str = include_str!("radix_rank_baseline.wgsl");
const WGSL_SUBGROUPS: &str = include_str!("radix_rank_subgroups.wgsl");
const BINDINGS: [Binding; 7] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];
/// Elements of one histogram workgroup: a window holds whole ones, and so whole tiles.
const HISTOGRAM_BLOCK: u32 = HISTOGRAM_ITEMS * WORKGROUP_SIZE;
const _: () = assert!(HISTOGRAM_BLOCK.is_multiple_of(RADIX_TILE));

/// A key the radix sort handles: a whole number of u32 words, least significant first.
pub trait RadixKey: Pod + Ord {
    const WORDS: u32;
}

impl RadixKey for u32 {
    const WORDS: u32 = 1;
}

/// On little-endian hosts (all wgpu targets) a u64 is its low word, then its high word.
impl RadixKey for u64 {
    const WORDS: u32 = 2;
}

/// Mirrors `RadixParams` in `radix_sort.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RadixParams {
    pub count: u32,
    pub pass_index: u32,
    pub passes: u32,
    pub tile_count: u32,
    pub first_tile: u32,
    pub destination_first: u32,
    pub destination_count: u32,
    pub replay: u32,
}
const _: () = assert!(size_of::<RadixParams>() == 32);

/// How a tile's elements are ranked by digit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SortPath {
    /// Per-digit bit masks in workgroup memory, three barriers per WORKGROUP_SIZE elements:
    /// any adapter.
    Baseline,
    /// Subgroup ballots and a count per subgroup and digit, two barriers per tile: adapters
    /// with subgroups whose smallest width leaves room for those counts.
    Subgroups,
}

impl SortPath {
    /// The fastest path `context` runs.
    pub fn best(context: &GpuContext) -> Self {
        if Self::Subgroups.runs_on(context) {
            Self::Subgroups
        } else {
            Self::Baseline
        }
    }

    /// Whether `context` can run this path.
    pub fn runs_on(self, context: &GpuContext) -> bool {
        match self {
            Self::Baseline => true,
            Self::Subgroups => {
                let limit = context.device.limits().max_compute_workgroup_storage_size;
                context.has_subgroups()
                    && SCATTER_BYTES + subgroup_counts_bytes(context.info.subgroup_min_size)
                        <= limit
            }
        }
    }
}

/// Workgroup memory of the scatter besides the subgroup counts: the tile, three words per
/// digit, two words.
const SCATTER_BYTES: u32 = (RADIX_TILE + 3 * RADIX + 2) * 4;

/// Workgroup memory of the subgroup ranking's counts (16 bits per subgroup and digit) for
/// subgroups at least `min_width` wide.
fn subgroup_counts_bytes(min_width: u32) -> u32 {
    (WORKGROUP_SIZE / min_width.max(1)) * RADIX * 2
}

/// The sort's WGSL on `path`, for subgroups at least `min_subgroup_width` wide (ignored on the
/// baseline path).
pub fn wgsl(key_words: u32, path: SortPath, min_subgroup_width: u32) -> Source {
    let source = Source::new()
        .constant_u32("KEY_WORDS", key_words)
        .constant_u32("ROUNDS", ROUNDS)
        .constant_u32("HISTOGRAM_ITEMS", HISTOGRAM_ITEMS)
        .constant_u32("POLLS", POLLS)
        .snippet("radix_sort.wgsl", WGSL);
    match path {
        SortPath::Baseline => source.snippet("radix_rank_baseline.wgsl", WGSL_BASELINE),
        SortPath::Subgroups => source
            .constant_u32("SUBGROUPS", WORKGROUP_SIZE / min_subgroup_width.max(1))
            .snippet("radix_rank_subgroups.wgsl", WGSL_SUBGROUPS),
    }
}

/// CPU twin: a stable sort by key (same order as the GPU, since both are stable).
pub fn radix_sort_cpu<K: RadixKey>(keys: &[K], values: &[u32]) -> (Vec<K>, Vec<u32>) {
    let mut pairs: Vec<(K, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.sort_by_key(|&(key, _)| key);
    pairs.into_iter().unzip()
}

/// Number of 8-bit passes for keys whose set bits all lie below `key_bits`.
pub fn passes_for(key_bits: u32) -> u32 {
    key_bits.div_ceil(8)
}

/// The radix sort of one set of buffers, built once and encoded every step.
#[derive(Debug, Default)]
pub struct RadixSort {
    /// None: the context's best path.
    path: Option<SortPath>,
    cached: Option<(SortKey, Vec<Dispatch>)>,
    /// The histogram and scatter kernels for (key words, path): kept, so that a sort of a new
    /// count (a tree's leaves, each step a body sleeps) binds them again without composing
    /// and hashing their source (about half of rebuilding the dispatches).
    kernels: Option<((u32, SortPath), [Kernel; 2])>,
}

/// What the cached dispatches were built for: buffers, count, key bits.
type SortKey = ([wgpu::Buffer; 4], usize, u32);

impl RadixSort {
    pub fn new() -> Self {
        Self::default()
    }

    /// A sort that always takes `path` (for tests and benchmarks of each path).
    ///
    /// # Panics
    ///
    /// When encoding on a context the path does not run on ([`SortPath::runs_on`]): a
    /// caller's mistake, as asking for subgroups the adapter lacks.
    pub fn on(path: SortPath) -> Self {
        Self {
            path: Some(path),
            ..Self::default()
        }
    }

    /// Encodes a sort of `input` = (keys, values) by key, stable, into `output`, resized to
    /// the input length. Only the low `key_bits` bits of the keys are looked at.
    pub fn encode<K: RadixKey>(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        input: (&GpuVec<K>, &GpuVec<u32>),
        output: (&mut GpuVec<K>, &mut GpuVec<u32>),
        key_bits: u32,
    ) -> Result<(), GpuError> {
        let ((keys_in, values_in), (keys_out, values_out)) = (input, output);
        let count = keys_in.len();
        debug_assert_eq!(values_in.len(), count, "one value per key");
        let key_bits = key_bits.min(32 * K::WORDS);
        keys_out.resize(context, count)?;
        values_out.resize(context, count)?;
        let key = (
            [
                keys_in.buffer().clone(),
                values_in.buffer().clone(),
                keys_out.buffer().clone(),
                values_out.buffer().clone(),
            ],
            count,
            key_bits,
        );
        let dispatches = match &mut self.cached {
            Some((cached_key, dispatches)) if *cached_key == key => dispatches,
            cached => {
                let path = self.path.unwrap_or_else(|| SortPath::best(context));
                let kernels = &mut self.kernels;
                let buffers = &key.0;
                let dispatches =
                    sort_dispatches::<K>(path, context, kernels, buffers, count, key_bits)?;
                &mut cached.insert((key, dispatches)).1
            }
        };
        encode_all(pass, dispatches);
        Ok(())
    }
}

/// The histogram and scatter kernels for keys of `words` u32 on `path`.
fn kernels(context: &GpuContext, words: u32, path: SortPath) -> [Kernel; 2] {
    let source = wgsl(words, path, context.info.subgroup_min_size);
    let kernel = |label, entry| Kernel::new(context, label, &source, entry, &BINDINGS);
    [
        kernel("radix histogram", "histogram"),
        kernel("radix scatter", "scatter"),
    ]
}

/// Builds the passes, with the kernels `kernels` holds for (key words, path), else compiled
/// into it ([`kernels`]). `buffers` = [keys in, values in, keys out, values out].
fn sort_dispatches<K: RadixKey>(
    path: SortPath,
    context: &GpuContext,
    kernels: &mut Option<((u32, SortPath), [Kernel; 2])>,
    buffers: &[wgpu::Buffer; 4],
    count: usize,
    key_bits: u32,
) -> Result<Vec<Dispatch>, GpuError> {
    let passes = passes_for(key_bits);
    if count == 0 || passes == 0 {
        // Nothing to order: the output is the input.
        return copy_dispatches::<K>(context, buffers, count);
    }
    if count > MAX_COUNT {
        return Err(GpuError::BufferTooLarge {
            what: "radix sort (at most 2^30 - 1 keys)",
            needed: (count * size_of::<K>()) as u64,
            limit: (MAX_COUNT * size_of::<K>()) as u64,
        });
    }
    assert!(
        path.runs_on(context),
        "{path:?} does not run on this adapter"
    );
    let [histogram, scatter] = match kernels {
        Some((built_for, kernels)) if *built_for == (K::WORDS, path) => kernels,
        _ => {
            &kernels
                .insert(((K::WORDS, path), self::kernels(context, K::WORDS, path)))
                .1
        }
    };
    let tiles = workgroups_for(count, RADIX_TILE) as usize;
    // Input windows also bound the look-back ([`look_back_tiles`]); output windows only the
    // binding.
    let inputs = windows_at_most(
        context,
        count,
        size_of::<K>(),
        HISTOGRAM_BLOCK as usize,
        look_back_tiles(context).saturating_mul(RADIX_TILE as usize),
    )?;
    let outputs = windows(context, count, size_of::<K>(), HISTOGRAM_BLOCK as usize)?;
    // The digit counts of every pass, then each pass's tile statuses, bound a pass at a time.
    let counts = Window {
        first: 0,
        len: 4 * K::WORDS as usize * RADIX as usize,
    };
    let pass_status = |pass: usize| Window {
        first: counts.len + pass * tiles * RADIX as usize,
        len: tiles * RADIX as usize,
    };
    let limit = context.device.limits().max_storage_buffer_binding_size;
    let status_bytes = (pass_status(0).len * 4) as u64;
    if status_bytes > limit {
        return Err(GpuError::BufferTooLarge {
            what: "radix sort tile statuses (one pass)",
            needed: status_bytes,
            limit,
        });
    }
    let passes = passes as usize;
    let state_words = pass_status(passes).first;
    let state = GpuVec::<u32>::windowed(context, "radix state", state_words)?;
    let scratch_keys = GpuVec::<K>::windowed(context, "radix scratch keys", count)?;
    let scratch_values = GpuVec::<u32>::windowed(context, "radix scratch values", count)?;
    // The chain of (keys, values) buffers: input, then alternating output and scratch so
    // that the last pass writes the output.
    let chain: Vec<(&wgpu::Buffer, &wgpu::Buffer)> = (0..=passes)
        .map(|step| {
            if step == 0 {
                (&buffers[0], &buffers[1])
            } else if (passes - step).is_multiple_of(2) {
                (&buffers[2], &buffers[3])
            } else {
                (scratch_keys.buffer(), scratch_values.buffer())
            }
        })
        .collect();
    // The runs in order: the histogram of each input window (with pass 0's bindings: its
    // input keys are the sort's input), then each pass's (input window, output window) pairs.
    struct Run<'k> {
        kernel: &'k Kernel,
        workgroups: u32,
        pass: usize,
        input: Window,
        output: Window,
        replay: bool,
    }
    let mut runs: Vec<Run> = inputs
        .iter()
        .map(|&input| Run {
            kernel: histogram,
            workgroups: workgroups_for(input.len, HISTOGRAM_BLOCK),
            pass: 0,
            input,
            output: input,
            replay: false,
        })
        .collect();
    for pass in 0..passes {
        for &input in &inputs {
            for (index, &output) in outputs.iter().enumerate() {
                runs.push(Run {
                    kernel: scatter,
                    workgroups: workgroups_for(input.len, RADIX_TILE),
                    pass,
                    input,
                    output,
                    replay: index > 0,
                });
            }
        }
    }
    let blocks: Vec<RadixParams> = runs
        .iter()
        .map(|run| RadixParams {
            count: run.input.len as u32,
            pass_index: run.pass as u32,
            passes: passes as u32,
            tile_count: workgroups_for(run.input.len, RADIX_TILE),
            first_tile: (run.input.first / RADIX_TILE as usize) as u32,
            destination_first: run.output.first as u32,
            destination_count: run.output.len as u32,
            replay: u32::from(run.replay),
        })
        .collect();
    let slots = UniformSlots::new(context, "radix params", &blocks);
    let key_bytes = size_of::<K>();
    let mut dispatches = fill_dispatch(context, state.buffer(), state_words, 0)?;
    for (slot, run) in runs.iter().enumerate() {
        let (keys_in, values_in) = chain[run.pass];
        let (keys_out, values_out) = chain[run.pass + 1];
        let bind_group = run.kernel.bind(
            context,
            &[
                slots.binding(slot),
                run.input.binding(keys_in, key_bytes),
                run.input.binding(values_in, 4),
                run.output.binding(keys_out, key_bytes),
                run.output.binding(values_out, 4),
                counts.binding(state.buffer(), 4),
                pass_status(run.pass).binding(state.buffer(), 4),
            ],
        );
        dispatches.push(run.kernel.dispatch(bind_group, run.workgroups));
    }
    Ok(dispatches)
}

/// With no key bits to sort by, the sort is a copy; done with the fill kernel's copy entry
/// so that it stays inside the compute pass.
fn copy_dispatches<K: RadixKey>(
    context: &GpuContext,
    buffers: &[wgpu::Buffer; 4],
    count: usize,
) -> Result<Vec<Dispatch>, GpuError> {
    if count == 0 {
        return Ok(Vec::new());
    }
    let mut dispatches = crate::gpu::prims::fill::copy_dispatch(
        context,
        &buffers[0],
        &buffers[2],
        count * K::WORDS as usize,
    )?;
    dispatches.extend(crate::gpu::prims::fill::copy_dispatch(
        context,
        &buffers[1],
        &buffers[3],
        count,
    )?);
    Ok(dispatches)
}
