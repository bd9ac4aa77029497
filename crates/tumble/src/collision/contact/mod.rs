//! Pair functions (placeholder: being written).
