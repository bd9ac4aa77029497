//! The shared context finds an adapter (lavapipe or llvmpipe on a machine without a GPU) and
//! `GpuVec` round-trips data, growing as needed.

use crate::gpu_common;

use gpu_common::context;
use tumble::gpu::{GpuContext, GpuVec};

#[test]
fn shared_context_is_created_once_and_describes_its_adapter() {
    let first = context();
    let second = GpuContext::shared().expect("the shared context exists now");
    assert_eq!(first.info.name, second.info.name);
    assert!(!first.describe().is_empty());
}

#[test]
fn gpu_vec_round_trips_and_grows_keeping_its_contents() {
    let context = context();
    let data: Vec<u32> = (0..1000).map(|i| i * 7 + 1).collect();
    let mut vector = GpuVec::from_slice(&context, "round trip", &data).expect("upload");
    assert_eq!(vector.download(&context).expect("download"), data);
    let capacity = vector.capacity();
    assert!(vector.reserve(&context, capacity + 1).expect("grow"));
    assert!(vector.capacity() >= 2 * capacity);
    assert_eq!(vector.download(&context).expect("download"), data);
    vector.upload(&context, &[]).expect("empty upload");
    assert!(vector.download(&context).expect("download").is_empty());
}

#[test]
fn oversized_buffer_is_an_error_not_a_panic() {
    let context = context();
    let limit = context.device.limits().max_storage_buffer_binding_size;
    let elements = (limit / 4 + 1) as usize;
    let error = GpuVec::<u32>::with_capacity(&context, "too big", elements).unwrap_err();
    assert!(error.to_string().contains("too big"), "{error}");
}

#[test]
fn kernel_sources_are_kept_from_when_they_are_asked_for() {
    use tumble::gpu::kernel::{Binding, Kernel, Source};
    // A context of its own: the shared one's kernels are the other tests'.
    let context = GpuContext::new().expect("a context");
    let source = |value: u32| {
        Source::new().snippet(
            "test",
            &format!(
                "@group(0) @binding(0) var<uniform> p: vec4<u32>;\n\
                 @group(0) @binding(1) var<storage, read_write> out: array<u32>;\n\
                 @compute @workgroup_size(1) fn main() {{ out[0] = p.x + {value}u; }}"
            ),
        )
    };
    let bindings = [Binding::Uniform, Binding::StorageReadWrite];
    Kernel::new(&context, "before", &source(1), "main", &bindings);
    assert!(
        context.kernel_sources().is_empty(),
        "none kept unless asked"
    );
    context.record_kernel_sources();
    Kernel::new(&context, "after", &source(2), "main", &bindings);
    // Cached, so not compiled again: neither is listed (again).
    Kernel::new(&context, "after", &source(2), "main", &bindings);
    Kernel::new(&context, "before", &source(1), "main", &bindings);
    let sources = context.kernel_sources();
    assert_eq!(sources.len(), 1, "{sources:?}");
    assert_eq!(
        (sources[0].label.as_str(), sources[0].entry.as_str()),
        ("after", "main")
    );
    assert!(sources[0].wgsl.contains("p.x + 2u"), "{}", sources[0].wgsl);
}
