//! Free-run simulation of a nominal-plus-effects model and a Levenberg-Marquardt refit of its
//! coefficients and initial states on simulation error (self-contained: the identify module's
//! multiple-shooting refit works on polynomial model files, these models carry expressions).
//!
//! The model is one output of order `n`: states `y, y_d1, ..., y_d(n-1)`, `y^(n) = sum_j c_j
//! phi_j(z)` with `z` the states then the inputs. `sign` is smoothed for the integrator over a
//! width of 1e-3 of each variable's spread (see [`super::expr`]).

use rayon::prelude::*;

use super::expr::Expr;
use crate::simulate::{
    rms_nrmse, simulate, simulate_sensitivities, std_dev, SampledInput, SimOptions, System,
};

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
    /// A thousandth of the smoothing width of `sign`, itself a thousandth of the state's spread:
    /// the default `1.5e-8 max(|x|, 1)` is coarse for states much smaller than one, and the
    /// sensitivities of the refit follow these Jacobians.
    fn fd_step(&self, k: usize, x: &[f64]) -> f64 {
        let scaled = 1e-3 * self.eps.get(k).copied().unwrap_or(0.0);
        if scaled > 0.0 {
            scaled.max(1e-12 * x[k].abs())
        } else {
            crate::simulate::default_fd_step(x[k])
        }
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
    free_run_from(m, run, &run.x0)
}

/// [`free_run`] from the initial state `x0` instead of the run's own.
fn free_run_from(m: &AugModel, run: &SimRun, x0: &[f64]) -> Option<Vec<f64>> {
    let input = SampledInput::new(run.t.clone(), run.u.clone()).ok()?;
    let tr = simulate(m, &input, x0, &run.t, &options(&run.id, &run.y)).ok()?;
    Some(tr.series(0))
}

/// Share of a run (from its start) on which [`fit_x0`] estimates the initial state.
pub const X0_WINDOW: f64 = 0.2;

/// The initial state that best explains the first [`X0_WINDOW`] of the run's measured output
/// under model `m` (Levenberg-Marquardt from the smoother's estimate in `run.x0`).
///
/// The smoother's derivative estimates are least certain at the first sample, and a system
/// with coexisting responses (a hardening Duffing oscillator) can follow a different one from
/// a slightly wrong start: one run of the acceptance cases went from 0.08 to 0.76 NRMSE on the
/// smoother's initial velocity alone. Every model is scored from its own estimate, so nominal and
/// augmented models are compared on equal terms.
pub fn fit_x0(m: &AugModel, run: &SimRun) -> Vec<f64> {
    let len = run.y.len();
    fit_x0_on(m, run, ((len as f64 * X0_WINDOW).ceil() as usize).max(20))
}

/// [`fit_x0`] on the first `w` samples (benchmarks fix it: Silverbox gives a model 50 samples).
pub fn fit_x0_on(m: &AugModel, run: &SimRun, w: usize) -> Vec<f64> {
    let w = w.min(run.y.len());
    if w < 3 {
        return run.x0.clone();
    }
    let head = SimRun {
        id: run.id.clone(),
        t: run.t[..w].to_vec(),
        y: run.y[..w].to_vec(),
        u: run.u.iter().map(|u| u[..w].to_vec()).collect(),
        x0: run.x0.clone(),
    };
    let fixed = vec![true; m.terms.len()];
    let (_, fitted) = refine_runs(m, &[head], &fixed, 10);
    fitted[0].x0.clone()
}

/// NRMSE of the free run from the initial state of [`fit_x0`] (infinite when it diverges).
pub fn nrmse(m: &AugModel, run: &SimRun) -> f64 {
    nrmse_against(m, run, &run.y)
}

/// As [`nrmse`], scored against `reference` instead of the run's measurement (the initial state
/// is still fitted on the measurement).
pub fn nrmse_against(m: &AugModel, run: &SimRun, reference: &[f64]) -> f64 {
    let r = SimRun {
        x0: fit_x0(m, run),
        ..run.clone()
    };
    match free_run(m, &r) {
        Some(s) => rms_nrmse(&s, reference).1,
        None => f64::INFINITY,
    }
}

