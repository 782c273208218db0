//! Regression of the weak-form residual on the dictionary, nominal terms held under their prior.
//!
//! Unknowns: `delta_j` (change of nominal coefficient j) and `c_k` (effect coefficients).
//! Objective: `|r - A_nom delta - A_S c|^2 + sum_j lambda_j delta_j^2` with
//! `lambda_j = OVERLAP * sigma^2 / (p_j theta0_j)^2`: a Gaussian prior of standard deviation
//! `p_j |theta0_j|` on each nominal coefficient, weighed against the data with the residual
//! variance `sigma^2` of the same structure fitted without prior (the [`super::weak::OVERLAP`]
//! factor because overlapping windows overstate the number of independent rows). A fixed term
//! (`p_j = 0`) is not a column at all.
//!
//! Everything is computed from Gram matrices (`A^T A`, `A^T r`, `r^T r`), per contiguous block of
//! rows, so a block-bootstrap refit is a sum of block Grams and a solve of a few unknowns.

use nalgebra::{DMatrix, DVector};

use super::weak::OVERLAP;

/// Two effects whose columns correlate above this after the nominal columns are partialled out
/// are aliases: the data cannot tell them apart.
pub const ALIAS: f64 = 0.95;

/// Sufficient statistics of a block of rows: columns are the free nominal terms, then effects.
#[derive(Debug, Clone)]
pub struct Gram {
    pub g: DMatrix<f64>,
    pub b: DVector<f64>,
    pub rr: f64,
    pub rows: usize,
}

impl Gram {
    pub fn zeros(p: usize) -> Gram {
        Gram {
            g: DMatrix::zeros(p, p),
            b: DVector::zeros(p),
            rr: 0.0,
            rows: 0,
        }
    }
    /// Adds rows `cols[j][i]` with labels `r[i]` for `i` in `range`. Panics when `cols` has more
    /// columns than the Gram, or (`range` not empty) `r` or a column is shorter than `range.end`.
    pub fn add_rows(&mut self, cols: &[Vec<f64>], r: &[f64], range: std::ops::Range<usize>) {
        let p = cols.len();
        for i in range {
            for a in 0..p {
                let xa = cols[a][i];
                self.b[a] += xa * r[i];
                for b in a..p {
                    self.g[(a, b)] += xa * cols[b][i];
                }
            }
            self.rr += r[i] * r[i];
            self.rows += 1;
        }
        for a in 0..p {
            for b in 0..a {
                self.g[(a, b)] = self.g[(b, a)];
            }
        }
    }
    /// Adds the rows of `o`. Panics when `o` has another number of columns.
    pub fn add(&mut self, o: &Gram) {
        self.g += &o.g;
        self.b += &o.b;
        self.rr += o.rr;
        self.rows += o.rows;
    }
}

/// The solution of one structure.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Changes of the free nominal coefficients, in column order.
    pub delta: Vec<f64>,
    /// Effect coefficients, in the order of the structure.
    pub coef: Vec<f64>,
    /// Penalised objective.
    pub objective: f64,
    /// Residual sum of squares.
    pub rss: f64,
}

/// Solves `(G_SS + Lambda) x = b_S` on the columns `idx`, `lambda[i]` the penalty of `idx[i]`.
fn solve(gram: &Gram, idx: &[usize], lambda: &[f64]) -> Option<(Vec<f64>, f64, f64)> {
    let k = idx.len();
    if k == 0 {
        return Some((vec![], gram.rr, gram.rr));
    }
    // Jacobi scaling for conditioning (monomials of different units).
    let d: Vec<f64> = idx
        .iter()
        .map(|&i| gram.g[(i, i)].max(1e-300).sqrt())
        .collect();
    let mut a = DMatrix::from_fn(k, k, |r, c| gram.g[(idx[r], idx[c])] / (d[r] * d[c]));
    for r in 0..k {
        a[(r, r)] += lambda[r] / (d[r] * d[r]) + 1e-12;
    }
    let bs = DVector::from_fn(k, |r, _| gram.b[idx[r]] / d[r]);
    let x = a.clone().cholesky()?.solve(&bs);
    let x: Vec<f64> = (0..k).map(|r| x[r] / d[r]).collect();
    // rss = rr - 2 x^T b + x^T G x
    let mut rss = gram.rr;
    let mut pen = 0.0;
    for r in 0..k {
        rss -= 2.0 * x[r] * gram.b[idx[r]];
        for c in 0..k {
            rss += x[r] * gram.g[(idx[r], idx[c])] * x[c];
        }
        pen += lambda[r] * x[r] * x[r];
    }
    let rss = rss.max(0.0);
    Some((x, rss + pen, rss))
}

/// The prior problem: `n_nom` free nominal columns (first in the Gram) with prior standard
/// deviations `prior_sd`, then effect columns.
#[derive(Debug, Clone)]
pub struct Problem {
    pub n_nom: usize,
    pub prior_sd: Vec<f64>,
}

