//! Stage 4 on the GPU, the twin of [`update_contacts`](super::update_contacts) (same cache
//! decisions, pair functions, feature ids and warm-start matching; the WGSL files say how they
//! keep the CPU's decisions): `move.wgsl` moves the cached manifolds, a thread per pair, and
//! lists the other pairs, whose pair functions `collide.wgsl` runs (`narrowphase.wgsl` says
//! why).
//!
//! [`GpuNarrowphase::encode`] works on device-resident arrays: this step's sorted pair keys,
//! the map from each pair to its index in last step's contacts (or [`NEW_PAIR`]), last step's
//! contacts and the bodies; it writes this step's contacts, parallel to the keys, in a second
//! array (a buffer cannot be read and written by one dispatch, so the pipeline alternates two).
//! [`GpuNarrowphase::update_contacts`] has the CPU function's signature, for parity tests and
//! for running this stage on the GPU between CPU stages.
//!
//! # Agreement with the CPU
//!
//! The kernel computes every expression of the CPU code in glam's operation order, in f32, so
//! each discrete choice (an axis, a face, a clip side, a feature id, a point kept by
//! `reduce`) is the CPU's wherever the compared values differ by more than rounding.
//! Rounding itself may differ: WGSL lets a driver fuse `a * b + c`, and division, square root
//! and the builtins carry a few ulps of slack (on lavapipe and llvmpipe, 95 % of manifolds
//! come out bitwise equal to the CPU's and the rest within an ulp or two). Where geometry makes two
//! values equal in exact arithmetic, the CPU rules decide without rounding:
//!
//! - box–box prefers faces to edges and one box's face to the other's only when clearly
//!   better (relative and absolute slack), so stacked boxes agree;
//! - `reduce` treats scores within [`REDUCE_TIE_RELATIVE`] as equal (lower index wins): the
//!   corners of a box face tie exactly (depths are compared strictly: see `reduce`);
//! - clipping counts a vertex on a side plane as inside, and axis-aligned inputs (stacked
//!   boxes, boxes on planes) are computed exactly on both sides, fused or not.
//!
//! What remains rounding-sensitive, on both executors alike, are exact comparisons between
//! values that are equal only by coincidence of the input: the largest of a box's three face
//! separations, the incident face when two faces are equally anti-parallel (a box edge down
//! at exactly 45°), the margin test of a point exactly at `margin`, and `MATCH_DISTANCE` or
//! equal anchor distances in the warm-start matching. A driver that rounds differently may
//! pick the other of two equally good answers there. (Lavapipe through Vulkan and llvmpipe
//! through GL agreed with the CPU on all of 300 000 random pairs and on the tests' ties.)
//!
//! # Hulls
//!
//! Box–hull, hull–hull, hull–plane, sphere–hull and capsule–hull pairs run
//! `contact_hull.wgsl`, the twin of `collision/contact/hull.rs`: the polyhedra come from one
//! word array, [`pack_hulls`], packed when the colliders change and read from storage wherever
//! an index is a variable; only the clipped polygon and its candidate points (up to
//! `2 * MAX_HULL_FACE_VERTICES`) are private arrays, and hull–plane reduces the hull's vertices
//! streaming, so a hull of any vertex count needs no more.
//!
//! Sphere– and capsule–hull use no GJK, on either executor: the separating-axis test for
//! overlapping cores and the nearest face or edge for cores apart, loops over the hull's faces
//! and edges with no state carried between them, so f32 on the GPU decides as the CPU does
//! (on lavapipe, all 3258 random pairs of the parity test came out bitwise equal). A WGSL GJK against the CPU's
//! (whose simplex arithmetic is f64, which baseline WGSL lacks) stopped up to 10 % short on
//! prisms and barrels, where parallel faces make simplices degenerate and a fused
//! multiply-add sends f32 down another path; see `hull.rs`.

use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};

use std::mem::offset_of;

