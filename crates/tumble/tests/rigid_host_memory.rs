//! More rigid particle bodies than the host can hold: a typed error naming the bodies, the
//! particles and the bytes, never an abort or the OOM killer.
//!
//! The only test of its file, so alone in its process: it caps that process' address space
//! (RLIMIT_AS) a little above what it uses, so that none of its allocations can succeed
//! lazily under Linux's overcommit and be killed when touched, whatever the machine's
//! memory (as `particle_host_memory.rs` does for the particle demo). Nothing here can take
//! more than the cap, on a small machine or a large one.

#![cfg(target_os = "linux")]

mod address_space;

use address_space::{address_space, limit_address_space};

use tumble::particles::rigid::{BUNNY_LENGTH, BUNNY_PARTICLE_RADIUS};
use tumble::particles::{
    MAX_PARTICLES, ParticleDevice, ParticleError, RigidBody, RigidConfig, RigidSystem, Solid,
    voxelize,
};

/// (bodies, particles, bytes, message) of a host-memory error, or a panic naming what came
/// instead.
fn host_memory_error<T: std::fmt::Debug>(
    result: Result<T, ParticleError>,
) -> (usize, usize, u64, String) {
    match result {
        Err(
            error @ (ParticleError::BodyHostMemory {
                bodies,
                particles,
                bytes,
                ..
            }
            | ParticleError::BodyHostAllocation {
                bodies,
                particles,
                bytes,
            }),
        ) => (bodies, particles, bytes, error.to_string()),
        other => panic!("expected a host-memory error, got {other:?}"),
    }
}

#[test]
fn more_bodies_than_memory_allows_is_an_error() {
    // A million boxes of 2000 particles each: 2·10⁹ particles, below MAX_PARTICLES, about
    // 270 GB of arrays; the scene itself (72 MB) is made before the cap.
    let mut huge = RigidConfig::bunny_pile(1).unwrap();
    let box_shape = voxelize(
        &Solid::Box {
            half_extents: [1.0, 0.5, 0.5],
        },
        BUNNY_PARTICLE_RADIUS,
        1.0,
    )
    .unwrap();
    assert_eq!(box_shape.offsets.len(), 2000);
    huge.shapes = vec![box_shape];
    huge.bodies = vec![(0, RigidBody::at([1.0; 3], [0.0, 0.0, 0.0, 1.0])); 1_000_000];
    // 2000 of them (4M particles, about 0.55 GB): less than any machine that builds this has
    // available, more than the cap leaves.
    let mut large = huge.clone();
    large.bodies.truncate(2000);
    let small = RigidConfig::bunny_pile(8).unwrap();
    // Rayon's workers started (their stacks and arenas) before the cap, by a first system.
    RigidSystem::new(&small, ParticleDevice::Cpu)
        .unwrap()
        .step()
        .unwrap();
    let bunny = voxelize(&Solid::bunny(BUNNY_LENGTH), BUNNY_PARTICLE_RADIUS, 1.0).unwrap();
    let previous = limit_address_space(address_space() + (64 << 20));

    // Refused before anything is allocated where less is available, else by the allocator
    // at the cap.
    let (bodies, particles, bytes, message) =
        host_memory_error(RigidSystem::new(&huge, ParticleDevice::Cpu));
    assert_eq!((bodies, particles), (1_000_000, 2_000_000_000));
    // The offsets (twice), the world particles (twice) and the forces (twice) at least.
    assert!(
        bytes > 2_000_000_000 * (2 * 16 + 2 * 32 + 2 * 16),
        "{bytes}"
    );
    assert!(
        message.contains("1000000 bodies of 2000000000 particles")
            && message.contains(&format!("{bytes} bytes")),
        "{message}"
    );

    // So the allocator refuses one of its arrays (try_reserve_exact); on a machine that other
    // work has left with less than that available, the check refuses it first.
    let result = RigidSystem::new(&large, ParticleDevice::Cpu);
    assert!(
        matches!(
            result,
            Err(ParticleError::BodyHostAllocation {
                bodies: 2000,
                particles: 4_000_000,
                ..
            }) | Err(ParticleError::BodyHostMemory {
                bodies: 2000,
                particles: 4_000_000,
                ..
            })
        ),
        "{result:?}"
    );

    // The bunnies scene with the most bunnies MAX_PARTICLES allows: its own list of bodies
    // (about 650 MB) is more than the cap leaves.
    let most = MAX_PARTICLES / bunny.offsets.len();
    let (bodies, particles, bytes, _) = host_memory_error(RigidConfig::bunny_pile(most));
    assert_eq!((bodies, particles), (most, most * bunny.offsets.len()));
    assert_eq!(bytes, most as u64 * 72, "a (shape, state) pair per body");
    // One more is more particles than a system holds: refused before either check.
    let result = RigidConfig::bunny_pile(most + 1);
    assert!(
        matches!(result, Err(ParticleError::TooManyParticles { .. })),
        "{result:?}"
    );

    // A small scene still fits under the cap.
    let mut system =
        RigidSystem::new(&small, ParticleDevice::Cpu).expect("8 bunnies fit under the cap");

    // SAFETY: as in limit_address_space; the limits it returned.
    unsafe {
        assert_eq!(libc::setrlimit(libc::RLIMIT_AS, &previous), 0);
    }
    system.step().expect("a step");
    assert_eq!(system.body_count(), 8);
    assert!(system.kinetic_energy().unwrap() > 0.0, "falling");
}
