//! The designed controller around a plant: a digital loop sampled at tau, and step metrics.

use super::tracking::{Law, ProfileDecider, Tracking};
use super::Design;
use crate::error::{Error, Result};
use crate::model::{CompiledModel, Model};
use crate::plants::rng::Rng;
use crate::simulate::{simulate, ConstantInput, SimOptions, System};
use nalgebra::DVector;

/// A setpoint step and how the loop is run.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Simulated time in seconds.
    pub duration: f64,
    /// Standard deviation of white noise added to each measured sample.
    pub noise_sd: f64,
    pub seed: u64,
    /// Input limits: the input is clipped, and while it is, the integrator takes only what pulls
    /// it back inside (no wind-up, no stall at a limit).
    pub u_limits: Option<(f64, f64)>,
}

/// A plant the loop runs around: a system, which of its states is the measured output, and its
/// rest state with the input that holds it there ([`rest_state`]).
pub struct Plant<'a> {
    pub system: &'a (dyn System + Sync),
    pub output: usize,
    pub x0: Vec<f64>,
    /// The input the loop was applying before t = 0 (its integrator starts from it: no bump).
    pub u0: f64,
}

/// The loop's record, one entry per sample.
#[derive(Debug, Clone, Default)]
pub struct Trace {
    pub t: Vec<f64>,
    /// The plant's output (noise-free) and the measured one.
    pub y: Vec<f64>,
    pub y_measured: Vec<f64>,
    /// The observer's estimates of y, y', ..., y^(n-1).
    pub estimate: Vec<Vec<f64>>,
    /// The input applied from this sample to the next.
    pub u: Vec<f64>,
    /// The reference at each sample.
    pub reference: Vec<f64>,
    /// Mean wall-clock time of one decision of the law, in seconds (a measurement of this
    /// machine, not part of the result).
    pub decision_seconds: f64,
}

/// Step-response figures of a trace, against a step from `from` to the setpoint.
#[derive(Debug, Clone, Copy)]
pub struct StepMetrics {
    /// 10 % to 90 % of the step, in seconds (`NaN` when never reached).
    pub rise_time: f64,
    /// Largest excursion beyond the setpoint, in % of the step.
    pub overshoot: f64,
    /// Time after which the output stays within 2 % of the step, in seconds (`NaN`: never).
    pub settling_time: f64,
    /// Mean output minus setpoint over the last 10 % of the run, in % of the step.
    pub final_error: f64,
    /// Input range used.
    pub u_min: f64,
    pub u_max: f64,
    /// RMS of the observer's output estimate minus the true output.
    pub observer_rms: f64,
    /// Largest difference between the output and the designed response
    /// ([`designed_response`]), in % of the step: how far the plant is from the design.
    pub design_deviation: f64,
}

/// Longest loop the library runs, in samples (each is a stiff integration over one sample).
pub const MAX_SAMPLES: usize = 1_000_000;

/// A default simulated time: long enough for the designed response of an order-n model (n + 1
/// poles at -w) to settle well within 1 % (three time constants per pole, plus six).
pub fn default_duration(d: &Design) -> f64 {
    settle_units(d.order) / d.bandwidth
}

/// [`default_duration`] in units of 1 / bandwidth, for an order-n design.
pub(crate) fn settle_units(order: usize) -> f64 {
    3.0 * (order as f64 + 1.0) + 6.0
}

/// Most integrator steps one loop may take (over all its samples): stiff or nearly unstable
/// loops are refused rather than left running for hours.
const MAX_STEPS: usize = 50_000_000;

/// The design's fields agree with each other (they are public: a hand-edited design is checked
/// before it indexes anything).
fn check(d: &Design) -> Result<()> {
    let n = d.order;
    let ok = n >= 1
        && d.k.len() == n
        && d.l.len() == n
        && d.a.nrows() == n
        && d.a.ncols() == n
        && d.b.len() == n
        && d.model.outputs.len() == 1
        && d.model.inputs.len() == 1
        && d.model.outputs[0].order == n
        && d.bandwidth.is_finite()
        && d.bandwidth > 0.0
        && d.b[n - 1] != 0.0
        && d.k
            .iter()
            .chain(&d.l)
            .chain([&d.k_i, &d.u_star, &d.setpoint])
            .all(|v| v.is_finite());
    if !ok {
        return Err(Error::param(
            "design",
            "its fields disagree (order, gains, linearisation); build it with control::design",
        ));
    }
    crate::records::check_tau(d.tau)
}

