//! Following a reference: reference signals (a file of (time, reference) or the built-in
//! step-and-ramp scenario), the source paper's exponential-profile law beside the pole
//! placement, blocking, and the figures a tracking run is judged by.
//!
//! # The exponential-profile law
//! The paper's step 4 (Alamir, "On continuous-time sparse identification of nonlinear
//! polynomial systems"): at each decision instant the tracking error `e = y - r` and its
//! estimated derivatives are matched by a profile `Psi(t) = sum_{j=1..n} alpha_j exp(-sigma j t)`
//! (`Psi^(k)(0) = e^(k)`, k < n), and the input is the admissible value whose model prediction
//! of `y^(n)` is closest to what the profile asks for:
//! `u* = argmin_{v in [u_min, u_max]} |r^(n) + Psi^(n)(0) - P(x_hat, v)|`.
//! With the reference held constant this is the paper's form with n + 1 exponentials, the
//! constant one (rate 0) carrying the reference; with the reference's derivatives (ramps) the
//! profile is the error's, so a ramp is followed without lag. `Psi^(n)(0)` needs no fit: the
//! profile's exponents are the roots of `prod_j (s + sigma j)`, so
//! `Psi^(n)(0) = -sum_k c_k e^(k)` with that polynomial's coefficients `c`
//! (`profile_target_equals_the_fitted_exponentials` checks the two against each other).
//! Where P is affine in the input (no monomial of degree 2 or more in it, no named term of it)
//! the argmin is closed form and clipped to the range; otherwise a 1-D search over the range
//! (a grid, then golden section around the best grid point).
//!
//! # Blocking
//! The input is decided every `block` samples and held in between (the paper's kappa), for
//! either law: a controller whose computation takes longer than one sample.

use crate::error::{Error, Result};
use crate::model::{CompiledModel, Model};
use std::path::Path;

/// A reference `r(t)`: piecewise linear between knots, a step where two knots share a time
/// (the later value holds from that time), held at its last value after the last knot.
#[derive(Debug, Clone)]
pub struct Reference {
    t: Vec<f64>,
    r: Vec<f64>,
}

/// Largest reference file read (a reference is a few thousand knots at most).
const MAX_REFERENCE_BYTES: u64 = 64 << 20;

impl Reference {
    /// A constant reference (a setpoint step from rest at t = 0).
    pub fn constant(r: f64) -> Reference {
        Reference {
            t: vec![0.0],
            r: vec![r],
        }
    }

    /// From knots; refuses fewer than one knot, non-finite values, decreasing times, a first
    /// knot after t = 0 and more than two knots at one time.
    pub fn from_knots(t: Vec<f64>, r: Vec<f64>) -> Result<Reference> {
        let bad = |why: String| Error::param("reference", why);
        if t.is_empty() || t.len() != r.len() {
            return Err(bad(format!(
                "{} times and {} values; give at least one (time, reference) pair",
                t.len(),
                r.len()
            )));
        }
        if let Some(k) = (0..t.len()).find(|&k| !t[k].is_finite() || !r[k].is_finite()) {
            return Err(bad(format!(
                "knot {} is ({}, {}); give finite numbers",
                k + 1,
                t[k],
                r[k]
            )));
        }
        if t[0] > 0.0 {
            return Err(bad(format!(
                "it starts at t = {} s; give its value at t = 0 (the loop starts there)",
                t[0]
            )));
        }
        for k in 1..t.len() {
            if t[k] < t[k - 1] {
                return Err(bad(format!(
                    "time goes back at knot {} ({} after {}); give times in order",
                    k + 1,
                    t[k],
                    t[k - 1]
                )));
            }
            // A slope that overflows (knots 1e-320 s apart, or values near f64's end): the loop
            // then asked for the steady input of a NaN reference and blamed the setpoint.
            if t[k] > t[k - 1] && !((r[k] - r[k - 1]) / (t[k] - t[k - 1])).is_finite() {
                return Err(bad(format!(
                    "the slope between knots {} and {} ({} to {} over {} s) overflows; give a step as two knots at one time, or smaller values",
                    k,
                    k + 1,
                    crate::util::short(r[k - 1]),
                    crate::util::short(r[k]),
                    crate::util::short(t[k] - t[k - 1])
                )));
            }
            if k >= 2 && t[k] == t[k - 1] && t[k - 1] == t[k - 2] {
                return Err(bad(format!(
                    "three knots at t = {}; a step is two knots at one time",
                    t[k]
                )));
            }
        }
        Ok(Reference { t, r })
    }

