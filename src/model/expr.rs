//! The expression language of named model terms: `-sign(y_d1)`, `abs(y_d1)*y_d1`,
//! `sqrt(abs(y))*sign(y)`.
//!
//! Grammar: numbers, variables (the model's state names `y`, `y_d1`, ... and input names),
//! `+ - * /`, `^` with a numeric exponent, parentheses, and the functions `sign abs sqrt tanh sin
//! cos exp sat relu` (`sat(x)` clips to [-1, 1], `relu(x) = max(x, 0)`). Variables are resolved to
//! indices of the evaluation vector `z` when parsing, so an unknown name is a parse error that
//! names it. The one discontinuity, `sign`, can be evaluated smoothed (`x / sqrt(x^2 + eps^2)`)
//! for the integrator: Radau with step-size control cannot step across a relay that chatters in a
//! stick phase. The width `eps` belongs to the variable the argument depends on first (its first
//! variable), and the model file stores it, so that a model simulates the same everywhere.
//!
//! The derivatives are taken symbolically by `super::tape`, which compiles an expression and
//! its partial derivatives into one program: the integrator's Newton steps and the refinement's
//! sensitivities need exact Jacobians of every term. The derivative of a smoothed `sign` is the
//! slope of the smoothed curve, `eps^2 / (x^2 + eps^2)^(3/2)`, and 0 where it is exact; those of
//! `abs`, `sat` and `relu` are taken piecewise (their kinks are a set of measure zero that a
//! Newton step does not need to resolve). The functions of that list that only derivatives use
//! (`SignSlope`, `SqrtSlope`, `Step`, `Inside`) are evaluated here, by `apply`.

use crate::error::{Error, Result};

#[derive(Debug, Clone, PartialEq)]
pub(super) enum Node {
    Num(f64),
    Var(usize),
    Neg(Box<Node>),
    Add(Box<Node>, Box<Node>),
    Sub(Box<Node>, Box<Node>),
    Mul(Box<Node>, Box<Node>),
    Div(Box<Node>, Box<Node>),
    Pow(Box<Node>, f64),
    /// A function of its argument; the index is the argument's first variable (the one whose
    /// smoothing width a smoothed `sign` and its slope use), resolved when parsing.
    Fun(Fun, Box<Node>, Option<usize>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Fun {
    Sign,
    Abs,
    Sqrt,
    Tanh,
    Sin,
    Cos,
    Exp,
    Sat,
    Relu,
    // Derivatives only (not in the grammar): the slope of the smoothed sign, the unit step
    // (relu'), the indicator of |x| < 1 (sat') and sqrt' (finite at 0, see `sqrt_slope`).
    SignSlope,
    SqrtSlope,
    Step,
    Inside,
}

/// Longest expression, in tokens, and deepest nesting of parentheses, calls or signs: parsing
/// and evaluation recurse along both, so they bound the stack an expression can take.
const MAX_TOKENS: usize = 2000;
const MAX_NESTING: usize = 64;

/// A parsed expression over a fixed list of variable names.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    text: String,
    root: Node,
}

impl Expr {
    /// Parses `text` over `vars` (the names of the entries of `z` in [`Expr::eval`]). Refuses an
    /// unexpected character, a malformed number, more than 2000 tokens, nesting deeper than 64
    /// levels, an unknown function or variable, a missing `)` or operand, a `^` without a numeric
    /// exponent or with one beyond 64 in magnitude, and text left after the expression (an empty
    /// text among them).
    pub fn parse(text: &str, vars: &[String]) -> Result<Expr> {
        let toks = lex(text)?;
        let mut p = Parser {
            toks,
            pos: 0,
            vars,
            text,
            depth: 0,
        };
        if p.toks.len() > MAX_TOKENS {
            return Err(p.err(&format!("longer than {MAX_TOKENS} tokens")));
        }
        let root = p.expr()?;
        if p.pos != p.toks.len() {
            return Err(p.err("unexpected text after the end of the expression"));
        }
        Ok(Expr {
            text: text.trim().to_string(),
            root,
        })
    }

    /// The expression as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The parsed tree (for [`super::tape`]).
    pub(super) fn root(&self) -> &Node {
        &self.root
    }

