//! The designed controller around a plant: a digital loop sampled at tau, and step metrics.

use super::Design;
use crate::error::{Error, Result};
use crate::plants::rng::Rng;
use crate::simulate::System;

/// A setpoint step and how the loop is run.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Simulated time in seconds.
    pub duration: f64,
    /// Standard deviation of white noise added to each measured sample.
    pub noise_sd: f64,
    pub seed: u64,
    /// Input limits (the integrator holds while the input is clipped: no wind-up).
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

/// The designed step response at `times`: the model linearised at the setpoint under the
/// continuous-time control law, at rest at `from` with the bumpless integrator (so the setpoint
/// enters through the integrator only) and the setpoint applied from t = 0.
pub fn designed_response(d: &Design, from: f64, times: &[f64]) -> Vec<f64> {
    let n = d.order;
    let delta = from - d.setpoint;
    // z = [x - x*, q]; at rest at `from` the linearised model needs du = -A[n-1][0] delta / b.
    let mut z = vec![0.0; n + 1];
    z[0] = delta;
    let du_from = -d.a[(n - 1, 0)] * delta / d.b[n - 1];
    if d.k_i != 0.0 {
        z[n] = (-d.k[0] * delta - du_from) / d.k_i;
    }
    let f = |z: &[f64], dz: &mut [f64]| {
        let du = -(0..n).map(|j| d.k[j] * z[j]).sum::<f64>() - d.k_i * z[n];
        for i in 0..n {
            dz[i] = (0..n).map(|j| d.a[(i, j)] * z[j]).sum::<f64>() + d.b[i] * du;
        }
        dz[n] = z[0];
    };
    let rate = d
        .closed_loop
        .iter()
        .map(|(r, i)| r.hypot(*i))
        .fold(1e-300, f64::max);
    let mut out = Vec::with_capacity(times.len());
    let mut t = 0.0;
    for &ti in times {
        let steps = ((ti - t) * rate / 0.2).ceil().max(0.0) as usize;
        if steps > 0 {
            let h = (ti - t) / steps as f64;
            for _ in 0..steps {
                rk4(&mut z, h, f);
            }
            t = ti;
        }
        out.push(d.setpoint + z[0]);
    }
    out
}

/// Sub-steps per sample for RK4: the fastest linear rate times the sub-step stays below 0.5.
fn substeps(rate: f64, tau: f64) -> Result<usize> {
    let s = (rate * tau / 0.5).ceil().max(1.0);
    if s > 10_000.0 {
        return Err(Error::InvalidData(format!(
            "the closed loop has rates near {rate:.3e} 1/s: too stiff for a loop sampled every {tau} s"
        )));
    }
    Ok(s as usize)
}

/// Largest eigenvalue magnitude of a system's Jacobian at `x`, `u`.
fn fastest_rate(sys: &(dyn System + Sync), x: &[f64], u: &[f64]) -> f64 {
    let n = sys.dim();
    let mut jac = vec![0.0; n * n];
    sys.jacobian(x, u, &mut jac);
    let m = nalgebra::DMatrix::from_row_slice(n, n, &jac);
    super::design::eigenvalues(&m)
        .iter()
        .map(|(r, i)| r.hypot(*i))
        .fold(0.0, f64::max)
}

