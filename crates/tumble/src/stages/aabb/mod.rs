//! Stage 1: world AABBs of all colliders, grown by the speculative contact margin and swept
//! along the body's motion over the step, so that the broadphase finds every pair the
//! narrowphase could make a contact for this step.
//!
//! Guarantees: `aabbs[i]` encloses body `i`'s shape at its current pose and at its pose moved
//! by `linear_velocity · dt`, expanded by `margin`; slots of removed bodies are left as they are
//! (the broadphase no longer holds them).
//!
//! The GPU executor ([`gpu`]) computes the same boxes on the device, to a few f32 roundings,
//! for spheres, capsules, boxes and planes. A hull, mesh or compound has no vertices there: it
//! gets the turned box of `ColliderData::params` (half extents about the body origin holding
//! the shape), which holds the CPU's box and is as tight when the shape's local box is centred
//! on the origin.

pub mod gpu;

use crate::dynamics::body::{BodyPose, BodyVelocity, Collider};
use crate::math::Aabb;
use rayon::prelude::*;

/// Bodies per rayon task: below this, splitting costs more than it saves.
const MIN_BODIES_PER_TASK: usize = 512;

/// CPU executor: one AABB per body slot.
pub fn compute_aabbs(
    poses: &[BodyPose],
    velocities: &[BodyVelocity],
    colliders: &[Collider],
    margin: f32,
    dt: f32,
    aabbs: &mut Vec<Aabb>,
) {
    aabbs.resize(poses.len(), Aabb::default());
    aabbs
        .par_iter_mut()
        .zip(
            poses
                .par_iter()
                .zip(velocities.par_iter().zip(colliders.par_iter())),
        )
        .with_min_len(MIN_BODIES_PER_TASK)
        .for_each(|(aabb, (pose, (velocity, collider)))| {
            let now = collider.shape.aabb(&pose.transform()).expanded(margin);
            let motion = velocity.linear * dt;
            *aabb = now.union(&Aabb::new(now.min + motion, now.max + motion));
        });
}
