//! Model selection along the path and the final refit.
//!
//! # Extended BIC
//! With n samples, p candidates and a model of k terms (the intercept counts as one) whose
//! least-squares residual sum of squares is RSS,
//! `eBIC = n ln(RSS / n) + k ln n + 2 gamma ln C(p, k)` (Chen & Chen 2008). The last term pays
//! for having searched C(p, k) supports of size k, which is what keeps the criterion consistent
//! when p >> n (plain BIC, or scikit-learn's LassoLarsIC that estimates the noise from an OLS
//! fit on all p candidates, is not). `gamma` = 1 by default. RSS is weighted when weights are
//! given, and floored at `(rss_floor * ||y~||)^2` so that a noise-free problem, whose exact fits
//! differ only by rounding, is decided by the penalty and not by the rounding.
//!
//! # Steps
//! 1. Every distinct support along the path gets an OLS refit (in the standardised, centred
//!    coordinates, so with the intercept) and its eBIC; the lowest wins. Forward-OLS
//!    breakpoints are such refits already: their own residual is used.
//! 2. That support is refitted by least squares in original units (Householder QR on the exact
//!    f64 columns, the constant monomial as an ordinary column when the intercept is fitted).
//! 3. Backward pruning: the term whose removal lowers eBIC the most is removed, until no removal
//!    lowers it. The increase of RSS when term t leaves is `b_t^2 / ||row t of R^{-1}||^2`, so each
//!    round costs one QR. The constant may be pruned too (then the model goes through the origin).

// `!(x > t)` is deliberate throughout: NaN must fail these checks.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use super::cholesky::Cholesky;
use super::path::{dot, Path};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// ln C(p, k). Infinity when `k > p`.
pub fn ln_binom(p: usize, k: usize) -> f64 {
    if k > p {
        return f64::INFINITY;
    }
    let k = k.min(p - k);
    (0..k)
        .map(|i| ((p - i) as f64).ln() - ((i + 1) as f64).ln())
        .sum()
}

/// Extended BIC (see the module docs).
pub fn ebic(n: usize, rss: f64, k: usize, p: usize, gamma: f64, floor: f64) -> f64 {
    let nf = n as f64;
    // A floor of 0 (a constant label: its norm sets the floor) would give ln 0 = -inf, printed
    // as such and written to the model file as a null that does not read back.
    let rss = rss.max(floor);
    let rss = if rss > 0.0 { rss } else { f64::MIN_POSITIVE };
    nf * (rss / nf).ln() + k as f64 * nf.ln() + 2.0 * gamma * ln_binom(p, k)
}

/// eBIC of every breakpoint's support (None where the refit is singular), in path order.
/// `n` is eBIC's sample count (the rows, or fewer effective samples). Panics on a path edited by
/// hand whose breakpoints name a candidate that `path.store` does not hold.
pub fn path_ebic(path: &Path, n: usize, p: usize, gamma: f64, rss_floor: f64) -> Vec<Scored> {
    let mut scorer = EbicScorer::new(n, p, gamma, rss_floor);
    (0..path.breakpoints.len())
        .map(|b| scorer.score(path, b))
        .collect()
}

/// eBIC and OLS RSS of a support (None where the refit is singular).
pub type Scored = Option<(f64, f64)>;

/// Scores breakpoints one at a time as a path grows (see [`path_ebic`]), so that the path can
/// stop once eBIC has stopped improving.
///
/// The Gram matrix of the stored columns grows with the store (each column's products once);
/// a support seen before is not refitted.
pub struct EbicScorer {
    n: usize,
    p: usize,
    gamma: f64,
    rss_floor: f64,
    /// Lower triangle of the Gram matrix of the first `gram.len()` stored columns.
    gram: Vec<Vec<f64>>,
    seen: Vec<(Vec<usize>, Scored)>,
    resid: Vec<f64>,
    /// Best eBIC so far and the breakpoint it came from.
    pub best: Option<(f64, usize)>,
}

impl EbicScorer {
    pub fn new(n: usize, p: usize, gamma: f64, rss_floor: f64) -> EbicScorer {
        EbicScorer {
            n,
            p,
            gamma,
            rss_floor,
            gram: Vec::new(),
            seen: Vec::new(),
            resid: Vec::new(),
            best: None,
        }
    }

