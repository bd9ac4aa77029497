//! Broadphase, CPU: two dynamic AABB trees as in the talk's "Dynamic BVH tree Broadphase"
//! slides. `moving` holds dynamic bodies, `fixed` holds static (and, later, sleeping) bodies;
//! a body moves from one tree to the other with [`Broadphase::set_moving`]. Candidate pairs
//! are moving × moving and moving × fixed overlaps; fixed × fixed pairs never need solving and
//! are never looked for.
//!
//! Each body's proxy stores a *fat* AABB: its AABB grown by [`Broadphase::fat_margin`] when it
//! was last (re-)inserted. [`Broadphase::update`] re-inserts a proxy only when the body's AABB
//! has left its fat box, so a body creeping less than the margin costs one containment test.
//!
//! A fast body leaves any fixed margin every step, so a re-inserted proxy's fat AABB also
//! reaches [`Broadphase::fat_lookahead`] times the body's last displacement ahead, on the side
//! it moves to (Box2D v2.4's `b2_aabbMultiplier`): a body falling at a steady speed is then
//! re-inserted (and queried) every few steps instead of every step. Behind the body the box
//! keeps only the margin, so a body that turns back soon gets a box stretched the new way. A
//! proxy whose fat AABB has grown more than [`SHRINK_MARGINS`] margins larger, on some axis,
//! than a fresh one would be (a fast body that slowed down or stopped) is re-inserted to
//! shrink it, so resting bodies keep tight boxes and few spurious pairs.
//!
//! Pairs are found incrementally, with Box2D's *move buffer*. Whether two bodies make a pair
//! depends only on their fat AABBs, on which tree each is in and on both being present, and
//! those change only in [`Broadphase::insert`], [`Broadphase::remove`],
//! [`Broadphase::set_moving`] and a re-insertion by [`Broadphase::update`]. Each of these puts
//! the body in the move buffer. [`Broadphase::find_pairs`] then queries only the moved bodies
//! (against both trees) and keeps every pair of its last result that has no moved body, which
//! is exactly the full result: an unmoved pair's status cannot have changed, and a moved
//! body's query decides all of its pairs afresh. In a settled pile almost no proxy leaves its
//! fat box, so a step costs a merge pass over the pairs instead of two queries per body.
//!
//! The GPU executor ([`gpu`]) rebuilds linear BVHs instead and reports exact AABB overlaps (no
//! fat AABBs), so its pairs are a subset of this broadphase's; its invariants are in its module.
//!
//! Invariants:
//! - Every body is in at most one tree, and after [`Broadphase::update`] each proxy's fat AABB
//!   contains the AABB it was last given. Hence every pair of bodies whose AABBs overlap is
//!   found, whatever the look-ahead: the fat AABBs only add candidates.
//! - The move buffer holds, once each, every body inserted, re-inserted, moved between the
//!   trees or removed since the last [`Broadphase::find_pairs`]; `in_move_buffer[body]` is true
//!   exactly for those bodies.
//! - `pairs` is the last result of [`Broadphase::find_pairs`] (empty before the first call).
//! - [`Broadphase::find_pairs`] returns exactly the keys
//!   ([`pair_key`](crate::stages::pairs::pair_key)) of the body pairs whose fat AABBs overlap
//!   or touch and of which at least one body is moving: each pair once, sorted ascending, no
//!   duplicates. The result is the same as querying every moving body, as the tests check.
//! - That output is bitwise the same for any rayon thread count: tasks only read the trees,
//!   and the sort and merge fix the order however the tasks were scheduled.
//! - Once the buffers have grown to the largest scene seen, a step allocates nothing.

pub mod alternatives;
mod body_lists;
mod cpu;
pub mod gpu;
mod query;

use crate::collision::dbvt::{Dbvt, ProxyId};
use crate::math::{Aabb, Vec3};

/// Default of [`Broadphase::fat_margin`] (m).
pub const DEFAULT_FAT_MARGIN: f32 = 0.1;

/// Default of [`Broadphase::fat_lookahead`] (steps): Box2D v2.4's multiplier. Measured on
/// falling-boxes (300 steps, 1 thread), 2 / 3 / 4 steps gave about 2.3 / 2.1 / 1.8 ms of
/// broadphase for 20.3k / 22.1k / 23.2k pairs (17.4k without look-ahead), and the cheaper
/// broadphase outweighed the narrowphase's extra pairs at each of them.
pub const DEFAULT_FAT_LOOKAHEAD: f32 = 4.0;