use super::{
    CACHE_TOLERANCE, MATCH_DISTANCE, MAX_HULL_FACE_VERTICES, ManifoldCache, NarrowphaseInputs,
    PAIR_CONTACT_WGSL, PairContact, PointImpulse,
};
use crate::collision::contact::hull::{self, BoxPolyhedron, Polyhedron};
use crate::collision::contact::wgsl_constants;
use crate::collision::manifold::{
    ContactPoint, MAX_MANIFOLD_POINTS, Manifold, REDUCE_TIE_RELATIVE,
};
use crate::dynamics::body::{BODY_WGSL, BodyPose, BodyVelocity, Collider, ColliderData};
use crate::gpu::buffer::GpuVec;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::kernel::{
    Binding, Dispatch, Kernel, LastTwo, Source, UniformSlots, WORKGROUP_SIZE, encode_all,
    workgroups_for,
};
use crate::math::Vec3;
use crate::shape::{Cuboid, Shape, ShapeKind};

/// `old_index` of a pair that did not exist last step: it starts with no impulses.
pub const NEW_PAIR: u32 = u32::MAX;

/// Parameters, keys, old index, old contacts, poses, velocities, colliders, skipped, hulls,
/// contacts, the list of pairs left to the pair functions.
const BINDINGS: [Binding; 11] = [
    Binding::Uniform,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageRead,
    Binding::StorageReadWrite,
    Binding::StorageReadWrite,
];

/// Mirrors `NarrowphaseParams` in `narrowphase.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct NarrowphaseParams {
    pub pair_count: u32,
    pub skipped_count: u32,
    /// Speculative distance at rest (m).
    pub margin: f32,
    /// Step length (s).
    pub dt: f32,
}
const _: () = assert!(size_of::<NarrowphaseParams>() == 16);

/// Words of a packed polyhedron's header: its vertex, face and edge counts.
const HULL_HEADER_WORDS: u32 = 3;
/// Words of a packed face: normal (3), offset, first loop entry, loop length.
const HULL_FACE_WORDS: u32 = 6;
/// Words of a packed edge: its two vertices, then its two faces.
const HULL_EDGE_WORDS: u32 = 4;

/// The polyhedra of the hull pairs, as the kernel reads them (`contact_hull.wgsl`): one array of
/// words, f32 values stored by their bits. First the unit box as a polyhedron (a box pair
/// scales its vertices by the half extents), then a directory with one word per collider (the
/// word where its hull's record starts; 0 for other shapes), then the records of the distinct
/// hulls in collider order, equal hulls once (a world gives each body its own copy of a hull
/// that is not centred on its principal axes). A record is the header, the vertices (3 words
/// each), faces, edges and face loops, in [`ConvexHull`](crate::shape::ConvexHull)'s order, so that indices and feature
/// ids are the CPU's.
///
/// Depends only on the colliders: pack it again when they change.
pub fn pack_hulls(colliders: &[Collider], words: &mut Vec<u32>) {
    words.clear();
    let unit_box = BoxPolyhedron::new(&Cuboid {
        half_extents: Vec3::ONE,
    });
    pack_polyhedron(unit_box.view(), words);
    debug_assert_eq!(words.len(), box_record_words());
    let directory = words.len();
    words.resize(directory + colliders.len(), 0);
    let mut packed: HashMap<Vec<u32>, u32> = HashMap::new();
    let mut record = Vec::new();
    for (slot, collider) in colliders.iter().enumerate() {
        if let Shape::ConvexHull(hull) = &collider.shape {
            record.clear();
            pack_polyhedron(Polyhedron::of_hull(hull), &mut record);
            // A table past 2^32 words (16 GiB) fails its upload with a typed error
            // (`BufferTooLarge`) before any kernel reads the saturated offsets.
            let next = u32::try_from(words.len()).unwrap_or(u32::MAX);
            let start = *packed.entry(record.clone()).or_insert_with(|| {
                words.extend_from_slice(&record);
                next
            });
            words[directory + slot] = start;
        }
    }
}

fn pack_polyhedron(polyhedron: Polyhedron, words: &mut Vec<u32>) {
    let (vertices, faces, face_vertices, edges) = polyhedron.parts();
    let count = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    words.extend([
        count(vertices.len()),
        count(faces.len()),
        count(edges.len()),
    ]);
    for vertex in vertices {
        words.extend(vertex.to_array().map(f32::to_bits));
    }
    for face in faces {
        words.extend(face.normal.to_array().map(f32::to_bits));
        words.extend([face.offset.to_bits(), face.first, face.count]);
    }
    for edge in edges {
        words.extend(edge.vertices);
        words.extend(edge.faces);
    }
    words.extend_from_slice(face_vertices);
}

