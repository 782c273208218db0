//! The linear algebra of the Radau stage equations: factors of `I - h (a_ij J_j)` (3n x 3n,
//! block (i, j) for stages i and j) and solves with them, for the simplified Newton iterations
//! and the forward sensitivities.
//!
//! Two forms. [`DenseLu`] factors the whole 3n x 3n matrix: O(n^3) per factorisation and
//! O(n^2) per solve, for any system. [`ChainLu`] is for systems made of chains of integrators
//! (`x_k' = x_{k+1}` up to one free row per chain), which every identified model is: the stage
//! values of a chain's lower states follow from those of its top state by back-substitution
//! (`dZ_k = R_k + B dZ_{k+1}`, `B = h A`), so only 3 unknowns per chain remain and a factorisation
//! costs O(chains^3 + chains n), a solve O(chains^2 + chains n). 40 outputs of order 8 is a
//! 120 x 120 system instead of 960 x 960. Both forms give the same solution up to rounding
//! (`chain_and_dense_solves_agree`).

/// LU factors with partial pivoting of the small dense Newton matrix (row-major, at most a few
/// dozen rows): hand-written because the generic dynamic-size factorisation and its allocations
/// were a third of a simulation's time.
pub(super) struct DenseLu {
    n: usize,
    a: Vec<f64>,
    /// Row i of the factored matrix is row `perm[i]` of the original.
    perm: Vec<usize>,
}

/// The work vectors of factors no longer used, handed to the next factorisation: a nonlinear
/// model's Jacobian changes at every step, and allocating and freeing a step's factors was about
/// 15 % of a benchmark's time (docs/method/simulation.md). Every vector comes out empty; a
/// chain solve's work space comes out as it was left (its solves clear what they use).
#[derive(Default)]
pub(super) struct Pool {
    f64s: Vec<Vec<f64>>,
    usizes: Vec<Vec<usize>>,
    pairs: Vec<Vec<(usize, f64)>>,
    chains: Vec<Vec<(usize, usize)>>,
    m3s: Vec<Vec<M3>>,
    works: Vec<Work>,
}

type Work = std::cell::RefCell<(Vec<f64>, Vec<f64>, Vec<f64>)>;

/// Most vectors of one kind a pool keeps (a step's factors hold a handful).
const POOL_DEPTH: usize = 8;

fn take<T>(v: &mut Vec<Vec<T>>) -> Vec<T> {
    let mut x = v.pop().unwrap_or_default();
    x.clear();
    x
}

fn give<T>(v: &mut Vec<T>, x: T) {
    if v.len() < POOL_DEPTH {
        v.push(x);
    }
}

/// Factors whose vectors go back to a [`Pool`] when they are no longer used.
pub(super) trait Recycle {
    fn recycle(self, pool: &mut Pool);
}

impl Recycle for StageLu {
    fn recycle(self, pool: &mut Pool) {
        match self {
            StageLu::Dense(lu) => lu.recycle(pool),
            StageLu::Chain(lu) => lu.recycle(pool),
        }
    }
}

impl Pool {
    fn f64s(&mut self) -> Vec<f64> {
        take(&mut self.f64s)
    }
    fn zeros(&mut self, len: usize) -> Vec<f64> {
        let mut x = self.f64s();
        x.resize(len, 0.0);
        x
    }
    fn work(&mut self) -> Work {
        self.works.pop().unwrap_or_default()
    }
}

impl DenseLu {
    /// Factors `a` (n x n, row-major) in place; `None` when a pivot is zero or not finite.
    #[cfg(test)]
    fn factor(n: usize, a: Vec<f64>) -> Option<DenseLu> {
        DenseLu::factor_with(n, a, Vec::new())
    }

