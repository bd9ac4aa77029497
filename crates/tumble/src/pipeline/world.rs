//! [`World`]: add and remove bodies, step, read poses and velocities back.
//!
//! ```
//! use tumble::{BodyDesc, Shape, StepConfig, World, math::Vec3};
//!
//! let mut world = World::new(StepConfig::default()).unwrap();
//! world.add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))).unwrap();
//! let ball = world
//!     .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(Vec3::new(0.0, 2.0, 0.0)))
//!     .unwrap();
//! for _ in 0..120 {
//!     world.step();
//! }
//! let height = world.pose(ball).unwrap().position.y;
//! assert!((height - 0.5).abs() < 0.01, "the ball rests on the ground: y = {height}");
//! ```

/// Stiffness of the drag of [`World::set_drag_target`] (Hz) and its damping ratio. The drag
/// is a soft point joint in every sweep, relax sweeps included (as Box2D's mouse joint): rigid
/// there, it stopped the dragged point at the end of each sub-step, so the force limit acted
/// as a speed limit of (force / mass − g) × sub-step (a 10-weight drag crept at 0.18 m/s).
/// Overdamped (ratio 3) so that a force-limited pull does not overshoot (ratio 1 overshot by
/// 0.39 m at 10 weights); at 20 Hz the dragged point trails a target moving at 1 m/s by 4 cm.
pub const DRAG_HERTZ: f32 = 20.0;
pub const DRAG_DAMPING_RATIO: f32 = 3.0;

use crate::dynamics::body::{
    BodyDesc, BodyError, BodyHandle, BodyMass, BodyPose, BodyVelocity, Collider,
};
use crate::dynamics::island::{Islands, SleepState};
use crate::dynamics::joint::{Joint, JointDesc, JointError, JointHandle, JointState};
use crate::gpu::context::{GpuContext, GpuError};
use crate::math::{Mat3, Transform, Vec3};
use crate::pipeline::config::{ConfigError, StepConfig};
use crate::pipeline::devices::StageDevices;
pub use crate::pipeline::gpu_stages::DevicePoses;
use crate::pipeline::gpu_stages::{BodyChanges, BodyInputs, GpuStages};
use crate::pipeline::parallel::filter_map_ordered;
use crate::pipeline::step::StepScratch;
use crate::profile::Profiler;
use crate::shape::Shape;
use crate::stages::broadphase::Broadphase;
use crate::stages::constraints::Drag;
use crate::stages::narrowphase::summary::PairSummary;
use crate::stages::narrowphase::{ChildCache, ManifoldCache, PairContact, gpu_shape};
use crate::stages::pairs::PairCache;
use std::sync::Arc;
use std::sync::OnceLock;

/// The poses and velocities read back from the device ([`World::current_bodies`]).
pub(crate) type DeviceBodyRead = Result<(Vec<BodyPose>, Vec<BodyVelocity>), GpuError>;

/// Batch number of a pair that has no constraint this step.
pub const NO_BATCH: u32 = u32::MAX;

/// Counts from the last step, for reports and the profiler.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Candidate pairs from the broadphase (fat AABBs overlap).
    pub pairs: usize,
    /// Pairs new this step / gone this step (the talk's persistent pairs).
    pub pairs_added: usize,
    pub pairs_removed: usize,
    /// Pairs whose manifolds the narrowphase's pair functions computed this step: the others
    /// moved their last manifolds with their bodies (the manifold cache, for polyhedra that
    /// barely moved), were skipped (jointed, or resting and asleep), or belong to meshes and
    /// compounds, whose manifolds are the children's.
    pub pairs_computed: usize,
    /// Child manifolds (one per touching triangle of a mesh, coplanar ones merged), and how
    /// many were new / gone this step.
    pub child_manifolds: usize,
    pub child_manifolds_added: usize,
    pub child_manifolds_removed: usize,
    /// Manifolds with at least one contact point, pair and child manifolds together.
    pub manifolds: usize,
    /// Contact points.
    pub contacts: usize,
    /// Deepest overlap of any contact (m, ≥ 0).
    pub max_penetration: f32,
    /// Joints solved this step (unbroken ones, and the drag of `set_drag_target`).
    pub joints: usize,
    /// Bodies asleep after the step.
    pub sleeping: usize,
    /// Constraints (contact manifolds and joints) per batch: the talk's batch histogram.
    pub batch_histogram: Vec<u32>,
    /// Rounds the batching took to give every constraint its batch (each a claim and a commit
    /// on the GPU, the CPU's twin counting the same; 0 when the Jacobi solver colors nothing).
    pub batching_rounds: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SlotState {
    Free,
    Static,
    Dynamic,
}

#[derive(Clone, Debug)]
pub(crate) struct Slot {
    generation: u32,
    state: SlotState,
    /// The mass the body was made with (kg), reported back in dumps.
    mass: f32,
    name: Option<String>,
}

impl Slot {
    /// Whether a body lives here (it was not removed).
    pub(crate) fn is_live(&self) -> bool {
        self.state != SlotState::Free
    }

    /// Whether the body was made dynamic (asleep or not).
    pub(crate) fn is_dynamic(&self) -> bool {
        self.state == SlotState::Dynamic
    }
}