/// Words of the unit box's record: 8 vertices, 6 faces, 12 edges, 24 loop entries.
const fn box_record_words() -> usize {
    (HULL_HEADER_WORDS + 8 * 3 + 6 * HULL_FACE_WORDS + 12 * HULL_EDGE_WORDS + 24) as usize
}

/// The kinds of shape in `colliders`, bit k for [`ShapeKind`](crate::shape::ShapeKind) k: the
/// narrowphase kernel for them ([`wgsl`]) holds only their pair functions.
pub fn shape_kinds(colliders: &[Collider]) -> u32 {
    colliders.iter().fold(0, |kinds, collider| {
        kinds | 1 << collider.shape.kind() as u32
    })
}

/// The most candidate points a pair function of the kernel for `shape_kinds` finds: a hull's
/// clipped incident face, or else the 8 vertices of a box (box–plane) or of its clipped face
/// (box–box). The candidates are a private array of each thread, which the drivers keep in
/// memory rather than registers: with room for 32 in a box world, NVIDIA reported 3136 bytes
/// of local memory for the kernel (its statistic less a flag bit), with 8 1600, and the settled 100k pile's contact kernels
/// 1.47 ms a step instead of 1.82 (an H100, `kernel_stats` and `scripts/device-check.sh`).
fn max_candidates(shape_kinds: u32) -> u32 {
    if shape_kinds & 1 << ShapeKind::ConvexHull as u32 != 0 {
        2 * MAX_HULL_FACE_VERTICES
    } else {
        8
    }
}

/// The 16-byte word of [`PairContact`] at which `offset` (bytes) starts.
const fn contact_word(offset: usize) -> u32 {
    assert!(
        offset.is_multiple_of(16),
        "a field of the word view starts a word"
    );
    (offset / 16) as u32
}
const CONTACT_WORDS: u32 = contact_word(size_of::<PairContact>());
const POINTS_WORD: u32 =
    contact_word(offset_of!(PairContact, manifold) + offset_of!(Manifold, points));
const IMPULSES_WORD: u32 = contact_word(offset_of!(PairContact, impulses));
const CACHE_WORD: u32 = contact_word(offset_of!(PairContact, cache));
// `move.wgsl` reads the rest of the layout within the words: the normal and count, a point's
// two words, the cache's four.
const _: () = {
    assert!(offset_of!(Manifold, normal) == 0 && offset_of!(Manifold, count) == 12);
    assert!(size_of::<ContactPoint>() == 32 && offset_of!(ContactPoint, separation) == 12);
    assert!(offset_of!(ContactPoint, anchor) == 16 && offset_of!(ContactPoint, id) == 28);
    assert!(IMPULSES_WORD == POINTS_WORD + 2 * MAX_MANIFOLD_POINTS as u32);
    // Point k's impulses end within the first ⌈3(k + 1)/4⌉ words of them.
    assert!(size_of::<PointImpulse>() == 12);
    assert!(offset_of!(ManifoldCache, margin) == 12 && offset_of!(ManifoldCache, rotation) == 16);
    assert!(offset_of!(ManifoldCache, normal) == 32 && offset_of!(ManifoldCache, valid) == 44);
    assert!(offset_of!(ManifoldCache, separations) == 48);
    assert!(CACHE_WORD + 4 == CONTACT_WORDS);
};

/// The source of the kernels that clear the list and move the cached manifolds (`move.wgsl`):
/// body and contact structs and the stage's bindings, without the pair functions.
pub fn move_wgsl() -> Source {
    let source = Source::new()
        .constant_f32("CACHE_TOLERANCE", CACHE_TOLERANCE)
        .constant_u32("CONTACT_WORDS", CONTACT_WORDS)
        .constant_u32("POINTS_WORD", POINTS_WORD)
        .constant_u32("IMPULSES_WORD", IMPULSES_WORD)
        .constant_u32("CACHE_WORD", CACHE_WORD)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("narrowphase.wgsl", include_str!("narrowphase.wgsl"))
        .snippet("move.wgsl", include_str!("move.wgsl"));
    // SAFETY: every loop was read for it (session 29): counted ones and a binary search.
    unsafe { source.every_loop_ends() }
}

