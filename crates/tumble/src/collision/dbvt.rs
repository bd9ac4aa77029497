//! Dynamic AABB tree (DBVT), after Box2D's `b2DynamicTree` and Bullet's `btDbvt`: the CPU
//! broadphase keeps two of them (moving and fixed proxies, see `stages::broadphase`).
//!
//! Each leaf holds a *fat* AABB (the tight box grown by a margin) and a `u32` user value. A
//! proxy is re-inserted only when its tight box leaves its fat box, so most steps touch no
//! tree at all.
//!
//! Invariants, checked by [`Dbvt::validate`]:
//! - Nodes live in one flat `Vec`; freed nodes form a singly linked free list and are reused
//!   first, so a tree that stops growing stops allocating.
//! - Every internal node has exactly two children, its AABB is exactly the union of theirs and
//!   its height is one more than the taller child's (leaves have height 0).
//! - Parent and child links agree; the root has no parent.
//! - Rotations on the way up after every insertion and removal keep the two children of any
//!   node within one level of height of each other wherever a rotation can fix it (as Box2D
//!   v2.4 does), so the height stays O(log n) even for sorted insertions.
//! - No randomness and no dependence on addresses: the same sequence of calls builds the same
//!   tree, node for node, so broadphase output is reproducible.

mod ray;

pub use ray::segment_enters_aabb;

use crate::math::Aabb;

/// Handle to a leaf of a [`Dbvt`]. Stays valid until the proxy is removed; the index may then
/// be reused by a later insertion.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ProxyId(u32);

/// Marks "no node": the root's parent, a leaf's children, the end of the free list.
const NULL_NODE: u32 = u32::MAX;

/// Height stored in freed nodes, so a stale [`ProxyId`] is caught instead of read as a leaf.
const FREE_HEIGHT: u32 = u32::MAX;

/// Traversal stack entries kept on the machine stack. A tree of height h needs at most h + 1
/// entries; the rotations keep h near 1.44·log2(n), so 64 covers any tree that fits in memory,
/// and a spill `Vec` handles the rest without a limit.
const INLINE_STACK_DEPTH: usize = 64;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    /// Leaf: the fat AABB. Internal: the union of the children's boxes.
    aabb: Aabb,
    /// Parent node, or [`NULL_NODE`] for the root. In a freed node: the next free node.
    parent: u32,
    /// Both [`NULL_NODE`] in a leaf.
    children: [u32; 2],
    /// 0 for a leaf, 1 + the taller child's height for an internal node, [`FREE_HEIGHT`] when
    /// freed.
    height: u32,
    /// The caller's value (a body index in the broadphase); unused in internal nodes.
    user: u32,
}

impl Node {
    #[inline]
    fn is_leaf(&self) -> bool {
        self.height == 0
    }
}

/// A dynamic AABB tree. See the module documentation for its invariants.
#[derive(Clone, Debug, PartialEq)]
pub struct Dbvt {
    nodes: Vec<Node>,
    root: u32,
    free_list: u32,
    leaf_count: usize,
}

impl Default for Dbvt {
    fn default() -> Self {
        Self::new()
    }
}

impl Dbvt {
    pub fn new() -> Self {
        Self {
            nodes: Vec::new(),
            root: NULL_NODE,
            free_list: NULL_NODE,
            leaf_count: 0,
        }
    }

    /// Number of leaves (proxies).
    pub fn len(&self) -> usize {
        self.leaf_count
    }

    pub fn is_empty(&self) -> bool {
        self.leaf_count == 0
    }

    /// Height of the root: 0 for an empty tree or a single leaf.
    pub fn height(&self) -> u32 {
        if self.root == NULL_NODE {
            0
        } else {
            self.nodes[self.root as usize].height
        }
    }

    /// Adds a leaf whose fat AABB is `aabb`, exactly as given (the caller chooses the margin).
    pub fn insert(&mut self, aabb: Aabb, user: u32) -> ProxyId {
        let leaf = self.allocate_node(Node {
            aabb,
            parent: NULL_NODE,
            children: [NULL_NODE; 2],
            height: 0,
            user,
        });
        self.insert_leaf(leaf);
        self.leaf_count += 1;
        ProxyId(leaf)
    }