    /// Value at `z`; `sign` is exact. Panics when `z` is too short for a variable the expression
    /// reads ([`Expr::variables`]); as many values as the `vars` it was parsed over are enough.
    pub fn eval(&self, z: &[f64]) -> f64 {
        eval(&self.root, z, None)
    }

    /// Value at `z` with `sign(x)` replaced by `x / sqrt(x^2 + eps[i]^2)` where `i` is the
    /// variable the argument depends on most directly (its first variable), for integration.
    /// Panics as [`Expr::eval`] does; a missing or nonpositive `eps[i]` keeps that `sign` exact.
    pub fn eval_smooth(&self, z: &[f64], eps: &[f64]) -> f64 {
        eval(&self.root, z, Some(eps))
    }

    /// What makes the expression not finite whatever its variables are: a part without
    /// variables whose value is not finite (`0/0`, `sqrt(-1)`, `exp(710)`), or a division by a
    /// part that is zero without variables (`y/0`). `None` when there is none. (Such a term was
    /// read from a model file and then blamed on the step size, or dropped from a fit quietly.)
    pub fn constant_fault(&self) -> Option<String> {
        // One pass: each node says whether it reads a variable; a part without any is evaluated
        // once, where its parent has one (or at the root), not at every level below.
        fn finite(n: &Node) -> std::result::Result<(), String> {
            let v = eval(n, &[], None);
            match v.is_finite() {
                true => Ok(()),
                false => Err(format!("a part of it without variables is {v}")),
            }
        }
        fn walk(n: &Node) -> std::result::Result<bool, String> {
            let kids: Vec<&Node> = match n {
                Node::Num(_) | Node::Var(_) => vec![],
                Node::Neg(a) | Node::Pow(a, _) | Node::Fun(_, a, _) => vec![a],
                Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
                    vec![a, b]
                }
            };
            let reads: Vec<bool> = kids
                .iter()
                .map(|k| walk(k))
                .collect::<std::result::Result<_, _>>()?;
            let any = matches!(n, Node::Var(_)) || reads.contains(&true);
            if any {
                for (k, _) in kids.iter().zip(&reads).filter(|(_, r)| !**r) {
                    finite(k)?;
                }
                if let (Node::Div(_, b), [_, false]) = (n, reads.as_slice()) {
                    if eval(b, &[], None) == 0.0 {
                        return Err("it divides by zero".into());
                    }
                }
            }
            Ok(any)
        }
        match walk(&self.root) {
            Ok(true) => None,
            Ok(false) => finite(&self.root).err(),
            Err(why) => Some(why),
        }
    }

    /// The indices (into `z`) of the variables the expression reads, in order of appearance.
    pub fn variables(&self) -> Vec<usize> {
        let mut v = Vec::new();
        collect_vars(&self.root, &mut v);
        v
    }

