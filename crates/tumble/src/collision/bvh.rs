//! A static bounding volume hierarchy over primitives' AABBs (a triangle mesh's triangles, a
//! compound's children), built once with the binned surface area heuristic and stored flat.
//!
//! # Layout
//!
//! ```text
//!   nodes:      [ root | left | right | ... ]   BvhNode, 32 bytes each, repr(C) + Pod
//!   primitives: [ p3 p0 p7 | p1 p2 | ... ]      u32 primitive indices, leaf by leaf
//! ```
//!
//! A node with `count == 0` is internal: its children are `nodes[first]` and
//! `nodes[first + 1]`. A node with `count > 0` is a leaf over
//! `primitives[first .. first + count]`. Node 0 is the root; an empty BVH has no nodes. Both
//! arrays are plain data, so a GPU port uploads them as they are and traverses with a stack.
//!
//! # Build (Wald 2007, "On fast construction of SAH-based bounding volume hierarchies")
//!
//! Each node's primitives are binned by centroid into [`BINS`] slots along each axis; the
//! split with the least `area(left) · count(left) + area(right) · count(right)` wins, unless
//! keeping the node as a leaf is cheaper (at most [`MAX_LEAF_SIZE`] primitives). When all
//! centroids coincide on every axis, the node is split at the middle of its list, so a leaf
//! never exceeds [`MAX_LEAF_SIZE`] however degenerate the input.
//!
//! Deterministic: the build uses no threads and breaks ties to the lower axis and bin, and
//! queries visit nodes in a fixed order (overlap queries left child first; rays nearer child
//! first, ties to the left), so callbacks see primitives in the same order every run.

use crate::math::{Aabb, Vec3};

/// Centroid bins per axis of the SAH build.
const BINS: usize = 12;

/// Most primitives a leaf holds.
pub const MAX_LEAF_SIZE: usize = 4;

/// Cost of visiting a node relative to testing one primitive, in the SAH.
const TRAVERSAL_COST: f32 = 1.0;

/// One node of a [`Bvh`]; see the module documentation. 32 bytes, WGSL-friendly
/// (`vec3<f32>` + `u32` twice).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BvhNode {
    pub min: Vec3,
    /// Leaf: first index into the primitive list; internal: index of the left child.
    pub first: u32,
    pub max: Vec3,
    /// Primitives in the leaf; 0 for an internal node.
    pub count: u32,
}
const _: () = assert!(size_of::<BvhNode>() == 32);

impl BvhNode {
    #[inline]
    pub fn aabb(&self) -> Aabb {
        Aabb::new(self.min, self.max)
    }

    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// A static BVH; see the module documentation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    nodes: Vec<BvhNode>,
    primitives: Vec<u32>,
}

/// A node under construction: the range `order[start..end]` of primitives it covers.
struct Pending {
    node: usize,
    start: usize,
    end: usize,
}

impl Bvh {
    /// Builds the tree over `aabbs`; primitive `i` is `aabbs[i]`. Boxes must be finite with
    /// `min <= max` (callers validate their input first).
    pub fn build(aabbs: &[Aabb]) -> Self {
        let mut bvh = Bvh {
            nodes: Vec::new(),
            primitives: (0..aabbs.len() as u32).collect(),
        };
        if aabbs.is_empty() {
            return bvh;
        }
        let centroids: Vec<Vec3> = aabbs.iter().map(Aabb::center).collect();
        bvh.nodes.push(BvhNode::default());
        let mut stack = vec![Pending {
            node: 0,
            start: 0,
            end: aabbs.len(),
        }];
        while let Some(Pending { node, start, end }) = stack.pop() {
            let bounds = bounds_of(aabbs, &bvh.primitives[start..end]);
            bvh.nodes[node].min = bounds.min;
            bvh.nodes[node].max = bounds.max;
            let split = split_point(aabbs, &centroids, &mut bvh.primitives[start..end], bounds);
            let Some(split) = split else {
                bvh.nodes[node].first = start as u32;
                bvh.nodes[node].count = (end - start) as u32;
                continue;
            };
            let left = bvh.nodes.len();
            bvh.nodes.push(BvhNode::default());
            bvh.nodes.push(BvhNode::default());
            bvh.nodes[node].first = left as u32;
            bvh.nodes[node].count = 0;
            // Right pushed first so that the left subtree is built first: nodes come out in
            // depth-first order, which keeps a query's memory walk mostly forward.
            stack.push(Pending {
                node: left + 1,
                start: start + split,
                end,
            });
            stack.push(Pending {
                node: left,
                start,
                end: start + split,
            });
        }
        bvh
    }