    /// Removes a leaf. Panics if `proxy` is not a live leaf of this tree.
    pub fn remove(&mut self, proxy: ProxyId) {
        self.leaf(proxy);
        self.remove_leaf(proxy.0);
        self.free_node(proxy.0);
        self.leaf_count -= 1;
    }

    /// Incremental update: when `tight` has left the leaf's fat AABB, re-inserts the leaf with
    /// the fat AABB `tight.expanded(margin)` and returns true; otherwise leaves the tree alone
    /// and returns false. The [`ProxyId`] stays the same either way. Panics if `proxy` is not
    /// a live leaf of this tree.
    pub fn update(&mut self, proxy: ProxyId, tight: Aabb, margin: f32) -> bool {
        if self.leaf(proxy).aabb.contains(&tight) {
            return false;
        }
        self.reinsert(proxy, tight.expanded(margin));
        true
    }

    /// Re-inserts the leaf with the fat AABB `fat`, exactly as given (the caller decides when
    /// and how large). The [`ProxyId`] stays the same. Panics if `proxy` is not a live leaf of
    /// this tree.
    pub fn reinsert(&mut self, proxy: ProxyId, fat: Aabb) {
        self.leaf(proxy);
        self.remove_leaf(proxy.0);
        self.nodes[proxy.0 as usize].aabb = fat;
        self.insert_leaf(proxy.0);
    }

    /// The leaf's fat AABB. Panics if `proxy` is not a live leaf of this tree.
    pub fn fat_aabb(&self, proxy: ProxyId) -> Aabb {
        self.leaf(proxy).aabb
    }

    /// The leaf's user value. Panics if `proxy` is not a live leaf of this tree.
    pub fn user(&self, proxy: ProxyId) -> u32 {
        self.leaf(proxy).user
    }

