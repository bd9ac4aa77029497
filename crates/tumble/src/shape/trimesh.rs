//! Static triangle meshes: vertices, triangles, a BVH over the triangles and, per triangle edge,
//! whether contacts on it may push sideways ("active" edges).
//!
//! # Winding and sides
//!
//! A triangle `[i, j, k]` faces the side from which `i → j → k` turns counter-clockwise: its
//! normal is `(v_j − v_i) × (v_k − v_i)`, normalized. Contacts are two-sided (a body behind a
//! triangle is pushed further behind it), but edge activity is judged from the front side, the
//! side a landscape or a room is walked on.
//!
//! # Active edges (internal edge handling)
//!
//! A body sliding across a flat mesh touches the edges shared by neighbouring triangles. Seen
//! from one triangle alone, such an edge is a boundary, and a contact on it gets a normal that
//! points sideways: the body bumps. An edge is *active* when a contact on it may really have a
//! normal other than the face's: a boundary edge (one triangle), a non-manifold edge (three or
//! more), or an edge whose neighbour folds away from the front side (convex) by more than
//! [`ACTIVE_EDGE_ANGLE`]. Flat and concave (folding towards the front) edges are inactive; the
//! narrowphase replaces the normal of a contact on an inactive edge with the face normal, as
//! Jolt's active edges and Bullet's `btAdjustInternalEdgeContacts` do.
//!
//! # Concave edges (speculative contacts across a valley)
//!
//! A contact computed at the start of a step holds a point only against the triangle it is
//! over; a capsule pivoting over a valley edge within the step puts its far end into the
//! other triangle, whose plane rises above the near one's. So the narrowphase lets a
//! triangle's capsule points (the part of the segment over the triangle) reach past its
//! *concave* edges (folding towards the front by more than [`CONCAVE_EDGE_ANGLE`]) by the
//! speculative margin: beyond such an edge the triangle's plane runs below the neighbour's
//! surface, so a point there is never closer to it than to the neighbour and the extra points
//! cannot push a body that does not touch. Past convex edges the plane runs above the
//! neighbour (a ghost contact), and past flat ones the neighbour's own points suffice.
//!
//! # Degenerate triangles are errors
//!
//! A triangle of zero area has no normal, so no contact against it is defined, and silently
//! dropping it could open a hole a body falls through. [`TriMesh::new`] refuses it, naming the
//! triangle, so the mesh is fixed where it is made.

use crate::collision::bvh::Bvh;
use crate::math::{Aabb, Vec3};
use std::collections::HashMap;

/// Fold angle (rad) above which a convex edge is active: 5°, Jolt's default. Gentler folds,
/// like a height field's, act as flat.
pub const ACTIVE_EDGE_ANGLE: f32 = 5.0 * std::f32::consts::PI / 180.0;

/// Fold angle (rad) above which an edge folding towards the front is concave (module docs):
/// 0.5°, the narrowphase's coplanar angle, so a flat mesh's rounding never counts.
pub const CONCAVE_EDGE_ANGLE: f32 = 0.5 * std::f32::consts::PI / 180.0;

/// `|a × b|²` (m⁴) under which a triangle counts as zero area: it is `4 · area²`.
const DEGENERATE_CROSS_SQUARED: f32 = 1.0e-20;

/// A static triangle mesh; see the module documentation. Build with [`TriMesh::new`].
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// Unit front normal of each triangle.
    normals: Vec<Vec3>,
    /// Bounds of each triangle, in the mesh frame.
    triangle_aabbs: Vec<Aabb>,
    bvh: Bvh,
    /// Bit `e` set when edge `e` (from vertex `e` to vertex `(e + 1) % 3` of the triangle) is
    /// active.
    active_edges: Vec<u8>,
    /// Bit `e` set when edge `e` is concave.
    concave_edges: Vec<u8>,
    /// Farthest vertex from the mesh origin (m).
    bounding_radius: f32,
}

/// Why a triangle mesh could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TriMeshError {
    #[error("the mesh has no triangles; give at least one")]
    Empty,
    #[error("vertex {index} is not finite (NaN or infinity)")]
    NonFiniteVertex { index: usize },
    #[error("triangle {triangle} refers to vertex {index}, but there are only {vertex_count}")]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("triangle {triangle} has zero area (repeated or collinear vertices); remove it")]
    DegenerateTriangle { triangle: usize },
    #[error("the index list has {0} entries, not a multiple of 3")]
    IndicesNotTriangles(usize),
}

