//! The uniform-grid particle system: GPU against its CPU twin, determinism, energy in a
//! closed damped box, and bad configurations.

use crate::gpu_common;

// Each test holds `context()` (the GPU turn) for its whole run and never asks for it twice.

use gpu_common::context;
use tumble::particles::{
    CellSort, MAX_PARTICLES, NeighbourSearch, Particle, ParticleConfig, ParticleDevice,
    ParticleError, ParticleSystem,
};

fn run(config: &ParticleConfig, device: ParticleDevice, steps: usize) -> Vec<Particle> {
    let mut system = ParticleSystem::new(config.clone(), device).expect("valid config");
    for _ in 0..steps {
        system.step().expect("step");
    }
    system.particles().expect("particles")
}

fn max_position_difference(a: &[Particle], b: &[Particle]) -> f32 {
    a.iter()
        .zip(b)
        .flat_map(|(a, b)| (0..3).map(move |axis| (a.position[axis] - b.position[axis]).abs()))
        .fold(0.0, f32::max)
}

/// Total energy (J): kinetic, gravitational (relative to the origin) and the elastic energy
/// of overlaps between particles and with the walls. Brute force over pairs: small scenes.
fn energy(config: &ParticleConfig, particles: &[Particle]) -> f64 {
    let mass = f64::from(config.mass);
    let radius = f64::from(config.radius);
    let mut total = 0.0;
    for (index, particle) in particles.iter().enumerate() {
        let position = particle.position.map(f64::from);
        let velocity = particle.velocity.map(f64::from);
        for axis in 0..3 {
            total += 0.5 * mass * velocity[axis] * velocity[axis];
            total -= mass
                * f64::from(config.gravity[axis])
                * (position[axis] - f64::from(config.origin[axis]));
            let low = f64::from(config.origin[axis]) + radius;
            let high = f64::from(config.origin[axis]) + f64::from(config.grid[axis]) * 2.0 * radius
                - radius;
            let outside = (low - position[axis]).max(0.0) + (position[axis] - high).max(0.0);
            total += 0.5 * f64::from(config.wall_spring) * outside * outside;
        }
        for other in &particles[index + 1..] {
            let offset: Vec<f64> = (0..3)
                .map(|axis| f64::from(other.position[axis]) - position[axis])
                .collect();
            let distance = offset.iter().map(|d| d * d).sum::<f64>().sqrt();
            let overlap = (2.0 * radius - distance).max(0.0);
            total += 0.5 * f64::from(config.spring) * overlap * overlap;
        }
    }
    total
}

/// The demo block with the box's ceiling just above it: the bottom layer rests on the
/// ground from the first step and the pile collapses sideways, so every step has contacts.
fn settling_scene(count: usize) -> ParticleConfig {
    let mut config = ParticleConfig::demo(count);
    let side = (count as f64).cbrt().ceil() as u32;
    config.grid[1] = side + 1;
    config
}

fn small_scene() -> ParticleConfig {
    settling_scene(1000)
}

/// Both run the same arithmetic in the same order; a GPU may still fuse multiply-adds, so
/// results can drift apart by rounding, which a granular pile amplifies. After 60 steps of
/// collapsing pile they must agree within 1 mm (the radius is 0.5 m); on lavapipe they
/// agree bitwise.
#[test]
fn gpu_and_cpu_agree_after_steps() {
    let gpu = context();
    let config = small_scene();
    let steps = 60;
    let cpu = run(&config, ParticleDevice::Cpu, steps);
    for sort in [CellSort::Radix, CellSort::Bitonic] {
        let gpu = run(
            &ParticleConfig {
                sort,
                ..config.clone()
            },
            ParticleDevice::Gpu(gpu.clone()),
            steps,
        );
        let difference = max_position_difference(&cpu, &gpu);
        assert!(
            difference < 1e-3,
            "{sort:?}: GPU and CPU differ by {difference} m"
        );
    }
}

#[test]
fn gpu_steps_are_bitwise_deterministic() {
    let gpu = context();
    let config = small_scene();
    let first = run(&config, ParticleDevice::Gpu(gpu.clone()), 30);
    let second = run(&config, ParticleDevice::Gpu(gpu.clone()), 30);
    assert!(first == second, "two GPU runs differ");
    let bitonic = ParticleConfig {
        sort: CellSort::Bitonic,
        ..config
    };
    // Bitonic sort orders ties by particle id: the same order as the stable radix sort.
    let third = run(&bitonic, ParticleDevice::Gpu(gpu.clone()), 30);
    assert!(first == third, "radix and bitonic runs differ");
}

