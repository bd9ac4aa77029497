//! Child contacts: the manifolds of pairs that need more than one normal — a body on a triangle
//! mesh touches several triangles, each with its own face; a compound touches with several
//! children — kept persistent from step to step like the pairs themselves.
//!
//! # Layout
//!
//! ```text
//!   pair cache:   keys [k0 k1 k2 ...]            values [PairContact ...]  (unchanged layout)
//!   child cache:  keys [(k1, t3) (k1, t4) (k2, t0) ...]  values [PairContact ...]
//! ```
//!
//! A pair with a mesh keeps an empty manifold in the pair cache; its contacts live in the child
//! cache, one [`PairContact`] per (pair key, triangle index), sorted by that key. Each step the
//! narrowphase rebuilds the child list from the mesh pairs and, in one merge with last step's
//! sorted list, reports which children were added, removed or kept. The constraint stage
//! addresses manifolds by *slot*: slots `0..pairs` are the pair cache's values, slots `pairs..`
//! the child cache's, so the solver's impulses go back to the right place.
//!
//! # Coplanar triangles share one manifold
//!
//! Triangles of one pair whose contact normals agree within [`COPLANAR_COSINE`] (a tessellated
//! floor) are merged into one manifold, reduced to 4 points like a box face, keyed by the
//! lowest triangle of the group. Kept apart, a box on such a floor gets a manifold per triangle
//! under it, 10 to 20 points whose friction rows share the load differently from the plane's 4
//! corners: measured, a box sliding over 0.5 m cells picked up 0.05 rad/s of yaw and drifted
//! sideways off the plane's path, with 10 or 60 solver iterations alike
//! (`tests/engine/trimesh_floor.rs`). Merged, the floor holds it by the same 4 corners a plane does.
//!
//! # Warm starting across triangles
//!
//! A child's points carry triangle-qualified feature ids (`triangle << 12 | feature`), unique
//! within the pair, and take over impulses from *any* of last step's children of the same pair:
//! same id first, then the nearest anchor within `MATCH_DISTANCE` (as [`carry_impulses`] does
//! within one pair). So a box sliding from one triangle to the next, or a merged group whose
//! lowest triangle changes, keeps its impulses.
//!
//! Guarantees: keys sorted ascending and unique; the result depends only on poses and last
//! step's children, never on thread count (children are computed per pair in parallel and
//! concatenated in pair order).

use super::{MATCH_DISTANCE, NarrowphaseInputs, PairContact, PointImpulse};
use crate::collision::contact::{collide_compound, collide_mesh, mix_child_ids};
use crate::collision::manifold::{ContactPoint, MAX_MANIFOLD_POINTS, Manifold, reduce};
use crate::math::{Quat, Transform};
use crate::shape::{Shape, TriMesh};
use crate::stages::pairs::pair_bodies;
use rayon::prelude::*;

/// (pair key, child index): the child index is the (lowest merged) triangle of the mesh,
/// `child_a * children_b + child_b` for a pair with a compound (`collide_compound`), or
/// `child * triangles + triangle` for a compound on a mesh.
pub type ChildKey = (u64, u32);

/// Cosine of the angle (0.5°) under which two triangles' contact normals count as one plane and
/// their contacts share a manifold.
pub const COPLANAR_COSINE: f32 = 0.999_96;

/// Bits of a child point's feature id left for the triangle's own feature (see
/// `collision::contact::triangle` and `hull_triangle`: box and hull ids use bits 0–11).
const TRIANGLE_ID_SHIFT: u32 = 12;

/// Child manifolds, sorted by key; see the module documentation.
#[derive(Clone, Debug, Default)]
pub struct ChildCache {
    keys: Vec<ChildKey>,
    values: Vec<PairContact>,
    /// Last step's children while the next are built; swapped, never rebuilt, so the buffers
    /// stop allocating once they have grown to the scene's size.
    old_keys: Vec<ChildKey>,
    old_values: Vec<PairContact>,
    /// Old points (4 per old child of the current pair) already given to a new point.
    claimed: Vec<bool>,
    added: usize,
    removed: usize,
}

impl ChildCache {
    pub fn keys(&self) -> &[ChildKey] {
        &self.keys
    }

    pub fn values(&self) -> &[PairContact] {
        &self.values
    }

