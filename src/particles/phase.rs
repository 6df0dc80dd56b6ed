//! Phase functions (in progress).
