//! GJK (Gilbert–Johnson–Keerthi): the distance and closest points of two convex shapes, from
//! their support maps alone.
//!
//! # Method
//!
//! Every convex shape here is a *core* (a point, a segment, a box, a hull) swept by a ball of
//! `radius` (a sphere is a point with a radius, a capsule a segment with one). GJK runs on the
//! cores, in A's frame, over the Minkowski difference `M = A - B`: it keeps a simplex of up to
//! four points of `M` and replaces it by the sub-simplex closest to the origin, adding the
//! support point of `M` opposite to the current closest point `v`, until
//!
//! - `|v|² - v·w` (an upper bound on `|v| (|v| - distance)`) falls under a relative tolerance:
//!   `v` is the distance vector (converged);
//! - the new point is already in the simplex, or the grown simplex is no closer (rounding: `v`
//!   is as good as f32 gets; the last simplex is kept);
//! - the simplex is a tetrahedron holding the origin, or `|v|` is below [`OVERLAP_DISTANCE`]:
//!   the cores overlap, and the simplex is handed to EPA or to the sampled depth.
//!
//! Each simplex vertex remembers the support points of A and B it came from, so the closest
//! points on A and B are the same barycentric combination of those.

use crate::math::{Transform, Vec3};
use crate::shape::{Capsule, ConvexHull, Cuboid, Sphere};
use glam::DVec3;

/// Core distance (m) under which the cores count as touching: the normal would be rounding.
pub const OVERLAP_DISTANCE: f32 = 1.0e-5;

/// Relative tolerance of the convergence test `|v|² - v·w <= tolerance · |v|²`: the distance is
/// then within this fraction of its true value.
const RELATIVE_TOLERANCE: f32 = 1.0e-6;

/// More iterations than a polytope of a few hundred vertices needs; a cap against cycling.
const MAX_ITERATIONS: usize = 64;

/// A convex shape as a support map: a core and the radius of the ball swept around it.
pub trait SupportMap {
    /// The point of the core farthest along `direction` (shape frame; any length, non-zero).
    fn support(&self, direction: Vec3) -> Vec3;

    /// Radius of the ball swept around the core (m); 0 for a polytope.
    fn radius(&self) -> f32 {
        0.0
    }
}

impl SupportMap for Sphere {
    fn support(&self, _direction: Vec3) -> Vec3 {
        Vec3::ZERO
    }

    fn radius(&self) -> f32 {
        self.radius
    }
}

impl SupportMap for Capsule {
    fn support(&self, direction: Vec3) -> Vec3 {
        // Ties (a direction across the axis) go to the + end, so the result is deterministic.
        let y = if direction.y >= 0.0 {
            self.half_height
        } else {
            -self.half_height
        };
        Vec3::new(0.0, y, 0.0)
    }

    fn radius(&self) -> f32 {
        self.radius
    }
}

impl SupportMap for Cuboid {
    fn support(&self, direction: Vec3) -> Vec3 {
        Vec3::select(
            direction.cmpge(Vec3::ZERO),
            self.half_extents,
            -self.half_extents,
        )
    }
}

impl SupportMap for ConvexHull {
    fn support(&self, direction: Vec3) -> Vec3 {
        ConvexHull::support(self, direction)
    }
}

/// A point of the Minkowski difference and the support points it is made of (A's frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimplexVertex {
    /// `a - b`.
    pub w: Vec3,
    pub a: Vec3,
    pub b: Vec3,
}

/// The Minkowski difference `A - B` of two placed cores, in A's frame.
pub struct MinkowskiDifference<'a, A: ?Sized, B: ?Sized> {
    pub a: &'a A,
    pub b: &'a B,
    /// B's frame in A's frame.
    pub b_in_a: Transform,
}

impl<'a, A: SupportMap + ?Sized, B: SupportMap + ?Sized> MinkowskiDifference<'a, A, B> {
    pub fn new(a: &'a A, pose_a: &Transform, b: &'a B, pose_b: &Transform) -> Self {
        Self {
            a,
            b,
            b_in_a: pose_a.inverse().mul_transform(pose_b),
        }
    }

    /// The support point of `A - B` along `direction` (A's frame).
    #[inline]
    pub fn support(&self, direction: Vec3) -> SimplexVertex {
        let a = self.a.support(direction);
        let b = self.b_in_a.transform_point(
            self.b
                .support(self.b_in_a.inverse_transform_vector(-direction)),
        );
        SimplexVertex { w: a - b, a, b }
    }

    /// Separation of the cores along the unit `normal` (from B to A, A's frame): how far A's
    /// core lies beyond B's along it (m); the largest over all normals is the signed distance.
    #[inline]
    pub fn separation_along(&self, normal: Vec3) -> f32 {
        // min over A of n·a - max over B of n·b = min over M of n·w: M's support along -n.
        self.support(-normal).w.dot(normal)
    }
}

/// Up to four vertices of the Minkowski difference.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Simplex {
    pub vertices: [SimplexVertex; 4],
    pub count: usize,
}

impl Simplex {
    pub fn vertices(&self) -> &[SimplexVertex] {
        &self.vertices[..self.count]
    }
}

