//! Broadphases for comparison, after Bullet's CDTestFramework: the two-tree DBVT of the step
//! beside a uniform grid, a one-axis sweep-and-prune and brute force, all behind one trait,
//! [`PairFinder`], so that `tumble bench broadphase` drives them alike and a test checks that
//! they find the same pairs.
//!
//! Contract of [`PairFinder::update`]: given this frame's AABBs (indexed by body), write the
//! keys ([`pair_key`]) of the pairs whose AABBs overlap or touch ([`Aabb::overlaps`]), each
//! once, sorted ascending. The DBVT with the engine's fat margins finds a superset (pairs of
//! fat AABBs); [`DbvtFinder::exact`] runs it with no fattening and then finds exactly this set.
//!
//! | finder | state kept between frames | cost per frame |
//! |---|---|---|
//! | [`DbvtFinder`] | the trees, the pairs | re-insert escaped proxies, query moved ones |
//! | [`UniformGrid`] | buffers only (rebuilt) | sort (cell, body) entries, test within cells |
//! | [`SweepAndPrune`] | the order along one axis | insertion sort (coherent), one sweep |
//! | [`BruteForce`] | nothing | n (n − 1) / 2 box tests |

mod grid;
mod sap;
pub mod scene;

pub use grid::UniformGrid;
pub use sap::SweepAndPrune;

use super::Broadphase;
use crate::math::Aabb;
use crate::stages::pairs::pair_key;

/// A broadphase that turns a frame's AABBs into sorted pair keys; see the module documentation.
pub trait PairFinder {
    /// Short name for tables: `dbvt`, `grid`, `sap`, `brute-force`.
    fn name(&self) -> &'static str;

    /// This frame's AABBs, indexed by body (the count may change between frames), in; the
    /// sorted keys of the overlapping pairs into `pairs` (cleared first).
    fn update(&mut self, aabbs: &[Aabb], pairs: &mut Vec<u64>) -> Result<(), AabbError>;
}

/// An AABB no broadphase can sort or bin.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum AabbError {
    #[error("AABB of body {body} is not finite: {aabb:?}")]
    NotFinite { body: usize, aabb: Aabb },
    #[error("AABB of body {body} has min > max on some axis: {aabb:?}")]
    Inverted { body: usize, aabb: Aabb },
}

/// Checks every AABB, naming the first bad one.
pub fn check_aabbs(aabbs: &[Aabb]) -> Result<(), AabbError> {
    for (body, aabb) in aabbs.iter().enumerate() {
        if !(aabb.min.is_finite() && aabb.max.is_finite()) {
            return Err(AabbError::NotFinite { body, aabb: *aabb });
        }
        if aabb.min.cmpgt(aabb.max).any() {
            return Err(AabbError::Inverted { body, aabb: *aabb });
        }
    }
    Ok(())
}

/// The step's broadphase ([`Broadphase`]) with every body in the moving tree.
#[derive(Clone, Debug)]
pub struct DbvtFinder {
    broadphase: Broadphase,
    name: &'static str,
}

impl DbvtFinder {
    /// The engine's default fat margin and look-ahead: finds every overlapping pair and some
    /// pairs of fat AABBs besides, as in the step.
    pub fn fat() -> Self {
        Self {
            broadphase: Broadphase::new(),
            name: "dbvt",
        }
    }

    /// No margin and no look-ahead: a proxy's box is its AABB, so the pairs are exactly the
    /// overlapping ones (every moved proxy is re-inserted each frame).
    pub fn exact() -> Self {
        let mut broadphase = Broadphase::new();
        broadphase.fat_margin = 0.0;
        broadphase.fat_lookahead = 0.0;
        Self {
            broadphase,
            name: "dbvt-exact",
        }
    }
}

impl PairFinder for DbvtFinder {
    fn name(&self) -> &'static str {
        self.name
    }

    fn update(&mut self, aabbs: &[Aabb], pairs: &mut Vec<u64>) -> Result<(), AabbError> {
        check_aabbs(aabbs)?;
        let bodies = &mut self.broadphase;
        // Bodies are 0..n: drop those past the new count, add the new ones.
        let mut count = bodies.len();
        while count > aabbs.len() {
            count -= 1;
            bodies.remove(count as u32);
        }
        for (body, aabb) in aabbs.iter().enumerate().skip(count) {
            bodies.insert(body as u32, *aabb, true);
        }
        bodies.update(aabbs);
        bodies.find_pairs(pairs);
        Ok(())
    }
}

/// Every pair tested: the reference, O(n²).
#[derive(Clone, Copy, Debug, Default)]
pub struct BruteForce;

impl PairFinder for BruteForce {
    fn name(&self) -> &'static str {
        "brute-force"
    }

    fn update(&mut self, aabbs: &[Aabb], pairs: &mut Vec<u64>) -> Result<(), AabbError> {
        check_aabbs(aabbs)?;
        pairs.clear();
        // Lower index outer, higher inner: the keys come out sorted.
        for (a, box_a) in aabbs.iter().enumerate() {
            for (b, box_b) in aabbs.iter().enumerate().skip(a + 1) {
                if box_a.overlaps(box_b) {
                    pairs.push(pair_key(a as u32, b as u32));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