    /// The variables whose smoothing width a `sign` in the expression uses.
    pub fn sign_variables(&self) -> Vec<usize> {
        fn walk(n: &Node, out: &mut Vec<usize>) {
            match n {
                Node::Num(_) | Node::Var(_) => {}
                Node::Fun(f, a, var) => {
                    if *f == Fun::Sign {
                        if let Some(i) = var {
                            if !out.contains(i) {
                                out.push(*i)
                            }
                        }
                    }
                    walk(a, out)
                }
                Node::Neg(a) | Node::Pow(a, _) => walk(a, out),
                Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
                    walk(a, out);
                    walk(b, out)
                }
            }
        }
        let mut v = Vec::new();
        walk(&self.root, &mut v);
        v
    }

    /// The exponents of the monomial the expression is a constant multiple of (`2*y`, `-y`,
    /// `y^2/2`, `y^0`), or `None` when it is no such multiple. A named term of this form is a
    /// candidate of the basis again, scaled.
    pub fn monomial_up_to_scale(&self) -> Option<Vec<(usize, u32)>> {
        self.powers(true)
    }

    /// Whether the expression is a product of integer powers of single variables (a monomial of
    /// the model file), with those exponents. `None` for any other expression: a sum, a function, a
    /// number other than 1, or a power that is not a positive integer power of one variable.
    pub fn monomial(&self) -> Option<Vec<(usize, u32)>> {
        self.powers(false)
    }

    /// The powers of a product of variables, by variable: [`Expr::monomial`], and with `scaled`
    /// also numbers, signs, division by a number and zeroth powers as factors.
    fn powers(&self, scaled: bool) -> Option<Vec<(usize, u32)>> {
        fn walk(n: &Node, scaled: bool, out: &mut Vec<(usize, u32)>) -> bool {
            let number = |n: &Node| matches!(n, Node::Num(v) if *v != 0.0 && v.is_finite());
            match n {
                Node::Num(v) => *v == 1.0 || (scaled && number(n)),
                Node::Var(i) => {
                    out.push((*i, 1));
                    true
                }
                Node::Mul(a, b) => walk(a, scaled, out) && walk(b, scaled, out),
                Node::Neg(a) if scaled => walk(a, scaled, out),
                Node::Div(a, b) if scaled => number(b) && walk(a, scaled, out),
                Node::Pow(_, e) if scaled && *e == 0.0 => true,
                Node::Pow(a, e) if *e >= 1.0 && e.fract() == 0.0 => match **a {
                    Node::Var(i) => {
                        out.push((i, *e as u32));
                        true
                    }
                    _ => false,
                },
                _ => false,
            }
        }
        let mut v = Vec::new();
        if !walk(&self.root, scaled, &mut v) {
            return None;
        }
        let mut merged: Vec<(usize, u32)> = Vec::new();
        for (i, e) in v {
            match merged.iter_mut().find(|(j, _)| *j == i) {
                Some(m) => m.1 += e,
                None => merged.push((i, e)),
            }
        }
        merged.sort();
        Some(merged)
    }
}

fn first_var(n: &Node) -> Option<usize> {
    match n {
        Node::Num(_) => None,
        Node::Var(i) => Some(*i),
        Node::Neg(a) | Node::Pow(a, _) | Node::Fun(_, a, _) => first_var(a),
        Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
            first_var(a).or_else(|| first_var(b))
        }
    }
}

fn collect_vars(n: &Node, out: &mut Vec<usize>) {
    match n {
        Node::Num(_) => {}
        Node::Var(i) => {
            if !out.contains(i) {
                out.push(*i)
            }
        }
        Node::Neg(a) | Node::Pow(a, _) | Node::Fun(_, a, _) => collect_vars(a, out),
        Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
            collect_vars(a, out);
            collect_vars(b, out)
        }
    }
}

fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn eval(n: &Node, z: &[f64], eps: Option<&[f64]>) -> f64 {
    match n {
        Node::Num(v) => *v,
        Node::Var(i) => z[*i],
        Node::Neg(a) => -eval(a, z, eps),
        Node::Add(a, b) => eval(a, z, eps) + eval(b, z, eps),
        Node::Sub(a, b) => eval(a, z, eps) - eval(b, z, eps),
        Node::Mul(a, b) => eval(a, z, eps) * eval(b, z, eps),
        Node::Div(a, b) => eval(a, z, eps) / eval(b, z, eps),
        Node::Pow(a, e) => num_power(eval(a, z, eps), *e),
        Node::Fun(f, a, var) => {
            let x = eval(a, z, eps);
            let width = match (eps, var) {
                (Some(e), Some(i)) => e.get(*i).copied().filter(|w| *w > 0.0),
                _ => None,
            };
            apply(*f, x, width)
        }
    }
}

/// `x^e` as the tree and the tape both compute it.
pub(super) fn num_power(x: f64, e: f64) -> f64 {
    if e.fract() == 0.0 {
        x.powi(e as i32)
    } else {
        x.powf(e)
    }
}