/// With a look-ahead, a proxy whose fat AABB is more than this many [`Broadphase::fat_margin`]s
/// larger on some axis than a fresh fat AABB is re-inserted (Box2D v2.4's "huge AABB" test,
/// there 4). Compared by size, not by containment: the trailing side of a fast body's box is
/// up to a few displacements behind the body, and must not count as too large.
pub const SHRINK_MARGINS: f32 = 4.0;

/// Where one body's proxy lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct BodyProxy {
    proxy: ProxyId,
    /// True: in the `moving` tree; false: in the `fixed` tree.
    moving: bool,
}

/// The two-tree broadphase. Bodies are named by their `u32` index; indices need not be dense.
#[derive(Clone, Debug)]
pub struct Broadphase {
    /// How far a proxy's fat AABB reaches past the body's AABB on every side (m); default
    /// [`DEFAULT_FAT_MARGIN`]. Larger: fewer re-insertions, more candidate pairs for the
    /// narrowphase to reject. Applies to proxies (re-)inserted after it is changed.
    pub fat_margin: f32,
    /// How many steps of the body's last displacement a re-inserted proxy's fat AABB reaches
    /// ahead of the body, on the side it moves to; default [`DEFAULT_FAT_LOOKAHEAD`]. 0: the
    /// fat AABB is the AABB grown by [`Self::fat_margin`] on every side. Larger: fewer
    /// re-insertions of fast bodies, more candidate pairs ahead of them.
    pub fat_lookahead: f32,
    moving: Dbvt,
    fixed: Dbvt,
    /// Indexed by body; `None` for an index with no body.
    proxies: Vec<Option<BodyProxy>>,
    /// Indexed by body, as long as `proxies`: the centre of the AABB the body was last given,
    /// from which [`Broadphase::update`] takes its displacement.
    centers: Vec<Vec3>,
    /// Bodies whose pairs may have changed since the last [`Broadphase::find_pairs`], each
    /// once, in the order they were marked (see the module documentation).
    move_buffer: Vec<u32>,
    /// Indexed by body, as long as `proxies`: whether the body is in `move_buffer`. Removed
    /// bodies keep their slot, so every body of a key in `pairs` has one.
    in_move_buffer: Vec<bool>,
    /// The last result of [`Broadphase::find_pairs`], sorted ascending.
    pairs: Vec<u64>,
    /// [`Broadphase::find_pairs`]'s pairs of moved bodies, concatenated and sorted.
    new_pairs: Vec<u64>,
    /// One pair buffer per task of [`Broadphase::find_pairs`]. All buffers here are kept from
    /// step to step so that their capacity is reused.
    task_pairs: Vec<Vec<u64>>,
}

impl Default for Broadphase {
    fn default() -> Self {
        Self::new()
    }
}

impl Broadphase {
    pub fn new() -> Self {
        Self {
            fat_margin: DEFAULT_FAT_MARGIN,
            fat_lookahead: DEFAULT_FAT_LOOKAHEAD,
            moving: Dbvt::new(),
            fixed: Dbvt::new(),
            proxies: Vec::new(),
            centers: Vec::new(),
            move_buffer: Vec::new(),
            in_move_buffer: Vec::new(),
            pairs: Vec::new(),
            new_pairs: Vec::new(),
            task_pairs: Vec::new(),
        }
    }

    /// Adds `body` with AABB `aabb` to the moving or the fixed tree; its fat AABB is `aabb`
    /// grown by [`Self::fat_margin`]. A body already present is replaced.
    pub fn insert(&mut self, body: u32, aabb: Aabb, moving: bool) {
        self.remove(body);
        let index = body as usize;
        if self.proxies.len() <= index {
            self.proxies.resize(index + 1, None);
            self.in_move_buffer.resize(index + 1, false);
            self.centers.resize(index + 1, Vec3::ZERO);
        }
        // No displacement is known yet: the first fat AABB has no look-ahead.
        self.centers[index] = aabb.center();
        let fat = aabb.expanded(self.fat_margin);
        let proxy = self.tree_mut(moving).insert(fat, body);
        self.proxies[index] = Some(BodyProxy { proxy, moving });
        self.mark_moved(body);
    }

