//! Operating point, linearisation and pole placement.

use super::Design;
use crate::error::{Error, Result};
pub use crate::linalg::eigenvalues;
use crate::model::{CompiledModel, Model};
use nalgebra::{DMatrix, DVector};

use crate::model::MAX_ORDER;

/// What the design needs besides the model.
#[derive(Debug, Clone)]
pub struct DesignOptions {
    /// The output value to hold.
    pub setpoint: f64,
    /// Closed-loop bandwidth w in rad/s: the integrator's pole and every open-loop pole slower
    /// than w go to -w, faster ones to minus their magnitude ([`placed_poles`]); `None`: the
    /// geometric mean of the open-loop eigenvalue magnitudes at the setpoint, the plant's own
    /// typical speed.
    pub bandwidth: Option<f64>,
    /// Observer poles at -observer_speed * w, or minus the open-loop pole's magnitude where that
    /// is faster (default 3: fast enough that the observer does not shape the response, slow
    /// enough that noise is not amplified much more).
    pub observer_speed: f64,
    /// Sampling period of the digital controller, in seconds.
    pub tau: f64,
}

impl DesignOptions {
    pub fn new(setpoint: f64, tau: f64) -> DesignOptions {
        DesignOptions {
            setpoint,
            bandwidth: None,
            observer_speed: 3.0,
            tau,
        }
    }

    fn validate(&self) -> Result<()> {
        if !self.setpoint.is_finite() {
            return Err(Error::param(
                "setpoint",
                format!("{}; give a finite value", self.setpoint),
            ));
        }
        crate::records::check_tau(self.tau)?;
        if let Some(w) = self.bandwidth {
            if !(w.is_finite() && w > 0.0) {
                return Err(Error::param(
                    "bandwidth",
                    format!("{w} rad/s; give a value > 0"),
                ));
            }
        }
        if !(self.observer_speed.is_finite() && (1.0..=100.0).contains(&self.observer_speed)) {
            return Err(Error::param(
                "observer-speed",
                format!("{}; give a factor in [1, 100]", self.observer_speed),
            ));
        }
        Ok(())
    }
}

/// The order of a one-output, one-input model, or an error saying what feedback design needs.
pub fn siso_order(model: &Model) -> Result<usize> {
    if model.outputs.len() != 1 || model.inputs.len() != 1 {
        return Err(Error::param(
            "model",
            format!(
                "{} output(s) and {} input(s); feedback design takes one output and one input: identify a model of the loop's own output from its input (`identify --output Y --input U`) to design on and to run as --plant",
                model.outputs.len(),
                model.inputs.len()
            ),
        ));
    }
    let n = model.outputs[0].order;
    if n == 0 || n > MAX_ORDER {
        return Err(Error::param(
            "model",
            format!("order {n}; give 1..={MAX_ORDER}"),
        ));
    }
    Ok(n)
}

/// `P(y, 0, ..., 0, u)`, its derivative in u and the sum of its terms' magnitudes (the scale a
/// root is judged against), at rest at output `y`.
fn rest_eval(c: &CompiledModel, n: usize, y: f64, u: f64) -> (f64, f64, f64) {
    let mut z = vec![0.0; n + 1];
    z[0] = y;
    z[n] = u;
    let mut g = vec![0.0; n + 1];
    c.grad_output_unchecked(0, &z, &mut g);
    // The size of the sum the root cancels: sum |c_k phi_k(z)| over the terms (for named terms
    // too, where |c| at |z| says nothing: cos(y) or s*sat(u/s) - u can come out negative),
    // held at f64's largest: for terms near 1e308 the sum overflowed, and an infinite size
    // called every root one where the input has no effect.
    let size: f64 = c
        .term_values_unchecked(0, &z)
        .iter()
        .zip(c.coefficients())
        .map(|(v, k)| (k * v).abs())
        .sum::<f64>()
        .min(f64::MAX);
    (c.eval_output_unchecked(0, &z), g[n], size)
}

/// Starting inputs for the steady-input search, nearest zero first.
const STARTS: [f64; 13] = [
    0.0, 1.0, -1.0, 0.1, -0.1, 10.0, -10.0, 1e-3, -1e-3, 1e3, -1e3, 1e-5, -1e-5,
];

