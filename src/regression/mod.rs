//! Sparse polynomial regression: find the few monomials of degree <= d that explain a label.
//!
//! ```no_run
//! use ctsid::regression::{Regression, Method};
//! # fn main() -> ctsid::Result<()> {
//! # let features = ctsid::engine::Features::new(vec!["u".into(), "y".into()], vec![vec![0.0; 10], vec![1.0; 10]])?;
//! # let label = vec![0.0; 10];
//! let model = Regression::builder().degree(3).method(Method::LassoLars).max_terms(20).build()?
//!     .fit(&features, &label, "y_d1", None)?;
//! println!("{}", model.equation());
//! # Ok(()) }
//! ```
//!
//! What happens in a fit:
//! 1. [`path::lars_path`] runs LARS or LassoLars over all candidates through a
//!    [`SweepEngine`] (standardised candidates, intercept by centring; see that module).
//! 2. [`select`] picks the path support with the lowest extended BIC on an OLS refit, refits it
//!    by least squares in original units and prunes terms backwards while eBIC improves.
//! 3. The [`Model`] holds the chosen terms with coefficients in original units (the constant
//!    monomial, when kept, is the intercept: a term with empty exponents), the path with
//!    coefficients in original units at every breakpoint, and the selection diagnostics.
//!
//! Settings are validated by [`RegressionBuilder::build`] before any data is touched.

// `!(x > t)` is deliberate throughout: NaN must fail these checks.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod cholesky;
pub mod forward;
pub mod path;
pub mod select;

pub use path::{
    lars_path, lars_path_monitored, Breakpoint, Event, Method, Path, PathOptions, StopReason,
};

use crate::basis::{Basis, BasisLimits};
#[cfg(feature = "gpu")]
use crate::engine::gpu::{GpuEngine, GpuOptions};
use crate::engine::select::choose;
#[cfg(feature = "gpu")]
use crate::engine::select::EngineKind;
use crate::engine::{CpuEngine, CpuOptions, Features, Precision, SweepEngine};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub use crate::engine::select::EngineChoice;

/// Largest ratio of the largest to the smallest positive weight [`check_weight_span`] accepts:
/// beyond it the small weights' rows drop below the rounding of the weighted sums (f64 keeps
/// about 16 digits; the column statistics need a few of them for the smaller rows' spread).
pub const MAX_WEIGHT_RATIO: f64 = 1e12;

