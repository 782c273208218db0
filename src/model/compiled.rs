//! The compiled model: a fast evaluator of every right-hand side, its Jacobians with respect to
//! states and inputs, and its derivatives with respect to the coefficients.
//!
//! Monomials are evaluated as products of powers; expression terms as a straight-line program of
//! the expression and its partial derivatives ([`super::tape`]), with `sign` smoothed over the
//! widths the model file gives (see [`super::expr`]). Every term's partial derivatives are
//! prepared once here (monomials by the power rule, expressions symbolically), so the
//! integrator's Newton matrices and the refinement's sensitivities are exact derivatives of the
//! very right-hand side the simulation integrates.

use super::expr::Expr;
use super::tape::Tape;
use super::{Interpolation, Limits, Model, Var};
use crate::error::{Error, Result};

/// What a compiled term computes, without its coefficient.
#[derive(Debug, Clone)]
enum Kind {
    /// `prod z_v^e` as (slot in z, exponent).
    Monomial(Vec<(usize, u32)>),
    /// An expression (as written) and its nonzero partial derivatives in one program.
    Expression { text: String, tape: Tape },
}

/// `x.powi(e)` without the library call for the exponents monomials mostly have (the same
/// values: `powi` also gives 1, x and x * x for 0, 1 and 2); the call was 2 % of a MIMO
/// identification's time.
#[inline]
fn small_powi(x: f64, e: i32) -> f64 {
    match e {
        0 => 1.0,
        1 => x,
        2 => x * x,
        _ => x.powi(e),
    }
}

#[derive(Debug, Clone)]
struct CTerm {
    coef: f64,
    kind: Kind,
}

impl CTerm {
    /// The term's value without its coefficient (its derivative with respect to it).
    fn basis(&self, z: &[f64], eps: &[f64]) -> f64 {
        match &self.kind {
            Kind::Monomial(f) => f.iter().fold(1.0, |a, &(v, e)| match e {
                1 => a * z[v],
                2 => a * z[v] * z[v],
                _ => a * z[v].powi(e as i32),
            }),
            Kind::Expression { tape, .. } => tape.value(z, eps),
        }
    }

    /// Adds `coef * d basis / dz` into `grad`.
    fn add_gradient(&self, z: &[f64], eps: &[f64], grad: &mut [f64]) {
        match &self.kind {
            Kind::Monomial(f) => {
                for (a, &(v, e)) in f.iter().enumerate() {
                    let mut p = self.coef * e as f64 * small_powi(z[v], e as i32 - 1);
                    for (b, &(w, k)) in f.iter().enumerate() {
                        if a != b {
                            p *= small_powi(z[w], k as i32);
                        }
                    }
                    grad[v] += p;
                }
            }
            Kind::Expression { tape, .. } => tape.add_gradient(self.coef, z, eps, grad),
        }
    }
}

/// Entries the programs of a model's expression terms may have in all (about 100 MB): an
/// expression of at most 2,000 tokens and its derivatives take at most a few thousand entries
/// per variable, so only a file of very many long terms reaches it. Models written by ctsid
/// stay far below it.
const MAX_TAPE_ENTRIES: usize = 4_000_000;

/// Fast evaluator of a model's right-hand sides.
///
/// `z` is the concatenation `[state, inputs]` (see [`Model::variable_names`]); the state holds,
/// for each output, its derivatives `0..n_i-1`.
#[derive(Debug, Clone)]
pub struct CompiledModel {
    orders: Vec<usize>,
    offsets: Vec<usize>,
    n_state: usize,
    n_inputs: usize,
    terms: Vec<Vec<CTerm>>,
    names: Vec<String>,
    /// Smoothing width of `sign` per slot of z (0: exact).
    eps: Vec<f64>,
    interpolation: Interpolation,
    /// Each output's hard limits ([`Limits`]).
    limits: Vec<Limits>,
}