/// The steady input that holds the model at rest at output `y`: the root of
/// `P(y, 0, ..., 0, u) = 0` with the smallest |u| among those damped Newton iterations reach
/// from a few starting inputs (one step when P is linear in u, as identified models mostly are).
pub fn steady_input(model: &Model, y: f64) -> Result<f64> {
    let n = siso_order(model)?;
    if !y.is_finite() {
        return Err(Error::param(
            "setpoint",
            format!("{y}; give a finite value"),
        ));
    }
    let c = model.compile()?;
    let name = &model.outputs[0].name;
    let (p0, _, _) = rest_eval(&c, n, y, 0.0);
    if !p0.is_finite() {
        return Err(Error::InvalidData(format!(
            "the model is not finite at rest at {name} = {y:?}; choose another value"
        )));
    }
    let mut best: Option<f64> = None;
    let mut zero_slope_root = false;
    for &start in &STARTS {
        let mut u = start;
        let (mut p, mut dp, mut sz) = rest_eval(&c, n, y, u);
        for _ in 0..100 {
            if p.abs() <= 1e-12 * sz || dp == 0.0 || !dp.is_finite() {
                break;
            }
            // Damped: halve the step until |P| decreases (cubic-like P makes plain Newton cycle).
            let step = p / dp;
            let mut lambda = 1.0;
            let mut moved = false;
            for _ in 0..40 {
                let un = u - lambda * step;
                let (pn, dpn, szn) = rest_eval(&c, n, y, un);
                if pn.is_finite() && pn.abs() < p.abs() {
                    (u, p, dp, sz) = (un, pn, dpn, szn);
                    moved = true;
                    break;
                }
                lambda *= 0.5;
            }
            if !moved {
                break;
            }
        }
        if u.is_finite() && p.abs() <= 1e-9 * sz.max(1e-300) {
            // A root where P barely moves with u (a double root: P = (u - 1)^2) would need
            // gains without bound: it counts as no effect.
            if dp.abs() * u.abs().max(1.0) <= 1e-6 * sz {
                zero_slope_root = true;
            } else if best.is_none_or(|b| u.abs() < b.abs()) {
                best = Some(u);
            }
        }
    }
    match best {
        Some(u) => Ok(u),
        None if zero_slope_root || (0..=3).all(|k| {
            let (_, dp, _) = rest_eval(&c, n, y, STARTS[k]);
            dp == 0.0
        }) => Err(Error::InvalidData(format!(
            "the input has no effect on the model at {name} = {y:?} (dP/du = 0 where it would hold it): it cannot be controlled there; choose another setpoint"
        ))),
        None => Err(Error::InvalidData(format!(
            "no steady input holds the model at {name} = {y:?} ({} = P(..., u) has no root in u that Newton's method finds); choose another setpoint",
            crate::model::derivative_name(name, n)
        ))),
    }
}

/// The polynomial with roots `poles` (conjugate pairs listed once, with im > 0, or twice),
/// evaluated at M: `prod (M - p I)` over real poles times `M^2 - 2 re M + |p|^2 I` per pair.
fn poly_at(m: &DMatrix<f64>, poles: &[(f64, f64)]) -> DMatrix<f64> {
    let k = m.nrows();
    let id = DMatrix::<f64>::identity(k, k);
    let mut p = id.clone();
    for &(re, im) in poles {
        if im == 0.0 {
            p = &p * (m - &id * re);
        } else if im > 0.0 {
            p = &p * (m * m - m * (2.0 * re) + &id * (re * re + im * im));
        }
    }
    p
}

/// Smallest damping ratio of an open-loop pair the design leaves where it is.
pub const KEEP_DAMPING: f64 = 0.5;

/// Where the design puts the poles, for each open-loop eigenvalue (re, im): modes no faster than
/// `floor` go to -floor; faster stable modes stay where they are (real ones, and pairs damped at
/// least [`KEEP_DAMPING`]); faster unstable or lightly damped ones go to minus their magnitude
/// (a pair becomes a real double pole). Slowing a fast stable mode down would take gains that
/// cancel the plant's own damping, which the sampling delay then destabilises. The second value
/// says whether the pole was moved (moved poles must be slow against the sampling).
pub fn placed_poles(open_loop: &[(f64, f64)], floor: f64) -> Vec<((f64, f64), bool)> {
    open_loop
        .iter()
        .map(|&(re, im)| {
            let mag = re.hypot(im);
            if mag <= floor {
                ((-floor, 0.0), true)
            } else if re < 0.0 && (im == 0.0 || -re >= KEEP_DAMPING * mag) {
                ((re, im), false)
            } else {
                ((-mag, 0.0), true)
            }
        })
        .collect()
}