    /// Removes `body`; returns false if it was not in the broadphase.
    pub fn remove(&mut self, body: u32) -> bool {
        let Some(BodyProxy { proxy, moving }) = self.proxy(body) else {
            return false;
        };
        self.tree_mut(moving).remove(proxy);
        self.proxies[body as usize] = None;
        // Its pairs must go: find_pairs drops the kept pairs of moved bodies.
        self.mark_moved(body);
        true
    }

    /// Moves `body` to the moving or the fixed tree, keeping its fat AABB (a body that falls
    /// asleep, or wakes up). Returns false if `body` is not in the broadphase.
    pub fn set_moving(&mut self, body: u32, moving: bool) -> bool {
        let Some(current) = self.proxy(body) else {
            return false;
        };
        if current.moving != moving {
            let fat = self.tree(current.moving).fat_aabb(current.proxy);
            self.tree_mut(current.moving).remove(current.proxy);
            let proxy = self.tree_mut(moving).insert(fat, body);
            self.proxies[body as usize] = Some(BodyProxy { proxy, moving });
            // Same fat AABB, but its pairs with fixed bodies appear or go.
            self.mark_moved(body);
        }
        true
    }

    /// Incremental update from this step's AABBs, indexed by body: every proxy whose body's
    /// AABB has left its fat AABB, or whose fat AABB has grown too large (see the module
    /// documentation), is re-inserted with a new fat AABB: the AABB grown by
    /// [`Self::fat_margin`] and reaching [`Self::fat_lookahead`] times the body's displacement
    /// since the last update ahead. Fixed proxies are checked too, so a static body that is
    /// teleported stays correct. Entries of indices with no body are ignored. Returns how many
    /// proxies were re-inserted.
    ///
    /// Sequential: tree updates do not parallelize well (the talk's "tree update hard to
    /// parallelize"), and most bodies stay inside their fat box.
    ///
    /// Panics if `aabbs` is shorter than the highest body index in the broadphase + 1.
    pub fn update(&mut self, aabbs: &[Aabb]) -> usize {
        let Self {
            fat_margin,
            fat_lookahead,
            moving: moving_tree,
            fixed: fixed_tree,
            proxies,
            centers,
            move_buffer,
            in_move_buffer,
            ..
        } = self;
        let (margin, lookahead) = (*fat_margin, *fat_lookahead);
        let mut reinserted = 0;
        for (body, slot) in proxies.iter().enumerate() {
            let Some(BodyProxy { proxy, moving }) = *slot else {
                continue;
            };
            let tree = if moving {
                &mut *moving_tree
            } else {
                &mut *fixed_tree
            };
            let aabb = aabbs[body];
            let center = aabb.center();
            let displacement = center - centers[body];
            centers[body] = center;
            let stored = tree.fat_aabb(proxy);
            // A fixed body does not keep moving: a teleported static body gets no look-ahead,
            // which would stretch its box by four times the jump. (A teleported moving body
            // does, for one step, until the shrink test below catches it.)
            let ahead = if moving {
                lookahead * displacement
            } else {
                Vec3::ZERO
            };
            let fat = predicted_fat_aabb(&aabb, margin, ahead);
            if stored.contains(&aabb)
                && (lookahead == 0.0 || !is_oversized(&stored, &fat, SHRINK_MARGINS * margin))
            {
                continue;
            }
            tree.reinsert(proxy, fat);
            reinserted += 1;
            if !in_move_buffer[body] {
                in_move_buffer[body] = true;
                // Lossless: bodies enter the broadphase by u32 index.
                move_buffer.push(body as u32);
            }
        }
        reinserted
    }

    /// The body's fat AABB, or `None` if it is not in the broadphase.
    pub fn fat_aabb(&self, body: u32) -> Option<Aabb> {
        let BodyProxy { proxy, moving } = self.proxy(body)?;
        Some(self.tree(moving).fat_aabb(proxy))
    }

    /// Whether the body is in the moving tree, or `None` if it is not in the broadphase.
    pub fn is_moving(&self, body: u32) -> Option<bool> {
        self.proxy(body).map(|proxy| proxy.moving)
    }

