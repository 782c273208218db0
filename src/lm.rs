//! Levenberg-Marquardt, written once for the two simulation-error fits of the crate: the
//! refinement of every model's coefficients and initial states ([`crate::identify::refine`],
//! which discover uses too) and the initial-state fit of a free run
//! ([`crate::simulate::fit_initial_state`]). Each supplies its residuals and its normal equations
//! (they know the Jacobian's structure: blocks per segment or per run, sensitivities from the
//! simulator) through [`LeastSquares`]; the damping logic lives here.
//!
//! # Method
//! The step solves `(J^T J + lambda D) d = -J^T r` with Marquardt's scaling `D = diag(J^T J)`,
//! each entry floored at `1e-12 (1 + max diag)` so that a parameter the data do not see stays
//! well-posed (its step is then zero). A trial that cannot be solved, cannot be evaluated (a
//! simulation that diverges) or does not lower the cost is rejected and lambda raised tenfold;
//! an accepted one lowers lambda by [`LmOptions::shrink`]. The fit stops after
//! [`LmOptions::max_iter`] Jacobians, when no trial is accepted, when an accepted step lowers
//! the cost by at most [`LmOptions::tol`] of it, or when the cost is at most
//! [`LmOptions::cost_floor`].

use nalgebra::{DMatrix, DVector};

/// A nonlinear least-squares problem `min_theta sum r(theta)^2`.
pub trait LeastSquares {
    /// The residuals at `theta`, or `None` where they cannot be evaluated.
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>>;
    /// `J^T J` and `J^T r` at `theta`, or `None` where they cannot be evaluated.
    fn normal_equations(&self, theta: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)>;
}

/// Damping and stopping settings (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct LmOptions {
    pub max_iter: usize,
    pub lambda0: f64,
    /// lambda is multiplied by this on an accepted step, and never goes below `lambda_min`.
    pub shrink: f64,
    pub lambda_min: f64,
    /// Trials per iteration, each with ten times the previous lambda, and the largest lambda.
    pub max_tries: usize,
    pub lambda_max: f64,
    pub tol: f64,
    /// The fit also stops once the cost is at most this (0: never): residuals already at the
    /// resolution the caller needs gain nothing from more simulations.
    pub cost_floor: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iter: 25,
            lambda0: 1e-3,
            shrink: 1.0 / 3.0,
            lambda_min: 1e-9,
            max_tries: usize::MAX,
            lambda_max: 1e10,
            tol: 1e-4,
            cost_floor: 0.0,
        }
    }
}

/// What a fit did.
#[derive(Debug, Clone, Copy, Default)]
pub struct LmStats {
    /// Jacobian evaluations.
    pub iterations: usize,
    pub accepted: usize,
    pub rejected: usize,
    /// Rejected trials whose residuals could not be evaluated.
    pub diverged: usize,
}

/// The sum of squared residuals, the cost [`minimize`] lowers.
pub fn cost(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Minimises the problem from `theta`: the final parameters and cost, or `None` when the
/// residuals cannot be evaluated at the start or the damping settings are degenerate (a
/// non-positive `lambda0` or `lambda_min`, `shrink` outside (0, 1), an infinite `lambda_max` or
/// one below `lambda0`).
pub fn minimize(
    p: &dyn LeastSquares,
    mut theta: Vec<f64>,
    o: &LmOptions,
    stats: &mut LmStats,
) -> Option<(Vec<f64>, f64)> {
    // Degenerate damping settings would retry one rejected step forever.
    let damping_ok = o.lambda0 > 0.0
        && o.lambda_min > 0.0
        && o.shrink > 0.0
        && o.shrink < 1.0
        && o.lambda_max.is_finite()
        && o.lambda_max >= o.lambda0;
    if !damping_ok {
        return None;
    }
    let mut c = cost(&p.residuals(&theta)?);
    let mut lambda = o.lambda0;
    for _ in 0..o.max_iter {
        if c <= o.cost_floor {
            break;
        }
        stats.iterations += 1;
        let Some((jtj, jtr)) = p.normal_equations(&theta) else {
            break;
        };
        let np = theta.len();
        let floor = 1e-12 * (1.0 + jtj.diagonal().max());
        let mut improved = None;
        let mut tries = 0;
        while lambda <= o.lambda_max && tries < o.max_tries {
            tries += 1;
            let mut a = jtj.clone();
            for j in 0..np {
                a[(j, j)] += lambda * jtj[(j, j)].max(floor);
            }
            let step = a.lu().solve(&(-&jtr));
            let Some(step) = step.filter(|s| s.iter().all(|v| v.is_finite())) else {
                stats.rejected += 1;
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = theta.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let trial_cost = p.residuals(&trial).map(|r| cost(&r));
            match trial_cost {
                Some(cn) if cn < c => {
                    stats.accepted += 1;
                    improved = Some((trial, cn));
                    lambda = (lambda * o.shrink).max(o.lambda_min);
                    break;
                }
                _ => {
                    stats.rejected += 1;
                    if trial_cost.is_none() {
                        stats.diverged += 1;
                    }
                    lambda *= 10.0;
                }
            }
        }
        match improved {
            Some((th, cn)) => {
                let gain = (c - cn) / c.max(f64::MIN_POSITIVE);
                theta = th;
                c = cn;
                if gain <= o.tol {
                    break;
                }
            }
            None => break,
        }
    }
    Some((theta, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as residuals (10 (y - x^2), 1 - x): the minimum (1, 1) from (-1.2, 1).
    struct Rosenbrock;
    impl LeastSquares for Rosenbrock {
        fn residuals(&self, t: &[f64]) -> Option<Vec<f64>> {
            Some(vec![10.0 * (t[1] - t[0] * t[0]), 1.0 - t[0]])
        }
        fn normal_equations(&self, t: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)> {
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * t[0], 10.0, -1.0, 0.0]);
            let r = DVector::from_vec(self.residuals(t)?);
            Some((j.transpose() * &j, j.transpose() * r))
        }
    }

    #[test]
    fn finds_the_rosenbrock_minimum() {
        let mut stats = LmStats::default();
        let o = LmOptions {
            max_iter: 200,
            tol: 0.0,
            ..Default::default()
        };
        let (t, c) = minimize(&Rosenbrock, vec![-1.2, 1.0], &o, &mut stats).unwrap();
        assert!(
            (t[0] - 1.0).abs() < 1e-6 && (t[1] - 1.0).abs() < 1e-6,
            "{t:?}"
        );
        assert!(c < 1e-12);
        // Stopped by itself (no trial lowers the cost any more), not by the iteration cap.
        assert!(stats.accepted > 5 && stats.iterations < 200, "{stats:?}");
    }
}
