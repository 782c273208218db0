//! Residual analysis of a free-run simulation error, as MATLAB's `resid` and Ljung's *System
//! Identification* (section 16.6) give it: the error's autocorrelation and its cross-correlation
//! with each input, with confidence bounds.
//!
//! For a model simulated from the inputs alone (an output-error model), the test that matters
//! is the cross-correlation: a model that has captured how the inputs drive the output leaves an
//! error uncorrelated with past inputs. The error itself is rarely white (measurement noise
//! through a sensor, unmodelled slow drift), so the cross-correlation's bound accounts for the
//! error's own correlation: under independence, `sqrt(N) r_eu(k)` has variance
//! `P = sum_j r_e(j) r_u(j)` (j over all lags within the window), so the bound is
//! `z sqrt(P / N)`; for a white error P = 1 and the bound is the familiar `z / sqrt(N)`. The
//! autocorrelation's bound `z / sqrt(N)` is whiteness's. Means are removed first: a constant
//! offset would otherwise correlate with everything (the summary reports it separately).

/// Two-sided 99 % point of the normal distribution (MATLAB's default confidence).
pub const Z99: f64 = 2.575_829_3;

/// Lags shown on each side (MATLAB's `resid` uses 25).
pub const LAGS: usize = 25;

/// Spacing of the shown lags for a record of `n` samples: the lags cover 5 % of the record.
/// MATLAB's `resid` shows 25 lags one sample apart; on a record sampled fast against its
/// dynamics (EMPS at 1 kHz) that window is 25 ms, over which every correlation is 1 and the
/// plot says nothing, so the lags are spread (the bounds still use every lag in between).
pub fn lag_stride(n: usize) -> usize {
    (n / (20 * LAGS)).max(1)
}

/// A correlation function over lags with its confidence bound.
#[derive(Debug, Clone)]
pub struct Correlation {
    /// Lags in samples (positive: the second signal leads).
    pub lags: Vec<i64>,
    /// Normalised correlation at each lag, in [-1, 1].
    pub r: Vec<f64>,
    /// Half-width of the 99 % band around zero.
    pub bound: f64,
    /// An autocorrelation (r(0) = 1 by construction, not tested).
    pub auto: bool,
}

impl Correlation {
    /// Lags (zero excluded for an autocorrelation, where r = 1 by construction) at which the
    /// correlation leaves the band.
    pub fn outside(&self) -> usize {
        self.lags
            .iter()
            .zip(&self.r)
            .filter(|(&k, r)| !(self.auto && k == 0) && r.abs() > self.bound)
            .count()
    }

    /// Lags tested (zero excluded for an autocorrelation). An autocorrelation with no lags
    /// overflows: debug builds panic, release builds return `usize::MAX`.
    pub fn tested(&self) -> usize {
        self.lags.len() - usize::from(self.auto)
    }
}

/// The residual analysis of one error signal.
#[derive(Debug, Clone)]
pub struct Resid {
    /// Samples analysed.
    pub samples: usize,
    /// Mean of the error (removed before correlating).
    pub mean: f64,
    /// Autocorrelation at lags 0..=M.
    pub auto: Correlation,
    /// Per input (name, cross-correlation at lags -M..=M; positive lags: input leads error).
    pub cross: Vec<(String, Correlation)>,
}

fn centred(v: &[f64]) -> (Vec<f64>, f64) {
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (v.iter().map(|x| x - mean).collect(), mean)
}

/// `sum_t a(t) b(t - k)` over the samples where both exist.
fn lagged_sum(a: &[f64], b: &[f64], k: i64) -> f64 {
    let n = a.len().min(b.len());
    let s = k.unsigned_abs() as usize;
    if s >= n {
        return 0.0;
    }
    if k >= 0 {
        a[s..n].iter().zip(&b[..n - s]).map(|(x, y)| x * y).sum()
    } else {
        a[..n - s].iter().zip(&b[s..n]).map(|(x, y)| x * y).sum()
    }
}

/// Normalised correlation `sum_t a(t) b(t-k) / sqrt(sum a^2 sum b^2)` of centred signals at each
/// lag (0 where either signal is constant).
fn correlate(a: &[f64], b: &[f64], lags: &[i64]) -> Vec<f64> {
    let norm = (lagged_sum(a, a, 0) * lagged_sum(b, b, 0)).sqrt();
    lags.iter()
        .map(|&k| {
            if norm > 0.0 {
                lagged_sum(a, b, k) / norm
            } else {
                0.0
            }
        })
        .collect()
}

