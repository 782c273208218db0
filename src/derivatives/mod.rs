//! Derivative reconstruction: y, y', ..., y^(K) at every sample of noisy, uniformly sampled
//! runs, each with a per-sample standard deviation.
//!
//! # Method
//! 1. *Prior.* The signal is the first state of a chain of m = K + 3 integrators driven by white
//!    noise, observed in white noise (`statespace`); in scaled time the two intensities are
//!    equal, so one number, the scaled step h, sets the smoothing level.
//! 2. *Tuning.* h maximises the profile likelihood of the Kalman innovations over all runs of a
//!    record set jointly (`tune`); the noise variance comes out in closed form.
//! 3. *Smoothing.* The Rauch-Tung-Striebel smoother (`smoother`) gives posterior means and
//!    variances of every derivative. The covariance recursions are data independent: they are
//!    computed once per run length and reused by every run, so each run costs O(N m^2).
//! 4. *Local adaptivity.* Fast transients need less smoothing than the rest of a run, slow
//!    stretches more. Smoothers at h*2^-0.5, h, h*2^0.5, ..., h*2^3 are compared locally by the
//!    sum of their innovation log-likelihoods, the rougher ones against h in a window of about
//!    2/h samples, the smoother one against h in a window six times longer, and blended with
//!    the resulting soft weights; the blend's variance includes the spread between levels, so
//!    sigma grows where the levels disagree (transients shorter than tau among them).
//! 5. *Ends.* Near the first and last samples the integrator chain extrapolates high derivatives
//!    with a large variance; there the estimate is blended into that of a stationary
//!    (Matern-type) prior with the same h, which shrinks towards zero instead, on runs long
//!    enough to have a middle between the two ends (`END_RUN_WIDTHS`; a drift over the whole
//!    run tunes so small an h that it has none), and at each end only if held-out samples there
//!    do not reject it (`end_prior_holds`: a step response recorded from the step does).
//! 6. *Exponential sums.* A run that is, to the noise level, a short sum of (damped)
//!    exponentials and sinusoids (a linear plant under a multisine, a free oscillation) gets a
//!    parametric model instead ([`expsum`]): poles by ESPRIT, amplitudes and poles by least
//!    squares, used only when its order is unambiguous, its residual white and its derivatives
//!    inside the smoother's band. It removes the smoother's bandwidth trade-off and end effects
//!    on such runs; everything else keeps the smoother.
//!
//! # Assumptions
//! Uniform sampling, white measurement noise, and a signal that is smooth at the scale of a few
//! samples. Each run is smoothed on its own: nothing crosses a run boundary (only the two
//! tuning numbers are shared). Time and memory are O(N) per run.

pub mod benchmark;
pub mod expsum;
mod kernel;
pub mod score;
// The numerical internals (state-space prior, tuning, smoother) are private: their functions
// assume the chain sizes and levels `derive` checks once (m in 2..=11, lambda > 0 where a
// stationary prior is asked for).
pub(crate) mod smoother;
pub(crate) mod statespace;
pub(crate) mod tune;

use crate::error::{Error, Result};
use kernel::Cov;

/// Highest supported derivative order.
pub const MAX_ORDER: usize = 8;

/// Smoothing levels tried locally, in octaves above the globally tuned one (negative: smoother).
const LADDER: [f64; 6] = [0.0, 0.5, 1.0, 2.0, 3.0, -0.5];

/// Local evidence for the smoother level is gathered over this many times the window of the
/// rougher ones: over-smoothing costs little likelihood per sample, so short windows take it by
/// chance. `cargo bench --bench derivative_windows` compares 0 (no smoother level),
/// 2 and 6 on the shared signals: at 2 sines and sys3 get worse at nearly every order (up to 2x);
/// at 6 only the chirp's slow start takes it, and the chirp's error drops 7-43 %.
const SMOOTH_WINDOW: f64 = 6.0;

/// The stationary end prior is used only on runs longer than this many end widths (1/h
/// samples): its blend fades out two widths from each end, so shorter runs have no middle left
/// to the chain, and on a drift over the whole run (a tiny h) it would pull every derivative
/// towards zero. The shared signals have runs of 28 to 150 widths.
const END_RUN_WIDTHS: f64 = 4.0;

