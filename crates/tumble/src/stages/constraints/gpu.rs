//! GPU executor of the contact rows: [`build_constraints`](super::build_constraints)'s contract
//! for contacts (the joint rows have theirs, [`joint_gpu`](super::joint_gpu)), with the kernels
//! of `rows.wgsl`: flag the slots that get a constraint, scan the flags into places (the CPU's
//! order), build each constraint at its place, in blocks of lanes ([`lanes`]).
//! Three dispatch groups; the constraint count stays on the device (the scan's last entry)
//! until a caller reads it. The threads cover the
//! slots' buffers, the live slots counted in a word on the device: the dispatches are built
//! again only when a buffer grows, not each step the pair count changes (that took 0.1–0.2 ms
//! a step of a 20k pile on the development machine).

use bytemuck::{Pod, Zeroable};

use super::lanes::{self, Word, with_lanes, word_count};
use super::{CONTACT_CONSTRAINT_WGSL, ContactConstraint};
use crate::dynamics::body::{BODY_WGSL, BodyMass, BodyPose, BodyVelocity, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, LastTwo, Source, UniformSlots, WORKGROUP_SIZE, workgroups_for,
};
use crate::gpu::prims::scan::{Scan, ScanKind};
use crate::pipeline::config::Softness;
use crate::stages::narrowphase::{PAIR_CONTACT_WGSL, PairContact};

const WGSL: &str = include_str!("rows.wgsl");
const BINDINGS: [Binding; 11] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
    Binding::StorageRead,
];

/// Mirrors `RowParams` in `rows.wgsl`: each softness as (bias rate, mass scale, impulse
/// scale, unused).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RowParams {
    pub softness: [f32; 4],
    pub static_softness: [f32; 4],
    /// Slots the dispatches cover, at least the live ones.
    pub slots: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

pub fn wgsl() -> Source {
    with_lanes(Source::new())
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("contact_constraint.wgsl", CONTACT_CONSTRAINT_WGSL)
        .snippet("rows.wgsl", WGSL)
}

/// The device inputs of the rows: one key and manifold per slot (pairs, then children), and
/// the body arrays.
pub struct GpuRowInputs<'a> {
    pub keys: &'a GpuVec<u64>,
    pub contacts: &'a GpuVec<PairContact>,
    pub poses: &'a GpuVec<BodyPose>,
    pub velocities: &'a GpuVec<BodyVelocity>,
    pub masses: &'a GpuVec<BodyMass>,
    pub colliders: &'a GpuVec<ColliderData>,
    pub softness: Softness,
    pub static_softness: Softness,
}

/// What the cached dispatches were built for: the buffers bound and the parameters.
type RowKey = ([wgpu::Buffer; 11], usize, [u32; 12]);

#[derive(Debug)]
pub struct GpuRows {
    flags: GpuVec<u32>,
    /// Exclusive scan of the flags: each constraint's place; entry `slots` is the count.
    places: GpuVec<u32>,
    /// One per slot at most; the first `count` are the constraints, in blocks of lanes
    /// ([`lanes`]).
    pub constraints: GpuVec<Word>,
    /// Each constraint's bodies (A, B; [`STATIC_BODY`](super::STATIC_BODY) for a side with no
    /// mass), at the constraint's place: what a batching on the device colors.
    pub bodies: GpuVec<[u32; 2]>,
    scan: Scan,
    /// Word 0: the live slots, sent with each encode.
    live: GpuVec<u32>,
    cached: LastTwo<RowKey, [Dispatch; 2]>,
    host_places: Vec<u32>,
    /// The constraints' words on their way back ([`Self::read_back`]).
    host_words: Vec<Word>,
}

