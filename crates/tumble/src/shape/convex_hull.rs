//! Convex hulls: the smallest convex polyhedron holding a set of points.
//!
//! # Construction
//!
//! An incremental hull in f64 (beneath–beyond): start from the tetrahedron of four extreme
//! points, then add the points in input order; a point more than `tolerance` outside some
//! triangles replaces them with a fan from the point to their horizon. Points within
//! `tolerance` of the hull count as inside, so duplicates and near-coplanar points never make
//! slivers. `tolerance` is [`RELATIVE_TOLERANCE`] of the points' extent.
//!
//! Adjacent triangles whose far vertices lie within `tolerance` of each other's plane are
//! merged into one polygon face (a box has 6 faces, not 12): SAT and clipping want true faces.
//! Vertices that end up on fewer than three faces (inside a face or on an edge) are dropped.
//!
//! # Frame
//!
//! The solver wants the body frame at the centre of mass with the principal axes of inertia
//! (`BodyMass` holds a diagonal inverse inertia). So the stored vertices are the input points
//! re-expressed in the principal centroid frame, and [`ConvexHull::local_frame`] is that frame
//! in the input points' frame: a body built from the hull at pose `P` sits at
//! `P * local_frame`. When the input is already centred on its principal axes (within
//! [`RELATIVE_TOLERANCE`]) the points are kept bit for bit and the frame is exactly the
//! identity, so a hull written out and read back (a dumped scene) is the same hull.
//!
//! # Determinism
//!
//! Points are visited in input order and kept vertices keep their input order; nothing
//! depends on hashing or addresses, so the same points give the same hull bit for bit.

use crate::math::{Quat, Transform, Vec3};
use glam::{DMat3, DVec3};

/// Fraction of the points' extent (largest side of their bounding box) under which distances
/// count as zero: a point that close to a face is on it, and two faces that close to coplanar
/// are one. f32 inputs carry about 1e-7 of relative rounding; this is well above that and well
/// below any feature a collision shape should have.
pub const RELATIVE_TOLERANCE: f64 = 1.0e-5;

/// Why points make no hull.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HullError {
    #[error("point {index} is not finite (NaN or infinity)")]
    NotFinite { index: usize },
    #[error("a hull needs at least 4 points, got {count}")]
    TooFewPoints { count: usize },
    #[error("all points are the same point")]
    AllCoincident,
    #[error("all points are collinear")]
    Collinear,
    #[error("all points are coplanar")]
    Coplanar,
}

/// A polygon face: outward unit `normal` and `offset` (the face is `normal · x = offset` in the
/// hull frame, every vertex has `normal · x <= offset`), its vertices
/// `face_vertices[first..first + count]`, counter-clockwise seen from outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullFace {
    pub normal: Vec3,
    pub offset: f32,
    pub first: u32,
    pub count: u32,
}

/// An edge between vertices `vertices[0]` and `vertices[1]`, shared by `faces[0]` (on whose
/// loop it runs from `vertices[0]` to `vertices[1]`) and `faces[1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullEdge {
    pub vertices: [u32; 2],
    pub faces: [u32; 2],
}

/// A convex polyhedron in its principal centroid frame (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexHull {
    vertices: Vec<Vec3>,
    faces: Vec<HullFace>,
    face_vertices: Vec<u32>,
    edges: Vec<HullEdge>,
    local_frame: Transform,
    volume: f32,
    /// Principal moments of inertia per kg of mass (m²).
    unit_inertia: Vec3,
    bounding_radius: f32,
    /// Vertices of the longest face loop.
    max_face_vertices: u32,
}

