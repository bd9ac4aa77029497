//! Dynamic AABB tree (placeholder: being written).
