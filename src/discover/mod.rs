//! The missing-physics workflow (`ctsid discover`): compare a nominal model with measured runs,
//! localise the disagreement, regress the residual on a dictionary of named effects with the
//! nominal terms held under their prior, gate every candidate, and add, retune, or refuse.
//!
//! Steps (issue 6):
//! - (a) compare: free-run NRMSE of the nominal per run (and the part above the noise floor that
//!   the derivative smoother estimates), and the derivative-space residual
//!   `r = y^(n) - P_nominal(z)` from the smoother's estimates;
//! - (b) localise: time windows where the free-run error exceeds three noise levels, and the
//!   share of `var(r)` explained by each coordinate (binned conditional means);
//! - (c) regress in the weak form ([`weak`]) so label and regressors see the same filter, with a
//!   Gaussian prior on each nominal coefficient (default +-20 %) ([`fit`]);
//! - (d) gates: block-bootstrap inclusion >= 80 %, a 95 % bootstrap interval excluding zero
//!   (both per effect: a selected effect that fails them is left out, reported, and the rest
//!   judged without it), >= 10 % less weak-form residual on validation runs and >= 20 % less
//!   free-run error on validation runs than both the nominal and the re-tuned nominal (for the
//!   remaining effects together);
//! - (e) names, formulas and aliases (partial correlation > 0.95 after the nominal columns);
//! - (f) the accepted structure is refined on simulation error (the one refit of
//!   [`crate::identify::refine`], nominal terms the user fixed held) and scored on the test runs,
//!   if any (the library takes an empty test list; `ctsid discover` asks for one), from the one
//!   initial-state convention of [`crate::simulate::initial_state`], as
//!   `ctsid simulate` scores the model file.
//!
//! Every model here, nominal, re-tuned or augmented, is a [`Model`]: effects are its expression
//! terms (`origin: effect`), so the augmented model is written, simulated and controlled like
//! any other.
//!
//! Assumptions: one output (the model file may have several; discover refuses them with an error),
//! uniformly sampled runs, only `y` and the inputs measured; initial states of the free runs are
//! fitted on each run's first samples ([`crate::simulate::initial_state`]).

pub mod benchmarks;
pub mod cases;
pub mod dictionary;

pub mod fit;
mod gates;
pub mod weak;

use std::collections::BTreeMap;

use serde::Serialize;

use crate::derivatives::{differentiate_runs, DerivativeOptions};
use crate::error::{Error, Result};
use crate::identify::refine::{refine_holding, RefineOptions};
use crate::metrics::{nrmse, rms_nrmse};
use crate::model::Expr;
use crate::model::Origin;
use crate::model::{derivative_name, Model, Term};
use crate::plants::noise::percentile;
use crate::records::RecordSet;
use crate::simulate::{free_run, RunData, SimOptions, INIT_WINDOW};
use crate::util::num4;
use dictionary::{num, Effect, Scales};
use fit::{Gram, Problem};
use gates::{Bootstrapped, Refitter, Resampling, Selected};

/// The error of a weak-form fit whose normal equations are singular.
fn singular() -> Error {
    Error::Numerical("discover: the weak-form normal equations are singular".into())
}

/// Settings of one discovery.
#[derive(Debug, Clone)]
pub struct Options {
    pub train: Vec<usize>,
    pub validation: Vec<usize>,
    pub test: Vec<usize>,
    /// Prior half-width per nominal term (by its monomial text, `y_d1`, `1`, `y^2*u`), as a
    /// fraction; 0 fixes the term. Terms not named get `default_confidence`.
    pub confidence: BTreeMap<String, f64>,
    pub default_confidence: f64,
    pub seed: u64,
    pub bootstrap: usize,
    pub max_effects: usize,
    /// User effects: (family name, expression).
    pub user_effects: Vec<(String, String)>,
    /// Weak-form window half-width in samples (default: chosen from the data).
    pub half_width: Option<usize>,
    /// Levenberg-Marquardt iterations of the simulation-error refit.
    pub refine_iterations: usize,
}

impl Options {
    pub fn new(train: Vec<usize>, validation: Vec<usize>, test: Vec<usize>) -> Options {
        Options {
            train,
            validation,
            test,
            confidence: BTreeMap::new(),
            default_confidence: 0.2,
            seed: 0,
            bootstrap: 100,
            max_effects: 2,
            user_effects: Vec::new(),
            half_width: None,
            refine_iterations: 25,
        }
    }
}

/// The gates of one candidate set.
#[derive(Debug, Clone, Serialize)]
pub struct Gates {
    pub inclusion: Vec<f64>,
    pub interval_excludes_zero: Vec<bool>,
    /// Validation weak-form residual, relative to the better of nominal and re-tuned nominal.
    pub residual_ratio: f64,
    /// Validation free-run NRMSE relative to the better of nominal and re-tuned nominal.
    pub simulation_ratio: f64,
    /// The first gate that failed, in words; `None` when all pass.
    pub failed: Option<String>,
}

impl Gates {
    fn of(
        boot: &gates::Bootstrapped,
        residual_ratio: f64,
        simulation_ratio: f64,
        failed: Option<String>,
    ) -> Gates {
        Gates {
            inclusion: boot.inclusion.clone(),
            interval_excludes_zero: boot
                .intervals
                .iter()
                .map(|iv| iv[0] > 0.0 || iv[1] < 0.0)
                .collect(),
            residual_ratio,
            simulation_ratio,
            failed,
        }
    }
}

/// One effect as reported.
#[derive(Debug, Clone, Serialize)]
pub struct FoundEffect {
    pub family: String,
    pub formula: String,
    /// After the simulation-error refit (when the effect is added), else the weak-form estimate.
    pub coefficient: f64,
    /// Weak-form estimate and its 95 % block-bootstrap interval.
    pub weak_coefficient: f64,
    pub interval: [f64; 2],
    pub inclusion: f64,
    pub aliases: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reading: Option<String>,
    /// Time invariance: the coefficient on the first and on the second half of each training
    /// run, and their difference in standard deviations (NaN where too few blocks).
    pub halves: [f64; 2],
    pub halves_z: f64,
    /// With several effects: the share of the validation free-run NRMSE this one removes
    /// (refitted and refined without it, the rest stays).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simulation_share: Option<f64>,
}

/// A nominal parameter change.
#[derive(Debug, Clone, Serialize)]
pub struct Retuned {
    pub term: String,
    pub nominal: f64,
    pub value: f64,
    pub change_percent: f64,
    /// The stated prior half-width of the term, in percent.
    pub confidence_percent: f64,
    /// The change is more than three times the stated half-width: the re-tuned value is not a
    /// correction within what the user claimed to know.
    pub outside_confidence: bool,
}

/// A candidate the gates refused, offered for a second look ([`Discovery::refused`]).
#[derive(Debug, Clone)]
pub struct Refused {
    /// The nominal plus the candidate, last, at its weak-form coefficient.
    pub model: Model,
    /// The simulation gate's ratio (validation free-run NRMSE of the candidate refitted on
    /// simulation error, over the better of nominal and re-tuned nominal), when the candidate
    /// was judged alone; `None` when it was judged in a set or left out before.
    pub simulation_ratio: Option<f64>,
}

/// Coordinate shares of the derivative-space residual.
#[derive(Debug, Clone, Serialize)]
pub struct Share {
    pub coordinate: String,
    pub share: f64,
    /// (bin centre, conditional mean of r)
    pub profile: Vec<(f64, f64)>,
}

/// Per-run free-run comparison.
#[derive(Debug, Clone, Serialize)]
pub struct RunScore {
    pub run: String,
    pub role: String,
    pub nrmse_nominal: f64,
    /// RMS free-run error of the nominal, in the output's units.
    pub rms_nominal: f64,
    pub above_noise: f64,
    pub nrmse_final: Option<f64>,
    /// RMS free-run error of the final model, in the output's units.
    pub rms_final: Option<f64>,
}

/// The result.
#[derive(Debug, Clone, Serialize)]
pub struct Discovery {
    pub verdict: String,
    pub effects: Vec<FoundEffect>,
    pub retuned: Vec<Retuned>,
    /// Why nothing was added, with the closest candidate.
    pub closest: Option<String>,
    /// Effects the forward selection chose that failed their own gates (inclusion or
    /// interval), and were left out before the others were judged.
    pub dropped: Vec<String>,
    pub gates: Option<Gates>,
    pub runs: Vec<RunScore>,
    pub shares: Vec<Share>,
    /// (run, start s, end s) where the nominal's free-run error exceeds three noise levels, in the
    /// record's time (a piece cut by `--segment` keeps its place in the record).
    pub windows: Vec<(String, f64, f64)>,
    /// Mean free-run NRMSE of the test runs with the nominal and the final model (NaN without
    /// test runs).
    pub nrmse_before: f64,
    pub nrmse_after: f64,
    pub half_width: usize,
    /// The final model (nominal terms, re-tuned or refined, plus added effects).
    #[serde(skip)]
    pub final_model: Option<Model>,
    /// When nothing was added: each candidate the gates refused (the closest set's effects and
    /// those left out), as the nominal plus that one effect at its weak-form coefficient, for a
    /// second look on simulation error (`ctsid benchmark`'s rounds).
    #[serde(skip)]
    pub refused: Vec<Refused>,
    #[serde(skip)]
    pub nominal_model: Option<Model>,
    #[serde(skip)]
    pub test_runs: Vec<RunData>,
}

