//! The LARS / LassoLars path, written once against [`SweepEngine`].
//!
//! # Conventions
//! - Candidates are standardised for selection: with weights w (unit weights when none) and
//!   `s_i = sqrt(w_i)`, candidate j becomes `x~_j = s * (x_j - m_j) / n_j` with the weighted mean
//!   `m_j` and centred norm `n_j` from [`SweepEngine::column_stats`]; the label becomes
//!   `y~ = s * (y - m_y)`. Centring is how the intercept is handled: it is always in the model
//!   during the path, and the constant monomial (zero centred norm) is never a path candidate.
//!   Columns whose centred norm is below 1e-8 of their root mean square are constant and excluded.
//! - Correlations are `c_j = x~_j^T r`; `alpha = max_j |c_j| / n_samples`, as in scikit-learn.
//! - The step logic follows scikit-learn's `lars_path` exactly (same entering order, same
//!   breakpoints), including its LAR quirk: when a coefficient would cross zero inside a LAR step,
//!   its sign in the equiangular system flips and the next iteration adds no variable.
//! - All active-set algebra is f64: exact columns of the active candidates (from
//!   [`SweepEngine::columns`]), an incremental Cholesky factor with deletions.
//! - Correlations are updated incrementally (`c -= gamma * a`, one sweep per step for `a`).
//!   Each time a candidate enters, its exact correlation is computed from its f64 column; when the
//!   incremental value differs by more than `refresh_tol` (relative), all correlations are
//!   recomputed with one exact sweep of the residual before the step goes on.
//! - Sweeps decide, exact columns measure: the swept correlations pick the entering candidate
//!   and the candidate that limits the step, but C (hence alpha) and that candidate's
//!   correlation and direction product (hence gamma and the coefficients) are recomputed from
//!   its exact f64 column. An f32 engine (GPU, or CPU in f32) then gives the f64 engine's
//!   breakpoints to rounding whenever it makes the same choices (tests/gpu_lars.rs).
//! - A candidate whose entry would make the active Gram matrix singular (Cholesky pivot below
//!   `collinearity_tol`, i.e. its distance to the span of the active columns, in unit norm) is
//!   skipped for the rest of the path and reported; nothing becomes NaN.

// `!(x > t)` is deliberate throughout: NaN must fail these checks.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use super::cholesky::Cholesky;
use crate::engine::SweepEngine;
use crate::error::{Error, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Plain LARS or the lasso modification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Lars,
    #[default]
    LassoLars,
    /// Forward selection by orthogonal least squares ([`super::forward`]).
    #[serde(rename = "forward_ols")]
    ForwardOls,
}

/// Why the path ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// alpha reached `alpha_min` (or every usable candidate is active).
    AlphaMin,
    MaxTerms,
    MaxSteps,
    /// The last monomial reduced the relative residual by less than epsilon.
    Relevance,
    /// The residual vanished (relative norm below 1e-12): an exact fit.
    ExactFit,
    /// As many active terms as samples minus one.
    SampleLimit,
    /// LassoLars: alpha increased, a sign of accumulated rounding (scikit-learn stops too).
    AlphaIncreasing,
    /// The label is constant: nothing to explain.
    ConstantLabel,
    /// The caller's monitor stopped the path (model selection saw no further improvement).
    NoImprovement,
}

/// Settings of one path.
#[derive(Debug, Clone, Copy)]
pub struct PathOptions {
    pub method: Method,
    pub max_terms: usize,
    pub max_steps: usize,
    pub alpha_min: f64,
    /// Relevance threshold epsilon (see [`StopReason::Relevance`]); 0 disables it.
    pub epsilon: f64,
    pub collinearity_tol: f64,
    pub refresh_tol: f64,
}

impl Default for PathOptions {
    fn default() -> Self {
        PathOptions {
            method: Method::LassoLars,
            max_terms: 40,
            max_steps: 500,
            alpha_min: 0.0,
            epsilon: 0.0,
            collinearity_tol: 1e-7,
            refresh_tol: 1e-4,
        }
    }
}

