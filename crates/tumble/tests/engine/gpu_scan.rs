//! Prefix scan parity: GPU against the CPU twin, exactly, on random u32 (sums wrap), on both
//! paths of the kernel (the subgroup one where the adapter has subgroups: lavapipe has).

use crate::gpu_common;

use gpu_common::{LARGE, Random, SIZES, context};
use tumble::gpu::GpuVec;
use tumble::gpu::prims::scan::{SCAN_TILE, Scan, ScanKind, ScanPath, scan_cpu};

fn check(count: usize, kind: ScanKind, seed: u64) {
    let context = context();
    let input = Random::new(seed).u32s(count);
    let source = GpuVec::from_slice(&context, "scan input", &input).expect("upload");
    let mut paths = vec![ScanPath::Baseline];
    if context.has_subgroups() {
        paths.push(ScanPath::Subgroups);
    }
    for path in paths {
        let mut destination = GpuVec::with_capacity(&context, "scan output", 0).expect("alloc");
        let mut scan = Scan::on(path);
        context
            .submit_pass("scan", |pass| {
                scan.encode(&context, pass, &source, &mut destination, kind)
            })
            .expect("encode");
        let output = destination.download(&context).expect("download");
        assert_eq!(
            output,
            scan_cpu(&input, kind),
            "{kind:?} scan of {count} on {path:?}"
        );
    }
}

#[test]
fn exclusive_scan_matches_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        check(count, ScanKind::Exclusive, seed as u64);
    }
}

#[test]
fn inclusive_scan_matches_cpu() {
    for (seed, count) in SIZES.into_iter().enumerate() {
        check(count, ScanKind::Inclusive, 100 + seed as u64);
    }
}

#[test]
fn large_scan_matches_cpu() {
    check(LARGE, ScanKind::Exclusive, 7);
}

#[test]
fn many_tile_scan_matches_cpu() {
    // 274 tiles, the last holding one element, with long look-back walks.
    check(273 * SCAN_TILE as usize + 1, ScanKind::Inclusive, 8);
}

#[test]
fn partial_last_tiles_match_cpu() {
    // The subgroup path once went wrong on NVIDIA only when the last tile was partial (its
    // look-back subgroup then holds positions past the end): every such shape, after one and
    // after many tiles. Lavapipe did not show it; run this file on the GPU machine too
    // (scripts/build-device-tests.sh).
    let tile = SCAN_TILE as usize;
    for tiles in [1, 2, 17] {
        for rest in [1, 32, 255, 480, 481, tile - 1] {
            let count = tiles * tile + rest;
            check(count, ScanKind::Exclusive, count as u64);
            check(count, ScanKind::Inclusive, count as u64 + 1);
        }
    }
}