    /// Calls `visit(user)` for every leaf whose fat AABB overlaps (or touches) `aabb`, in a
    /// deterministic order, until `visit` returns false. Allocates nothing unless the tree is
    /// deeper than 63 levels, which the rotations make all but impossible.
    pub fn query(&self, aabb: &Aabb, mut visit: impl FnMut(u32) -> bool) {
        if self.root == NULL_NODE {
            return;
        }
        let mut stack = NodeStack::new();
        stack.push(self.root);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if !node.aabb.overlaps(aabb) {
                continue;
            }
            if node.is_leaf() {
                if !visit(node.user) {
                    return;
                }
            } else {
                // Pushing the second child first visits the first child first: the order of
                // results follows the tree's left-to-right order.
                stack.push(node.children[1]);
                stack.push(node.children[0]);
            }
        }
    }

    /// Checks every invariant listed in the module documentation; panics with a message naming
    /// the first one broken. O(n): for tests and debugging.
    pub fn validate(&self) {
        let mut reachable = 0usize;
        let mut leaves = 0usize;
        if self.root != NULL_NODE {
            assert_eq!(
                self.nodes[self.root as usize].parent, NULL_NODE,
                "the root has a parent"
            );
            let mut stack = vec![self.root];
            while let Some(index) = stack.pop() {
                reachable += 1;
                let node = &self.nodes[index as usize];
                assert_ne!(
                    node.height, FREE_HEIGHT,
                    "node {index} is reachable but free"
                );
                if node.is_leaf() {
                    leaves += 1;
                    assert_eq!(node.children, [NULL_NODE; 2], "leaf {index} has children");
                    continue;
                }
                let [first, second] = node.children.map(|child| &self.nodes[child as usize]);
                for child in node.children {
                    assert_eq!(
                        self.nodes[child as usize].parent, index,
                        "child {child} does not point back to its parent {index}"
                    );
                    stack.push(child);
                }
                assert_eq!(
                    node.height,
                    1 + first.height.max(second.height),
                    "node {index} has a wrong height"
                );
                assert_eq!(
                    node.aabb,
                    first.aabb.union(&second.aabb),
                    "node {index}'s AABB is not the union of its children's"
                );
            }
        }
        assert_eq!(leaves, self.leaf_count, "leaf count");
        let mut free = 0usize;
        let mut index = self.free_list;
        while index != NULL_NODE {
            free += 1;
            assert!(free <= self.nodes.len(), "the free list has a cycle");
            let node = &self.nodes[index as usize];
            assert_eq!(
                node.height, FREE_HEIGHT,
                "free node {index} is not marked free"
            );
            index = node.parent;
        }
        assert_eq!(
            reachable + free,
            self.nodes.len(),
            "nodes neither in the tree nor in the free list"
        );
    }

    /// The live leaf behind `proxy`; panics on a freed node or an internal one, which only a
    /// stale or foreign handle can point to.
    #[inline]
    fn leaf(&self, proxy: ProxyId) -> &Node {
        let node = &self.nodes[proxy.0 as usize];
        assert!(node.is_leaf(), "{proxy:?} is not a live leaf of this tree");
        node
    }

    fn allocate_node(&mut self, node: Node) -> u32 {
        if self.free_list == NULL_NODE {
            let index = u32::try_from(self.nodes.len())
                .ok()
                .filter(|&index| index != NULL_NODE)
                .expect("a Dbvt holds fewer than 2^32 - 1 nodes");
            self.nodes.push(node);
            index
        } else {
            let index = self.free_list;
            self.free_list = self.nodes[index as usize].parent;
            self.nodes[index as usize] = node;
            index
        }
    }

    fn free_node(&mut self, index: u32) {
        let node = &mut self.nodes[index as usize];
        node.parent = self.free_list;
        node.children = [NULL_NODE; 2];
        node.height = FREE_HEIGHT;
        self.free_list = index;
    }

    /// Links the detached leaf `leaf` into the tree next to the sibling that costs least by the
    /// surface area heuristic, then refits and rebalances the path to the root.
    fn insert_leaf(&mut self, leaf: u32) {
        if self.root == NULL_NODE {
            self.root = leaf;
            self.nodes[leaf as usize].parent = NULL_NODE;
            return;
        }
        let leaf_aabb = self.nodes[leaf as usize].aabb;
        let sibling = self.find_best_sibling(&leaf_aabb);
        let old_parent = self.nodes[sibling as usize].parent;
        let sibling_node = self.nodes[sibling as usize];
        let new_parent = self.allocate_node(Node {
            aabb: leaf_aabb.union(&sibling_node.aabb),
            parent: old_parent,
            children: [sibling, leaf],
            height: sibling_node.height + 1,
            user: 0,
        });
        self.replace_child(old_parent, sibling, new_parent);
        self.nodes[sibling as usize].parent = new_parent;
        self.nodes[leaf as usize].parent = new_parent;
        self.refit_to_root(new_parent);
    }

    /// Unlinks `leaf` from the tree (its parent node is freed, its sibling takes the parent's
    /// place); the leaf node itself stays allocated.
    fn remove_leaf(&mut self, leaf: u32) {
        if leaf == self.root {
            self.root = NULL_NODE;
            return;
        }
        let parent = self.nodes[leaf as usize].parent;
        let parent_node = self.nodes[parent as usize];
        let sibling = if parent_node.children[0] == leaf {
            parent_node.children[1]
        } else {
            parent_node.children[0]
        };
        let grandparent = parent_node.parent;
        self.replace_child(grandparent, parent, sibling);
        self.nodes[sibling as usize].parent = grandparent;
        self.free_node(parent);
        if grandparent != NULL_NODE {
            self.refit_to_root(grandparent);
        }
    }

    /// In `parent`'s child slots, puts `new_child` where `old_child` was; a `parent` of
    /// [`NULL_NODE`] means the root slot.
    fn replace_child(&mut self, parent: u32, old_child: u32, new_child: u32) {
        if parent == NULL_NODE {
            self.root = new_child;
            return;
        }
        let children = &mut self.nodes[parent as usize].children;
        if children[0] == old_child {
            children[0] = new_child;
        } else {
            debug_assert_eq!(children[1], old_child);
            children[1] = new_child;
        }
    }

    /// Walks from `index` to the root, rebalancing each node and recomputing its AABB and height.
    fn refit_to_root(&mut self, mut index: u32) {
        while index != NULL_NODE {
            index = self.balance(index);
            self.refit(index);
            index = self.nodes[index as usize].parent;
        }
    }

    /// Recomputes an internal node's AABB and height from its children.
    #[inline]
    fn refit(&mut self, index: u32) {
        let [first, second] = self.nodes[index as usize]
            .children
            .map(|child| self.nodes[child as usize]);
        let node = &mut self.nodes[index as usize];
        node.aabb = first.aabb.union(&second.aabb);
        node.height = 1 + first.height.max(second.height);
    }

    /// Sibling choice by the surface area heuristic, Box2D v3's `b2FindBestSibling` in 3D: one
    /// greedy descent that keeps the cheapest sibling seen and stops as soon as a lower bound on
    /// the cost below both children cannot beat it (branch and bound on one path).
    ///
    /// Cost of making node N the sibling of the new leaf L = SA(N ∪ L) (the new parent) plus
    /// the growth SA(A ∪ L) − SA(A) of every ancestor A of N (the "inherited" cost).
    fn find_best_sibling(&self, leaf_aabb: &Aabb) -> u32 {
        let leaf_area = leaf_aabb.surface_area();
        let leaf_center = leaf_aabb.center();

        let mut index = self.root;
        let root_aabb = self.nodes[index as usize].aabb;
        let mut area = root_aabb.surface_area();
        let mut direct_cost = root_aabb.union(leaf_aabb).surface_area();
        let mut inherited_cost = 0.0f32;

        let mut best_sibling = index;
        let mut best_cost = direct_cost;

        while !self.nodes[index as usize].is_leaf() {
            let cost = direct_cost + inherited_cost;
            if cost < best_cost {
                best_sibling = index;
                best_cost = cost;
            }
            // Going below `index` grows it as well: its children inherit that growth.
            inherited_cost += direct_cost - area;

            let children = self.nodes[index as usize].children;
            let mut lower_costs = [f32::MAX; 2];
            let mut direct_costs = [0.0f32; 2];
            let mut areas = [0.0f32; 2];
            let mut leaves = [false; 2];
            for slot in 0..2 {
                let child = &self.nodes[children[slot] as usize];
                direct_costs[slot] = child.aabb.union(leaf_aabb).surface_area();
                if child.is_leaf() {
                    leaves[slot] = true;
                    // A leaf child can only become the sibling itself: its cost is exact.
                    let child_cost = direct_costs[slot] + inherited_cost;
                    if child_cost < best_cost {
                        best_sibling = children[slot];
                        best_cost = child_cost;
                    }
                } else {
                    areas[slot] = child.aabb.surface_area();
                    // Anything below the child costs at least its growth plus a new parent no
                    // smaller than the leaf itself.
                    lower_costs[slot] =
                        inherited_cost + direct_costs[slot] + (leaf_area - areas[slot]).min(0.0);
                }
            }

            if leaves[0] && leaves[1] {
                break;
            }
            if best_cost <= lower_costs[0] && best_cost <= lower_costs[1] {
                break;
            }
            if lower_costs[0] == lower_costs[1] && !leaves[0] {
                // No preference by area, which happens when both children contain the leaf:
                // descend toward the nearer centre instead.
                for slot in 0..2 {
                    let center = self.nodes[children[slot] as usize].aabb.center();
                    lower_costs[slot] = (center - leaf_center).length_squared();
                }
            }
            let slot = if lower_costs[0] < lower_costs[1] && !leaves[0] {
                0
            } else {
                1
            };
            index = children[slot];
            area = areas[slot];
            direct_cost = direct_costs[slot];
        }
        best_sibling
    }

    /// If the children of `index` differ in height by more than one, rotates the taller child
    /// up into `index`'s place (Box2D v2.4's `Balance`) and returns the node now in that place;
    /// otherwise returns `index`. Both rotated nodes are refitted.
    fn balance(&mut self, index: u32) -> u32 {
        let node = self.nodes[index as usize];
        if node.is_leaf() || node.height < 2 {
            return index;
        }
        let [first, second] = node.children;
        let first_height = self.nodes[first as usize].height;
        let second_height = self.nodes[second as usize].height;
        if second_height > first_height + 1 {
            self.rotate_up(index, second)
        } else if first_height > second_height + 1 {
            self.rotate_up(index, first)
        } else {
            index
        }
    }

    /// Rotation: `tall`, a child of `index`, takes `index`'s place; `index` becomes a child of
    /// `tall` and takes, in `tall`'s old slot, the shorter of `tall`'s two children. The taller
    /// grandchild stays with `tall`, which is what evens the heights.
    fn rotate_up(&mut self, index: u32, tall: u32) -> u32 {
        let [grandchild_a, grandchild_b] = self.nodes[tall as usize].children;
        let (kept, given) = if self.nodes[grandchild_a as usize].height
            > self.nodes[grandchild_b as usize].height
        {
            (grandchild_a, grandchild_b)
        } else {
            (grandchild_b, grandchild_a)
        };

        let old_parent = self.nodes[index as usize].parent;
        self.replace_child(old_parent, index, tall);
        self.nodes[tall as usize].parent = old_parent;

        self.replace_child(index, tall, given);
        self.nodes[given as usize].parent = index;

        self.nodes[tall as usize].children = [index, kept];
        self.nodes[index as usize].parent = tall;

        self.refit(index);
        self.refit(tall);
        tall
    }
}