    /// Number of bodies in the broadphase.
    pub fn len(&self) -> usize {
        self.moving.len() + self.fixed.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Puts `body` in the move buffer, once. `body` must have a slot in `in_move_buffer`.
    fn mark_moved(&mut self, body: u32) {
        let flag = &mut self.in_move_buffer[body as usize];
        if !*flag {
            *flag = true;
            self.move_buffer.push(body);
        }
    }

    fn proxy(&self, body: u32) -> Option<BodyProxy> {
        self.proxies.get(body as usize).copied().flatten()
    }

    fn tree(&self, moving: bool) -> &Dbvt {
        if moving { &self.moving } else { &self.fixed }
    }

    fn tree_mut(&mut self, moving: bool) -> &mut Dbvt {
        if moving {
            &mut self.moving
        } else {
            &mut self.fixed
        }
    }
}

/// `aabb` grown by `margin` on every side and stretched by `ahead` (m) on the side each
/// component of `ahead` points to. Contains `aabb`.
fn predicted_fat_aabb(aabb: &Aabb, margin: f32, ahead: Vec3) -> Aabb {
    let fat = aabb.expanded(margin);
    Aabb::new(
        fat.min + ahead.min(Vec3::ZERO),
        fat.max + ahead.max(Vec3::ZERO),
    )
}

/// Whether `stored` is more than `allowance` (m) larger than `fresh` along some axis.
fn is_oversized(stored: &Aabb, fresh: &Aabb, allowance: f32) -> bool {
    let excess = (stored.max - stored.min) - (fresh.max - fresh.min);
    excess.max_element() > allowance
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::dbvt::tests::TestRng;
    use crate::math::vec3;
    use crate::stages::pairs::{pair_bodies, pair_key};

    /// Runs `find_pairs` inside a rayon pool of `threads` threads.
    fn find_pairs_with_threads(broadphase: &mut Broadphase, threads: usize) -> Vec<u64> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut pairs = Vec::new();
        pool.install(|| broadphase.find_pairs(&mut pairs));
        pairs
    }

    /// All pairs of bodies, at least one moving, whose fat AABBs overlap: the specification.
    fn brute_force_pairs(broadphase: &Broadphase) -> Vec<u64> {
        let bodies: Vec<(u32, Aabb, bool)> = (0..broadphase.proxies.len() as u32)
            .filter_map(|body| {
                Some((
                    body,
                    broadphase.fat_aabb(body)?,
                    broadphase.is_moving(body)?,
                ))
            })
            .collect();
        let mut pairs = Vec::new();
        for (index, &(body_a, aabb_a, moving_a)) in bodies.iter().enumerate() {
            for &(body_b, aabb_b, moving_b) in &bodies[index + 1..] {
                if (moving_a || moving_b) && aabb_a.overlaps(&aabb_b) {
                    pairs.push(pair_key(body_a, body_b));
                }
            }
        }
        pairs.sort_unstable();
        pairs
    }

    /// The pairs found the non-incremental way: every moving body queried against both trees
    /// (the algorithm `find_pairs` replaced). The incremental result must equal it.
    fn full_query_pairs(broadphase: &Broadphase) -> Vec<u64> {
        let mut pairs = Vec::new();
        for (body, slot) in broadphase.proxies.iter().enumerate() {
            let Some(BodyProxy {
                proxy,
                moving: true,
            }) = *slot
            else {
                continue;
            };
            let body = body as u32;
            let fat = broadphase.moving.fat_aabb(proxy);
            broadphase.moving.query(&fat, |other| {
                if other > body {
                    pairs.push(pair_key(body, other));
                }
                true
            });
            broadphase.fixed.query(&fat, |other| {
                pairs.push(pair_key(body, other));
                true
            });
        }
        pairs.sort_unstable();
        pairs
    }

    /// The move buffer is empty and its flags are all clear, as `find_pairs` leaves them.
    fn assert_move_buffer_empty(broadphase: &Broadphase) {
        assert!(broadphase.move_buffer.is_empty());
        assert!(broadphase.in_move_buffer.iter().all(|&moved| !moved));
        assert_eq!(broadphase.in_move_buffer.len(), broadphase.proxies.len());
    }