/// One breakpoint of the path: alpha and the active coefficients (standardised units).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Breakpoint {
    pub alpha: f64,
    /// Active candidates, in the order they entered.
    pub active: Vec<usize>,
    /// Standardised coefficients, aligned with `active`.
    pub coefs: Vec<f64>,
    /// ||r|| / ||y~|| at this breakpoint.
    pub rel_residual: f64,
}

/// What happened along the path, for reports.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    Added {
        step: usize,
        candidate: usize,
    },
    Dropped {
        step: usize,
        candidate: usize,
    },
    /// Entry refused: the candidate is (numerically) a combination of the active ones.
    SkippedCollinear {
        step: usize,
        candidate: usize,
        pivot: f64,
    },
    /// The incremental correlations drifted; an exact sweep replaced them.
    Refreshed {
        step: usize,
        drift: f64,
    },
}

/// Exact data of every candidate that was ever active (for refits and selection).
#[derive(Debug, Clone, Default)]
pub struct ColumnStore {
    pub ids: Vec<usize>,
    /// Exact weighted mean and centred norm of each stored column.
    pub mean: Vec<f64>,
    pub norm: Vec<f64>,
    /// Standardised weighted columns x~.
    pub cols: Vec<Vec<f64>>,
    /// x~^T y~.
    pub xty: Vec<f64>,
}

impl ColumnStore {
    /// `None` when `id` was never stored.
    pub fn position(&self, id: usize) -> Option<usize> {
        self.ids.iter().position(|&j| j == id)
    }

    /// Stores candidate `id` (exact weighted mean `m` and centred norm `s`, standardised column
    /// `xt`) unless it is stored already.
    pub(super) fn add(&mut self, id: usize, m: f64, s: f64, xt: &[f64], y_tilde: &[f64]) {
        if self.position(id).is_none() {
            self.ids.push(id);
            self.mean.push(m);
            self.norm.push(s);
            self.xty.push(dot(xt, y_tilde));
            self.cols.push(xt.to_vec());
        }
    }
}

/// A computed path and everything the selection needs.
#[derive(Debug, Clone)]
pub struct Path {
    pub method: Method,
    pub breakpoints: Vec<Breakpoint>,
    pub events: Vec<Event>,
    pub stop: StopReason,
    pub sweeps: usize,
    pub refreshes: usize,
    /// Candidates excluded from the start because they are constant (the constant monomial included).
    pub constant_candidates: Vec<usize>,
    pub store: ColumnStore,
    /// Weighted label mean and ||y~||.
    pub y_mean: f64,
    pub y_norm: f64,
    pub sqrt_w: Vec<f64>,
    pub y_tilde: Vec<f64>,
    pub n_usable: usize,
}

impl Path {
    /// Candidates in the order they first entered.
    pub fn entering_order(&self) -> Vec<usize> {
        let mut seen = Vec::new();
        for e in &self.events {
            if let Event::Added { candidate, .. } = e {
                if !seen.contains(candidate) {
                    seen.push(*candidate);
                }
            }
        }
        seen
    }
}

const TINY32: f64 = 1.1754943508222875e-38;
const EQ_TOL: f64 = f64::EPSILON;

fn min_pos(it: impl Iterator<Item = f64>) -> f64 {
    it.filter(|x| *x > 0.0).fold(f64::MAX, f64::min)
}

/// `a . b` over eight partial sums: a single running sum is a dependency chain the compiler
/// may not reorder. The path's dot products over the active columns (k x n per step) and
/// `u = X_A w` are most of its non-sweep time (0.7 s of a 4.2 s 200-step path at 25,000 x
/// 12,376, `benches/cpu_report.sh`).
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut part = [0.0f64; 8];
    let (ac, bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ac
        .remainder()
        .iter()
        .zip(bc.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ac.zip(bc) {
        for l in 0..8 {
            part[l] += x[l] * y[l];
        }
    }
    part.iter().sum::<f64>() + tail
}

pub(super) struct Standardiser<'a> {
    pub(super) engine: &'a mut dyn SweepEngine,
    mean: Vec<f64>,
    norm: Vec<f64>,
    pub(super) usable: Vec<bool>,
    /// Sample weights, their sum and their square roots.
    w: Vec<f64>,
    sw: f64,
    sqrt_w: Vec<f64>,
    raw: Vec<f64>,
    scaled: Vec<f64>,
    pub(super) sweeps: usize,
}

