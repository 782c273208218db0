//! Free-run simulation of a nominal-plus-effects model and a small Levenberg-Marquardt refit of
//! its coefficients on simulation error (self-contained; the identify module has its own).
//!
//! The model is one output of order `n`: states `y, y_d1, ..., y_d(n-1)`, `y^(n) = sum_j c_j
//! phi_j(z)` with `z` the states then the inputs. `sign` is smoothed for the integrator over a
//! width of 1e-3 of each variable's spread (see [`super::expr`]).

use rayon::prelude::*;

use super::expr::Expr;
use crate::simulate::{rms_nrmse, simulate, SampledInput, SimOptions, System};

/// A single-output model: terms `c_j * phi_j(z)`.
#[derive(Debug, Clone)]
pub struct AugModel {
    pub order: usize,
    pub n_inputs: usize,
    pub names: Vec<String>,
    pub terms: Vec<(Expr, f64)>,
    /// Smoothing width of `sign` per variable.
    pub eps: Vec<f64>,
}

impl System for AugModel {
    fn dim(&self) -> usize {
        self.order
    }
    fn n_inputs(&self) -> usize {
        self.n_inputs
    }
    fn state_name(&self, k: usize) -> String {
        self.names[k].clone()
    }
    fn rhs(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let n = self.order;
        let mut z = Vec::with_capacity(n + u.len());
        z.extend_from_slice(x);
        z.extend_from_slice(u);
        dx[..(n - 1)].copy_from_slice(&x[1..n]);
        dx[n - 1] = self
            .terms
            .iter()
            .map(|(e, c)| c * e.eval_smooth(&z, &self.eps))
            .sum();
    }
}

impl AugModel {
    pub fn coefficients(&self) -> Vec<f64> {
        self.terms.iter().map(|t| t.1).collect()
    }
    pub fn with_coefficients(&self, c: &[f64]) -> AugModel {
        let mut m = self.clone();
        for (t, &v) in m.terms.iter_mut().zip(c) {
            t.1 = v;
        }
        m
    }
}

/// One run prepared for simulation.
#[derive(Debug, Clone)]
pub struct SimRun {
    pub id: String,
    pub t: Vec<f64>,
    pub y: Vec<f64>,
    pub u: Vec<Vec<f64>>,
    pub x0: Vec<f64>,
}

fn options(run: &str, y: &[f64]) -> SimOptions {
    let scale = y.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(1e-12);
    SimOptions {
        rtol: 1e-6,
        atol: 1e-8 * scale,
        bound: 1e6 * scale,
        max_steps_per_interval: 2000,
        run: run.into(),
        ..SimOptions::default()
    }
}

/// The simulated output of `m` on `run`; `None` when it diverges.
pub fn free_run(m: &AugModel, run: &SimRun) -> Option<Vec<f64>> {
    let input = SampledInput::new(run.t.clone(), run.u.clone()).ok()?;
    let tr = simulate(m, &input, &run.x0, &run.t, &options(&run.id, &run.y)).ok()?;
    Some(tr.series(0))
}

/// NRMSE of the free run (infinite when it diverges).
pub fn nrmse(m: &AugModel, run: &SimRun) -> f64 {
    match free_run(m, run) {
        Some(s) => rms_nrmse(&s, &run.y).1,
        None => f64::INFINITY,
    }
}

/// Mean NRMSE over runs (in parallel).
pub fn mean_nrmse(m: &AugModel, runs: &[SimRun]) -> f64 {
    let v: Vec<f64> = runs.par_iter().map(|r| nrmse(m, r)).collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn residuals(m: &AugModel, runs: &[SimRun]) -> Option<Vec<f64>> {
    let parts: Vec<Option<Vec<f64>>> = runs
        .par_iter()
        .map(|r| {
            let s = free_run(m, r)?;
            let mean = r.y.iter().sum::<f64>() / r.y.len() as f64;
            let sd = (r.y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / r.y.len() as f64)
                .sqrt()
                .max(1e-300);
            let w = 1.0 / (sd * (r.y.len() as f64).sqrt());
            Some(s.iter().zip(&r.y).map(|(a, b)| (a - b) * w).collect())
        })
        .collect();
    let mut out = Vec::new();
    for p in parts {
        out.extend(p?);
    }
    Some(out)
}

/// Levenberg-Marquardt on the coefficients (structure and initial states fixed), minimising the
/// sum over runs of the squared free-run error normalised by each run's spread. Returns the
/// refined model (the input unchanged when no step lowers the cost).
pub fn refine(m: &AugModel, runs: &[SimRun], max_iter: usize) -> AugModel {
    use nalgebra::{DMatrix, DVector};
    let mut c = m.coefficients();
    let p = c.len();
    let Some(mut r) = residuals(m, runs) else {
        return m.clone();
    };
    let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let mut lambda = 1e-3;
    for _ in 0..max_iter {
        let mut jac = DMatrix::<f64>::zeros(r.len(), p);
        for j in 0..p {
            let dj = 1e-6 * c[j].abs().max(1e-6);
            let mut cp = c.clone();
            cp[j] += dj;
            let Some(rp) = residuals(&m.with_coefficients(&cp), runs) else {
                return m.with_coefficients(&c);
            };
            for k in 0..r.len() {
                jac[(k, j)] = (rp[k] - r[k]) / dj;
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * DVector::from_column_slice(&r);
        let c0 = cost(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut a = jtj.clone();
            for j in 0..p {
                a[(j, j)] += lambda * jtj[(j, j)].max(1e-300);
            }
            let Some(step) = a.lu().solve(&(-&jtr)) else {
                break;
            };
            let cn: Vec<f64> = c.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            if let Some(rn) = residuals(&m.with_coefficients(&cn), runs) {
                if cost(&rn) < c0 {
                    c = cn;
                    r = rn;
                    lambda = (lambda * 0.3).max(1e-9);
                    improved = true;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved || c0 - cost(&r) <= 1e-6 * c0 {
            break;
        }
    }
    m.with_coefficients(&c)
}
