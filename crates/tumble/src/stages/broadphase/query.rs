//! Queries through both trees of the broadphase, for the world's ray casts and box queries.
//! Candidates come from the proxies' fat AABBs: the caller tests each against the exact shape.

use super::Broadphase;
use crate::math::{Aabb, Vec3};

impl Broadphase {
    /// Calls `visit(body)` for every body whose fat AABB overlaps or touches `aabb`: the moving
    /// tree first, then the fixed one, each in its deterministic order.
    pub fn query(&self, aabb: &Aabb, mut visit: impl FnMut(u32)) {
        for tree in [&self.moving, &self.fixed] {
            tree.query(aabb, |body| {
                visit(body);
                true
            });
        }
    }

    /// Calls `visit(body)` for the bodies whose fat AABB the segment
    /// `origin + t · direction`, `t` in `[0, max_distance]`, meets, with
    /// [`Dbvt::ray_cast`](crate::collision::dbvt::Dbvt::ray_cast)'s clipping contract: `visit`
    /// returns the segment's new end. The end carries from the moving tree into the fixed one.
    /// Boxes are grown by `inflate` (m) first: 0 for a ray, the radius for a sphere cast.
    pub fn ray_cast(
        &self,
        origin: Vec3,
        direction: Vec3,
        max_distance: f32,
        inflate: f32,
        mut visit: impl FnMut(u32) -> f32,
    ) {
        let mut end = max_distance;
        for tree in [&self.moving, &self.fixed] {
            tree.ray_cast_inflated(origin, direction, end, inflate, |body| {
                end = end.min(visit(body));
                end
            });
            if end < 0.0 {
                return;
            }
        }
    }
}
