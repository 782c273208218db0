//! Helpers shared by several test files.
#![allow(dead_code)]

pub mod cli;
pub mod lars_fixtures;
pub mod rng;
