//! Exponential sums: is a run, to the noise level, a short sum of (damped) exponentials and
//! sinusoids? If so its derivatives are analytic.
//!
//! Linear plants driven by multisines, free oscillations and periodic steady states give runs
//! that are exactly such sums. For them a parametric model beats every smoother: it has no
//! bandwidth to trade noise against bias, no end effects, and its error falls with the run's
//! length. For everything else (transients, saturation, chirps, nonlinear motion) it is wrong,
//! so it is used only when three checks pass:
//! 1. *Poles.* ESPRIT on the signal subspace of a Hankel matrix whose rows are D samples apart,
//!    D about 1/h (the smoother's bandwidth in samples), so that the poles of a heavily
//!    oversampled signal sit well apart on the unit circle. Only ranks the data state
//!    unambiguously are tried: where the Hankel spectrum drops by a factor `GAP` (20) both to the
//!    next eigenvalue and to the noise floor. A signal whose weakest components sit near the
//!    noise (a plant's response whose harmonics fade into it) has no such drop and keeps the
//!    smoother, which bounds what it cannot see by its prior instead of setting it to zero.
//! 2. *Whiteness.* Amplitudes by least squares, then poles and amplitudes refined together by
//!    Gauss-Newton; the residual must be white (Ljung-Box over 20 lags, fewer on short runs,
//!    below the 0.999 quantile of chi-square) at the chain's noise level. The covariance of the parameters gives each
//!    derivative's standard deviation (delta method).
//! 3. *Agreement.* Both estimates come from the same data, and a right, efficient model is the
//!    more precise one, so the difference between them has variance sd_smoother^2 - sd_model^2
//!    (a Hausman-type comparison; floored at a tenth of the smoother's variance). At every order
//!    the mean squared difference over that variance must be at most [`AGREE_MEAN`] and at
//!    least [`AGREE_SHARE`] of the samples within two of its standard deviations. A model that
//!    is white in values but wrong in derivatives (poles fitted to a chirp, sinusoids that miss a
//!    small transient or drift) fails here; on right models the mean is about 1.
//!
//! # Limits
//! A signal whose components continue below the noise (the harmonics of a periodic nonlinear
//! response at very low noise) can pass all three checks with its weakest components left out:
//! the values are then about as good as the smoother's, but the model's sigma, which knows only
//! its parameters' uncertainty, is too small at the higher orders.
//!
//! The cost is one L x L Hankel Gram matrix (L <= 40) and a few small least-squares problems per
//! run, O(N L^2); runs longer than [`MAX_LEN`] samples are left to the smoother.

use nalgebra::{Complex, DMatrix, DVector};

/// Longest run tried: beyond it the Gram matrix and the least squares cost more than the
/// smoother itself, and long records are rarely one short exponential sum.
pub const MAX_LEN: usize = 1 << 17;

/// Most Hankel rows (the largest model has L/2 poles), and the fewest the lag leaves room for.
const MAX_ROWS: usize = 40;
const MIN_ROWS: usize = 20;

/// Smallest drop of the Hankel spectrum that ends the signal subspace (module docs, step 1).
const GAP: f64 = 20.0;

/// Most lags of the Ljung-Box statistic (a quarter of the run for short ones).
const LB_LAGS: usize = 20;

/// Upper 0.999 point of the standard normal, for the chi-square quantile of the Ljung-Box test.
const Z_999: f64 = 3.090;

/// Largest residual variance, relative to the smoother's noise variance.
const RESID_RATIO: f64 = 1.15;

/// Agreement with the smoother (module docs, step 3). `cargo bench --bench
/// derive_holdout` prints the statistics: right models (sums of sinusoids) means 0.56-1.40,
/// shares 0.93-0.99; sinusoids plus a small transient or bump the model leaves out 2.6-3.3,
/// 0.75-0.76.
pub const AGREE_MEAN: f64 = 2.5;
pub const AGREE_SHARE: f64 = 0.8;

/// Floor of the difference variance, as a share of the smoother's variance.
const AGREE_FLOOR: f64 = 0.1;