/// A physics world: bodies, the persistent state between steps, and the step itself.
pub struct World {
    pub(crate) config: StepConfig,
    // Body arrays, indexed by slot (see `dynamics::body`).
    pub(crate) poses: Vec<BodyPose>,
    pub(crate) velocities: Vec<BodyVelocity>,
    pub(crate) masses: Vec<BodyMass>,
    pub(crate) colliders: Vec<Collider>,
    pub(crate) slots: Vec<Slot>,
    pub(crate) free_slots: Vec<u32>,
    // Joints, by slot; `None` is a free slot.
    pub(crate) joints: Vec<Option<Joint>>,
    joint_generations: Vec<u32>,
    free_joints: Vec<u32>,
    /// Sorted pair keys of bodies joined by an unbroken joint: their contacts are skipped.
    pub(crate) jointed_pairs: Vec<u64>,
    /// The body point being dragged towards a target (picking), if any.
    pub(crate) drag: Option<Drag>,
    // State carried from step to step.
    pub(crate) broadphase: Broadphase,
    pub(crate) pairs: PairCache<PairContact>,
    /// Per-triangle manifolds of pairs with a mesh (`stages::narrowphase::children`).
    pub(crate) children: ChildCache,
    pub(crate) scratch: StepScratch,
    pub(crate) stats: StepStats,
    /// The batch of each pair's manifold in the last step ([`NO_BATCH`] without contacts),
    /// found at the first [`World::contact_batches`] after it.
    pub(crate) pair_batches: OnceLock<Vec<u32>>,
    /// The last step's contact colors stayed on the device (its batch layout did): the
    /// contact batches read them from there.
    pub(crate) row_colors_on_device: bool,
    pub(crate) profiler: Profiler,
    pub(crate) steps: u64,
    /// The executor of each stage, and the GPU side when a stage runs there.
    pub(crate) devices: StageDevices,
    pub(crate) gpu: Option<GpuStages>,
    /// The device the GPU stages run on when the caller gave one
    /// ([`World::set_gpu_context`]); else the process's shared one.
    pub(crate) gpu_context: Option<GpuContext>,
    /// Sleep state of every body and the sleeping islands.
    pub(crate) islands: Islands,
    /// Sorted keys of the pairs between sleeping bodies, or a sleeping and a static one: the
    /// broadphase no longer looks for them (both are in its fixed tree), so they are merged
    /// into its result to keep their manifolds for when the island wakes. Made for the stages
    /// one by one: the collision in one GPU submission finds them on the device.
    pub(crate) resting_pairs: Vec<u64>,
    /// Bodies fell asleep, woke or went since `resting_pairs` was made: the next step makes it
    /// again before its broadphase ([`World::refresh_resting_pairs`]).
    resting_pairs_stale: bool,
    /// The next narrowphase recomputes the resting pairs too (an island just fell asleep, or a
    /// dumped state was loaded): their manifolds then hold the poses they rest at.
    pub(crate) refresh_resting: bool,
    /// Scratch: bodies woken or put to sleep by a call.
    pub(crate) changed_bodies: Vec<u32>,
    /// Bodies outside their broadphase fat AABB, for exact queries (`pipeline::query`); reset
    /// whenever bodies move, come or go.
    pub(crate) query_escapes: OnceLock<Vec<u32>>,
    /// The last step left its pairs' contacts on the device (all stages on the GPU, every pair
    /// one the GPU narrowphase computes): `pairs` has this step's keys, but its values are
    /// older than the device's. `pair_summaries` holds what the step needed of them;
    /// [`World::sync_contacts`] brings them over, and the contact queries read them through
    /// `device_contacts`, at their first call after the step.
    pub(crate) contacts_on_device: bool,
    /// Whether a step may leave the contacts on the device (tests turn it off to compare).
    pub(crate) contacts_may_stay_on_device: bool,
    pub(crate) pair_summaries: Vec<PairSummary>,
    /// Whether `pair_summaries` holds this step's: the collision leaves them on the device
    /// where the step will likely not read them (`World::fetch_pair_summaries`).
    pub(crate) pair_summaries_fresh: bool,
    pub(crate) device_contacts: OnceLock<Vec<PairContact>>,
    /// With the contacts, the pairs' keys stay on the device too: `pairs` holds their count
    /// ([`PairCache::adopt_key_count`]) until [`World::fetch_pair_keys`] brings them over, and
    /// the contact queries read them through `device_keys`, at their first call after the
    /// step.
    pub(crate) device_keys: OnceLock<Vec<u64>>,
    /// Where the last step moved the rest timers on the device
    /// ([`Islands::timers_on_device`]): theirs, read at the first call of
    /// [`Self::sleep_state`] after the step.
    pub(crate) device_timers: OnceLock<Vec<f32>>,
    /// Where the last step left the poses and velocities on the device
    /// ([`Self::bodies_on_device`]): theirs, read at the first call of a getter after the
    /// step ([`Self::current_bodies`]).
    pub(crate) device_bodies: OnceLock<DeviceBodyRead>,
    /// Whether a step may leave them there (tests turn it off to compare).
    pub(crate) bodies_may_stay_on_device: bool,
    /// Live bodies whose shape the GPU narrowphase has no kernel for ([`gpu_shape`]): while
    /// there are any, the contacts come back to the host every step.
    pub(crate) host_shapes: usize,
    /// Some body added so far bounces (restitution above 0): until one does, no contact row
    /// can, and the step looks no collider up to know it.
    pub(crate) may_bounce: bool,
    /// Bumped by every change of `poses`, `velocities` or `masses` ([`Self::bodies_changed`]):
    /// the GPU stages keep their copies of the bodies while it holds, so a step that
    /// integrated on the device uploads no body at the next.
    pub(crate) bodies_version: u64,
    /// The bodies changed since a version, for the GPU stages' uploads.
    pub(crate) body_changes: BodyChanges,
}

impl World {
    pub fn new(config: StepConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let mut broadphase = Broadphase::default();
        broadphase.fat_margin = config.aabb_margin;
        Ok(Self {
            config,
            poses: Vec::new(),
            velocities: Vec::new(),
            masses: Vec::new(),
            colliders: Vec::new(),
            slots: Vec::new(),
            free_slots: Vec::new(),
            joints: Vec::new(),
            joint_generations: Vec::new(),
            free_joints: Vec::new(),
            jointed_pairs: Vec::new(),
            drag: None,
            broadphase,
            pairs: PairCache::default(),
            children: ChildCache::default(),
            scratch: StepScratch::default(),
            stats: StepStats::default(),
            pair_batches: OnceLock::new(),
            row_colors_on_device: false,
            profiler: Profiler::new("step"),
            steps: 0,
            devices: StageDevices::default(),
            gpu: None,
            gpu_context: None,
            islands: Islands::default(),
            resting_pairs: Vec::new(),
            resting_pairs_stale: false,
            refresh_resting: false,
            changed_bodies: Vec::new(),
            query_escapes: OnceLock::new(),
            contacts_on_device: false,
            contacts_may_stay_on_device: true,
            pair_summaries: Vec::new(),
            pair_summaries_fresh: false,
            device_contacts: OnceLock::new(),
            device_timers: OnceLock::new(),
            device_bodies: OnceLock::new(),
            bodies_may_stay_on_device: true,
            device_keys: OnceLock::new(),
            host_shapes: 0,
            may_bounce: false,
            bodies_version: 0,
            body_changes: BodyChanges::default(),
        })
    }

    pub fn config(&self) -> &StepConfig {
        &self.config
    }

    /// Changes the step parameters; takes effect at the next step.
    pub fn set_config(&mut self, config: StepConfig) -> Result<(), ConfigError> {
        config.validate()?;
        self.broadphase.fat_margin = config.aabb_margin;
        self.config = config;
        if !config.sleeping {
            self.changed_bodies.clear();
            self.islands
                .wake_all(&mut self.masses, &mut self.changed_bodies);
            if !self.changed_bodies.is_empty() {
                self.masses_changed();
            }
            self.after_waking();
        }
        Ok(())
    }

