//! EPA (the expanding polytope algorithm): penetration depth and normal of two overlapping
//! convex cores, from the simplex GJK ends with.
//!
//! The Minkowski difference `M = A - B` holds the origin. Starting from a tetrahedron of `M`
//! around the origin, EPA repeatedly takes the polytope face nearest the origin, asks `M` for
//! its support point along that face's normal, and, if the point lies beyond the face, carves
//! the faces it sees away and fans the hole's rim (the horizon) to it. When the support point
//! is no farther than the face (within a tolerance), that face is a face of `M`: its distance
//! is the depth and the translation `-normal · depth` of A separates the cores, so the
//! contact normal (from B to A) is the face normal negated.
//!
//! EPA allocates its polytope and so runs on the CPU only; the GPU path uses the sampled depth
//! of [`penetration`](super::penetration) instead.

use super::gjk::{MinkowskiDifference, Simplex, SimplexVertex, SupportMap};
use crate::math::Vec3;

/// A face is a face of `M` when the support point along its normal lies no more than this far
/// (m) beyond it, plus [`RELATIVE_TOLERANCE`] of its distance.
const ABSOLUTE_TOLERANCE: f32 = 1.0e-6;
const RELATIVE_TOLERANCE: f32 = 1.0e-5;

/// Cap on expansions: each adds a vertex, and smooth shapes (a capsule core's rounded Minkowski
/// difference is still a polytope here) converge in a few dozen.
const MAX_ITERATIONS: usize = 128;

/// Penetration of two cores, in A's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Penetration {
    /// How deep the cores overlap (m, ≥ 0): A moved by `normal · depth` just touches B.
    pub depth: f32,
    /// Unit contact normal, from B to A.
    pub normal: Vec3,
    /// The deepest point of A's core (A's frame).
    pub point_a: Vec3,
    /// The deepest point of B's core (A's frame).
    pub point_b: Vec3,
}

#[derive(Clone, Copy, Debug)]
struct Face {
    vertices: [usize; 3],
    /// Unit normal, pointing away from the polytope's inside.
    normal: Vec3,
    /// Distance of the face's plane from the origin (m).
    distance: f32,
}

fn make_face(points: &[SimplexVertex], vertices: [usize; 3]) -> Option<Face> {
    let [a, b, c] = vertices.map(|i| points[i].w);
    let normal = (b - a).cross(c - a).try_normalize()?;
    Some(Face {
        vertices,
        normal,
        distance: normal.dot(a),
    })
}

/// EPA from GJK's overlapping `simplex`; `None` when `M` is flat (it then has no interior and
/// no depth direction, e.g. a point core against a segment core) or the polytope degenerates.
pub fn epa<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
    simplex: &Simplex,
) -> Option<Penetration> {
    let mut points: Vec<SimplexVertex> = simplex.vertices().to_vec();
    let scale = points
        .iter()
        .map(|p| p.w.length())
        .fold(0.0f32, f32::max)
        .max(m.support(Vec3::X).w.length());
    let tiny = 1.0e-6 * scale.max(1.0e-6);
    grow_to_tetrahedron(m, &mut points, tiny)?;

    let centre = points.iter().map(|p| p.w).sum::<Vec3>() / 4.0;
    let mut faces = Vec::with_capacity(64);
    for vertices in [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]] {
        let mut face = make_face(&points, vertices)?;
        if face.normal.dot(centre) > face.distance {
            face = make_face(&points, [vertices[0], vertices[2], vertices[1]])?;
        }
        faces.push(face);
    }

    let mut horizon: Vec<(usize, usize)> = Vec::new();
    for _ in 0..MAX_ITERATIONS {
        let nearest =
            (0..faces.len()).min_by(|&i, &j| faces[i].distance.total_cmp(&faces[j].distance))?;
        let face = faces[nearest];
        let w = m.support(face.normal);
        let beyond = face.normal.dot(w.w) - face.distance;
        if beyond <= ABSOLUTE_TOLERANCE + RELATIVE_TOLERANCE * face.distance.abs() {
            return Some(finish(&points, &face));
        }
        let new_index = points.len();
        points.push(w);
        // Carve away the faces that see the new point; their unshared edges are the horizon.
        horizon.clear();
        let mut kept = Vec::with_capacity(faces.len() + 8);
        let mut removed = Vec::new();
        for f in &faces {
            if f.normal.dot(w.w) - f.distance > 0.0 {
                removed.push(*f);
            } else {
                kept.push(*f);
            }
        }
        for f in &removed {
            let [a, b, c] = f.vertices;
            for (p, q) in [(a, b), (b, c), (c, a)] {
                let shared = removed.iter().any(|g| {
                    let [x, y, z] = g.vertices;
                    [(x, y), (y, z), (z, x)].contains(&(q, p))
                });
                if !shared {
                    horizon.push((p, q));
                }
            }
        }
        for &(p, q) in &horizon {
            kept.push(make_face(&points, [p, q, new_index])?);
        }
        faces = kept;
    }
    let nearest =
        (0..faces.len()).min_by(|&i, &j| faces[i].distance.total_cmp(&faces[j].distance))?;
    Some(finish(&points, &faces[nearest]))
}