impl CompiledModel {
    pub(super) fn new(m: &Model) -> Result<CompiledModel> {
        let table = m.variable_table().map_err(|message| Error::Model {
            path: "<memory>".into(),
            message,
        })?;
        let n_state = m.state_dim();
        let slot = |v: Var| match v {
            Var::State(i) => i,
            Var::Input(i) => n_state + i,
        };
        let names = m.variable_names();
        let mut terms = Vec::with_capacity(m.outputs.len());
        let mut entries: usize = 0;
        for o in &m.outputs {
            let mut ts = Vec::with_capacity(o.terms.len());
            for t in &o.terms {
                let kind = match &t.expression {
                    Some(text) => {
                        // The programs, within a model-wide budget (checked while building).
                        let left = MAX_TAPE_ENTRIES - entries;
                        let Some(tape) = Tape::new(&Expr::parse(text, &names)?, left) else {
                            return Err(Error::Model {
                                path: "<memory>".into(),
                                message: format!(
                                    "the term '{}' of '{}' makes the model's derivatives too large to build (more than {MAX_TAPE_ENTRIES} operations with the others); write long products as monomial exponents",
                                    crate::util::clip(text, 60),
                                    o.name
                                ),
                            });
                        };
                        entries += tape.len();
                        Kind::Expression {
                            text: text.clone(),
                            tape,
                        }
                    }
                    None => Kind::Monomial(
                        t.exponents
                            .iter()
                            .map(|(n, &e)| (slot(table[n]), e))
                            .collect(),
                    ),
                };
                ts.push(CTerm {
                    coef: t.coefficient,
                    kind,
                });
            }
            terms.push(ts);
        }
        let eps = names
            .iter()
            .map(|n| m.sign_smoothing.get(n).copied().unwrap_or(0.0))
            .collect();
        Ok(CompiledModel {
            orders: m.outputs.iter().map(|o| o.order).collect(),
            offsets: (0..m.outputs.len()).map(|i| m.state_offset(i)).collect(),
            n_state,
            n_inputs: m.inputs.len(),
            terms,
            names,
            eps,
            interpolation: m.input_interpolation,
            limits: m.outputs.iter().map(|o| o.limits).collect(),
        })
    }

    /// Sets every output that `x` carries beyond one of its [`Limits`] back onto it, with its
    /// derivatives that point beyond it at zero, and appends the state indices it set to
    /// `pinned` (their values no longer depend on the coefficients or the initial state).
    pub fn project(&self, x: &mut [f64], pinned: &mut Vec<usize>) {
        for (i, lim) in self.limits.iter().enumerate() {
            let (off, n) = (self.offsets[i], self.orders[i]);
            // The side crossed and the sign that points beyond it.
            let crossed = match (lim.min, lim.max) {
                (_, Some(hi)) if x[off] > hi => Some((hi, 1.0)),
                (Some(lo), _) if x[off] < lo => Some((lo, -1.0)),
                _ => None,
            };
            let Some((bound, out)) = crossed else {
                continue;
            };
            x[off] = bound;
            pinned.push(off);
            for k in off + 1..off + n {
                if x[k] * out > 0.0 {
                    x[k] = 0.0;
                    pinned.push(k);
                }
            }
        }
    }

    pub fn n_state(&self) -> usize {
        self.n_state
    }
    pub fn n_inputs(&self) -> usize {
        self.n_inputs
    }
    pub fn n_outputs(&self) -> usize {
        self.orders.len()
    }
    pub fn orders(&self) -> &[usize] {
        &self.orders
    }
    /// How the model reads sampled inputs between their samples (the file's
    /// `input_interpolation`).
    pub fn input_interpolation(&self) -> Interpolation {
        self.interpolation
    }
    /// Offset of output `i` in the state vector. Panics when `i` is not below
    /// [`CompiledModel::n_outputs`].
    pub fn offset(&self, i: usize) -> usize {
        self.offsets[i]
    }
    /// Names of z = [state, inputs].
    pub fn names(&self) -> &[String] {
        &self.names
    }
    /// All coefficients, output by output in term order (the order of the model file).
    pub fn coefficients(&self) -> Vec<f64> {
        self.terms
            .iter()
            .flat_map(|ts| ts.iter().map(|t| t.coef))
            .collect()
    }

    /// Replaces the coefficients (same order as [`CompiledModel::coefficients`]) without
    /// recompiling: for refinement loops that simulate many coefficient vectors. Refuses a slice
    /// whose length is not the number of terms.
    pub fn set_coefficients(&mut self, c: &[f64]) -> Result<()> {
        let n: usize = self.terms.iter().map(|ts| ts.len()).sum();
        if c.len() != n {
            return Err(Error::param(
                "coefficients",
                format!("got {} values for {n} terms", c.len()),
            ));
        }
        for (t, &v) in self.terms.iter_mut().flat_map(|ts| ts.iter_mut()).zip(c) {
            t.coef = v;
        }
        Ok(())
    }

    /// Checks the lengths the public evaluators take: `output` below the number of outputs,
    /// each `(what, length, wanted)` exact.
    fn check_args(&self, output: Option<usize>, lens: &[(&str, usize, usize)]) -> Result<()> {
        if let Some(i) = output {
            if i >= self.n_outputs() {
                return Err(Error::param(
                    "output",
                    format!("index {i}, but the model has {} outputs", self.n_outputs()),
                ));
            }
        }
        for &(what, len, want) in lens {
            if len != want {
                return Err(Error::param(
                    what,
                    format!("{len} values, the model needs {want}"),
                ));
            }
        }
        Ok(())
    }

