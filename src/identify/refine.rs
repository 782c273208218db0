//! Refinement of an identified model by minimising its free-run simulation error.
//!
//! The derivative-based fit regresses a reconstructed `y^(n)` on reconstructed `y, ..., y^(n-1)`:
//! noise in those regressors (errors in variables) biases the coefficients, most where a large
//! coefficient multiplies a noisy high derivative. Here the structure (which terms) is fixed and
//! the nonzero coefficients, together with initial states, are fitted so that the *simulated*
//! outputs match the *measured* ones: only the measured outputs enter the residuals, so
//! derivative noise no longer biases anything.
//!
//! # Method
//! Levenberg-Marquardt with multiple shooting, in two phases:
//! 1. **Multiple shooting.** Each run is cut into segments of about
//!    [`RefineOptions::segment_len`] samples; every segment has its own initial state as a free
//!    parameter. Residuals are the simulated minus measured outputs at every sample, divided by
//!    the output's standard deviation over the data, and the continuity defects
//!    `x_end(segment k) - x_start(segment k+1)` as *soft* residuals: divided by that state's
//!    spread and weighted by `sqrt(segment_len)`, so that a junction off by one spread costs as
//!    much as an output off by one standard deviation over a whole segment. Short segments keep a
//!    poor starting model from drifting far, which widens the basin of convergence.
//! 2. **Single shooting polish.** The segments of each run are joined (one initial state per
//!    run, started from the first segment's) and the same LM runs on the free-run error itself,
//!    which is what the validation gate measures; the soft defects of phase 1 leave no trace.
//!
//! The Jacobian comes from forward sensitivities carried through the adaptive Radau IIA
//! simulator of [`crate::simulate`] ([`crate::simulate::simulate_model_sensitivities`]): each
//! accepted step is differentiated through its own stage equations, so the columns are the
//! derivatives of the very simulation the cost and the gate measure (to its local error: the
//! full step is differentiated, the two half steps are kept), for the price of one small
//! factorisation and a multi-right-hand-side solve per step. Forward differences of whole
//! simulations (one per free parameter and segment) cost 2-5x more time for the same
//! iterations (measured on the throttle demo's scoring fits: 14.3 s -> 2.8 s for a 20-term
//! candidate, with the same result).
//!
//! The normal equations are assembled block by block (each segment touches only the
//! coefficients and its own state) and solved densely with Marquardt's scaling
//! `(J^T J + lambda diag(J^T J)) d = -J^T r`. A trial step whose simulation diverges, or that does
//! not lower the cost, is rejected and lambda raised tenfold; an accepted step lowers lambda.
//! Everything is deterministic: parallel results are collected in a fixed order.
//!
//! # What it assumes
//! Uniformly sampled runs with inputs interpolated linearly between samples (as everywhere in
//! the crate); a starting model that can be simulated over one segment from the given states.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::lm::{cost, LeastSquares, LmStats};
use crate::metrics::nrmse;
use crate::model::{CompiledModel, Model};
use crate::simulate::{
    free_run, simulate_model, simulate_model_sensitivities, SimOptions, Trajectory, INIT_WINDOW,
};
use crate::util::num4;

/// Settings of [`refine`].
#[derive(Debug, Clone)]
pub struct RefineOptions {
    /// Samples per shooting segment in phase 1 (a run's remainder shorter than half of it joins
    /// the last segment).
    pub segment_len: usize,
    /// Most LM iterations (Jacobian evaluations) of the multiple-shooting phase.
    pub max_iterations: usize,
    /// Most LM iterations of the single-shooting polish (0 skips it).
    pub polish_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction. Gains below
    /// `1e-4` of a mean squared error are far under what noise lets one tell apart, and along
    /// directions the data do not determine (a pole faster than the sampling, for instance)
    /// further iterations only drift.
    pub tolerance: f64,
    /// Tolerances of the simulations inside the fit (tighter than the gate's, so that the
    /// difference quotients are not dominated by integration error).
    pub rtol: f64,
    pub atol: f64,
    /// A simulated state beyond this many times the largest magnitude in the data (outputs and
    /// state spreads) counts as diverged.
    pub divergence_factor: f64,
    /// No refinement when the starting model's free-run NRMSE on both the fit and the gate runs
    /// is already below this: there is nothing left for simulation error to correct (noise-free
    /// data), and the fit would cost most of an identification's time.
    pub skip_below: f64,
    /// Where the start does not follow the output in free run, try its terms up to each lower
    /// degree (highest first) as for a start that cannot be simulated over the shooting
    /// segments, not its linear part alone. Off for the order search's scoring refinements (a
    /// candidate's linear part scores it cheaply, and the repaired candidates moved the search:
    /// `demo mimo --degrees 4 --noise 0.03 --seed 4` went to orders (4, 3, 4), 8 / 18 true
    /// terms); on for the selected model's refinement, the last chance to repair it (seed 4 at
    /// d = 6, 3 %: every coefficient of the orders (3, 3, 3) about half the truth's, refined from
    /// its terms up to degree 5 instead of its linear part: 0.66 / 0.78 / 1.30 % against truth
    /// instead of 101 / 42 / 34 %). docs/method/identification.md.
    pub every_lower_start: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            segment_len: 250,
            max_iterations: 25,
            polish_iterations: 8,
            tolerance: 1e-4,
            rtol: crate::simulate::FIT_RTOL,
            atol: crate::simulate::FIT_ATOL,
            divergence_factor: 1e6,
            skip_below: 1e-3,
            every_lower_start: false,
        }
    }
}