/// SVG of a step under feedback: the measured and true output (`output_label`), the designed
/// response and the setpoint over the trace's time; below, the output minus the designed
/// response (how far the loop is from its design), the observer's error on the output, and the
/// input.
pub fn step_plot(
    d: &Design,
    tr: &Trace,
    from: f64,
    title: &str,
    y_label: &str,
    output_label: &str,
) -> Result<String> {
    let designed = designed_response(d, from, tr.t.len())?;
    let setpoint = vec![d.setpoint; tr.t.len()];
    let top = [
        ("measured", &tr.y_measured[..], "#bbbbbb", false),
        (output_label, &tr.y[..], "black", false),
        ("designed response", &designed[..], "#1f77b4", true),
        ("setpoint", &setpoint[..], "#2ca02c", true),
    ];
    let against = ("output minus designed response", "deviation", &designed[..]);
    Ok(loop_figure(
        tr,
        title,
        ("step", y_label),
        &d.input,
        &top,
        against,
    ))
}

/// The stacked panels of a loop's plot: `top` (label, values, colour, dashed) over the trace's
/// time; the output minus `against.2` (panel title, series label); the observer's error on the
/// output; the input.
pub(crate) fn loop_figure(
    tr: &Trace,
    title: &str,
    (top_title, y_label): (&str, &str),
    u_label: &str,
    top: &[(&str, &[f64], &str, bool)],
    against: (&str, &str, &[f64]),
) -> String {
    use crate::report::svg::{figure, Panel, Series};
    let deviation: Vec<f64> = tr.y.iter().zip(against.2).map(|(y, r)| y - r).collect();
    let observer: Vec<f64> = match tr.estimate.first() {
        Some(est) => est.iter().zip(&tr.y).map(|(e, y)| e - y).collect(),
        None => vec![f64::NAN; tr.t.len()],
    };
    let series = |label, y, color, dashed| Series {
        label,
        x: &tr.t,
        y,
        color,
        band: None,
        dashed,
    };
    let panels = vec![
        Panel::lines(
            top_title,
            "t (s)",
            y_label,
            top.iter()
                .map(|&(label, y, color, dashed)| series(label, y, color, dashed))
                .collect(),
        ),
        Panel::lines(
            against.0,
            "t (s)",
            y_label,
            vec![series(against.1, &deviation, "#d62728", false)],
        )
        .height(180.0),
        Panel::lines(
            "observer: estimated minus true output",
            "t (s)",
            y_label,
            vec![series("estimation error", &observer, "#9467bd", false)],
        )
        .height(180.0),
        Panel::lines(
            "input",
            "t (s)",
            u_label,
            vec![series("input", &tr.u, "#ff7f0e", false)],
        )
        .height(200.0),
    ];
    figure(title, &panels)
}

/// The designed step response at the loop's sample times `k tau`, k < `samples`: the model
/// linearised at the setpoint under the continuous-time control law, at rest at `from` with the
/// bumpless integrator (so the setpoint enters through the integrator only), the setpoint
/// applied from t = 0. Exact per sample (a matrix exponential of the closed loop, in the
/// design's scaled time and states), whatever the stiffness.
pub fn designed_response(d: &Design, from: f64, samples: usize) -> Result<Vec<f64>> {
    check(d)?;
    let n = d.order;
    let w = d.bandwidth;
    let delta = from - d.setpoint;
    // z = [x - x*, q], scaled as the design scales it.
    let (scaled, sc) = super::design::scaled_closed_loop(&d.a, &d.b, &d.k, d.k_i, w);
    let phi = (scaled * (w * d.tau)).exp();
    // At rest at `from` the linearised model needs du = -A[n-1][0] delta / b.
    let du_from = -d.a[(n - 1, 0)] * delta / d.b[n - 1];
    let mut z = DVector::<f64>::zeros(n + 1);
    z[0] = delta;
    if d.k_i != 0.0 {
        z[n] = (-d.k[0] * delta - du_from) / d.k_i / sc[n];
    }
    let mut out = Vec::with_capacity(samples);
    for _ in 0..samples {
        out.push(d.setpoint + z[0]);
        z = &phi * z;
    }
    Ok(out)
}