/// The end prior is left out at an end where the chain alone predicts the held-out samples
/// with less than this share of the prior's error (see `end_prior_holds`), for the derivatives
/// up to END_CV_ORDER: the held-out values speak mostly for those; higher ones keep the prior,
/// which bounds their extrapolation (measured on decaying oscillations started at their peak:
/// orders 1-2 up to 5x better without the prior there, order 4 up to 4x worse).
const END_CV_RATIO: f64 = 0.33;
const END_CV_ORDER: usize = 2;

/// Largest scaled step: beyond a few units the smoother interpolates the samples and the
/// integrator chain's transition matrix only loses precision.
const H_MAX: f64 = 4.0;

/// Largest scaled step a caller may impose.
const H_OVERRIDE_MAX: f64 = 1e3;

/// Optional overrides; the defaults self-tune everything.
#[derive(Debug, Clone)]
pub struct DerivativeOptions {
    /// Number of states in the prior chain (default: max_order + 3, at least 5).
    pub states: Option<usize>,
    /// Fixed scaled step h (skips tuning).
    pub h: Option<f64>,
    /// Damping of the stationary prior used near the ends, in scaled time.
    pub end_lambda: f64,
    /// Blend smoothing levels locally by their local likelihood.
    pub adaptive: bool,
    /// Half-width of the local likelihood window, in units of 1/h samples.
    pub window: f64,
    /// Blend into the stationary-prior estimate near the ends.
    pub end_blend: bool,
    /// With `end_blend`: check the prior at each end on held-out samples (`end_prior_holds`);
    /// off, it is used at both ends of every run long enough to have a middle.
    pub end_check: bool,
    /// Window of the smoother level's local likelihood, in units of `window`; 0 leaves the
    /// smoother level out.
    pub smooth_window: f64,
    /// Replace the smoother's estimate of a run by an exponential-sum model where one passes
    /// the checks of [`expsum`].
    pub exp_sum: bool,
    /// Runs (indices into the runs given) whose data tune the smoothing level and the noise
    /// variance; `None` tunes on all. An identification passes its training runs, so that test
    /// runs never influence a fit.
    pub tune_runs: Option<Vec<usize>>,
}

impl Default for DerivativeOptions {
    fn default() -> Self {
        DerivativeOptions {
            states: None,
            h: None,
            end_lambda: 0.5,
            adaptive: true,
            window: 2.0,
            end_blend: true,
            end_check: true,
            smooth_window: SMOOTH_WINDOW,
            exp_sum: true,
            tune_runs: None,
        }
    }
}

/// Estimates of y^(k) for k = 0..=max_order and their standard deviations, for one run.
#[derive(Debug, Clone)]
pub struct Derivatives {
    pub tau: f64,
    /// `values[k][i]`: estimate of the k-th derivative at sample i (k = 0 is the smoothed signal).
    pub values: Vec<Vec<f64>>,
    /// `sigma[k][i]`: standard deviation of `values[k][i]`.
    pub sigma: Vec<Vec<f64>>,
    /// Estimated measurement noise standard deviation.
    pub noise_sd: f64,
    /// Tuned scaled step (smoothing level) and number of states.
    pub h: f64,
    pub states: usize,
    /// Number of exponential terms (a sinusoid counts two) when the run's estimate comes from an
    /// exponential-sum model ([`expsum`]) instead of the smoother.
    pub exp_terms: Option<usize>,
}

/// Fewest samples a run needs for derivatives up to `max_order`.
pub fn min_samples(max_order: usize) -> usize {
    2 * (max_order + 3) + 4
}