impl ConvexHull {
    /// The hull of `points`; `Err` says why they enclose no volume.
    pub fn new(points: &[Vec3]) -> Result<Self, HullError> {
        if let Some(index) = points.iter().position(|p| !p.is_finite()) {
            return Err(HullError::NotFinite { index });
        }
        if points.len() < 4 {
            return Err(HullError::TooFewPoints {
                count: points.len(),
            });
        }
        let input: Vec<DVec3> = points.iter().map(|p| p.as_dvec3()).collect();
        let topology = Topology::build(&input)?;
        // Four faces at least, or the merge found the points flat within the tolerance.
        if topology.loops.len() < 4 {
            return Err(HullError::Coplanar);
        }

        let (centroid, principal, inertia) = mass_moments(&input, &topology);
        let already_principal = centroid.length() <= RELATIVE_TOLERANCE * extent(&input)
            && off_diagonal_ratio(&inertia) <= RELATIVE_TOLERANCE;
        let (vertices, local_frame) = if already_principal {
            let kept = topology.kept.iter().map(|&i| points[i]).collect();
            (kept, Transform::IDENTITY)
        } else {
            let rotation = Quat::from_mat3(&principal.as_mat3()).normalize();
            let frame = Transform::new(centroid.as_vec3(), rotation);
            let kept = topology
                .kept
                .iter()
                .map(|&i| frame.inverse_transform_point(points[i]))
                .collect();
            (kept, frame)
        };
        Ok(Self::from_frame_vertices(
            vertices,
            &topology.loops,
            local_frame,
        ))
    }

    /// Builds faces, edges and mass properties from the final (stored) vertices, so that
    /// everything the hull reports is computed from the f32 points it keeps.
    fn from_frame_vertices(
        vertices: Vec<Vec3>,
        loops: &[Vec<u32>],
        local_frame: Transform,
    ) -> Self {
        let points: Vec<DVec3> = vertices.iter().map(|v| v.as_dvec3()).collect();
        let mut faces = Vec::with_capacity(loops.len());
        let mut face_vertices = Vec::new();
        for face_loop in loops {
            // Newell's normal: exact for a planar polygon, the best fit for a nearly planar one.
            let mut normal = DVec3::ZERO;
            for (k, &i) in face_loop.iter().enumerate() {
                let p = points[i as usize];
                let q = points[face_loop[(k + 1) % face_loop.len()] as usize];
                normal += p.cross(q);
            }
            let normal = normal.normalize();
            let offset = face_loop
                .iter()
                .map(|&i| normal.dot(points[i as usize]))
                .fold(f64::NEG_INFINITY, f64::max);
            faces.push(HullFace {
                normal: normal.as_vec3(),
                offset: offset as f32,
                first: face_vertices.len() as u32,
                count: face_loop.len() as u32,
            });
            face_vertices.extend_from_slice(face_loop);
        }

        // Each directed loop edge (a, b) meets its twin (b, a) on the neighbouring face.
        let mut directed: Vec<(u32, u32, u32)> = Vec::new();
        for (f, face_loop) in loops.iter().enumerate() {
            for (k, &a) in face_loop.iter().enumerate() {
                directed.push((a, face_loop[(k + 1) % face_loop.len()], f as u32));
            }
        }
        directed.sort_unstable();
        let mut edges = Vec::new();
        for &(a, b, face) in &directed {
            if a < b
                && let Ok(twin) = directed.binary_search_by(|probe| (probe.0, probe.1).cmp(&(b, a)))
            {
                edges.push(HullEdge {
                    vertices: [a, b],
                    faces: [face, directed[twin].2],
                });
            }
        }

        let (volume, centroid, second_moment) = integrate(&points, loops);
        let covariance = second_moment - volume * outer(centroid, centroid);
        let inertia = DMat3::from_diagonal(DVec3::splat(trace(&covariance))) - covariance;
        let unit_inertia =
            DVec3::new(inertia.x_axis.x, inertia.y_axis.y, inertia.z_axis.z) / volume;
        let bounding_radius = vertices.iter().map(|v| v.length()).fold(0.0, f32::max);
        let max_face_vertices = faces.iter().map(|face| face.count).max().unwrap_or(0);
        Self {
            vertices,
            faces,
            face_vertices,
            edges,
            local_frame,
            volume: volume as f32,
            unit_inertia: unit_inertia.as_vec3(),
            bounding_radius,
            max_face_vertices,
        }
    }

