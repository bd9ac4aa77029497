//! The rest timers and the sleep test on the device, where the step integrates the bodies
//! (`rest.wgsl`): [`Islands::update_timers`](super::island::Islands::update_timers) over the
//! velocities solved there, and a test of whether
//! [`Islands::fall_asleep`](super::island::Islands::fall_asleep) would put an island to sleep.
//!
//! On the host the timers need every body's velocity each step, read back, and the test is a
//! pass over every body and its root (0.6 ms a step of a settled pile of 100k boxes on an H100
//! machine's host, BENCHMARKS.md session 25), though a pile that stands seldom has an island
//! to put to sleep. Here they are two dispatches in the solver's submission, and the host
//! reads three words ([`RestTally`]): the timers come back only when an island may sleep.

use bytemuck::{Pod, Zeroable};

use crate::dynamics::body::{BODY_WGSL, ColliderData};
use crate::dynamics::island::{SLEEP_SPEED, TIME_TO_SLEEP};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, Source, UniformSlots, WORKGROUP_SIZE, encode_all, workgroups_for,
};
use crate::stages::constraints::CONTACT_CONSTRAINT_WGSL;
use crate::stages::integrate::MAX_ROTATION_PER_STEP;
use crate::stages::solver::SolverBody;
use crate::stages::solver::gpu::SOLVER_BODY_WGSL;

const WGSL: &str = include_str!("rest.wgsl");
/// Parameters, held word, bodies, colliders, timers, tally, roots, holds.
const BINDINGS: [Binding; 8] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageReadWrite,
];

/// Mirrors `RestParams` in `rest.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct RestParams {
    bodies: u32,
    dt: f32,
    test: u32,
    _pad: u32,
}

fn wgsl() -> Source {
    // The solver's bodies bring their helpers, which read the integration's constant and the
    // contact rows' structs.
    Source::new()
        .constant_f32("SLEEP_SPEED", SLEEP_SPEED)
        .constant_f32("TIME_TO_SLEEP", TIME_TO_SLEEP)
        .constant_f32("MAX_ROTATION_PER_STEP", MAX_ROTATION_PER_STEP)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("solver_body.wgsl", SOLVER_BODY_WGSL)
        .snippet("rest.wgsl", WGSL)
}

/// What the kernels read: the step's held word, its solved bodies, the colliders, and where
/// the islands were linked on the device this step, each body's root.
pub struct RestInputs<'a> {
    pub held: &'a GpuVec<u32>,
    pub bodies: &'a GpuVec<SolverBody>,
    pub colliders: &'a GpuVec<ColliderData>,
    pub roots: Option<&'a GpuVec<u32>>,
}

/// What a step's kernels found, read back after it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestTally {
    /// The largest rest time of an awake dynamic body (s).
    pub max_timer: f32,
    /// How many awake dynamic bodies have rested [`TIME_TO_SLEEP`].
    pub rested: u32,
    /// Where the islands were linked on the device: how many of those are in an island that
    /// no awake body holds, at least as many as [`Islands::fall_asleep`] would put to sleep
    /// (the device's islands leave out the joints and the dragged body), so 0 means none.
    ///
    /// [`Islands::fall_asleep`]: super::island::Islands::fall_asleep
    pub sleepers: Option<u32>,
}

impl RestTally {
    /// Whether the host must read the timers and look for islands to put to sleep.
    pub fn may_sleep(&self) -> bool {
        self.rested > 0 && self.sleepers != Some(0)
    }
}

/// The buffers bound (held, bodies, colliders, timers, tally, roots, holds), the bodies, the
/// step's length (bits) and whether the test runs.
type Key = ([wgpu::Buffer; 7], usize, u32, bool);

/// Every body's rest time on the device, and the kernels that move it.
pub struct GpuRestTimers {
    kernels: [Kernel; 2],
    timers: GpuVec<f32>,
    holds: GpuVec<u32>,
    tally: GpuVec<u32>,
    /// The tally read back, reused (a step allocates nothing).
    tally_host: Vec<u32>,
    cached: Option<(Key, Vec<Dispatch>, UniformSlots)>,
}

