//! Every built-in scene on the GPU, as `tumble run <scene> --device gpu` runs it: every stage
//! there (and the host's pair functions for what the GPU has none for: meshes, compounds).

use crate::gpu_common;

use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::{BUILTIN_SCENES, Scene, builtin};

/// Each scene, a few dozen bodies of it, steps 2 s on the GPU. Over its first 10 steps it
/// follows the CPU's run within rounding: on lavapipe every body is within 2 µm and 0.1 mm/s
/// of the CPU's then (stacked-boxes and raycast already resting on their grounds), and a stage
/// gone wrong moves bodies by millimetres in a step (a step's gravity alone is 2.7 mm and
/// 0.16 m/s). Later the runs
/// part, as any two roundings of a pile do: a millimetre by step 60 and decimetres by step 120
/// for the hulls tumbling on a landscape. So after that it is held only to staying finite.
#[test]
fn every_builtin_scene_steps_on_the_gpu_as_on_the_cpu() {
    for &(name, _) in BUILTIN_SCENES {
        let scene = builtin(name, 0.03).unwrap();
        let mut cpu = scene.build().unwrap();
        let mut gpu = scene.build().unwrap();
        let _turn = gpu_common::context();
        gpu.set_stage_devices(StageDevices::all(Executor::Gpu))
            .unwrap();
        let bodies: Vec<_> = cpu.bodies().collect();
        assert!(bodies.len() > 20, "{name}: {} bodies", bodies.len());
        for _ in 0..10 {
            cpu.step();
            gpu.try_step()
                .unwrap_or_else(|error| panic!("{name}: {error}"));
        }
        for &body in &bodies {
            let (c, g) = (cpu.pose(body).unwrap(), gpu.pose(body).unwrap());
            let apart = c.position.distance(g.position);
            assert!(apart < 1e-4, "{name}: a body {apart} m from the CPU's");
            let (c, g) = (cpu.linear_velocity(body), gpu.linear_velocity(body));
            let faster = c.unwrap().distance(g.unwrap());
            assert!(faster < 1e-3, "{name}: a body {faster} m/s off the CPU's");
        }
        for _ in 10..120 {
            gpu.try_step()
                .unwrap_or_else(|error| panic!("{name}: {error}"));
        }
        for &body in &bodies {
            let pose = gpu.pose(body).unwrap();
            assert!(
                pose.position.is_finite() && pose.rotation.is_finite(),
                "{name}: {pose:?}"
            );
        }
    }
}

/// Same scene, same device, same build: two runs of falling-boxes with every stage on the GPU
/// end bitwise the same (the dump holds every body's pose and velocity bit for bit, and the
/// contacts' warm-start impulses), through the landing, its pairs coming and going and its
/// batches colored by rounds of atomics.
#[test]
fn two_gpu_runs_of_falling_boxes_are_bitwise_identical() {
    let scene = builtin("falling-boxes", 0.05).unwrap();
    let run = || {
        let mut world = scene.build().unwrap();
        let _turn = gpu_common::context();
        world
            .set_stage_devices(StageDevices::all(Executor::Gpu))
            .unwrap();
        let mut most_contacts = 0;
        for _ in 0..150 {
            world.try_step().unwrap();
            most_contacts = most_contacts.max(world.stats().contacts);
        }
        assert!(
            most_contacts > 100,
            "{most_contacts} contacts: few boxes landed"
        );
        Scene::from_world(&world).to_json()
    };
    let (first, second) = (run(), run());
    assert!(first == second, "two GPU runs of falling-boxes differ");
}
