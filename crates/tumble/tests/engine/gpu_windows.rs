//! The primitives on arrays larger than one storage binding ([`GpuVec::windowed`]): fill,
//! copy, scan, reduce, compaction and radix sort agree with their CPU twins when the arrays
//! span many windows. The windows are made small by a device whose binding limit is lowered
//! to 256 KiB (every adapter allows a lower limit), so the sizes stay quick on Mesa's CPU
//! drivers; one test passes the adapter's real limit.

use std::sync::OnceLock;

use crate::gpu_common;

use gpu_common::{Random, context};
use tumble::gpu::kernel::encode_all;
use tumble::gpu::prims::compact::{Compact, compact_cpu};
use tumble::gpu::prims::fill::{copy_dispatch, fill_vec_dispatch};
use tumble::gpu::prims::radix_sort::{RadixKey, RadixSort, SortPath, radix_sort_cpu};
use tumble::gpu::prims::reduce::{Reduce, ReduceOp, ReduceScalar, reduce_cpu};
use tumble::gpu::prims::scan::{Scan, ScanKind, ScanPath, scan_cpu};
use tumble::gpu::{GpuContext, GpuError, GpuVec};

/// The lowered binding limit: 65 536 u32 a window.
const SMALL_BINDING: u64 = 256 << 10;

/// A context whose storage bindings hold at most [`SMALL_BINDING`] bytes; taken with the
/// shared context's turn held (see `gpu_common`), as every GPU test here is.
fn small_bindings() -> GpuContext {
    static SMALL: OnceLock<Result<GpuContext, GpuError>> = OnceLock::new();
    SMALL
        .get_or_init(|| {
            GpuContext::with_limits(|limits| {
                limits.max_storage_buffer_binding_size = SMALL_BINDING;
            })
        })
        .clone()
        .unwrap_or_else(|error| panic!("GPU tests need an adapter: {error}"))
}

/// A windowed vector holding `data`.
fn windowed<T: bytemuck::Pod>(context: &GpuContext, data: &[T]) -> GpuVec<T> {
    let mut vector = GpuVec::windowed(context, "windowed input", data.len()).expect("alloc");
    vector.upload(context, data).expect("upload");
    vector
}

fn empty<T: bytemuck::Pod>(context: &GpuContext) -> GpuVec<T> {
    GpuVec::windowed(context, "windowed output", 0).expect("alloc")
}

#[test]
fn a_plain_vector_grows_up_to_one_binding_not_past_it() {
    let _turn = context();
    let context = small_bindings();
    let most = (SMALL_BINDING / 4) as usize;
    // Past half the limit, doubling would ask for more than a binding holds: the vector takes
    // what fits instead, keeps its elements, and still refuses what does not fit.
    let data: Vec<u32> = (0..most as u32 / 2 + 1).collect();
    let mut vector = GpuVec::<u32>::with_capacity(&context, "plain", data.len()).expect("alloc");
    vector.upload(&context, &data).expect("upload");
    assert!(vector.reserve(&context, data.len() + 1).expect("grows"));
    assert_eq!(vector.capacity(), most);
    assert_eq!(vector.download(&context).expect("download"), data);
    let error = vector.reserve(&context, most + 1).unwrap_err();
    assert!(matches!(error, GpuError::BufferTooLarge { .. }), "{error}");
}

#[test]
fn a_plain_vector_past_one_binding_is_an_error_and_a_windowed_one_is_not() {
    let _turn = context();
    let context = small_bindings();
    let words = (SMALL_BINDING / 4) as usize + 1;
    let error = GpuVec::<u32>::with_capacity(&context, "plain", words).unwrap_err();
    assert!(matches!(error, GpuError::BufferTooLarge { .. }), "{error}");
    let data: Vec<u32> = (0..words as u32).collect();
    let mut vector = windowed(&context, &data);
    assert_eq!(vector.download(&context).expect("download"), data);
}

