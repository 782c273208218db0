//! An expression term and its partial derivatives as one straight-line program.
//!
//! Derivative trees, one per variable, copy their operands under the product and chain rules:
//! the derivative of a product of n factors has about n^2 / 2 nodes, that of k nested functions
//! evaluates the innermost argument k times, and every derivative evaluates again the parts of
//! the value it shares. A model of 30 nested `sin` over a product of 30 factors (523 bytes)
//! spent two minutes of `ctsid simulate` in such trees. Here the expression is a list of
//! operations in which equal subexpressions are one entry (hash-consing), and each partial
//! derivative is added to the same list: the derivative of an entry refers to the entries it
//! needs rather than copying them, so the program grows linearly with the expression per
//! variable, and one pass computes the value and the whole gradient.
//!
//! The value's entries compute what the tree's nodes compute, so a term's value is the tree's
//! to the bit. The derivatives fold the zeros and ones they produce (`d(3*y)/dy` is `3`, not
//! `0*y + 3*1`); they replaced per-variable derivative trees built by the same rules (session
//! 18), with the same results to the bit on every model the tests and benchmarks run.

use super::expr::{apply, num_power, Expr, Fun, Node};
use std::collections::HashMap;

/// One entry: its operands are earlier entries. Numbers are kept as their bits, so that an
/// entry is its own hash-consing key (`-0` and `0` apart, a NaN equal to itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Op {
    Num(u64),
    Var(usize),
    Neg(u32),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    Pow(u32, u64),
    Fun(Fun, u32, Option<usize>),
}

/// Entries on the stack when a tape is this short (most named terms: `sign(q_d1)` and its
/// derivative are four, `tanh(y_d1/1.2)` six); the integrator evaluates terms several times per
/// step, and zeroing a buffer of 48 for each took 3 % of `ctsid benchmark emps`.
const SMALL_ENTRIES: usize = 8;
const STACK_ENTRIES: usize = 48;

/// An expression and its nonzero partial derivatives as one program.
#[derive(Debug, Clone)]
pub(super) struct Tape {
    ops: Vec<Op>,
    /// The entry holding the value; the value needs only the entries before `value_len`.
    value: u32,
    value_len: usize,
    /// (variable, entry of the partial derivative), the nonzero ones in the order of
    /// [`Expr::variables`].
    grad: Vec<(usize, u32)>,
}

impl Tape {
    /// The program of `expr` and its partial derivatives; `None` once it has more than `most`
    /// entries (checked after the value and after each variable's derivative, each of which is
    /// at most a few times the expression's size).
    pub(super) fn new(expr: &Expr, most: usize) -> Option<Tape> {
        let mut b = Builder::default();
        let value = b.push(expr.root());
        let value_len = b.ops.len();
        let mut grad = Vec::new();
        for v in expr.variables() {
            if b.ops.len() > most {
                return None;
            }
            let mut memo = HashMap::new();
            let d = b.diff(value, v, &mut memo);
            if b.num_of(d) != Some(0.0) {
                grad.push((v, d));
            }
        }
        (b.ops.len() <= most).then_some(Tape {
            ops: b.ops,
            value,
            value_len,
            grad,
        })
    }

    /// Entries in all (value and derivatives).
    pub(super) fn len(&self) -> usize {
        self.ops.len()
    }

    /// The value at `z` (sign smoothed over `eps`, as [`Expr::eval_smooth`]).
    pub(super) fn value(&self, z: &[f64], eps: &[f64]) -> f64 {
        self.with_values(self.value_len, z, eps, |vals| vals[self.value as usize])
    }

    /// Adds `coef * d expr / d z_v` into `grad[v]` for every variable.
    pub(super) fn add_gradient(&self, coef: f64, z: &[f64], eps: &[f64], grad: &mut [f64]) {
        self.with_values(self.ops.len(), z, eps, |vals| {
            for &(v, d) in &self.grad {
                grad[v] += coef * vals[d as usize];
            }
        })
    }

    /// Runs the first `n` entries at `z` and hands their values to `f`.
    fn with_values<R>(&self, n: usize, z: &[f64], eps: &[f64], f: impl FnOnce(&[f64]) -> R) -> R {
        if n <= SMALL_ENTRIES {
            let mut vals = [0.0; SMALL_ENTRIES];
            self.run(&mut vals[..n], z, eps);
            f(&vals[..n])
        } else if n <= STACK_ENTRIES {
            let mut vals = [0.0; STACK_ENTRIES];
            self.run(&mut vals[..n], z, eps);
            f(&vals[..n])
        } else {
            let mut vals = vec![0.0; n];
            self.run(&mut vals, z, eps);
            f(&vals)
        }
    }