/// Threads per workgroup of `update_contacts`, and the most workgroups it is dispatched with
/// (a thread then takes every so many listed pairs). Launching the heavy kernel (108
/// registers, 1.5 KB of local memory a thread) over the whole capacity cost more than its work
/// on a settled pile of 100k boxes, whose 730k slots list about 800 pairs a step: on an H100
/// it took 0.206 ms with a workgroup of 256 per 256 slots, 0.074 with 256 such workgroups, and
/// 0.068 with these (4096 of 32, which also took falling-boxes' contacts pass at 3k from 0.088
/// to 0.078 ms).
const PAIR_FUNCTION_WORKGROUP: u32 = 32;
const PAIR_FUNCTION_GROUPS: u32 = 4096;

/// The source of the pair functions' kernel for a world of the shape kinds `shape_kinds`
/// ([`shape_kinds`]): body and contact structs, the stage's bindings, the pair functions.
pub fn wgsl(shape_kinds: u32) -> Source {
    let source = wgsl_constants(Source::new())
        .constant_u32("SHAPE_KINDS", shape_kinds)
        .constant_f32("MATCH_DISTANCE", MATCH_DISTANCE)
        .constant_f32("CACHE_TOLERANCE", CACHE_TOLERANCE)
        .constant_f32("REDUCE_TIE_RELATIVE", REDUCE_TIE_RELATIVE)
        .constant_u32("HULL_HEADER_WORDS", HULL_HEADER_WORDS)
        .constant_u32("HULL_FACE_WORDS", HULL_FACE_WORDS)
        .constant_u32("HULL_EDGE_WORDS", HULL_EDGE_WORDS)
        .constant_u32("HULL_DIRECTORY", box_record_words() as u32)
        .constant_u32("MAX_HULL_FACE_VERTICES", MAX_HULL_FACE_VERTICES)
        .constant_u32("MAX_CANDIDATES", max_candidates(shape_kinds))
        .constant_u32("PAIR_FUNCTION_WORKGROUP", PAIR_FUNCTION_WORKGROUP)
        .constant_f32("CAPSULE_FACE_COS_SQUARED", hull::CAPSULE_FACE_COS_SQUARED)
        .snippet("body.wgsl", BODY_WGSL)
        .snippet("pair_contact.wgsl", PAIR_CONTACT_WGSL)
        .snippet("contact_common.wgsl", include_str!("contact_common.wgsl"))
        .snippet("contact_round.wgsl", include_str!("contact_round.wgsl"))
        .snippet("contact_box_box.wgsl", include_str!("contact_box_box.wgsl"))
        .snippet("contact_hull.wgsl", include_str!("contact_hull.wgsl"))
        .snippet("narrowphase.wgsl", include_str!("narrowphase.wgsl"))
        .snippet("collide.wgsl", include_str!("collide.wgsl"));
    // SAFETY: every loop was read for it (session 29): the pair functions' count up to bounds
    // their bodies do not move, the binary search shrinks, and the listed pairs' stride stops
    // before it could wrap.
    unsafe { source.every_loop_ends() }
}

/// The stage's device-resident inputs.
pub struct GpuNarrowphaseInputs<'a> {
    /// This step's sorted pair keys ([`pair_key`](crate::stages::pairs::pair_key)).
    pub keys: &'a GpuVec<u64>,
    /// Per pair, its index in `old_contacts`, or [`NEW_PAIR`].
    pub old_index: &'a GpuVec<u32>,
    /// Last step's contacts, with the impulses the solver wrote into them.
    pub old_contacts: &'a GpuVec<PairContact>,
    pub poses: &'a GpuVec<BodyPose>,
    pub velocities: &'a GpuVec<BodyVelocity>,
    pub colliders: &'a GpuVec<ColliderData>,
    /// The colliders' hulls, packed by [`pack_hulls`].
    pub hulls: &'a GpuVec<u32>,
    /// Sorted keys of pairs that get no contacts (bodies joined by a joint).
    pub skipped: &'a GpuVec<u64>,
    /// Speculative distance at rest (m).
    pub margin: f32,
    /// Step length (s).
    pub dt: f32,
    /// The kinds of shape of `colliders` ([`shape_kinds`]).
    pub shape_kinds: u32,
}

