//! Sparse regression (work in progress).