/// Self-tuning derivatives of one run. Refuses what [`differentiate_runs`] refuses.
///
/// ```
/// // y = sin(2 t) sampled every 10 ms with noise of 1e-3 (a fixed sequence).
/// let tau = 0.01;
/// let y: Vec<f64> = (0..600)
///     .map(|k| (2.0 * k as f64 * tau).sin() + 1e-3 * ((k * 7919 % 101) as f64 / 50.0 - 1.0))
///     .collect();
/// let d = ctsid::derivatives::differentiate(&y, tau, 2)?;
/// // y'' = -4 sin(2 t): away from the ends, within a few per cent of its amplitude.
/// let worst = (100..500)
///     .map(|k| (d.values[2][k] + 4.0 * (2.0 * k as f64 * tau).sin()).abs())
///     .fold(0.0, f64::max);
/// assert!(worst < 0.2, "{worst}");
/// // Each estimate comes with its standard deviation.
/// assert!(d.sigma[2][300] > 0.0);
/// # Ok::<(), ctsid::Error>(())
/// ```
pub fn differentiate(y: &[f64], tau: f64, max_order: usize) -> Result<Derivatives> {
    differentiate_with(y, tau, max_order, &DerivativeOptions::default())
}

/// One run, with overrides. Refuses what [`differentiate_runs`] refuses.
pub fn differentiate_with(
    y: &[f64],
    tau: f64,
    max_order: usize,
    opts: &DerivativeOptions,
) -> Result<Derivatives> {
    Ok(differentiate_runs(&[y], tau, max_order, opts)?.remove(0))
}

/// What [`differentiate_runs`] refuses (see its docs); the number of smoother states.
fn check_request(
    runs: &[&[f64]],
    tau: f64,
    max_order: usize,
    opts: &DerivativeOptions,
) -> Result<usize> {
    crate::records::check_tau(tau)?;
    if max_order > MAX_ORDER {
        return Err(Error::param(
            "order",
            format!("{max_order}; at most {MAX_ORDER} is supported"),
        ));
    }
    let m = opts.states.unwrap_or((max_order + 3).max(5));
    if m <= max_order || !(kernel::MIN_STATES..=kernel::MAX_STATES).contains(&m) {
        return Err(Error::param(
            "states",
            format!(
                "{m} states cannot give order {max_order}; use {}..={}",
                max_order + 1,
                kernel::MAX_STATES
            ),
        ));
    }
    if runs.is_empty() {
        return Err(Error::InvalidData("no runs to differentiate".into()));
    }
    let min = min_samples(max_order);
    for (r, y) in runs.iter().enumerate() {
        if y.len() < min {
            return Err(Error::RunTooShort {
                run: r.to_string(),
                len: y.len(),
                min,
                what: format!("derivatives up to order {max_order}"),
            });
        }
        if let Some(i) = crate::records::first_unusable(y) {
            return Err(Error::InvalidData(format!(
                "run {r}, sample {i}: {}",
                crate::records::unusable_reason(y[i])
            )));
        }
    }
    if let Some(h) = opts.h {
        // Tuning stops at H_MAX; an override may go further (the identification's equation
        // smoothing does), but not so far that (h / tau)^k leaves f64.
        if !(h > 0.0 && h <= H_OVERRIDE_MAX) {
            return Err(Error::param(
                "h",
                format!("{h:?}; give a scaled step in (0, {H_OVERRIDE_MAX}]"),
            ));
        }
    }
    // 0 turns the stationary end prior into the integrator chain, which has no stationary
    // covariance; the range keeps its characteristic polynomial well scaled.
    if opts.end_blend && !(1e-3..=1e3).contains(&opts.end_lambda) {
        return Err(Error::param(
            "end_lambda",
            format!("{:?}; give a damping in [1e-3, 1e3]", opts.end_lambda),
        ));
    }
    crate::util::finite_nonneg("smooth_window", opts.smooth_window)?;
    Ok(m)
}

/// Each run as its mean with zero derivatives and zero uncertainty: the result for a constant
/// run, and the start every other run's estimates overwrite.
fn constant_estimates(
    runs: &[&[f64]],
    means: &[f64],
    tau: f64,
    max_order: usize,
    m: usize,
) -> Vec<Derivatives> {
    runs.iter()
        .zip(means)
        .map(|(y, &mu)| {
            let n = y.len();
            let mut values = vec![vec![0.0; n]; max_order + 1];
            values[0] = vec![mu; n];
            Derivatives {
                tau,
                values,
                sigma: vec![vec![0.0; n]; max_order + 1],
                noise_sd: 0.0,
                h: 1.0,
                states: m,
                exp_terms: None,
            }
        })
        .collect()
}