/// How far `poly_at(m, poles)` is from zero, relative to the size of its factors: by
/// Cayley-Hamilton 0 exactly when the eigenvalues of m are `poles`; checks that a placement was
/// achieved, whatever the rounding of the eigenvalues themselves (repeated poles split).
fn placement_residual(m: &DMatrix<f64>, poles: &[(f64, f64)]) -> f64 {
    let norm = m.norm();
    let size: f64 = poles
        .iter()
        .filter(|p| p.1 >= 0.0)
        .map(|&(re, im)| {
            if im == 0.0 {
                norm + re.abs()
            } else {
                (norm + re.hypot(im)).powi(2)
            }
        })
        .product();
    poly_at(m, poles).norm() / size.max(1e-300)
}

/// The closed loop of the linearisation under the gains, state `[x - x*, q]` (q the integral of
/// y - r), in the design's scaled time `w t` and states `y^(k) / w^k`, `q w`: the matrix whose
/// eigenvalues over w are the placed poles, of order one however fast the plant. Also the scales
/// (state = scale * scaled state).
pub fn scaled_closed_loop(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    k: &[f64],
    k_i: f64,
    w: f64,
) -> (DMatrix<f64>, Vec<f64>) {
    let n = k.len();
    let sc: Vec<f64> = (0..=n)
        .map(|j| if j < n { w.powi(j as i32) } else { 1.0 / w })
        .collect();
    let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
    for i in 0..n {
        for j in 0..n {
            m[(i, j)] = (a[(i, j)] - b[i] * k[j]) * sc[j] / sc[i] / w;
        }
        m[(i, n)] = -b[i] * k_i * sc[n] / sc[i] / w;
    }
    // q' = y - r: in scaled units exactly 1 (sc[0] / sc[n] / w, without its rounding).
    m[(n, 0)] = 1.0;
    (m, sc)
}

/// The scaled gains of a design: `k` = [K, k_i] on [x, q], `l` the observer's (see
/// [`scaled_closed_loop`] for the units).
struct SampledGains<'a> {
    k: &'a [f64],
    l: &'a [f64],
}

/// Spectral radius of the loop's one-sample map on the linearisation, in scaled units
/// (`a_s`, `b_s`, sample `tau_s` = w tau), exactly as [`super::closed_loop::run`] implements it:
/// the input u = -K x_hat - k_i q and the measurement y = x_0 are held over the sample, the plant
/// and the observer (corrected towards the held y) evolve in continuous time, and q integrates
/// the sampled y. State [x, x_hat, q]; below 1 the sampled loop is stable.
fn sampled_radius(
    a_s: &DMatrix<f64>,
    b_s: &DVector<f64>,
    g: &SampledGains,
    tau_s: f64,
) -> Result<f64> {
    let n = a_s.nrows();
    // exp([[M, G], [0, 0]] tau) holds Phi = exp(M tau) and Gamma = int_0^tau exp(M s) ds G, for
    // s = [x, x_hat], s' = M s + G [u, y].
    let mut big = DMatrix::<f64>::zeros(2 * n + 2, 2 * n + 2);
    for i in 0..n {
        for j in 0..n {
            big[(i, j)] = a_s[(i, j)];
            big[(n + i, n + j)] = a_s[(i, j)];
        }
        big[(n + i, n)] -= g.l[i];
        big[(i, 2 * n)] = b_s[i];
        big[(n + i, 2 * n)] = b_s[i];
        big[(n + i, 2 * n + 1)] = g.l[i];
    }
    let e = (big * tau_s).exp();
    // [u, y] = V [x, x_hat, q].
    let mut v = DMatrix::<f64>::zeros(2, 2 * n + 1);
    for j in 0..n {
        v[(0, n + j)] = -g.k[j];
    }
    v[(0, 2 * n)] = -g.k[n];
    v[(1, 0)] = 1.0;
    let mut f = e.view((0, 2 * n), (2 * n, 2)) * v;
    for i in 0..2 * n {
        for j in 0..2 * n {
            f[(i, j)] += e[(i, j)];
        }
    }
    let mut full = DMatrix::<f64>::zeros(2 * n + 1, 2 * n + 1);
    full.view_mut((0, 0), (2 * n, 2 * n + 1)).copy_from(&f);
    full[(2 * n, 0)] = tau_s;
    full[(2 * n, 2 * n)] = 1.0;
    Ok(eigenvalues(&full)?
        .iter()
        .map(|(re, im)| re.hypot(*im))
        .fold(0.0, f64::max))
}

