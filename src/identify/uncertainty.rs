//! Standard errors of coefficients that come from the derivative fit: written into the model
//! file when the refinement on free-run error was refused or not run, so that every model
//! identify writes says how well each coefficient is known (`ctsid show` prints them).
//!
//! The coefficients are then a weighted least-squares fit of the derivative labels on the
//! selected terms, so their covariance is that fit's: `s^2 (X^T W X)^-1` with `s^2 = sum w r^2 /
//! (N - p)`, inflated by `(1 + rho) / (1 - rho)` for the lag-one autocorrelation `rho` of the
//! weighted residuals within runs (an AR(1) effective sample size), as the refinement's are
//! (`refine::set_std_errors`). Smoothed derivative labels are strongly correlated from sample to
//! sample; without the inflation the errors would claim a precision the data do not have.

use crate::engine::Features;
use crate::model::Model;
use nalgebra::DMatrix;

/// One output's derivative fit: the states and inputs at every sample (columns in the model's
/// state order, then inputs), the label and the sample weights.
pub struct Design<'a> {
    pub z: &'a Features,
    pub label: &'a [f64],
    pub weights: &'a [f64],
}

/// Writes the derivative fit's standard errors into the terms of output `i` of `model`; leaves
/// them unset where the fit has no residual degrees of freedom or a singular normal matrix.
/// `run_lengths`: the samples of each run, in order (the autocorrelation stays within runs).
pub fn set_derivative_std_errors(
    model: &mut Model,
    i: usize,
    d: &Design,
    run_lengths: &[usize],
) -> crate::error::Result<()> {
    let compiled = model.compile()?;
    let n = d.z.n_samples;
    let p = model.outputs[i].terms.len();
    let coef: Vec<f64> = model.outputs[i]
        .terms
        .iter()
        .map(|t| t.coefficient)
        .collect();
    let mut xtwx = DMatrix::<f64>::zeros(p, p);
    // sqrt(w) times the residual per sample, for the RSS and the autocorrelation.
    let mut wr = vec![0.0; n];
    let mut used = 0usize;
    let mut z = vec![0.0; d.z.n_vars()];
    for s in 0..n {
        let w = d.weights[s];
        if w.is_nan() || w <= 0.0 {
            continue;
        }
        for (k, v) in z.iter_mut().enumerate() {
            *v = d.z.column(k)[s];
        }
        let x = compiled.term_values_unchecked(i, &z);
        let fit: f64 = x.iter().zip(&coef).map(|(a, b)| a * b).sum();
        wr[s] = w.sqrt() * (d.label[s] - fit);
        for a in 0..p {
            for b in 0..=a {
                xtwx[(a, b)] += w * x[a] * x[b];
            }
        }
        used += 1;
    }
    if used <= p {
        return Ok(());
    }
    for a in 0..p {
        for b in 0..a {
            xtwx[(b, a)] = xtwx[(a, b)];
        }
    }
    let rss: f64 = wr.iter().map(|v| v * v).sum();
    let rho = lag_one(&wr, run_lengths, rss);
    let s2 = rss / (used - p) as f64 * (1.0 + rho) / (1.0 - rho);
    let Some(inv) = xtwx.try_inverse() else {
        return Ok(());
    };
    for (k, t) in model.outputs[i].terms.iter_mut().enumerate() {
        let v = s2 * inv[(k, k)];
        t.std_error = (v.is_finite() && v >= 0.0).then(|| v.sqrt());
    }
    Ok(())
}

/// Lag-one autocorrelation of `r` within runs, clamped to [0, 0.9999].
fn lag_one(r: &[f64], run_lengths: &[usize], rss: f64) -> f64 {
    if rss.is_nan() || rss <= 0.0 {
        return 0.0;
    }
    let mut start = 0;
    let mut lag1 = 0.0;
    for &len in run_lengths {
        let end = (start + len).min(r.len());
        lag1 += r[start..end].windows(2).map(|w| w[0] * w[1]).sum::<f64>();
        start = end;
    }
    (lag1 / rss).clamp(0.0, 0.9999)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y' = a y + b u with labels exact but for white noise of known sd: the standard errors
    /// match the textbook `sigma^2 (X^T X)^-1` of ordinary least squares.
    #[test]
    fn white_label_noise_gives_the_ols_standard_errors() {
        let n = 4000;
        let mut s = 12345u64;
        let mut noise = || {
            // Sum of 12 uniforms minus 6: sd 1.
            (0..12)
                .map(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    (s >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        let y: Vec<f64> = (0..n).map(|k| (k as f64 * 0.01).sin()).collect();
        let u: Vec<f64> = (0..n).map(|k| (k as f64 * 0.037).cos()).collect();
        let sd = 0.1;
        let label: Vec<f64> = (0..n)
            .map(|k| -2.0 * y[k] + 3.0 * u[k] + sd * noise())
            .collect();
        let text = r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[
            {"exponents":{"y":1},"coefficient":-2.0},{"exponents":{"u":1},"coefficient":3.0}]}]}"#;
        let mut m = Model::from_json_str(text, "test").unwrap();
        let z = Features::new(vec!["y".into(), "u".into()], vec![y.clone(), u.clone()]).unwrap();
        let w = vec![1.0; n];
        let d = Design {
            z: &z,
            label: &label,
            weights: &w,
        };
        set_derivative_std_errors(&mut m, 0, &d, &[n]).unwrap();
        let xtx = DMatrix::from_fn(2, 2, |a, b| {
            let c = [&y, &u];
            c[a].iter().zip(c[b]).map(|(p, q)| p * q).sum::<f64>()
        });
        let inv = xtx.try_inverse().unwrap();
        for (k, t) in m.outputs[0].terms.iter().enumerate() {
            let want = sd * inv[(k, k)].sqrt();
            let got = t.std_error.unwrap();
            assert!((got / want - 1.0).abs() < 0.1, "term {k}: {got} vs {want}");
        }
    }
}
