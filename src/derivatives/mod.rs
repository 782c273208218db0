//! Derivative reconstruction (work in progress).
