//! Helpers shared by several test files.
#![allow(dead_code)]

pub mod lars_fixtures;
pub mod rng;