/// The plant and the observer as one system over a sample: inputs (u, measured y), both held.
struct Loop<'a> {
    plant: &'a (dyn System + Sync),
    model: &'a CompiledModel,
    l: &'a [f64],
}

impl System for Loop<'_> {
    fn dim(&self) -> usize {
        self.plant.dim() + self.model.n_state()
    }
    /// The plant's limits on its states, the model's on the observer's estimate (a level the
    /// model says overflows is not estimated above it).
    fn project(&self, x: &mut [f64], pinned: &mut Vec<usize>) {
        let np = self.plant.dim();
        self.plant.project(&mut x[..np], pinned);
        let from = pinned.len();
        System::project(self.model, &mut x[np..], pinned);
        pinned[from..].iter_mut().for_each(|k| *k += np);
    }
    fn n_inputs(&self) -> usize {
        2
    }
    fn state_name(&self, k: usize) -> String {
        let np = self.plant.dim();
        if k < np {
            format!("plant {}", self.plant.state_name(k))
        } else {
            format!("observer {}", self.model.names()[k - np])
        }
    }
    /// Block diagonal: the plant's Jacobian (its own, exact for models) and the model's minus
    /// the observer gain in column 0; the held measurement couples nothing.
    fn jacobian(&self, x: &[f64], u: &[f64], jac: &mut [f64]) {
        let np = self.plant.dim();
        let n = self.model.n_state();
        let dim = np + n;
        jac.iter_mut().for_each(|v| *v = 0.0);
        let mut jp = vec![0.0; np * np];
        self.plant.jacobian(&x[..np], &u[..1], &mut jp);
        for i in 0..np {
            jac[i * dim..i * dim + np].copy_from_slice(&jp[i * np..(i + 1) * np]);
        }
        let (mut jm, mut ju) = (vec![0.0; n * n], vec![0.0; n]);
        self.model
            .jacobians_unchecked(&x[np..], &u[..1], &mut jm, &mut ju);
        for i in 0..n {
            let row = (np + i) * dim + np;
            jac[row..row + n].copy_from_slice(&jm[i * n..(i + 1) * n]);
            jac[row] -= self.l[i];
        }
    }
    fn rhs(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let np = self.plant.dim();
        self.plant.rhs(&x[..np], &u[..1], &mut dx[..np]);
        let (xh, dxh) = (&x[np..], &mut dx[np..]);
        self.model.rhs_unchecked(xh, &u[..1], dxh);
        let e = u[1] - xh[0];
        for (d, l) in dxh.iter_mut().zip(self.l) {
            *d += l * e;
        }
    }
}

/// Runs the designed loop around `plant`: the loop has held the plant at rest (input `u0`)
/// and the setpoint steps to the design's at t = 0; the observer starts at rest at the plant's
/// output and the integrator where it gives `u0` (a bumpless start, so the setpoint enters
/// through the integrator only, as in [`designed_response`]).
///
/// Each sample: measure (plus noise), compute the input from the observer's state and the
/// integral of the error, hold it over the sample; the plant and the observer (the design's
/// nonlinear model corrected by its gain towards the held measurement) advance together with
/// the crate's stiff integrator ([`crate::simulate::simulate`]). [`track`] with
/// [`Tracking::step`].
pub fn run(d: &Design, plant: &Plant, s: &Scenario) -> Result<Trace> {
    track(d, plant, s, &Tracking::step(d.setpoint))
}

/// Checks a scenario's duration, noise and input limits (the limits must hold the design's
/// steady input where the law needs it: the pole placement). [`track`] checks it too; a caller
/// that prints the design first checks it before (`--noise NaN` printed the whole design, then
/// the error).
pub fn check_scenario(d: &Design, s: &Scenario, law: &Law) -> Result<()> {
    check_duration(d, s)?;
    crate::util::finite_nonneg("noise", s.noise_sd)?;
    // The profile law solves for the input by a bounded search where the model is not affine in
    // it: without limits it found no input at the first sample, after the design was printed.
    if matches!(law, Law::Profile(_))
        && s.u_limits.is_none()
        && !super::tracking::affine_in_input(&d.model)
    {
        return Err(Error::param(
            "u-min/u-max",
            "the exponential-profile law on a model not affine in its input searches the input between limits; give --u-min and --u-max",
        ));
    }
    if let Some((lo, hi)) = s.u_limits {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(Error::param(
                "u-min/u-max",
                format!("[{lo}, {hi}]; give finite limits, low < high (an empty input range holds nothing)"),
            ));
        }
        if matches!(law, Law::PolePlacement) && !(lo..=hi).contains(&d.u_star) {
            return Err(Error::param(
                "u-min/u-max",
                format!(
                    "the setpoint needs a steady input of {:e}, outside [{lo}, {hi}]: it is out of reach; widen the limits or choose another setpoint",
                    d.u_star
                ),
            ));
        }
    }
    Ok(())
}