/// What GJK found, in A's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GjkResult {
    /// The cores are `distance` apart (m, > [`OVERLAP_DISTANCE`]); `point_a` and `point_b` are
    /// the closest points of the cores, `normal` the unit direction from B's to A's. (The
    /// normal comes from GJK's closest point itself, not from `point_a - point_b`, which loses
    /// digits to cancellation when the cores nearly touch.)
    Separated {
        distance: f32,
        normal: Vec3,
        point_a: Vec3,
        point_b: Vec3,
    },
    /// The cores overlap or touch; `simplex` encloses (or nearly touches) the origin.
    Overlapping { simplex: Simplex },
}

/// GJK on the cores of `m` (see the module docs).
pub fn gjk<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
) -> GjkResult {
    // Start towards B from A: the centres' offset is a fair guess of the distance vector.
    let initial = if m.b_in_a.position.length_squared() > 0.0 {
        -m.b_in_a.position
    } else {
        Vec3::X
    };
    let mut simplex = Simplex {
        count: 1,
        ..Simplex::default()
    };
    simplex.vertices[0] = m.support(-initial);
    let mut weights = [1.0, 0.0, 0.0, 0.0];
    let mut v = simplex.vertices[0].w;
    for _ in 0..MAX_ITERATIONS {
        let vv = v.length_squared();
        if vv <= OVERLAP_DISTANCE * OVERLAP_DISTANCE {
            return GjkResult::Overlapping { simplex };
        }
        let w = m.support(-v);
        let duplicate = simplex.vertices().iter().any(|s| s.w == w.w);
        if duplicate || vv - v.dot(w.w) <= RELATIVE_TOLERANCE * vv {
            break;
        }
        let mut grown = simplex;
        grown.vertices[grown.count] = w;
        grown.count += 1;
        match closest_on_simplex(&mut grown) {
            // A larger simplex is never farther; if rounding says it is, keep the last one.
            Some((closest, _)) if closest.length_squared() >= vv => break,
            Some((closest, new_weights)) => {
                simplex = grown;
                v = closest;
                weights = new_weights;
            }
            None => return GjkResult::Overlapping { simplex: grown },
        }
    }
    let (mut point_a, mut point_b) = (Vec3::ZERO, Vec3::ZERO);
    for (vertex, weight) in simplex.vertices().iter().zip(weights) {
        point_a += vertex.a * weight;
        point_b += vertex.b * weight;
    }
    let distance = v.length();
    GjkResult::Separated {
        distance,
        normal: v / distance,
        point_a,
        point_b,
    }
}

/// A point of a simplex as weights of some of its vertices.
#[derive(Clone, Copy, Debug)]
struct Barycentric {
    /// Indices of the vertices used, `count` of them.
    indices: [usize; 3],
    count: usize,
    weights: [f64; 3],
}

impl Barycentric {
    fn vertex(i: usize) -> Self {
        Self {
            indices: [i, 0, 0],
            count: 1,
            weights: [1.0, 0.0, 0.0],
        }
    }

    fn edge(i: usize, j: usize, t: f64) -> Self {
        Self {
            indices: [i, j, 0],
            count: 2,
            weights: [1.0 - t, t, 0.0],
        }
    }

    fn point(&self, points: &[DVec3]) -> DVec3 {
        (0..self.count).fold(DVec3::ZERO, |sum, k| {
            sum + points[self.indices[k]] * self.weights[k]
        })
    }
}

/// Reduces `simplex` to the sub-simplex whose hull holds the point closest to the origin, and
/// returns that point with its barycentric weights (in the reduced vertex order); `None` when
/// the simplex is a tetrahedron holding the origin.
fn closest_on_simplex(simplex: &mut Simplex) -> Option<(Vec3, [f32; 4])> {
    // In f64: near contact the closest point is tiny next to the vertices, and f32 loses
    // it to cancellation in the barycentric products.
    let points = simplex.vertices.map(|v| v.w.as_dvec3());
    let closest = match simplex.count {
        1 => Barycentric::vertex(0),
        2 => segment(&points, 0, 1),
        3 => triangle(&points, [0, 1, 2]),
        _ => tetrahedron(&points)?,
    };
    let previous = simplex.vertices;
    simplex.count = closest.count;
    let mut weights = [0.0; 4];
    for k in 0..closest.count {
        simplex.vertices[k] = previous[closest.indices[k]];
        weights[k] = closest.weights[k] as f32;
    }
    Some((closest.point(&points).as_vec3(), weights))
}

/// Closest point of segment `points[i] points[j]` to the origin.
fn segment(points: &[DVec3], i: usize, j: usize) -> Barycentric {
    let (a, b) = (points[i], points[j]);
    let ab = b - a;
    let t = -a.dot(ab);
    if t <= 0.0 {
        return Barycentric::vertex(i);
    }
    let length_squared = ab.length_squared();
    if t >= length_squared {
        return Barycentric::vertex(j);
    }
    Barycentric::edge(i, j, t / length_squared)
}