/// Several runs of one record set, tuned jointly and smoothed separately. Refuses a tau that
/// [`crate::records::check_tau`] refuses, a `max_order` above [`MAX_ORDER`], a number of states not
/// above `max_order` or outside 2..=11, an empty run list, a run shorter than [`min_samples`], a
/// NaN, infinite or too large sample, an `h` outside (0, 1e3], an `end_lambda` outside [1e-3, 1e3]
/// when `end_blend` is on, and a `smooth_window` that is negative or not finite.
pub fn differentiate_runs(
    runs: &[&[f64]],
    tau: f64,
    max_order: usize,
    opts: &DerivativeOptions,
) -> Result<Vec<Derivatives>> {
    let m = check_request(runs, tau, max_order, opts)?;
    let means: Vec<f64> = runs
        .iter()
        .map(|y| y.iter().sum::<f64>() / y.len() as f64)
        .collect();
    let centred: Vec<Vec<f64>> = runs
        .iter()
        .zip(&means)
        .map(|(y, m)| y.iter().map(|v| v - m).collect())
        .collect();
    // Constant runs carry no information for tuning; they are returned exactly.
    let live: Vec<usize> = (0..runs.len())
        .filter(|&r| centred[r].iter().any(|v| *v != 0.0))
        .collect();
    let live_y: Vec<&[f64]> = live.iter().map(|&r| centred[r].as_slice()).collect();
    // The runs that tune: the chosen ones among the live, or all live runs if none is. (When
    // every chosen run is constant, their estimates are exact whatever the tuning, so the other
    // runs' level cannot reach a fit made on the chosen ones.)
    let tune_y: Vec<&[f64]> = match &opts.tune_runs {
        Some(t) if live.iter().any(|r| t.contains(r)) => live
            .iter()
            .filter(|r| t.contains(r))
            .map(|&r| centred[r].as_slice())
            .collect(),
        _ => live_y.clone(),
    };

    let mut out = constant_estimates(runs, &means, tau, max_order, m);
    if live.is_empty() {
        return Ok(out);
    }

    let (h, fit) = match opts.h {
        Some(h) => (h, tune::evaluate(m, h, 0.0, &tune_y)),
        None => tune::best_h(m, &tune_y, (1e-4f64).ln(), H_MAX.ln()),
    };
    // Constant runs share the record set's sensor and smoothing level too (callers take h
    // from any run, the first among them).
    for d in out.iter_mut() {
        d.h = h;
        d.noise_sd = fit.sigma2.sqrt();
    }
    let blend = Blend::new((m, h, fit.sigma2), (tau, max_order), opts, &live_y, &tune_y);
    for (li, &r) in live.iter().enumerate() {
        let y = live_y[li];
        let (mut mean, mut second) = blend.levels(y);
        blend.ends(y, &mut mean, &mut second);
        blend.finish(&mut out[r], y, mean, &second, means[r]);
    }
    check_range(&out, max_order)?;
    Ok(out)
}

/// Refuses derivatives beyond [`crate::records::MAX_MAGNITUDE`], the bound every sample obeys:
/// their squares (the smoother's second moments) overflow, and a sigma came out 0 where its
/// variance was `inf - inf` (a signal of 1e120 at tau = 1e-12, differentiated eight times).
fn check_range(out: &[Derivatives], max_order: usize) -> Result<()> {
    for d in out {
        for k in 0..=max_order {
            let big = d.values[k]
                .iter()
                .chain(&d.sigma[k])
                .any(|v| v.is_nan() || v.abs() > crate::records::MAX_MAGNITUDE);
            if big {
                return Err(Error::InvalidData(format!(
                    "derivative {k} of the signal goes beyond {:e} (or is not finite): rescale the signal or give tau in larger units",
                    crate::records::MAX_MAGNITUDE
                )));
            }
        }
    }
    Ok(())
}