pub use crate::simulate::RunData;

/// The result of [`refine`].
#[derive(Debug, Clone)]
pub struct Refined {
    /// The model with refined coefficients (same terms).
    pub model: Model,
    /// Refined initial state of every run.
    pub initial_states: Vec<Vec<f64>>,
    /// Cost (sum over outputs of the mean squared error over the output's variance) of the
    /// starting and the refined model, free-run from the starting and the refined initial states.
    pub cost_before: f64,
    pub cost_after: f64,
    /// Levenberg-Marquardt's counts over every stage of the refinement.
    pub lm: LmStats,
    pub seconds: f64,
}

/// A segment of a run: samples `a..=b`.
#[derive(Debug, Clone, Copy)]
struct Segment {
    run: usize,
    a: usize,
    b: usize,
    /// Last segment of its run: its residuals include sample `b`, and it has no defect.
    last: bool,
}

/// The least-squares problem of one phase.
struct Problem<'a> {
    base: &'a CompiledModel,
    runs: &'a [RunData],
    segs: Vec<Segment>,
    /// Indices (in the model's coefficient vector) of the free coefficients.
    free: Vec<usize>,
    all_coef: Vec<f64>,
    n: usize,
    out_scale: Vec<f64>,
    state_scale: Vec<f64>,
    /// 1/sqrt(samples per output): residuals then sum to mean squared normalised errors.
    norm: f64,
    defect_weight: f64,
    opts: SimOptions,
}

/// What one segment contributes: its residual rows and, for non-last segments, its end state.
struct SegEval {
    rows: Vec<f64>,
    end: Vec<f64>,
}