    /// Factors `a` (n x n, row-major) in place into `perm`'s vector; `None` when a pivot is
    /// zero or not finite.
    fn factor_with(n: usize, mut a: Vec<f64>, mut perm: Vec<usize>) -> Option<DenseLu> {
        perm.clear();
        perm.extend(0..n);
        for k in 0..n {
            let mut p = k;
            for i in k + 1..n {
                if a[i * n + k].abs() > a[p * n + k].abs() {
                    p = i;
                }
            }
            let d = a[p * n + k];
            if d == 0.0 || !d.is_finite() {
                return None;
            }
            if p != k {
                for j in 0..n {
                    a.swap(k * n + j, p * n + j);
                }
                perm.swap(k, p);
            }
            for i in k + 1..n {
                let f = a[i * n + k] / d;
                a[i * n + k] = f;
                if f != 0.0 {
                    for j in k + 1..n {
                        a[i * n + j] -= f * a[k * n + j];
                    }
                }
            }
        }
        Some(DenseLu { n, a, perm })
    }

    fn pooled(n: usize, a: Vec<f64>, pool: &mut Pool) -> Option<DenseLu> {
        let perm = take(&mut pool.usizes);
        DenseLu::factor_with(n, a, perm)
    }

    fn recycle(self, pool: &mut Pool) {
        give(&mut pool.f64s, self.a);
        give(&mut pool.usizes, self.perm);
    }

    /// Solves `A x = b`.
    pub(super) fn solve(&self, b: &[f64], x: &mut [f64]) {
        let n = self.n;
        for i in 0..n {
            x[i] = b[self.perm[i]];
        }
        for i in 0..n {
            let row = &self.a[i * n..i * n + i];
            let s: f64 = row.iter().zip(&x[..i]).map(|(a, b)| a * b).sum();
            x[i] -= s;
        }
        for i in (0..n).rev() {
            let row = &self.a[i * n + i + 1..(i + 1) * n];
            let s: f64 = row.iter().zip(&x[i + 1..n]).map(|(a, b)| a * b).sum();
            x[i] = (x[i] - s) / self.a[i * n + i];
        }
    }
}

impl DenseLu {
    /// Solves `A X = B` for `q` right-hand sides at once, `b` row-major `n x q`, in place: the
    /// inner loops run along the contiguous right-hand sides.
    pub(super) fn solve_many(&self, b: &mut [f64], q: usize, scratch: &mut Vec<f64>) {
        let n = self.n;
        scratch.clear();
        for i in 0..n {
            let p = self.perm[i];
            scratch.extend_from_slice(&b[p * q..(p + 1) * q]);
        }
        let x = scratch.as_mut_slice();
        for i in 0..n {
            let (done, rest) = x.split_at_mut(i * q);
            let xi = &mut rest[..q];
            for j in 0..i {
                let l = self.a[i * n + j];
                if l != 0.0 {
                    let xj = &done[j * q..(j + 1) * q];
                    xi.iter_mut().zip(xj).for_each(|(a, b)| *a -= l * b);
                }
            }
        }
        for i in (0..n).rev() {
            let (head, tail) = x.split_at_mut((i + 1) * q);
            let xi = &mut head[i * q..];
            for j in i + 1..n {
                let u = self.a[i * n + j];
                if u != 0.0 {
                    let xj = &tail[(j - i - 1) * q..(j - i) * q];
                    xi.iter_mut().zip(xj).for_each(|(a, b)| *a -= u * b);
                }
            }
            let d = 1.0 / self.a[i * n + i];
            xi.iter_mut().for_each(|v| *v *= d);
        }
        b.copy_from_slice(x);
    }
}

/// Factors of the Radau stage matrix `I - h (a_ij J_j)`, in the cheapest form the Jacobians'
/// structure allows.
pub(super) enum StageLu {
    Dense(DenseLu),
    Chain(ChainLu),
}

impl StageLu {
    /// Factors of `I - h (a_ij J_j)` for the row-major `n x n` stage Jacobians `jacs`
    /// (simplified Newton passes one Jacobian three times), or `None` when the matrix is
    /// singular. `chains` (first state, length) is the system's chain structure; it is used
    /// only when the Jacobians have it (unit shifts on every row but the chains' last).
    pub(super) fn factor(
        a: &[[f64; 3]; 3],
        n: usize,
        h: f64,
        jacs: [&[f64]; 3],
        chains: Option<&[(usize, usize)]>,
        pool: &mut Pool,
    ) -> Option<StageLu> {
        match chains {
            Some(c) if has_chains(n, c, &jacs) => {
                ChainLu::factor(a, n, h, jacs, c, pool).map(StageLu::Chain)
            }
            _ => dense_stage_matrix(a, n, h, jacs, pool).map(StageLu::Dense),
        }
    }