    /// Vertices in the hull frame (m), in the order of the input points they came from.
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    pub fn faces(&self) -> &[HullFace] {
        &self.faces
    }

    /// Vertex indices of `face`, counter-clockwise seen from outside.
    pub fn face_loop(&self, face: &HullFace) -> &[u32] {
        &self.face_vertices[face.first as usize..(face.first + face.count) as usize]
    }

    /// All face loops back to back, indexed by [`HullFace::first`].
    pub fn face_vertices(&self) -> &[u32] {
        &self.face_vertices
    }

    pub fn edges(&self) -> &[HullEdge] {
        &self.edges
    }

    /// The hull frame (centroid, principal axes) in the frame of the points it was built from.
    pub fn local_frame(&self) -> Transform {
        self.local_frame
    }

    /// The same hull with its frame taken as the input frame: what a body built from this hull
    /// stores, its pose having absorbed [`local_frame`](Self::local_frame).
    pub fn in_own_frame(&self) -> Self {
        Self {
            local_frame: Transform::IDENTITY,
            ..self.clone()
        }
    }

    /// m³.
    pub fn volume(&self) -> f32 {
        self.volume
    }

    /// Principal moments of inertia for a mass of 1 kg (kg m²).
    pub fn unit_inertia(&self) -> Vec3 {
        self.unit_inertia
    }

    /// Vertices of the longest face loop (the GPU narrowphase takes hulls up to a bound).
    pub fn max_face_vertices(&self) -> u32 {
        self.max_face_vertices
    }

    /// Distance from the hull frame's origin (the centroid) to the farthest vertex (m).
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// The vertex farthest along `direction` (hull frame); the lowest index on a tie.
    #[inline]
    pub fn support(&self, direction: Vec3) -> Vec3 {
        self.vertices[self.support_index(direction)]
    }

    /// Index of [`support`](Self::support)'s vertex.
    #[inline]
    pub fn support_index(&self, direction: Vec3) -> usize {
        let mut best = 0;
        let mut best_dot = f32::NEG_INFINITY;
        for (i, v) in self.vertices.iter().enumerate() {
            let d = v.dot(direction);
            if d > best_dot {
                best_dot = d;
                best = i;
            }
        }
        best
    }
}

/// Largest side of the points' bounding box (m).
fn extent(points: &[DVec3]) -> f64 {
    let (min, max) = points.iter().fold((points[0], points[0]), |(lo, hi), &p| {
        (lo.min(p), hi.max(p))
    });
    (max - min).max_element()
}

/// The combinatorial hull: which input points are vertices (`kept`, in input order) and the
/// face loops over indices into `kept`.
struct Topology {
    kept: Vec<usize>,
    loops: Vec<Vec<u32>>,
}

#[derive(Clone, Copy)]
struct Triangle {
    vertices: [usize; 3],
    normal: DVec3,
    offset: f64,
}

impl Triangle {
    fn new(points: &[DVec3], vertices: [usize; 3]) -> Self {
        let [a, b, c] = vertices.map(|i| points[i]);
        let normal = (b - a).cross(c - a).normalize();
        Self {
            vertices,
            normal,
            offset: normal.dot(a),
        }
    }

    fn distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p) - self.offset
    }

    fn edges(&self) -> [(usize, usize); 3] {
        let [a, b, c] = self.vertices;
        [(a, b), (b, c), (c, a)]
    }
}