/// Mean NRMSE over runs (in parallel).
pub fn mean_nrmse(m: &AugModel, runs: &[SimRun]) -> f64 {
    let v: Vec<f64> = runs.par_iter().map(|r| nrmse(m, r)).collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The weight `1 / (sd(y) sqrt(len))` of a run's residuals: runs count by their error relative
/// to their spread, whatever their length.
fn residual_weight(r: &SimRun) -> f64 {
    1.0 / (std_dev(&r.y).max(1e-300) * (r.y.len() as f64).sqrt())
}

/// A run's simulated output as normalised residuals, `(sim - y) / (sd(y) sqrt(len))`.
fn weighted_residuals(sim: &[f64], r: &SimRun) -> Vec<f64> {
    let w = residual_weight(r);
    sim.iter().zip(&r.y).map(|(a, b)| (a - b) * w).collect()
}

/// Normalised free-run residuals of one run from `x0`.
fn run_residuals(m: &AugModel, r: &SimRun, x0: &[f64]) -> Option<Vec<f64>> {
    Some(weighted_residuals(&free_run_from(m, r, x0)?, r))
}

/// [`run_residuals`] and their derivatives with respect to the coefficients `free` and then the
/// initial state, one column each, from forward sensitivities of the simulation.
#[allow(clippy::type_complexity)]
fn run_sensitivities(
    m: &AugModel,
    r: &SimRun,
    x0: &[f64],
    free: &[usize],
) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
    let n = m.order;
    let input = SampledInput::new(r.t.clone(), r.u.clone()).ok()?;
    let pjac = |x: &[f64], u: &[f64], out: &mut [f64]| {
        let mut z = Vec::with_capacity(x.len() + u.len());
        z.extend_from_slice(x);
        z.extend_from_slice(u);
        out.iter_mut().for_each(|v| *v = 0.0);
        for (c, &j) in free.iter().enumerate() {
            out[(n - 1) * free.len() + c] = m.terms[j].0.eval_smooth(&z, &m.eps);
        }
    };
    let opts = options(&r.id, &r.y);
    let (tr, sens) = simulate_sensitivities(m, &input, x0, &r.t, &opts, free.len(), &pjac).ok()?;
    let q = free.len() + n;
    let w = residual_weight(r);
    let cols: Vec<Vec<f64>> = (0..q)
        .map(|c| (0..r.t.len()).map(|k| sens[k * n * q + c] * w).collect())
        .collect();
    let res = weighted_residuals(&tr.series(0), r);
    cols.iter()
        .chain(std::iter::once(&res))
        .all(|c| c.iter().all(|v| v.is_finite()))
        .then_some((res, cols))
}

/// Levenberg-Marquardt on the coefficients and on each run's initial state (the structure
/// fixed), minimising the sum over runs of the squared free-run error normalised by each run's
/// spread. The smoother's initial states are least certain exactly at the first sample (the end
/// of a run), and a fit that kept them fixed would bend the coefficients to absorb the start-up
/// transient they cause; estimating them removes that bias. Returns the refined model and runs
/// (the inputs unchanged when no step lowers the cost).
///
/// `fixed[j]` holds coefficient j at its value (a nominal term the user marked as known).
pub fn refine_runs(
    m: &AugModel,
    runs: &[SimRun],
    fixed: &[bool],
    max_iter: usize,
) -> (AugModel, Vec<SimRun>) {
    let n = m.order;
    let nc = m.terms.len();
    let mut full: Vec<f64> = m.coefficients();
    for r in runs {
        full.extend(&r.x0);
    }
    let active: Vec<usize> = (0..full.len())
        .filter(|&j| j >= nc || !fixed.get(j).copied().unwrap_or(false))
        .collect();
    let start: Vec<f64> = active.iter().map(|&j| full[j]).collect();
    let p = RunsProblem {
        m,
        runs,
        full,
        active,
        offsets: runs
            .iter()
            .scan(0, |a, r| {
                let o = *a;
                *a += r.y.len();
                Some(o)
            })
            .collect(),
    };
    let o = crate::lm::LmOptions {
        max_iter,
        lambda0: 1e-3,
        shrink: 0.3,
        lambda_min: 1e-9,
        max_tries: 10,
        lambda_max: f64::MAX,
        tol: 1e-7,
    };
    let mut stats = crate::lm::LmStats::default();
    let Some((theta, _)) = crate::lm::minimize(&p, start, &o, &mut stats) else {
        return (m.clone(), runs.to_vec());
    };
    let th = p.expand(&theta);
    let rr = runs
        .iter()
        .enumerate()
        .map(|(k, r)| SimRun {
            x0: th[nc + k * n..nc + (k + 1) * n].to_vec(),
            ..r.clone()
        })
        .collect();
    (m.with_coefficients(&th[..nc]), rr)
}