impl<'a> Problem<'a> {
    /// The same problem over other segments.
    fn with_segments(&self, segs: Vec<Segment>) -> Problem<'a> {
        Problem {
            base: self.base,
            runs: self.runs,
            segs,
            free: self.free.clone(),
            all_coef: self.all_coef.clone(),
            n: self.n,
            out_scale: self.out_scale.clone(),
            state_scale: self.state_scale.clone(),
            norm: self.norm,
            defect_weight: self.defect_weight,
            opts: self.opts.clone(),
        }
    }

    fn n_coef(&self) -> usize {
        self.free.len()
    }
    fn n_params(&self) -> usize {
        self.free.len() + self.segs.len() * self.n
    }

    fn model_with(&self, theta: &[f64]) -> CompiledModel {
        let mut c = self.all_coef.clone();
        for (k, &j) in self.free.iter().enumerate() {
            c[j] = theta[k];
        }
        let mut m = self.base.clone();
        m.set_coefficients(&c).expect("same number of terms");
        m
    }

    /// Segment `s`, its run, sample times, inputs and simulation options.
    fn segment_data(&self, s: usize) -> (Segment, &RunData, &[f64], Vec<Vec<f64>>, SimOptions) {
        let seg = self.segs[s];
        let run = &self.runs[seg.run];
        let t = &run.t[seg.a..=seg.b];
        let u: Vec<Vec<f64>> = run.u.iter().map(|c| c[seg.a..=seg.b].to_vec()).collect();
        let mut opts = self.opts.clone();
        opts.run = run.id.clone();
        (seg, run, t, u, opts)
    }

    /// The residual rows of segment `seg` (samples `a..b`, or `a..=b` for a run's last
    /// segment) and its end state, from its simulated trajectory; `None` if not finite.
    fn seg_eval(&self, model: &CompiledModel, seg: Segment, tr: &Trajectory) -> Option<SegEval> {
        let run = &self.runs[seg.run];
        let len = seg.b - seg.a + 1;
        let m = if seg.last { len } else { len - 1 };
        let mut rows = Vec::with_capacity(m * run.y.len());
        for (i, y) in run.y.iter().enumerate() {
            let o = model.offset(i);
            let w = self.norm / self.out_scale[i];
            rows.extend((0..m).map(|k| (tr.state_at(k)[o] - y[seg.a + k]) * w));
        }
        let end = tr.state_at(len - 1).to_vec();
        rows.iter()
            .all(|v| v.is_finite())
            .then_some(SegEval { rows, end })
    }

    /// Simulates segment `s` of `model` from `x0`; `None` if it diverges.
    fn eval_segment(&self, model: &CompiledModel, s: usize, x0: &[f64]) -> Option<SegEval> {
        let (seg, _, t, u, opts) = self.segment_data(s);
        let tr = simulate_model(model, x0, t, &u, &opts).ok()?;
        self.seg_eval(model, seg, &tr)
    }

    /// [`Self::eval_segment`] with the derivatives of its rows and end state with respect to
    /// the free coefficients and the segment's initial state, in that column order.
    #[allow(clippy::type_complexity)]
    fn eval_segment_sensitivities(
        &self,
        model: &CompiledModel,
        s: usize,
        x0: &[f64],
    ) -> Option<(SegEval, Vec<(Vec<f64>, Vec<f64>)>)> {
        let (seg, run, t, u, opts) = self.segment_data(s);
        let (tr, sens) = simulate_model_sensitivities(model, x0, t, &u, &opts, &self.free).ok()?;
        let ev = self.seg_eval(model, seg, &tr)?;
        let n = self.n;
        let q = self.free.len() + n;
        let last = t.len() - 1;
        let m = if seg.last { t.len() } else { last };
        // Column c: the rows' derivatives (weighted like the rows), then the end state's.
        let cols = (0..q)
            .map(|c| {
                let mut d = Vec::with_capacity(ev.rows.len());
                for i in 0..run.y.len() {
                    let o = model.offset(i);
                    let w = self.norm / self.out_scale[i];
                    d.extend((0..m).map(|k| sens[(k * n + o) * q + c] * w));
                }
                let end = (0..n).map(|j| sens[(last * n + j) * q + c]).collect();
                (d, end)
            })
            .collect();
        sens.iter().all(|v| v.is_finite()).then_some((ev, cols))
    }

    fn x0_of<'t>(&self, theta: &'t [f64], s: usize) -> &'t [f64] {
        let o = self.n_coef() + s * self.n;
        &theta[o..o + self.n]
    }

    /// Defect residuals between segment `s` (ending at `end`) and segment `s + 1`.
    fn defect(&self, theta: &[f64], s: usize, end: &[f64]) -> Vec<f64> {
        let next = self.x0_of(theta, s + 1);
        (0..self.n)
            .map(|j| (end[j] - next[j]) / self.state_scale[j] * self.defect_weight)
            .collect()
    }
}

impl LeastSquares for Problem<'_> {
    /// All residuals, or `None` when a segment diverges.
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let model = self.model_with(theta);
        let evals: Vec<Option<SegEval>> = (0..self.segs.len())
            .into_par_iter()
            .map(|s| self.eval_segment(&model, s, self.x0_of(theta, s)))
            .collect();
        let mut r = Vec::new();
        for (s, e) in evals.into_iter().enumerate() {
            let e = e?;
            r.extend_from_slice(&e.rows);
            if !self.segs[s].last {
                r.extend(self.defect(theta, s, &e.end));
            }
        }
        Some(r)
    }

    /// Normal equations `J^T J`, `J^T r` from forward sensitivities, assembled per segment.
    fn normal_equations(&self, theta: &[f64]) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let nc = self.n_coef();
        let n = self.n;
        let np = self.n_params();
        let base = self.model_with(theta);
        // Per segment: local parameter columns [coefficients, own state] and their blocks.
        struct Local {
            r0: SegEval,
            cols: Vec<(Vec<f64>, Vec<f64>)>, // d rows / dp, d end / dp
        }
        let locals: Vec<Option<Local>> = (0..self.segs.len())
            .into_par_iter()
            .map(|s| {
                let (r0, cols) = self.eval_segment_sensitivities(&base, s, self.x0_of(theta, s))?;
                Some(Local { r0, cols })
            })
            .collect();
        let mut jtj = DMatrix::<f64>::zeros(np, np);
        let mut jtr = DVector::<f64>::zeros(np);
        for (s, l) in locals.into_iter().enumerate() {
            // The base point simulated before, so this fails only where the sensitivities do
            // (a singular stage matrix, non-finite values): no information from this segment
            // for this step; the trial's cost check still sees every segment.
            let Some(l) = l else { continue };
            let idx: Vec<usize> = (0..nc).chain((0..n).map(|j| nc + s * n + j)).collect();
            let q = idx.len();
            for a in 0..q {
                let ca = &l.cols[a].0;
                jtr[idx[a]] += ca.iter().zip(&l.r0.rows).map(|(x, y)| x * y).sum::<f64>();
                for b in a..q {
                    let v: f64 = ca.iter().zip(&l.cols[b].0).map(|(x, y)| x * y).sum();
                    jtj[(idx[a], idx[b])] += v;
                    if a != b {
                        jtj[(idx[b], idx[a])] += v;
                    }
                }
            }
            if !self.segs[s].last {
                // Defect rows: d/dp of (end - next) / scale * weight, over [local params, next state].
                let d = self.defect(theta, s, &l.r0.end);
                let mut idx2 = idx.clone();
                idx2.extend((0..n).map(|j| nc + (s + 1) * n + j));
                for (j, dj) in d.iter().enumerate() {
                    let w = self.defect_weight / self.state_scale[j];
                    let mut row: Vec<f64> = l.cols.iter().map(|c| c.1[j] * w).collect();
                    row.extend((0..n).map(|i| if i == j { -w } else { 0.0 }));
                    for a in 0..row.len() {
                        if row[a] == 0.0 {
                            continue;
                        }
                        jtr[idx2[a]] += row[a] * dj;
                        for b in 0..row.len() {
                            jtj[(idx2[a], idx2[b])] += row[a] * row[b];
                        }
                    }
                }
            }
        }
        Some((jtj, jtr))
    }
}

