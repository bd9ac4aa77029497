//! Ray traversal of a [`Dbvt`]: the leaves whose fat AABBs a ray segment meets, nearer
//! subtrees first, with the segment shortened by the caller as hits come in (Box2D's
//! `b2DynamicTree_RayCast` callback contract).

use super::{Dbvt, NULL_NODE, NodeStack};
use crate::math::{Aabb, Vec3};

/// Where the segment `origin + t · direction`, `t` in `[0, max_distance]`, enters `aabb`:
/// `Some(t)` (0 when the origin is inside), `None` when it misses. Closed box: touching is a
/// hit. An axis the segment is parallel to rejects it when the origin lies outside that slab,
/// which avoids the 0 · ∞ = NaN of the branch-free slab test.
#[inline]
pub fn segment_enters_aabb(
    origin: Vec3,
    direction: Vec3,
    max_distance: f32,
    aabb: &Aabb,
) -> Option<f32> {
    let mut enter = 0.0f32;
    let mut exit = max_distance;
    for axis in 0..3 {
        let (o, d) = (origin[axis], direction[axis]);
        let (low, high) = (aabb.min[axis], aabb.max[axis]);
        if d == 0.0 {
            if o < low || o > high {
                return None;
            }
            continue;
        }
        let inverse = 1.0 / d;
        let (mut near, mut far) = ((low - o) * inverse, (high - o) * inverse);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        enter = enter.max(near);
        exit = exit.min(far);
        if enter > exit {
            return None;
        }
    }
    Some(enter)
}

impl Dbvt {
    /// Calls `visit(user)` for the leaves whose fat AABB the segment `origin + t · direction`,
    /// `t` in `[0, max_distance]`, meets. `visit` returns the segment's new end: `max_distance`
    /// or more to go on unchanged, a smaller `t` (a hit's distance) to skip every subtree the
    /// segment enters only after it, a negative value to stop. Leaves entered exactly at the
    /// new end are still visited, so ties can be broken by the caller.
    ///
    /// The order is deterministic: depth first, the child the segment enters first before the
    /// other (the left one on a tie), which finds near hits early and prunes the most.
    /// `direction` need not be unit length: `t` is then in units of its length.
    pub fn ray_cast(
        &self,
        origin: Vec3,
        direction: Vec3,
        max_distance: f32,
        visit: impl FnMut(u32) -> f32,
    ) {
        self.ray_cast_inflated(origin, direction, max_distance, 0.0, visit);
    }