/// Refuses weights a user gives whose largest and smallest positive values span more than
/// [`MAX_WEIGHT_RATIO`]: beside one weight 1e20 times the others the other rows vanished from
/// the weighted means and norms, every centred column looked constant, and the path returned a
/// wrong model without a word (a weight 1e9 or 1e12 times the others pins its row and fits as
/// it should). For weights from a user (`ctsid regress --weights`), not for the pipeline's own:
/// its robust reweighting takes rows it distrusts down to 1e-14 of the others on purpose.
pub fn check_weight_span(w: &[f64]) -> Result<()> {
    let (lo, hi) = w
        .iter()
        .filter(|&&x| x > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
    if hi / lo > MAX_WEIGHT_RATIO {
        return Err(Error::param(
            "weights",
            format!(
                "they span {} (largest {}, smallest positive {}), more than the {} f64 sums keep: the small ones vanish beside the large; rescale them or drop rows",
                crate::util::short(hi / lo),
                crate::util::short(hi),
                crate::util::short(lo),
                crate::util::short(MAX_WEIGHT_RATIO)
            ),
        ));
    }
    Ok(())
}

/// Fewest samples a fit accepts: below this, selection among candidates means nothing.
pub const MIN_SAMPLES: usize = 10;

/// The rows of `all` that count as samples under `weights`: those of positive weight, or every
/// row without weights or where the weights are of another length or hold a value that is not
/// finite or is negative (left to the path's own checks). Rows of zero weight are not samples:
/// counted, they let three weighted rows pass [`MIN_SAMPLES`] and fit three terms exactly.
pub fn rows_that_count(weights: Option<&[f64]>, all: usize) -> Vec<usize> {
    match weights.filter(|w| w.len() == all && w.iter().all(|x| x.is_finite() && *x >= 0.0)) {
        Some(w) => (0..all).filter(|&i| w[i] > 0.0).collect(),
        None => (0..all).collect(),
    }
}

/// Unchecked settings; [`RegressionBuilder::build`] validates them into a [`Regression`].
#[derive(Debug, Clone)]

pub struct RegressionBuilder {
    degree: usize,
    method: Method,
    max_terms: usize,
    max_steps: Option<usize>,
    alpha_min: f64,
    epsilon: f64,
    ebic_gamma: f64,
    ebic_patience: Option<usize>,
    effective_samples: Option<f64>,
    prune: bool,
    fit_intercept: bool,
    collinearity_tol: f64,
    refresh_tol: f64,
    rss_floor: f64,
    engine: EngineChoice,
    precision: Option<Precision>,
    max_candidates: u64,
}

impl Default for RegressionBuilder {
    fn default() -> Self {
        let p = PathOptions::default();
        RegressionBuilder {
            degree: 2,
            method: p.method,
            max_terms: p.max_terms,
            max_steps: None,
            alpha_min: p.alpha_min,
            epsilon: p.epsilon,
            ebic_gamma: 1.0,
            ebic_patience: None,
            effective_samples: None,
            prune: true,
            fit_intercept: true,
            collinearity_tol: p.collinearity_tol,
            refresh_tol: p.refresh_tol,
            rss_floor: 1e-10,
            engine: EngineChoice::Auto,
            precision: None,
            max_candidates: BasisLimits::default().max_candidates,
        }
    }
}

macro_rules! setter {
    ($(#[$m:meta])* $name:ident: $t:ty) => {
        $(#[$m])*
        pub fn $name(mut self, v: $t) -> Self {
            self.$name = v;
            self
        }
    };
}

impl RegressionBuilder {
    setter!(/// Largest monomial degree d (1..=12).
        degree: usize);
    setter!(/// LARS or LassoLars (default).
        method: Method);
    setter!(/// Most active terms along the path (default 40).
        max_terms: usize);
    setter!(/// Smallest alpha (scikit-learn's convention) the path goes down to (default 0).
        alpha_min: f64);
    setter!(/// Relevance threshold: the path stops when a new monomial lowers ||r|| / ||y~|| by less (default 0: off).
        epsilon: f64);
    /// Number of independent samples eBIC counts (default: all samples). Residuals of smoothed
    /// signals are correlated over the smoother's window, so they carry fewer independent
    /// samples than rows; counting every row rewards terms that fit the smoother's own error.
    pub fn effective_samples(mut self, n: f64) -> Self {
        self.effective_samples = Some(n);
        self
    }
    setter!(/// eBIC's gamma in [0, 1] (default 1).
        ebic_gamma: f64);
    /// Stop the path once this many breakpoints in a row have not lowered eBIC below the best
    /// so far (0 computes the whole path). Late breakpoints add terms that eBIC charges for, so
    /// past a long run without improvement the choice is settled; on noisy data the path after
    /// the chosen support is most of the path. Default: 40 for LARS and the lasso (their
    /// breakpoints include drops and re-entries), 10 for forward OLS (one new term per
    /// breakpoint, the residual only falls).
    pub fn ebic_patience(mut self, v: usize) -> Self {
        self.ebic_patience = Some(v);
        self
    }
    setter!(/// Backward pruning after the eBIC choice (default on).
        prune: bool);
    setter!(/// Fit an intercept (the constant monomial, reported as a term; default on).
        fit_intercept: bool);
    setter!(/// Smallest Cholesky pivot (unit columns) a candidate needs to enter (default 1e-7).
        collinearity_tol: f64);
    setter!(/// Relative drift of incremental correlations that triggers an exact sweep (default 1e-4).
        refresh_tol: f64);
    setter!(/// Relative residual below which fits count as exact in eBIC (default 1e-10).
        rss_floor: f64);
    setter!(/// Engine: cpu, gpu or auto (default).
        engine: EngineChoice);
    setter!(/// Largest basis accepted (default from [`BasisLimits`]).
        max_candidates: u64);

    /// Most path iterations (default 8 x max_terms + 20).
    pub fn max_steps(mut self, v: usize) -> Self {
        self.max_steps = Some(v);
        self
    }

    /// Arithmetic of the CPU engine's sweeps (default: f32 on the matrix-free engine; the
    /// selection's refits are always exact f64).
    pub fn precision(mut self, p: Precision) -> Self {
        self.precision = Some(p);
        self
    }

    /// Checks every setting; the error names the first bad one. Refuses a degree outside 1..=12, a
    /// `max_terms` or `max_steps` of 0, `effective_samples` below 2 or not finite, an `alpha_min`,
    /// `epsilon` or `rss_floor` that is negative or not finite, an `epsilon` of 1 or more, an
    /// `ebic_gamma` outside [0, 1], a `collinearity_tol` outside (0, 1), a `refresh_tol` that is
    /// not finite and positive, and a `max_candidates` of 0.
    pub fn build(self) -> Result<Regression> {
        crate::basis::check_degree(self.degree)?;
        if self.max_terms == 0 {
            return Err(Error::param("max_terms", "must be at least 1"));
        }
        if let Some(n) = self.effective_samples {
            if !(n >= 2.0 && n.is_finite()) {
                return Err(Error::param(
                    "effective_samples",
                    format!("{n:?}; give a finite number >= 2"),
                ));
            }
        }
        if self.max_steps == Some(0) {
            return Err(Error::param("max_steps", "must be at least 1"));
        }
        use crate::util::finite_nonneg;
        finite_nonneg("alpha_min", self.alpha_min)?;
        finite_nonneg("epsilon", self.epsilon)?;
        finite_nonneg("rss_floor", self.rss_floor)?;
        if !(0.0..=1.0).contains(&self.ebic_gamma) {
            return Err(Error::param(
                "ebic_gamma",
                format!("{} is outside [0, 1]", crate::util::short(self.ebic_gamma)),
            ));
        }
        if !(self.epsilon < 1.0) {
            return Err(Error::param(
                "epsilon",
                format!(
                    "{} would stop before the first term (use a value below 1)",
                    crate::util::short(self.epsilon)
                ),
            ));
        }
        if !(self.collinearity_tol > 0.0 && self.collinearity_tol < 1.0) {
            return Err(Error::param(
                "collinearity_tol",
                format!("{} is outside (0, 1)", self.collinearity_tol),
            ));
        }
        if !(self.refresh_tol > 0.0 && self.refresh_tol.is_finite()) {
            return Err(Error::param(
                "refresh_tol",
                format!("{} must be positive", self.refresh_tol),
            ));
        }
        if self.max_candidates == 0 {
            return Err(Error::param("max_candidates", "must be at least 1"));
        }
        let path = PathOptions {
            method: self.method,
            max_terms: self.max_terms,
            // Saturating: `--max-terms 18446744073709551615` ("no limit") wrapped to 12 steps.
            max_steps: self
                .max_steps
                .unwrap_or(self.max_terms.saturating_mul(8).saturating_add(20)),
            alpha_min: self.alpha_min,
            epsilon: self.epsilon,
            collinearity_tol: self.collinearity_tol,
            refresh_tol: self.refresh_tol,
        };
        Ok(Regression {
            degree: self.degree,
            path,
            ebic_gamma: self.ebic_gamma,
            ebic_patience: self.ebic_patience.unwrap_or(match self.method {
                Method::ForwardOls => 10,
                Method::Lars | Method::LassoLars => 40,
            }),
            effective_samples: self.effective_samples,
            prune: self.prune,
            fit_intercept: self.fit_intercept,
            rss_floor: self.rss_floor,
            engine: self.engine,
            precision: self.precision,
            max_candidates: self.max_candidates,
        })
    }
}

/// Checked regression settings; [`Regression::fit`] runs them on data.
#[derive(Debug, Clone)]
pub struct Regression {
    degree: usize,
    path: PathOptions,
    ebic_gamma: f64,
    ebic_patience: usize,
    effective_samples: Option<f64>,
    prune: bool,
    fit_intercept: bool,
    rss_floor: f64,
    engine: EngineChoice,
    precision: Option<Precision>,
    max_candidates: u64,
}

/// One term of a model.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Term {
    /// Variable name -> exponent (empty for the constant).
    pub exponents: BTreeMap<String, u32>,
    pub coefficient: f64,
    /// Position in the candidate basis (graded-lex order; 0 is the constant).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<usize>,
    /// The monomial as written, e.g. `y_d1^2*u`, or the expression of a named column.
    #[serde(default)]
    pub name: String,
    /// The expression of a named column (`sign(y_d1)`); `None` for a monomial.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expression: Option<String>,
}

/// A named candidate beside the monomials: an expression and its values on the fit's samples
/// (computed by the caller, on the CPU).
#[derive(Debug, Clone)]
pub struct NamedColumn {
    pub name: String,
    pub values: Vec<f64>,
}

/// One breakpoint of the path, in original units.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PathPoint {
    pub alpha: f64,
    /// Active monomials (names) in entering order.
    pub active: Vec<String>,
    pub active_index: Vec<usize>,
    /// Coefficients in original units, aligned with `active`.
    pub coefficients: Vec<f64>,
    pub intercept: f64,
    pub rel_residual: f64,
    /// eBIC of an OLS refit on this support (None: singular refit).
    pub ebic: Option<f64>,
}

/// How the model was chosen.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Diagnostics {
    pub engine: String,
    pub method: Method,
    pub n_samples: usize,
    pub n_candidates: usize,
    pub path_steps: usize,
    pub stop: StopReason,
    pub sweeps: usize,
    pub refreshes: usize,
    /// Candidates with no variation on the data (the constant monomial among them).
    pub constant_candidates: usize,
    /// Candidates refused because they were collinear with the active set.
    pub skipped_collinear: Vec<String>,
    /// Breakpoint whose support had the lowest eBIC.
    pub chosen_breakpoint: usize,
    pub ebic_path_choice: f64,
    /// Terms removed by backward pruning, in order, and the final eBIC.
    pub pruned: Vec<String>,
    pub ebic_final: f64,
    /// Weighted residual sum of squares of the final model and R^2.
    pub rss: f64,
    pub r2: f64,
    pub notes: Vec<String>,
}