    /// The nodes, root first; empty for an empty BVH.
    pub fn nodes(&self) -> &[BvhNode] {
        &self.nodes
    }

    /// Primitive indices, leaf by leaf (see the module documentation).
    pub fn primitives(&self) -> &[u32] {
        &self.primitives
    }

    /// Bounds of everything; `None` for an empty BVH.
    pub fn root_aabb(&self) -> Option<Aabb> {
        self.nodes.first().map(BvhNode::aabb)
    }

    /// Calls `found` with every primitive whose leaf box overlaps `aabb` and whose own box
    /// overlaps it too (`primitive_aabbs` are the boxes the tree was built from).
    pub fn query_aabb(&self, aabb: &Aabb, primitive_aabbs: &[Aabb], mut found: impl FnMut(u32)) {
        self.query(
            |node| node.aabb().overlaps(aabb),
            |primitive| {
                if primitive_aabbs[primitive as usize].overlaps(aabb) {
                    found(primitive);
                }
            },
        );
    }

    /// Calls `found` with every primitive of every leaf reached through nodes, the root
    /// included, that pass `enter`: an overlap query with a test of the caller's (a compound
    /// tests its nodes' boxes turned into the world, `Compound::children_near`). Left child
    /// first, so the order is fixed.
    pub fn query(&self, mut enter: impl FnMut(&BvhNode) -> bool, mut found: impl FnMut(u32)) {
        let Some(root) = self.nodes.first() else {
            return;
        };
        if !enter(root) {
            return;
        }
        // Depth is bounded by the primitive count, not by a constant: a Vec, not an array.
        let mut stack = vec![0u32];
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if node.is_leaf() {
                let range = node.first as usize..(node.first + node.count) as usize;
                for &primitive in &self.primitives[range] {
                    found(primitive);
                }
                continue;
            }
            // Right pushed first: the left child is visited first.
            for child in [node.first + 1, node.first] {
                if enter(&self.nodes[child as usize]) {
                    stack.push(child);
                }
            }
        }
    }

    /// Walks the ray `origin + t · direction`, `0 <= t <= max_t`, through the tree, nearer
    /// child first. `hit(primitive, max_t)` is called for each primitive of each leaf the ray
    /// enters and returns the new `max_t`: the same value to keep looking (all hits), a smaller
    /// one when it found a hit at that distance (closest hit: farther boxes are then skipped).
    /// `t` is in units of `direction`'s length; `direction` need not be unit but must not be
    /// zero (callers validate it).
    pub fn ray(&self, origin: Vec3, direction: Vec3, max_t: f32, hit: impl FnMut(u32, f32) -> f32) {
        self.sweep(origin, Vec3::ZERO, direction, max_t, hit);
    }

    /// [`Bvh::ray`] for a box of `half_extents` (m) centred on `origin` moving along
    /// `direction`: the box meets a node's box exactly when its centre's ray meets that box
    /// grown by `half_extents` (their Minkowski sum), so this is the ray walk over grown boxes
    /// (a swept-AABB query that visits nearer nodes first and prunes behind a hit).
    pub fn sweep(
        &self,
        origin: Vec3,
        half_extents: Vec3,
        direction: Vec3,
        max_t: f32,
        mut hit: impl FnMut(u32, f32) -> f32,
    ) {
        let Some(root) = self.nodes.first() else {
            return;
        };
        let inverse = direction.recip();
        let mut max_t = max_t;
        let grown = |node: &BvhNode| Aabb::new(node.min - half_extents, node.max + half_extents);
        if ray_box_entry(origin, inverse, &grown(root), max_t).is_none() {
            return;
        }
        let mut stack = vec![0u32];
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            // Rechecked on pop: a hit found since the push may have moved max_t in front.
            if ray_box_entry(origin, inverse, &grown(node), max_t).is_none() {
                continue;
            }
            if node.is_leaf() {
                let range = node.first as usize..(node.first + node.count) as usize;
                for &primitive in &self.primitives[range] {
                    max_t = hit(primitive, max_t);
                }
                continue;
            }
            let left = node.first;
            let right = left + 1;
            let enter_left =
                ray_box_entry(origin, inverse, &grown(&self.nodes[left as usize]), max_t);
            let enter_right =
                ray_box_entry(origin, inverse, &grown(&self.nodes[right as usize]), max_t);
            match (enter_left, enter_right) {
                (Some(l), Some(r)) => {
                    // The farther child goes under the nearer one on the stack.
                    if r < l {
                        stack.extend([left, right]);
                    } else {
                        stack.extend([right, left]);
                    }
                }
                (Some(_), None) => stack.push(left),
                (None, Some(_)) => stack.push(right),
                (None, None) => {}
            }
        }
    }
}