/// What the recorded dispatches were built for: the buffers they bind, their parameters and
/// the shape kinds of their kernels.
type DispatchKey = ([wgpu::Buffer; 10], NarrowphaseParams, u32);

/// The stage's three kernels (`narrowphase.wgsl` says what each does).
struct Kernels {
    clear_misses: Kernel,
    move_cached: Kernel,
    update_contacts: Kernel,
}

/// The stage's recorded dispatches, in order, and the uniform slots their bind groups point
/// into.
type Recorded = LastTwo<DispatchKey, ([Dispatch; 3], UniformSlots)>;

/// Host copies of [`GpuNarrowphase::update_contacts`]'s inputs, kept between calls.
struct HostBuffers {
    keys: GpuVec<u64>,
    old_index: GpuVec<u32>,
    old_contacts: GpuVec<PairContact>,
    poses: GpuVec<BodyPose>,
    velocities: GpuVec<BodyVelocity>,
    colliders: GpuVec<ColliderData>,
    hulls: GpuVec<u32>,
    skipped: GpuVec<u64>,
    contacts: GpuVec<PairContact>,
    /// `Collider::data` of the colliders, rebuilt in place each call.
    collider_data: Vec<ColliderData>,
    /// [`pack_hulls`] of the colliders, rebuilt in place each call.
    hull_words: Vec<u32>,
    /// The downloaded contacts, before they are copied into the caller's slice.
    downloaded: Vec<PairContact>,
}

/// The GPU narrowphase: its kernels, the dispatches recorded for the current buffers, the list
/// of pairs left to the pair functions, and the buffers of
/// [`update_contacts`](Self::update_contacts).
pub struct GpuNarrowphase {
    /// The kernels for the shape kinds they were built for, built again when they change.
    kernels: Option<(u32, Kernels)>,
    /// The uniform slots live as long as the dispatches whose bind groups point into them.
    cached: Recorded,
    /// The pairs left to the pair functions: a count, then pair indices.
    misses: Option<GpuVec<u32>>,
    /// The list's count as [`Self::read_computed`] reads it back (scratch kept between steps).
    miss_count: Vec<u32>,
    host: Option<HostBuffers>,
}

impl Default for GpuNarrowphase {
    fn default() -> Self {
        Self::new()
    }
}

impl GpuNarrowphase {
    /// The stage with no kernels yet: the first encode builds those for its shape kinds.
    pub fn new() -> Self {
        Self {
            kernels: None,
            cached: Recorded::default(),
            misses: None,
            miss_count: Vec::new(),
            host: None,
        }
    }

    /// Encodes the download of how many pairs the pair functions computed in the last encoded
    /// pass (the others moved their manifolds with the bodies, or have none), for
    /// [`Self::read_computed`] after the submission.
    pub fn encode_computed_download(
        &mut self,
        context: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let misses = misses_buffer(&mut self.misses, context)?;
        // The list's count, its first word.
        misses.encode_download_prefix(context, encoder, 1);
        Ok(())
    }

    /// The list of the pairs the last encoded step computed, whose first word is their count:
    /// for a stage that reads that back with its own counts.
    pub fn computed_list(&mut self, context: &GpuContext) -> Result<&GpuVec<u32>, GpuError> {
        misses_buffer(&mut self.misses, context).map(|misses| &*misses)
    }

    /// The count [`Self::encode_computed_download`] copied.
    pub fn read_computed(&mut self, context: &GpuContext) -> Result<usize, GpuError> {
        let misses = misses_buffer(&mut self.misses, context)?;
        misses.read_download(context, &mut self.miss_count)?;
        Ok(self.miss_count.first().map_or(0, |&count| count as usize))
    }

