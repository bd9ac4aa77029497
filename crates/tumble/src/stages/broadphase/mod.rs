//! Two-tree DBVT broadphase (placeholder: being written).