    fn run(&self, vals: &mut [f64], z: &[f64], eps: &[f64]) {
        for k in 0..vals.len() {
            let x = |i: u32| vals[i as usize];
            vals[k] = match self.ops[k] {
                Op::Num(v) => f64::from_bits(v),
                Op::Var(i) => z[i],
                Op::Neg(a) => -x(a),
                Op::Add(a, b) => x(a) + x(b),
                Op::Sub(a, b) => x(a) - x(b),
                Op::Mul(a, b) => x(a) * x(b),
                Op::Div(a, b) => x(a) / x(b),
                Op::Pow(a, e) => num_power(x(a), f64::from_bits(e)),
                Op::Fun(f, a, var) => {
                    let width = var.and_then(|i| eps.get(i).copied()).filter(|w| *w > 0.0);
                    apply(f, x(a), width)
                }
            };
        }
    }
}

/// Builds a tape: entries in evaluation order, equal ones once.
#[derive(Default)]
struct Builder {
    ops: Vec<Op>,
    index: HashMap<Op, u32>,
}

#[allow(clippy::redundant_guards)] // float literals in patterns read worse (as in `expr`)
impl Builder {
    fn op(&mut self, op: Op) -> u32 {
        let next = self.ops.len() as u32;
        let k = *self.index.entry(op).or_insert(next);
        if k == next {
            self.ops.push(op);
        }
        k
    }

    /// The entries of a tree, as they are (no folding: the value is the tree's).
    fn push(&mut self, n: &Node) -> u32 {
        let op = match n {
            Node::Num(v) => Op::Num(v.to_bits()),
            Node::Var(i) => Op::Var(*i),
            Node::Neg(a) => Op::Neg(self.push(a)),
            Node::Add(a, b) => Op::Add(self.push(a), self.push(b)),
            Node::Sub(a, b) => Op::Sub(self.push(a), self.push(b)),
            Node::Mul(a, b) => Op::Mul(self.push(a), self.push(b)),
            Node::Div(a, b) => Op::Div(self.push(a), self.push(b)),
            Node::Pow(a, e) => Op::Pow(self.push(a), e.to_bits()),
            Node::Fun(f, a, var) => Op::Fun(*f, self.push(a), *var),
        };
        self.op(op)
    }

    fn num_of(&self, k: u32) -> Option<f64> {
        match self.ops[k as usize] {
            Op::Num(v) => Some(f64::from_bits(v)),
            _ => None,
        }
    }

    // Constructors that fold the zeros and ones a derivative produces.
    fn num(&mut self, v: f64) -> u32 {
        self.op(Op::Num(v.to_bits()))
    }
    fn add(&mut self, a: u32, b: u32) -> u32 {
        match (self.num_of(a), self.num_of(b)) {
            (Some(x), Some(y)) => self.num(x + y),
            (Some(x), _) if x == 0.0 => b,
            (_, Some(y)) if y == 0.0 => a,
            _ => self.op(Op::Add(a, b)),
        }
    }
    fn sub(&mut self, a: u32, b: u32) -> u32 {
        match (self.num_of(a), self.num_of(b)) {
            (Some(x), Some(y)) => self.num(x - y),
            (_, Some(y)) if y == 0.0 => a,
            (Some(x), _) if x == 0.0 => self.neg(b),
            _ => self.op(Op::Sub(a, b)),
        }
    }
    fn neg(&mut self, a: u32) -> u32 {
        match self.ops[a as usize] {
            Op::Num(x) => self.num(-f64::from_bits(x)),
            Op::Neg(b) => b,
            _ => self.op(Op::Neg(a)),
        }
    }
    fn mul(&mut self, a: u32, b: u32) -> u32 {
        match (self.num_of(a), self.num_of(b)) {
            (Some(x), Some(y)) => self.num(x * y),
            (Some(x), _) | (_, Some(x)) if x == 0.0 => self.num(0.0),
            (Some(x), _) if x == 1.0 => b,
            (_, Some(y)) if y == 1.0 => a,
            _ => self.op(Op::Mul(a, b)),
        }
    }
    fn div(&mut self, a: u32, b: u32) -> u32 {
        match (self.num_of(a), self.num_of(b)) {
            (Some(x), _) if x == 0.0 => self.num(0.0),
            (_, Some(y)) if y == 1.0 => a,
            _ => self.op(Op::Div(a, b)),
        }
    }