    /// Records the stage into `pass`: `contacts` (resized to the pair count) gets this step's
    /// contacts, parallel to `inputs.keys`. `contacts` must not be `inputs.old_contacts`.
    pub fn encode(
        &mut self,
        context: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        inputs: &GpuNarrowphaseInputs,
        contacts: &mut GpuVec<PairContact>,
    ) -> Result<(), GpuError> {
        let kernels = kernels_for(&mut self.kernels, context, inputs.shape_kinds);
        let misses = misses_buffer(&mut self.misses, context)?;
        encode_with(
            &mut self.cached,
            kernels,
            context,
            pass,
            inputs,
            (contacts, misses),
        )
    }

    /// [`update_contacts`](super::update_contacts) on the GPU: uploads the inputs (`contacts`
    /// holds last step's contacts of the same keys), runs the kernel and downloads the result
    /// into `contacts`. Returns how many pairs the pair functions computed.
    pub fn update_contacts(
        &mut self,
        context: &GpuContext,
        keys: &[u64],
        contacts: &mut [PairContact],
        inputs: &NarrowphaseInputs,
    ) -> Result<usize, GpuError> {
        assert_eq!(keys.len(), contacts.len(), "one contact per key");
        let host = match &mut self.host {
            Some(host) => host,
            empty => empty.insert(HostBuffers {
                keys: GpuVec::with_capacity(context, "narrowphase keys", 0)?,
                old_index: GpuVec::with_capacity(context, "narrowphase old index", 0)?,
                old_contacts: GpuVec::with_capacity(context, "narrowphase old contacts", 0)?,
                poses: GpuVec::with_capacity(context, "narrowphase poses", 0)?,
                velocities: GpuVec::with_capacity(context, "narrowphase velocities", 0)?,
                colliders: GpuVec::with_capacity(context, "narrowphase colliders", 0)?,
                hulls: GpuVec::with_capacity(context, "narrowphase hulls", 0)?,
                skipped: GpuVec::with_capacity(context, "narrowphase skipped", 0)?,
                contacts: GpuVec::with_capacity(context, "narrowphase contacts", 0)?,
                collider_data: Vec::new(),
                hull_words: Vec::new(),
                downloaded: Vec::new(),
            }),
        };
        host.keys.upload(context, keys)?;
        // `contacts[i]` is last step's contact of `keys[i]`: the identity map, which only
        // changes with the pair count.
        if host.old_index.len() != keys.len() {
            let count = u32::try_from(keys.len()).expect("pair count fits in u32");
            host.old_index
                .upload(context, &(0..count).collect::<Vec<u32>>())?;
        }
        host.old_contacts.upload(context, contacts)?;
        host.poses.upload(context, inputs.poses)?;
        host.velocities.upload(context, inputs.velocities)?;
        host.collider_data.clear();
        host.collider_data
            .extend(inputs.colliders.iter().map(|collider| collider.data()));
        host.colliders.upload(context, &host.collider_data)?;
        pack_hulls(inputs.colliders, &mut host.hull_words);
        host.hulls.upload(context, &host.hull_words)?;
        host.skipped.upload(context, inputs.skipped)?;

        let mut encoder = context
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("narrowphase"),
            });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("narrowphase"),
                timestamp_writes: None,
            });
            let device_inputs = GpuNarrowphaseInputs {
                keys: &host.keys,
                old_index: &host.old_index,
                old_contacts: &host.old_contacts,
                poses: &host.poses,
                velocities: &host.velocities,
                colliders: &host.colliders,
                hulls: &host.hulls,
                skipped: &host.skipped,
                margin: inputs.margin,
                dt: inputs.dt,
                shape_kinds: shape_kinds(inputs.colliders),
            };
            let kernels = kernels_for(&mut self.kernels, context, device_inputs.shape_kinds);
            let misses = misses_buffer(&mut self.misses, context)?;
            encode_with(
                &mut self.cached,
                kernels,
                context,
                &mut pass,
                &device_inputs,
                (&mut host.contacts, misses),
            )?;
        }
        // The count of pairs computed, with the contacts (`encode_computed_download`).
        misses_buffer(&mut self.misses, context)?.encode_download_prefix(context, &mut encoder, 1);
        context.queue.submit([encoder.finish()]);
        host.contacts.download_into(context, &mut host.downloaded)?;
        contacts.copy_from_slice(&host.downloaded);
        contacts.iter_mut().for_each(PairContact::clear_unused);
        self.read_computed(context)
    }
}