impl Standardiser<'_> {
    /// Candidate j's column standardised exactly in f64, `x~ = sqrt(w) (x - m) / s` with its
    /// weighted mean m and centred norm s (zeros when the column is constant), and m and s.
    pub(super) fn exact_column(&mut self, j: usize) -> Result<(Vec<f64>, f64, f64)> {
        let col = self.engine.columns(&[j])?.pop().expect("one column");
        let m = self.w.iter().zip(&col).map(|(a, b)| a * b).sum::<f64>() / self.sw;
        let s = self
            .w
            .iter()
            .zip(&col)
            .map(|(a, b)| a * (b - m) * (b - m))
            .sum::<f64>()
            .sqrt();
        if !(s > 0.0) {
            return Ok((vec![0.0; col.len()], m, s));
        }
        let xt = col
            .iter()
            .zip(&self.sqrt_w)
            .map(|(x, q)| q * (x - m) / s)
            .collect();
        Ok((xt, m, s))
    }

    /// c_j = x~_j^T u for every candidate (0 for unusable ones).
    pub(super) fn corr(&mut self, u: &[f64], out: &mut [f64]) -> Result<()> {
        for ((s, w), x) in self.scaled.iter_mut().zip(&self.sqrt_w).zip(u) {
            *s = w * x;
        }
        let total: f64 = self.scaled.iter().sum();
        self.engine.sweep(&self.scaled, &mut self.raw)?;
        self.sweeps += 1;
        for j in 0..out.len() {
            out[j] = if self.usable[j] {
                (self.raw[j] - self.mean[j] * total) / self.norm[j]
            } else {
                0.0
            };
        }
        Ok(())
    }
}

/// What every path starts from: the standardiser over the engine, an empty path with the
/// weighted, centred label, the weights and their sum.
pub(super) struct Begun<'a> {
    pub(super) sd: Standardiser<'a>,
    pub(super) path: Path,
    pub(super) y_tilde: Vec<f64>,
}

/// The path of a constant label: one empty breakpoint, nothing to explain.
fn constant_label(mut path: Path) -> Path {
    path.breakpoints.push(Breakpoint {
        alpha: 0.0,
        active: vec![],
        coefs: vec![],
        rel_residual: 0.0,
    });
    path.stop = StopReason::ConstantLabel;
    path
}

/// Checks the label, takes the column statistics and sets up the standardisation (see the
/// module docs) for a path of `method`; a constant label gets its finished path instead.
fn begin<'a>(
    engine: &'a mut dyn SweepEngine,
    y: &[f64],
    weights: Option<&[f64]>,
    method: Method,
) -> Result<std::result::Result<Begun<'a>, Path>> {
    let n = engine.n_samples();
    let nc = engine.n_candidates();
    if y.len() != n {
        return Err(Error::param(
            "label",
            format!("{} values for {n} samples", y.len()),
        ));
    }
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidData(format!(
            "the label is not finite at sample {i}"
        )));
    }
    // Weights matter only relative to each other: scaled to mean 1, so that neither the path's
    // tolerances nor an f32 engine see their units (uniform weights of 1e-30 once lost a term,
    // 1e-200 every term).
    let w: Vec<f64> = match weights {
        Some(w) => {
            // By the largest first: a sum of weights near 1e308 would overflow.
            let max = w.iter().fold(0.0f64, |m, x| m.max(*x));
            let w: Vec<f64> = if max.is_finite() && max > 0.0 {
                w.iter().map(|x| x / max).collect()
            } else {
                w.to_vec()
            };
            let mean = w.iter().sum::<f64>() / n.max(1) as f64;
            if mean.is_finite() && mean > 0.0 {
                w.iter().map(|x| x / mean).collect()
            } else {
                w
            }
        }
        None => vec![1.0; n],
    };
    let stats = engine.column_stats(weights.map(|_| w.as_slice()))?;
    let sw: f64 = w.iter().sum();
    let sqrt_w: Vec<f64> = w.iter().map(|x| x.sqrt()).collect();
    let y_mean = w.iter().zip(y).map(|(a, b)| a * b).sum::<f64>() / sw;
    let y_tilde: Vec<f64> = y
        .iter()
        .zip(&sqrt_w)
        .map(|(v, s)| s * (v - y_mean))
        .collect();
    let y_norm = dot(&y_tilde, &y_tilde).sqrt();

    let mut usable = vec![false; nc];
    let mut constant_candidates = Vec::new();
    for j in 0..nc {
        let (m, s) = (stats.mean[j], stats.norm[j]);
        let rms = (s * s + sw * m * m).sqrt();
        usable[j] = s.is_finite() && m.is_finite() && s > 1e-8 * rms && s > 0.0;
        if !usable[j] {
            constant_candidates.push(j);
        }
    }
    let n_usable = usable.iter().filter(|u| **u).count();
    let sd = Standardiser {
        engine,
        mean: stats.mean,
        norm: stats.norm,
        usable,
        w,
        sw,
        sqrt_w: sqrt_w.clone(),
        raw: vec![0.0; nc],
        scaled: vec![0.0; n],
        sweeps: 0,
    };

    let path = Path {
        method,
        breakpoints: Vec::new(),
        events: Vec::new(),
        stop: StopReason::AlphaMin,
        sweeps: 0,
        refreshes: 0,
        constant_candidates,
        store: ColumnStore::default(),
        y_mean,
        y_norm,
        sqrt_w,
        y_tilde: y_tilde.clone(),
        n_usable,
    };
    if !(path.y_norm > 0.0) {
        return Ok(Err(constant_label(path)));
    }
    Ok(Ok(Begun { sd, path, y_tilde }))
}