    /// `P_i(z)`: the highest derivative of output `i` at `z = [state, inputs]`. Refuses an
    /// output index out of range and a `z` of another length than states + inputs.
    pub fn eval_output(&self, i: usize, z: &[f64]) -> Result<f64> {
        self.check_args(Some(i), &[("z", z.len(), self.n_state + self.n_inputs)])?;
        Ok(self.eval_output_unchecked(i, z))
    }

    /// The value of every term of output `i` at `z` without its coefficient, in file order.
    /// Refuses what [`CompiledModel::eval_output`] refuses.
    pub fn term_values(&self, i: usize, z: &[f64]) -> Result<Vec<f64>> {
        self.check_args(Some(i), &[("z", z.len(), self.n_state + self.n_inputs)])?;
        Ok(self.term_values_unchecked(i, z))
    }

    /// `dP_i/dz` at `z` (length states + inputs). Refuses what [`CompiledModel::eval_output`]
    /// refuses.
    pub fn grad_output(&self, i: usize, z: &[f64]) -> Result<Vec<f64>> {
        self.check_args(Some(i), &[("z", z.len(), self.n_state + self.n_inputs)])?;
        let mut g = vec![0.0; z.len()];
        self.grad_output_unchecked(i, z, &mut g);
        Ok(g)
    }

    /// The state derivative at state `x` and inputs `u`: the chains of integrators closed by
    /// the right-hand sides. Refuses `x`, `u` or `dx` of other lengths than the model's.
    pub fn rhs(&self, x: &[f64], u: &[f64], dx: &mut [f64]) -> Result<()> {
        let (n, nu) = (self.n_state, self.n_inputs);
        self.check_args(
            None,
            &[("x", x.len(), n), ("u", u.len(), nu), ("dx", dx.len(), n)],
        )?;
        self.rhs_unchecked(x, u, dx);
        Ok(())
    }

    /// Jacobians of [`CompiledModel::rhs`] with respect to the state (row-major n x n) and the
    /// inputs (row-major n x n_u). Refuses slices of other lengths.
    pub fn jacobians(&self, x: &[f64], u: &[f64], jx: &mut [f64], ju: &mut [f64]) -> Result<()> {
        let (n, nu) = (self.n_state, self.n_inputs);
        self.check_args(
            None,
            &[
                ("x", x.len(), n),
                ("u", u.len(), nu),
                ("jx", jx.len(), n * n),
                ("ju", ju.len(), n * nu),
            ],
        )?;
        self.jacobians_unchecked(x, u, jx, ju);
        Ok(())
    }

    /// Unchecked [`CompiledModel::eval_output`]: `P_i(z)`, the highest derivative of output `i` at `z = [state, inputs]`.
    pub(crate) fn eval_output_unchecked(&self, i: usize, z: &[f64]) -> f64 {
        self.terms[i]
            .iter()
            .map(|t| t.coef * t.basis(z, &self.eps))
            .sum()
    }

    /// The first term (output index, its text, its value) whose value is not finite at state `x`
    /// and inputs `u`: a simulation that starts there fails at once, and the error should name
    /// the term, not call the model unstable (`sqrt(y)` from a negative `y`, `1/(y-y)`).
    pub(crate) fn nonfinite_term(&self, x: &[f64], u: &[f64]) -> Option<(usize, String, f64)> {
        let z: Vec<f64> = x.iter().chain(u).copied().collect();
        // A state or input of another length is the caller's error, reported where it is used.
        if z.len() != self.names.len() {
            return None;
        }
        self.terms.iter().enumerate().find_map(|(i, terms)| {
            terms.iter().find_map(|t| {
                let v = t.basis(&z, &self.eps);
                (!v.is_finite()).then(|| (i, self.term_text(t), v))
            })
        })
    }

    fn term_text(&self, t: &CTerm) -> String {
        match &t.kind {
            Kind::Expression { text, .. } => text.trim().to_string(),
            Kind::Monomial(f) => {
                let pairs: Vec<(&str, u32)> = f
                    .iter()
                    .map(|&(v, e)| (self.names[v].as_str(), e))
                    .collect();
                super::Term::new(&pairs, 1.0).monomial()
            }
        }
    }

    /// The value of every term of output `i` at `z` without its coefficient (the regression
    /// columns of that equation), in file order.
    pub(crate) fn term_values_unchecked(&self, i: usize, z: &[f64]) -> Vec<f64> {
        self.terms[i]
            .iter()
            .map(|t| t.basis(z, &self.eps))
            .collect()
    }