    /// Reads a CSV file of two columns, time (s) and reference, with an optional header line.
    /// A missing or non-numeric field (a gap), NaN, or time going back is a one-line error
    /// naming the line.
    pub fn read_csv(path: &Path) -> Result<Reference> {
        use std::io::Read;
        let mut text = String::new();
        crate::util::open_regular(path, Some(MAX_REFERENCE_BYTES))?
            .read_to_string(&mut text)
            .map_err(|e| Error::file(path.display().to_string(), e))?;
        let (mut t, mut r) = (Vec::new(), Vec::new());
        let bad = |line: usize, why: String| {
            Error::param(
                "reference",
                format!("{} line {line}: {why}", path.display()),
            )
        };
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            let parsed: Vec<Option<f64>> = fields.iter().map(|f| f.parse::<f64>().ok()).collect();
            if t.is_empty() && i == 0 && parsed.iter().all(Option::is_none) {
                continue; // the header
            }
            if fields.len() != 2 {
                return Err(bad(
                    i + 1,
                    format!("{} fields; give two, time and reference", fields.len()),
                ));
            }
            match (parsed[0], parsed[1]) {
                (Some(a), Some(b)) if a.is_finite() && b.is_finite() => {
                    t.push(a);
                    r.push(b);
                }
                _ => {
                    return Err(bad(
                        i + 1,
                        format!(
                            "'{}' is not two finite numbers (a gap or NaN); every line needs a time and a value",
                            crate::util::clip(line, 60)
                        ),
                    ))
                }
            }
        }
        Reference::from_knots(t, r).map_err(|e| match e {
            Error::InvalidParameter { reason, .. } => {
                Error::param("reference", format!("{}: {reason}", path.display()))
            }
            e => e,
        })
    }

    /// The built-in scenario after the paper's 5 s experiment, between levels `a` (the start)
    /// and `b`: a step to the middle, a ramp to `b`, a hold, a step back to the middle, a ramp
    /// down to `a`, a hold; times scaled to `duration` (5 s in the paper).
    pub fn steps_and_ramps(a: f64, b: f64, duration: f64) -> Result<Reference> {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(Error::param(
                "duration",
                format!("{duration} s; give a value > 0"),
            ));
        }
        let m = 0.5 * (a + b);
        let s = duration / 5.0;
        let knots = [
            (0.0, a),
            (0.5, a),
            (0.5, m),
            (1.5, m),
            (2.5, b),
            (3.0, b),
            (3.0, m),
            (3.5, m),
            (4.5, a),
            (5.0, a),
        ];
        Reference::from_knots(
            knots.iter().map(|k| k.0 * s).collect(),
            knots.iter().map(|k| k.1).collect(),
        )
    }

    /// The last knot's time (0 for a constant reference).
    pub fn end(&self) -> f64 {
        self.t[self.t.len() - 1]
    }

    /// `r(t)` and its slope `r'(t)` (zero on steps and after the last knot).
    pub fn at(&self, t: f64) -> (f64, f64) {
        // The last knot at or before t (the later of two at a step).
        let k = self.t.partition_point(|&tk| tk <= t);
        if k == 0 {
            return (self.r[0], 0.0);
        }
        let k = k - 1;
        if k + 1 == self.t.len() {
            return (self.r[k], 0.0);
        }
        let (t0, t1, r0, r1) = (self.t[k], self.t[k + 1], self.r[k], self.r[k + 1]);
        let slope = (r1 - r0) / (t1 - t0);
        (r0 + slope * (t - t0), slope)
    }

    /// The steps: (time, value before, value after).
    pub fn steps(&self) -> Vec<(f64, f64, f64)> {
        (1..self.t.len())
            .filter(|&k| self.t[k] == self.t[k - 1] && self.r[k] != self.r[k - 1])
            .map(|k| (self.t[k], self.r[k - 1], self.r[k]))
            .collect()
    }
}

/// Settings of the exponential-profile law (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct ProfileLaw {
    /// Profile rates are `sigma, 2 sigma, ..., n sigma` (1/s).
    pub sigma: f64,
}

/// Which law decides the input.
#[derive(Debug, Clone, Copy)]
pub enum Law {
    /// The design's state feedback with integral action (see [`super::design()`]).
    PolePlacement,
    /// The source paper's exponential-profile law.
    Profile(ProfileLaw),
}