/// Depth-first traversal stack: [`INLINE_STACK_DEPTH`] entries without allocating, then a
/// `Vec` for the rest. Entries pushed past the inline part are popped before it empties, so
/// the two parts together stay last-in first-out.
struct NodeStack {
    inline: [u32; INLINE_STACK_DEPTH],
    inline_len: usize,
    spill: Vec<u32>,
}

impl NodeStack {
    #[inline]
    fn new() -> Self {
        Self {
            inline: [NULL_NODE; INLINE_STACK_DEPTH],
            inline_len: 0,
            spill: Vec::new(),
        }
    }

    #[inline]
    fn push(&mut self, index: u32) {
        if self.inline_len < INLINE_STACK_DEPTH {
            self.inline[self.inline_len] = index;
            self.inline_len += 1;
        } else {
            self.spill.push(index);
        }
    }

    #[inline]
    fn pop(&mut self) -> Option<u32> {
        if let Some(index) = self.spill.pop() {
            return Some(index);
        }
        if self.inline_len == 0 {
            return None;
        }
        self.inline_len -= 1;
        Some(self.inline[self.inline_len])
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::math::{Vec3, vec3};

    /// SplitMix64: a tiny seeded generator, so the tests need no extra crate and replay the
    /// same scenes on every run.
    pub(crate) struct TestRng(u64);

    impl TestRng {
        pub(crate) fn new(seed: u64) -> Self {
            Self(seed)
        }

        pub(crate) fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }

        /// Uniform in [low, high).
        pub(crate) fn range(&mut self, low: f32, high: f32) -> f32 {
            let unit = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
            low + (high - low) * unit
        }

        /// Uniform in 0..count.
        pub(crate) fn below(&mut self, count: usize) -> usize {
            (self.next_u64() % count as u64) as usize
        }

        pub(crate) fn vec3(&mut self, low: f32, high: f32) -> Vec3 {
            vec3(
                self.range(low, high),
                self.range(low, high),
                self.range(low, high),
            )
        }

        /// A box of half-size 0.05..1 m centred in a cube of side `world` m.
        pub(crate) fn aabb(&mut self, world: f32) -> Aabb {
            Aabb::from_center_half_extents(
                self.vec3(-0.5 * world, 0.5 * world),
                self.vec3(0.05, 1.0),
            )
        }
    }