/// Samples between exact exponentials in [`ExpSum::exps`] (the products between them lose
/// about one rounding error each).
const REANCHOR: usize = 256;

/// Iteration limit of the eigen, Schur and singular value decompositions (they converge in
/// tens; the limit turns a pathological matrix into "no model" instead of a hang).
const ITER_LIMIT: usize = 10_000;

/// Gauss-Newton refinements of poles and amplitudes.
const GN_STEPS: usize = 4;

/// A fitted sum `offset + sum_j Re(c_j exp(lambda_j t))`, t in seconds from the run's middle.
#[derive(Debug, Clone)]
pub struct ExpSum {
    lam: Vec<Complex<f64>>,
    coef: Vec<Complex<f64>>,
    offset: f64,
    tau: f64,
    mid: f64,
    /// Covariance factor F (P x P): Cov(theta) = F F^T.
    cov_factor: DMatrix<f64>,
}

impl ExpSum {
    /// Number of exponential terms (a sinusoid counts two).
    pub fn terms(&self) -> usize {
        self.lam
            .iter()
            .map(|l| if l.im == 0.0 { 1 } else { 2 })
            .sum()
    }

    fn params(&self) -> usize {
        1 + self
            .lam
            .iter()
            .map(|l| if l.im == 0.0 { 2 } else { 4 })
            .sum::<usize>()
    }

    fn time(&self, i: usize) -> f64 {
        i as f64 * self.tau - self.mid
    }

    /// exp(lambda_j t_i) for all samples (row-major, one row per sample), by multiplication
    /// with exp(lambda_j tau) and a fresh exponential every [`REANCHOR`] samples.
    fn exps(&self, n: usize) -> Vec<Complex<f64>> {
        let nt = self.lam.len();
        let step: Vec<Complex<f64>> = self.lam.iter().map(|l| (l * self.tau).exp()).collect();
        let mut e = vec![Complex::new(0.0, 0.0); n * nt];
        for i in 0..n {
            for j in 0..nt {
                e[i * nt + j] = if i % REANCHOR == 0 {
                    (self.lam[j] * self.time(i)).exp()
                } else {
                    e[(i - 1) * nt + j] * step[j]
                };
            }
        }
        e
    }

    /// The signal at every sample.
    fn values0(&self, e: &[Complex<f64>], n: usize) -> Vec<f64> {
        let nt = self.lam.len();
        (0..n)
            .map(|i| {
                let row = &e[i * nt..(i + 1) * nt];
                self.offset
                    + row
                        .iter()
                        .zip(&self.coef)
                        .map(|(ei, c)| (c * ei).re)
                        .sum::<f64>()
            })
            .collect()
    }

    /// The k-th derivative at every sample (`v`) and its gradient with respect to the parameters
    /// (`g`, n x P: offset, then per term Re lambda, [Im lambda,] Re c, [Im c]).
    fn rows(&self, k: usize, e: &[Complex<f64>], g: &mut DMatrix<f64>, v: &mut [f64]) {
        let nt = self.lam.len();
        let lk: Vec<Complex<f64>> = self.lam.iter().map(|l| l.powi(k as i32)).collect();
        let dlk: Vec<Complex<f64>> = self
            .lam
            .iter()
            .map(|l| {
                if k == 0 {
                    Complex::new(0.0, 0.0)
                } else {
                    l.powi(k as i32 - 1) * k as f64
                }
            })
            .collect();
        for (i, vi) in v.iter_mut().enumerate() {
            let t = self.time(i);
            *vi = if k == 0 { self.offset } else { 0.0 };
            g[(i, 0)] = if k == 0 { 1.0 } else { 0.0 };
            let mut c = 1;
            for j in 0..nt {
                let ei = e[i * nt + j];
                let gc = lk[j] * ei;
                let gl = self.coef[j] * (dlk[j] + lk[j] * t) * ei;
                *vi += (self.coef[j] * gc).re;
                if self.lam[j].im == 0.0 {
                    g[(i, c)] = gl.re;
                    g[(i, c + 1)] = gc.re;
                    c += 2;
                } else {
                    g[(i, c)] = gl.re;
                    g[(i, c + 1)] = -gl.im;
                    g[(i, c + 2)] = gc.re;
                    g[(i, c + 3)] = -gc.im;
                    c += 4;
                }
            }
        }
    }