/// A tracking run: the reference, the law and the blocking.
#[derive(Debug, Clone)]
pub struct Tracking {
    pub reference: Reference,
    pub law: Law,
    /// The input is decided every `block` samples and held in between (>= 1).
    pub block: usize,
}

impl Tracking {
    /// A setpoint step under the pole placement, decided every sample (what `run` does).
    pub fn step(setpoint: f64) -> Tracking {
        Tracking {
            reference: Reference::constant(setpoint),
            law: Law::PolePlacement,
            block: 1,
        }
    }

    /// Refuses a zero block and a profile rate that is not finite and positive.
    pub fn check(&self) -> Result<()> {
        if self.block == 0 {
            return Err(Error::param(
                "block",
                "0 samples; the input is decided every K >= 1 samples",
            ));
        }
        if let Law::Profile(p) = self.law {
            if !(p.sigma.is_finite() && p.sigma > 0.0) {
                return Err(Error::param(
                    "sigma",
                    format!("{}; give a profile rate > 0 (1/s)", p.sigma),
                ));
            }
        }
        Ok(())
    }
}

/// Coefficients `c_0 .. c_{n-1}` of `prod_{j=1..n} (s + sigma j) = s^n + sum_k c_k s^k`.
pub fn profile_polynomial(n: usize, sigma: f64) -> Vec<f64> {
    // Coefficients, lowest power first, of the running product.
    let mut p = vec![1.0];
    for j in 1..=n {
        let root = sigma * j as f64;
        let mut q = vec![0.0; p.len() + 1];
        for (k, &c) in p.iter().enumerate() {
            q[k] += root * c;
            q[k + 1] += c;
        }
        p = q;
    }
    p.truncate(n);
    p
}

/// Observer gains of the paper's chain-of-integrators observer: the error of a chain of n
/// integrators corrected by `L (y - y_hat)` has all its poles at `-p` when
/// `l_k = C(n, k + 1) p^(k + 1)`; the model runs as the known leading term.
pub fn chain_observer_gains(n: usize, p: f64) -> Vec<f64> {
    let mut l = Vec::with_capacity(n);
    let mut binom = 1.0;
    for k in 0..n {
        binom = binom * (n - k) as f64 / (k + 1) as f64;
        l.push(binom * p.powi(k as i32 + 1));
    }
    l
}

/// Whether the one-output model's right-hand side is affine in its (only) input: every
/// monomial has the input to the power 0 or 1 and no named term uses it (by the parsed
/// expression's variables: a text search took `sign(w)` for a use of an input named `i`).
pub fn affine_in_input(model: &Model) -> bool {
    let input = &model.inputs[0];
    let names = model.variable_names();
    let Some(at) = names.iter().position(|n| n == input) else {
        return false;
    };
    model.outputs[0].terms.iter().all(|t| match &t.expression {
        Some(text) => {
            crate::model::Expr::parse(text, &names).is_ok_and(|e| !e.variables().contains(&at))
        }
        None => t.exponents.get(input).copied().unwrap_or(0) <= 1,
    })
}

/// The exponential-profile decision: the input in `[lo, hi]` whose predicted `y^(n)` is
/// closest to `r^(n) - sum_k c_k (x_hat_k - r^(k))` (`refs` = r, r', ..., r^(n)).
pub(crate) struct ProfileDecider<'a> {
    pub model: &'a CompiledModel,
    pub c: Vec<f64>,
    pub affine: bool,
    pub limits: Option<(f64, f64)>,
}

impl ProfileDecider<'_> {
    /// The decided input, or `None` where the model cannot be evaluated at the estimate.
    pub fn decide(&self, xh: &[f64], refs: &[f64], u_prev: f64) -> Option<f64> {
        let n = self.c.len();
        let target = refs[n] - (0..n).map(|k| self.c[k] * (xh[k] - refs[k])).sum::<f64>();
        let mut z = xh.to_vec();
        z.push(0.0);
        let mut p = |v: f64| -> f64 {
            z[n] = v;
            self.model.eval_output(0, &z).unwrap_or(f64::NAN)
        };
        if self.affine {
            let (p0, p1) = (p(u_prev), p(u_prev + 1.0));
            let slope = p1 - p0;
            if !(slope.is_finite() && p0.is_finite()) || slope == 0.0 {
                return None;
            }
            let v = u_prev + (target - p0) / slope;
            return Some(match self.limits {
                Some((lo, hi)) => v.clamp(lo, hi),
                None => v,
            });
        }
        let (lo, hi) = self.limits?;
        let miss = |v: f64, p: &mut dyn FnMut(f64) -> f64| {
            let m = (target - p(v)).abs();
            if m.is_nan() {
                f64::INFINITY
            } else {
                m
            }
        };
        const GRID: usize = 40;
        let at = |i: usize| lo + (hi - lo) * i as f64 / GRID as f64;
        let best = (0..=GRID)
            .map(|i| (i, miss(at(i), &mut p)))
            .min_by(|a, b| a.1.total_cmp(&b.1))?
            .0;
        // Golden section on the grid cells beside the best point.
        let (mut a, mut b) = (at(best.saturating_sub(1)), at((best + 1).min(GRID)));
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..40 {
            let (x1, x2) = (b - g * (b - a), a + g * (b - a));
            if miss(x1, &mut p) <= miss(x2, &mut p) {
                b = x2;
            } else {
                a = x1;
            }
        }
        let v = 0.5 * (a + b);
        let grid_best = at(best);
        Some(if miss(grid_best, &mut p) < miss(v, &mut p) {
            grid_best
        } else {
            v
        })
    }
}