    /// `d rhs / d c` for the coefficients `coefs` (indices into [`CompiledModel::coefficients`]):
    /// written row-major `n_state x coefs.len()` into `out`. Each coefficient only moves the
    /// top derivative of its own output, by the value of its term.
    pub(crate) fn coefficient_jacobian_unchecked(
        &self,
        x: &[f64],
        u: &[f64],
        coefs: &[usize],
        out: &mut [f64],
    ) {
        let q = coefs.len();
        out.iter_mut().for_each(|v| *v = 0.0);
        let mut buf = Buf::new(x.len() + u.len());
        let z = buf.concat(x, u);
        for (col, &k) in coefs.iter().enumerate() {
            let mut rest = k;
            let mut i = 0;
            while rest >= self.terms[i].len() {
                rest -= self.terms[i].len();
                i += 1;
            }
            let row = self.offsets[i] + self.orders[i] - 1;
            out[row * q + col] = self.terms[i][rest].basis(z, &self.eps);
        }
    }

    /// `dP_i/dz` at `z`, written into `grad` (length n_state + n_inputs).
    pub(crate) fn grad_output_unchecked(&self, i: usize, z: &[f64], grad: &mut [f64]) {
        grad.iter_mut().for_each(|g| *g = 0.0);
        for t in &self.terms[i] {
            t.add_gradient(z, &self.eps, grad);
        }
    }

    /// The state derivative: the chains of integrators closed by the right-hand sides.
    pub(crate) fn rhs_unchecked(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        // The solver calls this several times per step: no allocation for the usual sizes.
        let mut buf = Buf::new(self.n_state + self.n_inputs);
        let z = buf.concat(x, u);
        for (i, (&n, &o)) in self.orders.iter().zip(&self.offsets).enumerate() {
            for k in 0..n - 1 {
                dx[o + k] = x[o + k + 1];
            }
            dx[o + n - 1] = self.eval_output_unchecked(i, z);
        }
    }

    /// [`CompiledModel::jacobians_unchecked`] without the input part.
    pub(crate) fn state_jacobian_unchecked(&self, x: &[f64], u: &[f64], jx: &mut [f64]) {
        let mut ju = Buf::new(self.n_state * self.n_inputs);
        self.jacobians_unchecked(x, u, jx, ju.get());
    }

    /// Jacobian of [`CompiledModel::rhs`] with respect to the state (row-major n x n) and to the
    /// inputs (row-major n x n_u).
    pub(crate) fn jacobians_unchecked(&self, x: &[f64], u: &[f64], jx: &mut [f64], ju: &mut [f64]) {
        let n = self.n_state;
        let nu = self.n_inputs;
        let (mut zb, mut gb) = (Buf::new(n + nu), Buf::new(n + nu));
        let z = zb.concat(x, u);
        jx.iter_mut().for_each(|v| *v = 0.0);
        ju.iter_mut().for_each(|v| *v = 0.0);
        let g = gb.get();
        for (i, (&ord, &o)) in self.orders.iter().zip(&self.offsets).enumerate() {
            for k in 0..ord - 1 {
                jx[(o + k) * n + o + k + 1] = 1.0;
            }
            self.grad_output_unchecked(i, z, g);
            let row = o + ord - 1;
            jx[row * n..row * n + n].copy_from_slice(&g[..n]);
            ju[row * nu..row * nu + nu].copy_from_slice(&g[n..]);
        }
    }
}

/// A zeroed work vector on the stack when it is short (the solver evaluates right-hand sides and
/// Jacobians several times per step; their allocations were a tenth of a small model's
/// simulation), on the heap otherwise.
pub(crate) struct Buf {
    stack: [f64; 32],
    heap: Vec<f64>,
    len: usize,
}

impl Buf {
    #[inline(always)]
    pub(crate) fn new(len: usize) -> Buf {
        Buf {
            stack: [0.0; 32],
            heap: if len > 32 { vec![0.0; len] } else { Vec::new() },
            len,
        }
    }

    #[inline(always)]
    pub(crate) fn get(&mut self) -> &mut [f64] {
        if self.len <= 32 {
            &mut self.stack[..self.len]
        } else {
            &mut self.heap
        }
    }

    /// `x` then `u` (their lengths sum to the buffer's), element by element: a few states are
    /// copied faster by a loop than by a call to `memcpy`.
    #[inline(always)]
    pub(crate) fn concat(&mut self, x: &[f64], u: &[f64]) -> &[f64] {
        let z = self.get();
        for (d, v) in z.iter_mut().zip(x.iter().chain(u)) {
            *d = *v;
        }
        z
    }
}
