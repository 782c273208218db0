//! The paper's measurement noise `y_m = y + eta * percentile(|y|, 99) * nu`, `nu ~ N(0, 1)`.
//!
//! The percentile is taken over the samples of one run and one output channel, with linear
//! interpolation between order statistics (numpy's default), so the noise level scales with
//! each run's own amplitude.

use super::rng::Rng;

pub use crate::metrics::percentile;

/// `y + eta * percentile(|y|, 99) * nu`.
pub fn add_noise(y: &[f64], eta: f64, rng: &mut Rng) -> Vec<f64> {
    if eta == 0.0 {
        return y.to_vec();
    }
    let abs: Vec<f64> = y.iter().map(|v| v.abs()).collect();
    let level = eta * percentile(&abs, 99.0);
    y.iter().map(|v| v + level * rng.normal()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_matches_numpy_linear() {
        // numpy.percentile([1,2,3,4], 99) = 3.97
        assert!((percentile(&[4.0, 1.0, 3.0, 2.0], 99.0) - 3.97).abs() < 1e-12);
        assert_eq!(percentile(&[5.0], 99.0), 5.0);
        assert_eq!(percentile(&[1.0, 2.0, 3.0], 50.0), 2.0);
    }

    #[test]
    fn noise_level_follows_the_signal() {
        let y: Vec<f64> = (0..20000)
            .map(|k| 2.0 * ((k as f64) * 0.01).sin())
            .collect();
        let mut r = Rng::new(1);
        let m = add_noise(&y, 0.03, &mut r);
        let sd =
            (m.iter().zip(&y).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / y.len() as f64).sqrt();
        let expect = 0.03 * percentile(&y.iter().map(|v| v.abs()).collect::<Vec<_>>(), 99.0);
        assert!((sd / expect - 1.0).abs() < 0.03, "{sd} vs {expect}");
    }
}