/// The covariances of `covs` for runs of length `n` (every live run's length is there).
fn pick(covs: &[(usize, Cov)], n: usize) -> usize {
    covs.iter().position(|(l, _)| *l == n).unwrap()
}

/// What every live run is smoothed with: the smoothing levels and their covariances per run
/// length, and the stationary end prior with its held-out check (see the module docs).
struct Blend<'a> {
    m: usize,
    h: f64,
    sigma2: f64,
    tau: f64,
    max_order: usize,
    opts: &'a DerivativeOptions,
    levels: Vec<f64>,
    level_covs: Vec<Vec<(usize, Cov)>>,
    end_covs: Option<Vec<(usize, Cov)>>,
    end_sigma2: Option<f64>,
    end_width: f64,
    end_check: Vec<(usize, Cov, Cov)>,
}

impl<'a> Blend<'a> {
    fn new(
        (m, h, sigma2): (usize, f64, f64),
        (tau, max_order): (f64, usize),
        opts: &'a DerivativeOptions,
        live_y: &[&[f64]],
        tune_y: &[&[f64]],
    ) -> Blend<'a> {
        let mut levels: Vec<f64> = if opts.adaptive {
            LADDER
                .iter()
                .filter(|&&o| o >= 0.0 || opts.smooth_window > 0.0)
                .map(|o| h * 2f64.powf(*o))
                .filter(|&l| l == h || l <= H_MAX)
                .collect()
        } else {
            vec![h]
        };
        levels.dedup();
        // Covariances per (level, run length), shared by all runs of that length.
        let mut lengths: Vec<usize> = live_y.iter().map(|y| y.len()).collect();
        lengths.sort_unstable();
        lengths.dedup();
        let cov_for = |hl: f64, lambda: f64| -> Vec<(usize, Cov)> {
            let d = statespace::discretise(m, hl, lambda);
            lengths
                .iter()
                .map(|&n| (n, Cov::new(&d, n, true)))
                .collect()
        };
        let level_covs: Vec<Vec<(usize, Cov)>> =
            levels.iter().map(|&hl| cov_for(hl, 0.0)).collect();
        let end_covs = opts.end_blend.then(|| cov_for(h, opts.end_lambda));
        let end_sigma2 = opts
            .end_blend
            .then(|| tune::evaluate(m, h, opts.end_lambda, tune_y).sigma2);
        let mut blend = Blend {
            m,
            h,
            sigma2,
            tau,
            max_order,
            opts,
            levels,
            level_covs,
            end_covs,
            end_sigma2,
            end_width: (1.0 / h).max(2.0),
            end_check: Vec::new(),
        };
        if blend.end_sigma2.is_some() {
            blend.end_check = blend.end_check_covs(&lengths);
        }
        blend
    }

    /// Held-out check of the end prior (see `end_prior_holds`): round(1/h) samples at each end,
    /// none when fewer than the states (too few to overrule the prior).
    fn held_out(&self, n: usize) -> Option<usize> {
        let w = ((1.0 / self.h).round() as usize).min(n / 8).max(1);
        (self.opts.end_check && w >= self.m.max(5) && n as f64 > END_RUN_WIDTHS * self.end_width)
            .then_some(w)
    }

    /// The chain and the stationary prior's filters on each run length less its held-out end.
    fn end_check_covs(&self, lengths: &[usize]) -> Vec<(usize, Cov, Cov)> {
        let chain = statespace::discretise(self.m, self.h, 0.0);
        let stationary = statespace::discretise(self.m, self.h, self.opts.end_lambda);
        lengths
            .iter()
            .filter_map(|&n| {
                let k = n - self.held_out(n)?;
                Some((
                    n,
                    Cov::new(&chain, k, false),
                    Cov::new(&stationary, k, false),
                ))
            })
            .collect()
    }

    /// Mean and second moment of the blend of the smoothing levels, order by order.
    fn levels(&self, y: &[f64]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let (n, max_order, sigma2) = (y.len(), self.max_order, self.sigma2);
        let weights = level_weights(
            &self.levels,
            &self.level_covs,
            y,
            sigma2,
            (self.opts.window / self.h).round() as usize,
            self.opts.smooth_window,
            pick,
        );
        let mut mean = vec![vec![0.0; n]; max_order + 1];
        let mut second = vec![vec![0.0; n]; max_order + 1];
        for (j, &hl) in self.levels.iter().enumerate() {
            let covs = &self.level_covs[j];
            let cov = &covs[pick(covs, n)].1;
            let scale: Vec<f64> = (0..=max_order)
                .map(|k| (hl / self.tau).powi(k as i32))
                .collect();
            smooth_two_way(cov, y, |i, x, var| {
                let w = weights[j][i];
                if w == 0.0 {
                    return;
                }
                for k in 0..=max_order {
                    let v = x[k] * scale[k];
                    mean[k][i] += w * v;
                    second[k][i] += w * (var[k] * sigma2 * scale[k] * scale[k] + v * v);
                }
            });
        }
        (mean, second)
    }

    /// Near the ends of a long enough run, the stationary prior's estimate blended in, as far as
    /// the chain is less certain than it and its held-out check does not reject it.
    fn ends(&self, y: &[f64], mean: &mut [Vec<f64>], second: &mut [Vec<f64>]) {
        let n = y.len();
        let has_middle = n as f64 > END_RUN_WIDTHS * self.end_width;
        let (Some(covs), Some(s2), true) = (&self.end_covs, self.end_sigma2, has_middle) else {
            return;
        };
        let (h, tau, max_order) = (self.h, self.tau, self.max_order);
        let cov = &covs[pick(covs, n)].1;
        let scale: Vec<f64> = (0..=max_order).map(|k| (h / tau).powi(k as i32)).collect();
        let width = self.end_width;
        let holds = match (
            self.held_out(n),
            self.end_check.iter().find(|(l, _, _)| *l == n),
        ) {
            (Some(w), Some((_, chain, stationary))) => {
                let reversed: Vec<f64> = y.iter().rev().copied().collect();
                [&reversed[..], y].map(|run| {
                    end_prior_holds(chain, stationary, run, w, self.sigma2, s2, h / tau, tau)
                })
            }
            _ => [true, true],
        };
        smooth_two_way(cov, y, |i, x, var| {
            let b = end_weight(i.min(n - 1 - i) as f64, width);
            if b == 0.0 {
                return;
            }
            let rejected = !holds[(i >= n / 2) as usize];
            for k in 0..=max_order {
                if rejected && k <= END_CV_ORDER {
                    continue;
                }
                let v = x[k] * scale[k];
                let vm = var[k] * s2 * scale[k] * scale[k];
                // Trust the stationary prior only as far as the chain is less certain than it
                // (an exact polynomial keeps the chain's estimate).
                let vi = (second[k][i] - mean[k][i] * mean[k][i]).max(0.0);
                let bk = b * vi / (vi + vm).max(1e-300);
                mean[k][i] = (1.0 - bk) * mean[k][i] + bk * v;
                second[k][i] = (1.0 - bk) * second[k][i] + bk * (vm + v * v);
            }
        });
    }

    /// Run `d`'s values and sigmas from the blend's moments (or from a sum of exponentials that
    /// agrees with them), the run's mean `offset` added back.
    fn finish(
        &self,
        d: &mut Derivatives,
        y: &[f64],
        mut mean: Vec<Vec<f64>>,
        second: &[Vec<f64>],
        offset: f64,
    ) {
        let (n, max_order) = (y.len(), self.max_order);
        let sd: Vec<Vec<f64>> = (0..=max_order)
            .map(|k| {
                (0..n)
                    .map(|i| (second[k][i] - mean[k][i] * mean[k][i]).max(0.0).sqrt())
                    .collect()
            })
            .collect();
        let model = self
            .opts
            .exp_sum
            .then(|| expsum::fit(y, self.tau, self.sigma2, self.h))
            .flatten()
            .map(|es| (es.terms(), es.evaluate(n, max_order)))
            .filter(|(_, (v, s))| expsum::agrees(v, s, &mean, &sd));
        if let Some((terms, (v, s))) = model {
            mean = v;
            d.sigma = s;
            d.exp_terms = Some(terms);
        } else {
            d.sigma = sd;
        }
        for k in 0..=max_order {
            for i in 0..n {
                d.values[k][i] = mean[k][i] + if k == 0 { offset } else { 0.0 };
            }
        }
    }
}