    /// eBIC and OLS RSS of breakpoint `b`'s support (None where the refit is singular). Panics
    /// when `b` is not below `path.breakpoints.len()`, and as [`path_ebic`] does.
    pub fn score(&mut self, path: &Path, b: usize) -> Scored {
        let floor = (self.rss_floor * path.y_norm).powi(2);
        let mut key: Vec<usize> = path.breakpoints[b].active.clone();
        key.sort_unstable();
        let bp = &path.breakpoints[b];
        let val = if path.method == super::Method::ForwardOls && !key.is_empty() {
            // Forward OLS breakpoints are the least-squares fits of their supports already (their
            // residual is the refit's), and a forward path never returns to a support.
            let rss = (bp.rel_residual * path.y_norm).powi(2);
            Some((
                ebic(self.n, rss, key.len() + 1, self.p, self.gamma, floor),
                rss,
            ))
        } else if let Some((_, v)) = self.seen.iter().find(|(s, _)| *s == key) {
            *v
        } else {
            let val = self.refit(path, &key, floor);
            self.seen.push((key, val));
            val
        };
        if let Some((e, _)) = val {
            if self.best.is_none_or(|(be, _)| e < be) {
                self.best = Some((e, b));
            }
        }
        val
    }

    fn refit(&mut self, path: &Path, key: &[usize], floor: f64) -> Scored {
        let st = &path.store;
        // Only refits need the Gram matrix (forward-OLS paths never do): grown here, each new
        // stored column's products once.
        while self.gram.len() < st.ids.len() {
            let i = self.gram.len();
            let row = (0..=i)
                .map(|j| st.cols[i].iter().zip(&st.cols[j]).map(|(a, b)| a * b).sum())
                .collect();
            self.gram.push(row);
        }
        let (n, p, gamma) = (self.n, self.p, self.gamma);
        let pos: Vec<usize> = key
            .iter()
            .map(|id| st.position(*id).expect("active columns are stored"))
            .collect();
        let k = pos.len();
        if k == 0 {
            let yy: f64 = path.y_tilde.iter().map(|v| v * v).sum();
            return Some((ebic(n, yy, 1, p, gamma, floor), yy));
        }
        let gram = |a: usize, b: usize| {
            if a >= b {
                self.gram[a][b]
            } else {
                self.gram[b][a]
            }
        };
        let g: Vec<f64> = pos
            .iter()
            .flat_map(|&a| pos.iter().map(move |&b| (a, b)))
            .map(|(a, b)| gram(a, b))
            .collect();
        let ch = Cholesky::factor(&g, k, 1e-10)?;
        let mut b: Vec<f64> = pos.iter().map(|&q| st.xty[q]).collect();
        ch.solve(&mut b);
        self.resid.clear();
        self.resid.extend_from_slice(&path.y_tilde);
        for (&q, bq) in pos.iter().zip(&b) {
            self.resid
                .iter_mut()
                .zip(&st.cols[q])
                .for_each(|(r, x)| *r -= bq * x);
        }
        let rss: f64 = self.resid.iter().map(|r| r * r).sum();
        Some((ebic(n, rss, k + 1, p, gamma, floor), rss))
    }
}

/// Least squares by Householder QR on columns (each scaled to unit norm first).
pub struct LeastSquares {
    /// Coefficients for the original (unscaled) columns.
    pub coef: Vec<f64>,
    pub rss: f64,
    /// RSS increase if column t were removed (and the others refitted).
    pub removal_cost: Vec<f64>,
}

/// Reflections of fewer values than this (rows times columns left) stay on one thread.
const PARALLEL_MIN: usize = 1 << 16;