    /// Solves for one right-hand side `b` (stage-major, 3n) into `x`.
    pub(super) fn solve(&self, b: &[f64], x: &mut [f64]) {
        match self {
            StageLu::Dense(lu) => lu.solve(b, x),
            StageLu::Chain(lu) => lu.solve(b, x),
        }
    }

    /// Solves for `q` right-hand sides at once, `b` row-major `3n x q`, in place.
    pub(super) fn solve_many(&self, b: &mut [f64], q: usize, scratch: &mut Vec<f64>) {
        match self {
            StageLu::Dense(lu) => lu.solve_many(b, q, scratch),
            StageLu::Chain(lu) => lu.solve_many(b, q, scratch),
        }
    }
}

/// Factors of `I - s J` (n x n) for the embedded error estimate of a Radau step
/// (`s = gamma0 h`, see `Integrator::error_estimate`), in the cheapest form the Jacobian allows.
/// For chains of integrators a chain row reads `e_k - s e_{k+1} = b_k`, so every state of a chain
/// follows from its top state by `e_k = b_k + s e_{k+1}` and only the chains' top states are
/// unknowns: a factorisation costs O(chains^3 + n), not O(n^3).
pub(super) enum ErrorLu {
    Dense(DenseLu),
    Chain {
        s: f64,
        chains: Vec<(usize, usize)>,
        /// The chains' top rows of `J` (`chains x n`, row-major).
        top_rows: Vec<f64>,
        /// Factors of the reduced matrix on the top states.
        lu: DenseLu,
    },
}

impl ErrorLu {
    /// Factors of `I - s J` for the row-major `n x n` Jacobian `jac`; `None` when singular.
    /// `chains` as in [`StageLu::factor`] (used only when `jac` has the structure).
    pub(super) fn factor(
        n: usize,
        s: f64,
        jac: &[f64],
        chains: Option<&[(usize, usize)]>,
        pool: &mut Pool,
    ) -> Option<ErrorLu> {
        let Some(chains) = chains.filter(|c| has_chains(n, c, &[jac])) else {
            let mut m = pool.f64s();
            m.extend(jac.iter().map(|v| -s * v));
            (0..n).for_each(|d| m[d * n + d] += 1.0);
            return DenseLu::pooled(n, m, pool).map(ErrorLu::Dense);
        };
        // e_k = a_k e_top + (terms of b): a_k = s^(top - k).
        let mut a = pool.zeros(n);
        for &(off, len) in chains {
            let mut p = 1.0;
            for k in (off..off + len).rev() {
                a[k] = p;
                p *= s;
            }
        }
        let nc = chains.len();
        let mut mat = pool.zeros(nc * nc);
        let mut top_rows = pool.f64s();
        for (o, &(off, len)) in chains.iter().enumerate() {
            let row = &jac[(off + len - 1) * n..(off + len) * n];
            top_rows.extend_from_slice(row);
            for (o2, &(off2, len2)) in chains.iter().enumerate() {
                let g: f64 = (off2..off2 + len2).map(|j| row[j] * a[j]).sum();
                mat[o * nc + o2] = if o == o2 { 1.0 } else { 0.0 } - s * g;
            }
        }
        give(&mut pool.f64s, a);
        let mut chain_list = take(&mut pool.chains);
        chain_list.extend_from_slice(chains);
        Some(ErrorLu::Chain {
            s,
            chains: chain_list,
            top_rows,
            lu: DenseLu::pooled(nc, mat, pool)?,
        })
    }

    /// Hands the factors' vectors to `pool` for the next factorisation.
    pub(super) fn recycle(self, pool: &mut Pool) {
        match self {
            ErrorLu::Dense(lu) => lu.recycle(pool),
            ErrorLu::Chain {
                chains,
                top_rows,
                lu,
                ..
            } => {
                give(&mut pool.chains, chains);
                give(&mut pool.f64s, top_rows);
                lu.recycle(pool);
            }
        }
    }

