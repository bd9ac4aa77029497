//! Sampled penetration depth: the talk's GPU-friendly replacement for EPA.
//!
//! The separation of two cores along a unit normal `n` (from B to A) is
//! `s(n) = min over A of n·a - max over B of n·b = -h_M(-n)`, `h_M` being the support function
//! of the Minkowski difference `M = A - B`. Its maximum over all directions is the signed
//! distance: negative, it is minus the penetration depth, reached at the contact normal.
//!
//! Instead of building a polytope (EPA), evaluate `s` at a fixed set of directions — the
//! vertices of a subdivided icosahedron, 42 or 162 of them, nearly uniform on the sphere — take
//! the best few ([`REFINE_STARTS`]), then refine around each and keep the best: try eight
//! directions on a small circle around the current best, move to a better one, else halve the
//! circle, until the circle is under [`MIN_REFINE_ANGLE`]; last, fit a plane to the support points around the result (see
//! [`face_fit`]). Every step is a fixed amount of work on fixed-size data, with no allocation
//! and no branching on topology: what a GPU thread can do.

use std::sync::OnceLock;

use super::epa::Penetration;
use super::gjk::{MinkowskiDifference, SupportMap};
use crate::math::Vec3;

/// Moves at one circle size before it halves anyway: along a flat ridge, rounding-sized gains
/// would otherwise keep the search walking at a small step for hundreds of evaluations.
const MAX_MOVES_PER_ANGLE: u32 = 4;

/// How many of the best samples are refined: the best sample can lie in the basin of a
/// local optimum (a face of `M` whose foot point is inside it but which is not the nearest).
const REFINE_STARTS: usize = 3;

/// Radii (rad) of the probe circles of [`face_fit`], widest first: hill climbing can stall on
/// a ridge some way off the face normal, and a circle wider than that gap reaches the face's
/// third vertex.
const FACE_FIT_PROBE_ANGLES: [f32; 4] = [0.1, 0.03, 0.01, 0.003];

/// Hill climbing stops when the search circle's radius is under this angle (rad), about 0.06°:
/// the face fit that follows lands on the exact face normal from there.
const MIN_REFINE_ANGLE: f32 = 1.0e-3;

/// How finely the sphere of directions is sampled before refining.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// 42 directions (icosahedron subdivided once), about 32° apart.
    Directions42,
    /// 162 directions (subdivided twice), about 16° apart.
    Directions162,
}

impl Sampling {
    /// The unit directions, deterministic (the same list in every run).
    pub fn directions(self) -> &'static [Vec3] {
        static COARSE: OnceLock<Vec<Vec3>> = OnceLock::new();
        static FINE: OnceLock<Vec<Vec3>> = OnceLock::new();
        match self {
            Sampling::Directions42 => COARSE.get_or_init(|| icosphere(1)),
            Sampling::Directions162 => FINE.get_or_init(|| icosphere(2)),
        }
    }

    /// Angle between neighbouring directions (rad): where refinement starts.
    fn spacing(self) -> f32 {
        match self {
            Sampling::Directions42 => 0.55,
            Sampling::Directions162 => 0.28,
        }
    }
}

/// Vertices of an icosahedron subdivided `levels` times, projected on the unit sphere:
/// `10 · 4^levels + 2` of them.
pub fn icosphere(levels: u32) -> Vec<Vec3> {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let mut vertices: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        // Each edge's midpoint is made once: a sorted map keyed by the edge keeps the order
        // (and so the vertex list) the same in every run.
        let mut midpoints = std::collections::BTreeMap::new();
        let mut midpoint = |vertices: &mut Vec<Vec3>, a: usize, b: usize| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push((vertices[a] + vertices[b]).normalize());
                vertices.len() - 1
            })
        };
        let mut finer = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let ab = midpoint(&mut vertices, a, b);
            let bc = midpoint(&mut vertices, b, c);
            let ca = midpoint(&mut vertices, c, a);
            finer.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        triangles = finer;
    }
    vertices
}