    /// Adds a body; `Err` says which field of `desc` is invalid.
    pub fn add_body(&mut self, desc: BodyDesc) -> Result<BodyHandle, BodyError> {
        desc.validate()?;
        // The device's arrays grow with the host's: the host's must be the newest first.
        self.sync_bodies().map_err(BodyError::readback)?;
        if let Some(name) = &desc.name
            && self.find(name).is_some()
        {
            return Err(BodyError::DuplicateName(name.clone()));
        }
        let live_colliders = self
            .colliders
            .iter()
            .zip(&self.slots)
            .filter(|(_, slot)| slot.is_live());
        // A compound on a mesh keys its child manifolds `child * triangles + triangle` in a
        // u32 (the child cache's and the dump's child index).
        let too_many_keys = |a: &Shape, b: &Shape| match (a, b) {
            (Shape::Compound(compound), Shape::TriMesh(mesh))
            | (Shape::TriMesh(mesh), Shape::Compound(compound)) => {
                let keys = compound.children().len() as u64 * mesh.triangles().len() as u64;
                (keys > 1 << 32).then_some(BodyError::CompoundMeshKeys {
                    children: compound.children().len(),
                    triangles: mesh.triangles().len(),
                })
            }
            _ => None,
        };
        if let Some(error) = live_colliders
            .clone()
            .find_map(|(c, _)| too_many_keys(&desc.shape, &c.shape))
        {
            return Err(error);
        }
        let dynamic = !desc.is_static();
        // A hull's or a compound's body frame is its principal centroid frame: compose it with
        // the desc's pose and keep the shape in that frame, so the body (and a dump of it) has
        // the COM pose.
        let in_frame = |local_frame: Transform| {
            let frame =
                Transform::new(desc.position, desc.unit_rotation()).mul_transform(&local_frame);
            BodyPose::new(frame.position, frame.rotation)
        };
        let (pose, shape) = match &desc.shape {
            Shape::ConvexHull(hull) if hull.local_frame() != Transform::IDENTITY => (
                in_frame(hull.local_frame()),
                Shape::ConvexHull(Arc::new(hull.in_own_frame())),
            ),
            Shape::Compound(compound) if compound.local_frame() != Transform::IDENTITY => (
                in_frame(compound.local_frame()),
                Shape::Compound(Arc::new(compound.in_own_frame())),
            ),
            shape => (
                BodyPose::new(desc.position, desc.unit_rotation()),
                shape.clone(),
            ),
        };
        let velocity = if dynamic {
            BodyVelocity::new(desc.linear_velocity, desc.angular_velocity)
        } else {
            BodyVelocity::default()
        };
        let mass_properties = desc.shape.mass_properties(desc.mass);
        let mass = BodyMass {
            inverse_inertia: mass_properties.inverse_inertia,
            inverse_mass: mass_properties.inverse_mass,
        };
        let collider = Collider {
            shape,
            friction: desc.friction,
            restitution: desc.restitution,
        };
        self.may_bounce |= desc.restitution > 0.0;
        let state = if dynamic {
            SlotState::Dynamic
        } else {
            SlotState::Static
        };
        self.bodies_changed();
        let index = match self.free_slots.pop() {
            Some(index) => {
                let i = index as usize;
                self.poses[i] = pose;
                self.velocities[i] = velocity;
                self.masses[i] = mass;
                self.colliders[i] = collider;
                let slot = &mut self.slots[i];
                slot.state = state;
                slot.mass = desc.mass;
                slot.name = desc.name;
                index
            }
            None => {
                self.poses.push(pose);
                self.velocities.push(velocity);
                self.masses.push(mass);
                self.colliders.push(collider);
                self.slots.push(Slot {
                    generation: 0,
                    state,
                    mass: desc.mass,
                    name: desc.name,
                });
                (self.slots.len() - 1) as u32
            }
        };
        let aabb = self.colliders[index as usize]
            .shape
            .aabb(&pose.transform())
            .expanded(self.config.contact_margin);
        self.broadphase.insert(index, aabb, dynamic);
        if !gpu_shape(&self.colliders[index as usize].shape) {
            self.host_shapes += 1;
        }
        if let Some(gpu) = &mut self.gpu {
            gpu.colliders_changed();
        }
        self.islands.resize(self.slots.len());
        self.islands.reset_timer(index);
        self.query_escapes = OnceLock::new();
        Ok(BodyHandle {
            index,
            generation: self.slots[index as usize].generation,
        })
    }

    /// Removes a body; its contacts go with it at the next step, its joints at once.
    pub fn remove_body(&mut self, handle: BodyHandle) -> Result<(), BodyError> {
        let i = self.check(handle)?;
        // The body's pairs stay in the pair cache until the next step drops them, and a body
        // added before then takes this slot and their keys: none of their manifolds may be
        // moved as this body's (their caches go; the host holds the contacts from here).
        self.sync_contacts()
            .map_err(|error| BodyError::ContactsReadback(error.to_string()))?;
        let (keys, contacts) = self.pairs.keys_and_values_mut();
        for (&key, contact) in keys.iter().zip(contacts) {
            let (a, b) = crate::stages::pairs::pair_bodies(key);
            if a == handle.index || b == handle.index {
                contact.cache = ManifoldCache::default();
            }
        }
        // Whatever rests on the body, or sleeps with it, must feel it go.
        let touching: Vec<u32> = self
            .pairs
            .keys()
            .iter()
            .map(|&key| crate::stages::pairs::pair_bodies(key))
            .filter_map(|(a, b)| match (a == handle.index, b == handle.index) {
                (true, _) => Some(b),
                (_, true) => Some(a),
                _ => None,
            })
            .chain([handle.index])
            .collect();
        self.wake(&touching);
        let attached: Vec<u32> = (0..self.joints.len() as u32)
            .filter(|&j| {
                self.joints[j as usize].is_some_and(|joint| {
                    joint.body_a == handle.index || joint.body_b == handle.index
                })
            })
            .collect();
        for joint in attached {
            self.free_joint(joint);
        }
        self.broadphase.remove(handle.index);
        self.query_escapes = OnceLock::new();
        if !gpu_shape(&self.colliders[i].shape) {
            self.host_shapes -= 1;
        }
        let slot = &mut self.slots[i];
        slot.state = SlotState::Free;
        slot.generation = slot.generation.wrapping_add(1);
        slot.name = None;
        if self.drag.is_some_and(|drag| drag.body == handle.index) {
            self.drag = None;
        }
        // A free slot is static and shapeless for the stages: it never moves or collides.
        self.masses[i] = BodyMass::default();
        self.velocities[i] = BodyVelocity::default();
        self.changed_bodies.clear();
        self.changed_bodies.push(handle.index);
        self.masses_changed();
        self.free_slots.push(handle.index);
        self.resting_pairs_changed();
        Ok(())
    }

    /// Restores dumped sleep states: (body, rest time, sleeping island number). Bodies with the
    /// same number are put to sleep as one island; the contacts must be restored first, so
    /// that the island keeps its pairs. A rest time that is not finite and >= 0 is refused,
    /// and nothing is restored.
    pub fn restore_sleep(
        &mut self,
        states: &[(BodyHandle, f32, Option<u32>)],
    ) -> Result<(), BodyError> {
        if let Some(&(_, timer, _)) = states
            .iter()
            .find(|(_, timer, _)| !(timer.is_finite() && *timer >= 0.0))
        {
            return Err(if timer.is_finite() {
                BodyError::Negative {
                    field: "sleep_timer",
                    value: timer,
                }
            } else {
                BodyError::NotFinite {
                    field: "sleep_timer",
                }
            });
        }
        let mut islands: Vec<(u32, u32)> = Vec::new();
        for &(handle, timer, island) in states {
            let Ok(i) = self.check(handle) else { continue };
            self.islands.set_timer(i as u32, timer);
            if let Some(island) = island
                && self.masses[i].inverse_mass > 0.0
            {
                islands.push((island, i as u32));
            }
        }
        islands.sort_unstable();
        for group in islands.chunk_by(|a, b| a.0 == b.0) {
            let bodies: Vec<u32> = group.iter().map(|&(_, body)| body).collect();
            self.islands
                .restore_island(&bodies, &mut self.masses, &mut self.velocities);
            self.changed_bodies.clone_from(&bodies);
            self.masses_changed();
            for &body in &bodies {
                self.broadphase.set_moving(body, false);
            }
        }
        self.resting_pairs_changed();
        self.refresh_resting = true;
        Ok(())
    }