/// Whether the stationary end prior predicts the last `w` samples of `y`, held out, well enough:
/// the chain alone must not beat it by more than `END_CV_RATIO`. Both estimate every derivative
/// at the last sample kept, the prior's as the end blend would there (one smoothing level); each
/// extrapolates by its Taylor series over the held-out samples. The prior assumes the end looks
/// like the middle; a step response recorded from the step is steepest at its start, and there
/// the chain's extrapolation wins by far (1 % noise: 3.7 against 18 noise standard deviations),
/// while on multisines and chirps the prior's wins or ties (`chain`, `stationary`: covariances
/// for `y.len() - w` samples, the filter part suffices; `rate` = h / tau).
#[allow(clippy::too_many_arguments)]
fn end_prior_holds(
    chain: &Cov,
    stationary: &Cov,
    y: &[f64],
    w: usize,
    sigma2: f64,
    sigma2_stationary: f64,
    rate: f64,
    tau: f64,
) -> bool {
    let kept = &y[..y.len() - w];
    let last = kept.len() - 1;
    let at_last = |cov: &Cov, s2: f64| -> (Vec<f64>, Vec<f64>) {
        let x = cov.filter_last(kept);
        let scale: Vec<f64> = (0..x.len()).map(|k| rate.powi(k as i32)).collect();
        let v: Vec<f64> = x.iter().zip(&scale).map(|(a, s)| a * s).collect();
        let var: Vec<f64> = cov
            .var(last)
            .iter()
            .zip(&scale)
            .map(|(a, s)| a * s2 * s * s)
            .collect();
        (v, var)
    };
    let (c, vc) = at_last(chain, sigma2);
    let (p, vp) = at_last(stationary, sigma2_stationary);
    let blended: Vec<f64> = (0..c.len())
        .map(|k| {
            let b = vc[k] / (vc[k] + vp[k]).max(1e-300);
            (1.0 - b) * c[k] + b * p[k]
        })
        .collect();
    let error = |d: &[f64]| -> f64 {
        (1..=w)
            .map(|s| {
                let dt = s as f64 * tau;
                let (mut term, mut pred) = (1.0, 0.0);
                for (k, dk) in d.iter().enumerate() {
                    if k > 0 {
                        term *= dt / k as f64;
                    }
                    pred += term * dk;
                }
                (pred - y[last + s]).powi(2)
            })
            .sum::<f64>()
    };
    let (e_chain, e_prior) = (error(&c), error(&blended));
    !(e_chain.is_finite() && e_prior.is_finite()) || e_chain.sqrt() >= END_CV_RATIO * e_prior.sqrt()
}