    fn assert_find_pairs_exact(broadphase: &mut Broadphase) -> Vec<u64> {
        broadphase.moving.validate();
        broadphase.fixed.validate();
        let single = find_pairs_with_threads(broadphase, 1);
        let double = find_pairs_with_threads(broadphase, 2);
        assert_eq!(single, double, "1 and 2 threads disagree");
        assert!(single.windows(2).all(|window| window[0] < window[1]));
        for &key in &single {
            let (low, high) = pair_bodies(key);
            assert!(low < high);
            assert!(
                broadphase.is_moving(low) == Some(true) || broadphase.is_moving(high) == Some(true),
                "fixed × fixed pair {low}, {high}"
            );
        }
        assert_eq!(single, brute_force_pairs(broadphase));
        assert_eq!(single, full_query_pairs(broadphase));
        assert_move_buffer_empty(broadphase);
        single
    }

    /// A random scene of `count` bodies with holes in their indices, a third of them fixed,
    /// stepped a few times: bodies creep or teleport, some swap trees, some leave and return.
    fn run_random_scene(count: usize, seed: u64) {
        let mut rng = TestRng::new(seed);
        // About 1.5 boxes per 10 m³: enough overlaps to make pairs, few enough to stay sparse.
        let world = (count as f32 * 7.0).cbrt().max(2.0);
        let body_count = count + count / 4;
        let mut aabbs = vec![Aabb::default(); body_count];
        let mut present = vec![false; body_count];
        let mut broadphase = Broadphase::new();
        let mut placed = 0;
        while placed < count {
            let body = rng.below(body_count);
            if present[body] {
                continue;
            }
            present[body] = true;
            aabbs[body] = rng.aabb(world);
            broadphase.insert(body as u32, aabbs[body], rng.below(3) != 0);
            placed += 1;
        }
        assert_eq!(broadphase.len(), count);
        let pairs = assert_find_pairs_exact(&mut broadphase);
        let mut total_pairs = pairs.len();

        for _ in 0..4 {
            for body in 0..body_count {
                if !present[body] || broadphase.is_moving(body as u32) != Some(true) {
                    continue;
                }
                let offset = if rng.below(10) == 0 {
                    rng.vec3(-0.5 * world, 0.5 * world)
                } else {
                    // Often within the fat margin, so some proxies stay put and some not.
                    rng.vec3(-0.08, 0.08)
                };
                aabbs[body] = Aabb::new(aabbs[body].min + offset, aabbs[body].max + offset);
            }
            broadphase.update(&aabbs);
            for (body, aabb) in aabbs.iter().enumerate() {
                if let Some(fat) = broadphase.fat_aabb(body as u32) {
                    assert!(fat.contains(aabb), "body {body} escaped its fat AABB");
                }
            }
            // The empty scene has no index to draw from: it stays empty.
            let churn = if body_count == 0 { 0 } else { count / 10 + 1 };
            for _ in 0..churn {
                let body = rng.below(body_count);
                if present[body] {
                    let moving = rng.below(2) == 0;
                    assert!(broadphase.set_moving(body as u32, moving));
                    assert_eq!(broadphase.is_moving(body as u32), Some(moving));
                }
            }
            for _ in 0..churn.div_ceil(2) {
                let body = rng.below(body_count);
                if present[body] {
                    assert!(broadphase.remove(body as u32));
                } else {
                    aabbs[body] = rng.aabb(world);
                    broadphase.insert(body as u32, aabbs[body], rng.below(3) != 0);
                }
                present[body] = !present[body];
            }
            assert_eq!(broadphase.len(), present.iter().filter(|&&p| p).count());
            total_pairs += assert_find_pairs_exact(&mut broadphase).len();
        }
        if count >= 100 {
            assert!(total_pairs > 0, "the scene should make some pairs");
        }
    }

    #[test]
    fn random_scenes_match_brute_force() {
        for (count, seed) in [(0, 1), (1, 2), (2, 3), (100, 4), (2000, 5)] {
            run_random_scene(count, seed);
        }
    }