impl TriMesh {
    /// Checks the input, then builds the BVH and the edge adjacency.
    pub fn new(vertices: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self, TriMeshError> {
        if triangles.is_empty() {
            return Err(TriMeshError::Empty);
        }
        if let Some(index) = vertices.iter().position(|v| !v.is_finite()) {
            return Err(TriMeshError::NonFiniteVertex { index });
        }
        let mut normals = Vec::with_capacity(triangles.len());
        for (triangle, indices) in triangles.iter().enumerate() {
            if let Some(&index) = indices.iter().find(|&&i| i as usize >= vertices.len()) {
                return Err(TriMeshError::IndexOutOfRange {
                    triangle,
                    index,
                    vertex_count: vertices.len(),
                });
            }
            let [a, b, c] = indices.map(|i| vertices[i as usize]);
            let cross = (b - a).cross(c - a);
            if cross.length_squared() <= DEGENERATE_CROSS_SQUARED
                || indices[0] == indices[1]
                || indices[1] == indices[2]
                || indices[0] == indices[2]
            {
                return Err(TriMeshError::DegenerateTriangle { triangle });
            }
            normals.push(cross.normalize());
        }
        let triangle_aabbs: Vec<Aabb> = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| vertices[i as usize]);
                Aabb::new(a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        let bvh = Bvh::build(&triangle_aabbs);
        let (active_edges, concave_edges) = edge_kinds(&vertices, &triangles, &normals);
        let bounding_radius = vertices.iter().map(|v| v.length()).fold(0.0, f32::max);
        Ok(Self {
            vertices,
            triangles,
            normals,
            triangle_aabbs,
            bvh,
            active_edges,
            concave_edges,
            bounding_radius,
        })
    }

    /// Distance from the mesh origin to its farthest vertex (m).
    pub fn bounding_radius(&self) -> f32 {
        self.bounding_radius
    }

    /// A mesh from a flat index list, three indices per triangle.
    pub fn from_flat_indices(vertices: Vec<Vec3>, indices: &[u32]) -> Result<Self, TriMeshError> {
        if !indices.len().is_multiple_of(3) {
            return Err(TriMeshError::IndicesNotTriangles(indices.len()));
        }
        let triangles = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        Self::new(vertices, triangles)
    }

    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    pub fn triangle_aabbs(&self) -> &[Aabb] {
        &self.triangle_aabbs
    }

    /// Bounds of the whole mesh, in its frame.
    pub fn local_aabb(&self) -> Aabb {
        self.bvh
            .root_aabb()
            .expect("a mesh has at least one triangle (checked in new)")
    }

    /// Triangle `index` as the narrowphase uses it.
    pub fn triangle(&self, index: u32) -> Triangle {
        let i = index as usize;
        Triangle {
            vertices: self.triangles[i].map(|v| self.vertices[v as usize]),
            normal: self.normals[i],
            active_edges: self.active_edges[i],
            concave_edges: self.concave_edges[i],
        }
    }
}

/// One triangle of a mesh, in the mesh frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    pub vertices: [Vec3; 3],
    /// Unit front normal.
    pub normal: Vec3,
    /// Bit `e` set when edge `e` (vertex `e` to `(e + 1) % 3`) is active (module docs).
    pub active_edges: u8,
    /// Bit `e` set when edge `e` is concave (module docs): contacts may reach past it.
    pub concave_edges: u8,
}

impl Triangle {
    /// True when edge `e` is active.
    #[inline]
    pub fn edge_is_active(&self, edge: usize) -> bool {
        self.active_edges & (1 << edge) != 0
    }

    /// True when edge `e` is concave.
    #[inline]
    pub fn edge_is_concave(&self, edge: usize) -> bool {
        self.concave_edges & (1 << edge) != 0
    }

    /// A vertex may push sideways when either of its two edges in this triangle may.
    #[inline]
    pub fn vertex_is_active(&self, vertex: usize) -> bool {
        self.edge_is_active(vertex) || self.edge_is_active((vertex + 2) % 3)
    }
}

