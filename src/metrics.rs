//! Scores of a simulated output against a measured one: RMS, NRMSE and fit %.
//!
//! One definition for every report: NRMSE is the RMS of `sim - meas` over the population
//! standard deviation of `meas`, and fit % is MATLAB's `100 (1 - NRMSE)`. A constant measurement
//! has no spread: its NRMSE is 0 when the error is 0 and infinite otherwise.

/// Population standard deviation (0 for an empty slice).
pub fn std_dev(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
}

/// Root mean square of `sim - meas` over their common length (0 when empty).
pub fn rms(sim: &[f64], meas: &[f64]) -> f64 {
    let n = sim.len().min(meas.len());
    if n == 0 {
        return 0.0;
    }
    (sim.iter()
        .zip(meas)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt()
}

/// RMS of `sim - meas` and NRMSE = RMS / standard deviation of `meas` (see the module docs). Slices
/// of different lengths are compared over the shorter one; empty slices give (0, 0).
pub fn rms_nrmse(sim: &[f64], meas: &[f64]) -> (f64, f64) {
    let n = sim.len().min(meas.len());
    let rms = rms(sim, meas);
    let sd = std_dev(&meas[..n]);
    let nrmse = if sd > 0.0 {
        rms / sd
    } else if rms == 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    (rms, nrmse)
}

/// NRMSE alone. Compared over the shorter slice; empty slices give 0.
pub fn nrmse(sim: &[f64], meas: &[f64]) -> f64 {
    rms_nrmse(sim, meas).1
}

/// Fit in percent, `100 (1 - NRMSE)` (negative for a model worse than the mean). Compared over the
/// shorter slice; empty slices give 100, and a constant `meas` that `sim` misses gives minus
/// infinity.
pub fn fit_percent(sim: &[f64], meas: &[f64]) -> f64 {
    100.0 * (1.0 - nrmse(sim, meas))
}

/// The `q`-th percentile (`q` in 0..=100) of `values`, with linear interpolation between order
/// statistics (numpy's default). NaN for an empty slice or a `q` outside 0..=100 (or NaN);
/// NaN values sort last.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() || !(0.0..=100.0).contains(&q) {
        return f64::NAN;
    }
    let mut v: Vec<f64> = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let pos = q / 100.0 * (v.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    v[lo] + (v[hi] - v[lo]) * (pos - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores() {
        let meas = [1.0, 2.0, 3.0, 4.0];
        let sim = [1.5, 2.5, 3.5, 4.5];
        let (r, n) = rms_nrmse(&sim, &meas);
        assert!((r - 0.5).abs() < 1e-15);
        assert!((n - 0.5 / 1.25f64.sqrt()).abs() < 1e-15);
        assert!((fit_percent(&sim, &meas) - 100.0 * (1.0 - n)).abs() < 1e-12);
        assert_eq!(nrmse(&[2.0, 2.0], &[2.0, 2.0]), 0.0);
        assert_eq!(nrmse(&[2.0, 3.0], &[2.0, 2.0]), f64::INFINITY);
        assert_eq!(rms(&[], &[]), 0.0);
    }
}
