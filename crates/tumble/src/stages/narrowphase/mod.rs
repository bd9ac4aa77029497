//! Stage 4: contact manifolds for every candidate pair, persistent from step to step.
//!
//! Each step computes a fresh manifold per pair (one-shot, as Box2D does) and matches its points
//! with last step's by feature id; a matched point inherits the impulses the solver accumulated
//! on it, which warm-starts the solver (Bullet's persistent manifolds, the talk's reason for
//! persistent pairs).
//!
//! Guarantees: `contacts[i]` belongs to `keys[i]` = (a, b) with a < b, body A = a, normal from
//! b to a; the result depends only on the poses and last step's manifold, never on thread count.

use crate::collision::contact::collide;
use crate::collision::manifold::{MAX_MANIFOLD_POINTS, Manifold};
use crate::dynamics::body::{BodyPose, Collider};
use crate::stages::pairs::pair_bodies;
use rayon::prelude::*;

/// Impulses the solver accumulated on one contact point (N·s), kept for warm starting.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointImpulse {
    pub normal: f32,
    /// Along the two friction directions of [`crate::math::tangent_basis`] of the normal.
    pub tangent: [f32; 2],
}

/// What a pair keeps from one step to the next.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairContact {
    pub manifold: Manifold,
    /// Impulses of `manifold.points`, index for index.
    pub impulses: [PointImpulse; MAX_MANIFOLD_POINTS],
}

/// Pairs per rayon task.
const MIN_PAIRS_PER_TASK: usize = 64;

/// CPU executor: refresh the manifold of every pair. Pairs listed in `skipped` (sorted keys:
/// bodies joined by a joint) get no contacts.
pub fn update_contacts(
    keys: &[u64],
    contacts: &mut [PairContact],
    poses: &[BodyPose],
    colliders: &[Collider],
    margin: f32,
    skipped: &[u64],
) {
    debug_assert_eq!(keys.len(), contacts.len());
    contacts
        .par_iter_mut()
        .zip(keys.par_iter())
        .with_min_len(MIN_PAIRS_PER_TASK)
        .for_each(|(contact, &key)| {
            if !skipped.is_empty() && skipped.binary_search(&key).is_ok() {
                *contact = PairContact::default();
                return;
            }
            let (a, b) = pair_bodies(key);
            let (a, b) = (a as usize, b as usize);
            let mut manifold = Manifold::default();
            collide(
                &colliders[a].shape,
                &poses[a].transform(),
                &colliders[b].shape,
                &poses[b].transform(),
                margin,
                &mut manifold,
            );
            *contact = carry_impulses(manifold, contact);
        });
}

/// The new manifold with the impulses of last step's points that have the same feature id.
pub fn carry_impulses(manifold: Manifold, old: &PairContact) -> PairContact {
    let mut impulses = [PointImpulse::default(); MAX_MANIFOLD_POINTS];
    for (impulse, point) in impulses.iter_mut().zip(manifold.points()) {
        if let Some(j) = old.manifold.points().iter().position(|o| o.id == point.id) {
            *impulse = old.impulses[j];
        }
    }
    PairContact { manifold, impulses }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::manifold::ContactPoint;
    use crate::math::Vec3;

    #[test]
    fn impulses_follow_feature_ids() {
        let point = |id| ContactPoint {
            position: Vec3::ZERO,
            separation: 0.0,
            id,
        };
        let mut old = PairContact::default();
        old.manifold.push(point(7));
        old.manifold.push(point(3));
        old.impulses[0].normal = 1.0;
        old.impulses[1].normal = 2.0;
        let mut new = Manifold::default();
        new.push(point(3));
        new.push(point(9));
        let carried = carry_impulses(new, &old);
        assert_eq!(carried.impulses[0].normal, 2.0);
        assert_eq!(carried.impulses[1].normal, 0.0);
    }
}
