//! Small checks shared by the modules that validate their input, and number formatting for
//! messages.

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

/// `x` with four decimals where that reads well (1e-3 <= |x| < 1e6, or 0), else in scientific
/// notation with four: a rate of 1e160 rad/s is not 161 digits.
pub fn num4(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        format!("{x:.4}")
    } else {
        format!("{x:.4e}")
    }
}

/// A number as the user typed it where that is short (0.02, 1.5, -9999), in scientific
/// notation from 1e7 and below 1e-4 in magnitude (1e300, not 301 digits).
pub fn short(x: f64) -> String {
    if x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}