    /// Derivatives 0..=max_order at samples 0..n and their standard deviations (delta method:
    /// the gradient rows of all samples times the covariance factor, one matrix product per
    /// order).
    pub fn evaluate(&self, n: usize, max_order: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let e = self.exps(n);
        let mut g = DMatrix::<f64>::zeros(n, self.params());
        let mut values = Vec::with_capacity(max_order + 1);
        let mut sds = Vec::with_capacity(max_order + 1);
        for k in 0..=max_order {
            let mut v = vec![0.0; n];
            self.rows(k, &e, &mut g, &mut v);
            let gf = &g * &self.cov_factor;
            sds.push(gf.row_iter().map(|r| r.norm()).collect());
            values.push(v);
        }
        (values, sds)
    }

    fn apply(&mut self, dtheta: &[f64], step: f64) {
        self.offset += step * dtheta[0];
        let mut p = 1;
        for (l, c) in self.lam.iter_mut().zip(self.coef.iter_mut()) {
            if l.im == 0.0 {
                l.re += step * dtheta[p];
                c.re += step * dtheta[p + 1];
                p += 2;
            } else {
                l.re += step * dtheta[p];
                l.im += step * dtheta[p + 1];
                c.re += step * dtheta[p + 2];
                c.im += step * dtheta[p + 3];
                p += 4;
            }
        }
    }
}

/// Fits an exponential sum to one run (`y` centred or not) if one explains it to the noise
/// level `sigma2`; `h` is the smoother's tuned scaled step. `None` for a run shorter than 50 or
/// longer than [`MAX_LEN`] samples, an `h` that is NaN or not positive, a noise-free run (`sigma2`
/// NaN or below 1e-12 of the run's mean square), and wherever no model passes the pole and
/// whiteness checks or a decomposition does not converge.
pub fn fit(y: &[f64], tau: f64, sigma2: f64, h: f64) -> Option<ExpSum> {
    let n = y.len();
    if !(50..=MAX_LEN).contains(&n) || h.is_nan() || h <= 0.0 {
        return None;
    }
    let power = y.iter().map(|v| v * v).sum::<f64>() / n as f64;
    // Noise-free runs: the smoother is already exact there, and the whiteness test has nothing
    // to measure.
    if sigma2.is_nan() || sigma2 <= 1e-12 * power {
        return None;
    }
    // A very smooth run (tiny h: a drift, a slow exponential) would get a lag longer than the
    // run; the lag is capped so that at least MIN_ROWS rows fit in half of it.
    let d = ((1.0 / h).round() as usize).clamp(1, ((n / 2) / (MIN_ROWS - 1)).max(1));
    // At least MIN_ROWS rows: n >= 50 and the clamp above leave room for them.
    let l = MAX_ROWS.min((n / 2) / d + 1);
    let m = n - (l - 1) * d;
    // G[a][b] = sum_{j < m} y[j + aD] y[j + bD]: the first row directly, the rest from the
    // entry above-left by moving the window D samples (O(L m + L^2 D) instead of O(L^2 m)).
    let dot = |a: usize, b: usize, from: usize, to: usize| -> f64 {
        (from..to).map(|j| y[j + a * d] * y[j + b * d]).sum()
    };
    let mut g = DMatrix::<f64>::zeros(l, l);
    for b in 0..l {
        g[(0, b)] = dot(0, b, 0, m);
    }
    for a in 1..l {
        for b in a..l {
            g[(a, b)] = g[(a - 1, b - 1)] - dot(a - 1, b - 1, 0, d) + dot(a - 1, b - 1, m, m + d);
        }
    }
    for a in 0..l {
        for b in 0..a {
            g[(a, b)] = g[(b, a)];
        }
    }
    // nalgebra's default decompositions iterate without a limit, forever on a NaN.
    if !g.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = nalgebra::SymmetricEigen::try_new(g, f64::EPSILON, ITER_LIMIT)?;
    let mut order: Vec<usize> = (0..l).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let floor = m as f64 * sigma2 * (1.0 + (l as f64 / m as f64).sqrt()).powi(2);
    let ev: Vec<f64> = order.iter().map(|&i| eig.eigenvalues[i]).collect();
    let half_span = 0.5 * (n - 1) as f64 * tau;
    // Only ranks after which the spectrum drops by GAP, to below GAP times the weakest kept
    // eigenvalue and to the noise floor: an order the data state unambiguously.
    for r in (1..=l / 2).filter(|&r| ev[r - 1] >= GAP * ev[r].max(floor)) {
        let Some(lam) = esprit(&eig.eigenvectors, &order[..r], l, d as f64 * tau, half_span) else {
            continue;
        };
        let mut es = ExpSum {
            coef: vec![Complex::new(0.0, 0.0); lam.len()],
            lam,
            offset: 0.0,
            tau,
            mid: half_span,
            cov_factor: DMatrix::zeros(0, 0),
        };
        if !amplitudes(&mut es, y) {
            continue;
        }
        refine(&mut es, y, half_span);
        // One Jacobian at the final parameters gives both the residual and the covariance.
        let (jac, fitted) = jacobian(&es, n);
        let resid: Vec<f64> = y.iter().zip(&fitted).map(|(a, b)| a - b).collect();
        if !white(&resid, sigma2) {
            continue;
        }
        let s2 = resid.iter().map(|v| v * v).sum::<f64>() / (n - es.params()).max(1) as f64;
        let Some(f) = covariance_factor(&jac, s2) else {
            continue;
        };
        es.cov_factor = f;
        return Some(es);
    }
    None
}

