//! Contact manifolds: the output of the narrowphase for one pair of bodies.
//!
//! Conventions (the talk's, DESIGN.md principle 7): `separation > 0` means the surfaces are
//! apart, `< 0` that they overlap; the normal points from body B to body A.

use crate::math::Vec3;

/// Most points a manifold keeps: enough to hold a box flat on a face.
pub const MAX_MANIFOLD_POINTS: usize = 4;

/// One contact point, in world space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactPoint {
    /// World-space point midway between the two surfaces (m).
    pub position: Vec3,
    /// Signed distance of the surfaces along the normal (m): > 0 apart, < 0 overlapping.
    pub separation: f32,
    /// Feature id: the same while the same features touch, so the solver's impulses carry over
    /// from one step to the next (warm starting). Unique within a manifold.
    pub id: u32,
}

/// Up to [`MAX_MANIFOLD_POINTS`] contact points sharing one normal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Manifold {
    /// Unit normal, from body B to body A.
    pub normal: Vec3,
    pub points: [ContactPoint; MAX_MANIFOLD_POINTS],
    pub count: u32,
}

impl Manifold {
    pub fn points(&self) -> &[ContactPoint] {
        &self.points[..self.count as usize]
    }

    pub fn clear(&mut self) {
        self.count = 0;
    }

    /// Appends a point; the caller keeps the count within [`MAX_MANIFOLD_POINTS`].
    pub fn push(&mut self, point: ContactPoint) {
        debug_assert!((self.count as usize) < MAX_MANIFOLD_POINTS);
        self.points[self.count as usize] = point;
        self.count += 1;
    }

    /// The same contact seen from the other body: the normal flips, points stay.
    pub fn flipped(mut self) -> Self {
        self.normal = -self.normal;
        self
    }
}