    pub fn values_mut(&mut self) -> &mut [PairContact] {
        &mut self.values
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Children the last update added and removed.
    pub fn added(&self) -> usize {
        self.added
    }

    pub fn removed(&self) -> usize {
        self.removed
    }

    /// Sets a child's warm-start state (loading a dump), keeping the keys sorted.
    pub fn insert(&mut self, key: ChildKey, value: PairContact) {
        match self.keys.binary_search(&key) {
            Ok(index) => self.values[index] = value,
            Err(index) => {
                self.keys.insert(index, key);
                self.values.insert(index, value);
            }
        }
    }

    /// Replaces the children with this step's `(key, manifold)` list (sorted by key), carrying
    /// impulses over from last step's children of the same pair (module docs).
    fn replace(&mut self, fresh: impl Iterator<Item = (ChildKey, Manifold)>) {
        std::mem::swap(&mut self.keys, &mut self.old_keys);
        std::mem::swap(&mut self.values, &mut self.old_values);
        self.keys.clear();
        self.values.clear();
        let (old_keys, old_values) = (&self.old_keys, &self.old_values);
        let claimed = &mut self.claimed;
        // Old children of the current pair: old_keys[pair_start..pair_end]. Both lists are
        // sorted, so the range only moves forward.
        let (mut pair_start, mut pair_end) = (0, 0);
        let mut current_pair = None;
        let mut old = 0;
        let mut kept = 0;
        for (key, manifold) in fresh {
            debug_assert!(self.keys.last().is_none_or(|&last| last < key));
            if current_pair != Some(key.0) {
                current_pair = Some(key.0);
                pair_start = pair_end;
                while pair_start < old_keys.len() && old_keys[pair_start].0 < key.0 {
                    pair_start += 1;
                }
                pair_end = pair_start;
                while pair_end < old_keys.len() && old_keys[pair_end].0 == key.0 {
                    pair_end += 1;
                }
                claimed.clear();
                claimed.resize((pair_end - pair_start) * MAX_MANIFOLD_POINTS, false);
            }
            while old < old_keys.len() && old_keys[old] < key {
                old += 1;
            }
            if old < old_keys.len() && old_keys[old] == key {
                kept += 1;
            }
            let contact = carry_from_children(manifold, &old_values[pair_start..pair_end], claimed);
            self.keys.push(key);
            self.values.push(contact);
        }
        self.added = self.keys.len() - kept;
        self.removed = old_keys.len() - kept;
    }
}

/// The new manifold with the impulses of last step's points of the same pair (`old`, all its
/// children): same feature id first, then the nearest unclaimed point within
/// [`MATCH_DISTANCE`]. `claimed` marks old points (4 per child) already taken, across the
/// pair's new children.
fn carry_from_children(
    manifold: Manifold,
    old: &[PairContact],
    claimed: &mut [bool],
) -> PairContact {
    let mut impulses = [PointImpulse::default(); MAX_MANIFOLD_POINTS];
    let old_points = || {
        old.iter().enumerate().flat_map(|(child, contact)| {
            contact
                .manifold
                .points()
                .iter()
                .zip(&contact.impulses)
                .enumerate()
                .map(move |(point, (p, i))| (child * MAX_MANIFOLD_POINTS + point, p, i))
        })
    };
    let mut matched = [false; MAX_MANIFOLD_POINTS];
    for (index, point) in manifold.points().iter().enumerate() {
        if let Some((slot, _, impulse)) =
            old_points().find(|(slot, old, _)| !claimed[*slot] && old.id == point.id)
        {
            impulses[index] = *impulse;
            claimed[slot] = true;
            matched[index] = true;
        }
    }
    for (index, point) in manifold.points().iter().enumerate() {
        if matched[index] {
            continue;
        }
        let nearest = old_points()
            .filter(|(slot, _, _)| !claimed[*slot])
            .map(|(slot, old, impulse)| (slot, old.anchor.distance_squared(point.anchor), impulse))
            .filter(|&(_, distance_squared, _)| distance_squared < MATCH_DISTANCE * MATCH_DISTANCE)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((slot, _, impulse)) = nearest {
            impulses[index] = *impulse;
            claimed[slot] = true;
        }
    }
    // Child manifolds are computed afresh each step: they keep no cache.
    PairContact {
        manifold,
        impulses,
        ..PairContact::default()
    }
}

/// Merges the manifolds of `found` (sorted by triangle) whose normals agree within
/// [`COPLANAR_COSINE`] *and* are their triangles' face normals into the first of each group,
/// reduced to 4 points; ids become triangle-qualified (module docs). Returns the merged list,
/// still sorted by triangle. Manifolds with another normal (a box face or edge on the
/// triangle) stay apart: triangles that are not coplanar can share such a normal, and their
/// points belong to different surfaces.
fn merge_coplanar(
    found: Vec<(u32, Manifold)>,
    mesh: &TriMesh,
    mesh_rotation: Quat,
) -> Vec<(u32, Manifold)> {
    let on_face = |(triangle, manifold): &(u32, Manifold)| {
        let face = mesh_rotation * mesh.triangle(*triangle).normal;
        manifold.normal.dot(face).abs() >= COPLANAR_COSINE
    };
    let mut taken = vec![false; found.len()];
    let mut merged = Vec::with_capacity(found.len());
    let mut candidates: Vec<ContactPoint> = Vec::new();
    for first in 0..found.len() {
        if taken[first] {
            continue;
        }
        let normal = found[first].1.normal;
        let mergeable = on_face(&found[first]);
        candidates.clear();
        for member in first..found.len() {
            let (triangle, manifold) = &found[member];
            let joins = member == first
                || (mergeable
                    && on_face(&found[member])
                    && manifold.normal.dot(normal) >= COPLANAR_COSINE);
            if taken[member] || !joins {
                continue;
            }
            taken[member] = true;
            candidates.extend(manifold.points().iter().map(|point| ContactPoint {
                id: point.id | (triangle << TRIANGLE_ID_SHIFT),
                ..*point
            }));
        }
        merged.push((found[first].0, reduce(&candidates, normal)));
    }
    merged
}

/// True when the pair's contacts go through the child cache: pairs with a mesh (a manifold per
/// triangle) or a compound (a manifold per child pair).
pub fn has_children(a: &Shape, b: &Shape) -> bool {
    let split = |shape: &Shape| matches!(shape, Shape::TriMesh(_) | Shape::Compound(_));
    split(a) || split(b)
}

/// CPU executor: the child manifolds of every pair with a mesh or a compound (keys from the
/// pair cache, sorted), into `children`.
pub fn update_child_contacts(keys: &[u64], inputs: &NarrowphaseInputs, children: &mut ChildCache) {
    let NarrowphaseInputs {
        poses,
        colliders,
        skipped,
        // The margin is `pair_margin`'s.
        velocities: _,
        margin: _,
        dt: _,
        // Sleeping bodies' child manifolds are recomputed: the same poses give the same
        // manifolds and impulses, at the cost of the narrowphase work.
        keep_resting: _,
    } = *inputs;
    let per_pair: Vec<Vec<(ChildKey, Manifold)>> = keys
        .par_iter()
        .filter(|&&key| {
            let (a, b) = pair_bodies(key);
            has_children(&colliders[a as usize].shape, &colliders[b as usize].shape)
                && skipped.binary_search(&key).is_err()
        })
        .map(|&key| {
            let (a, b) = pair_bodies(key);
            let (a, b) = (a as usize, b as usize);
            let margin = inputs.pair_margin(a, b);
            let (shape_a, shape_b) = (&colliders[a].shape, &colliders[b].shape);
            let (pose_a, pose_b) = (poses[a].transform(), poses[b].transform());
            let found = match (shape_a, shape_b) {
                (_, Shape::TriMesh(mesh)) => mesh_children(shape_a, &pose_a, mesh, &pose_b, margin),
                // The mesh is the second argument of `collide_mesh`: flip the normal to run
                // from B to A.
                (Shape::TriMesh(mesh), _) => {
                    let mut found = mesh_children(shape_b, &pose_b, mesh, &pose_a, margin);
                    for (_, manifold) in &mut found {
                        *manifold = manifold.flipped();
                    }
                    found
                }
                _ => {
                    let mut found = Vec::new();
                    collide_compound(shape_a, &pose_a, shape_b, &pose_b, margin, &mut found);
                    found
                }
            };
            found
                .into_iter()
                .map(|(child, mut manifold)| {
                    let count = manifold.count as usize;
                    for point in &mut manifold.points[..count] {
                        point.anchor = pose_a.inverse_transform_point(point.position);
                    }
                    ((key, child), manifold)
                })
                .collect()
        })
        .collect();
    children.replace(per_pair.into_iter().flatten());
}

/// The triangle manifolds of `shape` (at `pose`) on `mesh` (at `mesh_pose`), coplanar ones
/// merged, normals from the mesh to the shape, sorted by child index. A compound's children
/// each get their own: child index `child * triangles + triangle` (`World::add_body` keeps it
/// in a u32), ids mixed with the child's so that children never trade impulses by id. With a
/// child BVH only the children near the mesh's bounds are tried, which changes no manifold.
fn mesh_children(
    shape: &Shape,
    pose: &Transform,
    mesh: &TriMesh,
    mesh_pose: &Transform,
    margin: f32,
) -> Vec<(u32, Manifold)> {
    let mut found = Vec::new();
    let Shape::Compound(compound) = shape else {
        collide_mesh(shape, pose, mesh, mesh_pose, margin, &mut found);
        return merge_coplanar(found, mesh, mesh_pose.rotation);
    };
    let triangles = mesh.triangles().len() as u32;
    let mut near = Vec::new();
    match (compound.child_bvh(), mesh.bvh().root_aabb()) {
        // Only children near the mesh's bounds can meet a triangle: `collide_mesh` finds
        // none for a child whose box (mesh frame, grown by the margin) misses them.
        (Some(_), Some(mesh_bounds)) => {
            let in_mesh_frame = mesh_pose.inverse().mul_transform(pose);
            compound.children_near(&in_mesh_frame, &mesh_bounds.expanded(margin), &mut near);
        }
        (Some(_), None) => {}
        (None, _) => near.extend(0..compound.children().len() as u32),
    }
    let mut all = Vec::new();
    for index in near {
        let child = &compound.children()[index as usize];
        let child_pose = pose.mul_transform(&child.pose);
        collide_mesh(
            &child.shape,
            &child_pose,
            mesh,
            mesh_pose,
            margin,
            &mut found,
        );
        let first = index * triangles;
        all.extend(
            merge_coplanar(std::mem::take(&mut found), mesh, mesh_pose.rotation)
                .into_iter()
                .map(|(triangle, mut manifold)| {
                    mix_child_ids(&mut manifold, index);
                    (first + triangle, manifold)
                }),
        );
    }
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    fn manifold(points: &[(u32, Vec3)]) -> Manifold {
        let mut manifold = Manifold {
            normal: Vec3::Y,
            ..Manifold::default()
        };
        for &(id, anchor) in points {
            manifold.push(ContactPoint {
                anchor,
                ..ContactPoint::new(anchor, 0.0, id)
            });
        }
        manifold
    }

    #[test]
    fn impulses_follow_a_body_from_one_triangle_to_the_next() {
        let mut cache = ChildCache::default();
        let near = Vec3::new(0.0, 0.0, 0.0);
        cache.replace(
            [
                ((7, 3), manifold(&[(3 << 12, near)])),
                ((9, 1), manifold(&[(1 << 12, Vec3::X)])),
            ]
            .into_iter(),
        );
        assert_eq!((cache.added(), cache.removed()), (2, 0));
        cache.values_mut()[0].impulses[0].normal = 1.5;
        cache.values_mut()[1].impulses[0].normal = 2.5;

        // Pair 7's point moved 1 cm onto triangle 4 (new key, new id): it keeps its impulse.
        // Pair 9 is gone; pair 8 is new and near pair 9's old point, but another pair's
        // impulses never carry over.
        cache.replace(
            [
                (
                    (7, 4),
                    manifold(&[(4 << 12, near + Vec3::new(0.01, 0.0, 0.0))]),
                ),
                ((8, 1), manifold(&[(1 << 12, Vec3::X)])),
            ]
            .into_iter(),
        );
        assert_eq!(cache.keys(), [(7, 4), (8, 1)]);
        assert_eq!((cache.added(), cache.removed()), (2, 2));
        assert_eq!(cache.values()[0].impulses[0].normal, 1.5);
        assert_eq!(cache.values()[1].impulses[0].normal, 0.0);

        // The same child again: kept, and an old point is claimed once only.
        cache.replace(
            [(
                (7, 4),
                manifold(&[(99, near), (98, near + Vec3::new(0.001, 0.0, 0.0))]),
            )]
            .into_iter(),
        );
        assert_eq!((cache.added(), cache.removed()), (0, 1));
        let normals: Vec<f32> = cache.values()[0].impulses[..2]
            .iter()
            .map(|impulse| impulse.normal)
            .collect();
        assert_eq!(normals, [1.5, 0.0]);
    }
}
