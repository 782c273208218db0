//! Sampled inputs read between their samples: straight lines, a natural cubic spline, or a
//! zero-order hold ([`Interpolation`]), constant beyond the ends.
//!
//! The integrator evaluates the input several times per step, so the spline's second
//! derivatives are solved once (one tridiagonal system per channel, O(N)) and the interval of a
//! time is computed rather than searched when the samples are uniform.

use super::Input;
use crate::error::{Error, Result};
use crate::model::Interpolation;

/// Samples read between their sample times by an [`Interpolation`] (constant beyond the ends).
#[derive(Debug, Clone)]
pub struct SampledInput {
    t: Vec<f64>,
    /// `values[channel][sample]`
    values: Vec<Vec<f64>>,
    /// The spline's second derivatives at the samples, per channel (empty unless cubic).
    curvature: Vec<Vec<f64>>,
    interpolation: Interpolation,
    /// `(t0, dt)` when the times are uniform to 1e-9 relative: the interval of `t` is then
    /// computed instead of searched (the solver evaluates the input several times per step).
    uniform: Option<(f64, f64)>,
}

impl SampledInput {
    /// Linear interpolation; `t` strictly increasing; one vector of samples per channel, each as
    /// long as `t`.
    pub fn new(t: Vec<f64>, values: Vec<Vec<f64>>) -> Result<SampledInput> {
        SampledInput::with_interpolation(t, values, Interpolation::Linear)
    }

    /// [`SampledInput::new`] read between the samples by `interpolation`.
    ///
    /// ```
    /// use ctsid::model::Interpolation;
    /// use ctsid::simulate::{Input, SampledInput};
    /// let t = vec![0.0, 1.0, 2.0, 3.0];
    /// let u = vec![vec![0.0, 1.0, 0.0, -1.0]];
    /// let mut v = [0.0];
    /// SampledInput::with_interpolation(t.clone(), u.clone(), Interpolation::Hold)?.eval(1.5, &mut v);
    /// assert_eq!(v[0], 1.0);
    /// SampledInput::with_interpolation(t, u, Interpolation::Cubic)?.eval(1.0, &mut v);
    /// assert!((v[0] - 1.0).abs() < 1e-12); // through every sample
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn with_interpolation(
        t: Vec<f64>,
        values: Vec<Vec<f64>>,
        interpolation: Interpolation,
    ) -> Result<SampledInput> {
        if !t.windows(2).all(|w| w[1] > w[0]) {
            return Err(Error::InvalidData(
                "input sample times must increase strictly".into(),
            ));
        }
        if values.iter().any(|v| v.len() != t.len()) {
            return Err(Error::InvalidData(
                "every input channel needs one value per sample time".into(),
            ));
        }
        let uniform = (t.len() >= 2)
            .then(|| {
                let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
                let tol = 1e-9 * dt.abs().max(t[t.len() - 1].abs());
                t.iter()
                    .enumerate()
                    .all(|(k, &s)| (s - (t[0] + k as f64 * dt)).abs() <= tol)
                    .then_some((t[0], dt))
            })
            .flatten();
        let curvature = match interpolation {
            Interpolation::Cubic => values.iter().map(|v| natural_spline(&t, v)).collect(),
            _ => Vec::new(),
        };
        Ok(SampledInput {
            t,
            values,
            curvature,
            interpolation,
            uniform,
        })
    }

    /// The first sample index `k >= 1` with `t[k] > t` (`t` strictly inside the samples' span).
    fn interval(&self, t: f64) -> usize {
        let n = self.t.len();
        match self.uniform {
            Some((t0, dt)) => {
                // The computed guess, corrected by a step either way for rounding.
                let mut k = (((t - t0) / dt).floor() as usize + 1).clamp(1, n - 1);
                while k > 1 && self.t[k - 1] > t {
                    k -= 1;
                }
                while k < n - 1 && self.t[k] <= t {
                    k += 1;
                }
                k
            }
            None => self.t.partition_point(|&s| s <= t),
        }
    }

    fn constant(&self, k: usize, u: &mut [f64]) {
        for (c, v) in self.values.iter().enumerate() {
            u[c] = v[k];
        }
    }
}

/// Second derivatives of the natural cubic spline through `(t, y)` at the samples (zero at
/// both ends), by the Thomas algorithm on the tridiagonal continuity equations.
fn natural_spline(t: &[f64], y: &[f64]) -> Vec<f64> {
    let n = t.len();
    let mut m = vec![0.0; n];
    if n < 3 {
        return m;
    }
    // Forward elimination: diag[i] and rhs[i] after eliminating the sub-diagonal.
    let mut diag = vec![0.0; n];
    let mut rhs = vec![0.0; n];
    for i in 1..n - 1 {
        let (h0, h1) = (t[i] - t[i - 1], t[i + 1] - t[i]);
        let r = 6.0 * ((y[i + 1] - y[i]) / h1 - (y[i] - y[i - 1]) / h0);
        let d = 2.0 * (h0 + h1);
        if i == 1 {
            diag[i] = d;
            rhs[i] = r;
        } else {
            let w = h0 / diag[i - 1];
            diag[i] = d - w * h0;
            rhs[i] = r - w * rhs[i - 1];
        }
    }
    for i in (1..n - 1).rev() {
        let upper = if i + 1 < n - 1 {
            (t[i + 1] - t[i]) * m[i + 1]
        } else {
            0.0
        };
        m[i] = (rhs[i] - upper) / diag[i];
    }
    m
}

