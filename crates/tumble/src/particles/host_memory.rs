//! Whether the host can hold a particle system's arrays, asked before they are allocated.
//!
//! `try_reserve_exact` alone is not enough on Linux: the kernel overcommits, so a reservation
//! far larger than free memory can succeed (each one below RAM + swap in the default
//! heuristic mode, any size with `vm.overcommit_memory = 1`), and the arrays are filled as soon
//! as they exist. Touching pages that cannot be backed does not fail an allocation: the OOM
//! killer ends the process (or another one), and there is no error to return. So the whole
//! request is first compared with what the kernel says it can give now: `MemAvailable` (free
//! memory plus the page cache and reclaimable slabs it can drop without swapping, proc(5))
//! plus free swap. A request above it is refused with an error; a request below it can still
//! lose a race with other processes, which is the kernel's call as for any program. Then every
//! array is reserved with `try_reserve_exact`, which catches what the allocator itself refuses
//! (an address-space limit, strict overcommit, other systems, where nothing is asked first).

use crate::particles::ParticleError;

/// Bytes of host memory the kernel can give now without the OOM killer, or `None` where it
/// does not say (not Linux, or no `/proc`).
pub(crate) fn available() -> Option<u64> {
    available_in(&std::fs::read_to_string("/proc/meminfo").ok()?)
}

/// `MemAvailable` + `SwapFree` (bytes) from the text of `/proc/meminfo` (values in kB).
/// `None` without `MemAvailable` (kernels before 3.14).
fn available_in(meminfo: &str) -> Option<u64> {
    let kilobytes = |name: &str| {
        meminfo.lines().find_map(|line| {
            let value = line.strip_prefix(name)?.strip_prefix(':')?;
            value.trim().strip_suffix("kB")?.trim().parse::<u64>().ok()
        })
    };
    let swap = kilobytes("SwapFree").unwrap_or(0);
    Some((kilobytes("MemAvailable")? + swap) * 1024)
}

/// What is available, when `bytes` is more than it (known): the request must be refused.
pub(crate) fn shortfall(bytes: u64, available: Option<u64>) -> Option<u64> {
    available.filter(|&available| bytes > available)
}

/// Refuses `bytes` of host memory for `count` particles when more than `available` (known).
pub(crate) fn check(count: usize, bytes: u64, available: Option<u64>) -> Result<(), ParticleError> {
    match shortfall(bytes, available) {
        Some(available) => Err(ParticleError::HostMemory {
            count,
            bytes,
            available,
        }),
        None => Ok(()),
    }
}

/// An empty vector with room for exactly `len` elements, or the allocator's refusal (never
/// an abort).
pub(crate) fn try_with_capacity<T>(
    len: usize,
) -> Result<Vec<T>, std::collections::TryReserveError> {
    let mut vector = Vec::new();
    vector.try_reserve_exact(len)?;
    Ok(vector)
}

/// `len` copies of `value`, or the allocator's refusal (never an abort).
pub(crate) fn try_filled<T: Clone>(
    len: usize,
    value: T,
) -> Result<Vec<T>, std::collections::TryReserveError> {
    let mut vector = try_with_capacity(len)?;
    vector.resize(len, value);
    Ok(vector)
}

/// A copy of `items`, or the allocator's refusal (never an abort).
pub(crate) fn try_to_vec<T: Clone>(
    items: &[T],
) -> Result<Vec<T>, std::collections::TryReserveError> {
    let mut vector = try_with_capacity(items.len())?;
    vector.extend_from_slice(items);
    Ok(vector)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The start of a real `/proc/meminfo` (24 GB, no swap), and one with swap in use.
    const NO_SWAP: &str = "MemTotal:       24683664 kB\nMemFree:        14177156 kB\n\
        MemAvailable:   24061212 kB\nBuffers:           11408 kB\nSwapTotal:             0 kB\n\
        SwapFree:              0 kB\n";
    const SWAP: &str = "MemTotal: 1000 kB\nMemAvailable: 300 kB\nSwapCached: 5 kB\n\
        SwapTotal: 2048 kB\nSwapFree: 1024 kB\n";

    #[test]
    fn available_is_mem_available_plus_free_swap() {
        assert_eq!(available_in(NO_SWAP), Some(24_061_212 * 1024));
        // SwapCached and SwapTotal are not SwapFree.
        assert_eq!(available_in(SWAP), Some((300 + 1024) * 1024));
        assert_eq!(available_in("MemTotal: 1000 kB\nMemFree: 10 kB\n"), None);
    }

    #[test]
    fn a_request_above_what_is_available_is_refused_with_both_figures() {
        assert!(check(10, 1000, Some(1000)).is_ok());
        assert!(
            check(10, 1000, None).is_ok(),
            "unknown: left to the allocator"
        );
        let error = check(2_000_000_000, 208_000_000_000, Some(24_000_000_000)).unwrap_err();
        assert!(
            matches!(
                error,
                ParticleError::HostMemory {
                    count: 2_000_000_000,
                    bytes: 208_000_000_000,
                    available: 24_000_000_000
                }
            ),
            "{error:?}"
        );
        let message = error.to_string();
        assert!(
            message.contains("2000000000 particles need 208000000000 bytes (208.0 GB)")
                && message.contains("24000000000 bytes (24.0 GB) are available"),
            "{message}"
        );
    }
}
