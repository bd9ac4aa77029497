//! Contact manifolds: the output of the narrowphase for one pair of bodies.
//!
//! Conventions (the talk's, DESIGN.md principle 7): `separation > 0` means the surfaces are
//! apart, `< 0` that they overlap; the normal points from body B to body A.

use crate::math::Vec3;

/// Most points a manifold keeps: enough to hold a box flat on a face.
pub const MAX_MANIFOLD_POINTS: usize = 4;

/// One contact point. 32 bytes, repr(C) + Pod with the WGSL layout: the GPU narrowphase
/// writes the same array.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ContactPoint {
    /// World-space point midway between the two surfaces (m).
    pub position: Vec3,
    /// Signed distance of the surfaces along the normal (m): > 0 apart, < 0 overlapping.
    pub separation: f32,
    /// The point in body A's frame (m), set by the narrowphase: last step's points are matched
    /// to this step's by it when feature ids change. Zero as the collision functions leave it.
    pub anchor: Vec3,
    /// Feature id: the same while the same features touch, so the solver's impulses carry over
    /// from one step to the next (warm starting). Unique within a manifold.
    pub id: u32,
}
const _: () = assert!(size_of::<ContactPoint>() == 32);

impl ContactPoint {
    /// A point at `position` (world) with its separation and feature id; no anchor yet.
    pub fn new(position: Vec3, separation: f32, id: u32) -> Self {
        Self {
            position,
            separation,
            anchor: Vec3::ZERO,
            id,
        }
    }
}

/// Up to [`MAX_MANIFOLD_POINTS`] contact points sharing one normal. 144 bytes, WGSL layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Manifold {
    /// Unit normal, from body B to body A.
    pub normal: Vec3,
    pub count: u32,
    pub points: [ContactPoint; MAX_MANIFOLD_POINTS],
}
const _: () = assert!(size_of::<Manifold>() == 144);

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

/// Scores of [`reduce`] (squared distances, areas) within this fraction of the best so far
/// count as equal to it, and the lower index wins. Symmetric candidates (the corners of a box
/// face) have scores equal in exact arithmetic that rounding tells apart, and rounding differs
/// between executors (a GPU may fuse a multiply and an add): with this slack the CPU and the
/// GPU narrowphase keep the same points in the same order.
pub const REDUCE_TIE_RELATIVE: f32 = 1.0e-4;

/// Keeps at most [`MAX_MANIFOLD_POINTS`] of `candidates`, chosen to hold the body as a larger
/// set would: the deepest point (it carries the largest impulse), then the point farthest from
/// it, then the one making the largest triangle with those two, then the one making the
/// largest quadrilateral with the triangle. Distances and areas are measured in the contact
/// plane (perpendicular to the unit `normal`), so depth differences do not count as spread.
///
/// Deterministic: ties (scores within [`REDUCE_TIE_RELATIVE`], equal depths) go to the
/// lower index; the kept points are listed in the order chosen.
/// The result's normal is `normal`. With four candidates or fewer, all are kept in order.
pub fn reduce(candidates: &[ContactPoint], normal: Vec3) -> Manifold {
    let mut manifold = Manifold {
        normal,
        ..Manifold::default()
    };
    if candidates.len() <= MAX_MANIFOLD_POINTS {
        for candidate in candidates {
            manifold.push(*candidate);
        }
        return manifold;
    }

    let mut deepest = 0;
    for (index, candidate) in candidates.iter().enumerate() {
        // Strictly deepest, with no slack for rounding as the scores have: a box sliding over
        // a mesh digs its leading edge in by micrometres, and a 1e-5 m (even 1e-6 m) tie rule
        // that kept a corner by index instead yawed it by 0.02 rad/s against 0.0015
        // (tests/engine/trimesh_floor.rs).
        if candidate.separation < candidates[deepest].separation {
            deepest = index;
        }
    }
    let first = candidates[deepest].position;

    // Squared distance from the first point in the contact plane (m²).
    let farthest = best_index(candidates, &[deepest], |position| {
        let offset = position - first;
        let along_normal = offset.dot(normal);
        offset.length_squared() - along_normal * along_normal
    });
    let second = candidates[farthest].position;

    // Twice the triangle's area projected on the contact plane (m²), either winding.
    let triangle_area = |position: Vec3| (second - first).cross(position - first).dot(normal);
    let widest = best_index(candidates, &[deepest, farthest], |position| {
        triangle_area(position).abs()
    });
    let third = candidates[widest].position;

    // Twice the quadrilateral's signed area, with the fourth point put in each of the three
    // gaps of the triangle; the triangle's winding makes a convex insertion positive. The
    // best gap is the quadrilateral the point would make with the triangle.
    let winding = if triangle_area(third) >= 0.0 {
        1.0
    } else {
        -1.0
    };
    let quadrilateral_area =
        |p0: Vec3, p1: Vec3, p2: Vec3, p3: Vec3| winding * (p2 - p0).cross(p3 - p1).dot(normal);
    let fourth = best_index(candidates, &[deepest, farthest, widest], |position| {
        quadrilateral_area(first, position, second, third)
            .max(quadrilateral_area(first, second, position, third))
            .max(quadrilateral_area(first, second, third, position))
    });

    for index in [deepest, farthest, widest, fourth] {
        manifold.push(candidates[index]);
    }
    manifold
}

