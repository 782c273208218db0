//! Self-tuning: the smoothing level is the scaled sampling step h = tau * omega, chosen by
//! maximising the profile likelihood of the innovations (noise and process intensities share
//! one scale that is profiled out in closed form). Several runs of one record set are tuned
//! jointly: they share the sensor, so one noise level and one smoothing level are estimated
//! from all their innovations. A coarse grid over log h finds the basin, golden-section search
//! refines it.

use super::kernel::Cov;
use super::statespace::discretise;

/// Profiled fit: noise variance and log-likelihood.
#[derive(Debug, Clone, Copy)]
pub struct Fit {
    pub sigma2: f64,
    pub loglik: f64,
}

/// Joint log-likelihood of centred runs at one (m, h, lambda).
pub fn evaluate(m: usize, h: f64, lambda: f64, runs: &[&[f64]]) -> Fit {
    let d = discretise(m, h, lambda);
    let mut cache: Vec<(usize, Cov)> = Vec::new();
    let (mut e2s, mut logs, mut count) = (0.0, 0.0, 0usize);
    for y in runs {
        let pos = match cache.iter().position(|(n, _)| *n == y.len()) {
            Some(p) => p,
            None => {
                cache.push((y.len(), Cov::new(&d, y.len(), false)));
                cache.len() - 1
            }
        };
        let (a, b, c) = cache[pos].1.loglik_terms(y);
        e2s += a;
        logs += b;
        count += c;
    }
    let count = count.max(1) as f64;
    let sigma2 = (e2s / count).max(1e-300);
    Fit {
        sigma2,
        loglik: -0.5 * count * sigma2.ln() - 0.5 * logs - 0.5 * count,
    }
}

/// Best h on [exp(lo), exp(hi)], by a coarse grid then golden section on log h.
pub fn best_h(m: usize, runs: &[&[f64]], lo: f64, hi: f64) -> (f64, Fit) {
    let grid = 11;
    let step = (hi - lo) / (grid - 1) as f64;
    let f = |lh: f64| evaluate(m, lh.exp(), 0.0, runs).loglik;
    let mut best = (lo, f64::NEG_INFINITY);
    for g in 0..grid {
        let lh = lo + step * g as f64;
        let v = f(lh);
        if v > best.1 {
            best = (lh, v);
        }
    }
    let (mut a, mut b) = (best.0 - step, best.0 + step);
    let gr = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - gr * (b - a);
    let mut d = a + gr * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    // 14 iterations shrink the bracket to 2 step * 0.618^14 ~ 0.003 step: far below what matters.
    for _ in 0..14 {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - gr * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + gr * (b - a);
            fd = f(d);
        }
    }
    let (lh, v) = if fc > fd { (c, fc) } else { (d, fd) };
    let lh = if v >= best.1 { lh } else { best.0 };
    (lh.exp(), evaluate(m, lh.exp(), 0.0, runs))
}
