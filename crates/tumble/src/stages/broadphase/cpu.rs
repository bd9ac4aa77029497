//! The broadphase step on the CPU: overlap queries of the bodies in the move buffer against
//! both trees, in parallel with rayon, merged into last call's pairs.
//!
//! The move buffer is cut into fixed-size tasks, each appending to its own reused buffer, so
//! the threads never share a buffer and nothing needs an atomic. The buffers are concatenated
//! in task order and sorted; because pair keys are unique, the sorted result cannot depend on
//! how the tasks were scheduled or on the number of threads. The merge with the kept pairs is
//! one sequential pass over sorted lists, so it cannot depend on them either.

use rayon::prelude::*;

use super::{BodyProxy, Broadphase};
use crate::stages::pairs::{pair_bodies, pair_key};

/// Moved bodies per rayon task: fixed, not derived from the thread count, so the per-task
/// buffers hold the same pairs whatever the pool. Large enough that a task's two tree queries
/// per body outweigh rayon's cost of a task, small enough to balance a pile where every body
/// moves over many cores.
const MOVED_PER_TASK: usize = 64;

impl Broadphase {
    /// Writes into `out` (cleared first) the keys of all moving × moving and moving × fixed
    /// pairs whose fat AABBs overlap or touch, each once, sorted ascending, and empties the move
    /// buffer. See the module invariants: only the bodies in the move buffer are queried; every
    /// other pair keeps the status it had at the last call.
    pub fn find_pairs(&mut self, out: &mut Vec<u64>) {
        let Self {
            moving,
            fixed,
            proxies,
            move_buffer,
            in_move_buffer,
            pairs,
            new_pairs,
            task_pairs,
            ..
        } = self;
        let task_count = move_buffer.len().div_ceil(MOVED_PER_TASK);
        if task_pairs.len() < task_count {
            task_pairs.resize_with(task_count, Vec::new);
        }
        let task_pairs = &mut task_pairs[..task_count];

        // 1. Every pair with a moved body, found by querying that body's fat AABB.
        let (moving, fixed, proxies, moved) = (&*moving, &*fixed, &*proxies, &**in_move_buffer);
        move_buffer
            .par_chunks(MOVED_PER_TASK)
            .zip(task_pairs.par_iter_mut())
            .for_each(|(bodies, task_pairs)| {
                task_pairs.clear();
                for &body in bodies {
                    // A removed body is in the move buffer only so that its old pairs go.
                    let Some(BodyProxy {
                        proxy,
                        moving: is_moving,
                    }) = proxies[body as usize]
                    else {
                        continue;
                    };
                    let fat = if is_moving {
                        moving.fat_aabb(proxy)
                    } else {
                        fixed.fat_aabb(proxy)
                    };
                    // A pair of two moved bodies is found by both of them (a moved body
                    // queries every tree its partners can be in): only the lower index
                    // reports it. The same rule drops `body` finding itself.
                    let mut report = |other: u32| {
                        if !moved[other as usize] || body < other {
                            task_pairs.push(pair_key(body, other));
                        }
                        true
                    };
                    moving.query(&fat, &mut report);
                    // Fixed × fixed pairs are never wanted.
                    if is_moving {
                        fixed.query(&fat, &mut report);
                    }
                }
            });
        new_pairs.clear();
        for task_pairs in task_pairs.iter() {
            new_pairs.extend_from_slice(task_pairs);
        }
        // An unstable sort is deterministic here: the keys are distinct integers.
        new_pairs.par_sort_unstable();

        // 2. Last call's pairs without a moved body are still pairs (compacted in place), and
        //    the new pairs all have one: the two sorted lists are disjoint, and one merge pass
        //    from the back joins them in `pairs` without a second buffer.
        pairs.retain(|&key| {
            let (low, high) = pair_bodies(key);
            !in_move_buffer[low as usize] && !in_move_buffer[high as usize]
        });
        let mut kept = pairs.len();
        let mut fresh = new_pairs.len();
        pairs.resize(kept + fresh, 0);
        // Invariant: pairs[..kept] and new_pairs[..fresh] are what is left to merge, and
        // pairs[kept + fresh..] is final. Once the new pairs are used up the kept ones are
        // already in place.
        while fresh > 0 {
            let write = kept + fresh - 1;
            if kept > 0 && pairs[kept - 1] > new_pairs[fresh - 1] {
                pairs[write] = pairs[kept - 1];
                kept -= 1;
            } else {
                pairs[write] = new_pairs[fresh - 1];
                fresh -= 1;
            }
        }
        debug_assert!(pairs.windows(2).all(|window| window[0] < window[1]));

        for &body in move_buffer.iter() {
            in_move_buffer[body as usize] = false;
        }
        move_buffer.clear();
        out.clear();
        out.extend_from_slice(pairs);
    }
}