/// One RK4 step of `f` over `h`.
fn rk4(x: &mut [f64], h: f64, mut f: impl FnMut(&[f64], &mut [f64])) {
    let n = x.len();
    let (mut k1, mut k2, mut k3, mut k4) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut tmp = vec![0.0; n];
    f(x, &mut k1);
    for i in 0..n {
        tmp[i] = x[i] + 0.5 * h * k1[i];
    }
    f(&tmp, &mut k2);
    for i in 0..n {
        tmp[i] = x[i] + 0.5 * h * k2[i];
    }
    f(&tmp, &mut k3);
    for i in 0..n {
        tmp[i] = x[i] + h * k3[i];
    }
    f(&tmp, &mut k4);
    for i in 0..n {
        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/// Runs the designed loop around `plant`: the loop has held the plant at rest (input `u0`)
/// and the setpoint steps to the design's at t = 0; the observer starts at rest at the plant's
/// output and the integrator where it gives `u0` (a bumpless start, so the setpoint enters
/// through the integrator only, as in [`designed_response`]).
///
/// Each sample: measure (plus noise), compute the input from the observer's state and the
/// integral of the error, hold it over the sample; the plant and the observer (the design's
/// nonlinear model corrected by its gain towards the held measurement) advance together by RK4.
pub fn run(d: &Design, plant: &Plant, s: &Scenario) -> Result<Trace> {
    if !(s.duration.is_finite() && s.duration > 0.0) {
        return Err(Error::param(
            "duration",
            format!("{} s; give a value > 0", s.duration),
        ));
    }
    if !(s.noise_sd.is_finite() && s.noise_sd >= 0.0) {
        return Err(Error::param(
            "noise",
            format!("{}; give a standard deviation >= 0", s.noise_sd),
        ));
    }
    if let Some((lo, hi)) = s.u_limits {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(Error::param(
                "u_limits",
                format!("[{lo}, {hi}]; give finite limits, low < high"),
            ));
        }
    }
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
    let samples = (s.duration / d.tau).round();
    if samples > 1e7 {
        return Err(Error::param(
            "duration",
            format!("{} s is {samples} samples; at most 1e7", s.duration),
        ));
    }
    let samples = samples.max(1.0) as usize + 1;
    let n = d.order;
    let model = d.model.compile()?;
    // The observer's fastest rate is its own design; the plant's from its Jacobian at the start.
    let obs_rate = d
        .observer
        .iter()
        .chain(&d.open_loop)
        .map(|(r, i)| r.hypot(*i))
        .fold(0.0, f64::max);
    let rate = obs_rate.max(fastest_rate(sys, &plant.x0, &[d.u_star]));
    let sub = substeps(rate, d.tau)?;
    let h = d.tau / sub as f64;

    let mut rng = Rng::new(s.seed);
    let mut x = plant.x0.clone();
    let mut xh = vec![0.0; n];
    xh[0] = x[plant.output];
    let law = |xh: &[f64]| -> f64 {
        let mut dev = 0.0;
        for j in 0..n {
            let target = if j == 0 { d.setpoint } else { 0.0 };
            dev += d.k[j] * (xh[j] - target);
        }
        d.u_star - dev
    };
    let mut q = if d.k_i != 0.0 {
        (law(&xh) - plant.u0) / d.k_i
    } else {
        0.0
    };
    let scale = plant
        .x0
        .iter()
        .fold(d.setpoint.abs(), |m, v| m.max(v.abs()))
        .max(1.0);
    let mut tr = Trace {
        estimate: vec![Vec::with_capacity(samples); n],
        ..Default::default()
    };
    for k in 0..samples {
        let t = k as f64 * d.tau;
        let y = x[plant.output];
        let ym = y + s.noise_sd * rng.normal();
        let raw = law(&xh) - d.k_i * q;
        let u = match s.u_limits {
            Some((lo, hi)) => raw.clamp(lo, hi),
            None => raw,
        };
        tr.t.push(t);
        tr.y.push(y);
        tr.y_measured.push(ym);
        for j in 0..n {
            tr.estimate[j].push(xh[j]);
        }
        tr.u.push(u);
        if k + 1 == samples {
            break;
        }
        // Conditional integration: while the input is clipped, integrating would only wind up.
        if u == raw {
            q += d.tau * (ym - d.setpoint);
        }
        let uu = [u];
        for _ in 0..sub {
            rk4(&mut x, h, |x, dx| sys.rhs(x, &uu, dx));
            rk4(&mut xh, h, |z, dz| {
                model.rhs(z, &uu, dz);
                let e = ym - z[0];
                for j in 0..n {
                    dz[j] += d.l[j] * e;
                }
            });
        }
        if x.iter()
            .chain(&xh)
            .any(|v| !v.is_finite() || v.abs() > 1e12 * scale)
        {
            return Err(Error::InvalidData(format!(
                "the closed loop diverged at t = {:.6} s (plant or observer state beyond 1e12 times the setpoint's scale): lower the bandwidth or check the model",
                t + d.tau
            )));
        }
    }
    Ok(tr)
}

/// Step metrics of a trace for a step from `from` to the design's setpoint.
pub fn metrics(tr: &Trace, d: &Design, from: f64) -> StepMetrics {
    let setpoint = d.setpoint;
    let step = setpoint - from;
    let frac = |y: f64| if step == 0.0 { 1.0 } else { (y - from) / step };
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
            .fold(0.0, f64::max);
    let band = 0.02 * step.abs();
    let settling_time = match tr.y.iter().rposition(|y| (y - setpoint).abs() > band) {
        None => 0.0,
        Some(i) if i + 1 == tr.y.len() => f64::NAN,
        Some(i) => tr.t[i + 1],
    };
    let tail = (tr.y.len() / 10).max(1);
    let mean_tail = tr.y[tr.y.len() - tail..].iter().sum::<f64>() / tail as f64;
    let final_error = if step == 0.0 {
        0.0
    } else {
        100.0 * (mean_tail - setpoint) / step.abs()
    };
    let observer_rms = (tr
        .y
        .iter()
        .zip(&tr.estimate[0])
        .map(|(y, e)| (y - e).powi(2))
        .sum::<f64>()
        / tr.y.len() as f64)
        .sqrt();
    let design_deviation = designed_response(d, from, &tr.t)
        .iter()
        .zip(&tr.y)
        .map(|(yd, y)| (y - yd).abs())
        .fold(0.0, f64::max)
        / step.abs().max(1e-300)
        * 100.0;
    StepMetrics {
        design_deviation,
        rise_time,
        overshoot,
        settling_time,
        final_error,
        u_min: tr.u.iter().copied().fold(f64::INFINITY, f64::min),
        u_max: tr.u.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        observer_rms,
    }
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
    sys.rhs(&x, &[u], &mut f);
    let f_start = norm(&f).max(1e-300);
    for _ in 0..100 {
        sys.rhs(&x, &[u], &mut f);
        if norm(&f) <= 1e-12 * f_start {
            break;
        }
        sys.jacobian(&x, &[u], &mut jac);
        let du = 1e-7 * u.abs().max(1e-3);
        sys.rhs(&x, &[u + du], &mut f1);
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
    if x.iter().any(|v| !v.is_finite()) || !u.is_finite() || norm(&f) > 1e-6 * f_start.max(1.0) {
        return Err(Error::InvalidData(format!(
            "the plant has no rest state at output {y} that Newton's method finds; choose another starting output"
        )));
    }
    Ok((x, u))
}
