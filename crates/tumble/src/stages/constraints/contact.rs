//! Contact rows: per contact point one non-penetration row along the normal and two friction
//! rows along the tangents.
//!
//! A row constrains the relative velocity of the two bodies along a direction `d` at the
//! contact point, with `r_a`, `r_b` the arms from each centre of mass to the point:
//!
//! ```text
//!   C_dot = J v = d·(v_a − v_b) + (r_a × d)·ω_a − (r_b × d)·ω_b
//!   K     = J M⁻¹ Jᵀ = 1/m_a + 1/m_b + (r_a × d)·I_a⁻¹(r_a × d) + (r_b × d)·I_b⁻¹(r_b × d)
//!   Δλ    = −(C_dot − target) / K                 (then clamped, see the solver)
//!   v_a += d Δλ/m_a,  ω_a += I_a⁻¹(r_a × d) Δλ,  v_b −= d Δλ/m_b,  ω_b −= I_b⁻¹(r_b × d) Δλ
//! ```
//!
//! A constraint keeps both bodies' world-frame inverse inertias (symmetric, 24 bytes each). On
//! the device a row is only its `1/K` and impulse: a sweep computes `r × d` from the point's
//! arms and `I⁻¹(r × d)` from the inertia. Storing `I⁻¹(r × d)` per row there (as Bullet's
//! solver does) was 24 bytes a row, 72 a point: the sweeps, bound by what they load, read a
//! two-point constraint in 16 words instead of 23 (on an H100 the pile's sweeps took 2.60 ms
//! a step instead of 2.85). The CPU keeps each row's `I⁻¹(r × d)` (`Row::angular_a`, computed
//! by the same expression): its sweeps run from the cache and are bound by arithmetic, and
//! computing it in every sweep made them 12% slower. The device's solve sweeps compute the
//! `1/K` too, and take the tangents from the normal and the inverse masses from the bodies,
//! rather than load them (`load_header` in `solver.wgsl`: 2.51 → 2.40 ms of sweeps on the
//! pile, 19.1 → 18.0 ms a step at 500k): so a constraint solved there must hold
//! `tangent_basis(normal)` and its bodies' inverse masses, as every built one does. The
//! Jacobians are fixed at the start of the step (Box2D v3 does the same across its sub-steps);
//! only the separation is tracked through the sub-steps, from the bodies' delta positions and
//! rotations:
//!
//! ```text
//!   s = n·((Δp_a + ΔR_a r_a) − (Δp_b + ΔR_b r_b)) + adjusted_separation,
//!   adjusted_separation = s₀ − n·(r_a − r_b)
//! ```
//!
//! Guarantees: constraints come in pair-key order (deterministic); static bodies are
//! [`STATIC_BODY`] and are never written; each row's `mass` is finite (K > 0 because at least
//! one body is dynamic).

use crate::dynamics::body::{BodyMass, BodyPose, BodyVelocity, Collider};
use crate::math::{Mat3, SymmetricMat3, Vec3, tangent_basis};
use crate::pipeline::config::Softness;
use crate::stages::constraints::STATIC_BODY;
use crate::stages::narrowphase::{ChildCache, PairContact};
use crate::stages::pairs::pair_bodies;

// Layout: the structs below are repr(C) + Pod, the arrays both executors build and solve. On the
// device they lie in blocks of lanes, 16-byte words of these fields (`lanes.rs`), converted
// where they cross; `Row` and `Softness` have WGSL twins (`contact_constraint.wgsl`, checked by
// tests/engine/gpu_layout.rs). Each vec3 shares its 16 bytes with a scalar (`anchor_a` +
// `adjusted_separation`, ...) instead of padding wherever a scalar can fill the slot.

/// One scalar constraint direction `d` at one contact point. 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Row {
    /// I_a⁻¹ (r_a × d), world frame: [`ContactConstraint::angular`] of the row's arms, kept
    /// for the CPU's sweeps only. The device does not store it (see the module docs); its
    /// read-back computes it again.
    pub angular_a: Vec3,
    /// Effective mass 1/K (kg).
    pub mass: f32,
    /// I_b⁻¹ (r_b × d), world frame, as `angular_a`.
    pub angular_b: Vec3,
    /// Accumulated impulse (N·s).
    pub impulse: f32,
}
const _: () = assert!(size_of::<Row>() == 32);

/// Rows and solver inputs of one contact point. 144 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ConstraintPoint {
    pub normal: Row,
    pub tangent: [Row; 2],
    /// Arms from the centres of mass to the point at the start of the step (m).
    pub anchor_a: Vec3,
    /// s₀ − n·(r_a − r_b): with the body deltas, gives the current separation (m).
    pub adjusted_separation: f32,
    pub anchor_b: Vec3,
    /// Current separation (m): s₀ here; the solver recomputes it whenever the bodies have moved
    /// and reuses it in the sweeps that see the same positions.
    pub separation: f32,
    /// Normal velocity before the solve (m/s), for restitution.
    pub approach_velocity: f32,
    /// Largest normal impulse applied this step (N·s): restitution applies only to points
    /// that actually pushed.
    pub max_normal_impulse: f32,
    pub _pad: [f32; 2],
}
const _: () = assert!(size_of::<ConstraintPoint>() == 144);