impl Problem {
    /// Fits the nominal changes and the effects `set` (indices among the effects). `None` when a
    /// normal system is not positive definite (its Cholesky factorisation fails). Panics when
    /// `prior_sd` is shorter than `n_nom`, or `gram` lacks column `n_nom + k` for a `k` in `set`.
    pub fn fit(&self, gram: &Gram, set: &[usize]) -> Option<Solution> {
        let idx: Vec<usize> = (0..self.n_nom)
            .chain(set.iter().map(|&k| self.n_nom + k))
            .collect();
        // Residual variance of the same structure without prior.
        let (_, _, rss0) = solve(gram, &idx, &vec![0.0; idx.len()])?;
        let dof = (gram.rows as f64 - idx.len() as f64).max(1.0);
        let sigma2 = (rss0 / dof).max(1e-300);
        let lambda: Vec<f64> = (0..idx.len())
            .map(|i| {
                if i < self.n_nom {
                    OVERLAP * sigma2 / self.prior_sd[i].powi(2).max(1e-300)
                } else {
                    0.0
                }
            })
            .collect();
        let (x, objective, rss) = solve(gram, &idx, &lambda)?;
        Some(Solution {
            delta: x[..self.n_nom].to_vec(),
            coef: x[self.n_nom..].to_vec(),
            objective,
            rss,
        })
    }

    /// Forward selection of at most `max_effects` effects: each step adds the effect that lowers
    /// the penalised objective most, while the Bayesian information criterion (with the number of
    /// independent windows) improves. Once an effect is in, its aliases (partial correlation
    /// above [`ALIAS`] after the nominal columns) are never tried: two names for one signal are
    /// one effect, not two. Panics when `gram` has fewer than `n_nom + n_eff` columns (with
    /// `max_effects` above 0), and as [`Problem::fit`] does.
    pub fn forward(&self, gram: &Gram, n_eff: usize, max_effects: usize) -> Vec<usize> {
        let n_ind = (gram.rows as f64 / OVERLAP).max(2.0);
        let mut set: Vec<usize> = Vec::new();
        let mut banned = vec![false; n_eff];
        let Some(mut cur) = self.fit(gram, &set) else {
            return set;
        };
        while set.len() < max_effects {
            let mut best: Option<(usize, f64)> = None;
            for k in 0..n_eff {
                if set.contains(&k) || banned[k] {
                    continue;
                }
                let mut s = set.clone();
                s.push(k);
                if let Some(sol) = self.fit(gram, &s) {
                    if best.is_none_or(|(_, o)| sol.objective < o) {
                        best = Some((k, sol.objective));
                    }
                }
            }
            let Some((k, obj)) = best else { break };
            let bic_gain = n_ind * (obj.max(1e-300) / cur.objective.max(1e-300)).ln() + n_ind.ln();
            if bic_gain >= 0.0 {
                break;
            }
            set.push(k);
            for (j, b) in banned.iter_mut().enumerate() {
                if !*b && j != k {
                    *b = partial_correlation(gram, self.n_nom, self.n_nom + k, self.n_nom + j)
                        .abs()
                        > ALIAS;
                }
            }
            cur = self.fit(gram, &set).unwrap_or(cur);
        }
        set
    }
}

/// Correlation of columns `a` and `b` after projecting out the first `n_nom` columns, from a Gram
/// matrix of centred-or-not columns (the projection uses the Gram algebra directly). Panics when
/// `a` or `b` is not below the Gram's number of columns, or `n_nom` above it.
pub fn partial_correlation(gram: &Gram, n_nom: usize, a: usize, b: usize) -> f64 {
    // Residual Gram of [a, b] after regressing on the nominal columns: G_xy - G_xN G_NN^-1 G_Ny.
    let g = &gram.g;
    let resid = |x: usize, y: usize| -> f64 {
        if n_nom == 0 {
            return g[(x, y)];
        }
        let gnn = DMatrix::from_fn(n_nom, n_nom, |r, c| g[(r, c)]);
        let gny = DVector::from_fn(n_nom, |r, _| g[(r, y)]);
        let gxn = DVector::from_fn(n_nom, |r, _| g[(x, r)]);
        let Some(ch) = (gnn + DMatrix::identity(n_nom, n_nom) * 1e-12).cholesky() else {
            return g[(x, y)];
        };
        g[(x, y)] - gxn.dot(&ch.solve(&gny))
    };
    let (aa, bb, ab) = (resid(a, a), resid(b, b), resid(a, b));
    if aa <= 0.0 || bb <= 0.0 {
        return 0.0;
    }
    ab / (aa * bb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_holds_a_nominal_term_and_forward_finds_the_effect() {
        // r = 0.1 * x0 (a small nominal mismatch) + 2 * x2 (an effect) + noise-free.
        let n = 400;
        let x0: Vec<f64> = (0..n).map(|i| (i as f64 * 0.1).sin()).collect();
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).cos()).collect();
        let x2: Vec<f64> = (0..n).map(|i| ((i as f64 * 0.05).sin()).powi(3)).collect();
        let r: Vec<f64> = (0..n)
            .map(|i| 0.1 * x0[i] + 2.0 * x2[i] + 0.01 * ((i * 7919) % 13) as f64 / 13.0)
            .collect();
        let mut g = Gram::zeros(3);
        g.add_rows(&[x0.clone(), x1.clone(), x2.clone()], &r, 0..n);
        let pb = Problem {
            n_nom: 1,
            prior_sd: vec![0.2],
        };
        let set = pb.forward(&g, 2, 2);
        assert_eq!(set, vec![1]);
        let sol = pb.fit(&g, &set).unwrap();
        assert!((sol.coef[0] - 2.0).abs() < 0.02, "{:?}", sol);
        assert!((sol.delta[0] - 0.1).abs() < 0.02, "{:?}", sol);
        // A tight prior keeps the nominal change near zero.
        let tight = Problem {
            n_nom: 1,
            prior_sd: vec![1e-9],
        };
        assert!(tight.fit(&g, &set).unwrap().delta[0].abs() < 1e-3);
    }
}