/// The least-squares problem of [`refine_runs`]: parameters are the coefficients, then each
/// run's initial state; only the `active` ones (ascending: free coefficients first) are free.
struct RunsProblem<'a> {
    m: &'a AugModel,
    runs: &'a [SimRun],
    full: Vec<f64>,
    active: Vec<usize>,
    /// First residual row of each run.
    offsets: Vec<usize>,
}

impl RunsProblem<'_> {
    fn expand(&self, theta: &[f64]) -> Vec<f64> {
        let mut th = self.full.clone();
        for (&j, &v) in self.active.iter().zip(theta) {
            th[j] = v;
        }
        th
    }
}

impl crate::lm::LeastSquares for RunsProblem<'_> {
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let (n, nc) = (self.m.order, self.m.terms.len());
        let th = self.expand(theta);
        let mm = self.m.with_coefficients(&th[..nc]);
        let per: Option<Vec<Vec<f64>>> = self
            .runs
            .par_iter()
            .enumerate()
            .map(|(k, r)| run_residuals(&mm, r, &th[nc + k * n..nc + (k + 1) * n]))
            .collect();
        Some(per?.concat())
    }

    fn normal_equations(
        &self,
        theta: &[f64],
    ) -> Option<(nalgebra::DMatrix<f64>, nalgebra::DVector<f64>)> {
        use nalgebra::{DMatrix, DVector};
        let (n, nc) = (self.m.order, self.m.terms.len());
        let th = self.expand(theta);
        let mm = self.m.with_coefficients(&th[..nc]);
        // Sensitivities, one simulation per run: a coefficient's column touches every run, an
        // initial state's only its own. `active` is ascending, so its first entries are the
        // free coefficients, in the order of the sensitivity columns.
        let free = &self.active[..self.active.partition_point(|&j| j < nc)];
        let sens: Vec<(Vec<f64>, Vec<Vec<f64>>)> = self
            .runs
            .par_iter()
            .enumerate()
            .map(|(k, r)| run_sensitivities(&mm, r, &th[nc + k * n..nc + (k + 1) * n], free))
            .collect::<Option<_>>()?;
        let total: usize = self.runs.iter().map(|r| r.y.len()).sum();
        let mut jac = DMatrix::<f64>::zeros(total, self.active.len());
        for (k, (_, cols)) in sens.iter().enumerate() {
            for (q, &j) in self.active.iter().enumerate() {
                let col = if j < nc {
                    Some(&cols[q])
                } else if (j - nc) / n == k {
                    Some(&cols[free.len() + (j - nc) % n])
                } else {
                    None
                };
                if let Some(col) = col {
                    for (i, v) in col.iter().enumerate() {
                        jac[(self.offsets[k] + i, q)] = *v;
                    }
                }
            }
        }
        let r = DVector::from_iterator(total, sens.iter().flat_map(|(res, _)| res.iter().copied()));
        Some((jac.transpose() * &jac, jac.transpose() * r))
    }
}

/// [`refine_runs`] without the refined initial states.
pub fn refine(m: &AugModel, runs: &[SimRun], fixed: &[bool], max_iter: usize) -> AugModel {
    refine_runs(m, runs, fixed, max_iter).0
}