    /// [`Self::ray_cast`] with every box grown by `inflate` (m) on every side: the traversal
    /// of a sphere cast of radius `inflate`, whose ball stays inside the grown boxes of what
    /// it can touch.
    pub fn ray_cast_inflated(
        &self,
        origin: Vec3,
        direction: Vec3,
        max_distance: f32,
        inflate: f32,
        mut visit: impl FnMut(u32) -> f32,
    ) {
        if self.root == NULL_NODE {
            return;
        }
        let mut end = max_distance;
        let mut stack = NodeStack::new();
        stack.push(self.root);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if segment_enters_aabb(origin, direction, end, &node.aabb.expanded(inflate)).is_none() {
                continue;
            }
            if node.is_leaf() {
                end = end.min(visit(node.user));
                if end < 0.0 {
                    return;
                }
                continue;
            }
            let [first, second] = node.children;
            let entry = |child: u32| {
                let aabb = self.nodes[child as usize].aabb.expanded(inflate);
                segment_enters_aabb(origin, direction, end, &aabb)
            };
            match (entry(first), entry(second)) {
                (Some(a), Some(b)) => {
                    // Pushed last, popped first: the nearer child.
                    let (near, far) = if b < a {
                        (second, first)
                    } else {
                        (first, second)
                    };
                    stack.push(far);
                    stack.push(near);
                }
                (Some(_), None) => stack.push(first),
                (None, Some(_)) => stack.push(second),
                (None, None) => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::TestRng;
    use super::*;

    /// Every leaf the segment meets, by brute force over the fat AABBs, with its entry.
    /// In user order.
    fn brute_force(boxes: &[Aabb], origin: Vec3, direction: Vec3, max: f32) -> Vec<(u32, f32)> {
        boxes
            .iter()
            .enumerate()
            .filter_map(|(user, aabb)| {
                segment_enters_aabb(origin, direction, max, aabb).map(|t| (user as u32, t))
            })
            .collect()
    }

    #[test]
    fn segment_aabb_closed_forms() {
        let unit = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let enter = |o: Vec3, d: Vec3, max: f32| segment_enters_aabb(o, d, max, &unit);
        assert_eq!(enter(Vec3::new(-2.0, 0.5, 0.5), Vec3::X, 10.0), Some(2.0));
        assert_eq!(enter(Vec3::new(-2.0, 0.5, 0.5), Vec3::X, 1.9), None);
        assert_eq!(enter(Vec3::new(0.5, 0.5, 0.5), Vec3::X, 10.0), Some(0.0));
        assert_eq!(enter(Vec3::new(2.0, 0.5, 0.5), Vec3::X, 10.0), None);
        // Parallel on the face plane (touching) hits, just off it misses, with no NaN.
        assert_eq!(enter(Vec3::new(-2.0, 1.0, 0.0), Vec3::X, 10.0), Some(2.0));
        assert_eq!(enter(Vec3::new(-2.0, 1.01, 0.0), Vec3::X, 10.0), None);
        assert_eq!(enter(Vec3::new(0.0, 1.0, 1.0), -Vec3::Y, 10.0), Some(0.0));
    }

    #[test]
    fn ray_cast_matches_brute_force_on_random_trees() {
        let mut rng = TestRng::new(0xa11);
        for count in [0usize, 1, 2, 7, 100, 1000] {
            let mut tree = Dbvt::new();
            let boxes: Vec<Aabb> = (0..count).map(|_| rng.aabb(40.0)).collect();
            for (user, aabb) in boxes.iter().enumerate() {
                tree.insert(*aabb, user as u32);
            }
            for _ in 0..200 {
                let origin = rng.vec3(-30.0, 30.0);
                let mut direction = rng.vec3(-1.0, 1.0).normalize_or(Vec3::Y);
                // Some rays along an axis, to walk the parallel-slab branch.
                if rng.below(4) == 0 {
                    direction = [Vec3::X, -Vec3::Y, Vec3::Z][rng.below(3)];
                }
                let max = rng.range(1.0, 80.0);

                // Without clipping: exactly the brute-force set, each once.
                let mut all = Vec::new();
                tree.ray_cast(origin, direction, max, |user| {
                    all.push(user);
                    max
                });
                let expected = brute_force(&boxes, origin, direction, max);
                let mut sorted = all.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, expected.iter().map(|h| h.0).collect::<Vec<_>>());

                // Clipping at each entry: the leaves with the nearest entry are all still
                // visited, so the closest (entry, user) is the brute-force one.
                let mut best: Option<(f32, u32)> = None;
                tree.ray_cast(origin, direction, max, |user| {
                    let entry = segment_enters_aabb(origin, direction, max, &boxes[user as usize])
                        .expect("visited leaves are met by the segment");
                    if best.is_none_or(|b| (entry, user) < b) {
                        best = Some((entry, user));
                    }
                    best.map_or(max, |b| b.0)
                });
                let nearest = expected
                    .iter()
                    .map(|&(user, t)| (t, user))
                    .min_by(|a, b| a.partial_cmp(b).unwrap());
                assert_eq!(best, nearest);
            }
        }
    }

    #[test]
    fn a_negative_end_stops_the_traversal() {
        let mut tree = Dbvt::new();
        for user in 0..10 {
            tree.insert(Aabb::new(Vec3::ZERO, Vec3::ONE), user);
        }
        let mut visits = 0;
        tree.ray_cast(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 10.0, |_| {
            visits += 1;
            -1.0
        });
        assert_eq!(visits, 1);
    }
}
