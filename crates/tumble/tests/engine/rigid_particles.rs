//! Rigid bodies made of particles (the `bunnies` scene): voxelized mass properties against
//! closed forms, a bunny coming to rest, momentum in a collision, determinism, GPU against
//! CPU, and bad input.

use crate::gpu_common;

use gpu_common::context;
use tumble::particles::rigid::{BUNNY_LENGTH, BUNNY_PARTICLE_RADIUS};
use tumble::particles::{
    ParticleDevice, ParticleError, RigidBody, RigidConfig, RigidSystem, Solid, voxelize,
};

/// Relative error of the mass and of the largest error of the inertia's diagonal, with the
/// largest off-diagonal term relative to the diagonal.
fn mass_errors(solid: &Solid, radius: f32, density: f64, mass: f64, inertia: [f64; 3]) -> f64 {
    let diameter = 2.0 * f64::from(radius);
    let particle_mass = density * diameter.powi(3);
    let shape = voxelize(solid, radius, particle_mass as f32).expect("voxelize");
    let mut error = ((shape.mass - mass) / mass).abs();
    for (axis, &expected) in inertia.iter().enumerate() {
        error = error.max(((shape.inertia[axis][axis] - expected) / expected).abs());
        for other in 0..3 {
            if other != axis {
                error = error.max((shape.inertia[axis][other] / expected).abs());
            }
        }
    }
    // The centre of mass is the origin of the offsets.
    let count = shape.offsets.len() as f64;
    for axis in 0..3 {
        let mean = shape
            .offsets
            .iter()
            .map(|o| f64::from(o[axis]))
            .sum::<f64>()
            / count;
        assert!(mean.abs() < 1e-5, "offsets' mean {mean} along {axis}");
    }
    error
}

/// Mass and inertia of a solid box of half extents `half` (kg, kg·m²).
fn box_mass(half: [f64; 3], density: f64) -> (f64, [f64; 3]) {
    let [a, b, c] = half;
    let mass = density * 8.0 * a * b * c;
    let inertia = [
        mass / 3.0 * (b * b + c * c),
        mass / 3.0 * (a * a + c * c),
        mass / 3.0 * (a * a + b * b),
    ];
    (mass, inertia)
}

/// A box whose sides are no multiple of the particle diameter: its voxelization is a box whose
/// sides are each off by at most half a voxel, so its mass and inertia are within what such a
/// box has (the bound, computed) and converge to the box's as the diameter shrinks.
#[test]
fn voxelized_box_approaches_its_mass_and_inertia() {
    let half = [0.5317f32, 0.3713, 0.2891];
    let density = 1000.0;
    let (mass, inertia) = box_mass(half.map(f64::from), density);
    let solid = Solid::Box { half_extents: half };
    let radii = [0.04f32, 0.02, 0.01, 0.005];
    let mut errors = Vec::new();
    for radius in radii {
        let error = mass_errors(&solid, radius, density, mass, inertia);
        // The worst box: every side half a voxel longer (mass and inertia grow with each).
        let grown = half.map(|h| f64::from(h) + 0.5 * f64::from(radius));
        let (worst_mass, worst_inertia) = box_mass(grown, density);
        let bound = (0..3)
            .map(|axis| (worst_inertia[axis] - inertia[axis]) / inertia[axis])
            .fold((worst_mass - mass) / mass, f64::max);
        assert!(error <= bound, "radius {radius}: error {error} > {bound}");
        errors.push(error);
    }
    println!("box errors by radius {radii:?} m: {errors:?}");
    // The bound shrinks with the radius (O(d)); the error is not monotonic in between (a
    // side's rounding to whole voxels comes and goes), but an eighth of the radius is a
    // quarter of the error at least.
    assert!(errors[3] < 0.25 * errors[0], "{errors:?}");
}

#[test]
fn voxelized_sphere_approaches_its_mass_and_inertia() {
    let radius = 0.5f64;
    let density = 500.0;
    let mass = density * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3);
    let inertia = [0.4 * mass * radius * radius; 3];
    let solid = Solid::sphere(radius as f32);
    let errors: Vec<f64> = [0.05f32, 0.025, 0.0125]
        .iter()
        .map(|&particle| mass_errors(&solid, particle, density, mass, inertia))
        .collect();
    println!("sphere errors by particle radius 0.05, 0.025, 0.0125 m: {errors:?}");
    assert!(errors[2] < 0.02, "{errors:?}");
    assert!(errors[2] < errors[0], "{errors:?}");
}

#[test]
fn the_bunny_has_a_few_hundred_particles() {
    let shape = voxelize(&Solid::bunny(BUNNY_LENGTH), BUNNY_PARTICLE_RADIUS, 1.0).unwrap();
    let count = shape.offsets.len();
    println!("bunny: {count} particles");
    assert!((100..=300).contains(&count), "{count}");
}

