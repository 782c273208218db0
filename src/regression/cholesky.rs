//! Incremental Cholesky factor `G = L L^T` of the active Gram matrix, with appends (a column
//! enters) and deletions (a lasso drop), in f64. Hand-written because the active set changes
//! one column at a time: each change costs O(k^2) instead of a fresh O(k^3) factorisation.

// `!(x > t)` is deliberate throughout: NaN must fail these checks.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

#[derive(Debug, Clone, Default)]
pub struct Cholesky {
    /// Row i holds L[i][0..=i].
    rows: Vec<Vec<f64>>,
}

impl Cholesky {
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Solves L x = b in place. Panics when `b` is shorter than [`Cholesky::len`].
    pub fn solve_lower(&self, b: &mut [f64]) {
        for i in 0..self.rows.len() {
            let r = &self.rows[i];
            let s: f64 = r[..i].iter().zip(&b[..i]).map(|(l, x)| l * x).sum();
            b[i] = (b[i] - s) / r[i];
        }
    }

    /// Solves L^T x = b in place. Panics when `b` is shorter than [`Cholesky::len`].
    pub fn solve_upper(&self, b: &mut [f64]) {
        let k = self.rows.len();
        for i in (0..k).rev() {
            b[i] /= self.rows[i][i];
            let xi = b[i];
            for (j, bj) in b[..i].iter_mut().enumerate() {
                *bj -= self.rows[i][j] * xi;
            }
        }
    }

    /// Solves G x = b in place. Panics when `b` is shorter than [`Cholesky::len`].
    pub fn solve(&self, b: &mut [f64]) {
        self.solve_lower(b);
        self.solve_upper(b);
    }

    /// The pivot a new column would get: `g` holds its inner products with the current
    /// columns, `c` its squared norm. Returns (w = L^{-1} g, pivot). Panics when `g` is shorter
    /// than [`Cholesky::len`].
    pub fn pivot(&self, g: &[f64], c: f64) -> (Vec<f64>, f64) {
        let mut w = g.to_vec();
        self.solve_lower(&mut w);
        let v: f64 = w.iter().map(|x| x * x).sum();
        (w, (c - v).abs().sqrt())
    }

    /// Appends a column with `w` and `pivot` from [`Cholesky::pivot`]. Nothing checks that `w` has
    /// [`Cholesky::len`] entries; another length corrupts the factor.
    pub fn append(&mut self, mut w: Vec<f64>, pivot: f64) {
        w.push(pivot);
        self.rows.push(w);
    }

    /// Removes column/row `i`, restoring the triangular shape with Givens rotations. Panics when
    /// `i` is not below [`Cholesky::len`].
    pub fn delete(&mut self, i: usize) {
        self.rows.remove(i);
        let k = self.rows.len();
        for p in i..k {
            // Row p (formerly p+1) has one entry too many: zero L[p][p+1] by rotating columns p, p+1.
            let (a, b) = (self.rows[p][p], self.rows[p][p + 1]);
            let h = a.hypot(b);
            let (c, s) = if h == 0.0 { (1.0, 0.0) } else { (a / h, b / h) };
            for r in p..k {
                let (x, y) = (self.rows[r][p], self.rows[r][p + 1]);
                self.rows[r][p] = c * x + s * y;
                self.rows[r][p + 1] = -s * x + c * y;
            }
            self.rows[p].truncate(p + 1);
        }
    }

    /// Factorises a dense symmetric positive definite matrix (row-major k x k); `None` when a
    /// pivot falls below `tol` times the largest diagonal element. A NaN or infinite pivot gives
    /// `None` too. Panics when `g` is shorter than `k * k`.
    pub fn factor(g: &[f64], k: usize, tol: f64) -> Option<Cholesky> {
        let dmax = (0..k).map(|i| g[i * k + i]).fold(0.0f64, f64::max);
        let mut ch = Cholesky::default();
        for j in 0..k {
            let (w, piv) = ch.pivot(&g[j * k..j * k + j], g[j * k + j]);
            if !(piv > tol * dmax.sqrt()) || !piv.is_finite() {
                return None;
            }
            ch.append(w, piv);
        }
        Some(ch)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn append_delete_matches_fresh_factor() {
        // G = A^T A for a fixed 6 x 4 A.
        let a = [
            [1.0, 2.0, 0.5, -1.0],
            [0.3, -1.0, 2.0, 0.0],
            [2.0, 0.1, 0.2, 1.0],
            [0.0, 1.0, 1.0, 1.0],
            [1.5, -0.5, 0.0, 2.0],
            [0.2, 0.2, -2.0, 0.7],
        ];
        let g = |i: usize, j: usize| (0..6).map(|r| a[r][i] * a[r][j]).sum::<f64>();
        let mut ch = Cholesky::default();
        for j in 0..4 {
            let gj: Vec<f64> = (0..j).map(|i| g(i, j)).collect();
            let (w, p) = ch.pivot(&gj, g(j, j));
            ch.append(w, p);
        }
        ch.delete(1);
        let keep = [0, 2, 3];
        let dense: Vec<f64> = keep
            .iter()
            .flat_map(|&i| keep.iter().map(move |&j| g(i, j)))
            .collect();
        let fresh = Cholesky::factor(&dense, 3, 1e-12).unwrap();
        for i in 0..3 {
            for j in 0..=i {
                assert!((ch.rows[i][j] - fresh.rows[i][j]).abs() < 1e-12, "{i} {j}");
            }
        }
        let mut b = vec![1.0, -2.0, 0.5];
        ch.solve(&mut b);
        for i in 0..3 {
            let lhs: f64 = (0..3).map(|j| dense[i * 3 + j] * b[j]).sum();
            assert!((lhs - [1.0, -2.0, 0.5][i]).abs() < 1e-12);
        }
    }
}
