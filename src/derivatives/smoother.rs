//! Kalman filter and Rauch-Tung-Striebel smoother for a scalar measurement of the first state,
//! written over fixed-size arrays (`const M`) so the small matrix products are unrolled.
//!
//! Everything about the covariances is data independent: for a time-invariant model and a run
//! length n, the filter covariances converge to a steady state within a few bandwidths, and so do
//! the smoothed ones away from the ends. [`Covariances`] stores only the transients (start, end)
//! plus the steady values, is computed once per (model, n) and shared by every run of that
//! length; each run then costs two O(n M^2) mean passes. Measurement noise has unit variance
//! here: the common scale sigma^2 of noise and process is profiled out of the likelihood.

use super::statespace::Discrete;

type Mat<const M: usize> = [[f64; M]; M];
type Vct<const M: usize> = [f64; M];

#[inline(always)]
fn mul<const M: usize>(a: &Mat<M>, b: &Mat<M>) -> Mat<M> {
    let mut o = [[0.0; M]; M];
    for i in 0..M {
        for k in 0..M {
            let aik = a[i][k];
            for j in 0..M {
                o[i][j] += aik * b[k][j];
            }
        }
    }
    o
}

#[inline(always)]
fn mul_bt<const M: usize>(a: &Mat<M>, b: &Mat<M>) -> Mat<M> {
    let mut o = [[0.0; M]; M];
    for i in 0..M {
        for j in 0..M {
            let mut s = 0.0;
            for k in 0..M {
                s += a[i][k] * b[j][k];
            }
            o[i][j] = s;
        }
    }
    o
}

#[inline(always)]
fn matvec<const M: usize>(a: &Mat<M>, x: &Vct<M>) -> Vct<M> {
    let mut o = [0.0; M];
    for i in 0..M {
        let mut s = 0.0;
        for k in 0..M {
            s += a[i][k] * x[k];
        }
        o[i] = s;
    }
    o
}

fn sym<const M: usize>(p: &mut Mat<M>) {
    for i in 0..M {
        for j in 0..i {
            let v = 0.5 * (p[i][j] + p[j][i]);
            p[i][j] = v;
            p[j][i] = v;
        }
    }
}

/// Converged when every entry moved less than `tol` relative to the diagonal scales.
fn close<const M: usize>(a: &Mat<M>, b: &Mat<M>, tol: f64) -> bool {
    (0..M).all(|i| {
        (0..M).all(|j| (a[i][j] - b[i][j]).abs() <= tol * (a[i][i] * a[j][j]).abs().sqrt() + 1e-300)
    })
}

fn to_mat<const M: usize>(v: &[f64]) -> Mat<M> {
    let mut o = [[0.0; M]; M];
    for i in 0..M {
        for j in 0..M {
            o[i][j] = v[i * M + j];
        }
    }
    o
}

/// Relative tolerance for declaring a covariance recursion converged.
const STEADY_TOL: f64 = 1e-10;

/// Data-independent covariances of the filter and smoother for one model and run length.
#[derive(Debug, Clone)]
pub struct Covariances<const M: usize> {
    pub n: usize,
    pub a: Mat<M>,
    pub diffuse: bool,
    /// Kalman gain and innovation variance at sample k < gain.len() - 1, then the steady values.
    pub gain: Vec<Vct<M>>,
    pub s: Vec<f64>,
    /// RTS gains, same indexing as `gain`.
    pub rts: Vec<Mat<M>>,
    /// Smoothed variances (diagonal): the first `head.len()` samples, the last `tail.len()`
    /// samples (`tail[0]` is sample n-1), and the steady value in between.
    pub head: Vec<Vct<M>>,
    pub tail: Vec<Vct<M>>,
    pub steady: Vct<M>,
}

impl<const M: usize> Covariances<M> {
    #[inline(always)]
    fn fidx(&self, k: usize) -> usize {
        k.min(self.gain.len() - 1)
    }

    /// Smoothed variance (diagonal) at sample k; without the smoother part (`new(.., false)`)
    /// only at the last sample.
    pub fn var(&self, k: usize) -> &Vct<M> {
        if k < self.head.len() {
            &self.head[k]
        } else if self.n - 1 - k < self.tail.len() {
            &self.tail[self.n - 1 - k]
        } else {
            &self.steady
        }
    }

