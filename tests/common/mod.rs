//! Helpers shared by several test files.
#![allow(dead_code)]

pub mod cli;
pub mod lars_fixtures;
pub mod rng;

/// A file or folder under ../shared/data, or None with a printed notice when the shared benchmark
/// data is absent (a plain clone).
pub fn shared_data(rel: &str) -> Option<String> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if p.exists() {
        Some(p.to_string_lossy().into_owned())
    } else {
        eprintln!(
            "skipped: {} not found (the shared benchmark data is absent)",
            p.display()
        );
        None
    }
}