/// Computes the path of `y` over every candidate of `engine` (see the module docs). Refuses an
/// `alpha_min` that is negative or not finite, a `max_terms` of 0, a label whose length is not the
/// engine's sample count or that is not finite, and weights of another length, negative, not finite
/// or all zero; errs ([`Error::Numerical`]) when the active system becomes singular, and with
/// whatever error the engine gives.
pub fn lars_path(
    engine: &mut dyn SweepEngine,
    y: &[f64],
    weights: Option<&[f64]>,
    opts: &PathOptions,
) -> Result<Path> {
    lars_path_monitored(engine, y, weights, opts, &mut |_, _| false)
}

/// [`lars_path`] with a monitor called with the path and the index of each new breakpoint
/// (its support is final when it is called); returning `true` stops the path there with
/// [`StopReason::NoImprovement`]. Model selection uses it to stop computing breakpoints it
/// can no longer choose. Refuses what [`lars_path`] refuses.
pub fn lars_path_monitored(
    engine: &mut dyn SweepEngine,
    y: &[f64],
    weights: Option<&[f64]>,
    opts: &PathOptions,
    monitor: &mut dyn FnMut(&Path, usize) -> bool,
) -> Result<Path> {
    // The builder checks these; a PathOptions built by hand is checked here.
    if !(opts.alpha_min >= 0.0 && opts.alpha_min.is_finite()) || opts.max_terms == 0 {
        return Err(Error::param(
            "path options",
            "alpha_min must be a finite number >= 0 and max_terms at least 1",
        ));
    }
    let begun = match begin(engine, y, weights, opts.method)? {
        Ok(b) => b,
        Err(done) => return Ok(done),
    };
    match opts.method {
        Method::ForwardOls => super::forward::forward_path(begun, opts, monitor),
        Method::Lars | Method::LassoLars => lars_steps(begun, opts, monitor),
    }
}

/// The LARS / LassoLars steps from a started path (see the module docs): each step takes the
/// candidate of largest correlation into the active set ([`Lars::enter`]), moves along the
/// equiangular direction ([`Lars::direction`]) until an inactive candidate catches up or, for
/// the lasso, a coefficient crosses zero ([`Lars::step_bound`], [`Lars::advance`]), and records
/// a breakpoint; [`Lars::stop`] says when the path ends.
fn lars_steps(
    begun: Begun,
    opts: &PathOptions,
    monitor: &mut dyn FnMut(&Path, usize) -> bool,
) -> Result<Path> {
    let mut s = Lars::new(begun, *opts)?;
    let mut last_idx;
    loop {
        let (c_idx, big) = s.entering();
        last_idx = c_idx;
        let mut c = if c_idx == usize::MAX { 0.0 } else { big };
        s.record_breakpoint(c / s.n as f64);
        if let Some(reason) = s.stop(c / s.n as f64, monitor) {
            s.path.stop = reason;
            break;
        }
        let mut added = false;
        if !s.drop {
            match s.enter(c_idx)? {
                Entry::Retry => continue,
                Entry::Added(exact) => {
                    c = exact;
                    added = true;
                }
            }
        }
        s.refreshed_this_iter = false;
        let alpha = c / s.n as f64;
        if s.lasso && s.n_iter > 0 && s.prev_alpha < alpha {
            s.path.stop = StopReason::AlphaIncreasing;
            break;
        }
        let (ls, aa) = s.direction()?;
        let gamma = s.step_bound(c, aa)?;
        s.advance(gamma, &ls, alpha, added);
    }
    s.finish(last_idx)
}