impl Topology {
    fn build(points: &[DVec3]) -> Result<Self, HullError> {
        let tolerance = RELATIVE_TOLERANCE * extent(points);
        let first = (0..points.len())
            .min_by(|&i, &j| points[i].x.total_cmp(&points[j].x))
            .unwrap_or(0);
        let farthest = |score: &dyn Fn(DVec3) -> f64| {
            let mut best = (0, f64::NEG_INFINITY);
            for (i, &p) in points.iter().enumerate() {
                let s = score(p);
                if s > best.1 {
                    best = (i, s);
                }
            }
            best
        };
        let p0 = points[first];
        let (second, d1) = farthest(&|p| (p - p0).length());
        if d1 <= tolerance {
            return Err(HullError::AllCoincident);
        }
        let axis = (points[second] - p0) / d1;
        let (third, d2) = farthest(&|p| (p - p0).cross(axis).length());
        if d2 <= tolerance {
            return Err(HullError::Collinear);
        }
        let plane_normal = axis.cross(points[third] - p0).normalize();
        let (fourth, d3) = farthest(&|p| plane_normal.dot(p - p0).abs());
        if d3 <= tolerance {
            return Err(HullError::Coplanar);
        }

        // The starting tetrahedron, wound so every normal points away from its centre.
        let seed = [first, second, third, fourth];
        let inside = seed.iter().map(|&i| points[i]).sum::<DVec3>() / 4.0;
        let mut triangles: Vec<Triangle> = [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]
            .iter()
            .map(|t| {
                let mut v = t.map(|k| seed[k]);
                let tri = Triangle::new(points, v);
                if tri.distance(inside) > 0.0 {
                    v.swap(1, 2);
                }
                Triangle::new(points, v)
            })
            .collect();

        let mut visible = Vec::new();
        let mut horizon = Vec::new();
        for (i, &p) in points.iter().enumerate() {
            if seed.contains(&i) {
                continue;
            }
            visible.clear();
            visible.extend((0..triangles.len()).filter(|&t| triangles[t].distance(p) > tolerance));
            if visible.is_empty() {
                continue;
            }
            // The horizon: edges of visible triangles whose twin is on a hidden triangle.
            horizon.clear();
            for &t in &visible {
                for (a, b) in triangles[t].edges() {
                    let twin_visible = visible
                        .iter()
                        .any(|&u| triangles[u].edges().contains(&(b, a)));
                    if !twin_visible {
                        horizon.push((a, b));
                    }
                }
            }
            // Remove from the back so earlier indices stay valid; keep the survivors' order.
            for &t in visible.iter().rev() {
                triangles.remove(t);
            }
            triangles.extend(
                horizon
                    .iter()
                    .map(|&(a, b)| Triangle::new(points, [a, b, i])),
            );
        }
        Ok(Self::merge(points, &triangles, tolerance))
    }