/// Levenberg-Marquardt ([`crate::lm`]) on a problem from `theta`, counting into `stats`.
fn levenberg_marquardt(
    p: &Problem,
    theta: Vec<f64>,
    max_iter: usize,
    tol: f64,
    stats: &mut Refined,
) -> Option<(Vec<f64>, f64)> {
    let o = crate::lm::LmOptions {
        max_iter,
        tol,
        ..Default::default()
    };
    crate::lm::minimize(p, theta, &o, &mut stats.lm)
}

/// Standard deviation (population) of a pooled set of samples.
fn spread<'a>(values: impl Iterator<Item = &'a f64>) -> f64 {
    crate::metrics::std_dev(&values.copied().collect::<Vec<f64>>())
}

/// Every run has the model's channels, all of one length (at least 2 samples), an initial
/// state of the model's size and, if given, state guesses of that shape.
fn check_runs(compiled: &crate::model::CompiledModel, runs: &[RunData]) -> Result<()> {
    let (n, n_out, n_in) = (
        compiled.n_state(),
        compiled.n_outputs(),
        compiled.n_inputs(),
    );
    for r in runs {
        let len = r.t.len();
        let bad = r.y.len() != n_out
            || r.u.len() != n_in
            || r.y.iter().chain(&r.u).any(|c| c.len() != len)
            || r.x0.len() != n
            || r.states
                .as_ref()
                .is_some_and(|s| s.len() != n || s.iter().any(|c| c.len() != len));
        if bad {
            return Err(Error::InvalidData(format!(
                "run '{}': refinement needs {n_out} output and {n_in} input channels of equal length, an initial state of {n} values and state guesses of that shape",
                r.id
            )));
        }
        if len < 2 {
            return Err(Error::RunTooShort {
                run: r.id.clone(),
                len,
                min: 2,
                what: "refinement".into(),
            });
        }
    }
    Ok(())
}

/// The shooting segments of every run (about `l` samples each; a remainder shorter than half
/// of that joins the last) and each segment's starting state: the run's initial state, the
/// state guesses where given, else a simulation of the starting model, else the measured
/// outputs with zero derivatives.
fn segments(
    compiled: &CompiledModel,
    runs: &[RunData],
    l: usize,
    sim_opts: &SimOptions,
) -> (Vec<Segment>, Vec<Vec<f64>>) {
    let (n, n_out) = (compiled.n_state(), compiled.n_outputs());
    let mut segs = Vec::new();
    let mut seg_x0: Vec<Vec<f64>> = Vec::new();
    for (ri, r) in runs.iter().enumerate() {
        let len = r.t.len();
        let mut starts: Vec<usize> = (0..len - 1).step_by(l).collect();
        if starts.len() > 1 && len - 1 - starts[starts.len() - 1] < l / 2 {
            starts.pop();
        }
        let fallback = match &r.states {
            Some(_) => None,
            None => simulate_model(compiled, &r.x0, &r.t, &r.u, sim_opts).ok(),
        };
        for (k, &a) in starts.iter().enumerate() {
            let last = k + 1 == starts.len();
            let b = if last { len - 1 } else { starts[k + 1] };
            segs.push(Segment {
                run: ri,
                a,
                b,
                last,
            });
            let x = if a == 0 {
                r.x0.clone()
            } else if let Some(st) = &r.states {
                st.iter().map(|c| c[a]).collect()
            } else if let Some(tr) = &fallback {
                tr.state_at(a).to_vec()
            } else {
                let mut x = vec![0.0; n];
                for i in 0..n_out {
                    x[compiled.offset(i)] = r.y[i][a];
                }
                x
            };
            seg_x0.push(x);
        }
    }
    (segs, seg_x0)
}

