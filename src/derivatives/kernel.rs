//! Run-time dispatch from the number of states m to the fixed-size smoother kernels.

use super::smoother::Covariances;
use super::statespace::Discrete;

/// Smallest and largest supported numbers of states.
pub const MIN_STATES: usize = 2;
pub const MAX_STATES: usize = 11;

macro_rules! cov_enum {
    ($($v:ident = $m:literal),*) => {
        /// [`Covariances`] for any supported m.
        pub enum Cov { $($v(Box<Covariances<$m>>)),* }

        impl Cov {
            /// Covariances for model `d` and run length n; the smoother part only when asked.
            pub fn new(d: &Discrete, n: usize, with_smoother: bool) -> Cov {
                match d.m {
                    $($m => Cov::$v(Box::new(Covariances::<$m>::new(d, n, with_smoother))),)*
                    m => panic!("unsupported number of states {m} (checked by the caller)"),
                }
            }

            pub fn loglik_terms(&self, y: &[f64]) -> (f64, f64, usize) {
                match self { $(Cov::$v(c) => c.loglik_terms(y)),* }
            }

            pub fn local_loglik(&self, y: &[f64], sigma2: f64, out: &mut [f64]) {
                match self { $(Cov::$v(c) => c.local_loglik(y, sigma2, out)),* }
            }

            /// Smoothed means, handed to `emit(sample, states)`.
            pub fn smooth(&self, y: &[f64], mut emit: impl FnMut(usize, &[f64])) {
                match self { $(Cov::$v(c) => c.smooth(y, |k, x| emit(k, &x[..]))),* }
            }

            /// State means at the last sample, by the forward pass alone.
            pub fn filter_last(&self, y: &[f64]) -> Vec<f64> {
                match self { $(Cov::$v(c) => c.filter_last(y).to_vec()),* }
            }

            /// Smoothed variances (diagonal) at sample k.
            pub fn var(&self, k: usize) -> &[f64] {
                match self { $(Cov::$v(c) => &c.var(k)[..]),* }
            }
        }
    };
}

cov_enum!(
    S2 = 2,
    S3 = 3,
    S4 = 4,
    S5 = 5,
    S6 = 6,
    S7 = 7,
    S8 = 8,
    S9 = 9,
    S10 = 10,
    S11 = 11
);