/// Solves min ||y - X b|| for the given columns; errors when they are rank deficient. Refuses more
/// columns than samples and a column that is zero everywhere or holds a NaN; no columns give the
/// plain sum of squares of `y`. Every column must hold `y.len()` values: another length gives a
/// wrong fit, or a panic when the column is shorter.
pub fn least_squares(cols: &[Vec<f64>], y: &[f64]) -> Result<LeastSquares> {
    let k = cols.len();
    let n = y.len();
    if k == 0 {
        return Ok(LeastSquares {
            coef: vec![],
            rss: y.iter().map(|v| v * v).sum(),
            removal_cost: vec![],
        });
    }
    if k > n {
        return Err(Error::Numerical(format!("{k} terms but only {n} samples")));
    }
    let scale: Vec<f64> = cols.iter().map(|c| dot(c, c).sqrt()).collect();
    if scale.iter().any(|s| !(*s > 0.0)) {
        return Err(Error::Numerical(
            "a chosen term is zero on every weighted sample".into(),
        ));
    }
    let mut a: Vec<Vec<f64>> = cols
        .iter()
        .zip(&scale)
        .map(|(c, s)| c.iter().map(|x| x / s).collect())
        .collect();
    let mut qy = y.to_vec();
    let mut rdiag = vec![0.0; k];
    for j in 0..k {
        let norm = dot(&a[j][j..], &a[j][j..]).sqrt();
        if !(norm > 1e-12) {
            return Err(Error::Numerical(
                "the chosen terms are linearly dependent".into(),
            ));
        }
        let alpha = if a[j][j] > 0.0 { -norm } else { norm };
        let mut v = a[j][j..].to_vec();
        v[0] -= alpha;
        let vn2 = dot(&v, &v);
        rdiag[j] = alpha;
        let apply = |col: &mut Vec<f64>| {
            let d = dot(&v, &col[j..]) * 2.0 / vn2;
            col[j..].iter_mut().zip(&v).for_each(|(c, vi)| *c -= d * vi);
        };
        // Each column's reflection is its own arithmetic, so threads change no result; they
        // pay where the columns are long (the MIMO fits refit 20-40 terms of 25,000 samples).
        apply(&mut qy);
        let rest = &mut a[j + 1..];
        if (n - j) * rest.len() >= PARALLEL_MIN {
            rest.par_iter_mut().for_each(apply);
        } else {
            rest.iter_mut().for_each(apply);
        }
        a[j][j] = alpha;
    }
    // R[i][j] = a[j][i] for i < j, diagonal in rdiag.
    let r = |i: usize, j: usize| if i == j { rdiag[i] } else { a[j][i] };
    let mut b: Vec<f64> = qy[..k].to_vec();
    for i in (0..k).rev() {
        let s: f64 = (i + 1..k).map(|j| r(i, j) * b[j]).sum();
        b[i] = (b[i] - s) / r(i, i);
    }
    let rss = dot(&qy[k..], &qy[k..]);
    // R^{-1} (upper triangular), row norms.
    let mut rinv = vec![0.0; k * k];
    for j in 0..k {
        rinv[j * k + j] = 1.0 / r(j, j);
        for i in (0..j).rev() {
            let s: f64 = (i + 1..=j).map(|q| r(i, q) * rinv[q * k + j]).sum();
            rinv[i * k + j] = -s / r(i, i);
        }
    }
    let removal_cost = (0..k)
        .map(|t| b[t] * b[t] / (t..k).map(|j| rinv[t * k + j].powi(2)).sum::<f64>())
        .collect();
    let coef = b.iter().zip(&scale).map(|(c, s)| c / s).collect();
    Ok(LeastSquares {
        coef,
        rss,
        removal_cost,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qr_least_squares_and_removal_cost() {
        let x0: Vec<f64> = (0..20).map(|i| 1.0 + i as f64 * 0.1).collect();
        let x1: Vec<f64> = (0..20).map(|i| ((i * 7 % 11) as f64).sin()).collect();
        let x2: Vec<f64> = (0..20).map(|i| (i as f64 * 0.3).cos()).collect();
        let y: Vec<f64> = (0..20)
            .map(|i| 2.0 * x0[i] - 0.5 * x1[i] + 0.01 * ((i * 13 % 5) as f64 - 2.0))
            .collect();
        let full = least_squares(&[x0.clone(), x1.clone(), x2.clone()], &y).unwrap();
        let without = least_squares(&[x0.clone(), x1.clone()], &y).unwrap();
        assert!(
            (full.rss + full.removal_cost[2] - without.rss).abs() < 1e-10 * (1.0 + without.rss)
        );
        let without1 = least_squares(&[x0, x2], &y).unwrap();
        assert!((full.rss + full.removal_cost[1] - without1.rss).abs() < 1e-9 * without1.rss);
        assert!((without.coef[0] - 2.0).abs() < 0.05);
    }

    #[test]
    fn ebic_penalises_search() {
        assert!((ln_binom(10, 3) - 120f64.ln()).abs() < 1e-12);
        assert!(ebic(100, 1.0, 3, 1000, 1.0, 0.0) > ebic(100, 1.0, 3, 10, 1.0, 0.0));
        assert_eq!(
            ebic(100, 1e-30, 2, 10, 1.0, 1e-20),
            ebic(100, 1e-25, 2, 10, 1.0, 1e-20)
        );
    }
}