/// Ackermann: the gain row `k` with eig(A - B k) at `poles`.
fn ackermann(a: &DMatrix<f64>, b: &DVector<f64>, poles: &[(f64, f64)]) -> Result<DVector<f64>> {
    let k = a.nrows();
    let mut ctrb = DMatrix::<f64>::zeros(k, k);
    let mut col = b.clone();
    for j in 0..k {
        ctrb.set_column(j, &col);
        col = a * &col;
    }
    let mut last = DVector::<f64>::zeros(k);
    last[k - 1] = 1.0;
    // k^T = e_last^T C^-1 p(A): solve C^T w = e_last, then k = p(A)^T w.
    let w = ctrb.transpose().lu().solve(&last).ok_or_else(|| {
        Error::InvalidData("the linearised model is not controllable at this setpoint".into())
    })?;
    Ok(poly_at(a, poles).transpose() * w)
}

/// The design: linearisation at the setpoint, state feedback with integral action, observer.
///
/// ```
/// use ctsid::control::{design, DesignOptions};
/// let plant = ctsid::Model::from_json_str(r#"{"format": "ctsid-model/2", "inputs": ["u"],
///   "outputs": [{"name": "y", "order": 1, "terms": [
///     {"exponents": {"y": 1}, "coefficient": -1}, {"exponents": {"u": 1}, "coefficient": 2}]}]}"#, "lag")?;
/// let d = design(&plant, &DesignOptions::new(0.5, 0.01))?;
/// // Holding y = 0.5 needs u = 0.25; the closed loop is stable.
/// assert!((d.u_star - 0.25).abs() < 1e-12);
/// assert!(d.closed_loop.iter().all(|&(re, _)| re < 0.0));
/// # Ok::<(), ctsid::Error>(())
/// ```
pub fn design(model: &Model, o: &DesignOptions) -> Result<Design> {
    o.validate()?;
    let n = siso_order(model)?;
    let u_star = steady_input(model, o.setpoint)?;
    let (a, b, notes) = linearised(model, o.setpoint, u_star, n)?;
    let open_loop = eigenvalues(&a)?;
    let w = bandwidth(o, &open_loop, n)?;
    let ctrl = placed_poles(&open_loop, w);
    let obs = placed_poles(&open_loop, o.observer_speed * w);
    check_moved_poles(o, w, (&ctrl, &obs))?;

    // Scaled time t' = w t and states y^(k) / w^k keep the matrices of order one (a throttle's
    // companion row holds 1e6 next to 1). The open loop with integral action (q_s' = y - r in
    // scaled units, q_s = w q) is the closed loop under zero gains.
    let (a_aug, sc) = scaled_closed_loop(&a, &b, &vec![0.0; n], 0.0, w);
    let a_s = a_aug.view((0, 0), (n, n)).into_owned();
    let mut b_aug = DVector::<f64>::zeros(n + 1);
    for i in 0..n {
        b_aug[i] = b[i] / sc[i] / w;
    }
    let scaled = |p: &[((f64, f64), bool)]| -> Vec<(f64, f64)> {
        p.iter().map(|((re, im), _)| (re / w, im / w)).collect()
    };
    let mut ctrl_s = scaled(&ctrl);
    ctrl_s.push((-1.0, 0.0));
    let k_aug = ackermann(&a_aug, &b_aug, &ctrl_s)?;
    // Observer of the state from y = x_0 (dual: gains for A^T, C^T).
    let mut c_t = DVector::<f64>::zeros(n);
    c_t[0] = 1.0;
    let obs_s = scaled(&obs);
    let l_s = ackermann(&a_s.transpose(), &c_t, &obs_s)?;
    let k: Vec<f64> = (0..n).map(|j| k_aug[j] / sc[j]).collect();
    let k_i = k_aug[n] * w;
    let l: Vec<f64> = (0..n).map(|i| w * sc[i] * l_s[i]).collect();
    // Check the placement in the scaled units it was made in: poles spread over many decades
    // (order 8, 1 to 1e4 rad/s) leave Ackermann's formula with too few digits.
    let (acl_s, _) = scaled_closed_loop(&a, &b, &k, k_i, w);
    let mut aobs_s = a_s.clone();
    for i in 0..n {
        aobs_s[(i, 0)] -= l_s[i];
    }
    let worst = placement_residual(&acl_s, &ctrl_s).max(placement_residual(&aobs_s, &obs_s));
    if worst.is_nan() || worst > 1e-6 {
        return Err(unreliable_placement(&open_loop, worst));
    }
    if k.iter().chain(&l).chain([&k_i]).any(|v| !v.is_finite()) {
        return Err(Error::InvalidData(
            "pole placement failed (gains not finite): the linearised model is too ill-conditioned at this setpoint".into(),
        ));
    }
    // The placement is continuous; the loop holds its input and measurement over each sample.
    // Slow poles (checked above) are not enough at high orders: the gains grow with the order,
    // and the hold's delay can destabilise a loop whose every pole is slow against tau.
    let gains = SampledGains {
        k: k_aug.as_slice(),
        l: l_s.as_slice(),
    };
    check_sampled_loop(&a_s, &b_aug.rows(0, n).into_owned(), &gains, (w, o.tau), n)?;

    Ok(Design {
        output: model.outputs[0].name.clone(),
        input: model.inputs[0].clone(),
        order: n,
        setpoint: o.setpoint,
        u_star,
        tau: o.tau,
        a,
        b,
        open_loop,
        bandwidth: w,
        observer_speed: o.observer_speed,
        k,
        k_i,
        l,
        closed_loop: eigenvalues(&acl_s)?
            .into_iter()
            .map(|(r, i)| (r * w, i * w))
            .collect(),
        observer: eigenvalues(&aobs_s)?
            .into_iter()
            .map(|(r, i)| (r * w, i * w))
            .collect(),
        model: model.clone(),
        notes,
    })
}