    fn query_sorted(tree: &Dbvt, aabb: &Aabb) -> Vec<u32> {
        let mut found = Vec::new();
        tree.query(aabb, |user| {
            found.push(user);
            true
        });
        found.sort_unstable();
        found
    }

    /// Checks `query` against a brute-force scan over the fat AABBs, for a spread of boxes.
    fn assert_queries_match(tree: &Dbvt, proxies: &[Option<ProxyId>], rng: &mut TestRng) {
        for _ in 0..100 {
            let probe = rng.aabb(60.0);
            let expected: Vec<u32> = proxies
                .iter()
                .flatten()
                .filter(|&&proxy| tree.fat_aabb(proxy).overlaps(&probe))
                .map(|&proxy| tree.user(proxy))
                .collect();
            let mut expected = expected;
            expected.sort_unstable();
            assert_eq!(query_sorted(tree, &probe), expected);
        }
    }

    #[test]
    fn empty_tree() {
        let tree = Dbvt::new();
        tree.validate();
        assert_eq!((tree.len(), tree.height()), (0, 0));
        assert!(tree.is_empty());
        assert!(query_sorted(&tree, &Aabb::new(Vec3::splat(-1e9), Vec3::splat(1e9))).is_empty());
    }

    #[test]
    fn single_leaf() {
        let mut tree = Dbvt::new();
        let aabb = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let proxy = tree.insert(aabb, 7);
        tree.validate();
        assert_eq!((tree.len(), tree.height()), (1, 0));
        assert_eq!((tree.fat_aabb(proxy), tree.user(proxy)), (aabb, 7));
        // Touching counts as overlapping.
        assert_eq!(
            query_sorted(&tree, &Aabb::new(Vec3::ONE, Vec3::splat(2.0))),
            [7]
        );
        assert!(query_sorted(&tree, &Aabb::new(Vec3::splat(1.5), Vec3::splat(2.0))).is_empty());

        // Inside the fat box: nothing moves. Outside: re-inserted with the new margin.
        assert!(!tree.update(proxy, Aabb::new(Vec3::splat(0.25), Vec3::splat(0.75)), 0.1));
        assert_eq!(tree.fat_aabb(proxy), aabb);
        let moved = Aabb::new(Vec3::splat(5.0), Vec3::splat(6.0));
        assert!(tree.update(proxy, moved, 0.1));
        assert_eq!(tree.fat_aabb(proxy), moved.expanded(0.1));
        tree.validate();

        tree.remove(proxy);
        tree.validate();
        assert!(tree.is_empty());
        // The freed leaf is reused.
        assert_eq!(tree.insert(aabb, 8), proxy);
        tree.validate();
    }