    /// Body slot `index`'s sleep state, its rest time wherever it is newest: the device's
    /// where the last step moved them there (read at the first call after the step; the
    /// host's older one if that read fails, and the next step reports the device's error).
    pub(crate) fn sleep_state(&self, index: u32) -> SleepState {
        let mut state = self.islands.state(index);
        if !self.islands.holds_timer(index) {
            let timers = self.device_timers.get_or_init(|| {
                (self.gpu.as_ref())
                    .and_then(|gpu| gpu.rest_timers().ok())
                    .unwrap_or_default()
            });
            if let Some(&timer) = timers.get(index as usize) {
                state.timer = timer;
            }
        }
        state
    }

    /// Whether the body sleeps (see [`crate::dynamics::island`]).
    pub fn is_sleeping(&self, handle: BodyHandle) -> Result<bool, BodyError> {
        let i = self.check(handle)?;
        Ok(self.islands.state(i as u32).is_asleep())
    }

    /// Wakes the body's island, if it sleeps, and starts its rest time afresh.
    pub fn wake_body(&mut self, handle: BodyHandle) -> Result<(), BodyError> {
        self.check(handle)?;
        self.wake(&[handle.index]);
        self.islands.reset_timer(handle.index);
        Ok(())
    }

    /// Wakes the islands of `bodies` (those asleep).
    pub(crate) fn wake(&mut self, bodies: &[u32]) {
        self.changed_bodies.clear();
        for &body in bodies {
            self.islands
                .wake(body, &mut self.masses, &mut self.changed_bodies);
        }
        if !self.changed_bodies.is_empty() {
            self.masses_changed();
        }
        self.after_waking();
    }

    /// The host changed `poses`, `velocities` or `masses`: the device's copies are stale.
    pub(crate) fn bodies_changed(&mut self) {
        self.bodies_version += 1;
        self.body_changes.all(self.bodies_version);
    }

    /// The bodies in `changed_bodies` fell asleep, woke, were removed or had their velocity
    /// set: only their masses and velocities changed, and a device that holds the bodies from
    /// before takes only theirs.
    pub(crate) fn masses_changed(&mut self) {
        self.bodies_version += 1;
        // The device's bodies read since the step take the host's new velocities too.
        if let Some(Ok((_, velocities))) = self.device_bodies.get_mut() {
            for &i in &self.changed_bodies {
                velocities[i as usize] = self.velocities[i as usize];
            }
        }
        let bodies = &mut self.body_changes.bodies;
        bodies.extend_from_slice(&self.changed_bodies);
        bodies.sort_unstable();
        bodies.dedup();
    }

    /// The bodies in `changed_bodies` just woke: back into the moving tree, and their pairs
    /// are found by the broadphase again.
    fn after_waking(&mut self) {
        if self.changed_bodies.is_empty() {
            return;
        }
        for &body in &self.changed_bodies {
            self.broadphase.set_moving(body, true);
        }
        self.resting_pairs_changed();
    }

    /// Bodies fell asleep, woke or went: the resting pairs are made again before the next
    /// broadphase. Once a step, however many islands changed: the pairs only change in the
    /// broadphase, and the pass is over all of them.
    pub(crate) fn resting_pairs_changed(&mut self) {
        self.resting_pairs_stale = true;
    }

    /// The pairs of the cache with no awake dynamic body and no removed one, when a body
    /// changed since they were made. A pass over every pair, on every core: a settling pile
    /// has islands waking or falling asleep at most steps.
    pub(crate) fn refresh_resting_pairs(&mut self) {
        if !std::mem::take(&mut self.resting_pairs_stale) {
            return;
        }
        self.profiler.begin("resting pairs");
        let live = |i: u32| self.slots[i as usize].state != SlotState::Free;
        let resting = |i: u32| self.masses[i as usize].inverse_mass == 0.0;
        let keys = self.pairs.keys();
        let rests = |pair: usize| {
            let key = keys[pair];
            let (a, b) = crate::stages::pairs::pair_bodies(key);
            (live(a) && live(b) && resting(a) && resting(b)).then_some(key)
        };
        let parts = &mut self.scratch.key_parts;
        filter_map_ordered(keys.len(), rests, parts, &mut self.resting_pairs);
        self.profiler.end();
    }

    /// Adds a joint between two bodies at their current poses.
    pub fn add_joint(&mut self, desc: JointDesc) -> Result<JointHandle, JointError> {
        desc.validate()?;
        let (a, b) = (
            self.check(desc.body_a).map_err(|_| JointError::StaleBody)?,
            self.check(desc.body_b).map_err(|_| JointError::StaleBody)?,
        );
        // Sleeping bodies have no mass until they wake: wake them before asking.
        self.wake(&[a as u32, b as u32]);
        if self.masses[a].inverse_mass == 0.0 && self.masses[b].inverse_mass == 0.0 {
            return Err(JointError::BothStatic);
        }
        let (poses, _) = self.current_bodies().map_err(JointError::readback)?;
        let pose = |i: usize| (poses[i].position, poses[i].rotation);
        let joint = Joint::new(&desc, pose(a), pose(b));
        let index = match self.free_joints.pop() {
            Some(index) => {
                self.joints[index as usize] = Some(joint);
                index
            }
            None => {
                self.joints.push(Some(joint));
                self.joint_generations.push(0);
                (self.joints.len() - 1) as u32
            }
        };
        self.joints_changed();
        Ok(JointHandle {
            index,
            generation: self.joint_generations[index as usize],
        })
    }

    pub fn remove_joint(&mut self, handle: JointHandle) -> Result<(), JointError> {
        self.check_joint(handle)?;
        self.free_joint(handle.index);
        Ok(())
    }

    /// Sets a joint's frames, warm-start impulses and broken flag, as read from a dumped scene
    /// (the joint was added with [`add_joint`](Self::add_joint) from the same description).
    pub fn restore_joint_state(
        &mut self,
        handle: JointHandle,
        state: &JointState,
    ) -> Result<(), JointError> {
        let index = self.check_joint(handle)?;
        if !state.is_finite() {
            return Err(JointError::NotFinite { field: "state" });
        }
        if let Some(joint) = self.joints[index].as_mut() {
            joint.restore(state);
        }
        self.joints_changed();
        Ok(())
    }

