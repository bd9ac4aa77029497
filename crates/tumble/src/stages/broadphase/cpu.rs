//! The broadphase step on the CPU: overlap queries of every moving proxy against both trees,
//! in parallel with rayon.
//!
//! Bodies are cut into fixed-size tasks, each appending to its own reused buffer, so the
//! threads never share a buffer and nothing needs an atomic. The buffers are concatenated in
//! task order and sorted; because pair keys are unique, the sorted result cannot depend on how
//! the tasks were scheduled or on the number of threads.

use rayon::prelude::*;

use super::{BodyProxy, Broadphase};
use crate::stages::pairs::pair_key;

/// Bodies per rayon task: fixed, not derived from the thread count, so the per-task buffers
/// hold the same pairs whatever the pool. Large enough that a task's two tree queries per
/// moving body outweigh rayon's cost of a task, small enough to balance 2000 bodies over many
/// cores.
const BODIES_PER_TASK: usize = 64;

impl Broadphase {
    /// Writes into `out` (cleared first) the keys of all moving × moving and moving × fixed
    /// pairs whose fat AABBs overlap or touch, each once, sorted ascending. See the module
    /// invariants.
    pub fn find_pairs(&mut self, out: &mut Vec<u64>) {
        let Self {
            moving,
            fixed,
            proxies,
            task_pairs,
            ..
        } = self;
        let task_count = proxies.len().div_ceil(BODIES_PER_TASK);
        if task_pairs.len() < task_count {
            task_pairs.resize_with(task_count, Vec::new);
        }
        let task_pairs = &mut task_pairs[..task_count];

        proxies
            .par_chunks(BODIES_PER_TASK)
            .zip(task_pairs.par_iter_mut())
            .enumerate()
            .for_each(|(task, (task_proxies, pairs))| {
                pairs.clear();
                let first_body = task * BODIES_PER_TASK;
                for (offset, slot) in task_proxies.iter().enumerate() {
                    let Some(BodyProxy {
                        proxy,
                        moving: true,
                    }) = *slot
                    else {
                        continue;
                    };
                    // Lossless: bodies enter the broadphase by u32 index.
                    let body = (first_body + offset) as u32;
                    let fat = moving.fat_aabb(proxy);
                    // Both bodies of a moving × moving pair find each other (and the query
                    // finds `body` itself): only the lower index reports the pair.
                    moving.query(&fat, |other| {
                        if other > body {
                            pairs.push(pair_key(body, other));
                        }
                        true
                    });
                    // Fixed proxies never query, so each moving × fixed pair is found once.
                    fixed.query(&fat, |other| {
                        pairs.push(pair_key(body, other));
                        true
                    });
                }
            });

        out.clear();
        for pairs in task_pairs.iter() {
            out.extend_from_slice(pairs);
        }
        // An unstable sort is deterministic here: the keys are distinct integers.
        out.par_sort_unstable();
        debug_assert!(out.windows(2).all(|window| window[0] < window[1]));
    }
}