/// Residual analysis of `error` (simulated minus measured) against `inputs` (name, samples), at
/// `lags` lags each side spaced `stride` samples apart (the window at most a quarter of the
/// samples). Constant signals give correlations of 0 (not NaN), and an input of another length is
/// correlated over the samples both have.
pub fn analyse(error: &[f64], inputs: &[(&str, &[f64])], lags: usize, stride: usize) -> Resid {
    let n = error.len();
    let stride = stride.max(1);
    let m = lags.min(n / 4 / stride) as i64;
    let (e, mean) = centred(error);
    let shown: Vec<i64> = (0..=m).map(|k| k * stride as i64).collect();
    // Every lag of the window, for the cross-correlation's variance.
    let all: Vec<i64> = (0..=m * stride as i64).collect();
    let r_e_all = correlate(&e, &e, &all);
    let sqrt_n = (n.max(1) as f64).sqrt();
    let auto = Correlation {
        lags: shown.clone(),
        r: shown.iter().map(|&k| r_e_all[k as usize]).collect(),
        bound: Z99 / sqrt_n,
        auto: true,
    };
    let cross_lags: Vec<i64> = shown
        .iter()
        .rev()
        .map(|k| -k)
        .chain(shown[1..].iter().copied())
        .collect();
    let cross = inputs
        .iter()
        .map(|&(name, u)| {
            let (u, _) = centred(u);
            let r_u = correlate(&u, &u, &all);
            // The sum over j in -W..=W of r_e(j) r_u(j); both are even functions of j.
            let p = r_e_all[0] * r_u[0]
                + 2.0 * (1..all.len()).map(|j| r_e_all[j] * r_u[j]).sum::<f64>();
            let p = if p.is_finite() && p > 0.0 { p } else { 1.0 };
            let c = Correlation {
                lags: cross_lags.clone(),
                r: correlate(&e, &u, &cross_lags),
                bound: Z99 * (p / n.max(1) as f64).sqrt(),
                auto: false,
            };
            (name.to_string(), c)
        })
        .collect();
    Resid {
        samples: n,
        mean,
        auto,
        cross,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic white sequence (xorshift), uniform in [-1, 1].
    fn white(n: usize, mut s: u64) -> Vec<f64> {
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    #[test]
    fn white_error_independent_of_the_input_stays_inside_the_bands() {
        let e = white(20_000, 1);
        let u = white(20_000, 2);
        let r = analyse(&e, &[("u", &u)], LAGS, 1);
        assert!((r.auto.r[0] - 1.0).abs() < 1e-12);
        // At 99 % about one lag in a hundred may leave the band by chance.
        assert!(r.auto.outside() <= 2, "{:?}", r.auto.r);
        assert!(r.cross[0].1.outside() <= 2, "{:?}", r.cross[0].1.r);
        assert!((r.cross[0].1.bound - Z99 / (20_000f64).sqrt()).abs() < 0.2 * r.cross[0].1.bound);
    }

    #[test]
    fn an_error_that_follows_a_past_input_shows_at_that_lag() {
        // e(t) = 0.5 u(t - 3) + noise: the missed dynamics at lag 3.
        let u = white(20_000, 3);
        let w = white(20_000, 4);
        let e: Vec<f64> = (0..u.len())
            .map(|t| w[t] + if t >= 3 { 0.5 * u[t - 3] } else { 0.0 })
            .collect();
        let r = analyse(&e, &[("u", &u)], LAGS, 1);
        let c = &r.cross[0].1;
        let at = |k: i64| c.r[c.lags.iter().position(|&l| l == k).unwrap()];
        assert!(
            at(3) > 10.0 * c.bound,
            "r(3) = {}, bound {}",
            at(3),
            c.bound
        );
        assert!(at(-3).abs() < c.bound);
        // The error is still white: its autocorrelation stays in the band.
        assert!(r.auto.outside() <= 2);
    }

    #[test]
    fn a_coloured_error_widens_the_cross_band_and_fails_whiteness() {
        // A slow error (moving average of 20) against a slow input.
        let ma = |v: Vec<f64>| -> Vec<f64> {
            (0..v.len())
                .map(|t| v[t.saturating_sub(19)..=t].iter().sum::<f64>())
                .collect()
        };
        let e = ma(white(20_000, 5));
        let u = ma(white(20_000, 6));
        let r = analyse(&e, &[("u", &u)], LAGS, 1);
        assert!(r.auto.outside() > 10);
        assert!(r.cross[0].1.bound > 3.0 * r.auto.bound);
        assert!(r.cross[0].1.outside() <= 5, "{:?}", r.cross[0].1.r);
    }

    #[test]
    fn spread_lags_cover_the_window_and_keep_the_bound_of_every_lag() {
        let u = white(20_000, 7);
        let e: Vec<f64> = (0..u.len())
            .map(|t| if t >= 40 { u[t - 40] } else { 0.0 })
            .collect();
        assert_eq!(lag_stride(20_000), 40);
        let r = analyse(&e, &[("u", &u)], LAGS, 40);
        assert_eq!(r.auto.lags.len(), LAGS + 1);
        assert_eq!(*r.auto.lags.last().unwrap(), 1000);
        let c = &r.cross[0].1;
        assert_eq!((c.lags[0], c.lags.len()), (-1000, 2 * LAGS + 1));
        // The delay of 40 samples is a shown lag.
        assert!(c.r[c.lags.iter().position(|&k| k == 40).unwrap()] > 0.99);
    }

    #[test]
    fn short_and_constant_signals_give_zeros_not_nan() {
        let r = analyse(&[1.0; 8], &[("u", &[2.0; 8])], LAGS, 1);
        assert_eq!(r.auto.lags, vec![0, 1, 2]);
        assert!(r.auto.r.iter().chain(&r.cross[0].1.r).all(|v| *v == 0.0));
        assert!(r.cross[0].1.bound.is_finite());
    }
}