/// Closest point of triangle `points[abc]` to the origin (Ericson, Real-Time Collision
/// Detection 5.1.5: Voronoi regions by barycentric sign tests).
fn triangle(points: &[DVec3], [ia, ib, ic]: [usize; 3]) -> Barycentric {
    let (a, b, c) = (points[ia], points[ib], points[ic]);
    let ab = b - a;
    let ac = c - a;
    let d1 = ab.dot(-a);
    let d2 = ac.dot(-a);
    if d1 <= 0.0 && d2 <= 0.0 {
        return Barycentric::vertex(ia);
    }
    let d3 = ab.dot(-b);
    let d4 = ac.dot(-b);
    if d3 >= 0.0 && d4 <= d3 {
        return Barycentric::vertex(ib);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return Barycentric::edge(ia, ib, d1 / (d1 - d3));
    }
    let d5 = ab.dot(-c);
    let d6 = ac.dot(-c);
    if d6 >= 0.0 && d5 <= d6 {
        return Barycentric::vertex(ic);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return Barycentric::edge(ia, ic, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return Barycentric::edge(ib, ic, (d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let sum = va + vb + vc;
    if sum <= 0.0 {
        // A flat (collinear) triangle: its closest point lies on an edge.
        return [(ia, ib), (ia, ic), (ib, ic)]
            .map(|(i, j)| segment(points, i, j))
            .into_iter()
            .min_by(|p, q| {
                p.point(points)
                    .length_squared()
                    .total_cmp(&q.point(points).length_squared())
            })
            .unwrap_or(Barycentric::vertex(ia));
    }
    let (v, w) = (vb / sum, vc / sum);
    Barycentric {
        indices: [ia, ib, ic],
        count: 3,
        weights: [1.0 - v - w, v, w],
    }
}

/// Closest point of the tetrahedron `points[0..4]` to the origin; `None` when the origin is
/// inside (on the inner side of every face). Outside, the closest point is the nearest of the
/// four faces' closest points: all four are searched, not only the faces that seem to face
/// the origin, because on a nearly flat tetrahedron those side tests are rounding.
fn tetrahedron(points: &[DVec3]) -> Option<Barycentric> {
    const FACES: [([usize; 3], usize); 4] = [
        ([0, 1, 2], 3),
        ([0, 1, 3], 2),
        ([0, 2, 3], 1),
        ([1, 2, 3], 0),
    ];
    let inside = FACES.iter().all(|&(face, opposite)| {
        let [i, j, k] = face.map(|i| points[i]);
        let normal = (j - i).cross(k - i);
        (-i).dot(normal) * (points[opposite] - i).dot(normal) > 0.0
    });
    if inside {
        return None;
    }
    FACES
        .iter()
        .map(|&(face, _)| triangle(points, face))
        .min_by(|p, q| {
            p.point(points)
                .length_squared()
                .total_cmp(&q.point(points).length_squared())
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Quat, vec3};

    fn distance_of(result: GjkResult) -> f32 {
        match result {
            GjkResult::Separated { distance, .. } => distance,
            GjkResult::Overlapping { .. } => 0.0,
        }
    }

    #[test]
    fn boxes_face_to_face_and_corner_to_corner() {
        let unit = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        let pose_a = Transform::IDENTITY;
        let pose_b = Transform::from_position(vec3(1.75, 0.2, -0.1));
        let m = MinkowskiDifference::new(&unit, &pose_a, &unit, &pose_b);
        let GjkResult::Separated {
            distance,
            point_a,
            point_b,
            ..
        } = gjk(&m)
        else {
            panic!("apart");
        };
        assert!((distance - 0.75).abs() < 1e-5);
        assert!((point_a.x - 0.5).abs() < 1e-5 && (point_b.x - 1.25).abs() < 1e-5);

        let pose_b = Transform::from_position(vec3(2.0, 2.0, 2.0));
        let m = MinkowskiDifference::new(&unit, &pose_a, &unit, &pose_b);
        assert!((distance_of(gjk(&m)) - 3.0f32.sqrt()).abs() < 1e-5);
    }

    #[test]
    fn capsule_over_rotated_box_edge() {
        // A box turned 45° about Z presents an edge at height sqrt(2)/2 · 1; a horizontal
        // capsule core 2 m up lies above that edge.
        let cube = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        let capsule = Capsule {
            radius: 0.1,
            half_height: 1.0,
        };
        let pose_box = Transform::new(
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_4),
        );
        let pose_capsule = Transform::new(
            vec3(0.0, 2.0, 0.0),
            Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
        );
        let m = MinkowskiDifference::new(&capsule, &pose_capsule, &cube, &pose_box);
        let expected = 2.0 - 0.5 * 2.0f32.sqrt();
        assert!((distance_of(gjk(&m)) - expected).abs() < 1e-5);
    }

    #[test]
    fn overlapping_cores_report_a_simplex() {
        let unit = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        let pose_b = Transform::new(vec3(0.3, 0.2, 0.1), Quat::from_rotation_y(0.3));
        let m = MinkowskiDifference::new(&unit, &Transform::IDENTITY, &unit, &pose_b);
        assert!(matches!(gjk(&m), GjkResult::Overlapping { .. }));
    }
}