/// What [`Lars::enter`] did with the candidate of largest correlation.
enum Entry {
    /// Taken into the active set; its exact |correlation| (the step's C).
    Added(f64),
    /// Skipped (collinear, or no spread) or the correlations refreshed: look again.
    Retry,
}

/// The state of a LARS / LassoLars path between steps, in standardised units: the correlations
/// `cov` of every candidate with the residual `r`, the active set with its columns `xa`,
/// coefficients, signs and the Cholesky factor of its Gram matrix, and the last step's
/// equiangular vector `u` and its correlations `a`.
struct Lars<'a> {
    sd: Standardiser<'a>,
    path: Path,
    y_tilde: Vec<f64>,
    opts: PathOptions,
    n: usize,
    /// scikit-learn's equality tolerance is the absolute f64 epsilon, which ends the path of a
    /// label of 1e-15 before it starts; here it is relative to alpha's scale (alpha <= ||y~|| / n).
    eq_tol: f64,
    lasso: bool,
    cov: Vec<f64>,
    r: Vec<f64>,
    in_active: Vec<bool>,
    skipped: Vec<bool>,
    active: Vec<usize>,
    xa: Vec<Vec<f64>>,
    coef: Vec<f64>,
    sign: Vec<f64>,
    chol: Cholesky,
    n_iter: usize,
    /// The last step ended at a lasso zero crossing (nothing enters at the next).
    drop: bool,
    /// The active set and coefficients at the end of the last step (the next breakpoint's).
    pending: (Vec<usize>, Vec<f64>),
    a: Vec<f64>,
    u: Vec<f64>,
    refreshed_this_iter: bool,
    stop_next: Option<StopReason>,
    prev_alpha: f64,
    rel_res_at_last_bp: f64,
}

