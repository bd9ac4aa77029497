//! One-axis sweep-and-prune (sort and sweep): boxes sorted by their lower bound on one axis;
//! each box is tested against the boxes that start before it ends on that axis.
//!
//! The sort is incremental: the order of the last frame is kept and re-sorted by insertion sort,
//! which costs O(n + swaps), and boxes move little from frame to frame, so the swaps are few
//! (Baraff's coherence argument behind Bullet's `btAxisSweep3`). The sweep that finds the pairs
//! is redone each frame: tracking pairs through the swaps, as the three-axis SAP does, needs
//! all three axes sorted. The axis is the one along which the box centres spread most, chosen
//! when the body count changes and then kept, so the kept order stays useful.

use super::{AabbError, PairFinder, check_aabbs};
use crate::math::Aabb;
use crate::stages::pairs::pair_key;

#[derive(Clone, Debug, Default)]
pub struct SweepAndPrune {
    /// 0, 1 or 2 (x, y, z).
    axis: usize,
    /// (box, body), sorted by the box's lower bound on the axis, then body, from the last
    /// frame. The boxes are copied in sorted order so that the sweep reads memory in order
    /// instead of jumping through the caller's array.
    order: Vec<(Aabb, u32)>,
}

impl SweepAndPrune {
    pub fn new() -> Self {
        Self::default()
    }

    /// The axis along which the box centres have the largest variance.
    fn widest_axis(aabbs: &[Aabb]) -> usize {
        let n = aabbs.len().max(1) as f64;
        let mut mean = [0.0f64; 3];
        let mut square = [0.0f64; 3];
        for aabb in aabbs {
            let center = aabb.center();
            for axis in 0..3 {
                let c = f64::from(center[axis]);
                mean[axis] += c / n;
                square[axis] += c * c / n;
            }
        }
        let variance = |axis: usize| square[axis] - mean[axis] * mean[axis];
        (0..3)
            .max_by(|&a, &b| variance(a).total_cmp(&variance(b)).then(b.cmp(&a)))
            .unwrap_or(0)
    }
}

impl PairFinder for SweepAndPrune {
    fn name(&self) -> &'static str {
        "sap"
    }

    fn update(&mut self, aabbs: &[Aabb], pairs: &mut Vec<u64>) -> Result<(), AabbError> {
        check_aabbs(aabbs)?;
        pairs.clear();
        let rebuilt = self.order.len() != aabbs.len();
        if rebuilt {
            self.axis = Self::widest_axis(aabbs);
            self.order.clear();
            self.order
                .extend((0..aabbs.len() as u32).map(|body| (Aabb::default(), body)));
        }
        let axis = self.axis;
        for entry in &mut self.order {
            entry.0 = aabbs[entry.1 as usize];
        }
        // Sorted by (bound, body): a total order, so the result is unique.
        let before = |a: &(Aabb, u32), b: &(Aabb, u32)| {
            let (start_a, start_b) = (a.0.min[axis], b.0.min[axis]);
            start_a < start_b || (start_a == start_b && a.1 < b.1)
        };
        if rebuilt {
            // No coherence to exploit: a full sort, not an O(n²) insertion sort.
            self.order.sort_unstable_by(|a, b| {
                a.0.min[axis].total_cmp(&b.0.min[axis]).then(a.1.cmp(&b.1))
            });
        }
        for i in 1..self.order.len() {
            let entry = self.order[i];
            let mut j = i;
            while j > 0 && before(&entry, &self.order[j - 1]) {
                self.order[j] = self.order[j - 1];
                j -= 1;
            }
            self.order[j] = entry;
        }

        for (i, (box_a, a)) in self.order.iter().enumerate() {
            let end = box_a.max[axis];
            for (box_b, b) in &self.order[i + 1..] {
                // Sorted by start: no later box can reach back to this one.
                if box_b.min[axis] > end {
                    break;
                }
                if box_a.overlaps(box_b) {
                    pairs.push(pair_key(*a, *b));
                }
            }
        }
        pairs.sort_unstable();
        Ok(())
    }
}