    /// Merges coplanar neighbours into polygons and drops vertices that are no corners.
    fn merge(points: &[DVec3], triangles: &[Triangle], tolerance: f64) -> Self {
        // Twin lookup: directed edge → triangle, sorted for binary search.
        let mut directed: Vec<((usize, usize), usize)> = triangles
            .iter()
            .enumerate()
            .flat_map(|(t, tri)| tri.edges().map(|e| (e, t)))
            .collect();
        directed.sort_unstable();
        let twin = |a: usize, b: usize| {
            directed
                .binary_search_by(|probe| probe.0.cmp(&(b, a)))
                .map(|k| directed[k].1)
                .ok()
        };

        // Union–find over triangles; the root is the lowest index, so groups are deterministic.
        let mut parent: Vec<usize> = (0..triangles.len()).collect();
        fn root(parent: &mut [usize], mut t: usize) -> usize {
            while parent[t] != t {
                parent[t] = parent[parent[t]];
                t = parent[t];
            }
            t
        }
        for (t, tri) in triangles.iter().enumerate() {
            for (a, b) in tri.edges() {
                let Some(u) = twin(a, b) else { continue };
                let other = &triangles[u];
                let far_of = |tri: &Triangle, a: usize, b: usize| {
                    tri.vertices.into_iter().find(|&v| v != a && v != b)
                };
                let coplanar = far_of(other, a, b)
                    .is_some_and(|v| tri.distance(points[v]).abs() <= tolerance)
                    && far_of(tri, a, b)
                        .is_some_and(|v| other.distance(points[v]).abs() <= tolerance);
                if coplanar {
                    let (ra, rb) = (root(&mut parent, t), root(&mut parent, u));
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
        let group: Vec<usize> = (0..triangles.len()).map(|t| root(&mut parent, t)).collect();

        // Boundary of each group: its directed edges whose twin is in another group.
        let mut groups: Vec<usize> = group.clone();
        groups.sort_unstable();
        groups.dedup();
        let mut faces_of_vertex = vec![0u32; points.len()];
        let mut raw_loops = Vec::with_capacity(groups.len());
        for &g in &groups {
            let mut boundary: Vec<(usize, usize)> = Vec::new();
            for (t, tri) in triangles.iter().enumerate() {
                if group[t] != g {
                    continue;
                }
                for (a, b) in tri.edges() {
                    if twin(a, b).is_none_or(|u| group[u] != g) {
                        boundary.push((a, b));
                    }
                }
            }
            boundary.sort_unstable();
            // A group with no boundary would be the whole surface: only a flat point set
            // merges that far, and `new` reports it as coplanar.
            let Some(&(start, second)) = boundary.first() else {
                continue;
            };
            // Walk the loop from its lowest vertex.
            let mut face_loop = vec![start];
            let mut at = second;
            while at != start && face_loop.len() <= boundary.len() {
                face_loop.push(at);
                at = match boundary.binary_search_by(|probe| probe.0.cmp(&at)) {
                    Ok(k) => boundary[k].1,
                    Err(_) => break,
                };
            }
            for &v in &face_loop {
                faces_of_vertex[v] += 1;
            }
            raw_loops.push(face_loop);
        }

        // A corner lies on three faces or more; others sit inside a face or along an edge.
        let kept: Vec<usize> = (0..points.len())
            .filter(|&v| faces_of_vertex[v] >= 3)
            .collect();
        let mut new_index = vec![u32::MAX; points.len()];
        for (k, &v) in kept.iter().enumerate() {
            new_index[v] = k as u32;
        }
        // Canonical order (each loop from its lowest vertex, loops sorted): the faces depend
        // only on the kept vertices' order, not on the order triangles were made in, so the
        // hull rebuilt from its own vertices has the same faces in the same order.
        let mut loops: Vec<Vec<u32>> = raw_loops
            .iter()
            .map(|face_loop| {
                let mut face_loop: Vec<u32> = face_loop
                    .iter()
                    .filter(|&&v| new_index[v] != u32::MAX)
                    .map(|&v| new_index[v])
                    .collect();
                let lowest = (0..face_loop.len())
                    .min_by_key(|&k| face_loop[k])
                    .unwrap_or(0);
                face_loop.rotate_left(lowest);
                face_loop
            })
            .collect();
        loops.sort_unstable();
        Self { kept, loops }
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn trace(m: &DMat3) -> f64 {
    m.x_axis.x + m.y_axis.y + m.z_axis.z
}

/// Volume (m³), centroid (m) and second moment `∫ x xᵀ dV` (m⁵) of the solid bounded by the
/// face loops, by tetrahedra from a point inside (the vertex mean: near the solid, so the
/// terms stay small) to each fan triangle of each face. For a tetrahedron (o, a, b, c) with
/// `A = [a b c]` relative to o, `∫ x xᵀ = det(A)/120 · A (I + 11ᵀ) Aᵀ` (Tonon 2004).
fn integrate(points: &[DVec3], loops: &[Vec<u32>]) -> (f64, DVec3, DMat3) {
    let origin = points.iter().sum::<DVec3>() / points.len() as f64;
    let mut volume = 0.0;
    let mut first_moment = DVec3::ZERO;
    let mut second_moment = DMat3::ZERO;
    let canonical = DMat3::from_cols(
        DVec3::new(2.0, 1.0, 1.0),
        DVec3::new(1.0, 2.0, 1.0),
        DVec3::new(1.0, 1.0, 2.0),
    );
    for face_loop in loops {
        let a = points[face_loop[0] as usize] - origin;
        for k in 1..face_loop.len() - 1 {
            let b = points[face_loop[k] as usize] - origin;
            let c = points[face_loop[k + 1] as usize] - origin;
            let m = DMat3::from_cols(a, b, c);
            let det = m.determinant();
            volume += det / 6.0;
            first_moment += det / 24.0 * (a + b + c);
            second_moment += m * canonical * m.transpose() * (det / 120.0);
        }
    }
    let centroid_offset = first_moment / volume;
    // Shift the second moment from `origin` to the true origin: ∫(x+o)(x+o)ᵀ.
    let shifted = second_moment
        + outer(first_moment, origin)
        + outer(origin, first_moment)
        + volume * outer(origin, origin);
    (volume, centroid_offset + origin, shifted)
}

/// Centroid, principal axes (columns, right handed) and inertia tensor about the centroid per
/// unit density, of the hull of `points` with `topology`.
fn mass_moments(points: &[DVec3], topology: &Topology) -> (DVec3, DMat3, DMat3) {
    let kept: Vec<DVec3> = topology.kept.iter().map(|&i| points[i]).collect();
    let (volume, centroid, second_moment) = integrate(&kept, &topology.loops);
    let covariance = second_moment - volume * outer(centroid, centroid);
    let inertia = DMat3::from_diagonal(DVec3::splat(trace(&covariance))) - covariance;
    let mut axes = jacobi_eigenvectors(inertia);
    if axes.determinant() < 0.0 {
        axes.z_axis = -axes.z_axis;
    }
    (centroid, axes, inertia)
}

/// Largest off-diagonal entry of a symmetric tensor relative to its largest diagonal entry.
pub(super) fn off_diagonal_ratio(m: &DMat3) -> f64 {
    let off = m.x_axis.y.abs().max(m.x_axis.z.abs()).max(m.y_axis.z.abs());
    let diagonal = m.x_axis.x.abs().max(m.y_axis.y.abs()).max(m.z_axis.z.abs());
    off / diagonal
}

/// Eigenvectors (columns) of a symmetric 3×3 matrix by cyclic Jacobi rotations.
pub(super) fn jacobi_eigenvectors(m: DMat3) -> DMat3 {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * (a[0][0].abs() + a[1][1].abs() + a[2][2].abs()) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // Rotation angle that zeroes a[p][q] (Numerical Recipes' stable form).
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a ← Jᵀ a J: columns p and q, then rows p and q.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // `v` holds eigenvectors as columns in row-major storage.
    DMat3::from_cols(
        DVec3::new(v[0][0], v[1][0], v[2][0]),
        DVec3::new(v[0][1], v[1][1], v[2][1]),
        DVec3::new(v[0][2], v[1][2], v[2][2]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3;

    fn box_corners(h: Vec3) -> Vec<Vec3> {
        (0..8)
            .map(|i| {
                h * Vec3::new(
                    [-1.0, 1.0][i & 1],
                    [-1.0, 1.0][(i >> 1) & 1],
                    [-1.0, 1.0][i >> 2],
                )
            })
            .collect()
    }

    #[test]
    fn box_has_six_quads_twelve_edges_and_box_inertia() {
        let h = vec3(1.0, 0.5, 0.25);
        let mut points = box_corners(h);
        // Extra points inside, on faces and on edges are not corners.
        points.extend([
            Vec3::ZERO,
            vec3(1.0, 0.0, 0.0),
            vec3(1.0, 0.5, 0.0),
            points[3],
        ]);
        let hull = ConvexHull::new(&points).unwrap();
        assert_eq!(hull.vertices(), &box_corners(h)[..]);
        assert_eq!(hull.faces().len(), 6);
        assert!(hull.faces().iter().all(|f| f.count == 4));
        assert_eq!(hull.edges().len(), 12);
        assert_eq!(hull.local_frame(), Transform::IDENTITY);
        assert!((hull.volume() - 8.0 * h.x * h.y * h.z).abs() < 1e-6);
        let d2 = (2.0 * h) * (2.0 * h);
        let expected = Vec3::new(d2.y + d2.z, d2.x + d2.z, d2.x + d2.y) / 12.0;
        assert!((hull.unit_inertia() - expected).abs().max_element() < 1e-6);
        for face in hull.faces() {
            // Every vertex is behind every face plane, the face's own on it.
            for v in hull.vertices() {
                assert!(face.normal.dot(*v) <= face.offset + 1e-6);
            }
            for &i in hull.face_loop(face) {
                assert!((face.normal.dot(hull.vertices()[i as usize]) - face.offset).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn offset_rotated_box_is_recentred_on_principal_axes() {
        let h = vec3(1.0, 0.5, 0.25);
        let pose = Transform::new(
            vec3(3.0, -1.0, 2.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.4, -0.7, 1.1),
        );
        let points: Vec<Vec3> = box_corners(h)
            .iter()
            .map(|&p| pose.transform_point(p))
            .collect();
        let hull = ConvexHull::new(&points).unwrap();
        let frame = hull.local_frame();
        assert!((frame.position - pose.position).length() < 1e-5);
        // The stored vertices are the box's corners in some principal frame: the same
        // moments (in some order) and the input points reproduced by the frame.
        let mut moments = hull.unit_inertia().to_array();
        moments.sort_by(f32::total_cmp);
        let d2 = (2.0 * h) * (2.0 * h);
        let mut expected = [
            (d2.y + d2.z) / 12.0,
            (d2.x + d2.z) / 12.0,
            (d2.x + d2.y) / 12.0,
        ];
        expected.sort_by(f32::total_cmp);
        for (m, e) in moments.iter().zip(expected) {
            assert!((m - e).abs() < 1e-5, "{moments:?} {expected:?}");
        }
        for (stored, input) in hull.vertices().iter().zip(&points) {
            assert!((frame.transform_point(*stored) - *input).length() < 1e-5);
        }
        // Rebuilding from the stored vertices is an exact no-op.
        let again = ConvexHull::new(hull.vertices()).unwrap();
        assert_eq!(again, hull.in_own_frame());
    }

    #[test]
    fn tetrahedron_volume_and_centroid() {
        let points = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let hull = ConvexHull::new(&points).unwrap();
        assert!((hull.volume() - 1.0 / 6.0).abs() < 1e-6);
        assert!((hull.local_frame().position - Vec3::splat(0.25)).length() < 1e-6);
        assert_eq!(hull.faces().len(), 4);
        assert_eq!(hull.edges().len(), 6);
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        assert_eq!(
            ConvexHull::new(&[Vec3::ZERO, Vec3::X, Vec3::Y]),
            Err(HullError::TooFewPoints { count: 3 })
        );
        assert_eq!(
            ConvexHull::new(&[Vec3::ONE; 5]),
            Err(HullError::AllCoincident)
        );
        let line: Vec<Vec3> = (0..6).map(|i| Vec3::splat(i as f32)).collect();
        assert_eq!(ConvexHull::new(&line), Err(HullError::Collinear));
        let flat: Vec<Vec3> = (0..9)
            .map(|i| vec3((i % 3) as f32, (i / 3) as f32, 2.0))
            .collect();
        assert_eq!(ConvexHull::new(&flat), Err(HullError::Coplanar));
        assert_eq!(
            ConvexHull::new(&[Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Z]),
            Err(HullError::NotFinite { index: 2 })
        );
    }

    #[test]
    fn random_points_hull_contains_them_all() {
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1664525).wrapping_add(1013904223);
            (state >> 8) as f32 / (1 << 24) as f32 * 2.0 - 1.0
        };
        let points: Vec<Vec3> = (0..200).map(|_| vec3(next(), next(), next())).collect();
        let hull = ConvexHull::new(&points).unwrap();
        let frame = hull.local_frame();
        for &p in &points {
            let local = frame.inverse_transform_point(p);
            for face in hull.faces() {
                assert!(face.normal.dot(local) <= face.offset + 1e-4);
            }
        }
        // Euler: V - E + F = 2.
        let (v, e, f) = (
            hull.vertices().len(),
            hull.edges().len(),
            hull.faces().len(),
        );
        assert_eq!(v + f, e + 2);
        assert_eq!(ConvexHull::new(&points).unwrap(), hull);
    }
}