#[test]
fn fill_and_copy_cover_every_window() {
    let _turn = context();
    let context = small_bindings();
    let count = 5 * (SMALL_BINDING / 4) as usize + 77;
    let mut filled = windowed(&context, &vec![0u32; count]);
    let mut copied = windowed(&context, &vec![0u32; count]);
    let data = Random::new(11).u32s(count);
    let source = windowed(&context, &data);
    let fill = fill_vec_dispatch(&context, &filled, 9u32).expect("fill");
    let copy = copy_dispatch(&context, source.buffer(), copied.buffer(), count).expect("copy");
    assert_eq!(fill.len(), 6, "one dispatch a window");
    context.submit_pass("fill and copy", |pass| {
        encode_all(pass, &fill);
        encode_all(pass, &copy);
    });
    assert!(
        filled
            .download(&context)
            .expect("download")
            .iter()
            .all(|&w| w == 9)
    );
    assert_eq!(copied.download(&context).expect("download"), data);
}

fn scan_windowed(context: &GpuContext, path: ScanPath, input: &[u32], kind: ScanKind) -> Vec<u32> {
    let source = windowed(context, input);
    let mut destination = empty(context);
    let mut scan = Scan::on(path);
    context
        .submit_pass("windowed scan", |pass| {
            scan.encode(context, pass, &source, &mut destination, kind)
        })
        .expect("encode");
    destination.download(context).expect("download")
}

fn scan_paths(context: &GpuContext) -> Vec<ScanPath> {
    let mut paths = vec![ScanPath::Baseline];
    if context.has_subgroups() {
        paths.push(ScanPath::Subgroups);
    }
    paths
}

/// Sizes around window edges: one window exactly, one element more, and five and a bit.
#[test]
fn scan_across_windows_matches_cpu() {
    let _turn = context();
    let context = small_bindings();
    let window = 17 * 3840; // whole tiles that fit 256 KiB
    let mut random = Random::new(5);
    for count in [window, window + 1, 5 * window + 1234] {
        // Small values keep the sums far from wrapping, and large ones check that they wrap.
        for input in [random.u32s_below(count, 100), random.u32s(count)] {
            for kind in [ScanKind::Exclusive, ScanKind::Inclusive] {
                for path in scan_paths(&context) {
                    assert!(
                        scan_windowed(&context, path, &input, kind) == scan_cpu(&input, kind),
                        "{count} elements, {kind:?}, {path:?}"
                    );
                }
            }
        }
    }
}

fn reduce_windowed<T: ReduceScalar>(context: &GpuContext, input: &[T], op: ReduceOp) -> T {
    let source = windowed(context, input);
    let mut output = GpuVec::with_capacity(context, "reduced", 1).expect("alloc");
    let mut reduce = Reduce::new();
    context
        .submit_pass("windowed reduce", |pass| {
            reduce.encode(context, pass, &source, &mut output, op)
        })
        .expect("encode");
    output.download(context).expect("download")[0]
}

#[test]
fn reduce_across_windows_matches_cpu_bitwise() {
    let _turn = context();
    let context = small_bindings();
    let count = 4 * (SMALL_BINDING / 4) as usize + 999;
    let mut random = Random::new(8);
    let words = random.u32s(count);
    let floats: Vec<f32> = random
        .u32s_below(count, 1 << 20)
        .iter()
        .map(|&w| w as f32 / 1024.0 - 512.0)
        .collect();
    for op in [ReduceOp::Min, ReduceOp::Max, ReduceOp::Sum] {
        assert_eq!(
            reduce_windowed(&context, &words, op),
            reduce_cpu(&words, op)
        );
        let gpu = reduce_windowed(&context, &floats, op);
        assert_eq!(gpu.to_bits(), reduce_cpu(&floats, op).to_bits(), "{op:?}");
    }
}