/// A fitted sparse polynomial.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Model {
    pub label: String,
    pub features: Vec<String>,
    pub degree: usize,
    pub terms: Vec<Term>,
    pub diagnostics: Diagnostics,
    pub path: Vec<PathPoint>,
}

/// Formats a number with about 6 significant digits, as people write it.
pub fn format_coefficient(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 {
        return "0".into();
    }
    if !(1e-4..1e6).contains(&a) {
        return format!("{x:.5e}");
    }
    let digits = (5 - a.log10().floor() as i32).clamp(0, 10) as usize;
    let s = format!("{x:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

impl Model {
    /// `label = c1*m1 + c2*m2 - ...`, the constant last.
    pub fn equation(&self) -> String {
        let mut parts: Vec<(String, f64)> = self
            .terms
            .iter()
            .filter(|t| !t.exponents.is_empty() || t.expression.is_some())
            .map(|t| (t.name.clone(), t.coefficient))
            .collect();
        if let Some(c) = self
            .terms
            .iter()
            .find(|t| t.exponents.is_empty() && t.expression.is_none())
        {
            parts.push((String::new(), c.coefficient));
        }
        if parts.is_empty() {
            return format!("{} = 0", self.label);
        }
        let mut s = format!("{} =", self.label);
        for (i, (name, c)) in parts.iter().enumerate() {
            let mag = format_coefficient(c.abs());
            let sign = if *c < 0.0 {
                "-"
            } else if i == 0 {
                ""
            } else {
                "+"
            };
            let body = if name.is_empty() {
                mag
            } else {
                format!("{mag}*{name}")
            };
            if i == 0 {
                s.push_str(&format!(" {sign}{body}"));
            } else {
                s.push_str(&format!(" {sign} {body}"));
            }
        }
        s
    }

    /// Evaluates the model on feature rows (by the model's feature names). Refuses features that
    /// fail [`Features::check`], a term whose expression does not parse over the feature names, and
    /// a term in a variable the features lack.
    pub fn predict(&self, features: &Features) -> Result<Vec<f64>> {
        features.check()?;
        let mut out = vec![0.0; features.n_samples];
        for t in &self.terms {
            let mut col = vec![t.coefficient; features.n_samples];
            if let Some(text) = &t.expression {
                let e = crate::model::Expr::parse(text, &features.names)?;
                let mut z = vec![0.0; features.n_vars()];
                for (i, c) in col.iter_mut().enumerate() {
                    for (k, zk) in z.iter_mut().enumerate() {
                        *zk = features.column(k)[i];
                    }
                    *c *= e.eval(&z);
                }
            }
            for (name, e) in &t.exponents {
                let k = features
                    .names
                    .iter()
                    .position(|n| n == name)
                    .ok_or_else(|| {
                        Error::InvalidData(format!(
                            "the model uses '{name}', which the data does not have"
                        ))
                    })?;
                col.iter_mut()
                    .zip(features.column(k))
                    .for_each(|(c, z)| *c *= z.powi(*e as i32));
            }
            out.iter_mut().zip(&col).for_each(|(o, c)| *o += c);
        }
        Ok(out)
    }
}

impl Regression {
    pub fn builder() -> RegressionBuilder {
        RegressionBuilder::default()
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    pub fn path_options(&self) -> &PathOptions {
        &self.path
    }

    /// Builds the basis and the engine chosen by the settings, then fits. Refuses what
    /// [`Regression::fit_with_columns`] refuses.
    pub fn fit(
        &self,
        features: &Features,
        label: &[f64],
        label_name: &str,
        weights: Option<&[f64]>,
    ) -> Result<Model> {
        self.fit_with_columns(features, &[], label, label_name, weights)
    }

    /// [`Regression::fit`] with named candidate columns after the monomials (any engine sweeps
    /// the monomials; the named columns are swept on the CPU beside it, see
    /// [`crate::engine::WithColumns`]). Refuses feature names that [`Basis::new`] refuses (too many
    /// candidates among them), features that fail [`Features::check`], with no samples or with a
    /// value that is not finite, fewer than [`MIN_SAMPLES`] samples, a label of another length or
    /// not finite, weights of another length, negative, not finite or all zero (weights spanning
    /// more than f64's sums keep are the caller's to refuse: [`check_weight_span`]), a named column of
    /// another length or with a value that is not finite, a GPU asked for where there is none, f32 sweeps asked for (GPU or
    /// [`Precision::F32`]) that the label would overflow, and a coefficient beyond f64's range in
    /// the data's units; errs ([`Error::Numerical`]) when the chosen terms are linearly dependent.
    pub fn fit_with_columns(
        &self,
        features: &Features,
        named: &[NamedColumn],
        label: &[f64],
        label_name: &str,
        weights: Option<&[f64]>,
    ) -> Result<Model> {
        let basis = Basis::new(
            &features.names,
            self.degree,
            BasisLimits {
                max_candidates: self.max_candidates,
            },
        )?;
        let notes = Vec::new();
        features.check()?;
        // A named column that is not finite somewhere cannot be fitted; the path set it aside
        // without a word (`--term '0/0'` ran and the heading still counted it).
        for c in named {
            let bad = c.values.iter().filter(|v| !v.is_finite()).count();
            if bad > 0 {
                return Err(Error::param(
                    "term",
                    format!(
                        "'{}' is not finite on {bad} of the fit's {} samples; reformulate it",
                        c.name,
                        c.values.len()
                    ),
                ));
            }
        }
        // Each feature is scaled by a power of two to a largest magnitude near 1 (exact: the
        // products and the path are those of the raw data, without their overflow), and the
        // coefficients are mapped back at the end. Raw features of 1e60 at degree 3 gave
        // monomials whose squares overflow: the cubic term was dropped without a word.
        let pows = power_of_two_scales(features);
        let scaled = scale_features(features, &pows);
        let features = &scaled;
        let mut model =
            self.fit_scaled(&basis, features, named, label, label_name, weights, notes)?;
        unscale(&mut model, &basis, &pows)?;
        Ok(model)
    }

    /// [`Regression::fit_with_columns`] on features already scaled (see there).
    #[allow(clippy::too_many_arguments)]
    fn fit_scaled(
        &self,
        basis: &Basis,
        features: &Features,
        named: &[NamedColumn],
        label: &[f64],
        label_name: &str,
        weights: Option<&[f64]>,
        mut notes: Vec<String>,
    ) -> Result<Model> {
        // f32 sweeps build monomials from the (scaled) features; a label beyond about 1e30
        // overflows them. Such data are swept in f64 on the CPU.
        let largest = (0..features.n_vars())
            .map(|k| {
                features
                    .column(k)
                    .iter()
                    .fold(1.0f64, |m, v| m.max(v.abs()))
            })
            .fold(1.0f64, f64::max);
        let label_scale = label.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let f32_safe = (self.degree as f64) * largest.log10() + label_scale.log10() < 30.0;
        let decision = choose(self.engine, features.n_samples, basis.len())?;
        notes.push(decision.reason.clone());
        if !f32_safe {
            notes.push(format!(
                "a label up to {label_scale:.1e}: sums beyond the f32 range, so the sweeps run in f64 on the CPU"
            ));
        }
        // An explicit request for f32 (the GPU, or CPU f32) is refused rather than overflowed.
        let f32_asked = self.engine == EngineChoice::Gpu || self.precision == Some(Precision::F32);
        if !f32_safe && f32_asked {
            return Err(Error::param(
                "engine",
                format!(
                    "f32 sweeps were asked for (GPU or f32 precision), and a label up to {label_scale:.1e} overflows them; rescale the label or use the CPU engine in f64"
                ),
            ));
        }
        // Without the `gpu` feature there are no adapters, so no decision is Gpu.
        #[cfg(feature = "gpu")]
        if decision.kind == EngineKind::Gpu && f32_safe {
            let attempt =
                GpuEngine::new(features, basis, GpuOptions::default()).and_then(|mut g| {
                    self.fit_candidates(basis, named, &mut g, label, label_name, weights)
                });
            match attempt {
                Ok(mut model) => {
                    model.diagnostics.notes.splice(0..0, notes);
                    return Ok(model);
                }
                // An explicit request for the GPU fails loudly when there is no adapter at all.
                Err(e @ Error::NoGpu(_)) if self.engine == EngineChoice::Gpu => return Err(e),
                Err(e) => {
                    // Kept in the model's notes (the CLI prints them); the library prints nothing.
                    notes.push(format!(
                        "GPU engine failed ({e}); falling back to the CPU engine"
                    ));
                }
            }
        }
        let precision = match self.precision {
            Some(p) => p,
            None if f32_safe => Precision::F32,
            None => Precision::F64,
        };

        let mut engine = CpuEngine::new(
            basis,
            features,
            CpuOptions {
                precision,
                ..CpuOptions::default()
            },
        )?;
        let mut model =
            self.fit_candidates(basis, named, &mut engine, label, label_name, weights)?;
        model.diagnostics.notes.splice(0..0, notes);
        Ok(model)
    }

    /// Fits with a given engine over `basis` (the engine's candidates must be that basis, in
    /// order). Refuses an engine whose number of candidates is not `basis.len()`, and, as
    /// [`Regression::fit_with_columns`] does, fewer than [`MIN_SAMPLES`] samples, a bad label or
    /// bad weights and linearly dependent chosen terms.
    pub fn fit_with_engine(
        &self,
        basis: &Basis,
        engine: &mut dyn SweepEngine,
        label: &[f64],
        label_name: &str,
        weights: Option<&[f64]>,
    ) -> Result<Model> {
        self.fit_candidates(basis, &[], engine, label, label_name, weights)
    }

    /// The fit over the candidates `basis` then `named` (the engine's are the basis).
    fn fit_candidates(
        &self,
        basis: &Basis,
        named: &[NamedColumn],
        engine: &mut dyn SweepEngine,
        label: &[f64],
        label_name: &str,
        weights: Option<&[f64]>,
    ) -> Result<Model> {
        let values: Vec<Vec<f64>> = named.iter().map(|c| c.values.clone()).collect();
        let mut with = crate::engine::WithColumns::new(engine, &values)?;
        let engine: &mut dyn SweepEngine = if named.is_empty() {
            with.into_inner()
        } else {
            &mut with
        };
        let nb = basis.len();
        let name_of = |j: usize| candidate_name(basis, named, j);
        if engine.n_candidates() != basis.len() + named.len() {
            return Err(Error::param(
                "engine",
                format!(
                    "the engine has {} candidates but the basis {}",
                    engine.n_candidates(),
                    basis.len()
                ),
            ));
        }
        // Rows of zero weight are not samples: counted, they let three weighted rows pass the
        // minimum and fit three terms exactly (R^2 1, eBIC at its floor).
        // (Weights of another length or with bad values are left to the path's own checks.)
        let n_rows = rows_that_count(weights, engine.n_samples()).len();
        if n_rows < MIN_SAMPLES {
            return Err(Error::InvalidData(format!(
                "{n_rows} samples{} are too few to select terms (at least {MIN_SAMPLES}); give more data",
                if weights.is_some() { " of positive weight" } else { "" }
            )));
        }
        // eBIC's n: the effective number of independent samples, never more than the rows.
        let n = self
            .effective_samples
            .map_or(n_rows, |e| (e.round() as usize).clamp(2, n_rows.max(2)));
        let p = nb + named.len();
        let mut scorer = select::EbicScorer::new(n, p, self.ebic_gamma, self.rss_floor);
        let patience = self.ebic_patience;
        // A path that enters as many terms as samples interpolates them (R^2 = 1, eBIC -inf):
        // at most half as many terms as samples may enter.
        let options = PathOptions {
            max_terms: self.path.max_terms.min(n_rows / 2),
            ..self.path
        };
        let path = lars_path_monitored(engine, label, weights, &options, &mut |path, b| {
            scorer.score(path, b);
            patience > 0 && scorer.best.is_some_and(|(_, best)| b >= best + patience)
        })?;
        let ebics: Vec<Option<(f64, f64)>> = (0..path.breakpoints.len())
            .map(|b| scorer.score(&path, b))
            .collect();
        let (chosen, ebic_choice) = ebics
            .iter()
            .enumerate()
            .filter_map(|(i, e)| e.map(|(v, _)| (i, v)))
            .fold(
                (0, f64::INFINITY),
                |best, cur| if cur.1 < best.1 { cur } else { best },
            );

        // Final refit in original units on the chosen support (+ the constant).
        let mut support: Vec<usize> = path.breakpoints[chosen].active.clone();
        if self.fit_intercept {
            support.insert(0, 0);
        }
        let (ls, score, pruned) =
            self.refit_pruned(engine, &mut support, (label, &path), (n, p), &name_of)?;

        let names = basis.names();
        let mut terms: Vec<Term> = support
            .iter()
            .zip(&ls.coef)
            .map(|(&id, &c)| term_of(basis, id, c, &name_of))
            .collect();
        terms.sort_by_key(|t| t.index);

        let path_points = path_points(&path, &ebics, &name_of);

        let yy: f64 = path.y_norm * path.y_norm;
        let diagnostics = Diagnostics {
            engine: engine.describe(),
            method: self.path.method,
            n_samples: n,
            n_candidates: p,
            path_steps: path.breakpoints.len().saturating_sub(1),
            stop: path.stop,
            sweeps: path.sweeps,
            refreshes: path.refreshes,
            constant_candidates: path.constant_candidates.len(),
            skipped_collinear: path
                .events
                .iter()
                .filter_map(|e| {
                    if let Event::SkippedCollinear { candidate, .. } = e {
                        Some(name_of(*candidate))
                    } else {
                        None
                    }
                })
                .collect(),
            chosen_breakpoint: chosen,
            ebic_path_choice: ebic_choice,
            pruned,
            ebic_final: score,
            rss: ls.rss,
            r2: if yy > 0.0 { 1.0 - ls.rss / yy } else { 1.0 },
            notes: Vec::new(),
        };
        Ok(Model {
            label: label_name.to_string(),
            features: names.to_vec(),
            degree: basis.degree(),
            terms,
            diagnostics,
            path: path_points,
        })
    }

    /// Least squares on `support` in the label's units (weighted), then, with pruning on, the
    /// term whose removal lowers eBIC most removed while one does: the fit, its eBIC and the
    /// names of the removed terms.
    #[allow(clippy::type_complexity)]
    fn refit_pruned(
        &self,
        engine: &mut dyn SweepEngine,
        support: &mut Vec<usize>,
        (label, path): (&[f64], &Path),
        (n, p): (usize, usize),
        name_of: &dyn Fn(usize) -> String,
    ) -> Result<(select::LeastSquares, f64, Vec<String>)> {
        let sw = &path.sqrt_w;
        let y_w: Vec<f64> = label.iter().zip(sw).map(|(y, s)| y * s).collect();
        let floor = (self.rss_floor * path.y_norm).powi(2);
        let mut pruned = Vec::new();
        let mut cols: Vec<Vec<f64>> = engine
            .columns(support)?
            .into_iter()
            .map(|c| c.iter().zip(sw).map(|(x, s)| x * s).collect())
            .collect();
        let mut ls = select::least_squares(&cols, &y_w)?;
        let mut score = select::ebic(n, ls.rss, support.len(), p, self.ebic_gamma, floor);
        while self.prune && !support.is_empty() {
            let k = support.len();
            let best = (0..k)
                .map(|t| {
                    (
                        t,
                        select::ebic(
                            n,
                            ls.rss + ls.removal_cost[t],
                            k - 1,
                            p,
                            self.ebic_gamma,
                            floor,
                        ),
                    )
                })
                .fold(
                    (usize::MAX, f64::INFINITY),
                    |b, c| if c.1 < b.1 { c } else { b },
                );
            if best.0 == usize::MAX || best.1 >= score {
                break;
            }
            let id = support.remove(best.0);
            cols.remove(best.0);
            pruned.push(name_of(id));
            ls = select::least_squares(&cols, &y_w)?;
            score = select::ebic(n, ls.rss, support.len(), p, self.ebic_gamma, floor);
        }
        Ok((ls, score, pruned))
    }
}

/// Per feature, the power of two `p` with `2^p` nearest its largest magnitude (0 for a column
/// of zeros).
fn power_of_two_scales(f: &Features) -> Vec<i32> {
    (0..f.n_vars())
        .map(|k| {
            let m = f.column(k).iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if m > 0.0 && m.is_finite() {
                m.log2().round() as i32
            } else {
                0
            }
        })
        .collect()
}

/// The features divided by `2^pows[k]`: exact, as long as no value leaves the normal range.
fn scale_features(f: &Features, pows: &[i32]) -> Features {
    let mut out = f.clone();
    for (k, &p) in pows.iter().enumerate() {
        let col = &mut out.data[k * f.n_samples..(k + 1) * f.n_samples];
        col.iter_mut()
            .for_each(|v| *v = times_pow2(*v, -(p as i64)));
    }
    out
}

/// x 2^p, in steps that neither overflow nor underflow on the way.
fn times_pow2(x: f64, p: i64) -> f64 {
    let (mut x, mut p) = (x, p);
    while p != 0 {
        let step = p.clamp(-1000, 1000);
        x *= 2f64.powi(step as i32);
        p -= step;
    }
    x
}

/// Maps coefficients fitted on scaled features back to the data's units: a monomial's
/// coefficient times `2^-(sum_k e_k p_k)`. A coefficient that leaves f64's normal range on the
/// way is an error naming the term (the model cannot be written in those units), never a 0.
fn unscale(model: &mut Model, basis: &Basis, pows: &[i32]) -> Result<()> {
    if pows.iter().all(|&p| p == 0) {
        return Ok(());
    }
    let nb = basis.len();
    let shift = |id: usize| -> i64 {
        basis
            .code(id)
            .exponents(pows.len())
            .iter()
            .zip(pows)
            .map(|(&e, &p)| e as i64 * p as i64)
            .sum()
    };
    // A candidate's coefficient in the data's units (a named column, past the basis, as it is).
    let scaled = |c: f64, id: usize| -> f64 {
        if id < nb {
            times_pow2(c, -shift(id))
        } else {
            c
        }
    };
    let map = |c: f64, id: usize, name: &str| -> Result<f64> {
        let v = scaled(c, id);
        if id < nb && c != 0.0 && !(v.is_finite() && v.abs() >= f64::MIN_POSITIVE) {
            return Err(Error::InvalidData(format!(
                "the coefficient of {name} in the data's units ({c:e} x 2^{}) is beyond the range of f64; rescale its variables (e.g. to other units)",
                -shift(id)
            )));
        }
        Ok(v)
    };
    for t in &mut model.terms {
        if let Some(id) = t.index {
            t.coefficient = map(t.coefficient, id, &t.name)?;
        }
    }
    // The path's breakpoints are diagnostics: one the selection did not choose may hold a term
    // whose coefficient leaves f64 in the data's units (x^6 of features near 1e60), which must
    // not refuse the fit; such a value is written at the end of the range with its sign.
    for bp in &mut model.path {
        for (c, &id) in bp.coefficients.iter_mut().zip(&bp.active_index) {
            let v = scaled(*c, id);
            *c = if v.is_finite() {
                v
            } else {
                f64::MAX.copysign(*c)
            };
        }
    }
    Ok(())
}

/// The name of candidate `j`: a monomial of `basis`, or a named column after them.
fn candidate_name(basis: &Basis, named: &[NamedColumn], j: usize) -> String {
    if j < basis.len() {
        basis.name(j)
    } else {
        named[j - basis.len()].name.clone()
    }
}

/// Candidate `id` with coefficient `c` as a model term (a named column keeps its expression).
fn term_of(basis: &Basis, id: usize, c: f64, name_of: &dyn Fn(usize) -> String) -> Term {
    if id >= basis.len() {
        return Term {
            exponents: BTreeMap::new(),
            coefficient: c,
            index: Some(id),
            name: name_of(id),
            expression: Some(name_of(id)),
        };
    }
    let names = basis.names();
    let e = basis.code(id).exponents(names.len());
    Term {
        exponents: e
            .iter()
            .enumerate()
            .filter(|(_, k)| **k > 0)
            .map(|(v, k)| (names[v].clone(), *k))
            .collect(),
        coefficient: c,
        index: Some(id),
        name: basis.name(id),
        expression: None,
    }
}

/// The path's breakpoints in original units, each with its eBIC.
fn path_points(
    path: &Path,
    ebics: &[Option<(f64, f64)>],
    name_of: &dyn Fn(usize) -> String,
) -> Vec<PathPoint> {
    let st = &path.store;
    path.breakpoints
        .iter()
        .zip(ebics)
        .map(|(bp, e)| {
            let mut intercept = path.y_mean;
            let coefficients: Vec<f64> = bp
                .active
                .iter()
                .zip(&bp.coefs)
                .map(|(id, c)| {
                    let q = st.position(*id).expect("stored");
                    let b = c / st.norm[q];
                    intercept -= b * st.mean[q];
                    b
                })
                .collect();
            PathPoint {
                alpha: bp.alpha,
                active: bp.active.iter().map(|j| name_of(*j)).collect(),
                active_index: bp.active.clone(),
                coefficients,
                intercept,
                rel_residual: bp.rel_residual,
                ebic: e.map(|v| v.0),
            }
        })
        .collect()
}