/// `f(x)`, with `sign` and its slope smoothed over `width` where there is one.
pub(super) fn apply(f: Fun, x: f64, width: Option<f64>) -> f64 {
    match f {
        Fun::Sign => match width {
            Some(e) => x / (x * x + e * e).sqrt(),
            None => sign(x),
        },
        Fun::SignSlope => match width {
            Some(e) => e * e / (x * x + e * e).powf(1.5),
            None => 0.0,
        },
        Fun::Abs => x.abs(),
        Fun::Sqrt => x.sqrt(),
        Fun::Tanh => x.tanh(),
        Fun::Sin => x.sin(),
        Fun::Cos => x.cos(),
        Fun::Exp => x.exp(),
        Fun::Sat => x.clamp(-1.0, 1.0),
        Fun::Relu => x.max(0.0),
        Fun::SqrtSlope => sqrt_slope(x),
        Fun::Step => (x > 0.0) as u8 as f64,
        Fun::Inside => (x.abs() < 1.0) as u8 as f64,
    }
}

/// `d sqrt(x) / dx = 0.5 / sqrt(x)`, finite at x = 0: there `0.5 / sqrt(0)` is infinite, and
/// the chain rule's product with an inner slope of zero (`sqrt(abs(v))` at v = 0, where the slope
/// of `abs` is `sign(0) = 0`) was NaN, so a Jacobian at rest (a linearisation, the integrator's
/// first step from a state at exactly zero) failed, though `sqrt(abs(v)) * v` has slope 0
/// there. A finite slope of 3.4e153 keeps such products at zero and others finite.
fn sqrt_slope(x: f64) -> f64 {
    if x == 0.0 {
        0.5 / f64::MIN_POSITIVE.sqrt()
    } else {
        0.5 / x.sqrt()
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Id(String),
    Op(char),
}

fn lex(text: &str) -> Result<Vec<Tok>> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch.is_ascii_digit() || ch == '.' {
            let s = i;
            while i < c.len()
                && (c[i].is_ascii_digit()
                    || c[i] == '.'
                    || ((c[i] == 'e' || c[i] == 'E') && i + 1 < c.len())
                    || ((c[i] == '-' || c[i] == '+')
                        && i > s
                        && (c[i - 1] == 'e' || c[i - 1] == 'E')))
            {
                i += 1;
            }
            let t: String = c[s..i].iter().collect();
            let v: f64 = t.parse().map_err(|_| {
                Error::param("expression", format!("'{text}': '{t}' is not a number"))
            })?;
            // `1e400` parses as infinity: refused here rather than blamed on the dynamics.
            if !v.is_finite() {
                return Err(Error::param(
                    "expression",
                    format!(
                        "'{}': '{t}' is beyond the range of f64 numbers",
                        crate::util::clip(text, 60)
                    ),
                ));
            }
            out.push(Tok::Num(v));
        } else if ch.is_alphabetic() || ch == '_' {
            let s = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(Tok::Id(c[s..i].iter().collect()));
        } else if "+-*/^()".contains(ch) {
            out.push(Tok::Op(ch));
            i += 1;
        } else {
            return Err(Error::param(
                "expression",
                format!("'{text}': unexpected character '{ch}'"),
            ));
        }
    }
    Ok(out)
}

struct Parser<'a> {
    toks: Vec<Tok>,
    pos: usize,
    vars: &'a [String],
    text: &'a str,
    /// Current nesting of parentheses, calls and signs (bounded by MAX_NESTING).
    depth: usize,
}

