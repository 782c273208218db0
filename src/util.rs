//! Small checks shared by the modules that validate their input.

use crate::error::{Error, Result};

/// The first element equal to an earlier one: (index of the earlier, index of the repeat).
pub(crate) fn first_repeat<T: PartialEq>(v: &[T]) -> Option<(usize, usize)> {
    v.iter()
        .enumerate()
        .find_map(|(j, x)| v[..j].iter().position(|y| y == x).map(|i| (i, j)))
}

/// A setting that must be a finite number >= 0.
pub(crate) fn finite_nonneg(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            name,
            format!("{v:?}; give a finite number >= 0"),
        ))
    }
}