/// `d` with the chain-of-integrators observer ([`super::chain_observer_gains`], all poles of a
/// pure chain at `-observer_speed x bandwidth`) in place of the linearised one: its gains, its
/// error poles on the linearisation (`A - L C`) and the sampled loop checked with them, as
/// [`design`] checks its own. Before, the command line swapped the gains in afterwards and
/// printed the poles, and checked the loop, of an observer that did not run.
pub fn with_chain_observer(mut d: super::Design) -> Result<super::Design> {
    let n = d.order;
    d.l = super::chain_observer_gains(n, d.observer_speed * d.bandwidth);
    let w = d.bandwidth;
    // In the units design() checks in (time scaled by the bandwidth; states unscaled).
    let a_s = &d.a / w;
    let b_s = &d.b / w;
    let l_s: Vec<f64> = d.l.iter().map(|l| l / w).collect();
    let mut k_aug = d.k.clone();
    k_aug.push(d.k_i / w);
    let mut aobs = d.a.clone();
    for i in 0..n {
        aobs[(i, 0)] -= d.l[i];
    }
    d.observer = eigenvalues(&aobs)?;
    let gains = SampledGains { k: &k_aug, l: &l_s };
    check_sampled_loop(&a_s, &b_s, &gains, (w, d.tau), n)?;
    Ok(d)
}