impl GpuRestTimers {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        let source = wgsl();
        let kernel = |entry| Kernel::new(context, entry, &source, entry, &BINDINGS);
        Ok(Self {
            kernels: [kernel("rest"), kernel("sleepers")],
            timers: GpuVec::with_capacity(context, "rest timers", 0)?,
            holds: GpuVec::with_capacity(context, "island holds", 0)?,
            tally: GpuVec::from_slice(context, "rest tally", &[0; 3])?,
            tally_host: Vec::new(),
            cached: None,
        })
    }

    /// The host's timers, one per body, to the device.
    pub fn upload(&mut self, context: &GpuContext, timers: &[f32]) -> Result<(), GpuError> {
        self.timers.upload(context, timers)?;
        self.holds.resize(context, timers.len())?;
        Ok(())
    }

    /// How many bodies have a timer on the device.
    pub fn bodies(&self) -> usize {
        self.timers.len()
    }

    /// Encodes the zeroing of the tally and the holds, before the pass of [`Self::encode`].
    pub fn encode_clear(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(self.tally.buffer(), 0, None);
        if !self.holds.is_empty() {
            let bytes = (self.holds.len() * size_of::<u32>()) as u64;
            encoder.clear_buffer(self.holds.buffer(), 0, Some(bytes));
        }
    }

    /// Encodes the kernels for the bodies that have timers ([`Self::upload`]), after the
    /// integration in the same pass, with the step's length `dt` (s).
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        inputs: &RestInputs,
        dt: f32,
    ) {
        let bodies = self.timers.len();
        let test = inputs.roots.is_some();
        // Any buffer read-only here fills the unread binding of the roots where there are none.
        let roots = inputs.roots.unwrap_or(inputs.held);
        let buffers = [
            inputs.held.buffer().clone(),
            inputs.bodies.buffer().clone(),
            inputs.colliders.buffer().clone(),
            self.timers.buffer().clone(),
            self.tally.buffer().clone(),
            roots.buffer().clone(),
            self.holds.buffer().clone(),
        ];
        let key = (buffers, bodies, dt.to_bits(), test);
        if self
            .cached
            .as_ref()
            .is_none_or(|(cached, ..)| *cached != key)
        {
            let params = RestParams {
                bodies: bodies as u32,
                dt,
                test: u32::from(test),
                _pad: 0,
            };
            let uniform = UniformSlots::new(context, "rest params", &[params]);
            let bindings = [
                uniform.binding(0),
                inputs.held.whole(),
                inputs.bodies.whole(),
                inputs.colliders.whole(),
                self.timers.whole(),
                self.tally.whole(),
                roots.whole(),
                self.holds.whole(),
            ];
            let workgroups = workgroups_for(bodies, WORKGROUP_SIZE);
            let kernels = if test {
                &self.kernels[..]
            } else {
                &self.kernels[..1]
            };
            let dispatches = kernels
                .iter()
                .map(|kernel| kernel.dispatch(kernel.bind(context, &bindings), workgroups))
                .collect();
            self.cached = Some((key, dispatches, uniform));
        }
        if let Some((_, dispatches, _)) = &self.cached {
            encode_all(pass, dispatches);
        }
    }

    /// Encodes the tally's read-back, after [`Self::encode`]'s pass.
    pub fn encode_download(&mut self, context: &GpuContext, encoder: &mut wgpu::CommandEncoder) {
        self.tally.encode_download(context, encoder);
    }

    /// Once the submission of [`Self::encode_download`] ran: what the kernels found, `tested`
    /// where they were encoded with the roots.
    pub fn read_tally(
        &mut self,
        context: &GpuContext,
        tested: bool,
    ) -> Result<RestTally, GpuError> {
        self.tally.read_download(context, &mut self.tally_host)?;
        let word = |i: usize| self.tally_host.get(i).copied().unwrap_or(0);
        Ok(RestTally {
            max_timer: f32::from_bits(word(0)),
            rested: word(1),
            sleepers: tested.then(|| word(2)),
        })
    }

    /// Every body's timer, read now (after the step's wait).
    pub fn read(&self, context: &GpuContext) -> Result<Vec<f32>, GpuError> {
        self.timers.read(context)
    }
}
