//! Uniform grid broadphase, rebuilt every frame (the CPU form of Bullet 3's
//! `b3GpuGridBroadphase` and of the particle pipeline's grid).
//!
//! Each box is entered in every cell it touches as a (cell key, body) entry; the entries are
//! sorted, and the boxes sharing a cell are tested against each other. Two boxes can share
//! several cells, so a pair is reported only by the cell holding the lower corner of the two
//! boxes' intersection, which lies in exactly one cell that both boxes touch.
//!
//! Rebuilt, not incremental: the rebuild is one sort of a few entries per box and does not
//! depend on how many boxes moved, it needs no per-cell lists kept across frames, and it is the
//! form a GPU runs (sort by cell, then scan). An incremental grid saves the sort when few boxes
//! move, but the pairs still have to be found again in every cell a moved box touches.
//!
//! A box touching more than [`MAX_CELLS_PER_BOX`] cells (a ground slab, a plane) would flood
//! the grid; such boxes are kept aside and tested against every box instead.

use super::{AabbError, PairFinder, check_aabbs};
use crate::math::{Aabb, Vec3};
use crate::stages::pairs::pair_key;

/// More cells than this and a box is tested against all boxes instead of being binned.
pub const MAX_CELLS_PER_BOX: u64 = 64;

/// Cell coordinates are clamped to [-2^20, 2^20) so that three of them pack into one `u64` key; cells
/// past that range merge, which costs speed, never pairs.
const CELL_LIMIT: i64 = 1 << 20;

#[derive(Clone, Debug, Default)]
pub struct UniformGrid {
    /// Edge of a cell (m); `None`: each frame, the mean of the boxes' longest edges, so that a
    /// typical box touches at most 8 cells.
    pub cell_size: Option<f32>,
    /// (cell key, body), sorted.
    entries: Vec<(u64, u32)>,
    /// Boxes over [`MAX_CELLS_PER_BOX`] cells.
    oversized: Vec<u32>,
}

impl UniformGrid {
    pub fn new(cell_size: Option<f32>) -> Self {
        Self {
            cell_size,
            ..Self::default()
        }
    }
}

/// The cell of `point`: `floor(point / size)`, clamped.
#[inline]
fn cell_of(point: Vec3, inverse_size: f32) -> [i64; 3] {
    let scaled = point * inverse_size;
    // `as` saturates; the clamp keeps keys packable.
    [scaled.x, scaled.y, scaled.z].map(|c| (c.floor() as i64).clamp(-CELL_LIMIT, CELL_LIMIT - 1))
}

#[inline]
fn cell_key(cell: [i64; 3]) -> u64 {
    // 21 bits per axis after the offset to 0..2^21.
    let bits = |c: i64| (c + CELL_LIMIT) as u64;
    (bits(cell[0]) << 42) | (bits(cell[1]) << 21) | bits(cell[2])
}

impl PairFinder for UniformGrid {
    fn name(&self) -> &'static str {
        "grid"
    }

    fn update(&mut self, aabbs: &[Aabb], pairs: &mut Vec<u64>) -> Result<(), AabbError> {
        check_aabbs(aabbs)?;
        pairs.clear();
        self.entries.clear();
        self.oversized.clear();
        if aabbs.is_empty() {
            return Ok(());
        }
        let size = self.cell_size.unwrap_or_else(|| {
            let total: f64 = aabbs
                .iter()
                .map(|aabb| f64::from((aabb.max - aabb.min).max_element()))
                .sum();
            (total / aabbs.len() as f64) as f32
        });
        // Points (zero-size boxes only) or a bad setting: any positive size is correct.
        let size = if size.is_finite() && size > 0.0 {
            size
        } else {
            1.0
        };
        let inverse_size = 1.0 / size;

        for (body, aabb) in aabbs.iter().enumerate() {
            let (low, high) = (
                cell_of(aabb.min, inverse_size),
                cell_of(aabb.max, inverse_size),
            );
            let cells: u64 = (0..3)
                .map(|axis| (high[axis] - low[axis] + 1) as u64)
                .product();
            if cells > MAX_CELLS_PER_BOX {
                self.oversized.push(body as u32);
                continue;
            }
            for x in low[0]..=high[0] {
                for y in low[1]..=high[1] {
                    for z in low[2]..=high[2] {
                        self.entries.push((cell_key([x, y, z]), body as u32));
                    }
                }
            }
        }
        // Distinct entries: the unstable sort is deterministic.
        self.entries.sort_unstable();

        let mut start = 0;
        while start < self.entries.len() {
            let key = self.entries[start].0;
            let mut end = start + 1;
            while end < self.entries.len() && self.entries[end].0 == key {
                end += 1;
            }
            let cell = &self.entries[start..end];
            for (i, &(_, a)) in cell.iter().enumerate() {
                let box_a = &aabbs[a as usize];
                for &(_, b) in &cell[i + 1..] {
                    let box_b = &aabbs[b as usize];
                    if box_a.overlaps(box_b)
                        && cell_key(cell_of(box_a.min.max(box_b.min), inverse_size)) == key
                    {
                        pairs.push(pair_key(a, b));
                    }
                }
            }
            start = end;
        }

        for &a in &self.oversized {
            let box_a = &aabbs[a as usize];
            for (b, box_b) in aabbs.iter().enumerate() {
                let b = b as u32;
                // Two oversized boxes meet twice here: the lower index reports.
                let other_oversized = self.oversized.binary_search(&b).is_ok();
                if b != a && (!other_oversized || a < b) && box_a.overlaps(box_b) {
                    pairs.push(pair_key(a, b));
                }
            }
        }
        // Cells come in key order, not pair order.
        pairs.sort_unstable();
        Ok(())
    }
}