fn run(config: &RigidConfig, device: ParticleDevice, steps: usize) -> Vec<RigidBody> {
    let mut system = RigidSystem::new(config, device).expect("valid scene");
    for _ in 0..steps {
        system.step().expect("step");
    }
    system.bodies().expect("bodies")
}

fn length(v: [f32; 4]) -> f32 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// One bunny dropped from 10 cm (lowest particle) onto the floor: it bounces, rocks on its
/// round belly (motion the dampers see little of: rolling barely moves the contacts) and after
/// 10 s rests, its particles sunk into the ground by less than a fifth of their radius (the
/// static sinking is weight / (contacts × stiffness), 0.023 m / contacts here; measured:
/// 3.5 mm, 7 % of the radius; speed 5e-6 m/s, spin 2e-5 rad/s).
#[test]
fn a_dropped_bunny_comes_to_rest() {
    let mut config = RigidConfig::bunny_pile(1).unwrap();
    let drop = 0.1;
    let lowest = config.shapes[0]
        .offsets
        .iter()
        .map(|o| o[1])
        .fold(f32::INFINITY, f32::min);
    let radius = config.particles.radius;
    let upright = RigidBody::at(
        [
            config.bodies[0].1.position[0],
            radius - lowest + drop,
            config.bodies[0].1.position[2],
        ],
        [0.0, 0.0, 0.0, 1.0],
    );
    config.bodies[0].1 = upright;
    let mut system = RigidSystem::new(&config, ParticleDevice::Cpu).unwrap();
    for _ in 0..2400 {
        system.step().unwrap();
    }
    let body = system.bodies().unwrap()[0];
    let lowest_now = system
        .positions()
        .unwrap()
        .iter()
        .map(|p| p[1])
        .fold(f32::INFINITY, f32::min);
    let sunk = radius - lowest_now;
    println!(
        "speed {} m/s, spin {} rad/s, sunk {sunk} m",
        length(body.linear_velocity),
        length(body.angular_velocity)
    );
    assert!(length(body.linear_velocity) < 1e-3, "{body:?}");
    assert!(length(body.angular_velocity) < 1e-2, "{body:?}");
    assert!(sunk < 0.2 * radius, "sunk {sunk} m");
}

/// Two bunnies thrown at each other in zero gravity, far from the walls: the pair forces
/// are antisymmetric bit for bit, so the total momentum changes only by the rounding of the
/// sums (f32, ~200 terms a body): well under 1e-4 of the momentum each brings.
#[test]
fn colliding_bunnies_conserve_momentum() {
    let mut config = RigidConfig::bunny_pile(2).unwrap();
    config.particles.gravity = [0.0; 3];
    config.particles.grid = [80, 80, 80];
    let speed = 2.0;
    config.bodies[0].1 = RigidBody::at([2.9, 4.0, 4.0], [0.0, 0.0, 0.0, 1.0])
        .with_velocity([speed, 0.0, 0.0], [0.0; 3]);
    config.bodies[1].1 = RigidBody::at([5.1, 4.3, 4.1], [0.0, 1.0, 0.0, 0.0])
        .with_velocity([-speed, 0.0, 0.0], [0.0; 3]);
    let mass = config.shapes[0].mass;
    let momentum = |bodies: &[RigidBody]| {
        [0, 1, 2].map(|axis| {
            bodies
                .iter()
                .map(|b| mass * f64::from(b.linear_velocity[axis]))
                .sum::<f64>()
        })
    };
    let before = momentum(&config.bodies.iter().map(|b| b.1).collect::<Vec<_>>());
    let after_bodies = run(&config, ParticleDevice::Cpu, 240);
    let after = momentum(&after_bodies);
    // They did collide: each one's velocity changed.
    assert!(
        (after_bodies[0].linear_velocity[0] - speed).abs() > 0.5 * speed,
        "{after_bodies:?}"
    );
    let scale = mass * f64::from(speed);
    for axis in 0..3 {
        let drift = (after[axis] - before[axis]).abs() / scale;
        println!("momentum drift along {axis}: {drift:e} of one bunny's");
        assert!(drift < 1e-4, "axis {axis}: {before:?} -> {after:?}");
    }
}

#[test]
fn same_input_gives_bitwise_the_same_bodies() {
    let config = RigidConfig::bunny_pile(8).unwrap();
    let first = run(&config, ParticleDevice::Cpu, 120);
    let second = run(&config, ParticleDevice::Cpu, 120);
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| run(&config, ParticleDevice::Cpu, 120));
    assert_eq!(bits(&first), bits(&second));
    assert_eq!(bits(&first), bits(&one_thread));
}