    /// `d entry / d z_v`, each entry's derivative built once (see the module docs of
    /// [`super::expr`] for the kinks).
    fn diff(&mut self, k: u32, v: usize, memo: &mut HashMap<u32, u32>) -> u32 {
        if let Some(&d) = memo.get(&k) {
            return d;
        }
        let d = match self.ops[k as usize] {
            Op::Num(_) => self.num(0.0),
            Op::Var(i) => self.num((i == v) as u8 as f64),
            Op::Neg(a) => {
                let da = self.diff(a, v, memo);
                self.neg(da)
            }
            Op::Add(a, b) => {
                let (da, db) = (self.diff(a, v, memo), self.diff(b, v, memo));
                self.add(da, db)
            }
            Op::Sub(a, b) => {
                let (da, db) = (self.diff(a, v, memo), self.diff(b, v, memo));
                self.sub(da, db)
            }
            Op::Mul(a, b) => {
                let (da, db) = (self.diff(a, v, memo), self.diff(b, v, memo));
                let (l, r) = (self.mul(da, b), self.mul(a, db));
                self.add(l, r)
            }
            // (a/b)' = a'/b - a b' / b^2
            Op::Div(a, b) => {
                let (da, db) = (self.diff(a, v, memo), self.diff(b, v, memo));
                let l = self.div(da, b);
                let adb = self.mul(a, db);
                let b2 = self.op(Op::Pow(b, 2f64.to_bits()));
                let r = self.div(adb, b2);
                self.sub(l, r)
            }
            Op::Pow(a, e) => {
                let e = f64::from_bits(e);
                let da = self.diff(a, v, memo);
                let inner = if e == 1.0 {
                    self.num(1.0)
                } else if e == 2.0 {
                    a
                } else {
                    self.op(Op::Pow(a, (e - 1.0).to_bits()))
                };
                let ne = self.num(e);
                let c = self.mul(ne, inner);
                self.mul(c, da)
            }
            Op::Fun(f, a, var) => {
                let da = self.diff(a, v, memo);
                if self.num_of(da) == Some(0.0) {
                    self.num(0.0)
                } else {
                    let outer = self.outer(f, a, var);
                    self.mul(outer, da)
                }
            }
        };
        memo.insert(k, d);
        d
    }

