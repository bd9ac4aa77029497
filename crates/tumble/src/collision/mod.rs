//! Geometry shared by the stages: the dynamic AABB tree, contact manifolds and the pair
//! functions that make them, and ray casts against shapes.

pub mod contact;
pub mod dbvt;
pub mod manifold;
pub mod ray;