fn check_plant(plant: &Plant) -> Result<()> {
    let sys = plant.system;
    if sys.n_inputs() != 1 || plant.output >= sys.dim() || plant.x0.len() != sys.dim() {
        return Err(Error::param(
            "plant",
            format!(
                "{} states and {} inputs (output state {}, initial state of {}); the loop needs one input and the output among the states",
                sys.dim(),
                sys.n_inputs(),
                plant.output,
                plant.x0.len()
            ),
        ));
    }
    if plant.x0.iter().any(|v| !v.is_finite()) || !plant.u0.is_finite() {
        return Err(Error::param(
            "plant",
            "the initial state or input is not finite",
        ));
    }
    Ok(())
}

/// Checks the run's length before any work: at most [`MAX_SAMPLES`] samples and at least 10 at
/// the design's tau (a caller prints the design only after this; `--duration 1e12` printed the
/// whole design before the error).
pub fn check_duration(d: &Design, s: &Scenario) -> Result<()> {
    if !(s.duration.is_finite() && s.duration > 0.0) {
        return Err(Error::param(
            "duration",
            format!("{} s; give a value > 0", s.duration),
        ));
    }
    sample_count(d, s).map(|_| ())
}

/// The number of samples of a run, checked against [`MAX_SAMPLES`] and a floor of 10.
fn sample_count(d: &Design, s: &Scenario) -> Result<usize> {
    let samples = (s.duration / d.tau).round() + 1.0;
    if samples > MAX_SAMPLES as f64 {
        return Err(Error::param(
            "duration",
            format!(
                "{} s is {samples:e} samples at tau = {} s; at most {MAX_SAMPLES}: give a shorter duration, a larger tau or a faster bandwidth",
                s.duration, d.tau
            ),
        ));
    }
    // A NaN duration is refused here too (it gave 0 samples and a misleading error).
    if samples.is_nan() || samples < 10.0 {
        return Err(Error::param(
            "duration",
            format!(
                "{} s is fewer than 10 samples at tau = {} s; give a longer duration",
                s.duration, d.tau
            ),
        ));
    }
    Ok(samples as usize)
}

/// The law's state between samples: the pole placement's integral of the error and its steady
/// input at the current reference; the profile law's decider.
enum Controller<'m> {
    Placement {
        q: f64,
        /// (reference, steady input there): the last one computed.
        u_star: (f64, f64),
    },
    Profile(ProfileDecider<'m>),
}

impl Controller<'_> {
    /// The input before limits, from the observer's state `xh` and the reference (r, r').
    fn raw(&mut self, d: &Design, xh: &[f64], r: (f64, f64), u_prev: f64) -> Result<f64> {
        let n = d.order;
        match self {
            Controller::Placement { q, u_star } => {
                if u_star.0 != r.0 {
                    let u = super::steady_input(&d.model, r.0).map_err(|e| {
                        Error::InvalidData(format!(
                            "the reference {} has no steady input on the model ({e}); keep the reference where the model can hold the output",
                            r.0
                        ))
                    })?;
                    *u_star = (r.0, u);
                }
                let target = |j: usize| match j {
                    0 => r.0,
                    1 => r.1,
                    _ => 0.0,
                };
                let dev: f64 = (0..n).map(|j| d.k[j] * (xh[j] - target(j))).sum();
                Ok(u_star.1 - dev - d.k_i * *q)
            }
            Controller::Profile(p) => {
                let mut refs = vec![0.0; n + 1];
                refs[0] = r.0;
                if n >= 1 {
                    refs[1] = r.1;
                }
                p.decide(xh, &refs, u_prev).ok_or_else(|| {
                    Error::InvalidData(format!(
                        "the exponential-profile law found no input at the estimate {xh:?}: the model does not depend on its input there"
                    ))
                })
            }
        }
    }
}