/// Distance parameter at which the ray enters `aabb` (0 when it starts inside), or `None` when
/// it misses the box within `[0, max_t]`. Slab test; `inverse` is `1 / direction`, infinite on
/// axes the ray runs parallel to. A ray parallel to an axis that starts exactly on one of the
/// box's planes across it gives `0 · ∞ = NaN` there: it runs along that (closed) face, so the
/// slab does not bound it and is skipped. (`t0.min(t1)` would instead return the other,
/// infinite bound and miss the box: a ray along a mesh's grid line missed both triangles.)
#[inline]
pub fn ray_box_entry(origin: Vec3, inverse: Vec3, aabb: &Aabb, max_t: f32) -> Option<f32> {
    let mut enter = 0.0f32;
    let mut exit = max_t;
    for axis in 0..3 {
        let t0 = (aabb.min[axis] - origin[axis]) * inverse[axis];
        let t1 = (aabb.max[axis] - origin[axis]) * inverse[axis];
        if t0.is_nan() || t1.is_nan() {
            continue;
        }
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
    }
    (enter <= exit).then_some(enter)
}

fn bounds_of(aabbs: &[Aabb], primitives: &[u32]) -> Aabb {
    let first = aabbs[primitives[0] as usize];
    primitives[1..]
        .iter()
        .fold(first, |bounds, &p| bounds.union(&aabbs[p as usize]))
}