    #[test]
    fn query_stops_when_visit_returns_false() {
        let mut tree = Dbvt::new();
        for user in 0..10 {
            tree.insert(Aabb::new(Vec3::ZERO, Vec3::ONE), user);
        }
        let mut visits = 0;
        tree.query(&Aabb::new(Vec3::ZERO, Vec3::ONE), |_| {
            visits += 1;
            visits < 3
        });
        assert_eq!(visits, 3);
    }

    #[test]
    fn random_insert_move_remove_match_brute_force() {
        let mut rng = TestRng::new(0x5eed);
        let mut tree = Dbvt::new();
        let mut proxies: Vec<Option<ProxyId>> = Vec::new();
        let mut tight: Vec<Aabb> = Vec::new();
        let margin = 0.1;

        for user in 0..1000u32 {
            let aabb = rng.aabb(50.0);
            tight.push(aabb);
            proxies.push(Some(tree.insert(aabb.expanded(margin), user)));
        }
        tree.validate();
        assert_queries_match(&tree, &proxies, &mut rng);

        for _ in 0..5 {
            let mut reinserted = 0;
            for (user, slot) in proxies.iter().enumerate() {
                let Some(proxy) = *slot else { continue };
                // Most bodies creep (often staying inside their fat box); some teleport.
                let offset = if rng.below(10) == 0 {
                    rng.vec3(-20.0, 20.0)
                } else {
                    rng.vec3(-0.15, 0.15)
                };
                tight[user] = Aabb::new(tight[user].min + offset, tight[user].max + offset);
                reinserted += usize::from(tree.update(proxy, tight[user], margin));
                assert!(tree.fat_aabb(proxy).contains(&tight[user]));
                assert_eq!(tree.user(proxy), user as u32);
            }
            assert!(reinserted > 0 && reinserted < 1000);
            tree.validate();
            assert_queries_match(&tree, &proxies, &mut rng);
        }

        for slot in proxies.iter_mut() {
            if rng.below(3) != 0 {
                tree.remove(slot.take().expect("every proxy is live before removal"));
            }
        }
        tree.validate();
        assert_eq!(tree.len(), proxies.iter().flatten().count());
        assert_queries_match(&tree, &proxies, &mut rng);

        // Refill: freed nodes are reused before the node array grows.
        let node_capacity = tree.nodes.len();
        for (user, slot) in proxies.iter_mut().enumerate() {
            if slot.is_none() {
                *slot = Some(tree.insert(rng.aabb(50.0), user as u32));
            }
        }
        tree.validate();
        assert_eq!(tree.nodes.len(), node_capacity);
        assert_queries_match(&tree, &proxies, &mut rng);

        for slot in proxies.iter_mut() {
            tree.remove(slot.take().expect("every proxy is live"));
        }
        tree.validate();
        assert!(tree.is_empty() && tree.height() == 0);
    }