/// The tracking run's sample count, refusing a block of at least that many samples (the input
/// would be decided once, at the start, and held: a run of the rest input that looked like an
/// answer) and the durations [`track`] refuses.
pub fn check_block(d: &Design, s: &Scenario, tk: &Tracking) -> Result<usize> {
    let samples = sample_count(d, s)?;
    if tk.block >= samples {
        return Err(Error::param(
            "block",
            format!(
                "{} samples, but the run has {samples}: the input would be decided once, at the start, and held; give a block shorter than the run",
                tk.block
            ),
        ));
    }
    Ok(samples)
}

/// Runs a tracking loop around `plant`: the reference `tk.reference` from t = 0, the input
/// decided by `tk.law` every `tk.block` samples and held in between (clipped to the
/// scenario's limits), the observer as in [`run`]. The trace carries the reference.
pub fn track(d: &Design, plant: &Plant, s: &Scenario, tk: &Tracking) -> Result<Trace> {
    check(d)?;
    tk.check()?;
    check_scenario(d, s, &tk.law)?;
    check_plant(plant)?;
    let samples = check_block(d, s, tk)?;
    let sys = plant.system;
    let n = d.order;
    let model = d.model.compile()?;
    let sys_loop = Loop {
        plant: sys,
        model: &model,
        l: &d.l,
    };
    let np = sys.dim();
    // Divergence: the output beyond 1e12 times the scale of the reference (derivative states
    // scale with powers of the bandwidth, so only their finiteness is judged).
    let r0 = tk.reference.at(0.0).0;
    let scale = [d.setpoint, r0, plant.x0[plant.output]]
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max((r0 - plant.x0[plant.output]).abs())
        .max(1e-300);
    // Absolute tolerance on the scale of the step (the default 1e-10 would be the whole step of
    // a plant measured in units of 1e-10).
    let opts = SimOptions {
        bound: 1e290,
        atol: 1e-10 * scale,
        run: "closed loop".into(),
        ..Default::default()
    };
    let mut steps = 0usize;

    let mut rng = Rng::new(s.seed);
    let mut z = plant.x0.clone();
    z.extend(std::iter::repeat_n(0.0, n));
    z[np] = plant.x0[plant.output];
    let mut ctl = match tk.law {
        Law::PolePlacement => {
            let mut c = Controller::Placement {
                q: 0.0,
                u_star: (d.setpoint, d.u_star),
            };
            // Bumpless: the integrator starts where the law gives the rest input u0.
            let raw = c.raw(d, &z[np..], tk.reference.at(0.0), plant.u0)?;
            if d.k_i != 0.0 {
                c = match c {
                    Controller::Placement { u_star, .. } => Controller::Placement {
                        q: (raw - plant.u0) / d.k_i,
                        u_star,
                    },
                    c => c,
                };
            }
            c
        }
        Law::Profile(p) => Controller::Profile(ProfileDecider {
            model: &model,
            c: super::tracking::profile_polynomial(n, p.sigma),
            affine: super::tracking::affine_in_input(&d.model),
            limits: s.u_limits,
        }),
    };
    let mut tr = Trace {
        estimate: vec![Vec::with_capacity(samples); n],
        ..Default::default()
    };
    let (mut u, mut raw) = (plant.u0, plant.u0);
    let mut decisions = 0usize;
    for k in 0..samples {
        let t = k as f64 * d.tau;
        let y = z[plant.output];
        let ym = y + s.noise_sd * rng.normal();
        let r = tk.reference.at(t);
        if k % tk.block == 0 {
            let clock = std::time::Instant::now();
            raw = ctl.raw(d, &z[np..], r, u)?;
            tr.decision_seconds += clock.elapsed().as_secs_f64();
            decisions += 1;
            u = match s.u_limits {
                Some((lo, hi)) => raw.clamp(lo, hi),
                None => raw,
            };
        }
        tr.t.push(t);
        tr.y.push(y);
        tr.y_measured.push(ym);
        tr.reference.push(r.0);
        for j in 0..n {
            tr.estimate[j].push(z[np + j]);
        }
        tr.u.push(u);
        if k + 1 == samples {
            break;
        }
        if let Controller::Placement { q, .. } = &mut ctl {
            // Conditional integration: while the input is clipped, integrate only what pulls
            // it back inside the limits (the rest would wind up).
            let dq = d.tau * (ym - r.0);
            let pull = -d.k_i * dq;
            if u == raw || (raw > u && pull < 0.0) || (raw < u && pull > 0.0) {
                *q += dq;
            }
        }
        // With sensor noise the noise is as likely a cause as the bandwidth (`--noise 1e300`
        // overflowed the observer and was blamed on the bandwidth alone).
        let diverged = |why: String| {
            let hint = if s.noise_sd > 0.0 {
                format!(
                    "lower the bandwidth or the sensor noise (sd {}), or check the model",
                    crate::util::short(s.noise_sd)
                )
            } else {
                "lower the bandwidth or check the model".to_string()
            };
            Error::InvalidData(format!(
                "the closed loop diverged between t = {t:.6} and {:.6} s ({why}): {hint}",
                t + d.tau
            ))
        };
        let step = simulate(
            &sys_loop,
            &ConstantInput(vec![u, ym]),
            &z,
            &[t, t + d.tau],
            &opts,
        )
        .map_err(|e| diverged(e.to_string()))?;
        z.copy_from_slice(step.state_at(1));
        steps += step.steps;
        if steps > MAX_STEPS {
            return Err(Error::InvalidData(format!(
                "the closed loop took over {MAX_STEPS} integrator steps by t = {:.6} s (stiff or nearly unstable); give a lower bandwidth or a shorter duration",
                t + d.tau
            )));
        }
        let yn = z[plant.output];
        if !yn.is_finite() || (yn - r.0).abs() > 1e12 * scale {
            return Err(diverged(format!("output {yn:e}")));
        }
    }
    tr.decision_seconds /= decisions.max(1) as f64;
    Ok(tr)
}

