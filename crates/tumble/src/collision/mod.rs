//! Geometry shared by the stages: the dynamic AABB tree, contact manifolds and the pair
//! functions that make them, and ray casts against shapes.

pub mod bvh;
pub mod contact;
pub mod dbvt;
pub mod epa;
pub mod gjk;
pub mod manifold;
pub mod penetration;
pub mod ray;
