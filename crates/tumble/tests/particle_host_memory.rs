//! More particles than the host can hold: a typed error naming the count and the bytes,
//! never an abort or the OOM killer.
//!
//! The only test of its file, so alone in its process: it caps that process' address space
//! (RLIMIT_AS) a little above what it uses, so that none of its allocations can succeed
//! lazily under Linux's overcommit and be killed when touched, whatever the machine's
//! memory. Nothing here can take more than the cap, on a small machine or a large one.

#![cfg(target_os = "linux")]

mod address_space;

use address_space::{address_space, limit_address_space};

use tumble::particles::{
    MAX_PARTICLES, NeighbourSearch, ParticleConfig, ParticleDevice, ParticleError, ParticleSystem,
};

/// (count, bytes) of a host-memory error, or a panic naming what came instead.
fn host_memory_error(result: Result<ParticleSystem, ParticleError>) -> (usize, u64, String) {
    match result {
        Err(
            error @ (ParticleError::HostMemory { count, bytes, .. }
            | ParticleError::HostAllocation { count, bytes }),
        ) => (count, bytes, error.to_string()),
        other => panic!("expected a host-memory error, got {other:?}"),
    }
}

#[test]
fn more_particles_than_memory_allows_is_an_error() {
    // 4M particles (128 MiB), made before the cap, for with_particles.
    let config = ParticleConfig {
        search: NeighbourSearch::Symmetric14,
        ..ParticleConfig::demo(1 << 22)
    };
    let particles: Vec<_> = config.initial_particles().collect();
    let previous = limit_address_space(address_space() + (64 << 20));

    // MAX_PARTICLES in a small box: about 290 GB. Refused before anything is allocated where
    // less is available, else by the allocator at the cap.
    let huge = ParticleConfig {
        count: MAX_PARTICLES,
        ..ParticleConfig::demo(10)
    };
    let (count, bytes, message) = host_memory_error(ParticleSystem::new(huge, ParticleDevice::Cpu));
    assert_eq!(count, MAX_PARTICLES);
    // The initial particles and three copies in the executor, at 32 bytes each, at least.
    assert!(bytes > 4 * 32 * MAX_PARTICLES as u64, "{bytes}");
    assert!(
        message.contains(&format!("{MAX_PARTICLES} particles"))
            && message.contains(&format!("{bytes} bytes")),
        "{message}"
    );

    // The executor's arrays for the 4M particles given (about 0.5 GB): less than any
    // machine that builds this has available, more than the cap leaves, so the allocator
    // refuses one of them (try_reserve_exact).
    let result = ParticleSystem::with_particles(config.clone(), ParticleDevice::Cpu, &particles);
    let (count, bytes, _) = host_memory_error(result);
    assert_eq!(count, 1 << 22);
    assert!(bytes > 3 * 32 * (1 << 22), "{bytes}");
    // (On a machine that other work has left with less than that available, the check
    // refuses it first.)
    let result = ParticleSystem::new(config.clone(), ParticleDevice::Cpu);
    assert!(
        matches!(
            result,
            Err(ParticleError::HostAllocation { count, .. })
                | Err(ParticleError::HostMemory { count, .. }) if count == 1 << 22
        ),
        "{result:?}"
    );

    // SAFETY: as in limit_address_space; the limits it returned.
    unsafe {
        assert_eq!(libc::setrlimit(libc::RLIMIT_AS, &previous), 0);
    }
    // Nothing was left half-made: with the memory back, the same request works.
    let mut system = ParticleSystem::with_particles(config, ParticleDevice::Cpu, &particles)
        .expect("4M particles fit without the cap");
    system.step().expect("a step");
}