impl Parser<'_> {
    fn err(&self, what: &str) -> Error {
        // Long texts are cut: the message stays one readable line.
        let text = self.text.trim();
        let shown: String = text.chars().take(60).collect();
        let more = if text.chars().count() > 60 { "..." } else { "" };
        Error::param(
            "expression",
            format!("'{shown}{more}': {what} (at token {})", self.pos + 1),
        )
    }
    /// Parses one nesting level deeper with `f`, refusing to go past MAX_NESTING.
    fn nested(&mut self, f: impl FnOnce(&mut Self) -> Result<Node>) -> Result<Node> {
        if self.depth >= MAX_NESTING {
            return Err(self.err(&format!("nested more than {MAX_NESTING} levels deep")));
        }
        self.depth += 1;
        let r = f(self);
        self.depth -= 1;
        r
    }
    fn peek_op(&self, ops: &str) -> Option<char> {
        match self.toks.get(self.pos) {
            Some(Tok::Op(c)) if ops.contains(*c) => Some(*c),
            _ => None,
        }
    }
    fn expr(&mut self) -> Result<Node> {
        let mut a = self.term()?;
        while let Some(op) = self.peek_op("+-") {
            self.pos += 1;
            let b = self.term()?;
            a = if op == '+' {
                Node::Add(Box::new(a), Box::new(b))
            } else {
                Node::Sub(Box::new(a), Box::new(b))
            };
        }
        Ok(a)
    }
    fn term(&mut self) -> Result<Node> {
        let mut a = self.unary()?;
        while let Some(op) = self.peek_op("*/") {
            self.pos += 1;
            let b = self.unary()?;
            a = if op == '*' {
                Node::Mul(Box::new(a), Box::new(b))
            } else {
                Node::Div(Box::new(a), Box::new(b))
            };
        }
        Ok(a)
    }
    fn unary(&mut self) -> Result<Node> {
        if self.peek_op("-").is_some() {
            self.pos += 1;
            return self.nested(|p| Ok(Node::Neg(Box::new(p.unary()?))));
        }
        if self.peek_op("+").is_some() {
            self.pos += 1;
            return self.nested(|p| p.unary());
        }
        self.power()
    }
    fn power(&mut self) -> Result<Node> {
        let a = self.atom()?;
        if self.peek_op("^").is_some() {
            self.pos += 1;
            let neg = if self.peek_op("-").is_some() {
                self.pos += 1;
                true
            } else {
                false
            };
            match self.toks.get(self.pos) {
                Some(Tok::Num(v)) => {
                    self.pos += 1;
                    if v.abs() > 64.0 {
                        return Err(self.err("exponents go up to 64"));
                    }
                    return Ok(Node::Pow(Box::new(a), if neg { -v } else { *v }));
                }
                _ => return Err(self.err("'^' needs a number as exponent")),
            }
        }
        Ok(a)
    }
    fn atom(&mut self) -> Result<Node> {
        match self.toks.get(self.pos).cloned() {
            Some(Tok::Num(v)) => {
                self.pos += 1;
                Ok(Node::Num(v))
            }
            Some(Tok::Op('(')) => {
                self.pos += 1;
                let e = self.nested(|p| p.expr())?;
                if self.peek_op(")").is_none() {
                    return Err(self.err("missing ')'"));
                }
                self.pos += 1;
                Ok(e)
            }
            Some(Tok::Id(name)) => {
                self.pos += 1;
                if self.peek_op("(").is_some() {
                    let f = match name.as_str() {
                        "sign" => Fun::Sign,
                        "abs" => Fun::Abs,
                        "sqrt" => Fun::Sqrt,
                        "tanh" => Fun::Tanh,
                        "sin" => Fun::Sin,
                        "cos" => Fun::Cos,
                        "exp" => Fun::Exp,
                        "sat" => Fun::Sat,
                        "relu" => Fun::Relu,
                        _ => {
                            return Err(self.err(&format!(
                                "unknown function '{name}' (known: sign abs sqrt tanh sin cos exp sat relu)"
                            )))
                        }
                    };
                    self.pos += 1;
                    let e = self.nested(|p| p.expr())?;
                    if self.peek_op(")").is_none() {
                        return Err(self.err("missing ')'"));
                    }
                    self.pos += 1;
                    let var = first_var(&e);
                    return Ok(Node::Fun(f, Box::new(e), var));
                }
                match self.vars.iter().position(|v| *v == name) {
                    Some(i) => Ok(Node::Var(i)),
                    None => Err(self.err(&format!(
                        "unknown variable '{name}' (known: {})",
                        self.vars.join(", ")
                    ))),
                }
            }
            _ => Err(self.err("expected a number, a variable, a function or '('")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_up_to_a_factor_are_recognised() {
        let vars = ["y".to_string(), "u".to_string()];
        let m = |t: &str| Expr::parse(t, &vars).unwrap().monomial_up_to_scale();
        assert_eq!(m("2*y"), Some(vec![(0, 1)]));
        assert_eq!(m("-y"), Some(vec![(0, 1)]));
        assert_eq!(m("y^2/2"), Some(vec![(0, 2)]));
        assert_eq!(m("u*y*3"), Some(vec![(0, 1), (1, 1)]));
        assert_eq!(m("y^0"), Some(vec![]));
        assert_eq!(m("2"), Some(vec![]));
        for other in ["y + 1", "y/u", "sign(y)", "y^0.5", "0*y", "y/0", "(y+u)^2"] {
            assert_eq!(m(other), None, "{other}");
        }
    }

    #[test]
    fn parts_that_are_not_finite_whatever_the_variables_are_named() {
        let vars = ["y".to_string(), "u".to_string()];
        let fault = |t: &str| Expr::parse(t, &vars).unwrap().constant_fault();
        for bad in [
            "0/0",
            "sqrt(-1)",
            "exp(710)",
            "y/0",
            "y*(1/0)",
            "u + 1/(2-2)",
            "tanh(y)/(1-1)",
        ] {
            assert!(fault(bad).is_some(), "{bad}");
        }
        for good in [
            "y/u",
            "1/(y-y)",
            "exp(709)*y",
            "sqrt(abs(y))",
            "sign(y)*2",
            "-1",
            "y^2/2",
        ] {
            assert_eq!(fault(good), None, "{good}");
        }
    }

    #[test]
    fn a_literal_beyond_f64_is_refused_not_read_as_infinity() {
        let vars = vec!["u".to_string()];
        for text in ["u*1e400", "0*1e400", "u + -1e309"] {
            let e = Expr::parse(text, &vars).unwrap_err().to_string();
            assert!(e.contains("beyond the range"), "{text}: {e}");
        }
        assert!(Expr::parse("u*1e300", &vars).is_ok());
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let vars = vec!["y".to_string()];
        let deep = format!("{}y{}", "(".repeat(500), ")".repeat(500));
        let e = Expr::parse(&deep, &vars).unwrap_err().to_string();
        assert!(e.contains("nested more than") && e.len() < 200, "{e}");
        let deeper = format!("{}y{}", "(".repeat(9000), ")".repeat(9000));
        let e = Expr::parse(&deeper, &vars).unwrap_err().to_string();
        assert!(e.contains("longer than") && e.len() < 200, "{e}");
        let signs = format!("{}y", "-".repeat(40000));
        assert!(Expr::parse(&signs, &vars).is_err());
        let long = vec!["y"; 5000].join("+");
        assert!(Expr::parse(&long, &vars).is_err());
        let fine = format!("{}y{}", "(".repeat(60), ")".repeat(60));
        assert!(Expr::parse(&fine, &vars).is_ok());
    }

    #[test]
    fn variables_and_sign_variables_are_listed() {
        let v: Vec<String> = ["y", "y_d1", "u"].iter().map(|s| s.to_string()).collect();
        assert_eq!(Expr::parse("3*y + u", &v).unwrap().variables(), vec![0, 2]);
        assert_eq!(
            Expr::parse("sign(y_d1)*y", &v).unwrap().sign_variables(),
            vec![1]
        );
    }

    #[test]
    fn parses_and_evaluates() {
        let v: Vec<String> = ["y", "y_d1", "u"].iter().map(|s| s.to_string()).collect();
        let e = Expr::parse(
            "-0.5*sign(y_d1) + abs(y_d1)*y_d1 - y^3/2 + sqrt(abs(y))",
            &v,
        )
        .unwrap();
        let z = [4.0, -2.0, 1.0];
        assert!((e.eval(&z) - (0.5 - 4.0 - 32.0 + 2.0)).abs() < 1e-12);
        assert_eq!(
            Expr::parse("y^3*y_d1", &v).unwrap().monomial(),
            Some(vec![(0, 3), (1, 1)])
        );
        assert_eq!(Expr::parse("sign(y)", &v).unwrap().monomial(), None);
        assert!(Expr::parse("q+1", &v).is_err());
        assert!(Expr::parse("foo(y)", &v).is_err());
        assert!(Expr::parse("(y", &v).is_err());
        let s = Expr::parse("sign(y_d1)", &v).unwrap();
        assert!(
            (s.eval_smooth(&[0.0, 1e-3, 0.0], &[1.0, 1e-3, 1.0]) - 0.5f64.sqrt()).abs() < 1e-12
        );
    }
}