#[test]
fn energy_does_not_grow_in_a_closed_damped_box() {
    let gpu = context();
    let config = settling_scene(343);
    for device in [ParticleDevice::Cpu, ParticleDevice::Gpu(gpu.clone())] {
        let mut system = ParticleSystem::new(config.clone(), device).expect("valid config");
        let start = energy(&config, &system.particles().expect("particles"));
        let mut previous = start;
        for _ in 0..10 {
            for _ in 0..30 {
                system.step().expect("step");
            }
            let now = energy(&config, &system.particles().expect("particles"));
            // Semi-implicit Euler's energy wobbles slightly within a contact: allow 0.5 %
            // of the starting energy per 30 steps, never a net gain.
            assert!(
                now <= previous + 0.005 * start,
                "energy grew from {previous} to {now}"
            );
            assert!(now <= start, "energy {now} above the start {start}");
            previous = now;
        }
        assert!(previous < start, "damping dissipated nothing");
    }
}

#[test]
fn cpu_symmetric_search_agrees_with_the_full_search() {
    let config = small_scene();
    let full = run(&config, ParticleDevice::Cpu, 40);
    let symmetric = run(
        &ParticleConfig {
            search: NeighbourSearch::Symmetric14,
            ..config
        },
        ParticleDevice::Cpu,
        40,
    );
    let difference = max_position_difference(&full, &symmetric);
    assert!(
        difference < 1e-3,
        "14-cell and 27-cell differ by {difference} m"
    );
}

/// The symmetric search sums pair forces in fixed point with atomics on the GPU: the same
/// result whatever order threads run in, and the CPU twin's (sequential) sums match it.
#[test]
fn gpu_symmetric_search_is_deterministic_and_matches_cpu() {
    let gpu = context();
    let config = ParticleConfig {
        search: NeighbourSearch::Symmetric14,
        ..small_scene()
    };
    let first = run(&config, ParticleDevice::Gpu(gpu.clone()), 40);
    let second = run(&config, ParticleDevice::Gpu(gpu.clone()), 40);
    assert!(
        first == second,
        "two GPU runs of the symmetric search differ"
    );
    let cpu = run(&config, ParticleDevice::Cpu, 40);
    let difference = max_position_difference(&cpu, &first);
    assert!(
        difference < 1e-3,
        "GPU and CPU symmetric searches differ by {difference} m"
    );
    let full = run(&small_scene(), ParticleDevice::Gpu(gpu.clone()), 40);
    let difference = max_position_difference(&full, &first);
    assert!(
        difference < 1e-3,
        "14-cell and 27-cell differ by {difference} m on the GPU"
    );
}

#[test]
fn bad_configurations_are_errors() {
    let turn = context();
    let gpu = || ParticleDevice::Gpu(turn.clone());
    let base = ParticleConfig::demo(10);
    let cases = [
        ParticleConfig {
            radius: 0.0,
            ..base.clone()
        },
        ParticleConfig {
            radius: -1.0,
            ..base.clone()
        },
        ParticleConfig {
            radius: f32::NAN,
            ..base.clone()
        },
        ParticleConfig {
            grid: [4, 0, 4],
            ..base.clone()
        },
        ParticleConfig {
            dt: 0.0,
            ..base.clone()
        },
        ParticleConfig {
            count: MAX_PARTICLES + 1,
            ..base.clone()
        },
    ];
    for config in cases {
        for device in [ParticleDevice::Cpu, gpu()] {
            let error = ParticleSystem::new(config.clone(), device).unwrap_err();
            assert!(!error.to_string().is_empty());
        }
    }
    // Valid, but more than the GPU's buffers can hold: an error before anything is built.
    let huge = ParticleConfig {
        count: MAX_PARTICLES,
        ..base.clone()
    };
    match ParticleSystem::new(huge, gpu()) {
        Err(ParticleError::Gpu(error)) => assert!(error.to_string().contains("particles")),
        other => panic!("expected a buffer-size error, got {other:?}"),
    }
}