    /// `f'(a)`.
    fn outer(&mut self, f: Fun, a: u32, var: Option<usize>) -> u32 {
        match f {
            Fun::Sign => self.op(Op::Fun(Fun::SignSlope, a, var)),
            Fun::Abs => self.op(Op::Fun(Fun::Sign, a, None)),
            Fun::Sqrt => self.op(Op::Fun(Fun::SqrtSlope, a, var)),
            Fun::Tanh => {
                let one = self.num(1.0);
                let t = self.op(Op::Fun(Fun::Tanh, a, var));
                let t2 = self.op(Op::Pow(t, 2f64.to_bits()));
                self.sub(one, t2)
            }
            Fun::Sin => self.op(Op::Fun(Fun::Cos, a, var)),
            Fun::Cos => {
                let s = self.op(Op::Fun(Fun::Sin, a, var));
                self.neg(s)
            }
            Fun::Exp => self.op(Op::Fun(Fun::Exp, a, var)),
            Fun::Sat => self.op(Op::Fun(Fun::Inside, a, var)),
            Fun::Relu => self.op(Op::Fun(Fun::Step, a, var)),
            Fun::SignSlope | Fun::SqrtSlope | Fun::Step | Fun::Inside => self.num(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars() -> Vec<String> {
        ["y", "y_d1", "u"].iter().map(|s| s.to_string()).collect()
    }

    fn gradient(t: &Tape, z: &[f64], eps: &[f64]) -> Vec<f64> {
        let mut g = vec![0.0; z.len()];
        t.add_gradient(1.0, z, eps, &mut g);
        g
    }

    /// The value is the tree's to the bit (the same operations on the same operands; also on the
    /// heap path and with `-0` constants); every partial derivative matches central differences.
    #[test]
    fn values_match_the_tree_and_derivatives_central_differences() {
        let v = vars();
        let eps = [0.0, 0.3, 0.0];
        for text in [
            "-0.5*sign(y_d1) + abs(y_d1)*y_d1 - y^3/2 + sqrt(abs(y))",
            "tanh(2*y_d1)*u - sin(y)*cos(u) + exp(-y^2)",
            "sat(y/3)*relu(u - 0.1) + y_d1/(1 + y^2) + y^2.5",
            "sign(y_d1)*u^2 - 3",
            "(y+u)*(y+u)*(y+u) - sin(sin(y*u))/(y_d1 + 2)",
            "sqrt(abs(y_d1))*y_d1 + 0*y + 1*u - (-y)",
            "y_d1/sqrt(abs(y) + 0.02) + u/(y_d1 + 0.5*sqrt(abs(y)))",
            "-0*y + 0*u - (-0)*y_d1 + y*-0",
            // More entries than the stack buffers hold: the heap path.
            "sin(sin(sin(sin((y+u)*(y+u)*(y+u)*(y_d1+u)*(y+u)*(y+u)*tanh(y_d1)))))^3/(1+u^2)",
        ] {
            let e = Expr::parse(text, &v).unwrap();
            let t = Tape::new(&e, usize::MAX).unwrap();
            if text.starts_with("sin(") {
                assert!(t.len() > STACK_ENTRIES, "{}", t.len());
            }
            for z in [[1.3, -0.4, 0.7], [0.0, 0.0, 0.0], [-2.5, 1e-3, -0.2]] {
                assert_eq!(
                    t.value(&z, &eps).to_bits(),
                    e.eval_smooth(&z, &eps).to_bits(),
                    "{text} at {z:?}"
                );
            }
            let z = [1.3, -0.4, 0.7];
            let g = gradient(&t, &z, &eps);
            for k in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (z, z);
                a[k] += h;
                b[k] -= h;
                let fd = (e.eval_smooth(&a, &eps) - e.eval_smooth(&b, &eps)) / (2.0 * h);
                assert!(
                    (fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{text} d/dz{k}: {} vs {fd}",
                    g[k]
                );
            }
        }
        // A variable the expression lacks has no entry; a linear term's slope is its factor.
        let t = Tape::new(&Expr::parse("3*y + u", &v).unwrap(), usize::MAX).unwrap();
        assert_eq!(t.grad.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(gradient(&t, &[0.0; 3], &eps), vec![3.0, 0.0, 1.0]);
    }

    #[test]
    fn the_slope_of_a_square_root_at_zero_is_finite() {
        let v: Vec<String> = ["y", "y_d1"].iter().map(|s| s.to_string()).collect();
        let slope = |text: &str, z: [f64; 2]| {
            let t = Tape::new(&Expr::parse(text, &v).unwrap(), usize::MAX).unwrap();
            gradient(&t, &z, &[0.0, 0.0])
        };
        // sqrt(|v|) v has slope 1.5 sqrt(|v|): 0 at rest, where the chain rule gave inf * 0.
        assert_eq!(slope("sqrt(abs(y_d1))*y_d1", [0.0, 0.0])[1], 0.0);
        let at = slope("sqrt(abs(y_d1))*y_d1", [0.0, 0.25])[1];
        assert!((at - 1.5 * 0.5).abs() < 1e-12, "{at}");
        // An outflow through an orifice at an empty tank: a number (0, as sign(0) = 0), not NaN.
        assert_eq!(slope("sqrt(abs(y))*sign(y)", [0.0, 0.0])[0], 0.0);
        assert!(slope("sqrt(y)", [0.0, 0.0])[0] > 1e150);
    }

    #[test]
    fn nested_functions_and_long_products_grow_the_tape_linearly() {
        let v = vars();
        let nested = |k: usize| {
            let product = vec!["(y+u)"; 30].join("*");
            format!("{}{product}{}", "sin(".repeat(k), ")".repeat(k))
        };
        let size = |text: &str| {
            Tape::new(&Expr::parse(text, &v).unwrap(), usize::MAX)
                .unwrap()
                .len()
        };
        // 30 nested sin over a product of 30 factors: the trees' derivative evaluated the
        // product under every level (two minutes of `simulate` for 1,800 samples).
        let (a, b) = (size(&nested(10)), size(&nested(30)));
        assert!(b < 400 && b - a < 3 * 20 * 2 + 10, "{a} {b}");
        let product = |n: usize| vec!["y"; n].join("*");
        let (a, b) = (size(&product(100)), size(&product(900)));
        assert!(b < 10 * a && b < 5_000, "{a} {b}");
    }
}