/// Weight of the stationary-prior estimate at `dist` samples from the nearest end: 1 within
/// half a bandwidth, fading linearly to 0 at two bandwidths.
fn end_weight(dist: f64, width: f64) -> f64 {
    if dist <= 0.5 * width {
        1.0
    } else if dist >= 2.0 * width {
        0.0
    } else {
        1.0 - (dist - 0.5 * width) / (1.5 * width)
    }
}

/// Soft weights of the smoothing levels at every sample (`levels[0]` is the tuned one): softmax
/// of windowed sums of the innovation log-likelihood, over `half` samples each side for the
/// rougher levels and `smooth_window` times that for the smoother one, then averaged over half
/// a window so that switches are gradual.
fn level_weights(
    levels: &[f64],
    covs: &[Vec<(usize, Cov)>],
    y: &[f64],
    sigma2: f64,
    half: usize,
    smooth_window: f64,
    pick: impl Fn(&[(usize, Cov)], usize) -> usize,
) -> Vec<Vec<f64>> {
    let n = y.len();
    if levels.len() == 1 {
        return vec![vec![1.0; n]];
    }
    let half = half.clamp(2, (n / 2).max(2));
    let long = ((smooth_window * half as f64) as usize).clamp(2, (n / 2).max(2));
    let lls: Vec<Vec<f64>> = covs
        .iter()
        .map(|c| {
            let mut ll = vec![0.0; n];
            c[pick(c, n)].1.local_loglik(y, sigma2, &mut ll);
            ll
        })
        .collect();
    // Softmax of windowed log-likelihood sums over the levels in `group`; within `half` of an
    // end the local evidence rests on few samples and chance favours other levels than the
    // tuned one, so the tuned one (index 0) is kept there (the stationary-prior blend takes over).
    let softmax = |group: &[usize], half: usize| -> Vec<Vec<f64>> {
        let sums: Vec<Vec<f64>> = group.iter().map(|&j| window_sum(&lls[j], half)).collect();
        let mut w = vec![vec![0.0; n]; group.len()];
        for i in 0..n {
            if i.min(n - 1 - i) < half {
                w[0][i] = 1.0;
                continue;
            }
            let best = sums.iter().map(|s| s[i]).fold(f64::NEG_INFINITY, f64::max);
            let z: f64 = sums.iter().map(|s| (s[i] - best).exp()).sum();
            for g in 0..group.len() {
                w[g][i] = (sums[g][i] - best).exp() / z;
            }
        }
        w
    };
    // Rougher levels compete with the tuned one over short windows (transients are short);
    // smoother ones over long windows (over-smoothing costs little likelihood per sample).
    let h = levels[0];
    let rough: Vec<usize> = (0..levels.len()).filter(|&j| levels[j] >= h).collect();
    let smooth: Vec<usize> = std::iter::once(0)
        .chain((0..levels.len()).filter(|&j| levels[j] < h))
        .collect();
    let wr = softmax(&rough, half);
    let ws = softmax(&smooth, long);
    let mut w = vec![vec![0.0; n]; levels.len()];
    for (g, &j) in rough.iter().enumerate() {
        for i in 0..n {
            w[j][i] = ws[0][i] * wr[g][i];
        }
    }
    for (g, &j) in smooth.iter().enumerate().skip(1) {
        w[j].clone_from_slice(&ws[g]);
    }
    let cnt = window_sum(&vec![1.0; n], half / 2);
    for wj in w.iter_mut() {
        let s = window_sum(wj, half / 2);
        for i in 0..n {
            wj[i] = s[i] / cnt[i];
        }
    }
    w
}

