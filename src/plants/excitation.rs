//! The paper's excitation `u(t) = Sat(e^(-mu t) * sum_{i=1..n_B} a_i sin(w_i t + psi_i))`.
//!
//! Choices (the paper gives the formula and u_bar = 5, mu = 4, w_max = 10, n_B = 20, not the
//! distributions):
//! - `Sat` clips to `[-u_bar, u_bar]`;
//! - `a_i ~ U(-u_bar, u_bar)`, `w_i ~ U(0, w_max)`, `psi_i ~ U(0, 2 pi)`, independent, drawn in
//!   that order for i = 1..n_B from the run's stream. With these the sum starts with a spread of
//!   several u_bar, so the saturation is active during the first tenths of a second and the
//!   damping then brings the signal into the linear range: the runs start with a strong, clipped
//!   push and end close to rest.
//! - An affine map `gain * Sat(.) + offset` after the saturation lets a preset rescale or shift
//!   the signal (the physical throttle preset uses it to keep the angle on one side of rest).
//!
//! The saturation corners (where `|e^(-mu t) sum(...)| = u_bar`) are found by scanning at a step
//! of `1 / (20 (w_max + mu))` (so that two crossings closer than that would have to be a
//! near-tangency, whose clipped piece is negligible) and refining each bracket by bisection to
//! machine precision; [`crate::simulate`] stops exactly on them.

use super::rng::Rng;
use crate::simulate::Input;

/// Parameters of the excitation family.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcitationConfig {
    pub u_bar: f64,
    pub mu: f64,
    pub w_max: f64,
    pub n_b: usize,
    /// Applied after the saturation: `u = gain * Sat(s) + offset`.
    pub gain: f64,
    pub offset: f64,
}

impl ExcitationConfig {
    /// The paper's values: u_bar = 5, mu = 4, w_max = 10, n_B = 20.
    pub fn paper() -> ExcitationConfig {
        ExcitationConfig {
            u_bar: 5.0,
            mu: 4.0,
            w_max: 10.0,
            n_b: 20,
            gain: 1.0,
            offset: 0.0,
        }
    }

    /// Checks the settings (the fields are public): a positive saturation level, a bounded
    /// bandwidth (the saturation corners are searched at a step set by it), finite gain and
    /// offset. Refuses a `u_bar` that is not finite and positive, a `mu` that is negative (or NaN),
    /// a `w_max` that is not positive, a `w_max + mu` above 1e6 rad/s, and a gain or offset that is
    /// not finite.
    pub fn check(&self) -> crate::Result<()> {
        let ok = self.u_bar > 0.0
            && self.u_bar.is_finite()
            && self.mu >= 0.0
            && self.w_max > 0.0
            && self.w_max + self.mu <= 1e6
            && self.gain.is_finite()
            && self.offset.is_finite();
        if ok {
            Ok(())
        } else {
            Err(crate::Error::param(
                "excitation",
                format!(
                    "u_bar {:?}, mu {:?}, w_max {:?}, gain {:?}, offset {:?}: need u_bar > 0, mu >= 0, 0 < w_max, w_max + mu <= 1e6 rad/s, finite gain and offset",
                    self.u_bar, self.mu, self.w_max, self.gain, self.offset
                ),
            ))
        }
    }

    /// Draws one signal from `rng`.
    pub fn draw(&self, rng: &mut Rng) -> Excitation {
        let mut a = Vec::with_capacity(self.n_b);
        let mut w = Vec::with_capacity(self.n_b);
        let mut psi = Vec::with_capacity(self.n_b);
        for _ in 0..self.n_b {
            a.push(rng.uniform_in(-self.u_bar, self.u_bar));
            w.push(rng.uniform_in(0.0, self.w_max));
            psi.push(rng.uniform_in(0.0, 2.0 * std::f64::consts::PI));
        }
        Excitation {
            cfg: *self,
            a,
            w,
            psi,
        }
    }
}