/// `max` that keeps a NaN (`f64::max` drops it, and a NaN figure would read as a good one).
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Step metrics of a trace of [`run`] for a step from `from` to the design's setpoint.
pub fn metrics(tr: &Trace, d: &Design, from: f64) -> Result<StepMetrics> {
    let setpoint = d.setpoint;
    let step = setpoint - from;
    if step == 0.0 || !step.is_finite() {
        return Err(Error::param(
            "from",
            format!("{from}: the same as the setpoint, there is no step to judge; give another starting output"),
        ));
    }
    check(d)?;
    if tr.y.is_empty() || tr.estimate.is_empty() || tr.estimate[0].len() != tr.y.len() {
        return Err(Error::param("trace", "empty or not from a loop run"));
    }
    let frac = |y: f64| (y - from) / step;
    let first = |level: f64| {
        tr.t.iter()
            .zip(&tr.y)
            .find(|(_, y)| frac(**y) >= level)
            .map_or(f64::NAN, |(t, _)| *t)
    };
    let rise_time = first(0.9) - first(0.1);
    let overshoot =
        tr.y.iter()
            .map(|y| 100.0 * (frac(*y) - 1.0))
            .fold(0.0, nan_max);
    let band = 0.02 * step.abs();
    let settling_time = match tr.y.iter().rposition(|y| (y - setpoint).abs() > band) {
        None => 0.0,
        Some(i) if i + 1 == tr.y.len() => f64::NAN,
        Some(i) => tr.t[i + 1],
    };
    let tail = (tr.y.len() / 10).max(1);
    let mean_tail = tr.y[tr.y.len() - tail..].iter().sum::<f64>() / tail as f64;
    let final_error = 100.0 * (mean_tail - setpoint) / step.abs();
    // In units of the step before squaring: outputs near 1e300 would overflow.
    let observer_rms = step.abs()
        * (tr
            .y
            .iter()
            .zip(&tr.estimate[0])
            .map(|(y, e)| ((y - e) / step).powi(2))
            .sum::<f64>()
            / tr.y.len() as f64)
            .sqrt();
    let design_deviation = designed_response(d, from, tr.y.len())?
        .iter()
        .zip(&tr.y)
        .map(|(yd, y)| (y - yd).abs())
        .fold(0.0, nan_max)
        / step.abs()
        * 100.0;
    // Both input extremes in one sweep (the minimum as the negated maximum of -u, NaN kept).
    let (neg_min, u_max) =
        tr.u.iter()
            .fold((f64::NEG_INFINITY, f64::NEG_INFINITY), |(lo, hi), &u| {
                (nan_max(lo, -u), nan_max(hi, u))
            });
    Ok(StepMetrics {
        design_deviation,
        rise_time,
        overshoot,
        settling_time,
        final_error,
        u_min: -neg_min,
        u_max,
        observer_rms,
    })
}

