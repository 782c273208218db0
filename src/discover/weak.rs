//! The weak (test-function) form: label and regressors see the same filter.
//!
//! For an output of order `n`, `y^(n) = f(z)` is multiplied by a compactly supported test
//! function `psi_j(t) = (1 - s^2)^p`, `s = (t - c_j) / (m tau)`, `p = n + 2`, and integrated over
//! its support. Integration by parts moves every derivative of the measured output onto `psi`:
//! the label is `(-1)^n int psi^(n) y dt` (no derivative estimate at all), a linear regressor
//! `y_dk` is `(-1)^k int psi^(k) y dt`, an input `u` is `int psi u dt`; any other regressor is
//! `int psi phi(z_hat) dt` with `z_hat` the smoother's derivative estimates. So the label is not
//! "differentiated but unfiltered" while the regressors are filtered (the prototype's 26 % bias):
//! both are the same linear functional of the signals.
//!
//! Windows overlap by 3/4 (centres every `m/2` samples, support `2m`), so rows are correlated;
//! [`OVERLAP`] is the factor by which raw row counts overstate the information, used when the
//! data are weighed against a prior and in information criteria.

/// Rows per independent window (support `2m` over stride `m/2`).
pub const OVERLAP: f64 = 4.0;

/// `d^k/ds^k (1 - s^2)^p` at `s` for `k = 0..=kmax`.
fn psi_derivs(s: f64, p: usize, kmax: usize) -> Vec<f64> {
    // (1 - s^2)^p = sum_j C(p, j) (-1)^j s^(2j): differentiate the polynomial term by term.
    let mut coef = vec![0.0; 2 * p + 1];
    let mut c = 1.0;
    for j in 0..=p {
        coef[2 * j] = if j % 2 == 0 { c } else { -c };
        c = c * (p - j) as f64 / (j + 1) as f64;
    }
    let mut out = Vec::with_capacity(kmax + 1);
    for _ in 0..=kmax {
        let mut v = 0.0;
        for (e, a) in coef.iter().enumerate().rev() {
            v = v * s + a;
            let _ = e;
        }
        out.push(v);
        let d: Vec<f64> = (1..coef.len()).map(|e| coef[e] * e as f64).collect();
        coef = if d.is_empty() { vec![0.0] } else { d };
    }
    out
}

/// Test functions of one run: for each window, its first sample and `psi^(k)` (in time units)
/// at each sample of its support, `k = 0..=order`.
#[derive(Debug, Clone)]
pub struct Windows {
    pub starts: Vec<usize>,
    pub len: usize,
    /// `w[k][i]`: `psi^(k)` at sample `i` of the support times `tau` (the quadrature weight).
    pub w: Vec<Vec<f64>>,
}

impl Windows {
    /// Windows of half-width `m` samples over a run of `n_samples`, for an equation of `order`. A
    /// run shorter than one window (`2 m + 1` samples) gets no windows; `m = 0` gives weights that
    /// are not finite.
    pub fn new(n_samples: usize, m: usize, order: usize, tau: f64) -> Windows {
        let len = 2 * m + 1;
        let stride = (m / 2).max(1);
        let mut starts = Vec::new();
        let mut a = 0;
        while a + len <= n_samples {
            starts.push(a);
            a += stride;
        }
        let p = order + 2;
        let ht = m as f64 * tau;
        let mut w = vec![vec![0.0; len]; order + 1];
        for i in 0..len {
            let s = (i as f64 - m as f64) / m as f64;
            let d = psi_derivs(s, p, order);
            for k in 0..=order {
                w[k][i] = d[k] / ht.powi(k as i32) * tau;
            }
        }
        Windows { starts, len, w }
    }

    /// `int psi^(k) x dt` over every window. Panics (unless there are no windows) when `k` is
    /// above the `order` they were built for, or `x` ends before the last window does.
    pub fn integrate(&self, k: usize, x: &[f64]) -> Vec<f64> {
        self.starts
            .iter()
            .map(|&a| {
                self.w[k]
                    .iter()
                    .zip(&x[a..a + self.len])
                    .map(|(w, v)| w * v)
                    .sum()
            })
            .collect()
    }
}

/// The window half-width for a run set: about a third of the mean interval between zero
/// crossings of the detrended output (so a window sees less than a half-period of the dominant
/// motion), clamped to 6..=60 samples. Runs shorter than 3 samples are skipped; without any run
/// left the width is 6.
pub fn choose_half_width(ys: &[&[f64]]) -> usize {
    let mut crossings = 0usize;
    let mut samples = 0usize;
    for y in ys {
        if y.len() < 3 {
            continue;
        }
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        crossings += y
            .windows(2)
            .filter(|w| (w[0] - mean) * (w[1] - mean) < 0.0)
            .count();
        samples += y.len();
    }
    let interval = samples as f64 / crossings.max(1) as f64;
    ((interval / 3.0).round() as usize).clamp(6, 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integration_by_parts_is_exact_for_smooth_signals() {
        // y = sin(2t): int psi'' y = int psi y'' = -4 int psi y.
        let tau = 0.01;
        let n = 400;
        let y: Vec<f64> = (0..n).map(|i| (2.0 * i as f64 * tau).sin()).collect();
        let w = Windows::new(n, 20, 2, tau);
        let a = w.integrate(2, &y);
        let b = w.integrate(0, &y);
        for (a, b) in a.iter().zip(&b) {
            assert!((a + 4.0 * b).abs() < 3e-3 * a.abs().max(1e-3), "{a} {b}");
        }
        // Odd order: int psi' y = -int psi y' with y' = 2 cos(2t).
        let yd: Vec<f64> = (0..n).map(|i| 2.0 * (2.0 * i as f64 * tau).cos()).collect();
        let a = w.integrate(1, &y);
        let b = w.integrate(0, &yd);
        for (a, b) in a.iter().zip(&b) {
            assert!((a + b).abs() < 3e-3 * a.abs().max(1e-3), "{a} {b}");
        }
    }
}