#[test]
fn compaction_across_windows_matches_cpu() {
    let _turn = context();
    let context = small_bindings();
    let count = 4 * (SMALL_BINDING / 4) as usize + 321;
    let mut random = Random::new(3);
    let values = random.u32s(count);
    // Dense at the start and sparse at the end, so kept values cross into earlier windows.
    let flags: Vec<u32> = (0..count)
        .map(|i| u32::from(random.below(count as u32) >= i as u32 / 2))
        .collect();
    let values_gpu = windowed(&context, &values);
    let flags_gpu = windowed(&context, &flags);
    let mut compacted = empty(&context);
    let mut total = GpuVec::with_capacity(&context, "total", 1).expect("alloc");
    let mut compact = Compact::new();
    context
        .submit_pass("windowed compaction", |pass| {
            compact.encode(
                &context,
                pass,
                &values_gpu,
                &flags_gpu,
                &mut compacted,
                &mut total,
            )
        })
        .expect("encode");
    let expected = compact_cpu(&values, &flags);
    let total = total.download(&context).expect("download")[0] as usize;
    assert_eq!(total, expected.len());
    let compacted = compacted.download(&context).expect("download");
    assert!(compacted[..total] == expected[..]);
}

fn sort_windowed<K: RadixKey>(
    context: &GpuContext,
    path: SortPath,
    keys: &[K],
    values: &[u32],
) -> (Vec<K>, Vec<u32>) {
    let keys_in = windowed(context, keys);
    let values_in = windowed(context, values);
    let mut keys_out = empty(context);
    let mut values_out = empty(context);
    let mut sort = RadixSort::on(path);
    context
        .submit_pass("windowed radix sort", |pass| {
            sort.encode(
                context,
                pass,
                (&keys_in, &values_in),
                (&mut keys_out, &mut values_out),
                8 * size_of::<K>() as u32,
            )
        })
        .expect("encode");
    (
        keys_out.download(context).expect("download"),
        values_out.download(context).expect("download"),
    )
}

fn check_sort<K: RadixKey + std::fmt::Debug>(context: &GpuContext, keys: &[K]) {
    // The values are the input order: a stable sort keeps it among equal keys.
    let values: Vec<u32> = (0..keys.len() as u32).collect();
    let expected = radix_sort_cpu(keys, &values);
    for path in [SortPath::Baseline, SortPath::Subgroups] {
        if path.runs_on(context) {
            let sorted = sort_windowed(context, path, keys, &values);
            assert!(sorted == expected, "{} keys, {path:?}", keys.len());
        }
    }
}

#[test]
fn radix_sort_across_windows_matches_cpu_and_is_stable() {
    let _turn = context();
    let context = small_bindings();
    let mut random = Random::new(21);
    // u32 keys: 65 536 a window; u64 keys: 32 768. Few distinct keys test stability.
    let count = 3 * 65_536 + 4_097;
    check_sort(&context, &random.u32s(count));
    check_sort(&context, &random.u32s_below(count, 300));
    let wide: Vec<u64> = (0..2 * 32_768 + 2_049)
        .map(|_| random.next_u64() >> random.below(64))
        .collect();
    check_sort(&context, &wide);
}

/// The adapter's own limit: a scan of more u32 than one binding holds (128 MiB on Mesa's CPU
/// drivers), on every path. Adapters whose binding limit is above 256 MiB are covered by the
/// small-binding tests above. On Mesa's CPU drivers this also crosses their loop limit (see
/// `look_back_tiles`): one dispatch of 3M u32 came out wrong from half-way on.
#[test]
fn scan_past_the_adapters_binding_limit_matches_cpu() {
    let context = context();
    let limit = context.device.limits().max_storage_buffer_binding_size;
    if limit > 256 << 20 {
        eprintln!("binding limit {limit} bytes: the small-binding tests cover windows here");
        return;
    }
    let count = (limit / 4) as usize + 4_321;
    let input = Random::new(2).u32s_below(count, 7);
    let expected = scan_cpu(&input, ScanKind::Exclusive);
    for path in scan_paths(&context) {
        let scanned = scan_windowed(&context, path, &input, ScanKind::Exclusive);
        assert!(scanned == expected, "{path:?}");
    }
}

/// 12M keys in one binding: on Mesa's CPU drivers one dispatch per pass gave a wrong order
/// (their loop limit, see `look_back_tiles`); the look-back windows keep it right.
#[test]
fn radix_sort_of_12m_keys_matches_cpu() {
    let context = context();
    check_sort(&context, &Random::new(4).u32s(12_000_000));
}