impl<'a> Lars<'a> {
    fn new(begun: Begun<'a>, opts: PathOptions) -> Result<Lars<'a>> {
        let Begun {
            mut sd,
            path,
            y_tilde,
        } = begun;
        let (n, nc) = (y_tilde.len(), sd.usable.len());
        let mut cov = vec![0.0; nc];
        sd.corr(&y_tilde, &mut cov)?;
        Ok(Lars {
            eq_tol: EQ_TOL * path.y_norm / n as f64,
            lasso: opts.method == Method::LassoLars,
            r: y_tilde.clone(),
            sd,
            path,
            y_tilde,
            opts,
            n,
            cov,
            in_active: vec![false; nc],
            skipped: vec![false; nc],
            active: Vec::new(),
            xa: Vec::new(),
            coef: Vec::new(),
            sign: Vec::new(),
            chol: Cholesky::default(),
            n_iter: 0,
            drop: false,
            pending: (vec![], vec![]),
            a: vec![0.0; nc],
            u: vec![0.0; n],
            refreshed_this_iter: false,
            stop_next: None,
            prev_alpha: f64::INFINITY,
            rel_res_at_last_bp: 1.0,
        })
    }

    fn inactive(&self, j: usize) -> bool {
        self.sd.usable[j] && !self.in_active[j] && !self.skipped[j]
    }

    /// The inactive usable candidate of largest |correlation| and that value (the first one on
    /// ties, like argmax); `usize::MAX` and -1 when there is none.
    fn entering(&self) -> (usize, f64) {
        let mut c_idx = usize::MAX;
        let mut big = -1.0f64;
        for j in 0..self.cov.len() {
            if self.inactive(j) && self.cov[j].abs() > big {
                big = self.cov[j].abs();
                c_idx = j;
            }
        }
        (c_idx, big)
    }

    fn rel_residual(&self) -> f64 {
        dot(&self.r, &self.r).sqrt() / self.path.y_norm
    }

    /// Breakpoint `n_iter`: coefficients from the end of the last step, alpha from now (a retry
    /// of the same step overwrites it).
    fn record_breakpoint(&mut self, alpha: f64) {
        let bp = Breakpoint {
            alpha,
            active: self.pending.0.clone(),
            coefs: self.pending.1.clone(),
            rel_residual: self.rel_residual(),
        };
        if self.path.breakpoints.len() == self.n_iter + 1 {
            self.path.breakpoints[self.n_iter] = bp;
        } else {
            self.path.breakpoints.push(bp);
        }
    }

    /// Why the path ends at the breakpoint just recorded, if it does (at `alpha_min`, the
    /// breakpoint is interpolated back to it).
    fn stop(
        &mut self,
        alpha: f64,
        monitor: &mut dyn FnMut(&Path, usize) -> bool,
    ) -> Option<StopReason> {
        let opts = self.opts;
        if let Some(reason) = self.stop_next {
            return Some(reason);
        }
        if monitor(&self.path, self.n_iter) {
            return Some(StopReason::NoImprovement);
        }
        if alpha <= opts.alpha_min + self.eq_tol {
            if (alpha - opts.alpha_min).abs() > self.eq_tol && self.n_iter > 0 {
                self.interpolate_to_alpha_min(alpha);
            }
            self.path.breakpoints[self.n_iter].alpha = opts.alpha_min;
            return Some(StopReason::AlphaMin);
        }
        if self.n_iter >= opts.max_steps {
            return Some(StopReason::MaxSteps);
        }
        if !self.drop && self.active.len() >= opts.max_terms {
            return Some(StopReason::MaxTerms);
        }
        if !self.drop && self.active.len() + 2 > self.n {
            return Some(StopReason::SampleLimit);
        }
        if self.rel_residual() < 1e-12 {
            return Some(StopReason::ExactFit);
        }
        None
    }

    /// The last breakpoint's coefficients moved back to `alpha_min`, linearly between the last
    /// two breakpoints.
    fn interpolate_to_alpha_min(&mut self, alpha: f64) {
        let prev = self.path.breakpoints[self.n_iter - 1].clone();
        let ss = (prev.alpha - self.opts.alpha_min) / (prev.alpha - alpha);
        let cur = &mut self.path.breakpoints[self.n_iter];
        for (k, id) in cur.active.clone().iter().enumerate() {
            let p = prev
                .active
                .iter()
                .position(|x| x == id)
                .map_or(0.0, |q| prev.coefs[q]);
            cur.coefs[k] = p + ss * (cur.coefs[k] - p);
        }
    }

    /// Takes candidate `c_idx` into the active set from its exact f64 column, unless it has no
    /// spread or is collinear with the active set (skipped for the rest of the path), or its
    /// swept correlation had drifted (every correlation refreshed, once per step).
    fn enter(&mut self, c_idx: usize) -> Result<Entry> {
        let (xt, m, s) = self.sd.exact_column(c_idx)?;
        if !(s > 0.0) || !s.is_finite() {
            self.skip(c_idx, 0.0);
            return Ok(Entry::Retry);
        }
        // Drift check: the exact correlation of the entering candidate against the incremental one.
        let exact = dot(&xt, &self.r);
        let drift = (exact - self.cov[c_idx]).abs() / self.cov[c_idx].abs().max(f64::MIN_POSITIVE);
        if drift > self.opts.refresh_tol && !self.refreshed_this_iter {
            self.sd.corr(&self.r, &mut self.cov)?;
            self.path.refreshes += 1;
            self.path.events.push(Event::Refreshed {
                step: self.n_iter,
                drift,
            });
            self.refreshed_this_iter = true;
            return Ok(Entry::Retry);
        }
        // The breakpoint's alpha and the step's C from the exact f64 column rather than the
        // swept value (which carries the engine's f32 rounding): with f32 sweeps this is what
        // keeps the breakpoints equal to an f64 engine's, not only the entering order.
        self.cov[c_idx] = exact;
        let c = exact.abs();
        self.path.breakpoints[self.n_iter].alpha = c / self.n as f64;
        let g: Vec<f64> = self.xa.par_iter().map(|x| dot(x, &xt)).collect();
        let (wv, pivot) = self.chol.pivot(&g, dot(&xt, &xt));
        let pivot = pivot.max(f64::EPSILON);
        if pivot < self.opts.collinearity_tol {
            self.skip(c_idx, pivot);
            return Ok(Entry::Retry);
        }
        self.chol.append(wv, pivot);
        self.path.store.add(c_idx, m, s, &xt, &self.y_tilde);
        self.xa.push(xt);
        self.active.push(c_idx);
        self.in_active[c_idx] = true;
        self.sign.push(if exact > 0.0 {
            1.0
        } else if exact < 0.0 {
            -1.0
        } else {
            0.0
        });
        self.coef.push(0.0);
        self.path.events.push(Event::Added {
            step: self.n_iter,
            candidate: c_idx,
        });
        Ok(Entry::Added(c))
    }

    fn skip(&mut self, candidate: usize, pivot: f64) {
        self.skipped[candidate] = true;
        self.path.events.push(Event::SkippedCollinear {
            step: self.n_iter,
            candidate,
            pivot,
        });
    }

    /// The equiangular direction: its coefficients `ls` (scaled by A_A) and A_A; sets `u` (the
    /// direction in sample space) and `a` (every candidate's correlation with it).
    fn direction(&mut self) -> Result<(Vec<f64>, f64)> {
        let k = self.active.len();
        let mut ls = self.sign.clone();
        self.chol.solve(&mut ls);
        let s_ls: f64 = ls.iter().zip(&self.sign).map(|(a, b)| a * b).sum();
        let aa = if k == 1 && ls[0] == 0.0 {
            ls[0] = 1.0;
            1.0
        } else {
            1.0 / s_ls.sqrt()
        };
        if !aa.is_finite() {
            return Err(Error::Numerical(format!("the active system became singular at step {} with {k} terms; raise the collinearity tolerance", self.n_iter)));
        }
        ls.iter_mut().for_each(|x| *x *= aa);
        active_combination(&self.xa, &ls, &mut self.u);
        self.sd.corr(&self.u, &mut self.a)?;
        Ok((ls, aa))
    }

    /// The step length along the direction: where the first inactive candidate's correlation
    /// catches up with the active ones' (`c`, falling at rate `aa`), at most to `c / aa`.
    fn step_bound(&mut self, c: f64, aa: f64) -> Result<f64> {
        let (cov, a) = (&self.cov, &self.a);
        let catch_up = |j: usize| (c - cov[j]) / (aa - a[j] + TINY32);
        let catch_down = |j: usize| (c + cov[j]) / (aa + a[j] + TINY32);
        let nc = cov.len();
        let g1 = min_pos((0..nc).filter(|&j| self.inactive(j)).map(catch_up));
        let g2 = min_pos((0..nc).filter(|&j| self.inactive(j)).map(catch_down));
        let g12 = g1.min(g2);
        // The candidate that limits the step: its exact f64 correlation and direction product
        // replace the swept ones, so gamma (hence every coefficient) is exact given that choice.
        let arg = (0..nc)
            .filter(|&j| self.inactive(j))
            .find(|&j| catch_up(j) == g12 || catch_down(j) == g12);
        let g_exact = match arg {
            Some(j) if g12 < c / aa => {
                let (xt, _, _) = self.sd.exact_column(j)?;
                let (cj, aj) = (dot(&xt, &self.r), dot(&xt, &self.u));
                let g = min_pos(
                    [(c - cj) / (aa - aj + TINY32), (c + cj) / (aa + aj + TINY32)].into_iter(),
                );
                if g < f64::MAX {
                    g
                } else {
                    g12
                }
            }
            _ => g12,
        };
        Ok(g_exact.min(c / aa))
    }

    /// Moves `gamma` along the direction (for the lasso, only to the first zero crossing, whose
    /// terms then leave the active set), and ends the step.
    fn advance(&mut self, mut gamma: f64, ls: &[f64], alpha: f64, added: bool) {
        let k = self.active.len();
        let z: Vec<f64> = self
            .coef
            .iter()
            .zip(ls)
            .map(|(cf, l)| -cf / (l + TINY32))
            .collect();
        let z_pos = min_pos(z.iter().copied());
        self.drop = false;
        let mut idx: Vec<usize> = Vec::new();
        if z_pos < gamma {
            idx = (0..k).filter(|&q| z[q] == z_pos).rev().collect();
            for &q in &idx {
                self.sign[q] = -self.sign[q];
            }
            if self.lasso {
                gamma = z_pos;
            }
            self.drop = true;
        }
        self.n_iter += 1;
        self.coef
            .iter_mut()
            .zip(ls)
            .for_each(|(cf, l)| *cf += gamma * l);
        self.cov
            .iter_mut()
            .zip(&self.a)
            .for_each(|(cv, av)| *cv -= gamma * av);
        self.r
            .iter_mut()
            .zip(&self.u)
            .for_each(|(ri, ui)| *ri -= gamma * ui);
        if self.drop && self.lasso {
            for &q in &idx {
                self.remove_active(q);
            }
        }
        self.pending = (self.active.clone(), self.coef.clone());
        self.prev_alpha = alpha;
        let new_rel = self.rel_residual();
        if added && self.opts.epsilon > 0.0 && self.rel_res_at_last_bp - new_rel < self.opts.epsilon
        {
            self.stop_next = Some(StopReason::Relevance);
        }
        self.rel_res_at_last_bp = new_rel;
    }

    /// The lasso drop: active term `q` leaves (its coefficient crossed zero).
    fn remove_active(&mut self, q: usize) {
        self.chol.delete(q);
        let id = self.active.remove(q);
        let col = self.xa.remove(q);
        self.coef.remove(q);
        self.sign.remove(q);
        self.in_active[id] = false;
        self.cov[id] = dot(&col, &self.r);
        self.path.events.push(Event::Dropped {
            step: self.n_iter,
            candidate: id,
        });
    }

    /// The finished path. One that stops before adding the candidate of its last breakpoint
    /// gets that alpha too from the exact column (as every entering breakpoint's), unless the
    /// swept value had drifted.
    fn finish(mut self, last_idx: usize) -> Result<Path> {
        if matches!(
            self.path.stop,
            StopReason::MaxSteps
                | StopReason::MaxTerms
                | StopReason::SampleLimit
                | StopReason::ExactFit
                | StopReason::Relevance
                | StopReason::NoImprovement
        ) && last_idx != usize::MAX
        {
            let exact = dot(&self.sd.exact_column(last_idx)?.0, &self.r);
            let drift = (exact - self.cov[last_idx]).abs()
                / self.cov[last_idx].abs().max(f64::MIN_POSITIVE);
            if drift <= self.opts.refresh_tol {
                if let Some(bp) = self.path.breakpoints.last_mut() {
                    bp.alpha = exact.abs() / self.n as f64;
                }
            }
        }
        self.path.sweeps = self.sd.sweeps;
        Ok(self.path)
    }
}

/// `u = X~_A ls`, parallel over sample chunks (O(n k) per step); four columns per pass over a
/// chunk, a quarter of the loads and stores of `u`.
fn active_combination(xa: &[Vec<f64>], ls: &[f64], u: &mut [f64]) {
    u.par_chunks_mut(4096).enumerate().for_each(|(c, uc)| {
        uc.iter_mut().for_each(|x| *x = 0.0);
        let (off, len) = (c * 4096, uc.len());
        let mut q = 0;
        while q + 4 <= xa.len() {
            let (c0, c1) = (&xa[q][off..off + len], &xa[q + 1][off..off + len]);
            let (c2, c3) = (&xa[q + 2][off..off + len], &xa[q + 3][off..off + len]);
            let (l0, l1, l2, l3) = (ls[q], ls[q + 1], ls[q + 2], ls[q + 3]);
            for i in 0..len {
                uc[i] += l0 * c0[i] + l1 * c1[i] + l2 * c2[i] + l3 * c3[i];
            }
            q += 4;
        }
        for (col, l) in xa[q..].iter().zip(&ls[q..]) {
            uc.iter_mut()
                .zip(&col[off..off + len])
                .for_each(|(ui, xi)| *ui += l * xi);
        }
    });
}