    /// The joint as the step sees it (frames in the bodies, impulses).
    pub fn joint(&self, handle: JointHandle) -> Result<&Joint, JointError> {
        let index = self.check_joint(handle)?;
        self.joints[index].as_ref().ok_or(JointError::StaleHandle)
    }

    /// True once the joint's impulse passed its break threshold; a broken joint stays in the
    /// world, inert, until removed, and its bodies collide again.
    pub fn is_joint_broken(&self, handle: JointHandle) -> Result<bool, JointError> {
        Ok(self.joints[self.check_joint(handle)?].is_some_and(|joint| joint.broken))
    }

    /// The joint's anchor as attached to body A and to body B, in the world frame at the current
    /// poses (m). They coincide while the joint holds; their distance is the joint's error
    /// (tests measure it, a viewer can draw it).
    pub fn joint_anchors(&self, handle: JointHandle) -> Result<(Vec3, Vec3), JointError> {
        let index = self.check_joint(handle)?;
        let Some(joint) = self.joints[index] else {
            return Err(JointError::StaleHandle);
        };
        let (poses, _) = self.current_bodies().map_err(JointError::readback)?;
        let anchor =
            |body: u32, local: Vec3| poses[body as usize].transform().transform_point(local);
        Ok((
            anchor(joint.body_a, joint.local_anchor_a),
            anchor(joint.body_b, joint.local_anchor_b),
        ))
    }