    /// Solves `(I - s J) x = b`; `work` is scratch.
    pub(super) fn solve(&self, b: &[f64], x: &mut [f64], work: &mut Vec<f64>) {
        let (s, chains, top_rows, lu) = match self {
            ErrorLu::Dense(lu) => return lu.solve(b, x),
            ErrorLu::Chain {
                s,
                chains,
                top_rows,
                lu,
            } => (*s, chains, top_rows, lu),
        };
        let (n, nc) = (b.len(), chains.len());
        // e_k = b_k + s e_{k+1} down each chain from its top value.
        let down = |x: &mut [f64], off: usize, len: usize, top: f64| {
            x[off + len - 1] = top;
            for k in (off..off + len - 1).rev() {
                x[k] = b[k] + s * x[k + 1];
            }
        };
        // The part of each state that does not depend on its chain's top state.
        for &(off, len) in chains {
            down(x, off, len, 0.0);
        }
        work.clear();
        work.resize(2 * nc, 0.0);
        let (r, w) = work.split_at_mut(nc);
        for (o, &(off, len)) in chains.iter().enumerate() {
            let row = &top_rows[o * n..(o + 1) * n];
            let jb: f64 = row.iter().zip(&x[..n]).map(|(j, v)| j * v).sum();
            r[o] = b[off + len - 1] + s * jb;
        }
        lu.solve(r, w);
        for (o, &(off, len)) in chains.iter().enumerate() {
            down(x, off, len, w[o]);
        }
    }
}

/// Whether `chains` tile the `n` states in order and every Jacobian row but a chain's last is
/// the unit shift `e_{k+1}` (so the chain solve is exact, not an approximation).
fn has_chains(n: usize, chains: &[(usize, usize)], jacs: &[&[f64]]) -> bool {
    let mut next = 0;
    for &(off, len) in chains {
        if off != next || len == 0 {
            return false;
        }
        next = off + len;
    }
    if next != n {
        return false;
    }
    // Simplified Newton passes one Jacobian three times: each is checked once.
    let first = |k: usize| !jacs[..k].iter().any(|j| std::ptr::eq(*j, jacs[k]));
    jacs.iter()
        .enumerate()
        .filter(|(k, _)| first(*k))
        .all(|(_, jac)| {
            chains.iter().all(|&(off, len)| {
                (off..off + len - 1).all(|r| {
                    let row = &jac[r * n..(r + 1) * n];
                    row.iter()
                        .enumerate()
                        .all(|(k, &v)| v == if k == r + 1 { 1.0 } else { 0.0 })
                })
            })
        })
}

/// The whole 3n x 3n stage matrix, factored.
fn dense_stage_matrix(
    a: &[[f64; 3]; 3],
    n: usize,
    h: f64,
    jacs: [&[f64]; 3],
    pool: &mut Pool,
) -> Option<DenseLu> {
    let m = 3 * n;
    let mut mat = pool.zeros(m * m);
    for d in 0..m {
        mat[d * m + d] = 1.0;
    }
    for i in 0..3 {
        for (j, jac) in jacs.iter().enumerate() {
            let hij = h * a[i][j];
            for r in 0..n {
                for q in 0..n {
                    mat[(i * n + r) * m + j * n + q] -= hij * jac[r * n + q];
                }
            }
        }
    }
    DenseLu::pooled(m, mat, pool)
}

type M3 = [[f64; 3]; 3];

fn mat_mul(x: &M3, y: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for l in 0..3 {
            r[i][l] = (0..3).map(|j| x[i][j] * y[j][l]).sum();
        }
    }
    r
}