/// The model's Jacobians at rest at `setpoint` under `u_star` (`n` states); refuses one that
/// is not finite. A slope that the model's sign smoothing sets is left out, with a note.
///
/// `sign(y_d1)` smoothed over a width w has the slope 1/w at rest: an artefact of the width,
/// not a property of the machine (EMPS: Coulomb friction 0.2395 over w = 8.6e-5 gave an open-loop
/// pole at -2788 /s, a default bandwidth of 0.235 rad/s and a 33 s step). At rest a Coulomb
/// friction is a bounded disturbance, which the integral action rejects, so the design takes the
/// exact sign's slope, 0: the Jacobian is computed again without the smoothing, and an entry
/// that differs by more than 1 % is taken from it. Nothing else depends on the widths (abs, sat,
/// relu and smooth laws such as `tanh(50*y_d1)` keep their slopes), and a sign a few widths off
/// its switch, whose smoothed slope is small but not the exact 0, gets the exact one too.
fn linearised(
    model: &Model,
    setpoint: f64,
    u_star: f64,
    n: usize,
) -> Result<(DMatrix<f64>, DVector<f64>, Vec<String>)> {
    let jacobians = |m: &Model| -> Result<Vec<f64>> {
        let c = m.compile()?;
        let mut x = vec![0.0; n];
        x[0] = setpoint;
        let (mut jx, mut ju) = (vec![0.0; n * n], vec![0.0; n]);
        c.jacobians_unchecked(&x, &[u_star], &mut jx, &mut ju);
        jx.extend(ju);
        Ok(jx)
    };
    let mut j = jacobians(model)?;
    let mut notes = Vec::new();
    if !model.sign_smoothing.is_empty() {
        let mut exact = model.clone();
        exact.sign_smoothing.clear();
        let je = jacobians(&exact)?;
        // Entry k: row k / n (k < n n) or the input's column (k >= n n); the rows above the last
        // are the chain y^(k)' = y^(k+1), which has no terms.
        let var = |k: usize| -> String {
            if k < n * n {
                crate::model::derivative_name(&model.outputs[0].name, k % n)
            } else {
                model.inputs[0].clone()
            }
        };
        let last = crate::model::derivative_name(&model.outputs[0].name, n);
        for (k, (v, e)) in j.iter_mut().zip(&je).enumerate() {
            if (*v - e).abs() > 0.01 * v.abs().max(e.abs()) && (*v - e).abs() > 1e-12 {
                notes.push(format!(
                    "d {last} / d {} at the setpoint, {}, comes from the sign smoothing (the exact sign's slope is 0 there), not from the machine: the design takes {} (a Coulomb friction at rest is a disturbance the integral action rejects)",
                    var(k),
                    crate::util::num4(*v),
                    crate::util::num4(*e)
                ));
                *v = *e;
            }
        }
    }
    let a = DMatrix::from_row_slice(n, n, &j[..n * n]);
    let b = DVector::from_column_slice(&j[n * n..]);
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) {
        return Err(Error::InvalidData(
            "the model's Jacobian at the setpoint is not finite".into(),
        ));
    }
    Ok((a, b, notes))
}

/// The design bandwidth: the one given, else the geometric mean of the open-loop pole
/// magnitudes; refuses one too slow to be shown settling within the loop's longest run.
fn bandwidth(o: &DesignOptions, open_loop: &[(f64, f64)], n: usize) -> Result<f64> {
    let w = match o.bandwidth {
        Some(w) => w,
        None => {
            let mags: Vec<f64> = open_loop
                .iter()
                .map(|(r, i)| r.hypot(*i))
                .filter(|m| *m > 0.0)
                .collect();
            if mags.is_empty() {
                return Err(Error::param(
                    "bandwidth",
                    "the model's open-loop eigenvalues are all 0 at the setpoint; give a bandwidth",
                ));
            }
            (mags.iter().map(|m| m.ln()).sum::<f64>() / mags.len() as f64).exp()
        }
    };
    // The loop runs at most MAX_SAMPLES samples, and its default length is settle_units / w:
    // a slower bandwidth could never be shown settling.
    let slowest = super::closed_loop::settle_units(n) / (super::MAX_SAMPLES as f64 * o.tau);
    if w < slowest {
        return Err(Error::param(
            "bandwidth",
            format!(
                "{w:e} rad/s is too slow for a controller sampled every {} s (settling would take over {} samples); give a bandwidth above {slowest:.3e} rad/s",
                o.tau,
                super::MAX_SAMPLES
            ),
        ));
    }
    Ok(w)
}