impl ConstraintPoint {
    /// `r_a × d` and `r_b × d`, the arms' moments along `direction`.
    #[inline]
    pub fn arms(&self, direction: Vec3) -> (Vec3, Vec3) {
        (
            self.anchor_a.cross(direction),
            self.anchor_b.cross(direction),
        )
    }
}

/// The rows of one manifold: up to 4 points sharing a normal, bodies and material.
/// 704 bytes here, 432 on the device (`lanes.rs`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ContactConstraint {
    pub body_a: u32,
    pub body_b: u32,
    /// Slot of the manifold, to store impulses back: `0..pairs` index the pair cache's values,
    /// `pairs..` the child cache's (`stages::narrowphase::children`).
    pub pair: u32,
    pub point_count: u32,
    /// Unit normal from B to A.
    pub normal: Vec3,
    pub friction: f32,
    /// The friction directions: `tangent_basis(normal)`.
    pub tangent1: Vec3,
    pub restitution: f32,
    pub tangent2: Vec3,
    pub inverse_mass_a: f32,
    pub inverse_mass_b: f32,
    /// Spring-damper of the position correction: stiffer against static bodies.
    pub softness: Softness,
    /// World-frame inverse inertia of each body at the start of the step (zero for a static
    /// side): a row's `I⁻¹(r × d)`.
    pub inverse_inertia_a: SymmetricMat3,
    pub inverse_inertia_b: SymmetricMat3,
    pub points: [ConstraintPoint; 4],
}
const _: () = assert!(size_of::<ContactConstraint>() == 704);

impl ContactConstraint {
    /// The two friction directions, in the order of the points' `tangent` rows.
    #[inline]
    pub fn tangents(&self) -> [Vec3; 2] {
        [self.tangent1, self.tangent2]
    }

    /// `I_a⁻¹ arm_a` and `I_b⁻¹ arm_b`: what a unit impulse along a row with these arms does
    /// to each body's angular velocity.
    #[inline]
    pub fn angular(&self, (arm_a, arm_b): (Vec3, Vec3)) -> (Vec3, Vec3) {
        (
            self.inverse_inertia_a.mul_vec3(arm_a),
            self.inverse_inertia_b.mul_vec3(arm_b),
        )
    }
}

/// WGSL twins of [`Row`] and [`Softness`], and [`STATIC_BODY`].
pub const CONTACT_CONSTRAINT_WGSL: &str = include_str!("contact_constraint.wgsl");

/// Per-step inputs the constraint rows need besides the manifolds.
pub struct RowInputs<'a> {
    pub poses: &'a [BodyPose],
    pub velocities: &'a [BodyVelocity],
    pub masses: &'a [BodyMass],
    pub colliders: &'a [Collider],
    /// World-frame inverse inertia of every body (zero for static ones).
    pub inverse_inertia: &'a [Mat3],
    /// Softness of contacts between dynamic bodies and against static ones.
    pub softness: Softness,
    pub static_softness: Softness,
}

/// World-frame inverse inertia R I⁻¹ Rᵀ of every body.
pub fn world_inverse_inertia(poses: &[BodyPose], masses: &[BodyMass], out: &mut Vec<Mat3>) {
    use rayon::prelude::*;
    out.resize(poses.len(), Mat3::ZERO);
    out.par_iter_mut()
        .zip(poses.par_iter().zip(masses.par_iter()))
        .with_min_len(1024)
        .for_each(|(inertia, (pose, mass))| *inertia = body_inverse_inertia(pose, mass));
}

/// One body's world-frame inverse inertia, R diag(I⁻¹) Rᵀ (zero for a static body).
pub fn body_inverse_inertia(pose: &BodyPose, mass: &BodyMass) -> Mat3 {
    let r = Mat3::from_quat(pose.rotation);
    r * Mat3::from_diagonal(mass.inverse_inertia) * r.transpose()
}

/// CPU executor: rows of every manifold with points, pairs in pair order and then children in
/// child order; child `i` gets slot `contacts.len() + i`.
pub fn build_constraints(
    keys: &[u64],
    contacts: &[PairContact],
    children: &ChildCache,
    inputs: &RowInputs,
    out: &mut Vec<ContactConstraint>,
) {
    out.clear();
    out.extend(
        constraint_slots(keys, contacts, children, inputs.masses)
            .map(|(slot, key, contact)| build_constraint(slot, key, contact, inputs)),
    );
}