/// Stage factors of a system of chains of integrators, reduced to the chains' top states.
///
/// With `W_o` the stage increments of chain `o`'s top state and `B = h A`, a lower state `k` of
/// a chain of length `L` has `dZ_k = c_k + B^(L-1-k) W_o`, where `c_{L-1} = 0` and
/// `c_k = R_k + B c_{k+1}`. The top rows `g_o^j` (row `o`'s Jacobian at stage `j`) then give
/// `(I - M) W = r` with `M[o, o'][i, l] = sum_j B_ij sum_k g_o^j[o', k] (B^(L'-1-k))_jl` and
/// `r_o = R_top + B (sum_s g_o^j[s] c_j(s))_j`.
pub(super) struct ChainLu {
    n: usize,
    chains: Vec<(usize, usize)>,
    /// `B^p` for p = 0 ..= the longest chain.
    bp: Vec<M3>,
    /// The nonzero entries (state, value) of the chains' top rows of the stage Jacobians,
    /// `[stage * chains + chain]`: a model's top row holds the few states its terms use, and
    /// scanning whole rows made every solve O(chains n).
    /// Flat: row `r` (= stage * chains + chain) is `g[g_start[r]..g_start[r + 1]]` (one
    /// allocation per factorisation instead of one per row: the sensitivities factor at every step).
    g: Vec<(usize, f64)>,
    g_start: Vec<usize>,
    /// Factors of `I - M`, unknowns ordered chain-major (`3 o + i`).
    lu: DenseLu,
    /// Work space of the solves (the reduced right-hand sides, the top rows' sums, the reduced
    /// solve's scratch), kept with the factors so that a Newton iteration allocates nothing.
    work: Work,
}

