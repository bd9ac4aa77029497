//! Scene queries on [`World`]: ray casts (closest hit, all hits), sphere and shape casts and box
//! overlap, through the broadphase trees, with a [`QueryFilter`].
//!
//! ```
//! use tumble::{BodyDesc, QueryFilter, Shape, StepConfig, World, collision::ray::Ray, math::Vec3};
//!
//! let mut world = World::new(StepConfig::default()).unwrap();
//! let ground = world.add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))).unwrap();
//! let ball = world
//!     .add_body(BodyDesc::dynamic(Shape::sphere(0.5)).position(Vec3::new(0.0, 3.0, 0.0)))
//!     .unwrap();
//! let down = Ray::new(Vec3::new(0.0, 10.0, 0.0), -Vec3::Y, 100.0).unwrap();
//! let hit = world.cast_ray(&down, &QueryFilter::default()).unwrap();
//! assert_eq!((hit.body, hit.distance), (ball, 6.5));
//! // Looking through the ball at what lies under it:
//! let under = world.cast_ray(&down, &QueryFilter::default().exclude_body(ball)).unwrap();
//! assert_eq!((under.body, under.distance), (ground, 10.0));
//! ```
//!
//! Exactness: the trees hold each body's fat AABB from the last broadphase update, and the step
//! moves bodies after that update, so a body may have left its fat box by the time a query
//! runs. The first query after a step (or after bodies were added or removed) lists those
//! bodies, O(n) once, and tests them one by one; the tree supplies the rest. Results are
//! therefore exactly those of testing every body, as the tests check against brute force.
//!
//! Determinism: ties are broken by body index. Closest hit: the smallest distance, then the
//! lowest index; all hits: sorted by (distance, index); box query: by index.

use crate::collision::ray::{CastError, Ray, ShapeHit, SweptParts, cast_ray, cast_sphere};
use crate::dynamics::body::BodyHandle;
use crate::math::{Aabb, Transform, Vec3};
use crate::pipeline::world::World;
use crate::shape::Shape;

/// Which bodies a query may report. The default reports every body.
///
/// ```
/// # use tumble::QueryFilter;
/// let only_dynamic = QueryFilter::default().exclude_static();
/// let odd = |body: tumble::BodyHandle| body.index() % 2 == 1;
/// let only_odd = QueryFilter::default().predicate(&odd);
/// ```
#[derive(Clone, Copy, Default)]
#[must_use]
pub struct QueryFilter<'a> {
    /// Skip static bodies (mass 0: the ground, walls).
    pub exclude_static: bool,
    /// Skip dynamic bodies.
    pub exclude_dynamic: bool,
    /// Skip this body (the one casting the ray, typically).
    pub exclude_body: Option<BodyHandle>,
    /// Report only bodies for which this returns true; called only for bodies the other
    /// fields let through, and only for candidates the shapes are tested against.
    pub predicate: Option<&'a dyn Fn(BodyHandle) -> bool>,
}

impl<'a> QueryFilter<'a> {
    pub fn exclude_static(self) -> Self {
        Self {
            exclude_static: true,
            ..self
        }
    }

    pub fn exclude_dynamic(self) -> Self {
        Self {
            exclude_dynamic: true,
            ..self
        }
    }

    pub fn exclude_body(self, body: BodyHandle) -> Self {
        Self {
            exclude_body: Some(body),
            ..self
        }
    }

    pub fn predicate(self, predicate: &'a dyn Fn(BodyHandle) -> bool) -> Self {
        Self {
            predicate: Some(predicate),
            ..self
        }
    }
}

impl std::fmt::Debug for QueryFilter<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QueryFilter")
            .field("exclude_static", &self.exclude_static)
            .field("exclude_dynamic", &self.exclude_dynamic)
            .field("exclude_body", &self.exclude_body)
            .field(
                "predicate",
                &self.predicate.map(|_| "Fn(BodyHandle) -> bool"),
            )
            .finish()
    }
}

/// A ray's (or a swept shape's) hit on a body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    pub body: BodyHandle,
    /// Along the ray from its origin (m); 0 when the origin is inside the body.
    pub distance: f32,
    /// World frame (m).
    pub point: Vec3,
    /// Outward unit surface normal (world frame); `-direction` when the origin is inside.
    pub normal: Vec3,
}

/// Why a query could not run.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum QueryError {
    #[error("query box {min:?}..{max:?} is not finite")]
    AabbNotFinite { min: Vec3, max: Vec3 },
    #[error("query box {min:?}..{max:?} has min > max on some axis")]
    AabbInverted { min: Vec3, max: Vec3 },
    #[error("sphere cast radius {0} must be finite and >= 0")]
    BadRadius(f32),
    #[error(transparent)]
    Cast(#[from] CastError),
}