    /// `with_smoother = false` computes only what the likelihood needs (the filter part).
    pub fn new(d: &Discrete, n: usize, with_smoother: bool) -> Self {
        assert_eq!(d.m, M);
        let a: Mat<M> = to_mat(&d.a);
        let q: Mat<M> = to_mat(&d.q);
        let mut pp: Mat<M> = to_mat(&d.p0);
        let (mut pps, mut pfs, mut gains, mut ss) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut next;
        loop {
            let k = pps.len();
            let s = pp[0][0] + 1.0;
            let mut g = [0.0; M];
            for i in 0..M {
                g[i] = pp[i][0] / s;
            }
            let mut pf = pp;
            for i in 0..M {
                for j in 0..M {
                    pf[i][j] -= g[i] * pp[0][j];
                }
            }
            sym(&mut pf);
            next = mul_bt(&mul(&a, &pf), &a);
            for i in 0..M {
                for j in 0..M {
                    next[i][j] += q[i][j];
                }
            }
            sym(&mut next);
            let converged = k > M && close(&pp, &next, STEADY_TOL);
            pps.push(pp);
            pfs.push(pf);
            gains.push(g);
            ss.push(s);
            if converged || k + 1 == n {
                break;
            }
            pp = next;
        }
        let last = pps.len() - 1;
        if !with_smoother {
            // The last sample's smoothed variance is its filtered one: kept for `var(n - 1)`.
            let mut end = [0.0; M];
            for i in 0..M {
                end[i] = pfs[last][i][i].max(0.0);
            }
            return Covariances {
                n,
                a,
                diffuse: d.diffuse,
                gain: gains,
                s: ss,
                rts: Vec::new(),
                head: Vec::new(),
                tail: vec![end],
                steady: [0.0; M],
            };
        }
        let pp_after = if last + 1 < n { next } else { pps[last] };
        let rts: Vec<Mat<M>> = (0..=last)
            .map(|k| rts_gain(&pfs[k], &a, if k < last { &pps[k + 1] } else { &pp_after }))
            .collect();
        let fidx = |k: usize| k.min(last);

        // Backward covariance recursion; steady stretches are skipped once converged.
        let diag = |p: &Mat<M>| -> Vct<M> {
            let mut v = [0.0; M];
            for i in 0..M {
                v[i] = p[i][i].max(0.0);
            }
            v
        };
        let mut ps = pfs[fidx(n - 1)];
        let mut tail = vec![diag(&ps)];
        let mut head_rev: Vec<Vct<M>> = Vec::new();
        let mut steady = diag(&ps);
        let mut in_tail = true;
        let mut k = n - 1;
        while k > 0 {
            k -= 1;
            let i = fidx(k);
            let g = &rts[i];
            let ppk1 = &pps[fidx(k + 1)];
            let mut diff = ps;
            for r in 0..M {
                for c in 0..M {
                    diff[r][c] -= ppk1[r][c];
                }
            }
            let mut nps = mul_bt(&mul(g, &diff), g);
            for r in 0..M {
                for c in 0..M {
                    nps[r][c] += pfs[i][r][c];
                }
            }
            sym(&mut nps);
            if in_tail {
                let conv = i == last && close(&ps, &nps, STEADY_TOL);
                ps = nps;
                if conv {
                    // Samples last..=k are all steady: resume the recursion just below `last`.
                    in_tail = false;
                    steady = diag(&ps);
                    k = last;
                    continue;
                }
                tail.push(diag(&ps));
            } else {
                ps = nps;
                head_rev.push(diag(&ps));
            }
        }
        head_rev.reverse();
        let head = head_rev;
        Covariances {
            n,
            a,
            diffuse: d.diffuse,
            gain: gains,
            s: ss,
            rts,
            head,
            tail,
            steady,
        }
    }

    /// Forward pass: profile log-likelihood terms (sum e^2/S, sum log S, count).
    pub fn loglik_terms(&self, y: &[f64]) -> (f64, f64, usize) {
        let skip = if self.diffuse {
            M.min(y.len().saturating_sub(1))
        } else {
            0
        };
        let last = self.gain.len() - 1;
        let mut x = [0.0; M];
        let (mut e2s, mut logs) = (0.0, 0.0);
        let log_steady = self.s[last].ln();
        for (k, &yk) in y.iter().enumerate() {
            let i = self.fidx(k);
            let e = yk - x[0];
            if k >= skip {
                e2s += e * e / self.s[i];
                logs += if i == last {
                    log_steady
                } else {
                    self.s[i].ln()
                };
            }
            let g = &self.gain[i];
            for r in 0..M {
                x[r] += g[r] * e;
            }
            x = matvec(&self.a, &x);
        }
        (e2s, logs, y.len() - skip)
    }

