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