/// Figures of a tracking run (see [`tracking_metrics`]).
#[derive(Debug, Clone, Copy)]
pub struct TrackingMetrics {
    /// RMS of the output minus the reference over the run, and over the ramps only (`NaN`
    /// without ramps).
    pub rms: f64,
    pub rms_ramps: f64,
    /// Over the reference's steps: the largest overshoot (% of its step) and the longest time
    /// to stay within 2 % of the step (`NaN`: not settled before the reference moved on), and
    /// the rise time (10-90 %) of the first step. `NaN` without steps.
    pub overshoot: f64,
    pub settling_time: f64,
    pub rise_time: f64,
    /// Samples where the input sits on a limit.
    pub saturated: usize,
    /// Reversals of the input's direction per second: chattering.
    pub reversals_per_s: f64,
}

/// The figures of a trace against its reference.
pub fn tracking_metrics(
    t: &[f64],
    y: &[f64],
    u: &[f64],
    reference: &Reference,
    limits: Option<(f64, f64)>,
) -> TrackingMetrics {
    let n = t.len().min(y.len()).min(u.len());
    let refs: Vec<(f64, f64)> = t[..n].iter().map(|&tk| reference.at(tk)).collect();
    let rms_of = |idx: &mut dyn Iterator<Item = usize>| {
        let (s, c) = idx.fold((0.0, 0usize), |(s, c), k| {
            (s + (y[k] - refs[k].0).powi(2), c + 1)
        });
        if c == 0 {
            f64::NAN
        } else {
            (s / c as f64).sqrt()
        }
    };
    let rms = rms_of(&mut (0..n));
    let rms_ramps = rms_of(&mut (0..n).filter(|&k| refs[k].1 != 0.0));
    let (mut overshoot, mut settling, mut rise) = (f64::NAN, f64::NAN, f64::NAN);
    // Each step's window: from the step until the reference next moves. A plant that starts
    // away from the reference's first value is a step at t = 0.
    let mut steps: Vec<(f64, f64, f64, f64)> = Vec::new();
    let hold_end = |from: usize, value: f64| {
        let mut end = reference.t[from];
        for k in from + 1..reference.t.len() {
            if reference.r[k] != value {
                return end;
            }
            end = reference.t[k];
        }
        f64::INFINITY
    };
    if n > 0 && y[0] != reference.r[0] && reference.t[0] <= t[0] {
        steps.push((t[0], y[0], reference.r[0], hold_end(0, reference.r[0])));
    }
    for k in 1..reference.t.len() {
        if reference.t[k] == reference.t[k - 1] && reference.r[k] != reference.r[k - 1] {
            let after = reference.r[k];
            steps.push((
                reference.t[k],
                reference.r[k - 1],
                after,
                hold_end(k, after),
            ));
        }
    }
    // `i` counts the steps measured: a step whose window is empty (the reference moves on at
    // once) is skipped, and counting it left every later step's settling and rise unset.
    let mut i = 0;
    for &(ts, before, after, end) in &steps {
        let idx: Vec<usize> = (0..n).filter(|&k| t[k] >= ts && t[k] < end).collect();
        let Some(&last) = idx.last() else { continue };
        let step = after - before;
        let frac = |k: usize| (y[k] - before) / step;
        let over = idx
            .iter()
            .map(|&k| 100.0 * (frac(k) - 1.0))
            .fold(0.0, f64::max);
        overshoot = if overshoot.is_nan() {
            over
        } else {
            overshoot.max(over)
        };
        let band = 0.02 * step.abs();
        let settle = match idx.iter().rposition(|&k| (y[k] - after).abs() > band) {
            None => 0.0,
            Some(j) if idx[j] == last => f64::NAN,
            Some(j) => t[idx[j + 1]] - ts,
        };
        settling = if i == 0 || settling.is_nan() || settle.is_nan() {
            if i == 0 || settle.is_nan() {
                settle
            } else {
                settling
            }
        } else {
            settling.max(settle)
        };
        if i == 0 {
            let first = |lvl: f64| idx.iter().find(|&&k| frac(k) >= lvl).map(|&k| t[k]);
            if let (Some(a), Some(b)) = (first(0.1), first(0.9)) {
                rise = b - a;
            }
        }
        i += 1;
    }
    let saturated = match limits {
        Some((lo, hi)) => u[..n].iter().filter(|&&v| v <= lo || v >= hi).count(),
        None => 0,
    };
    let mut reversals = 0;
    let mut dir = 0.0f64;
    for k in 1..n {
        let d = u[k] - u[k - 1];
        if d != 0.0 {
            if dir != 0.0 && d.signum() != dir {
                reversals += 1;
            }
            dir = d.signum();
        }
    }
    let span = if n > 1 { t[n - 1] - t[0] } else { f64::NAN };
    TrackingMetrics {
        rms,
        rms_ramps,
        overshoot,
        settling_time: settling,
        rise_time: rise,
        saturated,
        reversals_per_s: reversals as f64 / span,
    }
}