/// A pile of `count` bodies of three shapes (bunny, box, sphere, in turn), lowered so that
/// the first layer lands within a few dozen steps.
fn mixed_pile(count: usize) -> RigidConfig {
    let mut config = RigidConfig::bunny_pile(count).unwrap();
    let radius = config.particles.radius;
    let solids = [
        Solid::Box {
            half_extents: [0.3, 0.2, 0.15],
        },
        Solid::sphere(0.25),
    ];
    for solid in &solids {
        config.shapes.push(voxelize(solid, radius, 1.0).unwrap());
    }
    for (index, (shape, body)) in config.bodies.iter_mut().enumerate() {
        *shape = index % 3;
        body.position[1] -= 0.5;
    }
    config.bodies.truncate(count);
    config
}

fn bits(bodies: &[RigidBody]) -> Vec<u32> {
    bytemuck::cast_slice::<RigidBody, u32>(bodies).to_vec()
}

/// GPU and CPU run the same arithmetic in the same order, but a GPU may fuse multiply-adds,
/// which contacts amplify. After the pile has fallen onto the floor and itself, centres must
/// agree within 1 mm (the particles' radius is 5 cm); on lavapipe they agree within 1 µm.
/// Sizes: no body, one, 13 (odd), 64 (15k particles, fewer steps: a CPU driver is slow).
#[test]
fn gpu_and_cpu_agree_after_steps() {
    let gpu = context();
    for (count, steps) in [(0, 10), (1, 120), (13, 120), (64, 40)] {
        let config = mixed_pile(count);
        let cpu = run(&config, ParticleDevice::Cpu, steps);
        let on_gpu = run(&config, ParticleDevice::Gpu(gpu.clone()), steps);
        assert_eq!(cpu.len(), count);
        assert_eq!(on_gpu.len(), count);
        let mut worst = 0.0f32;
        for (a, b) in cpu.iter().zip(&on_gpu) {
            for axis in 0..3 {
                worst = worst.max((a.position[axis] - b.position[axis]).abs());
            }
        }
        println!("{count} bodies: largest centre difference after {steps} steps: {worst} m");
        assert!(worst < 1e-3, "{count} bodies: {worst}");
        // They did move: none is where it started.
        for (after, (_, before)) in cpu.iter().zip(&config.bodies) {
            assert!(after.position[1] < before.position[1] - 0.01, "{after:?}");
        }
        // And touched: some body is no longer falling freely (for the floor or another).
        let free_fall = config.particles.gravity[1] * config.particles.dt * steps as f32;
        let touched = cpu
            .iter()
            .filter(|body| (body.linear_velocity[1] - free_fall).abs() > 0.05)
            .count();
        println!("{touched} of {count} bodies touched something");
        assert!(count == 0 || touched > 0);
        if count == 13 {
            let again = run(&config, ParticleDevice::Gpu(gpu.clone()), steps);
            assert_eq!(
                bits(&on_gpu),
                bits(&again),
                "GPU steps are not deterministic"
            );
        }
    }
}

#[test]
fn bad_input_is_a_typed_error() {
    let solid = Solid::sphere(0.3);
    for radius in [0.0, -0.1, f32::NAN, f32::INFINITY] {
        assert!(matches!(
            voxelize(&solid, radius, 1.0),
            Err(ParticleError::Radius(_))
        ));
    }
    assert!(matches!(
        voxelize(&Solid::Ellipsoids(vec![]), 0.1, 1.0),
        Err(ParticleError::EmptyBody)
    ));
    assert!(matches!(
        voxelize(&solid, 0.1, 0.0),
        Err(ParticleError::Mass(_))
    ));
    let huge = Solid::Box {
        half_extents: [1e6; 3],
    };
    assert!(matches!(
        voxelize(&huge, 1e-3, 1.0),
        Err(ParticleError::VoxelLattice { .. })
    ));
    assert!(matches!(
        RigidConfig::bunny_pile(usize::MAX),
        Err(ParticleError::TooManyBodies { .. })
    ));
    let good = RigidConfig::bunny_pile(1).unwrap();
    let mut empty = good.clone();
    empty.shapes[0].offsets.clear();
    let mut missing = good.clone();
    missing.bodies[0].0 = 3;
    let mut zero_radius = good.clone();
    zero_radius.particles.radius = 0.0;
    let mut bad_turn = good.clone();
    bad_turn.bodies[0].1.orientation = [0.0; 4];
    let cases = [
        (empty, "EmptyBody"),
        (missing, "ShapeIndex"),
        (zero_radius, "Radius"),
        (bad_turn, "BodyState"),
    ];
    for (config, expected) in cases {
        let error = RigidSystem::new(&config, ParticleDevice::Cpu).unwrap_err();
        assert!(format!("{error:?}").starts_with(expected), "{error:?}");
    }
}