/// Continuous-time poles (upper half plane and real axis) from the `r` leading eigenvectors.
fn esprit(
    vecs: &DMatrix<f64>,
    cols: &[usize],
    l: usize,
    lag: f64,
    half_span: f64,
) -> Option<Vec<Complex<f64>>> {
    let r = cols.len();
    let mut u1 = DMatrix::<f64>::zeros(l - 1, r);
    let mut u2 = DMatrix::<f64>::zeros(l - 1, r);
    for (c, &i) in cols.iter().enumerate() {
        for a in 0..l - 1 {
            u1[(a, c)] = vecs[(a, i)];
            u2[(a, c)] = vecs[(a + 1, i)];
        }
    }
    let phi = (u1.transpose() * &u1).try_inverse()? * u1.transpose() * u2;
    if !phi.iter().all(|v| v.is_finite()) {
        return None;
    }
    let z = nalgebra::Schur::try_new(phi, f64::EPSILON, ITER_LIMIT)?.complex_eigenvalues();
    let mut lam = Vec::new();
    for zi in z.iter() {
        // A pole at the lag's Nyquist frequency (negative real z) is aliased; a pole at z = 0
        // decays within one lag; one growing by e^40 over half the run is not a plant's.
        if zi.norm() < 1e-8 || zi.arg().abs() > 0.9 * std::f64::consts::PI {
            return None;
        }
        let li = zi.ln() / lag;
        if li.re.abs() * half_span > 40.0 {
            return None;
        }
        // A conjugate pair has its partner below the axis (the eigenvalues come as exact
        // conjugates); a real z gives a real pole.
        let real = zi.im == 0.0;
        if !real && li.im < 0.0 {
            continue;
        }
        lam.push(if real { Complex::new(li.re, 0.0) } else { li });
    }
    Some(lam)
}