    /// Many steps of a churning scene, each step's incremental `find_pairs` (on 1, 2 or 3
    /// threads) checked against the full query: bodies creep inside their fat box, leave it,
    /// teleport (fixed ones too), swap trees, are replaced, removed and inserted (sometimes
    /// the same index in one step), the margin changes, and some steps update twice or skip
    /// `find_pairs` so that the move buffer spans several updates.
    #[test]
    fn incremental_pairs_equal_full_query_over_many_steps() {
        const COUNT: usize = 600;
        const STEPS: usize = 150;
        let mut rng = TestRng::new(17);
        let world = (COUNT as f32 * 7.0).cbrt();
        let body_count = COUNT + COUNT / 4;
        let mut aabbs = vec![Aabb::default(); body_count];
        let mut present = vec![false; body_count];
        let mut broadphase = Broadphase::new();
        for body in 0..COUNT {
            present[body] = true;
            aabbs[body] = rng.aabb(world);
            broadphase.insert(body as u32, aabbs[body], rng.below(3) != 0);
        }
        let shift = |aabb: Aabb, offset: Vec3| Aabb::new(aabb.min + offset, aabb.max + offset);
        let mut previous: Vec<u64> = Vec::new();
        let (mut added, mut removed, mut moved_bodies, mut checks) = (0, 0, 0, 0);
        for step in 0..STEPS {
            match step {
                50 => broadphase.fat_margin = 0.0,
                65 => broadphase.fat_margin = 0.25,
                100 => broadphase.fat_lookahead = 0.0,
                125 => broadphase.fat_lookahead = 5.0,
                _ => {}
            }
            let updates = if step % 7 == 3 { 2 } else { 1 };
            for _ in 0..updates {
                for body in 0..body_count {
                    if !present[body] {
                        continue;
                    }
                    let moving = broadphase.is_moving(body as u32) == Some(true);
                    let offset = match rng.below(100) {
                        // Fixed bodies are teleported now and then, and otherwise stay.
                        0 => rng.vec3(-0.3 * world, 0.3 * world),
                        _ if !moving => Vec3::ZERO,
                        // Every fifth body moves steadily, as the look-ahead expects, and
                        // turns back every 30 steps.
                        _ if body % 5 == 0 => {
                            let sign = if (step / 30) % 2 == 0 { 1.0 } else { -1.0 };
                            sign * vec3(0.1, -0.2, 0.1)
                        }
                        1..=20 => rng.vec3(-0.3, 0.3),
                        _ => rng.vec3(-0.03, 0.03),
                    };
                    aabbs[body] = shift(aabbs[body], offset);
                }
                broadphase.update(&aabbs);
            }
            for _ in 0..rng.below(8) {
                let body = rng.below(body_count);
                if present[body] {
                    broadphase.set_moving(body as u32, rng.below(2) == 0);
                }
            }
            for _ in 0..rng.below(6) {
                let body = rng.below(body_count);
                match (present[body], rng.below(3)) {
                    (true, 0) => {
                        // Replaced where it is, possibly into the other tree.
                        broadphase.insert(body as u32, aabbs[body], rng.below(2) == 0);
                    }
                    (true, 1) => {
                        // Removed, and its index reused elsewhere in the same step.
                        assert!(broadphase.remove(body as u32));
                        aabbs[body] = rng.aabb(world);
                        broadphase.insert(body as u32, aabbs[body], rng.below(3) != 0);
                    }
                    (true, _) => {
                        assert!(broadphase.remove(body as u32));
                        present[body] = false;
                    }
                    (false, _) => {
                        aabbs[body] = rng.aabb(world);
                        broadphase.insert(body as u32, aabbs[body], rng.below(3) != 0);
                        present[body] = true;
                    }
                }
            }
            if step % 11 == 5 {
                // No find_pairs this step: the next call sees two steps of changes.
                continue;
            }
            moved_bodies += broadphase.move_buffer.len();
            checks += 1;
            let expected = full_query_pairs(&broadphase);
            let pairs = find_pairs_with_threads(&mut broadphase, 1 + step % 3);
            assert_eq!(pairs, expected, "step {step}");
            assert_move_buffer_empty(&broadphase);
            if step % 25 == 0 {
                broadphase.moving.validate();
                broadphase.fixed.validate();
                assert_eq!(pairs, brute_force_pairs(&broadphase), "step {step}");
            }
            added += pairs
                .iter()
                .filter(|key| previous.binary_search(key).is_err())
                .count();
            removed += previous
                .iter()
                .filter(|key| pairs.binary_search(key).is_err())
                .count();
            previous = pairs;
        }
        // The scene must exercise both sides of the merge, and the incremental path must have
        // queried far fewer bodies than the full query would.
        assert!(
            added > 100 && removed > 100,
            "added {added}, removed {removed}"
        );
        assert!(
            moved_bodies < checks * COUNT / 2,
            "{moved_bodies} moved in {checks} calls"
        );
    }