/// The active-edge and concave-edge bits of every triangle (module docs).
fn edge_kinds(vertices: &[Vec3], triangles: &[[u32; 3]], normals: &[Vec3]) -> (Vec<u8>, Vec<u8>) {
    // Undirected edge → the (triangle, edge) slots using it. Only looked up, never iterated,
    // so the hash order cannot leak into the result.
    let mut users: HashMap<(u32, u32), Vec<(usize, usize)>> = HashMap::new();
    for (triangle, indices) in triangles.iter().enumerate() {
        for edge in 0..3 {
            let (i, j) = (indices[edge], indices[(edge + 1) % 3]);
            users
                .entry((i.min(j), i.max(j)))
                .or_default()
                .push((triangle, edge));
        }
    }
    let fold_sine_limit = ACTIVE_EDGE_ANGLE.sin();
    let concave_sine_limit = CONCAVE_EDGE_ANGLE.sin();
    triangles
        .iter()
        .enumerate()
        .map(|(triangle, indices)| {
            let (mut bits, mut concave) = (0u8, 0u8);
            for edge in 0..3 {
                let (i, j) = (indices[edge], indices[(edge + 1) % 3]);
                let slots = &users[&(i.min(j), i.max(j))];
                let [first, second] = slots[..] else {
                    // Boundary or non-manifold edge: anything may touch it from the side.
                    bits |= 1 << edge;
                    continue;
                };
                let (neighbour, neighbour_edge) = if first.0 == triangle { second } else { first };
                // The neighbour's vertex off the shared edge, as seen from this triangle: its
                // height over this triangle's plane, relative to its distance from the edge,
                // is the sine of the fold (negative = folds away from the front = convex).
                let opposite = vertices[triangles[neighbour][(neighbour_edge + 2) % 3] as usize];
                let start = vertices[i as usize];
                let direction = (vertices[j as usize] - start).normalize();
                let offset = opposite - start;
                let across = offset - direction * offset.dot(direction);
                let fold_sine = normals[triangle].dot(across) / across.length();
                if fold_sine < -fold_sine_limit {
                    bits |= 1 << edge;
                }
                if fold_sine > concave_sine_limit {
                    concave |= 1 << edge;
                }
            }
            (bits, concave)
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vec3;

    /// Two triangles sharing the edge 1–2, the second folded down by `drop` at its far vertex.
    fn hinge(drop: f32) -> TriMesh {
        let vertices = vec![
            vec3(0.0, 0.0, 0.0),
            vec3(1.0, 0.0, 1.0),
            vec3(1.0, 0.0, 0.0),
            vec3(2.0, -drop, 1.0),
        ];
        TriMesh::new(vertices, vec![[0, 1, 2], [2, 1, 3]]).unwrap()
    }

    #[test]
    fn flat_shared_edges_are_inactive_and_boundaries_active() {
        let mesh = hinge(0.0);
        // Triangle 0's edge 1 (vertex 1 → 2) and triangle 1's edge 0 (2 → 1) are shared.
        assert_eq!(mesh.triangle(0).active_edges, 0b101);
        assert_eq!(mesh.triangle(1).active_edges, 0b110);
        assert!((mesh.triangle(0).normal - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn convex_folds_beyond_the_angle_are_active_concave_ones_not() {
        // Folding down by 45° (convex seen from above): active on both sides.
        let convex = hinge(1.0);
        assert_eq!(convex.triangle(0).active_edges, 0b111);
        assert_eq!(convex.triangle(1).active_edges, 0b111);
        // Folding up (a valley): inactive.
        let concave = hinge(-1.0);
        assert_eq!(concave.triangle(0).active_edges, 0b101);
        // A 2° fold stays inactive.
        let gentle = hinge((2.0f32).to_radians().tan());
        assert_eq!(gentle.triangle(0).active_edges, 0b101);
    }

    #[test]
    fn only_valleys_beyond_half_a_degree_are_concave() {
        // The shared edge: triangle 0's edge 1, triangle 1's edge 0.
        let valley = hinge(-1.0);
        assert_eq!(valley.triangle(0).concave_edges, 0b010);
        assert_eq!(valley.triangle(1).concave_edges, 0b001);
        let gentle_valley = hinge(-(1.0f32).to_radians().tan());
        assert_eq!(gentle_valley.triangle(0).concave_edges, 0b010);
        for flat_or_convex in [
            0.0,
            (0.3f32).to_radians().tan(),
            -(0.3f32).to_radians().tan(),
            1.0,
        ] {
            let mesh = hinge(flat_or_convex);
            assert_eq!(mesh.triangle(0).concave_edges, 0, "drop {flat_or_convex}");
            assert_eq!(mesh.triangle(1).concave_edges, 0, "drop {flat_or_convex}");
        }
    }

    #[test]
    fn bad_input_names_the_problem() {
        let square = || vec![Vec3::ZERO, Vec3::X, Vec3::Z];
        assert_eq!(TriMesh::new(square(), vec![]), Err(TriMeshError::Empty));
        assert_eq!(
            TriMesh::new(square(), vec![[0, 2, 1], [0, 1, 3]]),
            Err(TriMeshError::IndexOutOfRange {
                triangle: 1,
                index: 3,
                vertex_count: 3
            })
        );
        assert_eq!(
            TriMesh::new(vec![Vec3::ZERO, Vec3::X, 2.0 * Vec3::X], vec![[0, 1, 2]]),
            Err(TriMeshError::DegenerateTriangle { triangle: 0 })
        );
        assert_eq!(
            TriMesh::new(square(), vec![[0, 0, 1]]),
            Err(TriMeshError::DegenerateTriangle { triangle: 0 })
        );
        assert_eq!(
            TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::NAN], vec![[0, 1, 2]]),
            Err(TriMeshError::NonFiniteVertex { index: 2 })
        );
        assert_eq!(
            TriMesh::from_flat_indices(square(), &[0, 2]),
            Err(TriMeshError::IndicesNotTriangles(2))
        );
    }
}