    /// Per-sample innovation log-likelihood under noise variance sigma2.
    pub fn local_loglik(&self, y: &[f64], sigma2: f64, out: &mut [f64]) {
        let skip = if self.diffuse { M } else { 0 };
        let mut x = [0.0; M];
        for (k, &yk) in y.iter().enumerate() {
            let i = self.fidx(k);
            let e = yk - x[0];
            let s = self.s[i] * sigma2;
            out[k] = if k >= skip {
                -0.5 * (s.ln() + e * e / s)
            } else {
                0.0
            };
            let g = &self.gain[i];
            for r in 0..M {
                x[r] += g[r] * e;
            }
            x = matvec(&self.a, &x);
        }
    }

    /// Mean of every state at the last sample, where filtered and smoothed agree: the forward
    /// pass alone, nothing stored.
    pub fn filter_last(&self, y: &[f64]) -> Vct<M> {
        let mut x = [0.0; M];
        for (k, &yk) in y.iter().enumerate() {
            if k > 0 {
                x = matvec(&self.a, &x);
            }
            let e = yk - x[0];
            let g = &self.gain[self.fidx(k)];
            for r in 0..M {
                x[r] += g[r] * e;
            }
        }
        x
    }

    /// Smoothed means of states 0..=K at every sample, handed to `emit(k, mean)` in backward order.
    pub fn smooth(&self, y: &[f64], mut emit: impl FnMut(usize, &Vct<M>)) {
        let n = y.len();
        let mut xf: Vec<Vct<M>> = Vec::with_capacity(n);
        let mut x = [0.0; M];
        for (k, &yk) in y.iter().enumerate() {
            let i = self.fidx(k);
            let e = yk - x[0];
            let g = &self.gain[i];
            for r in 0..M {
                x[r] += g[r] * e;
            }
            xf.push(x);
            x = matvec(&self.a, &x);
        }
        let mut xs = xf[n - 1];
        emit(n - 1, &xs);
        for k in (0..n - 1).rev() {
            let pred = matvec(&self.a, &xf[k]);
            let mut d = [0.0; M];
            for r in 0..M {
                d[r] = xs[r] - pred[r];
            }
            let corr = matvec(&self.rts[self.fidx(k)], &d);
            for r in 0..M {
                xs[r] = xf[k][r] + corr[r];
            }
            emit(k, &xs);
        }
    }
}

/// G = P_f A^T P_p^{-1}, solved with a diagonally scaled Cholesky factorisation so that states
/// of very different magnitudes do not spoil the conditioning.
fn rts_gain<const M: usize>(pf: &Mat<M>, a: &Mat<M>, pp: &Mat<M>) -> Mat<M> {
    let b = mul_bt(pf, a);
    let mut scale = [0.0; M];
    for i in 0..M {
        scale[i] = pp[i][i].max(1e-300).sqrt();
    }
    // C = D^-1 P_p D^-1 (unit diagonal), factor C = L L^T.
    let mut l = [[0.0; M]; M];
    for i in 0..M {
        for j in 0..=i {
            let mut s = pp[i][j] / (scale[i] * scale[j]) + if i == j { 1e-13 } else { 0.0 };
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = if i == j {
                s.max(1e-300).sqrt()
            } else {
                s / l[j][j]
            };
        }
    }
    // P_p G^T = B^T  <=>  C (D G^T) = D^-1 B^T; solve column by column.
    let mut g = [[0.0; M]; M];
    for col in 0..M {
        // rhs_i = B[col][i] / scale_i  (column `col` of B^T)
        let mut z = [0.0; M];
        for i in 0..M {
            let mut s = b[col][i] / scale[i];
            for k in 0..i {
                s -= l[i][k] * z[k];
            }
            z[i] = s / l[i][i];
        }
        for i in (0..M).rev() {
            let mut s = z[i];
            for k in i + 1..M {
                s -= l[k][i] * z[k];
            }
            z[i] = s / l[i][i];
        }
        // z = D G^T[:, col]  =>  G[col][i] = z_i / scale_i
        for i in 0..M {
            g[col][i] = z[i] / scale[i];
        }
    }
    g
}