impl World {
    /// The closest body `ray` hits, or `None`. Ties go to the lower body index.
    pub fn cast_ray(&self, ray: &Ray, filter: &QueryFilter) -> Option<RayHit> {
        self.closest(ray, 0.0, |index, ray| self.ray_hit(index, ray, filter))
    }

    /// Sweeps a ball of `radius` (m) whose centre follows `ray`; returns the first body it
    /// touches (`distance`: how far the centre travelled; `point`: the contact on the body;
    /// `normal`: the body's outward normal there), ties to the lower body index. A ball that
    /// already touches a body at the start hits it at 0 (see [`cast_sphere`]).
    pub fn cast_sphere(
        &self,
        radius: f32,
        ray: &Ray,
        filter: &QueryFilter,
    ) -> Result<Option<RayHit>, QueryError> {
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(QueryError::BadRadius(radius));
        }
        Ok(self.closest(ray, radius, |index, ray| {
            if !self.passes(index, filter) {
                return None;
            }
            let i = index as usize;
            let pose = self.current_bodies_or_host().0[i].transform();
            let hit = cast_sphere(radius, &self.colliders[i].shape, &pose, ray)?;
            Some(RayHit {
                body: self.handle_of(index),
                distance: hit.distance,
                point: hit.point,
                normal: hit.normal,
            })
        }))
    }

    /// Sweeps `shape` (sphere, capsule, box, convex hull, or a compound of them) from `pose`
    /// along `direction` (any non-zero length) for at most `max_distance` (m), without turning;
    /// returns the first body it touches (`distance`: how far the shape travelled; `point`: the
    /// contact; `normal`: the body's outward normal there), ties to the lower body index. A
    /// shape that already touches a body at the start hits it at 0, at `pose.position`, with
    /// the normal `-direction`. See [`cast_shape`](crate::collision::ray::cast_shape) for the
    /// method; a compound hits where its first child to hit does, each child swept from its
    /// own pose ([`SweptParts`]).
    ///
    /// ```
    /// use tumble::{BodyDesc, QueryFilter, Shape, StepConfig, World};
    /// use tumble::math::{Transform, Vec3};
    ///
    /// let mut world = World::new(StepConfig::default()).unwrap();
    /// world.add_body(BodyDesc::fixed(Shape::plane(Vec3::Y, 0.0))).unwrap();
    /// let crate_box = Shape::cuboid(Vec3::splat(0.5));
    /// let start = Transform::from_position(Vec3::new(0.0, 3.0, 0.0));
    /// let hit = world
    ///     .cast_shape(&crate_box, &start, -Vec3::Y, 10.0, &QueryFilter::default())
    ///     .unwrap()
    ///     .unwrap();
    /// assert_eq!(hit.distance, 2.5);
    /// ```
    pub fn cast_shape(
        &self,
        shape: &Shape,
        pose: &Transform,
        direction: Vec3,
        max_distance: f32,
        filter: &QueryFilter,
    ) -> Result<Option<RayHit>, QueryError> {
        let sweep = SweptParts::new(shape, pose, direction, max_distance)?;
        // The broadphase walk is a ray walk over boxes grown by the shape's bounding radius:
        // the swept shape stays within that distance of its path.
        Ok(
            self.closest(sweep.path(), sweep.bounding_radius(), |index, path| {
                if !self.passes(index, filter) {
                    return None;
                }
                let i = index as usize;
                let hit = sweep.cast(
                    &self.colliders[i].shape,
                    &self.current_bodies_or_host().0[i].transform(),
                    path.max_distance(),
                )?;
                Some(RayHit {
                    body: self.handle_of(index),
                    distance: hit.distance,
                    point: hit.point,
                    normal: hit.normal,
                })
            }),
        )
    }

    /// The smallest (distance, index) hit of `hit_of` (which applies the filter) over the
    /// bodies whose fat AABB grown by `inflate` the ray meets, and over the escaped bodies.
    fn closest(
        &self,
        ray: &Ray,
        inflate: f32,
        hit_of: impl Fn(u32, &Ray) -> Option<RayHit>,
    ) -> Option<RayHit> {
        let escaped = self.escaped_bodies();
        let mut best: Option<RayHit> = None;
        let mut consider = |index: u32, end: f32| {
            if let Some(hit) = hit_of(index, &ray.with_max_distance(end))
                && best.is_none_or(|b| (hit.distance, hit.body.index) < (b.distance, b.body.index))
            {
                best = Some(hit);
            }
            best.map_or(ray.max_distance(), |b| b.distance)
        };
        let (origin, direction) = (ray.origin(), ray.direction());
        let mut end = ray.max_distance();
        self.broadphase
            .ray_cast(origin, direction, ray.max_distance(), inflate, |index| {
                // Escaped bodies are tested below, once.
                if escaped.binary_search(&index).is_err() {
                    end = consider(index, end);
                }
                end
            });
        for &index in escaped {
            end = consider(index, end);
        }
        best
    }

    /// Every body `ray` hits (once each, where it enters), into `hits` (cleared first), sorted
    /// by distance, ties by body index.
    pub fn cast_ray_all(&self, ray: &Ray, filter: &QueryFilter, hits: &mut Vec<RayHit>) {
        hits.clear();
        let escaped = self.escaped_bodies();
        let (origin, direction, max) = (ray.origin(), ray.direction(), ray.max_distance());
        self.broadphase
            .ray_cast(origin, direction, max, 0.0, |index| {
                if escaped.binary_search(&index).is_err() {
                    hits.extend(self.ray_hit(index, ray, filter));
                }
                max
            });
        hits.extend(
            escaped
                .iter()
                .filter_map(|&index| self.ray_hit(index, ray, filter)),
        );
        hits.sort_unstable_by(|a, b| {
            a.distance
                .total_cmp(&b.distance)
                .then(a.body.index.cmp(&b.body.index))
        });
    }

    /// The bodies whose AABB at their current pose overlaps or touches `aabb` (the box test,
    /// not the exact shape), into `bodies` (cleared first), by index.
    pub fn intersect_aabb(
        &self,
        aabb: &Aabb,
        filter: &QueryFilter,
        bodies: &mut Vec<BodyHandle>,
    ) -> Result<(), QueryError> {
        let (min, max) = (aabb.min, aabb.max);
        if !(min.is_finite() && max.is_finite()) {
            return Err(QueryError::AabbNotFinite { min, max });
        }
        if min.cmpgt(max).any() {
            return Err(QueryError::AabbInverted { min, max });
        }
        bodies.clear();
        let escaped = self.escaped_bodies();
        let mut consider = |index: u32| {
            let i = index as usize;
            let pose = self.current_bodies_or_host().0[i].transform();
            let shape_aabb = self.colliders[i].shape.aabb(&pose);
            if shape_aabb.overlaps(aabb) && self.passes(index, filter) {
                bodies.push(self.handle_of(index));
            }
        };
        self.broadphase.query(aabb, |index| {
            if escaped.binary_search(&index).is_err() {
                consider(index);
            }
        });
        escaped.iter().for_each(|&index| consider(index));
        bodies.sort_unstable();
        Ok(())
    }

    /// `ray` against body `index`'s shape, if the filter lets the body through.
    fn ray_hit(&self, index: u32, ray: &Ray, filter: &QueryFilter) -> Option<RayHit> {
        if !self.passes(index, filter) {
            return None;
        }
        let i = index as usize;
        let ShapeHit {
            distance,
            point,
            normal,
        } = cast_ray(
            &self.colliders[i].shape,
            &self.current_bodies_or_host().0[i].transform(),
            ray,
        )?;
        Some(RayHit {
            body: self.handle_of(index),
            distance,
            point,
            normal,
        })
    }

    fn passes(&self, index: u32, filter: &QueryFilter) -> bool {
        // The body's kind, not its mass: a sleeping body has none while asleep.
        let is_static = !self.slots[index as usize].is_dynamic();
        let body = self.handle_of(index);
        let excluded_kind = if is_static {
            filter.exclude_static
        } else {
            filter.exclude_dynamic
        };
        !excluded_kind
            && filter.exclude_body != Some(body)
            && filter.predicate.is_none_or(|keep| keep(body))
    }

    /// Sorted indices of the bodies whose AABB at their current pose is not inside their fat
    /// AABB in the broadphase (see the module documentation); computed by the first query after
    /// the bodies moved, were added or were removed.
    fn escaped_bodies(&self) -> &[u32] {
        self.query_escapes.get_or_init(|| {
            let (poses, _) = self.current_bodies_or_host();
            (0..poses.len() as u32)
                .filter(|&index| {
                    let i = index as usize;
                    self.broadphase.fat_aabb(index).is_some_and(|fat| {
                        !fat.contains(&self.colliders[i].shape.aabb(&poses[i].transform()))
                    })
                })
                .collect()
        })
    }
}

#[cfg(test)]
mod tests;