/// One drawn excitation signal.
#[derive(Debug, Clone)]
pub struct Excitation {
    pub cfg: ExcitationConfig,
    pub a: Vec<f64>,
    pub w: Vec<f64>,
    pub psi: Vec<f64>,
}

impl Excitation {
    /// The unsaturated signal `e^(-mu t) sum a_i sin(w_i t + psi_i)` and its time derivative.
    /// Panics when `w` or `psi` is shorter than `a`.
    pub fn raw(&self, t: f64) -> (f64, f64) {
        let e = (-self.cfg.mu * t).exp();
        let (mut s, mut ds) = (0.0, 0.0);
        for i in 0..self.a.len() {
            let ph = self.w[i] * t + self.psi[i];
            s += self.a[i] * ph.sin();
            ds += self.a[i] * self.w[i] * ph.cos();
        }
        (e * s, e * (ds - self.cfg.mu * s))
    }

    /// `u(t)`.
    pub fn value(&self, t: f64) -> f64 {
        let (s, _) = self.raw(t);
        self.cfg.gain * s.clamp(-self.cfg.u_bar, self.cfg.u_bar) + self.cfg.offset
    }

    /// `u'(t)`; at a corner, the derivative from the right.
    pub fn derivative(&self, t: f64) -> f64 {
        let (s, ds) = self.raw(t);
        let ub = self.cfg.u_bar;
        if s > ub || s < -ub || (s == ub && ds >= 0.0) || (s == -ub && ds <= 0.0) {
            0.0
        } else {
            self.cfg.gain * ds
        }
    }

    /// Saturation corners strictly inside `(t0, t1)`, increasing.
    pub fn corners(&self, t0: f64, t1: f64, out: &mut Vec<f64>) {
        let ub = self.cfg.u_bar;
        let g = |t: f64| {
            let s = self.raw(t).0;
            // Distance to the nearer bound, signed: > 0 inside the band.
            (ub - s.abs(), s >= 0.0)
        };
        let step = 1.0 / (20.0 * (self.cfg.w_max + self.cfg.mu).max(1e-9));
        let n = ((t1 - t0) / step).ceil().max(1.0) as usize;
        let h = (t1 - t0) / n as f64;
        let mut ta = t0;
        let mut ga = g(ta);
        for k in 1..=n {
            let tb = if k == n { t1 } else { t0 + k as f64 * h };
            let gb = g(tb);
            // A sign change of ub - |s| with s keeping its sign: one band crossing. (s cannot
            // jump from +ub to -ub within a scan step.)
            if (ga.0 > 0.0) != (gb.0 > 0.0) {
                let (mut lo, mut hi) = (ta, tb);
                let inside_lo = ga.0 > 0.0;
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if mid <= lo || mid >= hi {
                        break;
                    }
                    if (g(mid).0 > 0.0) == inside_lo {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let tc = 0.5 * (lo + hi);
                if tc > t0 && tc < t1 {
                    out.push(tc);
                }
            }
            ta = tb;
            ga = gb;
        }
    }
}

/// Several excitation signals, one per input channel, as a simulator [`Input`].
#[derive(Debug, Clone)]
pub struct ExcitationInput {
    pub channels: Vec<Excitation>,
}

impl ExcitationInput {
    /// `u'(t)` per channel. Panics when `du` is shorter than `channels`.
    pub fn derivative(&self, t: f64, du: &mut [f64]) {
        for (c, e) in self.channels.iter().enumerate() {
            du[c] = e.derivative(t);
        }
    }
}

impl Input for ExcitationInput {
    fn n_inputs(&self) -> usize {
        self.channels.len()
    }
    fn eval(&self, t: f64, u: &mut [f64]) {
        for (c, e) in self.channels.iter().enumerate() {
            u[c] = e.value(t);
        }
    }
    fn breakpoints(&self, t0: f64, t1: f64, out: &mut Vec<f64>) {
        let start = out.len();
        for e in &self.channels {
            e.corners(t0, t1, out);
        }
        out[start..].sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    }
}