/// Adds support points until `points` spans a tetrahedron; `None` if `M` is flat.
fn grow_to_tetrahedron<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
    points: &mut Vec<SimplexVertex>,
    tiny: f32,
) -> Option<()> {
    const AXES: [Vec3; 6] = [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    if points.len() == 1 {
        let p0 = points[0].w;
        let w = AXES
            .iter()
            .map(|&d| m.support(d))
            .find(|w| (w.w - p0).length() > tiny)?;
        points.push(w);
    }
    if points.len() == 2 {
        let axis = (points[1].w - points[0].w).normalize();
        let (u, v) = crate::math::tangent_basis(axis);
        let p0 = points[0].w;
        let w = [u, -u, v, -v]
            .iter()
            .map(|&d| m.support(d))
            .find(|w| (w.w - p0).cross(axis).length() > tiny)?;
        points.push(w);
    }
    if points.len() == 3 {
        let [a, b, c] = [points[0].w, points[1].w, points[2].w];
        let normal = (b - a).cross(c - a).try_normalize()?;
        // The apex on the origin's side keeps the origin inside the tetrahedron.
        let towards_origin = if (-a).dot(normal) >= 0.0 {
            normal
        } else {
            -normal
        };
        let w = [towards_origin, -towards_origin]
            .iter()
            .map(|&d| m.support(d))
            .find(|w| (w.w - a).dot(normal).abs() > tiny)?;
        points.push(w);
    }
    let [a, b, c, d] = [points[0].w, points[1].w, points[2].w, points[3].w];
    ((b - a).cross(c - a).dot(d - a).abs() > tiny * tiny * tiny).then_some(())
}

/// The penetration from the face of `M` nearest the origin: the origin's projection on it, as
/// barycentric weights of its vertices, gives the witness points.
fn finish(points: &[SimplexVertex], face: &Face) -> Penetration {
    let [a, b, c] = face.vertices.map(|i| points[i]);
    let p = face.normal * face.distance;
    let (v0, v1, v2) = (b.w - a.w, c.w - a.w, p - a.w);
    let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
    let (d20, d21) = (v2.dot(v0), v2.dot(v1));
    let denominator = d00 * d11 - d01 * d01;
    let (u, v) = if denominator > 0.0 {
        (
            (d11 * d20 - d01 * d21) / denominator,
            (d00 * d21 - d01 * d20) / denominator,
        )
    } else {
        (0.0, 0.0)
    };
    let weights = [1.0 - u - v, u, v];
    let point_a = a.a * weights[0] + b.a * weights[1] + c.a * weights[2];
    let point_b = a.b * weights[0] + b.b * weights[1] + c.b * weights[2];
    Penetration {
        depth: face.distance.max(0.0),
        normal: -face.normal,
        point_a,
        point_b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::gjk::{GjkResult, gjk};
    use crate::math::{Transform, vec3};
    use crate::shape::Cuboid;

    #[test]
    fn overlapping_boxes_depth_is_the_smallest_overlap() {
        let a = Cuboid {
            half_extents: vec3(1.0, 0.5, 0.75),
        };
        let b = Cuboid {
            half_extents: Vec3::splat(0.5),
        };
        // B sits below A, overlapping 0.1 m in y and far more in x and z.
        let pose_b = Transform::from_position(vec3(0.2, -0.9, 0.1));
        let m = MinkowskiDifference::new(&a, &Transform::IDENTITY, &b, &pose_b);
        let GjkResult::Overlapping { simplex } = gjk(&m) else {
            panic!("overlapping");
        };
        let penetration = epa(&m, &simplex).unwrap();
        assert!((penetration.depth - 0.1).abs() < 1e-5, "{penetration:?}");
        assert!((penetration.normal - Vec3::Y).length() < 1e-5);
        assert!((penetration.point_a.y + 0.5).abs() < 1e-5);
        assert!((penetration.point_b.y + 0.4).abs() < 1e-5);
    }
}
