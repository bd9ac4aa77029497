//! Stage 1: world AABBs of all colliders, grown by the speculative contact margin so that the
//! broadphase finds every pair the narrowphase could make a contact for.
//!
//! Guarantees: `aabbs[i]` encloses body `i`'s shape at its current pose, expanded by `margin`;
//! slots of removed bodies are left as they are (the broadphase no longer holds them).

use crate::dynamics::body::{BodyPose, Collider};
use crate::math::Aabb;
use rayon::prelude::*;

/// Bodies per rayon task: below this, splitting costs more than it saves.
const MIN_BODIES_PER_TASK: usize = 512;

/// CPU executor: one AABB per body slot.
pub fn compute_aabbs(
    poses: &[BodyPose],
    colliders: &[Collider],
    margin: f32,
    aabbs: &mut Vec<Aabb>,
) {
    aabbs.resize(poses.len(), Aabb::default());
    aabbs
        .par_iter_mut()
        .zip(poses.par_iter().zip(colliders.par_iter()))
        .with_min_len(MIN_BODIES_PER_TASK)
        .for_each(|(aabb, (pose, collider))| {
            *aabb = collider.shape.aabb(&pose.transform()).expanded(margin)
        });
}
