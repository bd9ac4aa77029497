//! Pair cache (placeholder: being written).