/// The manifold slots that get a constraint, in constraint order: (slot, pair key, manifold).
/// Both executors build exactly these (rows.wgsl's `has_constraint` is the GPU's twin).
pub fn constraint_slots<'a>(
    keys: &'a [u64],
    contacts: &'a [PairContact],
    children: &'a ChildCache,
    masses: &'a [BodyMass],
) -> impl Iterator<Item = (u32, u64, &'a PairContact)> + 'a {
    let child_pairs = children.keys().iter().map(|&(key, _)| key);
    let all_keys = keys.iter().copied().chain(child_pairs);
    let all_contacts = contacts.iter().chain(children.values());
    all_contacts
        .zip(all_keys)
        .enumerate()
        .filter(move |&(_, (contact, key))| has_constraint(key, contact.manifold.count, masses))
        .map(|(slot, (contact, key))| (slot as u32, key, contact))
}

/// Whether the manifold of pair `key` with `point_count` points gets a constraint: not
/// without points, nor between two sleeping bodies (or one asleep on a static one).
pub fn has_constraint(key: u64, point_count: u32, masses: &[BodyMass]) -> bool {
    let (a, b) = pair_bodies(key);
    let resting = |body: u32| masses[body as usize].inverse_mass == 0.0;
    point_count > 0 && !(resting(a) && resting(b))
}

/// The bodies a constraint on the pair `key` moves: [`STATIC_BODY`] for a side without mass.
pub fn constraint_bodies(key: u64, masses: &[BodyMass]) -> (u32, u32) {
    let (a, b) = pair_bodies(key);
    let moving = |body: u32| {
        if masses[body as usize].inverse_mass > 0.0 {
            body
        } else {
            STATIC_BODY
        }
    };
    (moving(a), moving(b))
}

fn build_constraint(
    pair: u32,
    key: u64,
    contact: &PairContact,
    inputs: &RowInputs,
) -> ContactConstraint {
    let (a, b) = pair_bodies(key);
    let (ia, ib) = (a as usize, b as usize);
    let mass_a = inputs.masses[ia].inverse_mass;
    let mass_b = inputs.masses[ib].inverse_mass;
    let collider_a = &inputs.colliders[ia];
    let collider_b = &inputs.colliders[ib];
    let normal = contact.manifold.normal;
    let (t1, t2) = tangent_basis(normal);
    let against_static = mass_a == 0.0 || mass_b == 0.0;
    let (body_a, body_b) = constraint_bodies(key, inputs.masses);
    let mut constraint = ContactConstraint {
        body_a,
        body_b,
        pair,
        point_count: contact.manifold.count,
        normal,
        friction: (collider_a.friction * collider_b.friction).sqrt(),
        tangent1: t1,
        restitution: collider_a.restitution.max(collider_b.restitution),
        tangent2: t2,
        inverse_mass_a: mass_a,
        inverse_mass_b: mass_b,
        softness: if against_static {
            inputs.static_softness
        } else {
            inputs.softness
        },
        inverse_inertia_a: SymmetricMat3::from_upper(inputs.inverse_inertia[ia]),
        inverse_inertia_b: SymmetricMat3::from_upper(inputs.inverse_inertia[ib]),
        points: [ConstraintPoint::default(); 4],
    };
    let (center_a, center_b) = (inputs.poses[ia].position, inputs.poses[ib].position);
    let (va, vb) = (inputs.velocities[ia], inputs.velocities[ib]);
    for (i, point) in contact.manifold.points().iter().enumerate() {
        let r_a = point.position - center_a;
        let r_b = point.position - center_b;
        let row = |direction: Vec3, impulse: f32| {
            let arms = (r_a.cross(direction), r_b.cross(direction));
            let (angular_a, angular_b) = constraint.angular(arms);
            let k = mass_a + mass_b + arms.0.dot(angular_a) + arms.1.dot(angular_b);
            Row {
                angular_a,
                mass: if k > 0.0 { 1.0 / k } else { 0.0 },
                angular_b,
                impulse,
            }
        };
        let warm = contact.impulses[i];
        let mut constraint_point = ConstraintPoint {
            normal: row(normal, warm.normal),
            tangent: [row(t1, warm.tangent[0]), row(t2, warm.tangent[1])],
            anchor_a: r_a,
            anchor_b: r_b,
            adjusted_separation: point.separation - normal.dot(r_a - r_b),
            separation: point.separation,
            ..ConstraintPoint::default()
        };
        let (arm_a, arm_b) = constraint_point.arms(normal);
        constraint_point.approach_velocity =
            normal.dot(va.linear - vb.linear) + arm_a.dot(va.angular) - arm_b.dot(vb.angular);
        constraint.points[i] = constraint_point;
    }
    constraint
}
