//! Record sets (work in progress).