/// One line of a tracking run's figures (`samples` in the run, `decision_seconds` per decision).
pub fn describe(m: &TrackingMetrics, samples: usize, decision_seconds: f64) -> String {
    let opt = |v: f64, unit: &str| {
        if v.is_nan() {
            "-".to_string()
        } else {
            format!("{}{unit}", crate::util::num4(v))
        }
    };
    format!(
        "tracking RMS {}, on ramps {}; steps: rise (10-90 %) {}, overshoot {}, settling (2 %) {}; saturated samples {} of {samples}; input reversals {}/s; computation {:.1} us per decision",
        opt(m.rms, ""),
        opt(m.rms_ramps, ""),
        opt(m.rise_time, " s"),
        opt(m.overshoot, " %"),
        // NaN settling with steps: not settled; without steps (NaN overshoot): nothing to say.
        if m.settling_time.is_nan() && !m.overshoot.is_nan() {
            "none within the run".to_string()
        } else {
            opt(m.settling_time, " s")
        },
        m.saturated,
        crate::util::num4(m.reversals_per_s),
        1e6 * decision_seconds
    )
}

/// SVG of a tracking run: reference, output and measurement; the tracking error; the
/// observer's error on the output; the input.
pub fn tracking_plot(tr: &super::Trace, title: &str, y_label: &str, u_label: &str) -> String {
    let top = [
        ("measured", &tr.y_measured[..], "#bbbbbb", false),
        ("output", &tr.y[..], "black", false),
        ("reference", &tr.reference[..], "#2ca02c", true),
    ];
    let against = (
        "output minus reference",
        "tracking error",
        &tr.reference[..],
    );
    super::closed_loop::loop_figure(tr, title, ("tracking", y_label), u_label, &top, against)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_target_equals_the_fitted_exponentials() {
        // Fit alpha to e, e', e'' with exponents -sigma j and compare Psi'''(0) with -c . e.
        let (n, sigma) = (3, 7.0);
        let e = [0.3, -1.2, 5.0];
        let lam: Vec<f64> = (1..=n).map(|j| -sigma * j as f64).collect();
        let v = nalgebra::DMatrix::from_fn(n, n, |k, j| lam[j].powi(k as i32));
        let alpha = v
            .lu()
            .solve(&nalgebra::DVector::from_column_slice(&e))
            .unwrap();
        let psi_n: f64 = (0..n).map(|j| alpha[j] * lam[j].powi(n as i32)).sum();
        let c = profile_polynomial(n, sigma);
        let from_c: f64 = -(0..n).map(|k| c[k] * e[k]).sum::<f64>();
        assert!(
            (psi_n - from_c).abs() < 1e-9 * psi_n.abs(),
            "{psi_n} vs {from_c}"
        );
        // (s + 7)(s + 14)(s + 21) = s^3 + 42 s^2 + 539 s + 2058
        assert_eq!(c, vec![2058.0, 539.0, 42.0]);
    }

    #[test]
    fn a_step_straight_into_a_ramp_does_not_hide_the_later_steps_figures() {
        // Steps at t = 1 (into a ramp at once: an empty window) and at t = 4 (held to 10).
        let reference = Reference::from_knots(
            vec![0.0, 1.0, 1.0, 2.0, 4.0, 4.0, 10.0],
            vec![0.0, 0.0, 1.0, 2.0, 2.0, 3.0, 3.0],
        )
        .unwrap();
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.01).collect();
        // Follows the reference, and after t = 4 rises as 1 - exp(-5 (t - 4)).
        let y: Vec<f64> = t
            .iter()
            .map(|&tk| {
                if tk < 4.0 {
                    reference.at(tk).0
                } else {
                    2.0 + 1.0 - (-5.0 * (tk - 4.0)).exp()
                }
            })
            .collect();
        let u = vec![0.0; t.len()];
        let m = tracking_metrics(&t, &y, &u, &reference, None);
        // 2 % band: exp(-5 s) = 0.02 at s = 0.78; 10-90 %: ln 9 / 5 = 0.44.
        assert!((m.settling_time - 0.79).abs() < 0.02, "{m:?}");
        assert!((m.rise_time - 0.44).abs() < 0.02, "{m:?}");
    }

    #[test]
    fn affinity_reads_the_variables_of_named_terms_not_their_text() {
        let model = |terms: &str| {
            Model::from_json_str(
                &format!(r#"{{"format":"ctsid-model/2","inputs":["i"],"outputs":[{{"name":"w","order":1,"terms":[{{"exponents":{{"w":1}},"coefficient":-2}},{terms}]}}]}}"#),
                "m.json",
            )
            .unwrap()
        };
        // "sign" contains the input's name "i".
        assert!(affine_in_input(&model(
            r#"{"expression":"sign(w)","coefficient":-0.1},{"exponents":{"i":1},"coefficient":3}"#
        )));
        assert!(!affine_in_input(&model(
            r#"{"expression":"tanh(i)","coefficient":3}"#
        )));
        assert!(!affine_in_input(&model(
            r#"{"exponents":{"i":2},"coefficient":3}"#
        )));
    }

    #[test]
    fn chain_observer_places_every_pole_at_minus_p() {
        // Error dynamics of the chain: companion with last row... characteristic polynomial
        // s^n + l_0 s^(n-1) + ... + l_{n-1} = (s + p)^n.
        let l = chain_observer_gains(4, 2.0);
        assert_eq!(l, vec![8.0, 24.0, 32.0, 16.0]);
    }

    #[test]
    fn reference_steps_ramps_and_refusals() {
        let r = Reference::steps_and_ramps(0.0, 1.0, 5.0).unwrap();
        assert_eq!(r.at(0.2), (0.0, 0.0));
        assert_eq!(r.at(0.5).0, 0.5);
        let (v, s) = r.at(2.0);
        assert!((v - 0.75).abs() < 1e-12 && (s - 0.5).abs() < 1e-12);
        assert_eq!(r.at(9.0), (0.0, 0.0));
        assert_eq!(r.steps().len(), 2);
        assert!(Reference::from_knots(vec![0.0, 1.0, 0.5], vec![0.0; 3]).is_err());
        assert!(Reference::from_knots(vec![0.0, f64::NAN], vec![0.0; 2]).is_err());
        assert!(Reference::from_knots(vec![0.1], vec![0.0]).is_err());
        let dir = std::env::temp_dir().join(format!("ctsid-ref-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("r.csv");
        std::fs::write(&p, "t,r\n0,0\n1,\n").unwrap();
        let e = Reference::read_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("gap"), "{e}");
        std::fs::write(&p, "t,r\n0,0\n1,NaN\n").unwrap();
        assert!(Reference::read_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("line 3"));
        std::fs::write(&p, "t,r\n0,0\n1,1\n1,2\n3,2\n").unwrap();
        let r = Reference::read_csv(&p).unwrap();
        assert_eq!(r.steps(), vec![(1.0, 1.0, 2.0)]);
        std::fs::remove_dir_all(&dir).ok();
        let bad = Tracking {
            block: 0,
            ..Tracking::step(1.0)
        };
        assert!(bad.check().unwrap_err().to_string().contains("block"));
        let bad = Tracking {
            law: Law::Profile(ProfileLaw { sigma: 0.0 }),
            ..Tracking::step(1.0)
        };
        assert!(bad.check().unwrap_err().to_string().contains("sigma"));
    }
}