/// Refines the nonzero coefficients of `model` (structure fixed) and the initial state of every
/// run by minimising the simulation error on `runs` (see the module docs).
///
/// Fails with a typed error when the data do not fit the model, or when the starting model
/// cannot be simulated over the segments from the given states. Refuses a model that
/// [`Model::validate`] refuses, no runs, a `segment_len` below 4, and a run whose channels, lengths
/// (at least 2 samples), initial state or state guesses do not fit the model; errs
/// ([`Error::Numerical`]) when the starting model cannot be simulated.
pub fn refine(model: &Model, runs: &[RunData], opts: &RefineOptions) -> Result<Refined> {
    refine_holding(model, runs, opts, &[])
}

/// [`refine`] with the coefficients `fixed[k]` (in the model's term order, output by output)
/// held at their values: a nominal term the user marked as known. Shorter masks free the rest.
/// Refuses what [`refine`] refuses.
pub fn refine_holding(
    model: &Model,
    runs: &[RunData],
    opts: &RefineOptions,
    fixed: &[bool],
) -> Result<Refined> {
    let t_start = std::time::Instant::now();
    let compiled = model.compile()?;
    let n = compiled.n_state();
    let n_out = compiled.n_outputs();

    if runs.is_empty() {
        return Err(Error::param("refine", "no runs to refine on"));
    }
    if opts.segment_len < 4 {
        return Err(Error::param("segment_len", "needs at least 4 samples"));
    }
    check_runs(&compiled, runs)?;
    let all_coef = compiled.coefficients();
    let free: Vec<usize> = (0..all_coef.len())
        .filter(|&k| all_coef[k] != 0.0 && !fixed.get(k).copied().unwrap_or(false))
        .collect();
    let out_scale: Vec<f64> = (0..n_out)
        .map(|i| {
            let s = spread(runs.iter().flat_map(|r| r.y[i].iter()));
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect();
    let mut sim_opts = SimOptions {
        rtol: opts.rtol,
        atol: opts.atol,
        ..Default::default()
    };

    let (segs, seg_x0) = segments(&compiled, runs, opts.segment_len, &sim_opts);
    let state_scale = state_scales(&compiled, runs, &seg_x0, &out_scale);
    // A trial whose states leave the data's range by orders of magnitude has diverged: stopping
    // it there saves the time of integrating a blow-up up to the simulator's default bound.
    let largest = state_scale
        .iter()
        .chain(&out_scale)
        .chain(runs.iter().flat_map(|r| r.y.iter().flatten()))
        .fold(0.0f64, |a, v| a.max(v.abs()));
    sim_opts.bound = (opts.divergence_factor * largest).min(sim_opts.bound);
    let total: usize = runs.iter().map(|r| r.t.len()).sum();
    let mut problem = Problem {
        base: &compiled,
        runs,
        segs,
        free: free.clone(),
        all_coef: all_coef.clone(),
        n,
        out_scale,
        state_scale,
        norm: 1.0 / (total as f64).sqrt(),
        defect_weight: (opts.segment_len as f64 / total as f64).sqrt(),
        opts: sim_opts,
    };

    let mut stats = Refined {
        model: model.clone(),
        initial_states: runs.iter().map(|r| r.x0.clone()).collect(),
        cost_before: f64::NAN,
        cost_after: f64::NAN,
        lm: LmStats::default(),
        seconds: 0.0,
    };
    let whole: Vec<Segment> = runs
        .iter()
        .enumerate()
        .map(|(ri, r)| Segment {
            run: ri,
            a: 0,
            b: r.t.len() - 1,
            last: true,
        })
        .collect();
    let free_run = problem.with_segments(whole.clone());
    let theta_of = |coef: &[f64], xs: &[Vec<f64>]| -> Vec<f64> {
        let mut th: Vec<f64> = free.iter().map(|&k| coef[k]).collect();
        xs.iter().for_each(|x| th.extend_from_slice(x));
        th
    };
    stats.cost_before = free_run
        .residuals(&theta_of(&all_coef, &stats.initial_states))
        .map_or(f64::INFINITY, |r| cost(&r));

    // Phase 1: multiple shooting.
    let theta0 = theta_of(&all_coef, &seg_x0);
    let (theta1, _) = levenberg_marquardt(
        &problem,
        theta0,
        opts.max_iterations,
        opts.tolerance,
        &mut stats,
    )
    .ok_or_else(|| {
        Error::Numerical(
            "refinement: the starting model cannot be simulated over the shooting segments".into(),
        )
    })?;
    // Phase 2: single shooting from each run's first segment.
    let nc = free.len();
    let mut theta2: Vec<f64> = theta1[..nc].to_vec();
    for (s, seg) in problem.segs.iter().enumerate() {
        if seg.a == 0 {
            theta2.extend_from_slice(&theta1[nc + s * n..nc + (s + 1) * n]);
        }
    }
    problem = problem.with_segments(whole);
    let mut theta = theta2.clone();
    let mut c_after = problem
        .residuals(&theta)
        .map_or(f64::INFINITY, |r| cost(&r));
    if opts.polish_iterations > 0 {
        if let Some((th, c)) = levenberg_marquardt(
            &problem,
            theta2,
            opts.polish_iterations,
            opts.tolerance,
            &mut stats,
        ) {
            theta = th;
            c_after = c;
        }
    }
    // Keep whichever of start and result simulates better on the training runs (a multiple-
    // shooting optimum whose joined trajectory diverges is no refinement).
    if c_after < stats.cost_before {
        let mut m = with_free_coefficients(model, &all_coef, &free, &theta[..nc]);
        set_std_errors(&mut m, &problem, &theta, &free);
        stats.model = m;
        stats.initial_states = (0..runs.len())
            .map(|r| theta[nc + r * n..nc + (r + 1) * n].to_vec())
            .collect();
        stats.cost_after = c_after;
    } else {
        stats.cost_after = stats.cost_before;
    }
    stats.seconds = t_start.elapsed().as_secs_f64();
    Ok(stats)
}

/// Per state, the spread that scales its initial-state unknown: of the runs' state guesses
/// where they have them, else of the shooting segments' starting states; an output's own spread
/// when its derivative guesses do not vary.
fn state_scales(
    compiled: &CompiledModel,
    runs: &[RunData],
    seg_x0: &[Vec<f64>],
    out_scale: &[f64],
) -> Vec<f64> {
    let (n, n_out) = (compiled.n_state(), compiled.n_outputs());
    (0..n)
        .map(|j| {
            let s = match runs[0].states {
                Some(_) => spread(
                    runs.iter()
                        .flat_map(|r| r.states.as_ref().map_or([].iter(), |s| s[j].iter())),
                ),
                None => spread(seg_x0.iter().map(|x| &x[j])),
            };
            let i = (0..n_out)
                .rev()
                .find(|&i| compiled.offset(i) <= j)
                .unwrap_or(0);
            if s > 0.0 {
                s
            } else {
                out_scale[i]
            }
        })
        .collect()
}

/// `model` with the coefficients `all_coef`, where those at positions `free` (in file order)
/// are replaced by `values`.
fn with_free_coefficients(
    model: &Model,
    all_coef: &[f64],
    free: &[usize],
    values: &[f64],
) -> Model {
    let mut coef = all_coef.to_vec();
    for (&j, &v) in free.iter().zip(values) {
        coef[j] = v;
    }
    let mut m = model.clone();
    let terms = m.outputs.iter_mut().flat_map(|o| o.terms.iter_mut());
    for (t, c) in terms.zip(coef) {
        t.coefficient = c;
    }
    m
}

/// Standard errors of the refined coefficients from the free-run problem's Jacobian at its
/// optimum: `s^2 (J^T J)^-1` over coefficients and initial states, `s^2` the residual variance
/// (RSS over residuals minus parameters), inflated by `(1 + rho) / (1 - rho)` for the lag-one
/// autocorrelation `rho` of the residuals (an AR(1) effective sample size). Simulation errors
/// are strongly correlated in time: without the inflation, a first-order cubic plant (its record
/// made by Euler steps, so the data's own dynamics are off by a little) got -0.99347 +- 0.00023
/// for a true -1 (28 standard errors off); with it +- 0.0024.
/// Written into the free terms of `model`; nothing when the normal matrix is singular.
fn set_std_errors(model: &mut Model, problem: &Problem, theta: &[f64], free: &[usize]) {
    let (Some(r), Some((jtj, _))) = (problem.residuals(theta), problem.normal_equations(theta))
    else {
        return;
    };
    let dof = r.len().saturating_sub(theta.len());
    if dof == 0 {
        return;
    }
    let rss = r.iter().map(|v| v * v).sum::<f64>();
    let lag1 = r.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
    let rho = if rss > 0.0 {
        (lag1 / rss).clamp(0.0, 0.9999)
    } else {
        0.0
    };
    let s2 = rss / dof as f64 * (1.0 + rho) / (1.0 - rho);
    let Some(inv) = jtj.try_inverse() else {
        return;
    };
    let mut k_of = vec![None; model.outputs.iter().map(|o| o.terms.len()).sum()];
    for (k, &j) in free.iter().enumerate() {
        k_of[j] = Some(k);
    }
    let terms = model.outputs.iter_mut().flat_map(|o| o.terms.iter_mut());
    for (t, k) in terms.zip(k_of) {
        if let Some(k) = k {
            let v = s2 * inv[(k, k)];
            t.std_error = (v.is_finite() && v >= 0.0).then(|| v.sqrt());
        }
    }
}

/// Free-run simulation error of `model` on `runs`: per output, the root mean square over runs
/// of the NRMSE (RMS error over the measured output's standard deviation). Each run starts from
/// the [`crate::simulate::initial_state`] on its first [`crate::simulate::INIT_WINDOW`] samples,
/// as every report does, so that two models are compared on equal terms. A run that diverges
/// makes the error infinite. Refuses a model that [`Model::validate`] refuses and a run whose
/// channels, lengths (at least 2 samples) or initial state do not fit the model; no runs give NaN.
pub fn free_run_nrmse(model: &Model, runs: &[RunData]) -> Result<Vec<f64>> {
    let compiled = model.compile()?;
    check_runs(&compiled, runs)?;
    let n_out = compiled.n_outputs();
    let opts = SimOptions::fitting();
    let per_run: Vec<Vec<f64>> = runs
        .par_iter()
        .map(|r| match free_run(&compiled, r, INIT_WINDOW, &opts) {
            Ok(sim) => (0..n_out).map(|i| nrmse(&sim[i], &r.y[i])).collect(),
            Err(_) => vec![f64::INFINITY; n_out],
        })
        .collect();
    Ok((0..n_out)
        .map(|i| {
            if per_run.is_empty() {
                f64::NAN
            } else {
                (per_run.iter().map(|v| v[i] * v[i]).sum::<f64>() / per_run.len() as f64).sqrt()
            }
        })
        .collect())
}

/// The refinement of `model` from its first lower-degree start that can be simulated over the
/// shooting segments, and the note that says so: the terms up to each lower degree the model
/// has, highest first, where it `follows` the output in free run; else its linear part alone.
/// A derivative fit with spurious nonlinear terms can blow up from the state guesses at some
/// segment's start though its free run follows the output (a high-degree term amplifying a
/// noisy derivative estimate): `demo mimo --degrees 6 --noise 0.01 --seed 4`, y3's order-3
/// candidate lost `y1^2` with its three spurious degree-6 terms when its linear part was the
/// start (gate NRMSE 0.17 -> 0.58; from its terms up to degree 2, 0.17 -> 0.04).
fn lower_degree_start(
    model: &Model,
    fit: &[RunData],
    opts: &RefineOptions,
    follows: bool,
) -> Option<(Refined, String)> {
    let mut degrees: Vec<u32> = model
        .outputs
        .iter()
        .flat_map(|eq| eq.terms.iter().map(|t| t.degree()))
        .collect();
    degrees.sort_unstable();
    degrees.dedup();
    let lower: Vec<u32> = if follows {
        let below = degrees.len().saturating_sub(1);
        degrees[..below]
            .iter()
            .rev()
            .copied()
            .filter(|&k| k >= 1)
            .collect()
    } else {
        vec![1]
    };
    lower.into_iter().find_map(|k| {
        let r = refine(&up_to_degree(model, k)?, fit, opts).ok()?;
        let note = if k == 1 {
            " (the full derivative fit could not be simulated or did not follow the output; refined its linear terms)".to_string()
        } else {
            format!(" (the full derivative fit could not be simulated; refined its terms up to degree {k})")
        };
        Some((r, note))
    })
}

/// `model` with only its terms of degree at most `k` (a named expression counts as degree 0);
/// `None` where that drops nothing or leaves an output without terms.
fn up_to_degree(model: &Model, k: u32) -> Option<Model> {
    let mut m = model.clone();
    let mut dropped = false;
    for eq in m.outputs.iter_mut() {
        let before = eq.terms.len();
        eq.terms.retain(|t| t.degree() <= k);
        dropped |= eq.terms.len() < before;
    }
    (dropped && m.outputs.iter().all(|eq| !eq.terms.is_empty())).then_some(m)
}

/// One number for a gate decision: the root mean square over outputs (NaN counts as infinite). An
/// empty slice gives 0.
pub fn overall(e: &[f64]) -> f64 {
    let v = (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt();
    if v.is_nan() {
        f64::INFINITY
    } else {
        v
    }
}

/// The outcome of [`refine_gated`].
#[derive(Debug, Clone)]
pub struct Gated {
    /// The model to use: the refined one when the gate accepted it, else the starting one.
    pub model: Model,
    /// Whether the refined model was kept.
    pub kept: bool,
    /// Free-run NRMSE per output on the fitting runs and the gate runs, before and after.
    pub train_before: Vec<f64>,
    pub train_after: Vec<f64>,
    pub gate_before: Vec<f64>,
    pub gate_after: Vec<f64>,
    /// The refinement itself; `None` when it failed (see `message`).
    pub refined: Option<Refined>,
    /// Why it was kept or refused, in one line.
    pub message: String,
}

impl Gated {
    /// The starting model kept as it is, with the reason.
    fn unchanged(model: &Model, train: Vec<f64>, gate: Vec<f64>, message: String) -> Gated {
        Gated {
            model: model.clone(),
            kept: false,
            train_after: train.clone(),
            gate_after: gate.clone(),
            train_before: train,
            gate_before: gate,
            refined: None,
            message,
        }
    }
}

/// Refines `model` on `fit` runs and keeps the result only if its free-run error on the `gate`
/// runs (runs the refinement did not see) is lower than the starting model's.
///
/// A start that cannot be simulated over the shooting segments is refined from its terms up to
/// each lower degree it has (highest first), one that does not follow the output in free run
/// (NRMSE above 1 on the fit runs) from its linear part; the gate judges the result against the
/// full start. A refinement that fails from every start is not an error: the
/// starting model is returned with the reason. Refuses what [`free_run_nrmse`] refuses on either
/// run list; errors of [`refine`] other than [`Error::Numerical`] are passed on.
pub fn refine_gated(
    model: &Model,
    fit: &[RunData],
    gate: &[RunData],
    opts: &RefineOptions,
) -> Result<Gated> {
    let train_before = free_run_nrmse(model, fit)?;
    let gate_before = free_run_nrmse(model, gate)?;
    let (tb, gb) = (overall(&train_before), overall(&gate_before));
    if tb < opts.skip_below && gb < opts.skip_below {
        let message = format!(
            "refinement skipped: the derivative fit already simulates at NRMSE {tb:.1e} (fit runs) / {gb:.1e} (gate runs), below {:.0e}",
            opts.skip_below
        );
        return Ok(Gated::unchanged(model, train_before, gate_before, message));
    }
    // A start that diverges in free run on the fit runs, or does not follow the output at all
    // (NRMSE above 1: worse than its mean), is not refined in full: its shooting segments blow
    // up too, or dozens of spurious terms must be walked back (with finite-difference Jacobians
    // one 35-term candidate of the noise-free throttle search took 90 s). Its linear part is
    // the start instead ([`lower_degree_start`]).
    let follows = tb <= 1.0;
    let first = if follows || up_to_degree(model, 1).is_none() {
        refine(model, fit, opts)
    } else {
        Err(Error::Numerical(format!(
            "the derivative fit does not follow the output in free run (NRMSE {tb:.3})"
        )))
    };
    let fallback = matches!(first, Err(Error::Numerical(_)))
        .then(|| lower_degree_start(model, fit, opts, follows || opts.every_lower_start))
        .flatten();
    let (first, start_note) = match fallback {
        Some((r, note)) => (Ok(r), note),
        None => (first, String::new()),
    };
    let refined = match first {
        Ok(r) => r,
        Err(e @ Error::Numerical(_)) => {
            let message = format!("refinement not applied: {e}");
            return Ok(Gated::unchanged(model, train_before, gate_before, message));
        }
        Err(e) => return Err(e),
    };
    let train_after = free_run_nrmse(&refined.model, fit)?;
    let gate_after = free_run_nrmse(&refined.model, gate)?;
    let (b, a) = (overall(&gate_before), overall(&gate_after));
    let kept = a < b;
    let message = if kept {
        format!(
            "refinement kept: free-run NRMSE on the gate runs {} -> {}{start_note}",
            num4(b),
            num4(a)
        )
    } else {
        format!(
            "refinement refused: free-run NRMSE on the gate runs {} -> {} is not lower{start_note}",
            num4(b),
            num4(a)
        )
    };
    Ok(Gated {
        model: if kept {
            refined.model.clone()
        } else {
            model.clone()
        },
        kept,
        train_before,
        train_after,
        gate_before,
        gate_after,
        refined: Some(refined),
        message,
    })
}