/// The kernels in `slot` when they were built for `shape_kinds`, else new ones there: a world
/// that gains a kind of shape compiles others.
fn kernels_for<'a>(
    slot: &'a mut Option<(u32, Kernels)>,
    context: &GpuContext,
    shape_kinds: u32,
) -> &'a Kernels {
    if slot.as_ref().is_none_or(|(kinds, _)| *kinds != shape_kinds) {
        let kernel = |source, entry| Kernel::new(context, "narrowphase", source, entry, &BINDINGS);
        let moving = move_wgsl();
        let kernels = Kernels {
            clear_misses: kernel(&moving, "clear_misses"),
            move_cached: kernel(&moving, "move_cached"),
            update_contacts: kernel(&wgsl(shape_kinds), "update_contacts"),
        };
        *slot = Some((shape_kinds, kernels));
    }
    let Some((_, kernels)) = slot else {
        unreachable!("built above")
    };
    kernels
}

/// The list of missed pairs, made on first use (its size follows the pair count).
fn misses_buffer<'a>(
    slot: &'a mut Option<GpuVec<u32>>,
    context: &GpuContext,
) -> Result<&'a mut GpuVec<u32>, GpuError> {
    if slot.is_none() {
        *slot = Some(GpuVec::with_capacity(context, "narrowphase misses", 1)?);
    }
    Ok(slot.as_mut().expect("made above"))
}

/// [`GpuNarrowphase::encode`] on its parts, so that `update_contacts` can lend its own buffers:
/// `outputs` are the contacts and the list of missed pairs.
fn encode_with(
    cached_dispatches: &mut Recorded,
    kernels: &Kernels,
    context: &GpuContext,
    pass: &mut wgpu::ComputePass<'_>,
    inputs: &GpuNarrowphaseInputs,
    (contacts, misses): (&mut GpuVec<PairContact>, &mut GpuVec<u32>),
) -> Result<(), GpuError> {
    debug_assert_eq!(inputs.keys.len(), inputs.old_index.len());
    contacts.resize(context, inputs.keys.len())?;
    // A count, then room for every pair.
    misses.resize(context, inputs.keys.len() + 1)?;
    let params = NarrowphaseParams {
        pair_count: u32::try_from(inputs.keys.len()).expect("pair count fits in u32"),
        skipped_count: u32::try_from(inputs.skipped.len()).expect("skipped count fits"),
        margin: inputs.margin,
        dt: inputs.dt,
    };
    let key = (
        [
            inputs.keys.buffer().clone(),
            inputs.old_index.buffer().clone(),
            inputs.old_contacts.buffer().clone(),
            inputs.poses.buffer().clone(),
            inputs.velocities.buffer().clone(),
            inputs.colliders.buffer().clone(),
            inputs.hulls.buffer().clone(),
            inputs.skipped.buffer().clone(),
            contacts.buffer().clone(),
            misses.buffer().clone(),
        ],
        params,
        inputs.shape_kinds,
    );
    let (dispatches, _) = cached_dispatches.get_or_insert(key, || {
        let slots = UniformSlots::new(context, "narrowphase params", &[params]);
        let buffers = [
            slots.binding(0),
            inputs.keys.whole(),
            inputs.old_index.whole(),
            inputs.old_contacts.whole(),
            inputs.poses.whole(),
            inputs.velocities.whole(),
            inputs.colliders.whole(),
            inputs.skipped.whole(),
            inputs.hulls.whole(),
            contacts.whole(),
            misses.whole(),
        ];
        let groups = workgroups_for(inputs.keys.len(), WORKGROUP_SIZE);
        let pair_function_groups =
            workgroups_for(inputs.keys.len(), PAIR_FUNCTION_WORKGROUP).min(PAIR_FUNCTION_GROUPS);
        let dispatch =
            |kernel: &Kernel, groups| kernel.dispatch(kernel.bind(context, &buffers), groups);
        let dispatches = [
            dispatch(&kernels.clear_misses, 1),
            dispatch(&kernels.move_cached, groups),
            // Threads past the list's count return at once.
            dispatch(&kernels.update_contacts, pair_function_groups),
        ];
        (dispatches, slots)
    });
    encode_all(pass, dispatches);
    Ok(())
}