    #[test]
    fn sorted_insertions_keep_the_tree_shallow() {
        for count in [2usize, 3, 100, 10_000] {
            let mut tree = Dbvt::new();
            for user in 0..count as u32 {
                let center = vec3(user as f32, 0.0, 0.0);
                tree.insert(
                    Aabb::from_center_half_extents(center, Vec3::splat(0.4)),
                    user,
                );
            }
            tree.validate();
            let bound = 2.0 * (count as f32).log2() + 2.0;
            assert!(
                (tree.height() as f32) <= bound,
                "height {} for {count} sorted boxes (bound {bound})",
                tree.height()
            );
        }
    }

    #[test]
    fn sorted_removals_keep_the_tree_shallow() {
        let count = 10_000u32;
        let mut tree = Dbvt::new();
        let proxies: Vec<ProxyId> = (0..count)
            .map(|user| {
                let center = vec3(0.0, user as f32, 0.0);
                tree.insert(
                    Aabb::from_center_half_extents(center, Vec3::splat(0.4)),
                    user,
                )
            })
            .collect();
        // Removing one whole end unbalances the tree the most.
        for &proxy in &proxies[..(count as usize * 9 / 10)] {
            tree.remove(proxy);
        }
        tree.validate();
        let bound = 2.0 * (tree.len() as f32).log2() + 2.0;
        assert!((tree.height() as f32) <= bound, "height {}", tree.height());
    }

    #[test]
    fn traversal_stack_spills_past_its_inline_part_in_order() {
        let mut stack = NodeStack::new();
        let count = 3 * INLINE_STACK_DEPTH as u32;
        for index in 0..count {
            stack.push(index);
        }
        assert!(!stack.spill.is_empty());
        for index in (0..count).rev() {
            assert_eq!(stack.pop(), Some(index));
            if index == count / 2 {
                // Pushing again mid-way keeps last-in first-out order.
                stack.push(1000);
                assert_eq!(stack.pop(), Some(1000));
            }
        }
        assert_eq!(stack.pop(), None);
    }

    #[test]
    fn same_calls_build_the_same_tree() {
        let build = || {
            let mut rng = TestRng::new(42);
            let mut tree = Dbvt::new();
            let proxies: Vec<ProxyId> = (0..300)
                .map(|user| tree.insert(rng.aabb(30.0), user))
                .collect();
            for (step, &proxy) in proxies.iter().enumerate() {
                if step % 3 == 0 {
                    tree.remove(proxy);
                } else {
                    tree.update(proxy, rng.aabb(30.0), 0.1);
                }
            }
            tree
        };
        assert_eq!(build(), build());
    }
}