impl ChainLu {
    fn factor(
        a: &[[f64; 3]; 3],
        n: usize,
        h: f64,
        jacs: [&[f64]; 3],
        chains: &[(usize, usize)],
        pool: &mut Pool,
    ) -> Option<ChainLu> {
        let nc = chains.len();
        let longest = chains.iter().map(|c| c.1).max().unwrap_or(0);
        let b: M3 = std::array::from_fn(|i| std::array::from_fn(|j| h * a[i][j]));
        let mut bp = take(&mut pool.m3s);
        bp.push([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        for p in 1..=longest {
            bp.push(mat_mul(&bp[p - 1], &b));
        }
        // The top row of chain o at stage j: row `top` of that stage's Jacobian.
        let top_row = |j: usize, o: usize| {
            let top = chains[o].0 + chains[o].1 - 1;
            &jacs[j][top * n..(top + 1) * n]
        };
        let m = 3 * nc;
        let mut mat = pool.zeros(m * m);
        for o in 0..nc {
            for (o2, &(off, len)) in chains.iter().enumerate() {
                // v[j][l] = sum_k g_o^j[off + k] (B^(len-1-k))_jl
                let mut v = [[0.0; 3]; 3];
                for (j, vj) in v.iter_mut().enumerate() {
                    let row = top_row(j, o);
                    for k in 0..len {
                        let gk = row[off + k];
                        if gk != 0.0 {
                            let p = &bp[len - 1 - k];
                            for l in 0..3 {
                                vj[l] += gk * p[j][l];
                            }
                        }
                    }
                }
                let bv = mat_mul(&b, &v);
                for i in 0..3 {
                    for l in 0..3 {
                        let d = if o == o2 && i == l { 1.0 } else { 0.0 };
                        mat[(3 * o + i) * m + 3 * o2 + l] = d - bv[i][l];
                    }
                }
            }
        }
        let lu = DenseLu::pooled(m, mat, pool)?;
        let mut g = take(&mut pool.pairs);
        let mut g_start = take(&mut pool.usizes);
        for j in 0..3 {
            for o in 0..nc {
                g_start.push(g.len());
                let row = top_row(j, o).iter().enumerate();
                g.extend(row.filter(|(_, v)| **v != 0.0).map(|(s, v)| (s, *v)));
            }
        }
        g_start.push(g.len());
        let mut chain_list = take(&mut pool.chains);
        chain_list.extend_from_slice(chains);
        Some(ChainLu {
            n,
            chains: chain_list,
            bp,
            g,
            g_start,
            lu,
            work: pool.work(),
        })
    }

    fn recycle(self, pool: &mut Pool) {
        give(&mut pool.chains, self.chains);
        give(&mut pool.m3s, self.bp);
        give(&mut pool.pairs, self.g);
        give(&mut pool.usizes, self.g_start);
        self.lu.recycle(pool);
        give(&mut pool.works, self.work);
    }

    /// [`ChainLu::solve_many`] for one right-hand side (every Newton iteration), written out:
    /// the general loops over q = 1 column, their slices and the reduced solve's copies were
    /// a third of a two-state model's simulation (Silverbox).
    fn solve(&self, b: &[f64], x: &mut [f64]) {
        x.copy_from_slice(b);
        let (n, nc) = (self.n, self.chains.len());
        let bm = self.bp[1.min(self.bp.len() - 1)];
        let mul = |m: &M3, v: [f64; 3], i: usize| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2];
        let mut work = self.work.borrow_mut();
        let (r, _, w) = &mut *work;
        r.clear();
        r.resize(3 * nc, 0.0);
        for (o, &(off, len)) in self.chains.iter().enumerate() {
            let top = off + len - 1;
            for i in 0..3 {
                r[3 * o + i] = x[i * n + top];
                x[i * n + top] = 0.0;
            }
            for s in (off..top).rev() {
                let c = [x[s + 1], x[n + s + 1], x[2 * n + s + 1]];
                for i in 0..3 {
                    x[i * n + s] += mul(&bm, c, i);
                }
            }
        }
        for o in 0..nc {
            let mut t = [0.0; 3];
            for (j, tj) in t.iter_mut().enumerate() {
                for &(s, gs) in &self.g[self.g_start[j * nc + o]..self.g_start[j * nc + o + 1]] {
                    *tj += gs * x[j * n + s];
                }
            }
            for i in 0..3 {
                r[3 * o + i] += mul(&bm, t, i);
            }
        }
        w.clear();
        w.resize(3 * nc, 0.0);
        self.lu.solve(r, w);
        for (o, &(off, len)) in self.chains.iter().enumerate() {
            let wo = [w[3 * o], w[3 * o + 1], w[3 * o + 2]];
            for k in 0..len {
                let p = &self.bp[len - 1 - k];
                for i in 0..3 {
                    x[i * n + off + k] += mul(p, wo, i);
                }
            }
        }
    }

    /// Solves for `q` right-hand sides, `b` row-major `3n x q` (row `i n + s`: stage i, state
    /// s), in place; every inner loop runs along the q contiguous right-hand sides.
    fn solve_many(&self, b: &mut [f64], q: usize, scratch: &mut Vec<f64>) {
        let (n, nc) = (self.n, self.chains.len());
        let bm = self.bp[1.min(self.bp.len() - 1)];
        let row = |i: usize, s: usize| (i * n + s) * q;
        // r_o starts as the top rows; the top's c is zero; c_k = R_k + B c_{k+1} down the chain.
        let mut work = self.work.borrow_mut();
        let (r, t, _) = &mut *work;
        r.clear();
        r.resize(3 * nc * q, 0.0);
        t.clear();
        t.resize(3 * q, 0.0);
        for (o, &(off, len)) in self.chains.iter().enumerate() {
            let top = off + len - 1;
            for i in 0..3 {
                let src = row(i, top);
                r[(3 * o + i) * q..(3 * o + i + 1) * q].copy_from_slice(&b[src..src + q]);
                b[src..src + q].iter_mut().for_each(|v| *v = 0.0);
            }
            for s in (off..top).rev() {
                for i in 0..3 {
                    for l in 0..3 {
                        let f = bm[i][l];
                        let (dst, src) = (row(i, s), row(l, s + 1));
                        for c in 0..q {
                            b[dst + c] += f * b[src + c];
                        }
                    }
                }
            }
        }
        // r_o += B t, t_j = sum_s g_o^j[s] c_j(s).
        for o in 0..nc {
            t.iter_mut().for_each(|v| *v = 0.0);
            for j in 0..3 {
                let tj = &mut t[j * q..(j + 1) * q];
                for &(s, gs) in &self.g[self.g_start[j * nc + o]..self.g_start[j * nc + o + 1]] {
                    let cs = &b[row(j, s)..row(j, s) + q];
                    tj.iter_mut().zip(cs).for_each(|(a, c)| *a += gs * c);
                }
            }
            for i in 0..3 {
                let ro = &mut r[(3 * o + i) * q..(3 * o + i + 1) * q];
                for j in 0..3 {
                    let f = bm[i][j];
                    ro.iter_mut()
                        .zip(&t[j * q..(j + 1) * q])
                        .for_each(|(a, v)| *a += f * v);
                }
            }
        }
        self.lu.solve_many(r, q, scratch);
        // dZ_k = c_k + B^(L-1-k) W_o.
        for (o, &(off, len)) in self.chains.iter().enumerate() {
            for k in 0..len {
                let p = &self.bp[len - 1 - k];
                for i in 0..3 {
                    let dst = row(i, off + k);
                    for l in 0..3 {
                        let f = p[i][l];
                        let w = &r[(3 * o + l) * q..(3 * o + l + 1) * q];
                        b[dst..dst + q]
                            .iter_mut()
                            .zip(w)
                            .for_each(|(a, v)| *a += f * v);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random value in [-1, 1).
    fn rnd(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn dense_lu_solves_with_pivoting_and_refuses_singular_matrices() {
        // A zero leading entry forces a row swap.
        let a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let lu = DenseLu::factor(3, a.clone()).unwrap();
        let x_true = [1.0, -2.0, 0.5];
        let b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a[i * 3 + j] * x_true[j]).sum())
            .collect();
        let mut x = [0.0; 3];
        lu.solve(&b, &mut x);
        for k in 0..3 {
            assert!((x[k] - x_true[k]).abs() < 1e-14, "{x:?}");
        }
        assert!(DenseLu::factor(2, vec![1.0, 2.0, 2.0, 4.0]).is_none());
    }

    #[test]
    fn chain_and_dense_solves_agree() {
        // Chains of lengths 1, 3 and 2 (6 states), a different top row at each stage, as the
        // sensitivities have; simplified Newton's equal stages are the special case.
        let chains = [(0, 1), (1, 3), (4, 2)];
        let n = 6;
        let mut seed = 7u64;
        let mut jacs = vec![vec![0.0; n * n]; 3];
        for jac in jacs.iter_mut() {
            for &(off, len) in &chains {
                for k in off..off + len - 1 {
                    jac[k * n + k + 1] = 1.0;
                }
                let top = off + len - 1;
                for c in 0..n {
                    jac[top * n + c] = 3.0 * rnd(&mut seed);
                }
            }
        }
        let a = [[0.2, -0.05, 0.02], [0.4, 0.2, -0.03], [0.38, 0.5, 0.11]];
        let stages = [&jacs[0][..], &jacs[1][..], &jacs[2][..]];
        let chain =
            StageLu::factor(&a, n, 0.7, stages, Some(&chains), &mut Pool::default()).unwrap();
        assert!(matches!(chain, StageLu::Chain(_)));
        let dense = StageLu::factor(&a, n, 0.7, stages, None, &mut Pool::default()).unwrap();
        let q = 4;
        let b: Vec<f64> = (0..3 * n * q).map(|_| rnd(&mut seed)).collect();
        let (mut bc, mut bd) = (b.clone(), b.clone());
        let mut scratch = Vec::new();
        chain.solve_many(&mut bc, q, &mut scratch);
        dense.solve_many(&mut bd, q, &mut scratch);
        for (c, d) in bc.iter().zip(&bd) {
            assert!((c - d).abs() < 1e-10 * (1.0 + d.abs()), "{c} vs {d}");
        }
        // The single right-hand side (Newton's) has its own loops: column 1 of the above.
        let b1: Vec<f64> = (0..3 * n).map(|r| b[r * q + 1]).collect();
        let (mut xc, mut xd) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
        chain.solve(&b1, &mut xc);
        dense.solve(&b1, &mut xd);
        for r in 0..3 * n {
            assert!((xc[r] - xd[r]).abs() < 1e-10 * (1.0 + xd[r].abs()));
            assert!((xc[r] - bd[r * q + 1]).abs() < 1e-10 * (1.0 + xd[r].abs()));
        }
        // A Jacobian that breaks a chain (an entry off the shift) is factored densely.
        let mut broken = jacs[0].clone();
        broken[n + 3] = 0.5;
        let f = StageLu::factor(
            &a,
            n,
            0.7,
            [&broken, &broken, &broken],
            Some(&chains),
            &mut Pool::default(),
        )
        .unwrap();
        assert!(matches!(f, StageLu::Dense(_)));
    }

    #[test]
    fn error_matrix_chain_and_dense_solves_agree() {
        let chains = [(0, 2), (2, 1), (3, 4)];
        let n = 7;
        let mut seed = 11u64;
        let mut jac = vec![0.0; n * n];
        for &(off, len) in &chains {
            for k in off..off + len - 1 {
                jac[k * n + k + 1] = 1.0;
            }
            for c in 0..n {
                jac[(off + len - 1) * n + c] = 5.0 * rnd(&mut seed);
            }
        }
        let s = 0.3;
        let chain = ErrorLu::factor(n, s, &jac, Some(&chains), &mut Pool::default()).unwrap();
        assert!(matches!(chain, ErrorLu::Chain { .. }));
        let dense = ErrorLu::factor(n, s, &jac, None, &mut Pool::default()).unwrap();
        let b: Vec<f64> = (0..n).map(|_| rnd(&mut seed)).collect();
        let (mut xc, mut xd, mut work) = (vec![0.0; n], vec![0.0; n], Vec::new());
        chain.solve(&b, &mut xc, &mut work);
        dense.solve(&b, &mut xd, &mut work);
        // (I - s J) x = b, row by row.
        for r in 0..n {
            let jx: f64 = (0..n).map(|c| jac[r * n + c] * xc[c]).sum();
            assert!((xc[r] - s * jx - b[r]).abs() < 1e-12, "row {r}");
            assert!((xc[r] - xd[r]).abs() < 1e-12 * (1.0 + xd[r].abs()));
        }
    }

    #[test]
    fn factors_from_recycled_vectors_solve_to_the_same_bits() {
        // Factors of one system, used and recycled, leave their (dirty) vectors in the pool;
        // factors of another system built from them must solve exactly as fresh ones do.
        let chains = [(0, 1), (1, 3), (4, 2)];
        let n = 6;
        let mut seed = 11u64;
        let jac = |seed: &mut u64| {
            let mut j = vec![0.0; n * n];
            for &(off, len) in &chains {
                for k in off..off + len - 1 {
                    j[k * n + k + 1] = 1.0;
                }
                for c in 0..n {
                    j[(off + len - 1) * n + c] = 3.0 * rnd(seed);
                }
            }
            j
        };
        let (j1, j2) = (jac(&mut seed), jac(&mut seed));
        let a = [[0.2, -0.05, 0.02], [0.4, 0.2, -0.03], [0.38, 0.5, 0.11]];
        let q = 3;
        let b: Vec<f64> = (0..3 * n * q).map(|_| rnd(&mut seed)).collect();
        let b1: Vec<f64> = b[..3 * n].to_vec();
        let e1: Vec<f64> = b[..n].to_vec();
        for chained in [Some(&chains[..]), None] {
            let mut pool = Pool::default();
            let first = StageLu::factor(&a, n, 0.7, [&j1, &j1, &j1], chained, &mut pool).unwrap();
            let err = ErrorLu::factor(n, 0.3, &j1, chained, &mut pool).unwrap();
            let (mut x, mut scratch, mut work) = (vec![0.0; 3 * n], Vec::new(), Vec::new());
            first.solve(&b1, &mut x);
            first.solve_many(&mut b.clone(), q, &mut scratch);
            err.solve(&e1, &mut x[..n], &mut work);
            first.recycle(&mut pool);
            err.recycle(&mut pool);
            let stages = [&j2[..], &j2[..], &j2[..]];
            let reused = StageLu::factor(&a, n, 0.9, stages, chained, &mut pool).unwrap();
            let fresh = StageLu::factor(&a, n, 0.9, stages, chained, &mut Pool::default()).unwrap();
            let (mut xr, mut xf) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
            reused.solve(&b1, &mut xr);
            fresh.solve(&b1, &mut xf);
            assert_eq!(xr, xf);
            let (mut br, mut bf) = (b.clone(), b.clone());
            reused.solve_many(&mut br, q, &mut scratch);
            fresh.solve_many(&mut bf, q, &mut scratch);
            assert_eq!(br, bf);
            let err_r = ErrorLu::factor(n, 0.5, &j2, chained, &mut pool).unwrap();
            let err_f = ErrorLu::factor(n, 0.5, &j2, chained, &mut Pool::default()).unwrap();
            let (mut er, mut ef) = (vec![0.0; n], vec![0.0; n]);
            err_r.solve(&e1, &mut er, &mut work);
            err_f.solve(&e1, &mut ef, &mut work);
            assert_eq!(er, ef);
        }
    }
}