/// Index of the candidate not in `taken` with the largest `score` of its position; the lower
/// index on ties (within [`REDUCE_TIE_RELATIVE`]). `candidates` has more entries than `taken`, so there is always one.
fn best_index(candidates: &[ContactPoint], taken: &[usize], score: impl Fn(Vec3) -> f32) -> usize {
    let mut best = usize::MAX;
    let mut best_score = f32::NEG_INFINITY;
    for (index, candidate) in candidates.iter().enumerate() {
        if taken.contains(&index) {
            continue;
        }
        let candidate_score = score(candidate.position);
        if best == usize::MAX
            || candidate_score > best_score + REDUCE_TIE_RELATIVE * best_score.abs()
        {
            best = index;
            best_score = candidate_score;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3;

    fn point(x: f32, z: f32, separation: f32, id: u32) -> ContactPoint {
        ContactPoint::new(vec3(x, 0.0, z), separation, id)
    }

    #[test]
    fn few_candidates_are_kept_as_they_are() {
        let candidates = [point(0.0, 0.0, -0.1, 7), point(1.0, 0.0, 0.0, 3)];
        let manifold = reduce(&candidates, Vec3::Y);
        assert_eq!(manifold.points(), &candidates);
        assert_eq!(manifold.normal, Vec3::Y);
    }

    #[test]
    fn keeps_deepest_then_the_widest_spread() {
        // A regular octagon of radius 1 in the xz plane, with its centre and a point near an
        // edge's middle; vertex 3 is the deepest.
        let mut candidates = Vec::new();
        for index in 0..8 {
            let angle = index as f32 * std::f32::consts::FRAC_PI_4;
            let separation = if index == 3 { -0.02 } else { -0.01 };
            candidates.push(point(angle.cos(), angle.sin(), separation, index));
        }
        candidates.push(point(0.0, 0.0, -0.015, 8));
        candidates.push(point(0.9, 0.3, -0.015, 9));
        let manifold = reduce(&candidates, Vec3::Y);
        let ids: Vec<u32> = manifold.points().iter().map(|point| point.id).collect();
        // Deepest 3, its opposite 7, then the two vertices a quarter turn off: the largest
        // square. 1 and 5 make triangles equal up to rounding: a tie, so 1 comes first.
        assert_eq!(ids, [3, 7, 1, 5]);
    }

    #[test]
    fn spread_ignores_depth_along_the_normal() {
        // Far apart along the normal only: no spread at all in the contact plane.
        let candidates = [
            ContactPoint::new(vec3(0.0, 5.0, 0.0), -0.1, 0),
            point(0.0, 0.0, 0.0, 1),
            point(0.5, 0.0, 0.0, 2),
            point(0.0, 0.5, 0.0, 3),
            point(0.5, 0.5, 0.0, 4),
            point(0.1, 0.1, 0.0, 5),
        ];
        let ids: Vec<u32> = reduce(&candidates, Vec3::Y)
            .points()
            .iter()
            .map(|point| point.id)
            .collect();
        assert_eq!(ids, [0, 4, 2, 3]);
    }

    #[test]
    fn identical_candidates_give_distinct_points() {
        let candidates = [point(1.0, 1.0, 0.0, 0); 6];
        let manifold = reduce(&candidates, Vec3::Y);
        assert_eq!(manifold.count, 4);
    }
}
