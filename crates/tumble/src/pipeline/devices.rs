//! Which executor runs each stage of the step: the talk's "the developer can mix stages
//! between CPU and GPU". Data crosses between host and device only where two consecutive
//! stages run on different sides; the profile shows each such copy as its own line.

use std::fmt;
use std::str::FromStr;

/// Where a stage runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Executor {
    /// Rust on the host, with rayon.
    #[default]
    Cpu,
    /// WGSL kernels on the world's GPU adapter.
    Gpu,
}

impl fmt::Display for Executor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Executor::Cpu => "cpu",
            Executor::Gpu => "gpu",
        })
    }
}

/// A stage of the step that can run on either executor, in step order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    Aabb,
    Broadphase,
    Narrowphase,
    Constraints,
    Batching,
    Solver,
    Integrate,
}

impl Stage {
    pub const ALL: [Stage; 7] = [
        Stage::Aabb,
        Stage::Broadphase,
        Stage::Narrowphase,
        Stage::Constraints,
        Stage::Batching,
        Stage::Solver,
        Stage::Integrate,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Aabb => "aabb",
            Stage::Broadphase => "broadphase",
            Stage::Narrowphase => "narrowphase",
            Stage::Constraints => "constraints",
            Stage::Batching => "batching",
            Stage::Solver => "solver",
            Stage::Integrate => "integrate",
        }
    }
}

/// The executor of each stage. Default: all on the CPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct StageDevices {
    executors: [Executor; Stage::ALL.len()],
}

/// Why a `--stages` list was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StageDevicesError {
    #[error("{0:?} is not stage=device (e.g. broadphase=gpu)")]
    NotAnAssignment(String),
    #[error(
        "unknown stage {0:?}; stages are aabb, broadphase, narrowphase, constraints, batching, solver, integrate"
    )]
    UnknownStage(String),
    #[error("unknown device {device:?} for {stage}; use cpu or gpu")]
    UnknownDevice { stage: String, device: String },
}

impl StageDevices {
    /// Every stage on `executor`.
    pub fn all(executor: Executor) -> Self {
        Self {
            executors: [executor; Stage::ALL.len()],
        }
    }

    pub fn get(&self, stage: Stage) -> Executor {
        self.executors[stage as usize]
    }

    pub fn set(&mut self, stage: Stage, executor: Executor) {
        self.executors[stage as usize] = executor;
    }

    /// Whether any stage needs the GPU.
    pub fn any_gpu(&self) -> bool {
        self.executors.contains(&Executor::Gpu)
    }

    /// Applies a comma-separated `stage=device` list (`broadphase=gpu,solver=cpu`) on top of
    /// `self`; an empty list changes nothing.
    pub fn with_assignments(mut self, list: &str) -> Result<Self, StageDevicesError> {
        for assignment in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (stage_name, device) = assignment
                .split_once('=')
                .ok_or_else(|| StageDevicesError::NotAnAssignment(assignment.to_owned()))?;
            let stage = Stage::ALL
                .into_iter()
                .find(|stage| stage.name() == stage_name)
                .ok_or_else(|| StageDevicesError::UnknownStage(stage_name.to_owned()))?;
            let executor = match device {
                "cpu" => Executor::Cpu,
                "gpu" => Executor::Gpu,
                _ => {
                    return Err(StageDevicesError::UnknownDevice {
                        stage: stage_name.to_owned(),
                        device: device.to_owned(),
                    });
                }
            };
            self.set(stage, executor);
        }
        Ok(self)
    }
}

impl FromStr for StageDevices {
    type Err = StageDevicesError;

    fn from_str(list: &str) -> Result<Self, Self::Err> {
        Self::default().with_assignments(list)
    }
}

/// `aabb=cpu,broadphase=gpu,...`: the form `--stages` takes, every stage named.
impl fmt::Display for StageDevices {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, stage) in Stage::ALL.into_iter().enumerate() {
            let separator = if i == 0 { "" } else { "," };
            write!(f, "{separator}{}={}", stage.name(), self.get(stage))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn assignments_override_per_stage_and_round_trip() {
        let devices: StageDevices = "broadphase=gpu, solver=gpu".parse().unwrap();
        assert_eq!(devices.get(Stage::Aabb), Executor::Cpu);
        assert_eq!(devices.get(Stage::Broadphase), Executor::Gpu);
        assert_eq!(devices.get(Stage::Narrowphase), Executor::Cpu);
        assert_eq!(devices.get(Stage::Solver), Executor::Gpu);
        assert!(devices.any_gpu());
        assert_eq!(devices.to_string().parse::<StageDevices>(), Ok(devices));
        let all_gpu = StageDevices::all(Executor::Gpu);
        assert_eq!(
            all_gpu
                .with_assignments("solver=cpu")
                .unwrap()
                .get(Stage::Solver),
            Executor::Cpu
        );
        assert!(!StageDevices::default().any_gpu());
        assert_eq!("".parse(), Ok(StageDevices::default()));
    }

    #[test]
    fn bad_lists_name_the_problem() {
        assert_eq!(
            "broadphase".parse::<StageDevices>(),
            Err(StageDevicesError::NotAnAssignment("broadphase".into()))
        );
        assert_eq!(
            "physics=gpu".parse::<StageDevices>(),
            Err(StageDevicesError::UnknownStage("physics".into()))
        );
        assert_eq!(
            "solver=tpu".parse::<StageDevices>(),
            Err(StageDevicesError::UnknownDevice {
                stage: "solver".into(),
                device: "tpu".into()
            })
        );
    }
}
