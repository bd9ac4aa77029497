//! One case: a scene at one scale on one engine with one thread count. Warm-up steps, then
//! timed steps, each timed alone; quality figures taken outside the timed calls.

use crate::engine::{BuildError, EngineKind, Simulation};
use std::time::Instant;
use tumble::math::Vec3;
use tumble::scene::Scene;

/// What a case is.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseKey {
    pub scene: String,
    pub scale: f32,
    /// Dynamic bodies in the scene.
    pub bodies: usize,
    pub engine: EngineKind,
    pub threads: usize,
}

/// How a case ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    /// Every warm-up and timed step ran.
    Ok,
    /// A step took longer than the time limit; the figures come from the steps before and
    /// including it.
    TimeLimit,
    /// A smaller scale of the same column hit the time limit; nothing ran.
    Skipped,
    /// The engine cannot run here (e.g. no GPU step yet); nothing ran.
    NotAvailable(String),
    /// The engine lacks something the scene uses (e.g. breakable joints on rapier); nothing
    /// ran, rather than a different scene.
    Unsupported(String),
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Status::Ok => f.write_str("ok"),
            Status::TimeLimit => f.write_str("time-limit"),
            Status::Skipped => f.write_str("skipped"),
            Status::NotAvailable(why) => write!(f, "not available: {why}"),
            Status::Unsupported(why) => write!(f, "unsupported: {why}"),
        }
    }
}

/// Median and spread of the step times (ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    pub median: f64,
    pub p10: f64,
    pub p90: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    /// `None` for no samples. Percentiles by nearest rank: real step times, no interpolation.
    pub fn of(samples: &[f64]) -> Option<Self> {
        if samples.is_empty() {
            return None;
        }
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let rank = |fraction: f64| {
            let index = (fraction * sorted.len() as f64).ceil() as usize;
            sorted[index.clamp(1, sorted.len()) - 1]
        };
        Some(Self {
            median: tumble::profile::median(&sorted),
            p10: rank(0.1),
            p90: rank(0.9),
            min: sorted[0],
            max: sorted[sorted.len() - 1],
        })
    }
}

/// Which drift a scene's bodies are judged by (crate docs, "Quality figures").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriftKind {
    /// Distance from the start position (m): bodies that start at rest and should stay.
    Displacement,
    /// Linear speed at the end (m/s): bodies that should have come to rest.
    Speed,
}

impl DriftKind {
    /// `stacked-boxes` starts at rest; every other scene falls and settles.
    pub fn for_scene(scene: &str) -> Self {
        match scene {
            "stacked-boxes" => DriftKind::Displacement,
            _ => DriftKind::Speed,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            DriftKind::Displacement => "displacement_m",
            DriftKind::Speed => "speed_m_per_s",
        }
    }
}

/// Drift over the dynamic bodies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drift {
    pub kind: DriftKind,
    pub mean: f64,
    pub max: f64,
}

/// Figures of a case that ran (fully or up to the time limit).
#[derive(Clone, Debug, PartialEq)]
pub struct Figures {
    pub warmup_steps: usize,
    pub timed_steps: usize,
    /// `None` when the time limit struck during the warm-up.
    pub step_ms: Option<Spread>,
    pub stage_ms: Vec<(String, f64)>,
    pub max_penetration: f32,
    pub drift: Drift,
    pub kinetic_energy: f64,
    pub pairs: usize,
    pub contacts: usize,
}

/// One row of the report.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseResult {
    pub key: CaseKey,
    pub status: Status,
    pub figures: Option<Figures>,
    /// The scene's step settings: dt (s), solver iterations, sub-steps.
    pub dt: f32,
    pub solver_iterations: u32,
    pub substeps: u32,
    /// Tumble's solver (`--solver`); none for the peers, which keep their own.
    pub solver: Option<tumble::stages::solver::SolverKind>,
}

/// How long a case runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    pub warmup: usize,
    pub steps: usize,
    pub time_limit_ms: f64,
}