/// Sum over the window [i - half, i + half] (clipped at the ends), by prefix sums.
fn window_sum(v: &[f64], half: usize) -> Vec<f64> {
    let n = v.len();
    let mut pre = vec![0.0; n + 1];
    for i in 0..n {
        pre[i + 1] = pre[i] + v[i];
    }
    (0..n)
        .map(|i| pre[(i + half + 1).min(n)] - pre[i.saturating_sub(half)])
        .collect()
}

/// Smoothed states and their variances at every sample, from two passes.
///
/// The integrator chain's initial state is diffuse, which a covariance-form filter can only
/// approximate (a large but finite prior variance, in units of the noise variance), so the
/// estimates carry a small start-up bias for the first few bandwidths; at the far end there is
/// none. Smoothing the time-reversed run as well, and taking each half from the pass whose start
/// is far away, removes it (in the middle the two passes agree to rounding). Odd derivatives
/// change sign under time reversal.
fn smooth_two_way(cov: &Cov, y: &[f64], mut emit: impl FnMut(usize, &[f64], &[f64])) {
    let n = y.len();
    let half = n / 2;
    cov.smooth(y, |i, x| {
        if i >= half {
            emit(i, x, cov.var(i));
        }
    });
    let rev: Vec<f64> = y.iter().rev().copied().collect();
    let mut flipped = Vec::new();
    cov.smooth(&rev, |j, x| {
        let i = n - 1 - j;
        if i < half {
            flipped.clear();
            flipped.extend(
                x.iter()
                    .enumerate()
                    .map(|(k, v)| if k % 2 == 1 { -v } else { *v }),
            );
            emit(i, &flipped, cov.var(j));
        }
    });
}
