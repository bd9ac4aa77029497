//! A generated landscape: a height field of N × N square cells, each split into two triangles,
//! as a static triangle mesh. About 100 000 triangles at scale 1, like the talk's trimesh demos.
//!
//! The heights are a sum of a few sine waves (rolling hills, slopes up to about 20°), a fixed
//! function of the grid position: the same scale gives the same mesh bit for bit, with no
//! random state to seed. [`Landscape::height_at`] evaluates the *mesh* (the triangles' planes),
//! not the smooth function, so tests can check bodies against the surface they collide with.

use crate::math::Vec3;
use crate::shape::{TriMesh, TriMeshError};

/// Side of a cell (m).
pub const CELL_SIZE: f32 = 1.0;

/// Triangles at scale 1 (two per cell).
pub const TRIANGLES_AT_SCALE_1: f32 = 100_000.0;

/// A height field centred on the origin, `cells × cells` cells of [`CELL_SIZE`].
#[derive(Clone, Debug, PartialEq)]
pub struct Landscape {
    cells: u32,
    /// `(cells + 1)²` heights (m), row by row along +z, each row along +x.
    heights: Vec<f32>,
}

impl Landscape {
    /// About `TRIANGLES_AT_SCALE_1 · scale` triangles, at least one cell. `scale` > 0 and
    /// finite (callers check it: the built-in scenes refuse other scales).
    pub fn new(scale: f32) -> Self {
        let cells = ((TRIANGLES_AT_SCALE_1 * scale / 2.0).sqrt().round() as u32).max(1);
        Self::with_cells(cells)
    }

    /// A landscape of exactly `cells × cells` cells (`cells ≥ 1`).
    pub fn with_cells(cells: u32) -> Self {
        let cells = cells.max(1);
        let mut heights = Vec::with_capacity(((cells + 1) * (cells + 1)) as usize);
        for row in 0..=cells {
            for column in 0..=cells {
                let (x, z) = grid_position(cells, row, column);
                heights.push(hill_height(x, z));
            }
        }
        Self { cells, heights }
    }

    pub fn cells(&self) -> u32 {
        self.cells
    }

    /// Half the side of the square the landscape covers (m).
    pub fn half_size(&self) -> f32 {
        0.5 * self.cells as f32 * CELL_SIZE
    }

    /// The triangle mesh: two triangles per cell, facing +y, the diagonal from the cell's
    /// (-x, -z) corner to its (+x, +z) corner.
    pub fn mesh(&self) -> Result<TriMesh, TriMeshError> {
        let mut vertices = Vec::with_capacity(self.heights.len());
        for row in 0..=self.cells {
            for column in 0..=self.cells {
                let (x, z) = grid_position(self.cells, row, column);
                vertices.push(Vec3::new(x, self.height(row, column), z));
            }
        }
        let index = |row: u32, column: u32| row * (self.cells + 1) + column;
        let mut triangles = Vec::with_capacity(2 * (self.cells * self.cells) as usize);
        for row in 0..self.cells {
            for column in 0..self.cells {
                let low = index(row, column);
                let right = index(row, column + 1);
                let up = index(row + 1, column);
                let diagonal = index(row + 1, column + 1);
                // Counter-clockwise seen from above (+y): (x, z) → (x, z + 1) → (x + 1, z + 1).
                triangles.push([low, up, diagonal]);
                triangles.push([low, diagonal, right]);
            }
        }
        TriMesh::new(vertices, triangles)
    }

    /// Height of the mesh surface above (x, z) (m): the plane of the triangle below that point.
    /// `None` outside the landscape.
    pub fn height_at(&self, x: f32, z: f32) -> Option<f32> {
        let half = self.half_size();
        let u = (x + half) / CELL_SIZE;
        let v = (z + half) / CELL_SIZE;
        let limit = self.cells as f32;
        if !(0.0..=limit).contains(&u) || !(0.0..=limit).contains(&v) {
            return None;
        }
        let column = (u.floor() as u32).min(self.cells - 1);
        let row = (v.floor() as u32).min(self.cells - 1);
        let (s, t) = (u - column as f32, v - row as f32);
        let low = self.height(row, column);
        let right = self.height(row, column + 1);
        let up = self.height(row + 1, column);
        let diagonal = self.height(row + 1, column + 1);
        // The diagonal s = t splits the cell; each half is one plane.
        Some(if t >= s {
            low + s * (diagonal - up) + t * (up - low)
        } else {
            low + s * (right - low) + t * (diagonal - right)
        })
    }

    fn height(&self, row: u32, column: u32) -> f32 {
        self.heights[(row * (self.cells + 1) + column) as usize]
    }
}

/// World (x, z) of a grid vertex (m).
fn grid_position(cells: u32, row: u32, column: u32) -> (f32, f32) {
    let half = 0.5 * cells as f32 * CELL_SIZE;
    (
        column as f32 * CELL_SIZE - half,
        row as f32 * CELL_SIZE - half,
    )
}

/// Rolling hills (m): three waves of 17 to 40 m with 0.3 to 1.2 m amplitude, steepest slope
/// about tan⁻¹(Σ amplitude · 2π / wavelength) ≈ 20°.
fn hill_height(x: f32, z: f32) -> f32 {
    use std::f32::consts::TAU;
    1.2 * (TAU * x / 40.0).sin() * (TAU * z / 33.0).cos()
        + 0.6 * (TAU * (x + z) / 23.0).sin()
        + 0.3 * (TAU * (x - 0.5 * z) / 17.0).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_one_has_about_100k_triangles_and_is_deterministic() {
        let landscape = Landscape::new(1.0);
        let triangles = 2 * landscape.cells() * landscape.cells();
        assert!((99_000..=101_000).contains(&triangles), "{triangles}");
        assert_eq!(Landscape::new(0.01), Landscape::new(0.01));
        let mesh = Landscape::new(0.01).mesh().unwrap();
        assert_eq!(mesh.triangles().len(), 2 * 22 * 22);
        assert!(
            mesh.triangles()
                .iter()
                .enumerate()
                .all(|(i, _)| mesh.triangle(i as u32).normal.y > 0.9)
        );
    }

    #[test]
    fn height_at_lies_on_the_triangles() {
        let landscape = Landscape::with_cells(6);
        let mesh = landscape.mesh().unwrap();
        // At vertices: the stored height; inside a triangle: on its plane.
        for &vertex in mesh.vertices() {
            let height = landscape.height_at(vertex.x, vertex.z).unwrap();
            assert!((height - vertex.y).abs() < 1e-5);
        }
        for index in 0..mesh.triangles().len() as u32 {
            let triangle = mesh.triangle(index);
            let centroid =
                (triangle.vertices[0] + triangle.vertices[1] + triangle.vertices[2]) / 3.0;
            let height = landscape.height_at(centroid.x, centroid.z).unwrap();
            assert!((height - centroid.y).abs() < 1e-5, "triangle {index}");
        }
        assert_eq!(landscape.height_at(100.0, 0.0), None);
    }
}