impl GpuRows {
    pub fn new(context: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self {
            flags: GpuVec::with_capacity(context, "row flags", 0)?,
            places: GpuVec::with_capacity(context, "row places", 0)?,
            constraints: GpuVec::with_capacity(context, "contact constraints", 0)?,
            bodies: GpuVec::with_capacity(context, "row bodies", 0)?,
            scan: Scan::new(),
            live: GpuVec::from_slice(context, "live row slots", &[0])?,
            cached: LastTwo::default(),
            host_places: Vec::new(),
            host_words: Vec::new(),
        })
    }

    /// Encodes the rows of every slot of `inputs` into `constraints`: room for `count` of them
    /// when the caller knows that at most that many slots have one, else for one per slot.
    /// The live slots are the keys' length, or, `live_on_device`, the count that
    /// [`Self::encode_live_copy`] copied in before the pass; then `count` is a guess: past
    /// it the build writes wherever the device's bounds checks send it, and the caller checks
    /// the count before it uses the rows.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        inputs: &GpuRowInputs,
        count: Option<usize>,
        live_on_device: bool,
    ) -> Result<(), GpuError> {
        let live = inputs.keys.len();
        let rows = count.unwrap_or(live);
        if !live_on_device {
            debug_assert_eq!(inputs.contacts.len(), live, "one manifold per key");
            debug_assert!(rows <= live, "more rows than manifold slots");
            // Lands before this submission's commands run.
            self.live.upload(context, &[live as u32])?;
        }
        let slots = inputs.keys.capacity().min(inputs.contacts.capacity());
        self.flags.resize(context, slots + 1)?;
        self.places.resize(context, slots + 1)?;
        self.constraints.resize(context, word_count(rows))?;
        self.bodies.resize(context, rows)?;
        let buffers = [
            inputs.keys.buffer().clone(),
            inputs.contacts.buffer().clone(),
            inputs.masses.buffer().clone(),
            inputs.poses.buffer().clone(),
            inputs.velocities.buffer().clone(),
            inputs.colliders.buffer().clone(),
            self.flags.buffer().clone(),
            self.places.buffer().clone(),
            self.constraints.buffer().clone(),
            self.bodies.buffer().clone(),
            self.live.buffer().clone(),
        ];
        let params = RowParams {
            softness: inputs.softness.words(),
            static_softness: inputs.static_softness.words(),
            slots: slots as u32,
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        };
        let words: [u32; 12] = bytemuck::cast(params);
        let key = (buffers, slots, words);
        // Out of `self` while it is filled, since the dispatches are made from `self`.
        let mut cached = std::mem::take(&mut self.cached);
        let [flag, build] = cached
            .get_or_insert(key, || self.dispatches(context, inputs, params))
            .clone();
        self.cached = cached;
        flag.encode(pass);
        self.scan.encode(
            context,
            pass,
            &self.flags,
            &mut self.places,
            ScanKind::Exclusive,
        )?;
        build.encode(pass);
        Ok(())
    }

    /// Encodes the copy of word 0 of `count` (a pair count on the device) into the live slots'
    /// count, for an [`Self::encode`] in a pass after it with `live_on_device`.
    pub fn encode_live_copy(&self, encoder: &mut wgpu::CommandEncoder, count: &GpuVec<u32>) {
        encoder.copy_buffer_to_buffer(count.buffer(), 0, self.live.buffer(), 0, 4);
    }

    fn dispatches(
        &self,
        context: &GpuContext,
        inputs: &GpuRowInputs,
        params: RowParams,
    ) -> [Dispatch; 2] {
        let source = wgsl();
        let slots = UniformSlots::new(context, "row params", &[params]);
        let bind = |entry: &str, places: &GpuVec<u32>| {
            let kernel = Kernel::new(context, &format!("rows {entry}"), &source, entry, &BINDINGS);
            let group = kernel.bind(
                context,
                &[
                    slots.binding(0),
                    inputs.keys.whole(),
                    inputs.contacts.whole(),
                    inputs.masses.whole(),
                    places.whole(),
                    inputs.poses.whole(),
                    inputs.velocities.whole(),
                    inputs.colliders.whole(),
                    self.constraints.whole(),
                    self.bodies.whole(),
                    self.live.whole(),
                ],
            );
            // `flag` also writes the closing 0 past the last slot.
            let threads = params.slots as usize + 1;
            kernel.dispatch(group, workgroups_for(threads, WORKGROUP_SIZE))
        };
        [bind("flag", &self.flags), bind("build", &self.places)]
    }

    /// The manifold slot of each row the last encoded pass built, in row order (after it ran):
    /// from the places, where a slot with a row is one whose place the next slot's passes.
    /// Through a staging buffer of its own, so that a caller holding `&self` can read it.
    pub fn read_slots(&self, context: &GpuContext) -> Result<Vec<u32>, GpuError> {
        let places = self.places.read(context)?;
        let rows = places.windows(2).enumerate();
        let slots = rows.filter(|(_, place)| place[1] > place[0]);
        Ok(slots.map(|(slot, _)| slot as u32).collect())
    }

    /// Reads the built constraints back (after the encoded pass ran) into `out`.
    pub fn read_back(
        &mut self,
        context: &GpuContext,
        out: &mut Vec<ContactConstraint>,
    ) -> Result<(), GpuError> {
        self.places.download_into(context, &mut self.host_places)?;
        let count = self.host_places.last().copied().unwrap_or(0) as usize;
        let words = self.constraints.len();
        // The vector's length becomes the count's blocks, so only the constraints come back.
        self.constraints.resize(context, word_count(count))?;
        let result = self
            .constraints
            .download_into(context, &mut self.host_words);
        self.constraints.resize(context, words)?;
        result?;
        out.clear();
        out.resize(count, ContactConstraint::default());
        lanes::read_back(&self.host_words, out);
        Ok(())
    }
}