    #[test]
    fn removed_replaced_and_swapped_bodies_update_kept_pairs() {
        let mut broadphase = Broadphase::new();
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let far = Aabb::new(Vec3::splat(10.0), Vec3::splat(11.0));
        broadphase.insert(0, unit, true);
        broadphase.insert(1, unit, true);
        broadphase.insert(2, unit, false);
        let all = [pair_key(0, 1), pair_key(0, 2), pair_key(1, 2)];
        assert_eq!(assert_find_pairs_exact(&mut broadphase), all);
        // Nothing changed: the kept pairs alone are the answer.
        assert_eq!(assert_find_pairs_exact(&mut broadphase), all);
        assert!(broadphase.remove(1));
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(0, 2)]);
        // Index 1 comes back far away, then body 0 joins the fixed tree: no pair is left.
        broadphase.insert(1, far, true);
        assert!(broadphase.set_moving(0, false));
        assert!(assert_find_pairs_exact(&mut broadphase).is_empty());
        // Body 2 is replaced by a moving body at the same place: it pairs with 0 again.
        broadphase.insert(2, unit, true);
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(0, 2)]);
        // Removed and inserted again between two calls: the pair stays.
        assert!(broadphase.remove(0));
        broadphase.insert(0, unit, false);
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(0, 2)]);
    }

    #[test]
    fn two_bodies_pair_unless_both_fixed() {
        let mut broadphase = Broadphase::new();
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        broadphase.insert(5, unit, true);
        broadphase.insert(2, unit, false);
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(2, 5)]);
        assert!(broadphase.set_moving(5, false));
        assert!(assert_find_pairs_exact(&mut broadphase).is_empty());
        assert!(broadphase.set_moving(2, true));
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(2, 5)]);

        // Fat margins touch at 2 × 0.1 m apart, and not beyond.
        let gap = |distance: f32| Aabb::new(vec3(1.0 + distance, 0.0, 0.0), vec3(2.0, 1.0, 1.0));
        broadphase.insert(5, gap(0.2), true);
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(2, 5)]);
        broadphase.insert(5, gap(0.21), true);
        assert!(assert_find_pairs_exact(&mut broadphase).is_empty());
    }

    #[test]
    fn update_reinserts_only_escaped_proxies() {
        let mut broadphase = Broadphase::new();
        // Without look-ahead a fat AABB is the AABB grown by the margin, nothing more.
        broadphase.fat_lookahead = 0.0;
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let far = Aabb::new(Vec3::splat(10.0), Vec3::splat(11.0));
        broadphase.insert(0, unit, true);
        broadphase.insert(1, far, false);
        assert!(assert_find_pairs_exact(&mut broadphase).is_empty());

        let shift = |aabb: Aabb, offset: Vec3| Aabb::new(aabb.min + offset, aabb.max + offset);
        let crept = shift(unit, Vec3::splat(0.05));
        assert_eq!(broadphase.update(&[crept, far]), 0);
        assert_eq!(broadphase.fat_aabb(0), Some(unit.expanded(0.1)));

        let escaped = shift(unit, Vec3::splat(0.5));
        assert_eq!(broadphase.update(&[escaped, far]), 1);
        assert_eq!(broadphase.fat_aabb(0), Some(escaped.expanded(0.1)));

        // A fixed body that is teleported is re-inserted as well, and found where it now is.
        broadphase.fat_margin = 0.0;
        assert_eq!(broadphase.update(&[escaped, unit]), 1);
        assert_eq!(broadphase.fat_aabb(1), Some(unit));
        assert_eq!(assert_find_pairs_exact(&mut broadphase), [pair_key(0, 1)]);
    }

    #[test]
    fn lookahead_stretches_fat_aabbs_ahead_and_shrinks_them_after_a_stop() {
        let mut broadphase = Broadphase::new();
        broadphase.fat_lookahead = 4.0;
        let margin = Vec3::splat(DEFAULT_FAT_MARGIN);
        let shift = |aabb: Aabb, offset: Vec3| Aabb::new(aabb.min + offset, aabb.max + offset);
        let fall = vec3(0.0, -0.5, 0.0);
        let mut aabb = Aabb::new(Vec3::ZERO, Vec3::ONE);
        broadphase.insert(0, aabb, true);

        // Falling 0.5 m per step: re-inserted with the box reaching 4 steps further down.
        aabb = shift(aabb, fall);
        assert_eq!(broadphase.update(&[aabb]), 1);
        let stretched = Aabb::new(aabb.min - margin + 4.0 * fall, aabb.max + margin);
        assert_eq!(broadphase.fat_aabb(0), Some(stretched));
        // A steady fall uses the 2.1 m ahead up in 4 steps: re-inserted every 5th step.
        let mut reinserted = Vec::new();
        for _ in 0..10 {
            aabb = shift(aabb, fall);
            reinserted.push(broadphase.update(&[aabb]));
            assert!(broadphase.fat_aabb(0).unwrap().contains(&aabb));
        }
        assert_eq!(reinserted, [0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);

        // Stopped: the box is 2 m taller than a fresh one, more than 4 margins, so it shrinks
        // back to the plain margin, and then stays.
        assert_eq!(broadphase.update(&[aabb]), 1);
        assert_eq!(
            broadphase.fat_aabb(0),
            Some(aabb.expanded(DEFAULT_FAT_MARGIN))
        );
        assert_eq!(broadphase.update(&[aabb]), 0);
        assert!(assert_find_pairs_exact(&mut broadphase).is_empty());
    }

    #[test]
    fn teleported_fixed_bodies_get_no_lookahead() {
        let mut broadphase = Broadphase::new();
        broadphase.insert(0, Aabb::new(Vec3::ZERO, Vec3::ONE), false);
        let jumped = Aabb::new(Vec3::splat(5.0), Vec3::splat(6.0));
        assert_eq!(broadphase.update(&[jumped]), 1);
        assert_eq!(
            broadphase.fat_aabb(0),
            Some(jumped.expanded(DEFAULT_FAT_MARGIN))
        );
    }

    #[test]
    fn unknown_bodies_and_replacement() {
        let mut broadphase = Broadphase::new();
        assert!(!broadphase.remove(3));
        assert!(!broadphase.set_moving(3, true));
        assert_eq!(
            (broadphase.fat_aabb(3), broadphase.is_moving(3)),
            (None, None)
        );
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        broadphase.insert(3, unit, true);
        broadphase.insert(3, unit, false);
        assert_eq!(broadphase.len(), 1);
        assert_eq!(broadphase.is_moving(3), Some(false));
        assert_eq!(
            broadphase.fat_aabb(3),
            Some(unit.expanded(DEFAULT_FAT_MARGIN))
        );
        assert!(broadphase.remove(3) && broadphase.is_empty());
    }

    #[test]
    fn warmed_up_find_pairs_reuses_its_buffers() {
        let mut rng = TestRng::new(9);
        let mut broadphase = Broadphase::new();
        // Moving back and forth must give back the same fat AABBs.
        broadphase.fat_lookahead = 0.0;
        for body in 0..500 {
            broadphase.insert(body, rng.aabb(15.0), body % 3 != 0);
        }
        let mut pairs = Vec::new();
        broadphase.find_pairs(&mut pairs);
        let capacities = |broadphase: &Broadphase, pairs: &Vec<u64>| {
            let mut capacities: Vec<usize> =
                broadphase.task_pairs.iter().map(Vec::capacity).collect();
            capacities.extend([pairs, &broadphase.pairs, &broadphase.new_pairs].map(Vec::capacity));
            capacities.push(broadphase.move_buffer.capacity());
            capacities
        };
        // The first call queried every body; a second one, with every body moved again,
        // needs no more room.
        let aabbs: Vec<Aabb> = (0..500)
            .map(|body| broadphase.fat_aabb(body).unwrap())
            .collect();
        let shifted: Vec<Aabb> = aabbs
            .iter()
            .map(|aabb| Aabb::new(aabb.min + Vec3::X, aabb.max + Vec3::X))
            .collect();
        broadphase.update(&shifted);
        broadphase.find_pairs(&mut pairs);
        let warmed = capacities(&broadphase, &pairs);
        let first = pairs.clone();
        // Nothing moved, then everything moved back and forth: same pairs, same buffers.
        broadphase.find_pairs(&mut pairs);
        assert_eq!(pairs, first);
        broadphase.update(&aabbs);
        broadphase.update(&shifted);
        broadphase.find_pairs(&mut pairs);
        assert_eq!(pairs, first);
        assert_eq!(capacities(&broadphase, &pairs), warmed);
    }
}
