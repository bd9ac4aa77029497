//! Whether a pile stands: how many contact pairs are deeper than a few depths, and the
//! deepest ones with their bodies' poses, after N steps of a scene file (a `tumble run
//! --dump` of a settled pile, say). `max_penetration` alone cannot tell a pile sinking
//! everywhere from a few boxes jammed into each other.
//!
//! ```text
//! cargo run --release -p tumble --example deepest_contacts -- pile.json [STEPS [cpu|gpu]]
//! ```
//!
//! STEPS defaults to 1, the device to every stage on the GPU.

use std::path::Path;
use std::process::ExitCode;

use tumble::World;
use tumble::pipeline::devices::{Executor, StageDevices};
use tumble::scene::Scene;

const DEPTHS: [f32; 5] = [0.02, 0.05, 0.1, 0.2, 0.4];
const SHOWN: usize = 12;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("deepest_contacts: {error}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [path, rest @ ..] = args.as_slice() else {
        return Err("usage: deepest_contacts SCENE.json [STEPS [cpu|gpu]]".into());
    };
    let steps: u64 = match rest.first() {
        Some(steps) => steps
            .parse()
            .map_err(|_| format!("bad step count {steps:?}"))?,
        None => 1,
    };
    let on_gpu = match rest.get(1).map(String::as_str) {
        None | Some("gpu") => true,
        Some("cpu") => false,
        Some(other) => return Err(format!("device {other:?}: cpu or gpu")),
    };
    let scene = Scene::load(Path::new(path)).map_err(|e| e.to_string())?;
    let mut world = scene.build().map_err(|e| e.to_string())?;
    if on_gpu {
        world
            .set_stage_devices(StageDevices::all(Executor::Gpu))
            .map_err(|e| e.to_string())?;
    }
    for _ in 0..steps {
        world.try_step().map_err(|e| e.to_string())?;
    }
    report(&world).map_err(|e| e.to_string())
}

/// Each manifold's deepest point: (separation, body A, body B, normal, point count).
fn report(world: &World) -> Result<(), tumble::BodyError> {
    let mut deepest: Vec<_> = world
        .contacts()
        .filter_map(|(a, b, contact)| {
            let manifold = &contact.manifold;
            let point = manifold
                .points()
                .iter()
                .min_by(|p, q| p.separation.total_cmp(&q.separation))?;
            Some((point.separation, a, b, manifold.normal, manifold.count))
        })
        .collect();
    deepest.sort_by(|x, y| x.0.total_cmp(&y.0));
    println!(
        "{} bodies, {} pairs with points, kinetic energy {:.3} J",
        world.body_count(),
        deepest.len(),
        world.kinetic_energy()
    );
    for depth in DEPTHS {
        let deeper = deepest.iter().filter(|d| d.0 < -depth).count();
        println!("pairs deeper than {depth} m: {deeper}");
    }
    for &(separation, a, b, normal, count) in deepest.iter().take(SHOWN) {
        let (pose_a, pose_b) = (world.pose(a)?, world.pose(b)?);
        println!(
            "{separation:.3} m: bodies {} and {}, normal {normal:?}, {count} points; \
             A at {:?} {:?}, B at {:?} {:?}; asleep {} {}",
            a.index(),
            b.index(),
            pose_a.position,
            pose_a.rotation,
            pose_b.position,
            pose_b.rotation,
            world.is_sleeping(a)?,
            world.is_sleeping(b)?,
        );
    }
    Ok(())
}