/// Least-squares offset and amplitudes for fixed poles; false when singular.
fn amplitudes(es: &mut ExpSum, y: &[f64]) -> bool {
    let n = y.len();
    let cols = 1 + es.terms();
    let nt = es.lam.len();
    let e = es.exps(n);
    let mut a = DMatrix::<f64>::zeros(n, cols);
    for i in 0..n {
        a[(i, 0)] = 1.0;
        let mut c = 1;
        for (j, l) in es.lam.iter().enumerate() {
            let ei = e[i * nt + j];
            a[(i, c)] = ei.re;
            c += 1;
            if l.im != 0.0 {
                a[(i, c)] = -ei.im;
                c += 1;
            }
        }
    }
    let Some(x) = solve_ls(&a, y) else {
        return false;
    };
    es.offset = x[0];
    let mut c = 1;
    for (l, k) in es.lam.iter().zip(es.coef.iter_mut()) {
        if l.im == 0.0 {
            *k = Complex::new(x[c], 0.0);
            c += 1;
        } else {
            *k = Complex::new(x[c], x[c + 1]);
            c += 2;
        }
    }
    true
}

/// Least squares through the column-scaled normal equations and a pseudo-inverse: the
/// exponentials of nearby poles are nearly collinear, and the small systems (P <= 81) cost
/// little beside forming them.
fn solve_ls(a: &DMatrix<f64>, y: &[f64]) -> Option<DVector<f64>> {
    let (ata, scale) = scaled_gram(a)?;
    let aty = a.transpose() * DVector::from_column_slice(y);
    let rhs = aty.component_mul(&scale);
    if !ata.iter().chain(rhs.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let svd = nalgebra::SVD::try_new(ata, true, true, f64::EPSILON, ITER_LIMIT)?;
    let x = svd.solve(&rhs, 1e-12).ok()?;
    let x = x.component_mul(&scale);
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// A^T A with unit diagonal and the column scaling that gave it.
fn scaled_gram(a: &DMatrix<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let ata = a.transpose() * a;
    let p = ata.nrows();
    let mut scale = DVector::zeros(p);
    for j in 0..p {
        let d = ata[(j, j)];
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        scale[j] = 1.0 / d.sqrt();
    }
    let mut s = ata;
    for i in 0..p {
        for j in 0..p {
            s[(i, j)] *= scale[i] * scale[j];
        }
    }
    Some((s, scale))
}

/// Jacobian of the values (n x P) and the values.
fn jacobian(es: &ExpSum, n: usize) -> (DMatrix<f64>, Vec<f64>) {
    let mut j = DMatrix::<f64>::zeros(n, es.params());
    let mut v = vec![0.0; n];
    es.rows(0, &es.exps(n), &mut j, &mut v);
    (j, v)
}

/// Gauss-Newton on poles and amplitudes together, each step halved until the residual shrinks.
fn refine(es: &mut ExpSum, y: &[f64], half_span: f64) {
    let n = y.len();
    let rss = |e: &ExpSum| -> f64 {
        let v = e.values0(&e.exps(n), n);
        y.iter().zip(&v).map(|(a, b)| (a - b).powi(2)).sum()
    };
    let mut cur = rss(es);
    for _ in 0..GN_STEPS {
        let (jac, v) = jacobian(es, n);
        let resid: Vec<f64> = y.iter().zip(&v).map(|(a, b)| a - b).collect();
        let Some(dx) = solve_ls(&jac, &resid) else {
            return;
        };
        let mut step = 1.0;
        let mut improved = false;
        while step > 1e-3 {
            let mut trial = es.clone();
            trial.apply(dx.as_slice(), step);
            let stable = trial.lam.iter().all(|l| l.re.abs() * half_span <= 40.0);
            let r = rss(&trial);
            if stable && r < cur {
                *es = trial;
                improved = (cur - r) > 1e-10 * cur;
                cur = r;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            return;
        }
    }
}

/// F with Cov(theta) = s2 (J^T J)^-1 = F F^T for the Jacobian `jac` of the values, through the scaled Gram matrix's eigenvectors
/// (directions it cannot see get no variance rather than an infinite one: they are the
/// collinear ones, whose combination in the values the other directions already carry).
fn covariance_factor(jac: &DMatrix<f64>, s2: f64) -> Option<DMatrix<f64>> {
    let (m, scale) = scaled_gram(jac)?;
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = nalgebra::SymmetricEigen::try_new(m, f64::EPSILON, ITER_LIMIT)?;
    let top = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let p = scale.len();
    let mut f = DMatrix::<f64>::zeros(p, p);
    for c in 0..p {
        let ev = eig.eigenvalues[c];
        if ev <= 1e-12 * top {
            continue;
        }
        let w = (s2 / ev).sqrt();
        for r in 0..p {
            f[(r, c)] = scale[r] * eig.eigenvectors[(r, c)] * w;
        }
    }
    Some(f)
}

/// Residual white at the noise level: Ljung-Box over [`LB_LAGS`] lags, variance at most
/// [`RESID_RATIO`] times the smoother's noise variance.
fn white(resid: &[f64], sigma2: f64) -> bool {
    let n = resid.len();
    let c0: f64 = resid.iter().map(|v| v * v).sum();
    if c0.is_nan() || c0 <= 0.0 || c0 / n as f64 > RESID_RATIO * sigma2 {
        return false;
    }
    let lags = LB_LAGS.min(n / 4);
    let mut q = 0.0;
    for k in 1..=lags {
        let ck: f64 = (k..n).map(|i| resid[i] * resid[i - k]).sum();
        q += (ck / c0).powi(2) / (n - k) as f64;
    }
    q * (n * (n + 2)) as f64 <= chi2_999(lags as f64)
}

/// 0.999 quantile of chi-square with `nu` degrees of freedom (Wilson-Hilferty; 45.4 at 20
/// against the exact 45.3).
fn chi2_999(nu: f64) -> f64 {
    let c = 2.0 / (9.0 * nu);
    nu * (1.0 - c + Z_999 * c.sqrt()).powi(3)
}

/// Whether the model's derivatives (`model`, `model_sd`) agree with the smoother's (`mean`,
/// `sd`, same centring) at every order (module docs, step 3). Panics as [`agreement`] does.
pub fn agrees(
    model: &[Vec<f64>],
    model_sd: &[Vec<f64>],
    mean: &[Vec<f64>],
    sd: &[Vec<f64>],
) -> bool {
    let (z2, share) = agreement(model, model_sd, mean, sd);
    z2 <= AGREE_MEAN && share >= AGREE_SHARE
}

/// The agreement statistics behind [`agrees`]: the largest mean squared difference over its
/// variance, and the smallest share of samples within two of its standard deviations, over the
/// orders (infinity and 0 where a difference is not finite or has no variance to be judged by).
/// Panics when `model`, `model_sd` or `sd` has fewer orders than `mean`, or at some order fewer
/// samples than `mean`.
pub fn agreement(
    model: &[Vec<f64>],
    model_sd: &[Vec<f64>],
    mean: &[Vec<f64>],
    sd: &[Vec<f64>],
) -> (f64, f64) {
    let (mut worst_z2, mut worst_share) = (0.0f64, 1.0f64);
    for k in 0..mean.len() {
        let n = mean[k].len();
        let (mut z2, mut inside) = (0.0, 0usize);
        for i in 0..n {
            let diff = model[k][i] - mean[k][i];
            let (sc, sm) = (sd[k][i] * sd[k][i], model_sd[k][i] * model_sd[k][i]);
            if !(diff.is_finite() && sm.is_finite()) {
                return (f64::INFINITY, 0.0);
            }
            let var = (sc - sm).max(AGREE_FLOOR * sc);
            if var.is_nan() || var <= 0.0 {
                if diff != 0.0 {
                    return (f64::INFINITY, 0.0);
                }
                inside += 1;
                continue;
            }
            z2 += diff * diff / var;
            if diff * diff <= 4.0 * var {
                inside += 1;
            }
        }
        worst_z2 = worst_z2.max(z2 / n as f64);
        worst_share = worst_share.min(inside as f64 / n as f64);
    }
    (worst_z2, worst_share)
}