impl Input for SampledInput {
    fn n_inputs(&self) -> usize {
        self.values.len()
    }
    fn eval(&self, t: f64, u: &mut [f64]) {
        let n = self.t.len();
        if n == 0 {
            u.iter_mut().for_each(|v| *v = 0.0);
            return;
        }
        // A NaN time passes both end tests below; the interval search then indexed t[-1].
        if t.is_nan() {
            u.iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        if t <= self.t[0] || n == 1 {
            return self.constant(0, u);
        }
        if t >= self.t[n - 1] {
            // A hold keeps the previous sample up to and including the last sample time.
            let last = match self.interpolation {
                Interpolation::Hold
                    if t - self.t[n - 1] <= 1e-9 * (self.t[n - 1] - self.t[n - 2]) =>
                {
                    n - 2
                }
                _ => n - 1,
            };
            return self.constant(last, u);
        }
        let k = self.interval(t);
        let (t0, t1) = (self.t[k - 1], self.t[k]);
        let h = t1 - t0;
        let w = (t - t0) / h;
        match self.interpolation {
            Interpolation::Linear => {
                for (c, v) in self.values.iter().enumerate() {
                    u[c] = v[k - 1] + w * (v[k] - v[k - 1]);
                }
            }
            Interpolation::Cubic => {
                let a = 1.0 - w;
                let (ca, cb) = ((a * a * a - a) * h * h / 6.0, (w * w * w - w) * h * h / 6.0);
                for (c, v) in self.values.iter().enumerate() {
                    let m = &self.curvature[c];
                    u[c] = a * v[k - 1] + w * v[k] + ca * m[k - 1] + cb * m[k];
                }
            }
            Interpolation::Hold => {
                // A step that ends on a sample time evaluates its last stage there (up to
                // rounding): the value held over the step is the previous sample's.
                let j = if w <= 1e-9 && k >= 2 { k - 2 } else { k - 1 };
                self.constant(j, u);
            }
        }
    }
    fn breakpoints(&self, t0: f64, t1: f64, out: &mut Vec<f64>) {
        // The spline is twice continuously differentiable: no kink to land on.
        if self.interpolation == Interpolation::Cubic {
            return;
        }
        let a = self.t.partition_point(|&s| s <= t0);
        for &s in &self.t[a..] {
            if s >= t1 {
                break;
            }
            out.push(s);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_spline_reconstructs_a_band_limited_signal_better_than_lines() {
        // A 60 Hz sine sampled at 610 Hz, as the Silverbox's input is near its resonance.
        let fs = 610.0;
        let f = 60.0;
        let t: Vec<f64> = (0..400).map(|k| k as f64 / fs).collect();
        let u = vec![t
            .iter()
            .map(|&s| (2.0 * std::f64::consts::PI * f * s).sin())
            .collect::<Vec<_>>()];
        let err = |interp| {
            let input = SampledInput::with_interpolation(t.clone(), u.clone(), interp).unwrap();
            let mut v = [0.0];
            (100..300)
                .map(|k| {
                    let s = (k as f64 + 0.5) / fs;
                    input.eval(s, &mut v);
                    (v[0] - (2.0 * std::f64::consts::PI * f * s).sin()).abs()
                })
                .fold(0.0f64, f64::max)
        };
        let (lin, cub) = (err(Interpolation::Linear), err(Interpolation::Cubic));
        assert!(lin > 0.04, "linear {lin}");
        assert!(cub < lin / 20.0, "cubic {cub} against linear {lin}");
    }

    #[test]
    fn spline_passes_through_samples_on_uneven_times() {
        let t = vec![0.0, 0.3, 1.0, 1.2, 2.5, 3.0];
        let y: Vec<f64> = t.iter().map(|&s: &f64| s.powi(3) - 2.0 * s).collect();
        let input =
            SampledInput::with_interpolation(t.clone(), vec![y.clone()], Interpolation::Cubic)
                .unwrap();
        let mut v = [0.0];
        for (s, want) in t.iter().zip(&y) {
            input.eval(*s, &mut v);
            assert!((v[0] - want).abs() < 1e-12, "at {s}: {} for {want}", v[0]);
        }
        // Between samples it is smooth: close to the cubic it samples, away from the ends
        // where the natural spline's zero curvature differs from the cubic's.
        input.eval(1.1, &mut v);
        assert!((v[0] - (1.1f64.powi(3) - 2.2)).abs() < 0.05, "{}", v[0]);
    }

    #[test]
    fn hold_keeps_each_sample_over_the_step_that_ends_on_the_next() {
        let t = vec![0.0, 0.1, 0.2, 0.3];
        let input = SampledInput::with_interpolation(
            t,
            vec![vec![1.0, 2.0, 3.0, 4.0]],
            Interpolation::Hold,
        )
        .unwrap();
        let mut v = [0.0];
        for (s, want) in [
            (0.0, 1.0),
            (0.05, 1.0),
            (0.1, 1.0),
            (0.1 + 1e-12, 1.0),
            (0.15, 2.0),
            (0.3, 3.0),
            (0.31, 4.0),
        ] {
            input.eval(s, &mut v);
            assert_eq!(v[0], want, "at {s}");
        }
    }

    #[test]
    fn a_nan_time_gives_nan_inputs_on_any_grid() {
        let mut v = [0.0];
        for t in [vec![0.0, 1.0, 3.0], vec![0.0, 1.0, 2.0]] {
            let input = SampledInput::new(t, vec![vec![0.0, 1.0, 2.0]]).unwrap();
            input.eval(f64::NAN, &mut v);
            assert!(v[0].is_nan());
        }
    }
}