    /// Live joints, in slot order.
    pub fn joints(&self) -> impl Iterator<Item = (JointHandle, &Joint)> + '_ {
        self.joints.iter().enumerate().filter_map(|(index, joint)| {
            let handle = JointHandle {
                index: index as u32,
                generation: self.joint_generations[index],
            };
            joint.as_ref().map(|joint| (handle, joint))
        })
    }

    fn free_joint(&mut self, index: u32) {
        self.joints[index as usize] = None;
        self.joint_generations[index as usize] =
            self.joint_generations[index as usize].wrapping_add(1);
        self.free_joints.push(index);
        self.joints_changed();
    }

    /// Joints were added, removed, restored or broke: the pairs they keep from colliding
    /// change, and GPU joint rows upload them again.
    pub(crate) fn joints_changed(&mut self) {
        self.update_jointed_pairs();
        if let Some(gpu) = &mut self.gpu {
            gpu.joints_changed();
        }
    }

    fn update_jointed_pairs(&mut self) {
        self.jointed_pairs.clear();
        self.jointed_pairs.extend(
            self.joints
                .iter()
                .flatten()
                .filter(|j| !j.broken)
                .map(|j| crate::stages::pairs::pair_key(j.body_a, j.body_b)),
        );
        self.jointed_pairs.sort_unstable();
        self.jointed_pairs.dedup();
    }

    fn check_joint(&self, handle: JointHandle) -> Result<usize, JointError> {
        match self.joints.get(handle.index as usize) {
            Some(Some(_)) if self.joint_generations[handle.index as usize] == handle.generation => {
                Ok(handle.index as usize)
            }
            _ => Err(JointError::StaleHandle),
        }
    }

    /// Pulls the point `local_anchor` of `body` (body frame, m) towards `target` (world frame,
    /// m) with at most `max_force` (N), until [`clear_drag`](Self::clear_drag): the picking
    /// of a viewer's mouse drag. It is solved with the joints, as a soft point joint
    /// ([`DRAG_HERTZ`]) to the static world. Call it again each frame as the target moves;
    /// a new body or anchor replaces the drag, one body at a time. A static body is not moved.
    /// A `max_force` of a few times the body's weight lifts it without flinging it.
    pub fn set_drag_target(
        &mut self,
        body: BodyHandle,
        local_anchor: Vec3,
        target: Vec3,
        max_force: f32,
    ) -> Result<(), BodyError> {
        let index = self.check(body)? as u32;
        if !(local_anchor.is_finite() && target.is_finite()) {
            return Err(BodyError::NotFinite { field: "drag" });
        }
        if !(max_force.is_finite() && max_force >= 0.0) {
            return Err(BodyError::Negative {
                field: "max_force",
                value: max_force,
            });
        }
        // Only an accepted drag wakes the body's island.
        self.wake(&[index]);
        // The same point keeps its warm-start impulse, so a moving target pulls smoothly.
        let impulse = self
            .drag
            .filter(|drag| drag.body == index && drag.local_anchor == local_anchor)
            .map_or(Vec3::ZERO, |drag| drag.impulse);
        self.drag = Some(Drag {
            body: index,
            local_anchor,
            target,
            max_force,
            impulse,
        });
        Ok(())
    }

    /// While a drag is set: the dragged point, on the body at its current pose, and the target
    /// it is pulled towards, both in the world frame (m). Their distance is how far the drag
    /// trails; a viewer draws the line between them.
    pub fn drag_anchors(&self) -> Option<(Vec3, Vec3)> {
        let (poses, _) = self.current_bodies_or_host();
        self.drag.map(|drag| {
            let pose = poses[drag.body as usize].transform();
            (pose.transform_point(drag.local_anchor), drag.target)
        })
    }

    /// Lets go of the dragged body.
    pub fn clear_drag(&mut self) {
        self.drag = None;
    }

    /// Advances the world by `config.dt`.
    ///
    /// # Panics
    ///
    /// If a stage on the GPU fails (see [`try_step`](Self::try_step)); with every stage on the
    /// CPU (the default) a step cannot fail.
    pub fn step(&mut self) {
        if let Err(error) = self.try_step() {
            panic!("a GPU stage failed: {error}");
        }
    }

    /// One step, reporting a failure of a GPU stage (a buffer past the adapter's limits, a
    /// lost device) instead of panicking. A failed step leaves the bodies as they were before
    /// it, but where they stayed on the device ([`Self::bodies_on_device`]) and it failed
    /// after moving them there: then they are as it moved them.
    pub fn try_step(&mut self) -> Result<(), GpuError> {
        self.try_step_then(|_| {})
    }

    /// Advances the world by `config.dt`, then runs `after` (queries, typically) inside the
    /// same profiler frame, so that the scopes it opens on [`Self::profiler_mut`] show in the
    /// step's report beside the stages.
    ///
    /// # Panics
    ///
    /// As [`step`](Self::step).
    pub fn step_then<R>(&mut self, after: impl FnOnce(&mut World) -> R) -> R {
        self.try_step_then(after)
            .unwrap_or_else(|error| panic!("a GPU stage failed: {error}"))
    }

    /// [`step_then`](Self::step_then), reporting a failure of a GPU stage as
    /// [`try_step`](Self::try_step) does; `after` runs only after a step that succeeded.
    pub fn try_step_then<R>(&mut self, after: impl FnOnce(&mut World) -> R) -> Result<R, GpuError> {
        // The bodies need no copy to be left as they were: every stage that can fail (the GPU
        // ones) runs before the integration, the first write to the poses and velocities.
        self.profiler.begin_frame();
        let result = self.step_stages();
        self.query_escapes = OnceLock::new();
        let result = result.map(|()| after(self));
        self.profiler.end_frame();
        match result {
            Ok(value) => {
                self.steps += 1;
                Ok(value)
            }
            Err(error) => {
                // Bodies the device holds come back where it still can: the next step starts
                // from them (where it cannot, the next step reports why). Timers the host
                // holds go to the device again: the failed step may have moved the device's.
                let _ = self.sync_bodies();
                if let Some(gpu) = &mut self.gpu
                    && self.islands.holds_timers()
                {
                    gpu.rest_timers_stale();
                }
                Err(error)
            }
        }
    }

    /// Which executor runs each stage.
    pub fn stage_devices(&self) -> StageDevices {
        self.devices
    }

    /// Puts stages on the CPU or the GPU from the next step on (the talk's mixing of stages);
    /// the first GPU stage opens the adapter
    /// ([`GpuContext::shared`](crate::gpu::context::GpuContext::shared)). Results agree between
    /// executors within the parity tests' tolerances, not bitwise.
    pub fn set_stage_devices(&mut self, devices: StageDevices) -> Result<(), GpuError> {
        if devices.any_gpu() && self.gpu.is_none() {
            let context = match &self.gpu_context {
                Some(context) => context.clone(),
                None => GpuContext::shared()?,
            };
            self.gpu = Some(GpuStages::new(context)?);
        }
        self.devices = devices;
        Ok(())
    }

    /// Runs the GPU stages on `context`'s device from the next step on, instead of the
    /// process's shared one: a viewer that presents to a window on a device of its own hands
    /// it over, so the step's buffers ([`Self::device_poses`]) are on the device it draws with.
    /// The GPU side starts afresh there (its buffers are uploaded again at the next step).
    pub fn set_gpu_context(&mut self, context: GpuContext) -> Result<(), GpuError> {
        // The contacts and rest timers left on the old device come over first.
        self.sync_contacts()?;
        self.take_device_rest_timers()?;
        self.sync_bodies()?;
        if self.gpu.is_some() {
            self.gpu = Some(GpuStages::new(context.clone())?);
        }
        self.gpu_context = Some(context);
        Ok(())
    }

    /// The last step's end poses on the GPU, when it integrated there (`integrate=gpu`): see
    /// [`DevicePoses`]. The buffer is on the device the GPU stages run on:
    /// [`Self::set_gpu_context`]'s, else [`GpuContext::shared`].
    pub fn device_poses(&self) -> Option<DevicePoses<'_>> {
        self.gpu.as_ref()?.device_poses()
    }

    /// The adapter the GPU stages run on, when any does.
    pub fn gpu_adapter(&self) -> Option<String> {
        self.gpu.as_ref().map(GpuStages::describe)
    }

    /// Number of live bodies.
    pub fn body_count(&self) -> usize {
        self.slots.len() - self.free_slots.len()
    }

    /// Handles of all live bodies, in slot order.
    pub fn bodies(&self) -> impl Iterator<Item = BodyHandle> + '_ {
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, slot)| slot.state != SlotState::Free)
            .map(|(index, slot)| BodyHandle {
                index: index as u32,
                generation: slot.generation,
            })
    }

    /// The body named `name`, if any.
    pub fn find(&self, name: &str) -> Option<BodyHandle> {
        self.slots
            .iter()
            .position(|slot| slot.state != SlotState::Free && slot.name.as_deref() == Some(name))
            .map(|index| BodyHandle {
                index: index as u32,
                generation: self.slots[index].generation,
            })
    }

    /// The body's pose now. Where the last step left the bodies on the device, the first
    /// getter after it reads them back (see [`Self::sync_bodies`]).
    pub fn pose(&self, handle: BodyHandle) -> Result<Transform, BodyError> {
        let i = self.check(handle)?;
        let (poses, _) = self.current_bodies().map_err(BodyError::readback)?;
        Ok(poses[i].transform())
    }

    /// The velocity of the body's centre of mass (m/s), read as [`Self::pose`] is.
    pub fn linear_velocity(&self, handle: BodyHandle) -> Result<Vec3, BodyError> {
        let i = self.check(handle)?;
        let (_, velocities) = self.current_bodies().map_err(BodyError::readback)?;
        Ok(velocities[i].linear)
    }

    /// The body's angular velocity (rad/s), read as [`Self::pose`] is.
    pub fn angular_velocity(&self, handle: BodyHandle) -> Result<Vec3, BodyError> {
        let i = self.check(handle)?;
        let (_, velocities) = self.current_bodies().map_err(BodyError::readback)?;
        Ok(velocities[i].angular)
    }

    /// Whether the last step left the poses and velocities on the device: its solve
    /// integrated them there and nothing on the host needed them. The host's copies are then
    /// older, but for the bodies it changed since; the getters read the device's at their
    /// first call after the step, and [`Self::sync_bodies`] brings them over.
    pub fn bodies_on_device(&self) -> bool {
        self.gpu
            .as_ref()
            .is_some_and(GpuStages::bodies_left_on_device)
    }

    /// The poses and velocities wherever they are newest: the host's, or where the last step
    /// left them on the device, the device's (read at the first call after the step) with the
    /// host's velocities for the bodies it changed since (a sleep, a wake, a velocity set).
    pub(crate) fn current_bodies(&self) -> Result<(&[BodyPose], &[BodyVelocity]), GpuError> {
        if !self.bodies_on_device() {
            return Ok((&self.poses, &self.velocities));
        }
        match self.device_bodies.get_or_init(|| self.read_device_bodies()) {
            Ok((poses, velocities)) => Ok((poses, velocities)),
            Err(error) => Err(error.clone()),
        }
    }

    /// [`Self::current_bodies`] for the readers that report no error of their own (queries,
    /// dumps, the energy): the host's older copies where the read-back fails, whose error the
    /// next step reports.
    pub(crate) fn current_bodies_or_host(&self) -> (&[BodyPose], &[BodyVelocity]) {
        self.current_bodies()
            .unwrap_or((&self.poses, &self.velocities))
    }

    fn read_device_bodies(&self) -> DeviceBodyRead {
        let gpu = self.gpu.as_ref().ok_or(GpuError::StaleBodies)?;
        let (poses, mut velocities) = gpu.read_bodies()?;
        if poses.len() != self.poses.len() || velocities.len() != self.velocities.len() {
            return Err(GpuError::Readback {
                what: "bodies",
                reason: format!("{} poses for {} bodies", poses.len(), self.poses.len()),
            });
        }
        // The host changes no pose without bringing the bodies over first, but the velocities
        // of bodies that slept, woke, went or were set since are its own.
        for &i in &self.body_changes.bodies {
            velocities[i as usize] = self.velocities[i as usize];
        }
        Ok((poses, velocities))
    }

    /// Brings the poses and velocities the last step left on the device
    /// ([`Self::bodies_on_device`]) to the host's copies. The getters and the step do this
    /// themselves where they need them; a caller rarely has to.
    pub fn sync_bodies(&mut self) -> Result<(), GpuError> {
        if !self.bodies_on_device() {
            return Ok(());
        }
        let (poses, velocities) = match self.device_bodies.take() {
            Some(read) => read?,
            None => self.read_device_bodies()?,
        };
        self.poses.copy_from_slice(&poses);
        self.velocities.copy_from_slice(&velocities);
        if let Some(gpu) = &mut self.gpu {
            gpu.bodies_read(&BodyInputs {
                poses: &self.poses,
                velocities: &self.velocities,
                masses: &self.masses,
                colliders: &self.colliders,
                version: self.bodies_version,
                changed: &self.body_changes,
            });
        }
        Ok(())
    }

    /// Sets a dynamic body's velocities (static bodies ignore this).
    pub fn set_velocity(
        &mut self,
        handle: BodyHandle,
        linear: Vec3,
        angular: Vec3,
    ) -> Result<(), BodyError> {
        let i = self.check(handle)?;
        if !(linear.is_finite() && angular.is_finite()) {
            return Err(BodyError::NotFinite { field: "velocity" });
        }
        if self.slots[i].state == SlotState::Dynamic {
            self.wake(&[handle.index]);
            self.islands.reset_timer(handle.index);
            self.velocities[i] = BodyVelocity::new(linear, angular);
            // This body's alone: a device that holds the others' newer velocities keeps them.
            self.changed_bodies.clear();
            self.changed_bodies.push(handle.index);
            self.masses_changed();
        }
        Ok(())
    }

    /// The description the body would be re-created from now (current pose and velocity).
    pub fn body_desc(&self, handle: BodyHandle) -> Result<BodyDesc, BodyError> {
        let bodies = self.current_bodies().map_err(BodyError::readback)?;
        self.body_desc_in(handle, bodies)
    }

    /// [`Self::body_desc`] at the poses and velocities of `bodies`.
    pub(crate) fn body_desc_in(
        &self,
        handle: BodyHandle,
        (poses, velocities): (&[BodyPose], &[BodyVelocity]),
    ) -> Result<BodyDesc, BodyError> {
        let i = self.check(handle)?;
        let (pose, velocity, collider, slot) = (
            &poses[i],
            &velocities[i],
            &self.colliders[i],
            &self.slots[i],
        );
        Ok(BodyDesc {
            shape: collider.shape.clone(),
            position: pose.position,
            rotation: pose.rotation,
            mass: slot.mass,
            linear_velocity: velocity.linear,
            angular_velocity: velocity.angular,
            friction: collider.friction,
            restitution: collider.restitution,
            name: slot.name.clone(),
        })
    }

    pub fn is_dynamic(&self, handle: BodyHandle) -> Result<bool, BodyError> {
        Ok(self.slots[self.check(handle)?].state == SlotState::Dynamic)
    }

    /// Counts from the last step.
    pub fn stats(&self) -> &StepStats {
        &self.stats
    }

    /// Stage timings since creation or the last [`Profiler::reset`].
    pub fn profiler(&self) -> &Profiler {
        &self.profiler
    }

    pub fn profiler_mut(&mut self) -> &mut Profiler {
        &mut self.profiler
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Kinetic energy of all bodies (J): ½ m v² + ½ ω·Iω.
    pub fn kinetic_energy(&self) -> f64 {
        let (poses, velocities) = self.current_bodies_or_host();
        let mut energy = 0.0f64;
        for (i, velocity) in velocities.iter().enumerate() {
            let mass = &self.masses[i];
            if mass.inverse_mass == 0.0 {
                continue;
            }
            let rotation = Mat3::from_quat(poses[i].rotation);
            let local_omega = rotation.transpose() * velocity.angular;
            let inertia = mass.inverse_inertia.recip();
            let linear = velocity.linear.length_squared() / mass.inverse_mass;
            let angular = (local_omega * local_omega * inertia).element_sum();
            energy += 0.5 * (linear as f64 + angular as f64);
        }
        energy
    }

    /// Persistent contacts as (body A, body B, pair data), in pair order.
    /// When the last step left the contacts on the device, the first call after it reads them
    /// back (an empty list if that read-back fails: the next step reports the device's error).
    pub fn contacts(&self) -> impl Iterator<Item = (BodyHandle, BodyHandle, &PairContact)> + '_ {
        self.pair_keys()
            .iter()
            .zip(self.pair_values())
            .filter(|(_, c)| c.manifold.count > 0)
            .map(|(&key, contact)| {
                let (a, b) = crate::stages::pairs::pair_bodies(key);
                (self.handle_of(a), self.handle_of(b), contact)
            })
    }

    /// The batch each contact manifold was solved in during the last step, as (body A, body B,
    /// batch), in the order of [`contacts`](Self::contacts): the talk's "colored batches".
    /// Batches are numbered as in [`StepStats::batch_histogram`] (the last one is the
    /// sequential overflow batch when there is one).
    pub fn contact_batches(&self) -> impl Iterator<Item = (BodyHandle, BodyHandle, u32)> + '_ {
        self.pair_keys()
            .iter()
            .zip(self.pair_values())
            .zip(
                self.pair_batches()
                    .iter()
                    .chain(std::iter::repeat(&NO_BATCH)),
            )
            .filter(|((_, contact), _)| contact.manifold.count > 0)
            .map(|((&key, _), &batch)| {
                let (a, b) = crate::stages::pairs::pair_bodies(key);
                (self.handle_of(a), self.handle_of(b), batch)
            })
    }

    /// The batch of each manifold slot (pairs, then children) in the last step, from its
    /// rows and their colors: the device's when its batch layout stayed there, else the host's
    /// (summaries of the device's rows, or the host's rows, whose colors follow the joints'). An
    /// empty list if the device's cannot be read: the next step reports the device's error.
    fn pair_batches(&self) -> &[u32] {
        self.pair_batches.get_or_init(|| {
            let scratch = &self.scratch;
            let coloring = &scratch.coloring;
            let (device_slots, device_colors): (Vec<u32>, Vec<u8>);
            let (slots, colors): (&mut dyn Iterator<Item = u32>, &[u8]) =
                if self.row_colors_on_device {
                    let read = self.gpu.as_ref().map(|gpu| {
                        let slots = gpu.read_row_slots()?;
                        gpu.read_row_colors().map(|colors| (slots, colors))
                    });
                    let (slots, colors) = read.and_then(Result::ok).unwrap_or_default();
                    device_colors = colors.into_iter().map(|color| color as u8).collect();
                    device_slots = slots;
                    (&mut device_slots.iter().copied(), &device_colors[..])
                } else {
                    let rows = scratch.row_summaries.len() + scratch.contacts.len();
                    let colors = &coloring.colors[coloring.colors.len().saturating_sub(rows)..];
                    // One of the two is empty: the step kept summaries of the device's rows, or
                    // rows.
                    let row_slots = scratch.row_summaries.iter().map(|row| row.slot);
                    let contact_slots = scratch.contacts.iter().map(|c| c.pair);
                    (&mut row_slots.chain(contact_slots), colors)
                };
            let mut batches = vec![NO_BATCH; self.pairs.len() + self.children.len()];
            for (slot, &color) in slots.zip(colors) {
                if let Some(batch) = batches.get_mut(slot as usize) {
                    *batch = coloring.batch_of(color) as u32;
                }
            }
            batches
        })
    }

    /// The pairs' contacts in pair order, wherever they are newest (see `contacts_on_device`).
    pub(crate) fn pair_values(&self) -> &[PairContact] {
        if !self.contacts_on_device {
            return self.pairs.values();
        }
        self.device_contacts.get_or_init(|| {
            self.gpu
                .as_ref()
                .and_then(|gpu| gpu.read_pair_contacts().ok())
                .unwrap_or_default()
        })
    }

    /// The pairs' keys in pair order, wherever they are: the host's pair cache, or the
    /// device's when the last step left them there (read back at the first call after it; an
    /// empty list if that read fails: the next step reports the device's error).
    pub(crate) fn pair_keys(&self) -> &[u64] {
        if self.pairs.has_keys() {
            return self.pairs.keys();
        }
        self.device_keys.get_or_init(|| {
            self.gpu
                .as_ref()
                .and_then(|gpu| gpu.read_pair_keys().ok())
                .unwrap_or_default()
        })
    }

    /// Brings the pairs' keys to the host's pair cache when the last step left them on the
    /// device, as it leaves them with the contacts: for the rarer steps that pass over the
    /// pairs on the host (an island woken, the host's links).
    pub(crate) fn fetch_pair_keys(&mut self) -> Result<(), GpuError> {
        match &self.gpu {
            Some(gpu) => {
                let (pairs, device_keys) = (&mut self.pairs, &mut self.device_keys);
                fetch_pair_keys(gpu, &mut self.profiler, pairs, device_keys)
            }
            None => Ok(()),
        }
    }

    /// Brings the pairs' contacts (and their keys) to the host's pair cache when the last step
    /// left them on the device (every stage on the GPU). The step does this itself when a
    /// stage on the host needs them; a caller rarely has to.
    pub fn sync_contacts(&mut self) -> Result<(), GpuError> {
        self.fetch_pair_keys()?;
        if !self.contacts_on_device {
            return Ok(());
        }
        let gpu = self
            .gpu
            .as_mut()
            .expect("contacts stay on the device only with GPU stages");
        let contacts = match self.device_contacts.take() {
            Some(contacts) if contacts.len() == self.pairs.len() => contacts,
            _ => gpu.read_pair_contacts()?,
        };
        if contacts.len() != self.pairs.len() {
            // Not one contact per pair: a bug, reported rather than copied in part.
            return Err(GpuError::Readback {
                what: "pair contacts",
                reason: format!("{} contacts for {} pairs", contacts.len(), self.pairs.len()),
            });
        }
        self.pairs.values_mut().copy_from_slice(&contacts);
        gpu.pair_cache_adopted(self.pairs.version());
        self.contacts_on_device = false;
        Ok(())
    }

    /// Child contacts (per triangle of a mesh) as (body A, body B, triangle, pair data), in
    /// child order: what [`contacts`](Self::contacts) is for pairs without a mesh.
    pub fn child_contacts(
        &self,
    ) -> impl Iterator<Item = (BodyHandle, BodyHandle, u32, &PairContact)> + '_ {
        self.children
            .keys()
            .iter()
            .zip(self.children.values())
            .map(|(&(key, child), contact)| {
                let (a, b) = crate::stages::pairs::pair_bodies(key);
                (self.handle_of(a), self.handle_of(b), child, contact)
            })
    }

    /// Seeds the warm-start impulses of a pair (used when loading a dumped scene, so the run
    /// continues bitwise). With a valid cache ([`ManifoldCache`]) the next step may move these
    /// points with the bodies; otherwise it computes the manifold, and points keep these
    /// impulses where their feature ids match.
    pub fn restore_contact(
        &mut self,
        a: BodyHandle,
        b: BodyHandle,
        contact: PairContact,
    ) -> Result<(), BodyError> {
        let (key, contact) = self.pair_ordered(a, b, contact)?;
        self.sync_contacts()
            .map_err(|error| BodyError::ContactsReadback(error.to_string()))?;
        self.pairs.insert(key, contact);
        Ok(())
    }

    /// [`restore_contact`](Self::restore_contact) for the child manifold of triangle `child`.
    pub fn restore_child_contact(
        &mut self,
        a: BodyHandle,
        b: BodyHandle,
        child: u32,
        contact: PairContact,
    ) -> Result<(), BodyError> {
        let (key, contact) = self.pair_ordered(a, b, contact)?;
        self.children.insert((key, child), contact);
        Ok(())
    }

    /// The pair key of (a, b) and the contact as the cache keeps it, from the lower index.
    fn pair_ordered(
        &self,
        a: BodyHandle,
        b: BodyHandle,
        mut contact: PairContact,
    ) -> Result<(u64, PairContact), BodyError> {
        let (ia, ib) = (self.check(a)?, self.check(b)?);
        let key = crate::stages::pairs::pair_key(ia as u32, ib as u32);
        if ia > ib {
            // The cache keeps the pair as (lower, higher): flip the normal and move the anchors
            // into the other body's frame.
            contact.manifold = contact.manifold.flipped();
            let (poses, _) = self.current_bodies().map_err(BodyError::readback)?;
            let (from, to) = (poses[ia].transform(), poses[ib].transform());
            let count = contact.manifold.count as usize;
            for point in &mut contact.manifold.points[..count] {
                point.anchor = to.inverse_transform_point(from.transform_point(point.anchor));
            }
            // The cache is of the other order: the next step computes the points.
            contact.cache = ManifoldCache::default();
        }
        Ok((key, contact))
    }

    pub(crate) fn handle_of(&self, index: u32) -> BodyHandle {
        BodyHandle {
            index,
            generation: self.slots[index as usize].generation,
        }
    }

    fn check(&self, handle: BodyHandle) -> Result<usize, BodyError> {
        match self.slots.get(handle.index as usize) {
            Some(slot) if slot.generation == handle.generation && slot.state != SlotState::Free => {
                Ok(handle.index as usize)
            }
            _ => Err(BodyError::StaleHandle),
        }
    }
}

/// [`World::fetch_pair_keys`] on the world's parts, for a step that holds others borrowed:
/// the keys from `device_keys` when a query read them already, else from `gpu` (timed in
/// `profiler`).
pub(crate) fn fetch_pair_keys(
    gpu: &GpuStages,
    profiler: &mut Profiler,
    pairs: &mut PairCache<PairContact>,
    device_keys: &mut OnceLock<Vec<u64>>,
) -> Result<(), GpuError> {
    if pairs.has_keys() {
        return Ok(());
    }
    let keys = match device_keys.take() {
        Some(keys) if keys.len() == pairs.len() => keys,
        _ => gpu.fetch_pair_keys(profiler)?,
    };
    if keys.len() != pairs.len() {
        // Not one key per pair: a bug, reported rather than adopted.
        return Err(GpuError::Readback {
            what: "pair keys",
            reason: format!("{} keys for {} pairs", keys.len(), pairs.len()),
        });
    }
    pairs.fetched_keys(keys);
    Ok(())
}