/// Partitions `primitives` for a split and returns how many go left, or `None` when the node
/// should stay a leaf.
fn split_point(
    aabbs: &[Aabb],
    centroids: &[Vec3],
    primitives: &mut [u32],
    bounds: Aabb,
) -> Option<usize> {
    let count = primitives.len();
    if count <= 1 {
        return None;
    }
    let mut centroid_min = Vec3::splat(f32::INFINITY);
    let mut centroid_max = Vec3::splat(f32::NEG_INFINITY);
    for &p in primitives.iter() {
        centroid_min = centroid_min.min(centroids[p as usize]);
        centroid_max = centroid_max.max(centroids[p as usize]);
    }
    let extent = centroid_max - centroid_min;

    // Best (cost, axis, bins left of the split) over all axes with any spread.
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |p: u32| {
            (((centroids[p as usize][axis] - centroid_min[axis]) * scale) as usize).min(BINS - 1)
        };
        let mut bin_bounds: [Option<Aabb>; BINS] = [None; BINS];
        let mut bin_counts = [0usize; BINS];
        for &p in primitives.iter() {
            let bin = bin_of(p);
            bin_counts[bin] += 1;
            let aabb = aabbs[p as usize];
            bin_bounds[bin] = Some(bin_bounds[bin].map_or(aabb, |b| b.union(&aabb)));
        }
        // Sweep from the right to get the right side's area and count for every split.
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0usize; BINS];
        let mut accumulated: Option<Aabb> = None;
        let mut accumulated_count = 0;
        for bin in (1..BINS).rev() {
            if let Some(b) = bin_bounds[bin] {
                accumulated = Some(accumulated.map_or(b, |a| a.union(&b)));
            }
            accumulated_count += bin_counts[bin];
            right_area[bin] = accumulated.map_or(0.0, |a| a.surface_area());
            right_count[bin] = accumulated_count;
        }
        let mut left: Option<Aabb> = None;
        let mut left_count = 0;
        for split in 1..BINS {
            if let Some(b) = bin_bounds[split - 1] {
                left = Some(left.map_or(b, |a| a.union(&b)));
            }
            left_count += bin_counts[split - 1];
            if left_count == 0 || right_count[split] == 0 {
                continue;
            }
            let cost = left.map_or(0.0, |a| a.surface_area()) * left_count as f32
                + right_area[split] * right_count[split] as f32;
            if best.is_none_or(|(best_cost, _, _)| cost < best_cost) {
                best = Some((cost, axis, split));
            }
        }
    }

    let Some((cost, axis, split)) = best else {
        // Every centroid is the same point: no plane separates them. Halve the list so leaves
        // stay small.
        return (count > MAX_LEAF_SIZE).then_some(count / 2);
    };
    // SAH: splitting costs a traversal plus the children's expected tests; a leaf costs its
    // primitives. Areas are relative to this node's (guarded against a flat zero-area node).
    let area = bounds.surface_area().max(f32::MIN_POSITIVE);
    let split_cost = TRAVERSAL_COST + cost / area;
    if count <= MAX_LEAF_SIZE && split_cost >= count as f32 {
        return None;
    }
    let scale = BINS as f32 / extent[axis];
    let goes_left = |p: u32| {
        let bin =
            (((centroids[p as usize][axis] - centroid_min[axis]) * scale) as usize).min(BINS - 1);
        bin < split
    };
    // Stable partition (a scratch copy): primitives keep their relative order, so the result
    // does not depend on how an in-place swap happens to shuffle them.
    let (left, right): (Vec<u32>, Vec<u32>) = primitives.iter().partition(|&&p| goes_left(p));
    let left_count = left.len();
    primitives[..left_count].copy_from_slice(&left);
    primitives[left_count..].copy_from_slice(&right);
    Some(left_count)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift32: deterministic inputs without a dependency.
    struct Random(u32);

    impl Random {
        fn unit(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 17;
            self.0 ^= self.0 << 5;
            (self.0 >> 8) as f32 / (1u32 << 24) as f32
        }

        fn vec3(&mut self, scale: f32) -> Vec3 {
            Vec3::new(self.unit(), self.unit(), self.unit()) * scale
        }

        fn aabb(&mut self) -> Aabb {
            let min = self.vec3(20.0) - Vec3::splat(10.0);
            Aabb::new(min, min + self.vec3(1.5))
        }
    }

    fn random_aabbs(count: usize, seed: u32) -> Vec<Aabb> {
        let mut random = Random(seed);
        (0..count).map(|_| random.aabb()).collect()
    }

    /// Structural invariants: every primitive once, leaves small, parents enclose children.
    fn check_structure(bvh: &Bvh, aabbs: &[Aabb]) {
        let mut seen = vec![0u32; aabbs.len()];
        for node in bvh.nodes() {
            if node.is_leaf() {
                assert!(node.count as usize <= MAX_LEAF_SIZE);
                for &p in &bvh.primitives()[node.first as usize..(node.first + node.count) as usize]
                {
                    seen[p as usize] += 1;
                    assert!(node.aabb().contains(&aabbs[p as usize]));
                }
            } else {
                for child in [node.first, node.first + 1] {
                    assert!(node.aabb().contains(&bvh.nodes()[child as usize].aabb()));
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
    }

    #[test]
    fn overlap_queries_equal_brute_force() {
        for (size, seed) in [(0, 1), (1, 2), (2, 3), (1000, 4)] {
            let aabbs = random_aabbs(size, seed);
            let bvh = Bvh::build(&aabbs);
            check_structure(&bvh, &aabbs);
            let mut random = Random(seed + 100);
            for _ in 0..200 {
                let query = random.aabb().expanded(random.unit() * 2.0);
                let mut found = Vec::new();
                bvh.query_aabb(&query, &aabbs, |p| found.push(p));
                found.sort_unstable();
                let expected: Vec<u32> = (0..size as u32)
                    .filter(|&p| aabbs[p as usize].overlaps(&query))
                    .collect();
                assert_eq!(found, expected, "size {size}");
            }
        }
    }

    /// A ray parallel to z starting in the plane z = 0 runs along the faces of the boxes on
    /// either side of that plane: it enters both (closed boxes), and misses one it runs beside.
    #[test]
    fn a_ray_along_a_box_face_enters_the_box() {
        let below = Aabb::new(Vec3::new(0.0, -1.0, -1.0), Vec3::new(1.0, 0.0, 0.0));
        let above = Aabb::new(Vec3::new(0.0, -1.0, 0.0), Vec3::new(1.0, 0.0, 1.0));
        let beside = Aabb::new(Vec3::new(0.0, -1.0, 0.5), Vec3::new(1.0, 0.0, 1.0));
        let origin = Vec3::new(0.2, 2.0, 0.0);
        let inverse = Vec3::new(0.1, -1.0, 0.0).normalize().recip();
        for aabb in [below, above] {
            let entry = ray_box_entry(origin, inverse, &aabb, 10.0).unwrap();
            assert!((entry - 2.0 * Vec3::new(0.1, -1.0, 0.0).length()).abs() < 1e-5);
        }
        assert_eq!(ray_box_entry(origin, inverse, &beside, 10.0), None);
    }

    #[test]
    fn rays_find_the_same_boxes_and_the_same_closest_as_brute_force() {
        for (size, seed) in [(0, 5), (1, 6), (2, 7), (1000, 8)] {
            let aabbs = random_aabbs(size, seed);
            let bvh = Bvh::build(&aabbs);
            let mut random = Random(seed + 200);
            for ray in 0..200 {
                let origin = random.vec3(30.0) - Vec3::splat(15.0);
                let mut direction = random.vec3(2.0) - Vec3::ONE;
                // Some rays run parallel to an axis plane, exercising the infinite slabs.
                if ray % 4 == 0 {
                    direction[ray % 3] = 0.0;
                }
                let max_t = 40.0;
                let inverse = direction.recip();
                let entry =
                    |p: u32, max_t: f32| ray_box_entry(origin, inverse, &aabbs[p as usize], max_t);
                let expected: Vec<u32> = (0..size as u32)
                    .filter(|&p| entry(p, max_t).is_some())
                    .collect();

                let mut all = Vec::new();
                bvh.ray(origin, direction, max_t, |p, current| {
                    if entry(p, current).is_some() {
                        all.push(p);
                    }
                    current
                });
                all.sort_unstable();
                assert_eq!(all, expected, "size {size}");

                let mut closest = None;
                bvh.ray(origin, direction, max_t, |p, current| {
                    match entry(p, current) {
                        Some(t) => {
                            closest = Some((t, p));
                            t
                        }
                        None => current,
                    }
                });
                let expected_closest = expected
                    .iter()
                    .map(|&p| entry(p, max_t).unwrap())
                    .min_by(f32::total_cmp);
                assert_eq!(closest.map(|(t, _)| t), expected_closest, "size {size}");
            }
        }
    }

    #[test]
    fn identical_boxes_still_make_small_leaves() {
        let aabbs = vec![Aabb::new(Vec3::ZERO, Vec3::ONE); 37];
        let bvh = Bvh::build(&aabbs);
        check_structure(&bvh, &aabbs);
        let mut found = Vec::new();
        bvh.query_aabb(
            &Aabb::new(Vec3::splat(0.5), Vec3::splat(0.6)),
            &aabbs,
            |p| found.push(p),
        );
        assert_eq!(found.len(), 37);
    }

    #[test]
    fn build_is_deterministic() {
        let aabbs = random_aabbs(500, 9);
        assert_eq!(Bvh::build(&aabbs), Bvh::build(&aabbs));
    }
}
