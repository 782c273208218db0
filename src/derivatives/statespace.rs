//! The prior: a chain of m integrators in *scaled* time s = t * omega, driven by white noise on
//! the top state, optionally damped so that it becomes a stationary Matern-type process whose
//! characteristic polynomial is (p + lambda)^m.
//!
//! Working in scaled time is what keeps the filter well conditioned: omega is chosen so that
//! process and measurement noise have the same intensity, which makes every state O(1) at the
//! signal's own bandwidth, whatever tau and whatever the derivative order. With lambda = 0 the
//! prior is the integrated Wiener process (polynomial spline smoothing); lambda > 0 gives a
//! proper stationary prior, which matters at the ends of a run, where the integrator chain would
//! otherwise extrapolate high derivatives with huge variance.

use nalgebra::DMatrix;

/// Discretised model for one sampling step h (in scaled time).
#[derive(Debug, Clone)]
pub struct Discrete {
    pub m: usize,
    /// Transition matrix, row-major m x m.
    pub a: Vec<f64>,
    /// Process noise covariance per step (unit intensity), row-major.
    pub q: Vec<f64>,
    /// Initial (prior) covariance: stationary for lambda > 0, large and diffuse otherwise.
    pub p0: Vec<f64>,
    /// Whether p0 is diffuse (the first m innovations are then left out of the likelihood).
    pub diffuse: bool,
}

fn factorial(n: usize) -> f64 {
    (1..=n).map(|k| k as f64).product()
}

fn binom(n: usize, k: usize) -> f64 {
    factorial(n) / (factorial(k) * factorial(n - k))
}

/// Continuous-time drift matrix F of the damped chain.
pub fn drift(m: usize, lambda: f64) -> DMatrix<f64> {
    let mut f = DMatrix::zeros(m, m);
    for i in 0..m - 1 {
        f[(i, i + 1)] = 1.0;
    }
    if lambda > 0.0 {
        for j in 0..m {
            f[(m - 1, j)] = -binom(m, j) * lambda.powi((m - j) as i32);
        }
    }
    f
}

/// Discretises the prior for step `h`; `lambda` is in the same scaled time units.
pub fn discretise(m: usize, h: f64, lambda: f64) -> Discrete {
    let (a, q) = if lambda == 0.0 {
        // Closed forms for the integrated Wiener process: exact and cheap at any h.
        let mut a = vec![0.0; m * m];
        let mut q = vec![0.0; m * m];
        for i in 0..m {
            for j in i..m {
                a[i * m + j] = h.powi((j - i) as i32) / factorial(j - i);
            }
            for j in 0..m {
                let p = 2 * m - 1 - i - j;
                q[i * m + j] =
                    h.powi(p as i32) / (p as f64 * factorial(m - 1 - i) * factorial(m - 1 - j));
            }
        }
        (a, q)
    } else {
        // Van Loan: expm([[-F, L L^T], [0, F^T]] h) = [[., E12], [0, E22]], A = E22^T, Q = A E12.
        let f = drift(m, lambda);
        let mut big = DMatrix::zeros(2 * m, 2 * m);
        for i in 0..m {
            for j in 0..m {
                big[(i, j)] = -f[(i, j)] * h;
                big[(m + i, m + j)] = f[(j, i)] * h;
            }
        }
        big[(m - 1, 2 * m - 1)] = h;
        let e = big.exp();
        let e22t = e.view((m, m), (m, m)).transpose();
        let e12 = e.view((0, m), (m, m)).into_owned();
        let qm = &e22t * e12;
        let mut a = vec![0.0; m * m];
        let mut q = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                a[i * m + j] = e22t[(i, j)];
                // Symmetrise: the product is symmetric only up to rounding.
                q[i * m + j] = 0.5 * (qm[(i, j)] + qm[(j, i)]);
            }
        }
        (a, q)
    };
    let (p0, diffuse) = if lambda == 0.0 {
        (diffuse_prior(m), true)
    } else {
        (stationary_cov(m, lambda), false)
    };
    Discrete {
        m,
        a,
        q,
        p0,
        diffuse,
    }
}

fn diffuse_prior(m: usize) -> Vec<f64> {
    let mut p = vec![0.0; m * m];
    for i in 0..m {
        p[i * m + i] = 1e8;
    }
    p
}

/// Stationary covariance: solves F P + P F^T + L L^T = 0 (Kronecker form, m^2 unknowns).
pub fn stationary_cov(m: usize, lambda: f64) -> Vec<f64> {
    let f = drift(m, lambda);
    let n = m * m;
    let mut k = DMatrix::zeros(n, n);
    // vec(F P + P F^T) = (I kron F + F kron I) vec(P), column-major vec.
    for i in 0..m {
        for j in 0..m {
            for l in 0..m {
                // (I kron F): block (j, j) = F  -> row i + j m, col l + j m
                k[(i + j * m, l + j * m)] += f[(i, l)];
                // (F kron I): block (j, l) = F[j, l] I -> row i + j m, col i + l m
                k[(i + j * m, i + l * m)] += f[(j, l)];
            }
        }
    }
    let mut rhs = nalgebra::DVector::zeros(n);
    rhs[(m - 1) + (m - 1) * m] = -1.0;
    let sol = k
        .lu()
        .solve(&rhs)
        .expect("stationary covariance of a stable damped chain exists");
    let mut p = vec![0.0; n];
    for i in 0..m {
        for j in 0..m {
            p[i * m + j] = 0.5 * (sol[i + j * m] + sol[j + i * m]);
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn van_loan_matches_closed_form_as_lambda_vanishes() {
        let m = 5;
        let h = 0.3;
        let exact = discretise(m, h, 0.0);
        let damped = discretise(m, h, 1e-7);
        for i in 0..m * m {
            assert!(
                (exact.a[i] - damped.a[i]).abs() < 1e-5 * (1.0 + exact.a[i].abs()),
                "A[{i}]"
            );
            assert!(
                (exact.q[i] - damped.q[i]).abs() < 1e-5 * (1e-3 + exact.q[i].abs()),
                "Q[{i}]: {} {}",
                exact.q[i],
                damped.q[i]
            );
        }
    }

    #[test]
    fn stationary_covariance_is_invariant_under_one_step() {
        let m = 4;
        let d = discretise(m, 0.5, 0.8);
        let a = DMatrix::from_row_slice(m, m, &d.a);
        let q = DMatrix::from_row_slice(m, m, &d.q);
        let p = DMatrix::from_row_slice(m, m, &d.p0);
        let next = &a * &p * a.transpose() + q;
        assert!((next - &p).abs().max() < 1e-10 * p.abs().max());
    }
}
