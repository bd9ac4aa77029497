//! Meshes of the shapes, built on the CPU once and instanced: a box of half extent 1 (scaled per
//! instance), a sphere of radius 1 (scaled), a capsule per distinct radius and half height (a
//! capsule does not scale: its caps would turn into ellipsoids), a unit segment for lines, a
//! cross for points, and one mesh per convex hull and per triangle mesh, in the shape's own
//! frame.

use std::f32::consts::PI;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

// repr(C) + Pod: uploaded as is into the vertex buffer the mesh shader reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
}

const _: () = assert!(size_of::<Vertex>() == 24);

/// Vertices with triangle indices (solid) and edge indices (wireframe, lines).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    pub vertices: Vec<Vertex>,
    pub triangles: Vec<u32>,
    pub lines: Vec<u32>,
}

/// Segments of a sphere or capsule around its axis, and rings per hemisphere.
const SEGMENTS: u32 = 24;
const RINGS: u32 = 8;
/// The same for a particle of the particle demo: thousands of small spheres, where Mesa's CPU
/// rasterizer spends its time on vertices (1000 particles at 24 × 8: 1.6M triangles with the
/// shadow pass, about 1 frame/s), and the facets of a sphere a few pixels wide do not show.
const PARTICLE_SEGMENTS: u32 = 10;
const PARTICLE_RINGS: u32 = 3;