/// The penetration of the cores of `m` found by sampling (see the module docs), in A's frame.
/// Also right when the cores are apart: `depth` is then negative, minus their distance
/// (along the sampled normal, so a lower bound of it).
pub fn sampled_penetration<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
    sampling: Sampling,
) -> Penetration {
    // The REFINE_STARTS best samples, best first (ties keep the earlier direction).
    let mut starts = [(Vec3::Y, f32::NEG_INFINITY); REFINE_STARTS];
    for &direction in sampling.directions() {
        let separation = m.separation_along(direction);
        if let Some(slot) = starts.iter().position(|&(_, s)| separation > s) {
            starts.copy_within(slot..REFINE_STARTS - 1, slot + 1);
            starts[slot] = (direction, separation);
        }
    }
    let (best, best_separation) = starts
        .iter()
        .map(|&(direction, separation)| refine(m, direction, separation, sampling.spacing()))
        .fold((Vec3::Y, f32::NEG_INFINITY), |best, candidate| {
            if candidate.1 > best.1 {
                candidate
            } else {
                best
            }
        });
    let deepest = m.support(-best);
    Penetration {
        depth: -best_separation,
        normal: best,
        point_a: deepest.a,
        point_b: deepest.b,
    }
}

/// Hill climbing from `start` (with its `separation`) on circles from half the sampling
/// `spacing` down to [`MIN_REFINE_ANGLE`], then [`face_fit`]: the best normal found and its
/// separation.
fn refine<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
    start: Vec3,
    separation: f32,
    spacing: f32,
) -> (Vec3, f32) {
    let (mut best, mut best_separation) = (start, separation);
    let mut angle = 0.5 * spacing;
    let mut moves = 0;
    while angle > MIN_REFINE_ANGLE {
        let (u, v) = crate::math::tangent_basis(best);
        let mut improved = false;
        for k in 0..8 {
            let (sin, cos) = (k as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
            let candidate = (best + angle * (cos * u + sin * v)).normalize();
            let separation = m.separation_along(candidate);
            if separation > best_separation {
                best_separation = separation;
                best = candidate;
                improved = true;
            }
        }
        moves += 1;
        if !improved || moves == MAX_MOVES_PER_ANGLE {
            angle *= 0.5;
            moves = 0;
        }
    }
    for probe_angle in FACE_FIT_PROBE_ANGLES {
        if let Some((normal, separation)) = face_fit(m, best, probe_angle)
            && separation > best_separation
        {
            best_separation = separation;
            best = normal;
        }
    }
    (best, best_separation)
}

/// Hill climbing ends within [`MIN_REFINE_ANGLE`] of the best normal, but where `s` has a
/// kink (the best normal of polytopes is a face normal of `M`) it may stop on a ridge a little
/// off it. The support points of `M` around the found direction are then that face's
/// vertices: the plane through the three that span the largest triangle has the exact normal.
/// Returns that normal and its separation.
fn face_fit<A: SupportMap + ?Sized, B: SupportMap + ?Sized>(
    m: &MinkowskiDifference<A, B>,
    normal: Vec3,
    probe_angle: f32,
) -> Option<(Vec3, f32)> {
    let (u, v) = crate::math::tangent_basis(normal);
    let probes: [Vec3; 9] = std::array::from_fn(|k| {
        if k == 0 {
            return m.support(-normal).w;
        }
        let (sin, cos) = ((k - 1) as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
        m.support(-(normal + probe_angle * (cos * u + sin * v)).normalize())
            .w
    });
    let first = probes[0];
    let second = probes.iter().copied().max_by(|p, q| {
        (*p - first)
            .length_squared()
            .total_cmp(&(*q - first).length_squared())
    })?;
    let third = probes.iter().copied().max_by(|p, q| {
        let area = |x: Vec3| (second - first).cross(x - first).length_squared();
        area(*p).total_cmp(&area(*q))
    })?;
    let mut fitted = (second - first).cross(third - first).try_normalize()?;
    if fitted.dot(normal) < 0.0 {
        fitted = -fitted;
    }
    Some((fitted, m.separation_along(fitted)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icospheres_have_42_and_162_unit_directions() {
        for (sampling, count) in [(Sampling::Directions42, 42), (Sampling::Directions162, 162)] {
            let directions = sampling.directions();
            assert_eq!(directions.len(), count);
            for (i, d) in directions.iter().enumerate() {
                assert!((d.length() - 1.0).abs() < 1e-6);
                // Neighbours are about `spacing` apart and none repeats.
                let nearest = directions
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, e)| d.angle_between(*e))
                    .fold(f32::INFINITY, f32::min);
                assert!(nearest > 0.7 * sampling.spacing() && nearest < 1.3 * sampling.spacing());
            }
        }
    }
}