/// Refuses poles the design moves that are fast against the sampling (the controller updates
/// once per tau), saying whether the model's own mode or the bandwidth asks for them.
#[allow(clippy::type_complexity)]
fn check_moved_poles(
    o: &DesignOptions,
    w: f64,
    (ctrl, obs): (&[((f64, f64), bool)], &[((f64, f64), bool)]),
) -> Result<()> {
    // The poles the design moves must be slow against the sampling: the controller updates once
    // per tau, and a pole at -p holds its value over a sample only while p tau is small. (Fast
    // stable poles it keeps are the model's own, integrated as such.)
    let fastest_moved = ctrl
        .iter()
        .chain(obs)
        .filter(|(_, moved)| *moved)
        .map(|((re, im), _)| re.hypot(*im))
        .fold(0.0, f64::max);
    if fastest_moved * o.tau > 0.5 {
        let own = ctrl
            .iter()
            .chain(obs)
            .any(|((re, im), moved)| *moved && re.hypot(*im) > o.observer_speed * w);
        let fix = if own && 0.5 / fastest_moved < crate::records::TAU_MIN {
            format!(
                "the model has an unstable or lightly damped mode at {} rad/s that feedback must move, faster than any sampling (tau >= {:e} s) can follow; check the model's coefficients",
                crate::util::num4(fastest_moved),
                crate::records::TAU_MIN
            )
        } else if own {
            format!(
                "the model has a fast unstable or lightly damped mode at {} rad/s that feedback must move; sample faster: give a tau below {:.3e} s",
                crate::util::num4(fastest_moved),
                0.5 / fastest_moved
            )
        } else {
            format!(
                "{} puts the observer poles at {} rad/s, too fast for a controller sampled every {} s; give a bandwidth below {} rad/s",
                if o.bandwidth.is_some() {
                    format!("{} rad/s", crate::util::num4(w))
                } else {
                    format!(
                        "the default bandwidth {} rad/s (the geometric mean of the model's pole magnitudes)",
                        crate::util::num4(w)
                    )
                },
                crate::util::num4(o.observer_speed * w),
                o.tau,
                crate::util::num4(0.5 / (o.tau * o.observer_speed))
            )
        };
        return Err(Error::param(if own { "tau" } else { "bandwidth" }, fix));
    }
    Ok(())
}

/// The error for a placement whose poles are off by `worst` (relative), with how many decades
/// the model's modes spread over.
fn unreliable_placement(open_loop: &[(f64, f64)], worst: f64) -> Error {
    let mags = open_loop
        .iter()
        .map(|(r, i)| r.hypot(*i))
        .filter(|v| *v > 0.0);
    let (lo, hi) = mags.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let decades = if hi > 0.0 { (hi / lo).log10() } else { 0.0 };
    Error::InvalidData(format!(
        "pole placement is numerically unreliable for this model (relative residual {worst:.1e}; its modes spread over {decades:.1} decades): identify a lower order or give a bandwidth nearer the plant's poles"
    ))
}

/// Refuses gains whose loop, holding the input and measurement over each sample of `tau`, is
/// unstable (spectral radius of one sample at least 1), suggesting a tau that holds it.
fn check_sampled_loop(
    a_s: &DMatrix<f64>,
    b_s: &DVector<f64>,
    gains: &SampledGains,
    (w, tau): (f64, f64),
    n: usize,
) -> Result<()> {
    let radius = sampled_radius(a_s, b_s, gains, w * tau)?;
    if radius.is_nan() || radius >= 1.0 {
        // Suggested: a quarter of the longest tau / 2^h at which the sampled loop is stable (at
        // the limit itself it barely decays: an order-7 loop at its limit was 21 % off its
        // design, at a quarter of it 0.7 %).
        let stable_tau = (1..=20)
            .map(|h| tau / 2f64.powi(h))
            .find(|&t| sampled_radius(a_s, b_s, gains, w * t).is_ok_and(|r| r < 1.0))
            .map(|t| t / 4.0);
        let fix = match stable_tau {
            Some(t) if t >= crate::records::TAU_MIN => {
                format!("give a tau of {t:.3e} s or less (a quarter of the longest that is stable)")
            }
            _ => "no sampling period holds it: give another bandwidth or identify a lower order"
                .into(),
        };
        return Err(Error::param(
            "tau",
            format!(
                "the loop sampled every {} s is unstable (one sample multiplies a deviation by up to {radius:.3}; the continuous design is stable, holding the input and measurement over a sample is not, at order {n}): {fix}",
                tau
            ),
        ));
    }
    Ok(())
}