/// A model as the plant, at rest at output `y`: compiled, with its rest state and input
/// ([`rest_state`], started from the model's own steady input, or from `u_guess` where that
/// search finds none).
pub fn model_at_rest(
    model: &Model,
    y: f64,
    u_guess: f64,
) -> Result<(CompiledModel, Vec<f64>, f64)> {
    let c = model.compile()?;
    let guess = super::steady_input(model, y).unwrap_or(u_guess);
    let (x, u) = rest_state(&c, 0, y, guess)?;
    Ok((c, x, u))
}

/// The state at rest at output `y` of a system whose state `output` is the measured output:
/// the other states and the steady input solve `f(x, u) = 0` (Newton, forward-difference
/// Jacobians, from `x = (y, 0, ...)` and `u_guess`).
pub fn rest_state(
    sys: &(dyn System + Sync),
    output: usize,
    y: f64,
    u_guess: f64,
) -> Result<(Vec<f64>, f64)> {
    let n = sys.dim();
    if sys.n_inputs() != 1 || output >= n {
        return Err(Error::param(
            "plant",
            "one input and the output among the states are needed",
        ));
    }
    let mut x = vec![0.0; n];
    x[output] = y;
    let mut u = u_guess;
    let free: Vec<usize> = (0..n).filter(|&i| i != output).collect();
    let mut f = vec![0.0; n];
    let mut jac = vec![0.0; n * n];
    let mut f1 = vec![0.0; n];
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    // The Jacobian in x and, by a forward difference, the rhs at u + du; du.
    let linearise = |x: &[f64], u: f64, jac: &mut [f64], f1: &mut [f64]| -> f64 {
        sys.jacobian(x, &[u], jac);
        let du = 1e-7 * u.abs().max(1e-3);
        sys.rhs(x, &[u + du], f1);
        du
    };
    sys.rhs(&x, &[u], &mut f);
    let f_start = norm(&f).max(1e-300);
    if !(f_start.is_finite() && y.is_finite() && u.is_finite()) {
        return Err(Error::InvalidData(format!(
            "the plant is not finite at rest at output {y:?}; choose another starting output (--from)"
        )));
    }
    for _ in 0..100 {
        sys.rhs(&x, &[u], &mut f);
        if norm(&f) <= 1e-12 * f_start {
            break;
        }
        let du = linearise(&x, u, &mut jac, &mut f1);
        if jac.iter().chain(&f1).any(|v| !v.is_finite()) {
            break;
        }
        // Unknowns: the free states, then u.
        let mut m = nalgebra::DMatrix::<f64>::zeros(n, n);
        for r in 0..n {
            for (c, &i) in free.iter().enumerate() {
                m[(r, c)] = jac[r * n + i];
            }
            m[(r, n - 1)] = (f1[r] - f[r]) / du;
        }
        let rhs = nalgebra::DVector::from_iterator(n, f.iter().map(|v| -v));
        let Some(step) = m.lu().solve(&rhs) else {
            break;
        };
        for (c, &i) in free.iter().enumerate() {
            x[i] += step[c];
        }
        u += step[n - 1];
        if step.iter().any(|v| !v.is_finite()) {
            break;
        }
    }
    sys.rhs(&x, &[u], &mut f);
    // At rest each equation balances its terms: judged against their size (|J||x| + |B||u|),
    // not against how far the first guess was.
    let du = linearise(&x, u, &mut jac, &mut f1);
    let sizes: Vec<f64> = (0..n)
        .map(|r| {
            (0..n).map(|j| (jac[r * n + j] * x[j]).abs()).sum::<f64>()
                + ((f1[r] - f[r]) / du * u).abs()
        })
        .collect();
    let floor = 1e-12 * sizes.iter().fold(0.0f64, |a, b| a.max(*b));
    let unbalanced = (0..n).any(|r| f[r].is_nan() || f[r].abs() > 1e-8 * sizes[r] + floor);
    if x.iter().any(|v| !v.is_finite()) || !u.is_finite() || unbalanced {
        return Err(Error::InvalidData(format!(
            "the plant has no rest state at output {y:?} that Newton's method finds; choose another starting output (--from)"
        )));
    }
    Ok((x, u))
}