impl MeshData {
    /// A box from -1 to 1 on each axis, with a flat normal per face.
    pub fn cube() -> Self {
        let mut mesh = MeshData::default();
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let mut normal = Vec3::ZERO;
                normal[axis] = sign;
                // u × v = normal, so the corners below wind counter-clockwise seen from outside.
                let u = Vec3::from_array(std::array::from_fn(|i| {
                    if i == (axis + 1) % 3 { 1.0 } else { 0.0 }
                })) * sign;
                let v = normal.cross(u);
                let base = mesh.vertices.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    mesh.push(normal + a * u + b * v, normal);
                }
                mesh.triangles
                    .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
                mesh.lines.extend([
                    base,
                    base + 1,
                    base + 1,
                    base + 2,
                    base + 2,
                    base + 3,
                    base + 3,
                    base,
                ]);
            }
        }
        mesh
    }

    /// A convex hull in its own frame: each polygon face flat shaded, fanned into triangles,
    /// its outline as lines.
    pub fn hull(hull: &tumble::shape::ConvexHull) -> Self {
        let mut mesh = MeshData::default();
        for face in hull.faces() {
            let base = mesh.vertices.len() as u32;
            let face_loop = hull.face_loop(face);
            for &v in face_loop {
                mesh.push(hull.vertices()[v as usize], face.normal);
            }
            let count = face_loop.len() as u32;
            for k in 1..count - 1 {
                mesh.triangles.extend([base, base + k, base + k + 1]);
            }
            for k in 0..count {
                mesh.lines.extend([base + k, base + (k + 1) % count]);
            }
        }
        mesh
    }

    /// A static triangle mesh in its own frame, flat shaded: three vertices of its own per
    /// triangle, with the triangle's front normal (a landscape reads by its facets). Its edges
    /// are the wireframe; an edge shared by two triangles is listed twice, which draws the same.
    pub fn trimesh(trimesh: &tumble::shape::TriMesh) -> Self {
        let count = trimesh.triangles().len();
        let mut mesh = MeshData {
            vertices: Vec::with_capacity(3 * count),
            triangles: Vec::with_capacity(3 * count),
            lines: Vec::with_capacity(6 * count),
        };
        for index in 0..count as u32 {
            let triangle = trimesh.triangle(index);
            let base = mesh.vertices.len() as u32;
            for corner in triangle.vertices {
                mesh.push(corner, triangle.normal);
            }
            mesh.triangles.extend([base, base + 1, base + 2]);
            mesh.lines
                .extend([base, base + 1, base + 1, base + 2, base + 2, base]);
        }
        mesh
    }

    /// A sphere of radius 1.
    pub fn sphere() -> Self {
        Self::capsule(1.0, 0.0)
    }

    /// A coarser sphere of radius 1, for the particle demo's particles.
    pub fn particle() -> Self {
        Self::revolved(1.0, 0.0, PARTICLE_SEGMENTS, PARTICLE_RINGS)
    }

    /// A capsule along Y: the segment from -`half_height` to `half_height` swept by a ball of
    /// `radius` (m), as [`tumble::shape::Capsule`]. With `half_height` 0 it is a sphere.
    pub fn capsule(radius: f32, half_height: f32) -> Self {
        Self::revolved(radius, half_height, SEGMENTS, RINGS)
    }

    /// A capsule of `segments` around its axis and `rings` per hemisphere.
    fn revolved(radius: f32, half_height: f32, segments: u32, rings_per_cap: u32) -> Self {
        let mut mesh = MeshData::default();
        // Latitude rings from the south pole to the north pole; the two equator rings coincide
        // for a sphere and are `2 * half_height` apart for a capsule (the cylinder between).
        let rings = 2 * rings_per_cap + 2;
        for ring in 0..rings {
            let (latitude, shift) = if ring <= rings_per_cap {
                (
                    -PI / 2.0 + PI / 2.0 * ring as f32 / rings_per_cap as f32,
                    -half_height,
                )
            } else {
                (
                    PI / 2.0 * (ring - rings_per_cap - 1) as f32 / rings_per_cap as f32,
                    half_height,
                )
            };
            for segment in 0..=segments {
                let longitude = 2.0 * PI * segment as f32 / segments as f32;
                let normal = Vec3::new(
                    latitude.cos() * longitude.sin(),
                    latitude.sin(),
                    latitude.cos() * longitude.cos(),
                );
                mesh.push(normal * radius + Vec3::Y * shift, normal);
            }
        }
        let row = segments + 1;
        for ring in 0..rings - 1 {
            for segment in 0..segments {
                let a = ring * row + segment;
                let (b, c, d) = (a + 1, a + row, a + row + 1);
                mesh.triangles.extend([a, b, d, a, d, c]);
                // Wireframe: meridians and parallels, not the diagonals.
                mesh.lines.extend([a, b, a, c]);
            }
        }
        mesh
    }

    /// The segment from the origin to +Y (1 m), drawn as a line and scaled per instance.
    pub fn segment() -> Self {
        MeshData {
            vertices: vec![
                Vertex {
                    position: [0.0; 3],
                    normal: [0.0, 1.0, 0.0],
                },
                Vertex {
                    position: [0.0, 1.0, 0.0],
                    normal: [0.0, 1.0, 0.0],
                },
            ],
            triangles: Vec::new(),
            lines: vec![0, 1],
        }
    }

    /// Three segments from -1 to 1 along the axes, lines only: a point that reads as one from
    /// every side (a constraint's anchor).
    pub fn cross() -> Self {
        let mut mesh = MeshData::default();
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            let base = mesh.vertices.len() as u32;
            mesh.push(-axis, axis);
            mesh.push(axis, axis);
            mesh.lines.extend([base, base + 1]);
        }
        mesh
    }

    fn push(&mut self, position: Vec3, normal: Vec3) {
        self.vertices.push(Vertex {
            position: position.to_array(),
            normal: normal.to_array(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle winds counter-clockwise seen from outside: its geometric normal points
    /// the way of its vertex normals (back faces are culled, so a wrong winding hides faces).
    fn assert_outward(mesh: &MeshData) {
        for t in mesh.triangles.chunks_exact(3) {
            let t: [u32; 3] = t.try_into().unwrap();
            let p = t.map(|i| Vec3::from_array(mesh.vertices[i as usize].position));
            let n = t.map(|i| Vec3::from_array(mesh.vertices[i as usize].normal));
            let face = (p[1] - p[0]).cross(p[2] - p[0]);
            // Triangles at the poles are degenerate (their corners coincide up to rounding).
            if face.length() > 1e-6 {
                assert!(face.dot(n[0] + n[1] + n[2]) > 0.0, "inward triangle {t:?}");
            }
        }
    }

    #[test]
    fn cube_has_a_flat_face_per_side() {
        let cube = MeshData::cube();
        assert_eq!(cube.vertices.len(), 24);
        assert_eq!(cube.triangles.len(), 36);
        assert_outward(&cube);
        for v in &cube.vertices {
            assert!(v.position.iter().all(|x| x.abs() == 1.0));
        }
    }

    #[test]
    fn capsule_spans_its_height() {
        let capsule = MeshData::capsule(0.25, 0.5);
        assert_outward(&capsule);
        let ys = capsule.vertices.iter().map(|v| v.position[1]);
        let (low, high) = ys.fold((f32::MAX, f32::MIN), |(l, h), y| (l.min(y), h.max(y)));
        assert!((low + 0.75).abs() < 1e-6 && (high - 0.75).abs() < 1e-6);
        assert_eq!(capsule.lines.len() % 2, 0);
    }

    #[test]
    fn trimesh_is_flat_shaded_per_triangle() {
        // Two triangles sharing an edge, one folded up: each keeps its own normal.
        let vertices = vec![
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 1.0, -1.0),
        ];
        let trimesh = tumble::shape::TriMesh::new(vertices, vec![[0, 1, 2], [1, 3, 2]]).unwrap();
        let mesh = MeshData::trimesh(&trimesh);
        assert_eq!(mesh.vertices.len(), 6);
        assert_eq!(mesh.triangles.len(), 6);
        assert_eq!(mesh.lines.len(), 12);
        assert_outward(&mesh);
        assert_eq!(mesh.vertices[0].normal, [0.0, 1.0, 0.0]);
        assert_ne!(mesh.vertices[3].normal, mesh.vertices[0].normal);
    }

    #[test]
    fn sphere_vertices_lie_on_the_unit_sphere() {
        for sphere in [MeshData::sphere(), MeshData::particle()] {
            assert_outward(&sphere);
            for v in &sphere.vertices {
                assert!((Vec3::from_array(v.position).length() - 1.0).abs() < 1e-5);
            }
        }
        // The particle's sphere costs a sixth of the triangles.
        let triangles = |mesh: MeshData| mesh.triangles.len() / 3;
        assert_eq!(triangles(MeshData::sphere()), 17 * 24 * 2);
        assert_eq!(triangles(MeshData::particle()), 7 * 10 * 2);
    }
}