struct Prepared {
    nominal: Model,
    vars: Vec<String>,
    order: usize,
    nom_exprs: Vec<Expr>,
    nom_text: Vec<String>,
    theta0: Vec<f64>,
    free: Vec<usize>,
    effects: Vec<Effect>,
    /// Per run: label residual r and columns [free nominal..., effects...].
    rows: Vec<Rows>,
    /// Per run of the record set, in its order (simulation runs on time since the start).
    simruns: Vec<RunData>,
    zhat: Vec<Vec<Vec<f64>>>,
    top: Vec<Vec<f64>>,
    noise_sd: Vec<f64>,
    eps: Vec<f64>,
    half_width: usize,
}

fn monomial_exponents(t: &Term, vars: &[String]) -> Vec<(usize, u32)> {
    let mut v: Vec<(usize, u32)> = t
        .exponents
        .iter()
        .map(|(n, &e)| (vars.iter().position(|x| x == n).unwrap_or(usize::MAX), e))
        .collect();
    v.sort();
    v
}

/// The checks of [`discover`]'s inputs that need no computation (see its docs): one output of
/// order at least 1, non-empty train and validation lists (test may be empty) that identify's
/// split rules accept, the
/// channels present and varying over the training runs, and confidences only for nominal
/// terms. Returns the record set's channel of the output and of each input.
fn check_setup(rs: &RecordSet, nominal: &Model, o: &Options) -> Result<(usize, Vec<usize>)> {
    nominal.validate()?;
    if nominal.outputs.len() != 1 {
        // The command for the first output with the model's own names (a placeholder `Y2`
        // beside `--output y2` read as the output on both sides).
        let o = nominal.outputs.first().map_or("Y", |q| q.name.as_str());
        let others: Vec<&str> = (nominal.inputs.iter().map(String::as_str))
            .chain(nominal.outputs.iter().skip(1).map(|q| q.name.as_str()))
            .collect();
        return Err(Error::param(
            "nominal",
            format!(
                "has {} outputs; discover handles one output per model: identify the output in question alone, with the outputs it depends on as inputs (for '{o}': `identify --output {o} --input {}`), then discover on that model",
                nominal.outputs.len(),
                others.join(",")
            ),
        ));
    }
    let eq = &nominal.outputs[0];
    let n = eq.order;
    if n == 0 {
        return Err(Error::param("nominal", "output order must be at least 1"));
    }
    if o.train.is_empty() || o.validation.is_empty() {
        return Err(Error::param(
            "split",
            "discover needs at least one train and one validation run",
        ));
    }
    // The same rules as identify's split: indices in range, no run in two lists.
    let ids: Vec<String> = rs.runs.iter().map(|r| r.id.clone()).collect();
    let split = crate::identify::Split::new(
        o.train.clone(),
        Some(o.validation.clone()),
        o.test.clone(),
        &ids,
    )?;
    // Every run is simulated from an initial state fitted on its first samples: a run too short
    // for that fit was called diverged, and the gates then compared inf with inf (exit 0 and
    // a re-tuned model from runs of 13 samples).
    split.require_free_runs(
        rs,
        n,
        &format!(
            "estimating the initial state of output '{}' (order {n}) for its free run",
            eq.name
        ),
    )?;
    let yc = rs.channel_index(&eq.name)?;
    let uc: Vec<usize> = nominal
        .inputs
        .iter()
        .map(|u| rs.channel_index(u))
        .collect::<Result<_>>()?;
    rs.require_varies(yc, &o.train, "output")?;
    for &c in &uc {
        rs.require_varies(c, &o.train, "input")?;
    }
    for name in o.confidence.keys() {
        if !eq.terms.iter().any(|t| t.monomial() == *name) {
            return Err(Error::param(
                "confidence",
                format!(
                    "no nominal term '{name}' (terms are: {})",
                    eq.terms
                        .iter()
                        .map(|t| t.monomial())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    Ok((yc, uc))
}

fn prepare(rs: &RecordSet, nominal: &Model, o: &Options) -> Result<Prepared> {
    let (yc, uc) = check_setup(rs, nominal, o)?;
    let eq = &nominal.outputs[0];
    let n = eq.order;
    let mut vars: Vec<String> = (0..n).map(|k| derivative_name(&eq.name, k)).collect();
    vars.extend(nominal.inputs.iter().cloned());
    let nom_exprs: Vec<Expr> = eq
        .terms
        .iter()
        .map(|t| Expr::parse(&t.monomial(), &vars))
        .collect::<Result<_>>()?;
    let nom_text: Vec<String> = eq.terms.iter().map(|t| t.monomial()).collect();
    let theta0: Vec<f64> = eq.terms.iter().map(|t| t.coefficient).collect();
    let conf: Vec<f64> = nom_text
        .iter()
        .map(|t| *o.confidence.get(t).unwrap_or(&o.default_confidence))
        .collect();
    let free: Vec<usize> = (0..theta0.len())
        .filter(|&j| conf[j] > 0.0 && theta0[j] != 0.0)
        .collect();
    let _ = conf;

    let ys: Vec<&[f64]> = rs.runs.iter().map(|r| r.channels[yc].as_slice()).collect();
    // Checked here, where runs have their ids (the derivative code knows only positions).
    rs.require_derivable(n)?;
    // Tuned on the training runs only: validation and test runs never influence the fit.
    let tuning = DerivativeOptions {
        tune_runs: Some(o.train.clone()),
        ..DerivativeOptions::default()
    };
    let der = differentiate_runs(&ys, rs.tau, n, &tuning)?;
    let zhat: Vec<Vec<Vec<f64>>> = rs
        .runs
        .iter()
        .zip(&der)
        .map(|(r, d)| {
            let mut z: Vec<Vec<f64>> = (0..n).map(|k| d.values[k].clone()).collect();
            z.extend(uc.iter().map(|&c| r.channels[c].clone()));
            z
        })
        .collect();
    let top: Vec<Vec<f64>> = der.iter().map(|d| d.values[n].clone()).collect();
    let scales = training_scales(&zhat, &o.train);
    // The nominal's monomials and its named terms: the dictionary offers neither again.
    let nom_monos: Vec<Vec<(usize, u32)>> = eq
        .terms
        .iter()
        .filter(|t| t.is_monomial())
        .map(|t| monomial_exponents(t, &vars))
        .collect();
    let bare = |e: &str| -> String { e.chars().filter(|c| !c.is_whitespace()).collect() };
    let nom_named: Vec<String> = eq
        .terms
        .iter()
        .filter_map(|t| t.expression.as_deref().map(bare))
        .collect();
    let mut effects = dictionary::build(&vars, n, &scales, &nom_monos, &o.user_effects)?;
    effects.retain(|e| !nom_named.contains(&bare(e.expr.text())));
    let effects = distinct_on_data(effects, &o.user_effects, &zhat, &o.train)?;
    // Zero crossings of the smoothed output (the raw one crosses its mean at every noise sample).
    let train_y: Vec<&[f64]> = o.train.iter().map(|&r| zhat[r][0].as_slice()).collect();
    let m = o
        .half_width
        .unwrap_or_else(|| weak::choose_half_width(&train_y));
    if m < 2 {
        return Err(Error::param(
            "half width",
            format!("{m} samples; use at least 2"),
        ));
    }
    // Every run holds a window of 2m + 1 samples (checked before the windows are built).
    rs.require_min_len(
        m.saturating_mul(2).saturating_add(1),
        &format!("the weak form (half width {m})"),
    )?;
    let mut rows = Vec::with_capacity(rs.runs.len());
    let mut simruns = Vec::new();
    for (ri, run) in rs.runs.iter().enumerate() {
        let len = run.len();
        let w = weak::Windows::new(len, m, n, rs.tau);
        let y = ys[ri];
        let (r, cols) = weak_rows(&w, y, &zhat[ri], n, (&nom_exprs, &theta0, &free), &effects);
        rows.push((r, cols));
        let t: Vec<f64> = (0..len).map(|i| i as f64 * rs.tau).collect();
        simruns.push(RunData {
            id: run.id.clone(),
            t,
            y: vec![y.to_vec()],
            u: uc.iter().map(|&c| run.channels[c].clone()).collect(),
            states: Some((0..n).map(|k| der[ri].values[k].clone()).collect()),
            x0: (0..n).map(|k| der[ri].values[k][0]).collect(),
        });
    }
    let eps: Vec<f64> = scales
        .sd
        .iter()
        .map(|s| crate::identify::SIGN_WIDTH * s)
        .collect();
    Ok(Prepared {
        nominal: nominal.clone(),
        vars,
        order: n,
        nom_exprs,
        nom_text,
        theta0,
        free,
        effects,
        rows,
        simruns,
        zhat,
        top,
        noise_sd: der.iter().map(|d| d.noise_sd).collect(),
        eps,
        half_width: m,
    })
}

/// Each variable's standard deviation, median and 99th percentile of magnitude over the
/// training runs (`zhat[run][variable][sample]`), floored at 1e-12.
fn training_scales(zhat: &[Vec<Vec<f64>>], train: &[usize]) -> Scales {
    let nz = zhat.first().map_or(0, |z| z.len());
    let mut sd = vec![0.0; nz];
    let mut median = vec![0.0; nz];
    let mut p99 = vec![0.0; nz];
    for v in 0..nz {
        let all: Vec<f64> = train
            .iter()
            .flat_map(|&r| zhat[r][v].iter().copied())
            .collect();
        sd[v] = spread(&all).max(1e-12);
        median[v] = percentile(&all, 50.0);
        let abs: Vec<f64> = all.iter().map(|x| x.abs()).collect();
        p99[v] = percentile(&abs, 99.0).max(1e-12);
    }
    Scales { sd, median, p99 }
}

/// The standard deviation of `x`; where its squares overflow or underflow, computed on `x`
/// scaled by its largest deviation from the mean (derivatives of records near the 1e150 magnitude limit:
/// an infinite scale wrote `tanh(y_d1/inf)` into the dictionary, which then did not parse).
/// Sums of many samples near f64's limit are taken as means of scaled values for the same
/// reason. 0 for fewer than one sample or a constant; not finite only when `x` is not.
fn spread(x: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    // The plain formula where it holds (the same bits as before for every ordinary record).
    let mean = x.iter().sum::<f64>() / n;
    let plain = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    if plain.is_finite() && plain > 1e-150 {
        return plain;
    }
    let big = x.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if !big.is_finite() {
        return f64::NAN;
    }
    if big == 0.0 {
        return 0.0;
    }
    let mean = x.iter().map(|v| v / big).sum::<f64>() / n * big;
    let dev = x.iter().fold(0.0f64, |a, v| a.max((v - mean).abs()));
    if dev == 0.0 {
        return 0.0;
    }
    dev * (x.iter().map(|v| ((v - mean) / dev).powi(2)).sum::<f64>() / n).sqrt()
}

/// One run's weak-form rows: the label less the nominal's terms at their coefficients, and the
/// columns of the free nominal terms and of the effects. A column is the exact integration by
/// parts for a single state variable, else the window integral of `phi(z_hat)`.
/// `nominal` is (every term's expression, its coefficient, the free terms).
fn weak_rows(
    w: &weak::Windows,
    y: &[f64],
    zhat: &[Vec<f64>],
    n: usize,
    nominal: (&[Expr], &[f64], &[usize]),
    effects: &[Effect],
) -> (Vec<f64>, Vec<Vec<f64>>) {
    let (nom_exprs, theta0, free) = nominal;
    let sgn = |k: usize| if k.is_multiple_of(2) { 1.0 } else { -1.0 };
    let label = w
        .integrate(n, y)
        .into_iter()
        .map(|v| sgn(n) * v)
        .collect::<Vec<f64>>();
    let column = |e: &Expr| -> Vec<f64> {
        if let Some(mono) = e.monomial() {
            if mono.len() == 1 && mono[0].1 == 1 {
                let v = mono[0].0;
                if v < n {
                    return w.integrate(v, y).into_iter().map(|x| sgn(v) * x).collect();
                }
                return w.integrate(0, &zhat[v]);
            }
        }
        let mut z = vec![0.0; zhat.len()];
        let phi: Vec<f64> = (0..y.len())
            .map(|i| {
                for (v, zv) in z.iter_mut().enumerate() {
                    *zv = zhat[v][i];
                }
                e.eval(&z)
            })
            .collect();
        w.integrate(0, &phi)
    };
    let nom_cols: Vec<Vec<f64>> = nom_exprs.iter().map(&column).collect();
    let mut r = label;
    for (c, th) in nom_cols.iter().zip(theta0) {
        for (ri, v) in r.iter_mut().zip(c) {
            *ri -= th * v;
        }
    }
    let mut cols: Vec<Vec<f64>> = free.iter().map(|&j| nom_cols[j].clone()).collect();
    cols.extend(effects.iter().map(|e| column(&e.expr)));
    (r, cols)
}

/// Drops candidates that the training data cannot tell from a simpler one: a column that is
/// constant there, or takes one value on more than 95 % of the samples (`sign(y)` of a level
/// that crosses zero only in noise: an offset but for a few samples), unless it is the offset
/// itself; and a column equal to an earlier candidate's (`abs(y)*y` and `y^2` of a positive
/// level). Keeping them would only split the bootstrap's votes between two names for one column.
/// A built-in effect whose column is not finite on the training data (the cube of a level near
/// 1e150) cannot be fitted and is dropped too. A user's effect (named in `user`) is not dropped
/// quietly: any of these, or a column that is not finite on the training data, is an error
/// naming it.
fn distinct_on_data(
    effects: Vec<Effect>,
    user: &[(String, String)],
    zhat: &[Vec<Vec<f64>>],
    train: &[usize],
) -> Result<Vec<Effect>> {
    let nz = zhat.first().map_or(0, |r| r.len());
    let rows: Vec<Vec<f64>> = train
        .iter()
        .flat_map(|&r| {
            let len = zhat[r].first().map_or(0, |c| c.len());
            (0..len)
                .step_by(4)
                .map(move |i| (0..nz).map(|v| zhat[r][v][i]).collect::<Vec<f64>>())
        })
        .collect();
    let refuse = |e: &Effect, why: String| {
        Err(Error::param(
            "effect",
            format!("'{}' ({}) {why}", e.family, e.formula),
        ))
    };
    let mut kept: Vec<(Effect, Vec<f64>)> = Vec::new();
    for e in effects {
        let is_user = user.iter().any(|(n, _)| n.trim() == e.family);
        let col: Vec<f64> = rows.iter().map(|z| e.expr.eval(z)).collect();
        if col.iter().any(|v| !v.is_finite()) {
            if is_user {
                return refuse(
                    &e,
                    "is not finite on the training data; reformulate it".into(),
                );
            }
            continue;
        }
        let scale = col.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(1e-300);
        let (lo, hi) = col
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let mode_share = {
            let mut v = col.clone();
            v.sort_by(|a, b| a.total_cmp(b));
            let (mut best, mut run) = (0usize, 0usize);
            for i in 0..v.len() {
                run = if i > 0 && v[i] == v[i - 1] {
                    run + 1
                } else {
                    1
                };
                best = best.max(run);
            }
            best as f64 / v.len().max(1) as f64
        };
        if (hi - lo <= 1e-9 * scale || mode_share > 0.95) && e.formula != "1" {
            if is_user {
                return refuse(
                    &e,
                    format!("is (nearly) constant on the training data, {lo:?}..{hi:?}, one value on {:.0} % of the samples: the runs do not reach where it acts", 100.0 * mode_share),
                );
            }
            continue;
        }
        let same = kept.iter().find(|(_, c)| {
            c.iter()
                .zip(&col)
                .all(|(a, b)| (a - b).abs() <= 1e-9 * scale)
        });
        match same {
            None => kept.push((e, col)),
            Some((other, _)) if is_user => {
                return refuse(
                    &e,
                    format!(
                        "equals {} {} on the training data; leave it out",
                        other.family, other.formula
                    ),
                )
            }
            Some(_) => {}
        }
    }
    Ok(kept.into_iter().map(|(e, _)| e).collect())
}

const BLOCK: usize = 8;

/// Memory the training runs' block Gram matrices may take together. Each block keeps a Gram of
/// `ncol^2` f64, so at [`BLOCK`] windows a block their total grows as `N ncol^2 / m` (some GB
/// for 10^6 samples and a few hundred columns); past this budget blocks get longer (a whole
/// multiple of [`BLOCK`] windows), which a block bootstrap allows: longer blocks keep more of
/// the residual's serial correlation, and the bootstrap still draws from at least
/// [`MIN_BLOCKS`] of them.
const BLOCK_BUDGET_BYTES: usize = 256 << 20;

/// The least number of blocks the memory budget may leave (the budget is then exceeded for
/// very wide problems, by design: fewer blocks than this would make the bootstrap's spread
/// meaningless).
const MIN_BLOCKS: usize = 256;

/// One run's weak-form rows: the labels and the columns (free nominal terms, then effects).
type Rows = (Vec<f64>, Vec<Vec<f64>>);

/// How the training runs' windows are cut into bootstrap blocks: at most `blen` consecutive
/// windows of a run (and at most half of it, so that every run of two blocks or more has blocks
/// in both halves), and `group` such blocks of one half summed into one where even those blocks
/// would be too many (many short runs: each run ends a block).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Blocking {
    blen: usize,
    group: usize,
}

impl Blocking {
    /// Windows per block of a run of `len` windows: `blen`, or fewer for a short run, so that
    /// its first half and its second half are not one block (a multiple of [`BLOCK`]).
    fn run_blen(&self, len: usize) -> usize {
        // Rounded down: a block never reaches past the middle of its run.
        self.blen.min(BLOCK * (len / 2 / BLOCK)).max(BLOCK)
    }
}

/// The [`Blocking`] of runs of `lens` windows with `ncol` columns within [`BLOCK_BUDGET_BYTES`].
fn blocking(lens: &[usize], ncol: usize) -> Blocking {
    blocking_within(lens, ncol, BLOCK_BUDGET_BYTES)
}

/// Blocks of [`BLOCK`] windows, or of a multiple of it, then groups of them, where the blocks'
/// Gram matrices would exceed `budget` bytes (never fewer than [`MIN_BLOCKS`] blocks).
fn blocking_within(lens: &[usize], ncol: usize, budget: usize) -> Blocking {
    let max_blocks = (budget / gram_bytes(ncol)).max(MIN_BLOCKS);
    let windows: usize = lens.iter().sum();
    let blen = BLOCK * windows.div_ceil(BLOCK).div_ceil(max_blocks).max(1);
    let b = Blocking { blen, group: 1 };
    let count: usize = lens.iter().map(|&l| l.div_ceil(b.run_blen(l))).sum();
    Blocking {
        blen,
        group: count.div_ceil(max_blocks).max(1),
    }
}

/// Bytes of one block's Gram matrix over `ncol` columns (with its vector and bookkeeping).
fn gram_bytes(ncol: usize) -> usize {
    8 * (ncol * ncol + ncol) + 64
}

/// The bootstrap blocks of a run of `len` windows: `blen` consecutive windows each.
fn block_ranges(len: usize, blen: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
    (0..len).step_by(blen).map(move |a| a..(a + blen).min(len))
}

/// The Gram matrix of each bootstrap block of `runs` and whether it lies in the second half of
/// its run. With `group` > 1, up to `group` blocks of the same half (of consecutive runs) are
/// summed into one, so the halves' comparison keeps its meaning and at most two groups are open
/// at a time.
fn block_grams(rows: &[Rows], ncol: usize, runs: &[usize], b: Blocking) -> (Vec<Gram>, Vec<bool>) {
    let (mut out, mut late) = (Vec::<Gram>::new(), Vec::new());
    // Per half: the open group's index in `out` and how many blocks it holds.
    let mut open: [Option<(usize, usize)>; 2] = [None, None];
    for (g, is_late) in blocks(rows, ncol, runs, b) {
        let h = is_late as usize;
        match open[h] {
            Some((at, n)) if n < b.group => {
                out[at].add(&g);
                open[h] = Some((at, n + 1));
            }
            _ => {
                out.push(g);
                late.push(is_late);
                open[h] = Some((out.len() - 1, 1));
            }
        }
    }
    (out, late)
}

/// Each block's Gram matrix of `runs` (in run order, blocks of [`Blocking::run_blen`] windows)
/// and whether it lies in the second half of its run.
fn blocks<'a>(
    rows: &'a [Rows],
    ncol: usize,
    runs: &'a [usize],
    b: Blocking,
) -> impl Iterator<Item = (Gram, bool)> + 'a {
    runs.iter().flat_map(move |&r| {
        let (lab, cols) = &rows[r];
        block_ranges(lab.len(), b.run_blen(lab.len())).map(move |range| {
            let is_late = range.start + range.end >= lab.len();
            let mut g = Gram::zeros(ncol);
            g.add_rows(cols, lab, range);
            (g, is_late)
        })
    })
}

/// The sum of the validation runs' block Grams at [`BLOCK`] windows a block, without keeping
/// the blocks (the same additions in the same order as when they were kept).
fn summed_block_grams(p: &Prepared, runs: &[usize]) -> Gram {
    let ncol = p.free.len() + p.effects.len();
    let plain = Blocking {
        blen: BLOCK,
        group: 1,
    };
    let mut total = Gram::zeros(ncol);
    for (g, _) in blocks(&p.rows, ncol, runs, plain) {
        total.add(&g);
    }
    total
}

fn sum_grams<'a>(gs: impl IntoIterator<Item = &'a Gram>, ncol: usize) -> Gram {
    let mut g = Gram::zeros(ncol);
    for b in gs {
        g.add(b);
    }
    g
}

/// Residual sum of squares of coefficients `x` on columns `idx` of `g`.
fn rss_at(g: &Gram, idx: &[usize], x: &[f64]) -> f64 {
    let mut rss = g.rr;
    for (a, &i) in idx.iter().enumerate() {
        rss -= 2.0 * x[a] * g.b[i];
        for (b, &j) in idx.iter().enumerate() {
            rss += x[a] * g.g[(i, j)] * x[b];
        }
    }
    rss.max(0.0)
}

impl Prepared {
    /// Effect `k` as reports name it: its family and formula.
    fn effect_name(&self, k: usize) -> String {
        format!("{} {}", self.effects[k].family, self.effects[k].formula)
    }

    /// The nominal with its free coefficients moved by `delta` and the `effects` (index,
    /// coefficient) appended: monomial effects as monomials, the others as expressions, each
    /// with its family as origin; `sign` smoothed over 1e-3 of its variable's spread.
    fn model(&self, delta: &[f64], effects: &[(usize, f64)]) -> Model {
        let mut m = self.nominal.clone();
        let eq = &mut m.outputs[0];
        for (t, &c) in eq.terms.iter_mut().zip(&self.theta0) {
            t.coefficient = c;
            t.origin.get_or_insert(Origin::Nominal);
        }
        for (k, &j) in self.free.iter().enumerate() {
            eq.terms[j].coefficient += delta.get(k).copied().unwrap_or(0.0);
        }
        for &(k, c) in effects {
            let e = &self.effects[k];
            let term = match e.expr.monomial() {
                Some(mono) => {
                    let ex: Vec<(&str, u32)> = mono
                        .iter()
                        .map(|&(v, p)| (self.vars[v].as_str(), p))
                        .collect();
                    Term::new(&ex, c)
                }
                None => {
                    for v in e.expr.sign_variables() {
                        m.sign_smoothing.insert(self.vars[v].clone(), self.eps[v]);
                    }
                    Term::expression(e.expr.text(), c)
                }
            };
            eq.terms
                .push(term.with_origin(Origin::Effect(e.family.clone())));
        }
        m.degree = m.degree.max(
            m.outputs[0]
                .terms
                .iter()
                .map(|t| t.degree() as usize)
                .max()
                .unwrap_or(0),
        );
        m
    }
    /// Per term of [`Prepared::model`]'s models: whether the simulation refit must hold it
    /// (nominal terms that are not free); effects are always free.
    fn fixed_mask(&self) -> Vec<bool> {
        (0..self.theta0.len())
            .map(|j| !self.free.contains(&j))
            .collect()
    }
    fn runs(&self, idx: &[usize]) -> Vec<RunData> {
        idx.iter().map(|&r| self.simruns[r].clone()).collect()
    }
}

/// Simulation settings of the gates: looser than the reports' (the defaults, as `ctsid
/// simulate`), since many candidate models are compared on many runs.
fn gate_options() -> SimOptions {
    SimOptions {
        max_steps_per_interval: 2000,
        max_mean_steps_per_interval: 2000,
        ..SimOptions::fitting()
    }
}

/// The free-run output of `m` on `run` from the one initial-state convention; `None` when it
/// cannot be simulated.
fn simulated(m: &Model, run: &RunData, opts: &SimOptions) -> Option<Vec<f64>> {
    let c = m.compile().ok()?;
    free_run(&c, run, INIT_WINDOW, opts)
        .ok()
        .map(|mut v| v.swap_remove(0))
}

/// Free-run NRMSE of `m` on `run` (infinite when it cannot be simulated).
fn run_nrmse(m: &Model, run: &RunData, opts: &SimOptions) -> f64 {
    simulated(m, run, opts).map_or(f64::INFINITY, |s| nrmse(&s, &run.y[0]))
}

/// [`mean_nrmse`] of the test runs; NaN without any (nothing was scored on unseen runs).
fn test_nrmse(m: &Model, runs: &[RunData], opts: &SimOptions) -> f64 {
    if runs.is_empty() {
        return f64::NAN;
    }
    mean_nrmse(m, runs, opts)
}

/// Mean free-run NRMSE over runs (in parallel).
fn mean_nrmse(m: &Model, runs: &[RunData], opts: &SimOptions) -> f64 {
    use rayon::prelude::*;
    let v: Vec<f64> = runs.par_iter().map(|r| run_nrmse(m, r, opts)).collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// `m` refined on free-run error of `runs` with the `fixed` coefficients held (the start when
/// the refinement cannot run).
fn refit(m: &Model, runs: &[RunData], fixed: &[bool], iterations: usize) -> Model {
    let opts = RefineOptions {
        max_iterations: iterations,
        skip_below: 0.0,
        ..RefineOptions::default()
    };
    refine_holding(m, runs, &opts, fixed).map_or_else(|_| m.clone(), |r| r.model)
}

/// Least share of validation free-run error one of several effects must remove: the simulation
/// has to notice it at all. Each named effect's report prints its share ("in simulation"), and a
/// dropped one's reason: a bump near the empty tank (`SCALE=1.667`, seed 3 of the acceptance
/// example) removes 0.0 %; Silverbox's small even stiffness y^2, a known second-order effect of
/// that circuit, removes 1.9 % (`benches/research/silverbox_discover.rs`).
const MARGINAL_GAIN: f64 = 0.01;

/// An effect is not constant in time when its coefficients on the first and the second half of
/// the training runs differ by more than DRIFT_Z standard deviations of that difference and by
/// more than DRIFT_REL of the larger. Each named effect's report prints both ("over time"), and
/// a refusal for drift its reason, and `cargo bench --bench discover_acceptance -- 25`
/// prints the largest z per case: the effects named in the 275 case-seeds at 3 % noise reach 2.9 (as
/// many draws of a standard normal would); the tank driven near empty (`SCALE=1.667`) 3.8, its
/// outflow law 16 % apart (biased by the smoother where it is steepest); an offset fitted to the
/// sensor drift at 1 % noise (`-- 10 0.01 negative_drift`) 4.5 to 7.2, its halves 58-67 % apart
/// (a ramp gives one third against two thirds); Silverbox and EMPS (their examples) at most 1.3.
const DRIFT_Z: f64 = 3.5;
const DRIFT_REL: f64 = 0.5;
/// Fewest blocks in each half of the training runs for the time-invariance check to speak.
const MIN_HALF_BLOCKS: usize = 4;

/// One effect's time-invariance figures: coefficient on the first half, on the second, and z.
type Halves = (f64, f64, f64);

/// Whether coefficients `early` and `late` of one effect, `z` standard deviations apart, say it
/// is not constant in time.
fn drifts(early: f64, late: f64, z: f64) -> bool {
    z > DRIFT_Z && (early - late).abs() > DRIFT_REL * early.abs().max(late.abs())
}

/// Whether a coefficient refined on simulation error takes the sign its interval excludes.
fn contradicts(interval: &[f64; 2], refined: f64) -> bool {
    (interval[0] > 0.0 && refined < 0.0) || (interval[1] < 0.0 && refined > 0.0)
}

/// A stretch of a run where the nominal's error is high: (run, start s, end s).
type Window = (String, f64, f64);

/// (a) and (b): the nominal's free-run NRMSE on every run of the split (and the part above the
/// noise floor), and the time windows where its error exceeds three noise levels, in the
/// record's own time. An error when the nominal diverges on every run: there is no error to
/// explain and nothing to compare an augmented model with.
fn compare(
    p: &Prepared,
    rs: &RecordSet,
    o: &Options,
    nominal_model: &Model,
    report_opts: &SimOptions,
) -> Result<(Vec<RunScore>, Vec<Window>)> {
    let mut runs = Vec::new();
    let mut windows = Vec::new();
    let mut diverged = 0usize;
    for (ri, sr) in p.simruns.iter().enumerate() {
        let role = if o.train.contains(&ri) {
            "train"
        } else if o.validation.contains(&ri) {
            "validation"
        } else if o.test.contains(&ri) {
            "test"
        } else {
            continue;
        };
        let sim = simulated(nominal_model, sr, report_opts);
        diverged += sim.is_none() as usize;
        let (rms, nr, above) = match &sim {
            Some(s) => {
                let (rms, nr) = rms_nrmse(s, &sr.y[0]);
                let floor = p.noise_sd[ri] / crate::metrics::std_dev(&sr.y[0]).max(1e-300);
                (rms, nr, (nr * nr - floor * floor).max(0.0).sqrt())
            }
            None => (f64::INFINITY, f64::INFINITY, f64::INFINITY),
        };
        if let Some(s) = &sim {
            let t0 = rs.runs[ri].t0;
            windows.extend(
                hot_windows(s, &sr.y[0], p.half_width, 3.0 * p.noise_sd[ri])
                    .into_iter()
                    .map(|(a, b)| (sr.id.clone(), t0 + sr.t[a], t0 + sr.t[b])),
            );
        }
        runs.push(RunScore {
            run: sr.id.clone(),
            role: role.into(),
            nrmse_nominal: nr,
            rms_nominal: rms,
            above_noise: above,
            nrmse_final: None,
            rms_final: None,
        });
    }
    if !runs.is_empty() && diverged == runs.len() {
        return Err(Error::InvalidData(format!(
            "the nominal model diverges in free run on every run ({} of them): discover needs a nominal that simulates the record; check its coefficients with `ctsid simulate`",
            runs.len()
        )));
    }
    Ok((runs, windows))
}

/// Sample ranges `(first, last)` where the moving RMS of `sim - y` over `2m + 1` samples
/// exceeds `level` (a window still open at the end closes at the last sample).
fn hot_windows(sim: &[f64], y: &[f64], m: usize, level: f64) -> Vec<(usize, usize)> {
    let e2: Vec<f64> = sim.iter().zip(y).map(|(a, b)| (a - b).powi(2)).collect();
    let mut out = Vec::new();
    let mut inside = None;
    for i in 0..e2.len() {
        let a = i.saturating_sub(m);
        let b = (i + m + 1).min(e2.len());
        let rms = (e2[a..b].iter().sum::<f64>() / (b - a) as f64).sqrt();
        match (rms > level, inside) {
            (true, None) => inside = Some(i),
            (false, Some(st)) => {
                out.push((st, i));
                inside = None;
            }
            _ => {}
        }
    }
    if let (Some(st), Some(last)) = (inside, e2.len().checked_sub(1)) {
        out.push((st, last));
    }
    out
}

/// Runs the workflow. Refuses a nominal model that [`Model::validate`] refuses or that has more
/// than one output, an empty train or validation list (an empty test list is allowed: nothing is
/// then scored on unseen runs and the test figures are NaN), lists that
/// [`crate::identify::Split::new`] refuses, a channel the record set lacks, an output or input that
/// is constant over the training runs, a confidence for a term the nominal lacks, runs too short
/// for the derivatives or for the weak-form windows, a half width below 2, user effects that
/// [`dictionary::build`] refuses or that repeat another on the data (or are not finite there); errs
/// ([`Error::Numerical`]) when the weak-form normal equations are singular, and passes on errors of
/// the derivatives and the simulations.
///
/// ```no_run
/// use ctsid::discover::{discover, Options};
/// use ctsid::{Model, RecordSet, Split};
/// let nominal = Model::read("linear.json")?;
/// let records = RecordSet::read_csv("emps.csv", &["q_m", "force_N"], Some("run"), 1e-3)?;
/// let split = Split::from_lists(&records, "est0,est1,est2,est3", Some("est4,est5"), "pulses")?;
/// let options = Options::new(split.train, split.validation.unwrap_or_default(), split.test);
/// let found = discover(&records, &nominal, &options)?;
/// println!("{}", found.text()); // verdict, evidence, before/after table
/// found.augmented_model(&nominal)?.write("augmented.json")?;
/// # Ok::<(), ctsid::Error>(())
/// ```
pub fn discover(rs: &RecordSet, nominal: &Model, o: &Options) -> Result<Discovery> {
    let p = prepare(rs, nominal, o)?;
    let n_nom = p.free.len();
    let n_eff = p.effects.len();
    let ncol = n_nom + n_eff;
    let pb = problem(&p, o);
    let lens: Vec<usize> = o.train.iter().map(|&r| p.rows[r].0.len()).collect();
    let (blocks, late) = block_grams(&p.rows, ncol, &o.train, blocking(&lens, ncol));
    let train = sum_grams(&blocks, ncol);
    let val = summed_block_grams(&p, &o.validation);

    // (a) compare and (b) localise.
    let nominal_model = p.model(&[], &[]);
    let report_opts = SimOptions::default();
    let (mut runs, windows) = compare(&p, rs, o, &nominal_model, &report_opts)?;
    let shares = coordinate_shares(&p, &o.train);

    // (c) regression.
    let retune = pb.fit(&train, &[]).ok_or_else(singular)?;
    let set = pb.forward(&train, n_eff, o.max_effects);
    // The closest single candidate, for the report when nothing passes.
    let best_single = (0..n_eff)
        .filter_map(|k| pb.fit(&train, &[k]).map(|s| (k, s.objective)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|x| x.0);

    // (d) the gates of each effect, on block-bootstrap draws made once.
    let mut cand: Vec<usize> = set.clone();
    if cand.is_empty() {
        cand.extend(best_single);
    }
    let resampling = Resampling::new(&pb, &train, &blocks, &late, n_eff, o);
    let idx_nom: Vec<usize> = (0..n_nom).collect();
    let val_nominal = val.rr;
    let val_retuned = rss_at(&val, &idx_nom, &retune.delta);
    // The simulation gate compares structures at their best: each one refined on free-run error
    // of the training runs (coefficients and initial states) before it is scored on validation.
    let refitter = Refitter {
        p: &p,
        pb: &pb,
        train: &train,
        truns: p.runs(&o.train),
        vruns: p.runs(&o.validation),
        fixed: p.fixed_mask(),
        gate: gate_options(),
        iterations: o.refine_iterations,
    };
    let retuned_model = refit(
        &p.model(&retune.delta, &[]),
        &refitter.truns,
        &refitter.fixed,
        o.refine_iterations,
    );
    let (vruns, gate) = (&refitter.vruns, &refitter.gate);
    let nt = p.theta0.len();
    let selected = gates::select(&resampling, &refitter, cand)?;
    let effect_failure = gates::effect_failure(&p, &resampling, &selected, set.is_empty());
    let Selected {
        cand,
        sol: cand_sol,
        model: cand_model,
        shares: sim_shares,
        boot,
        dropped,
        dropped_effects,
        ..
    } = selected;
    let idx_cand: Vec<usize> = (0..n_nom).chain(cand.iter().map(|&k| n_nom + k)).collect();
    let mut xc = cand_sol.delta.clone();
    xc.extend(&cand_sol.coef);
    let val_cand = rss_at(&val, &idx_cand, &xc);
    let residual_ratio = val_cand / val_nominal.min(val_retuned).max(1e-300);
    let sim_nom = mean_nrmse(&nominal_model, vruns, gate);
    let sim_ret = mean_nrmse(&retuned_model, vruns, gate);
    let sim_cand = mean_nrmse(&cand_model, vruns, gate);
    let simulation_ratio = sim_cand / sim_nom.min(sim_ret);
    let (failed, dz) = effect_failure;
    let failed = failed.or_else(|| gate_failure(residual_ratio, (sim_cand, sim_nom, sim_ret)));
    let gates = Gates::of(&boot, residual_ratio, simulation_ratio, failed.clone());

    // Verdict; the models were refined on simulation error above (f).
    let test_runs = p.runs(&o.test);
    let nrmse_before = test_nrmse(&nominal_model, &test_runs, &report_opts);
    let mut effects = Vec::new();
    let mut retuned = Vec::new();
    let mut closest = None;
    let verdict;
    let final_model;
    let retune_ok = (val_retuned <= 0.9 * val_nominal) && sim_ret <= 0.8 * sim_nom;
    if failed.is_none() {
        verdict = "added";
        let refined = cand_model.clone();
        let c = coefficients(&refined);
        effects = found_effects(
            &p,
            (&cand, &cand_sol.coef, &c[nt..]),
            &boot,
            &dz,
            &sim_shares,
        );
        retuned = retuned_list(&p, &c[..nt], o);
        final_model = refined;
    } else if retune_ok {
        verdict = "retune";
        let refined = retuned_model.clone();
        retuned = retuned_list(&p, &coefficients(&refined), o);
        closest = Some(failed.clone().unwrap_or_default());
        final_model = refined;
    } else {
        verdict = "none";
        closest = Some(match cand.first() {
            Some(&k) => format!(
                "closest: {} (coefficient {}); failed: {}",
                p.effect_name(k),
                num(cand_sol.coef[0]),
                failed.clone().unwrap_or_default()
            ),
            None => "no candidate".into(),
        });
        final_model = nominal_model.clone();
    }
    let refused = match verdict {
        "added" => Vec::new(),
        _ => refused_models(&p, &pb, &train, (&cand, &dropped_effects), simulation_ratio),
    };
    score_final(
        &mut runs,
        &p,
        (&final_model, verdict == "none"),
        &report_opts,
    );
    let nrmse_after = test_nrmse(&final_model, &test_runs, &report_opts);
    Ok(Discovery {
        verdict: verdict.into(),
        effects,
        retuned,
        closest,
        dropped,
        gates: Some(gates),
        runs,
        shares,
        windows,
        nrmse_before,
        nrmse_after,
        half_width: p.half_width,
        final_model: Some(final_model),
        refused,
        nominal_model: Some(nominal_model),
        test_runs,
    })
}

/// [`Discovery::refused`]: the nominal plus each effect of the refused set `cand` and of those
/// left out before (`dropped`), once each, at its weak-form coefficient fitted alone on the
/// training runs; a set of one carries the simulation gate's `ratio`.
fn refused_models(
    p: &Prepared,
    pb: &Problem,
    train: &Gram,
    (cand, dropped): (&[usize], &[usize]),
    ratio: f64,
) -> Vec<Refused> {
    let alone = (cand.len() == 1).then(|| (cand[0], ratio));
    let effects = cand.iter().chain(dropped);
    let mut seen = Vec::new();
    effects
        .filter(|k| {
            let new = !seen.contains(*k);
            seen.push(**k);
            new
        })
        .filter_map(|&k| {
            let s = pb.fit(train, &[k])?;
            Some(Refused {
                model: p.model(&[], &[(k, s.coef[0])]),
                simulation_ratio: alone.filter(|a| a.0 == k).map(|a| a.1),
            })
        })
        .collect()
}

/// The regression problem: the nominal's free coefficients with their prior standard deviations
/// (each term's confidence times its magnitude).
fn problem(p: &Prepared, o: &Options) -> Problem {
    Problem {
        n_nom: p.free.len(),
        prior_sd: p
            .free
            .iter()
            .map(|&j| {
                o.confidence
                    .get(&p.nom_text[j])
                    .copied()
                    .unwrap_or(o.default_confidence)
                    * p.theta0[j].abs()
            })
            .collect(),
    }
}

/// The residual and simulation gates on the validation runs: why the candidate fails them, if it
/// does. `sims` are the validation free-run NRMSEs of the candidate, the nominal and the re-tuned
/// nominal.
fn gate_failure(
    residual_ratio: f64,
    (sim_cand, sim_nom, sim_ret): (f64, f64, f64),
) -> Option<String> {
    if residual_ratio > 0.9 {
        return Some(format!(
            "validation residual only {:.1} % below the better of nominal and re-tuned (< 10 %)",
            100.0 * (1.0 - residual_ratio)
        ));
    }
    let simulation_ratio = sim_cand / sim_nom.min(sim_ret);
    // Written so that a NaN ratio (a model that cannot be simulated) fails the gate.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let sim_gate_fails = !(simulation_ratio <= 0.8);
    sim_gate_fails.then(|| {
        format!(
            "validation free-run NRMSE {} vs {} nominal / {} re-tuned: {:.1} % lower (< 20 %)",
            num(sim_cand),
            num(sim_nom),
            num(sim_ret),
            100.0 * (1.0 - simulation_ratio)
        )
    })
}

/// The added effects as reported: `cand` (effect indices) with their weak-form and refined
/// coefficients, bootstrap figures, half-record checks and simulation shares.
fn found_effects(
    p: &Prepared,
    (cand, weak, refined): (&[usize], &[f64], &[f64]),
    boot: &Bootstrapped,
    dz: &[Halves],
    sim_shares: &[f64],
) -> Vec<FoundEffect> {
    cand.iter()
        .enumerate()
        .map(|(i, &k)| {
            let e = &p.effects[k];
            FoundEffect {
                family: e.family.clone(),
                formula: e.formula.clone(),
                coefficient: refined[i],
                weak_coefficient: weak[i],
                interval: boot.intervals[i],
                inclusion: boot.inclusion[i],
                aliases: boot.aliases[i].iter().map(|&a| p.effect_name(a)).collect(),
                reading: reading(&e.family, refined[i], p),
                halves: dz.get(i).map_or([f64::NAN; 2], |z| [z.0, z.1]),
                halves_z: dz.get(i).map_or(f64::NAN, |z| z.2),
                simulation_share: sim_shares.get(i).copied(),
            }
        })
        .collect()
}

/// Each run's RMS and NRMSE under the final model.
fn score_final(
    runs: &mut [RunScore],
    p: &Prepared,
    (model, is_nominal): (&Model, bool),
    opts: &SimOptions,
) {
    if is_nominal {
        // Scored in (a) already.
        for r in runs.iter_mut() {
            r.nrmse_final = Some(r.nrmse_nominal);
            r.rms_final = Some(r.rms_nominal);
        }
        return;
    }
    for r in runs.iter_mut() {
        if let Some(sr) = p.simruns.iter().find(|s| s.id == r.run) {
            let (rms, nr) = simulated(model, sr, opts)
                .map_or((f64::INFINITY, f64::INFINITY), |s| rms_nrmse(&s, &sr.y[0]));
            r.nrmse_final = Some(nr);
            r.rms_final = Some(rms);
        }
    }
}

/// The coefficients of a one-output model in term order.
fn coefficients(m: &Model) -> Vec<f64> {
    m.outputs[0].terms.iter().map(|t| t.coefficient).collect()
}

fn retuned_list(p: &Prepared, c: &[f64], o: &Options) -> Vec<Retuned> {
    p.nom_text
        .iter()
        .zip(&p.theta0)
        .zip(c)
        .filter(|((_, &a), &b)| a != 0.0 && ((b - a) / a).abs() > 0.05)
        .map(|((t, &a), &b)| {
            let conf = o.confidence.get(t).copied().unwrap_or(o.default_confidence);
            let change = (b - a) / a;
            Retuned {
                term: t.clone(),
                nominal: a,
                value: b,
                change_percent: 100.0 * change,
                confidence_percent: 100.0 * conf,
                outside_confidence: change.abs() > 3.0 * conf,
            }
        })
        .collect()
}

/// A physical reading where one exists: a force from an acceleration coefficient and the mass
/// the nominal implies (the input gain of a second-order model `y'' = ... + u / M`).
fn reading(family: &str, coef: f64, p: &Prepared) -> Option<String> {
    if p.order != 2 || p.vars.len() <= p.order {
        return None;
    }
    let u = &p.vars[p.order];
    let k = p.nom_text.iter().position(|t| t == u)?;
    let gain = p.theta0[k];
    if gain == 0.0 {
        return None;
    }
    let force = coef / gain;
    match family {
        "coulomb_friction" | "stribeck" => Some(format!(
            "Coulomb force {} (in input units; mass 1/{} from the nominal input gain)",
            num(force.abs()),
            num(gain)
        )),
        "cubic_stiffness" => Some(format!(
            "cubic spring constant {} (input units per y^3)",
            num(-force)
        )),
        "quadratic_drag" => Some(format!(
            "drag constant {} (input units per v^2)",
            num(-force)
        )),
        _ => None,
    }
}

/// Share of var(r) explained by each coordinate (12 quantile bins of the derivative-space residual).
fn coordinate_shares(p: &Prepared, train: &[usize]) -> Vec<Share> {
    let nz = p.vars.len();
    let mut r = Vec::new();
    let mut z: Vec<Vec<f64>> = vec![Vec::new(); nz];
    for &ri in train {
        let len = p.top[ri].len();
        // Skip the ends, where the smoother is least certain.
        let e = p.half_width.min(len / 4);
        for i in e..len - e {
            let zi: Vec<f64> = (0..nz).map(|v| p.zhat[ri][v][i]).collect();
            let pn: f64 = p
                .nom_exprs
                .iter()
                .zip(&p.theta0)
                .map(|(x, c)| c * x.eval(&zi))
                .sum();
            r.push(p.top[ri][i] - pn);
            for v in 0..nz {
                z[v].push(zi[v]);
            }
        }
    }
    let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
    let var = r
        .iter()
        .map(|v| (v - mean).powi(2))
        .sum::<f64>()
        .max(1e-300);
    let mut out = Vec::new();
    for v in 0..nz {
        let mut order: Vec<usize> = (0..r.len()).collect();
        order.sort_by(|&a, &b| z[v][a].total_cmp(&z[v][b]));
        let nb = 12;
        let mut between = 0.0;
        let mut profile = Vec::new();
        for b in 0..nb {
            let s = b * order.len() / nb;
            let e = (b + 1) * order.len() / nb;
            if e <= s {
                continue;
            }
            let idx = &order[s..e];
            let mr = idx.iter().map(|&i| r[i]).sum::<f64>() / idx.len() as f64;
            let mz = idx.iter().map(|&i| z[v][i]).sum::<f64>() / idx.len() as f64;
            between += idx.len() as f64 * (mr - mean).powi(2);
            profile.push((mz, mr));
        }
        out.push(Share {
            coordinate: p.vars[v].clone(),
            share: between / var,
            profile,
        });
    }
    out
}

impl Discovery {
    /// The report's plots as `(file name, SVG)`: each test run's measurement against the free
    /// runs of the nominal and the final model (both from the one initial-state convention)
    /// with their fits, errors and a zoom on long runs, the residual analysis of the final
    /// model ([`crate::report::compare`]), and the conditional mean of the derivative-space
    /// residual along each coordinate.
    pub fn plots(&self) -> Vec<(String, String)> {
        use crate::report::compare::{comparison_figure, residual_figure, Comparison};
        use crate::report::svg::{line_plot, Series};
        let mut out = Vec::new();
        // One figure name per run, also where run ids share their safe name.
        let (mut stems, mut coordinate_stems) = Default::default();
        if let (Some(nom), Some(fin)) = (&self.nominal_model, &self.final_model) {
            for r in &self.test_runs {
                let sim_of = |m: &Model| simulated(m, r, &SimOptions::default());
                let (Some(a), Some(b)) = (sim_of(nom), sim_of(fin)) else {
                    continue;
                };
                let final_label = format!("{} model", self.verdict);
                let c = Comparison {
                    run: &r.id,
                    t: &r.t,
                    output: &nom.outputs[0].name,
                    measured: &r.y[0],
                    simulated: vec![("nominal", &a), (&final_label, &b)],
                    inputs: nom
                        .inputs
                        .iter()
                        .zip(&r.u)
                        .map(|(n, u)| (n.as_str(), &u[..]))
                        .collect(),
                };
                let stem = crate::report::unique_stem(crate::report::safe_name(&r.id), &mut stems);
                out.push((format!("test_run_{stem}.svg"), comparison_figure(&c)));
                out.push((format!("resid_{stem}.svg"), residual_figure(&c).1));
            }
        }
        for sh in &self.shares {
            if sh.profile.is_empty() {
                continue;
            }
            let x: Vec<f64> = sh.profile.iter().map(|p| p.0).collect();
            let y: Vec<f64> = sh.profile.iter().map(|p| p.1).collect();
            let stem = crate::report::unique_stem(
                crate::report::safe_name(&format!("residual_along_{}", sh.coordinate)),
                &mut coordinate_stems,
            );
            out.push((
                format!("{stem}.svg"),
                line_plot(
                    &format!(
                        "conditional mean of the residual along {} ({:.0} % of var(r))",
                        sh.coordinate,
                        100.0 * sh.share
                    ),
                    &sh.coordinate,
                    "mean of r = y^(n) - P_nominal(z)",
                    &[Series {
                        label: "binned mean",
                        x: &x,
                        y: &y,
                        color: "#1f77b4",
                        band: None,
                        dashed: false,
                    }],
                ),
            ));
        }
        out
    }

    /// The verdict, the evidence and the before/after table as text.
    pub fn text(&self) -> String {
        let mut s = format!("verdict: {}\n", self.verdict);
        for e in &self.effects {
            s += &format!(
                "  {}: {} {} (weak form {}, 95 % CI [{}, {}]), bootstrap inclusion {:.0} %\n",
                e.family,
                num(e.coefficient),
                e.formula,
                num(e.weak_coefficient),
                num(e.interval[0]),
                num(e.interval[1]),
                100.0 * e.inclusion
            );
            if let Some(r) = &e.reading {
                s += &format!("    reading: {r}\n");
            }
            if e.halves_z.is_finite() {
                s += &format!(
                    "    over time: {} on the first half of each training run, {} on the second ({:.1} standard deviations apart)\n",
                    num(e.halves[0]),
                    num(e.halves[1]),
                    e.halves_z
                );
            }
            if let Some(g) = e.simulation_share {
                s += &format!(
                    "    in simulation: removes {:.1} % of the validation free-run NRMSE\n",
                    100.0 * g
                );
            }
            if !e.aliases.is_empty() {
                s += &format!(
                    "    aliases (|partial corr| > 0.95): {}\n",
                    e.aliases.join("; ")
                );
            }
        }
        for r in &self.retuned {
            s += &format!(
                "  retuned {}: {} -> {} ({} %){}\n",
                r.term,
                num(r.nominal),
                num(r.value),
                if r.change_percent.abs() < 1e6 {
                    format!("{:+.1}", r.change_percent)
                } else {
                    format!("{:+.2e}", r.change_percent)
                },
                if r.outside_confidence {
                    format!(
                        "; more than 3x its +-{:.0} % confidence: not a small correction (a missing effect the dictionary cannot name, or parameters these runs cannot tell apart)",
                        r.confidence_percent
                    )
                } else {
                    String::new()
                }
            );
        }
        if let Some(c) = &self.closest {
            s += &format!("  {c}\n");
        }
        for d in &self.dropped {
            s += &format!("  left out (failed its own gates): {d}\n");
        }
        if let Some(g) = &self.gates {
            s += &format!(
                "gates: inclusion {:?}, interval excludes 0 {:?}, validation residual ratio {}, validation free-run ratio {}\n",
                g.inclusion.iter().map(|v| (v * 100.0).round() / 100.0).collect::<Vec<_>>(),
                g.interval_excludes_zero,
                gate_ratio(g.residual_ratio),
                gate_ratio(g.simulation_ratio)
            );
        }
        s += "share of var(r) by coordinate:";
        for sh in &self.shares {
            s += &format!(" {} {:.0} %", sh.coordinate, 100.0 * sh.share);
        }
        s += "\n";
        if let Some(top) = self
            .shares
            .iter()
            .max_by(|a, b| a.share.total_cmp(&b.share))
        {
            s += &format!("  conditional mean of r along {}:", top.coordinate);
            for (z, m) in &top.profile {
                s += &format!(" ({}, {})", num(*z), num(*m));
            }
            s += "\n";
        }
        if !self.windows.is_empty() {
            s += &format!(
                "windows above 3 noise levels: {}{}\n",
                self.windows
                    .iter()
                    .take(6)
                    .map(|(r, a, b)| format!("run {r} {a:.2}-{b:.2} s"))
                    .collect::<Vec<_>>()
                    .join(", "),
                if self.windows.len() > 6 {
                    format!(" (+{} more)", self.windows.len() - 6)
                } else {
                    String::new()
                }
            );
        }
        s += "| run | role | NRMSE nominal | above noise | NRMSE final | RMS final |\n|---|---|---|---|---|---|\n";
        for r in &self.runs {
            s += &format!(
                "| {} | {} | {} | {} | {} | {} |\n",
                crate::report::md_cell(&r.run),
                r.role,
                or_diverged(r.nrmse_nominal, num4),
                or_diverged(r.above_noise, num4),
                r.nrmse_final
                    .map(|x| or_diverged(x, num4))
                    .unwrap_or_default(),
                r.rms_final.map(|x| or_diverged(x, num)).unwrap_or_default()
            );
        }
        if !self.test_runs.is_empty() {
            s += &format!(
                "test runs: mean free-run NRMSE before {}, after {}\n",
                or_diverged(self.nrmse_before, num4),
                or_diverged(self.nrmse_after, num4)
            );
        }
        s
    }

    /// The augmented model file: the final model (the nominal's terms re-tuned or refined,
    /// each added effect as a term with its family as origin, and its bootstrap interval where
    /// the coefficient is the weak-form estimate the interval belongs to) and the `discovery`
    /// section (every effect's weak-form estimate and interval). `nominal` must be the model the
    /// discovery was run with. Refuses a discovery without a final model, a `nominal` other than
    /// the one it was run with, and an augmented model that [`Model::validate`] refuses.
    pub fn augmented_model(&self, nominal: &Model) -> Result<Model> {
        let fm = self.final_model.as_ref().ok_or_else(|| {
            Error::param(
                "discovery",
                "has no final model (it was not run by discover)",
            )
        })?;
        let same_nominal = nominal.outputs.len() == 1
            && fm.outputs[0].terms.len() == nominal.outputs[0].terms.len() + self.effects.len()
            && fm.outputs[0]
                .terms
                .iter()
                .zip(&nominal.outputs[0].terms)
                .all(|(a, b)| a.monomial() == b.monomial());
        if !same_nominal {
            return Err(Error::param(
                "nominal",
                "not the nominal model this discovery was run with",
            ));
        }
        let mut m = fm.clone();
        let nt = nominal.outputs[0].terms.len();
        for (t, e) in m.outputs[0].terms[nt..].iter_mut().zip(&self.effects) {
            t.interval = term_interval(t.coefficient, e);
        }
        let section = serde_json::json!({
            "verdict": self.verdict,
            "effects": self.effects,
            "retuned": self.retuned,
            "closest": self.closest,
            "dropped": self.dropped,
            "nrmse_before": self.nrmse_before,
            "nrmse_after": self.nrmse_after,
        });
        m.extra.insert("discovery".into(), section);
        m.validate()?;
        Ok(m)
    }
}

/// The interval a term of the augmented model keeps: the bootstrap interval is the weak-form
/// estimate's, so only a coefficient that is still that estimate (bit for bit: the refit on
/// simulation error could not run and left the model as it was, see `refit`) keeps it. Beside a
/// refined coefficient it read as that coefficient's (-0.2416 next to [-0.2204, -0.2083] on
/// EMPS); the `discovery` section keeps both, the term its standard error.
fn term_interval(coefficient: f64, e: &FoundEffect) -> Option<[f64; 2]> {
    (coefficient == e.weak_coefficient).then_some(e.interval)
}

/// A gate's ratio for the summary, to three decimals (see [`or_diverged`]).
fn gate_ratio(x: f64) -> String {
    or_diverged(x, |x| format!("{x:.3}"))
}

/// A figure of the summary as `f` writes it, "diverged" where a free run was infinite and "-"
/// where none could be formed (the summary printed `inf` and exited 0).
fn or_diverged(x: f64, f: impl Fn(f64) -> String) -> String {
    if x.is_finite() {
        f(x)
    } else if x == f64::INFINITY {
        "diverged".into()
    } else {
        "-".into()
    }
}

#[cfg(test)]
mod tests {
    use super::{
        block_grams, blocking, blocking_within, contradicts, drifts, gate_ratio, gram_bytes,
        or_diverged, spread, term_interval, Blocking, FoundEffect, Rows, BLOCK, MIN_BLOCKS,
    };

    /// An effect singular on the data made the free run diverge: the summary said `ratio inf`
    /// (and `inf` in its runs' table).
    #[test]
    fn gate_ratios_that_are_not_finite_are_named() {
        assert_eq!(gate_ratio(0.81234), "0.812");
        assert_eq!(gate_ratio(f64::INFINITY), "diverged");
        assert_eq!(gate_ratio(f64::NAN), "-");
        assert_eq!(or_diverged(f64::INFINITY, |x| format!("{x}")), "diverged");
    }

    #[test]
    fn grouped_blocks_sum_to_the_same_gram_and_keep_their_halves() {
        // Runs of 3 to 40 windows, two columns.
        let rows: Vec<Rows> = (0..12)
            .map(|r| {
                let n = 3 + (r * 7) % 38;
                let col = |k: usize| (0..n).map(|i| ((i * 5 + r + k) % 9) as f64 - 4.0).collect();
                (col(2), vec![col(0), col(1)])
            })
            .collect();
        let runs: Vec<usize> = (0..12).collect();
        let plain = Blocking {
            blen: BLOCK,
            group: 1,
        };
        let (g1, l1) = block_grams(&rows, 2, &runs, plain);
        for group in [2, 3, 50] {
            let (g, l) = block_grams(&rows, 2, &runs, Blocking { blen: BLOCK, group });
            assert_eq!(g.len(), l.len());
            assert!(
                g.len() < g1.len() && g.len() * group >= g1.len(),
                "{group}: {}",
                g.len()
            );
            let total = |gs: &[super::Gram]| {
                gs.iter().fold(super::Gram::zeros(2), |mut a, b| {
                    a.add(b);
                    a
                })
            };
            let (a, b) = (total(&g1), total(&g));
            assert_eq!(a.rows, b.rows);
            assert!((a.g.clone() - b.g.clone()).abs().max() < 1e-9 && (a.rr - b.rr).abs() < 1e-9);
            // Each half's rows stay in blocks of that half.
            let half_rows = |gs: &[super::Gram], ls: &[bool], h: bool| -> usize {
                gs.iter()
                    .zip(ls)
                    .filter(|(_, &x)| x == h)
                    .map(|(g, _)| g.rows)
                    .sum()
            };
            for h in [false, true] {
                assert_eq!(half_rows(&g1, &l1, h), half_rows(&g, &l, h), "{group} {h}");
            }
        }
    }

    #[test]
    fn spread_does_not_overflow_near_the_magnitude_limit() {
        let x: Vec<f64> = (0..1000).map(|i| (i as f64 * 0.37).sin()).collect();
        let plain = spread(&x);
        let mean = x.iter().sum::<f64>() / 1000.0;
        let direct = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 1000.0).sqrt();
        assert!((plain - direct).abs() < 1e-12 * direct);
        for scale in [1e160, 1e300, 1e-300] {
            let big: Vec<f64> = x.iter().map(|v| v * scale).collect();
            let s = spread(&big);
            assert!(
                s.is_finite() && (s / scale - plain).abs() < 1e-9 * plain,
                "{scale:e}: {s:e}"
            );
        }
        assert_eq!(spread(&[3.0; 10]), 0.0);
        assert_eq!(spread(&[]), 0.0);
        assert!(spread(&[1.0, f64::INFINITY]).is_nan());
    }

    #[test]
    fn bootstrap_blocks_stay_within_their_memory_budget() {
        // The benchmarks' sizes keep blocks of BLOCK windows (Silverbox: 65,000 samples at most
        // one window each, some 40 columns).
        let one = Blocking {
            blen: BLOCK,
            group: 1,
        };
        assert_eq!(blocking(&[65_000], 40), one);
        assert_eq!(blocking(&[16_000; 4], 40), one);
        assert_eq!(blocking(&[], 40), one);
        // 10^6 samples at a stride of 5 and 300 columns: 25,000 blocks of 721 KB (18 GB) before.
        let b = blocking(&[200_000], 300);
        assert!(
            b.blen.is_multiple_of(BLOCK) && b.blen > BLOCK && b.group == 1,
            "{b:?}"
        );
        // Long blocks stop at the middle of a short run (rounded down to whole BLOCKs).
        let b = Blocking { blen: 24, group: 1 };
        assert_eq!((b.run_blen(40), b.run_blen(17), b.run_blen(9)), (16, 8, 8));
        assert_eq!(b.run_blen(1000), 24);
        // So wide that the budget holds fewer than MIN_BLOCKS: MIN_BLOCKS of them.
        let b = blocking(&[1_000_000], 3000);
        assert_eq!(1_000_000usize.div_ceil(b.blen), MIN_BLOCKS);
    }

    /// Rows of `lens` windows, two columns.
    fn rows_of(lens: &[usize]) -> Vec<Rows> {
        lens.iter()
            .enumerate()
            .map(|(r, &n)| {
                let col = |k: usize| (0..n).map(|i| ((i * 5 + r + k) % 9) as f64 - 4.0).collect();
                (col(2), vec![col(0), col(1)])
            })
            .collect()
    }

    #[test]
    fn blocks_counted_as_built_stay_within_a_budget_and_keep_both_halves() {
        // A budget of MIN_BLOCKS Grams of two columns, over shapes that broke the first design:
        // many short runs (each ends a block), runs of exactly two blocks (early, late, early,
        // late: nothing consecutive to merge), and one long run.
        let budget = MIN_BLOCKS * gram_bytes(2);
        for lens in [
            vec![12; 5_000],
            vec![16; 3_000],
            vec![200; 300],
            vec![40_000],
            vec![9; 2_000],
        ] {
            let b = blocking_within(&lens, 2, budget);
            let runs: Vec<usize> = (0..lens.len()).collect();
            let (g, late) = block_grams(&rows_of(&lens), 2, &runs, b);
            assert!(
                g.len() <= MIN_BLOCKS + 2,
                "{} runs of {}: {} Grams, {b:?}",
                lens.len(),
                lens[0],
                g.len()
            );
            assert!(
                late.iter().any(|&l| l) && late.iter().any(|&l| !l),
                "{lens:?}: one half only"
            );
            let rows: usize = g.iter().map(|x| x.rows).sum();
            assert_eq!(rows, lens.iter().sum::<usize>());
        }
    }

    #[test]
    fn drift_needs_a_large_and_significant_change() {
        // An offset fitted to a sensor ramp: one third against two thirds, z = 5.8.
        assert!(drifts(0.026, 0.071, 5.8));
        // The tank's outflow law near empty: significant but 16 % apart.
        assert!(!drifts(-2.17, -1.84, 3.8));
        // Large but not significant.
        assert!(!drifts(0.03, 0.09, 2.0));
        assert!(!drifts(f64::NAN, f64::NAN, f64::NAN));
        assert!(!drifts(0.03, 0.09, f64::NAN));
    }

    #[test]
    fn a_term_keeps_the_bootstrap_interval_only_beside_its_own_estimate() {
        let e = FoundEffect {
            family: "coulomb_friction".into(),
            formula: "sign(y_d1)".into(),
            coefficient: -0.2416,
            weak_coefficient: -0.2136,
            interval: [-0.2204, -0.2083],
            inclusion: 1.0,
            aliases: Vec::new(),
            reading: None,
            halves: [f64::NAN; 2],
            halves_z: f64::NAN,
            simulation_share: None,
        };
        assert_eq!(
            term_interval(-0.2416, &e),
            None,
            "refined: not its interval"
        );
        assert_eq!(term_interval(-0.2136, &e), Some([-0.2204, -0.2083]));
    }

    #[test]
    fn refined_sign_against_the_interval() {
        // Stribeck beside Coulomb at 10 % noise: [0.27, 0.52] refined to -0.10.
        assert!(contradicts(&[0.27, 0.52], -0.10));
        assert!(contradicts(&[-0.5, -0.2], 0.01));
        // Outside the interval but on its side, or an interval that holds zero: no contradiction.
        assert!(!contradicts(&[0.27, 0.52], 0.9));
        assert!(!contradicts(&[-0.46, -0.33], -0.51));
        assert!(!contradicts(&[-0.1, 0.2], -5.0));
    }
}