impl CaseResult {
    /// A row for a case that did not run.
    pub fn not_run(key: CaseKey, scene: &Scene, status: Status) -> Self {
        let tumble = matches!(key.engine, EngineKind::TumbleCpu | EngineKind::TumbleGpu);
        let solver = tumble.then_some(scene.config.solver);
        Self {
            key,
            status,
            figures: None,
            dt: scene.config.dt,
            solver_iterations: scene.config.solver_iterations,
            substeps: scene.config.substeps,
            solver,
        }
    }
}

/// Runs one case on the current rayon pool. `on_step` is called after every step (progress).
pub fn run_case(key: CaseKey, scene: &Scene, schedule: Schedule, on_step: &dyn Fn()) -> CaseResult {
    let mut simulation = match key.engine.build(scene) {
        Ok(simulation) => simulation,
        Err(BuildError::NotAvailable(why)) => {
            return CaseResult::not_run(key, scene, Status::NotAvailable(why));
        }
        Err(BuildError::Unsupported(why)) => {
            return CaseResult::not_run(key, scene, Status::Unsupported(why));
        }
    };
    let start_positions: Vec<Vec3> = scene
        .bodies
        .iter()
        .filter(|desc| !desc.is_static())
        .map(|desc| desc.position)
        .collect();
    // The first step builds the engines' acceleration structures from nothing, a cost no later
    // step pays: it is exempt from the time limit.
    let over_limit = |step_index: usize, ms: f64| step_index > 0 && ms > schedule.time_limit_ms;
    let mut status = Status::Ok;
    let mut warmup_steps = 0;
    while warmup_steps < schedule.warmup && status == Status::Ok {
        if over_limit(warmup_steps, timed_step(simulation.as_mut())) {
            status = Status::TimeLimit;
        }
        warmup_steps += 1;
        on_step();
    }
    simulation.reset_stage_timers();
    let mut step_ms = Vec::with_capacity(schedule.steps);
    let mut max_penetration = 0.0f32;
    while step_ms.len() < schedule.steps && status == Status::Ok {
        let ms = timed_step(simulation.as_mut());
        if over_limit(warmup_steps + step_ms.len(), ms) {
            status = Status::TimeLimit;
        }
        step_ms.push(ms);
        max_penetration = max_penetration.max(simulation.contact_sample().max_penetration);
        on_step();
    }
    let sample = simulation.contact_sample();
    let drift = drift(
        DriftKind::for_scene(&key.scene),
        &start_positions,
        simulation.as_ref(),
    );
    let figures = Figures {
        warmup_steps,
        timed_steps: step_ms.len(),
        step_ms: Spread::of(&step_ms),
        stage_ms: simulation.stage_ms(),
        max_penetration: max_penetration.max(sample.max_penetration),
        drift,
        kinetic_energy: simulation.kinetic_energy(),
        pairs: sample.pairs,
        contacts: sample.contacts,
    };
    CaseResult {
        figures: Some(figures),
        ..CaseResult::not_run(key, scene, status)
    }
}

/// Wall time of one step (ms).
fn timed_step(simulation: &mut dyn Simulation) -> f64 {
    let start = Instant::now();
    simulation.step();
    start.elapsed().as_secs_f64() * 1e3
}

fn drift(kind: DriftKind, start_positions: &[Vec3], simulation: &dyn Simulation) -> Drift {
    let values: Vec<f64> = simulation
        .dynamic_states()
        .iter()
        .zip(start_positions)
        .map(|(state, start)| match kind {
            DriftKind::Displacement => state.position.distance(*start) as f64,
            DriftKind::Speed => state.linear_velocity.length() as f64,
        })
        .collect();
    let mean = if values.is_empty() {
        0.0
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    };
    Drift {
        kind,
        mean,
        max: values.iter().copied().fold(0.0, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_uses_nearest_ranks() {
        assert_eq!(Spread::of(&[]), None);
        let one = Spread::of(&[2.0]).unwrap();
        assert_eq!((one.median, one.p10, one.p90), (2.0, 2.0, 2.0));
        let samples: Vec<f64> = (1..=20).rev().map(f64::from).collect();
        let spread = Spread::of(&samples).unwrap();
        assert_eq!(
            (
                spread.min,
                spread.p10,
                spread.median,
                spread.p90,
                spread.max
            ),
            (1.0, 2.0, 10.5, 18.0, 20.0)
        );
    }
}
