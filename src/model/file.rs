//! The model file: reading, writing and validating `ctsid-model/2` (and reading `/1`).
//!
//! See the [module docs](super) for the format.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::compiled::CompiledModel;
use super::expr::Expr;
use crate::basis::Code;
use crate::error::{Error, Result};

/// The format tag this version writes.
pub const FORMAT: &str = "ctsid-model/2";
/// The earlier format, polynomial terms only; still read.
pub const FORMAT_V1: &str = "ctsid-model/1";
/// Top-level sections the tools write for people (settings, training metrics, a discovery's
/// evidence) and that reading keeps as they are; any other unknown key is an error.
pub const SECTIONS: [&str; 2] = ["training", "discovery"];

/// Where a term came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum Origin {
    /// Selected by the sparse regression of `identify`.
    Identified,
    /// Given by the user (a term of the nominal model handed to `discover`).
    Nominal,
    /// Added by `discover`, with the effect's family (`coulomb_friction`, ...).
    Effect(String),
}

/// One term of a right-hand side: `coefficient * monomial` or `coefficient * expression`.
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    /// Variable name -> positive integer exponent; empty for the constant and for expressions.
    pub exponents: BTreeMap<String, u32>,
    /// A named term in the expression language of [`super::expr`] (`sign(y_d1)`,
    /// `abs(y_d1)*y_d1`); `None` for a monomial.
    pub expression: Option<String>,
    pub coefficient: f64,
    /// Standard error of the coefficient, where one was estimated.
    pub std_error: Option<f64>,
    /// A 95 % interval of the coefficient, where one was computed (discover's bootstrap).
    pub interval: Option<[f64; 2]>,
    pub origin: Option<Origin>,
}

// The written shape of a term: a monomial has "exponents" (empty for the constant), an
// expression has "expression" and no exponents.
#[derive(Serialize)]
struct TermOut<'a> {
    #[serde(skip_serializing_if = "Option::is_none")]
    exponents: Option<&'a BTreeMap<String, u32>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    expression: Option<&'a str>,
    coefficient: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    std_error: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    interval: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    origin: Option<&'a Origin>,
}

impl Serialize for Term {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        TermOut {
            exponents: self.expression.is_none().then_some(&self.exponents),
            expression: self.expression.as_deref(),
            coefficient: self.coefficient,
            std_error: self.std_error,
            interval: self.interval,
            origin: self.origin.as_ref(),
        }
        .serialize(s)
    }
}

impl Term {
    /// A monomial term; zero exponents are left out, and a name given twice keeps its last
    /// exponent.
    pub fn new(exponents: &[(&str, u32)], coefficient: f64) -> Term {
        Term::monomial_term(
            exponents
                .iter()
                .filter(|(_, e)| *e > 0)
                .map(|(n, e)| (n.to_string(), *e))
                .collect(),
            coefficient,
        )
    }

    fn monomial_term(exponents: BTreeMap<String, u32>, coefficient: f64) -> Term {
        Term {
            exponents,
            expression: None,
            coefficient,
            std_error: None,
            interval: None,
            origin: None,
        }
    }

    /// A named term `coefficient * expression`.
    pub fn expression(text: &str, coefficient: f64) -> Term {
        Term {
            expression: Some(text.trim().to_string()),
            ..Term::monomial_term(BTreeMap::new(), coefficient)
        }
    }

    /// The same term with its origin.
    pub fn with_origin(mut self, origin: Origin) -> Term {
        self.origin = Some(origin);
        self
    }

    /// The term of a basis monomial `code` over the variables `names` (the regression's features).
    /// Panics when a variable of `code` is not below `names.len()`.
    pub fn from_code(code: Code, names: &[String], coefficient: f64) -> Term {
        let exps = code.exponents(names.len());
        Term::monomial_term(
            exps.iter()
                .enumerate()
                .filter(|(_, &e)| e > 0)
                .map(|(v, &e)| (names[v].clone(), e))
                .collect(),
            coefficient,
        )
    }

    /// Total degree of a monomial (0 for an expression).
    pub fn degree(&self) -> u32 {
        self.exponents
            .values()
            .fold(0u32, |a, &e| a.saturating_add(e))
    }

    /// Whether the term is a monomial (not an expression).
    pub fn is_monomial(&self) -> bool {
        self.expression.is_none()
    }

    /// Human-readable factor: the monomial `y*y_d1^2*u` (or `1`), or the expression as written.
    pub fn monomial(&self) -> String {
        if let Some(e) = &self.expression {
            return e.clone();
        }
        if self.exponents.is_empty() {
            return "1".into();
        }
        self.exponents
            .iter()
            .map(|(n, &e)| {
                if e == 1 {
                    n.clone()
                } else {
                    format!("{n}^{e}")
                }
            })
            .collect::<Vec<_>>()
            .join("*")
    }
}

/// The equation of one output: `name^(order) = sum of terms`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutputEquation {
    pub name: String,
    pub order: usize,
    pub terms: Vec<Term>,
    /// Hard limits of the output's level (an overflowing tank, an end stop); none by default.
    #[serde(skip_serializing_if = "Limits::is_none")]
    pub limits: Limits,
}

/// Hard limits of an output's level: where a simulation would carry the output beyond one, the
/// output stays on it and its derivatives that point beyond it are zero, as a tank that
/// overflows keeps its level and a carriage against an end stop its position (what the record
/// shows as its output held at one extreme value). The equation holds inside the limits.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
}

impl Limits {
    /// No limit on either side.
    pub fn is_none(&self) -> bool {
        self.min.is_none() && self.max.is_none()
    }

    /// `at least 0 and at most 10` for people; `None` without limits.
    pub fn text(&self) -> Option<String> {
        let sides: Vec<String> = [("at least", self.min), ("at most", self.max)]
            .into_iter()
            .filter_map(|(side, v)| v.map(|v| format!("{side} {v}")))
            .collect();
        (!sides.is_empty()).then(|| sides.join(" and "))
    }

    /// Finite bounds, the lower below the upper; the message says what is wrong.
    fn check(&self) -> std::result::Result<(), String> {
        for (side, v) in [("min", self.min), ("max", self.max)] {
            if v.is_some_and(|v| !v.is_finite()) {
                return Err(format!("limits: {side} is not a finite number"));
            }
        }
        if let (Some(lo), Some(hi)) = (self.min, self.max) {
            if lo >= hi {
                return Err(format!(
                    "limits: min {lo} is not below max {hi}; give a range the output can move in"
                ));
            }
        }
        Ok(())
    }
}

impl OutputEquation {
    pub fn new(name: &str, order: usize, terms: Vec<Term>) -> OutputEquation {
        OutputEquation {
            name: name.into(),
            order,
            terms,
            limits: Limits::default(),
        }
    }

    /// The equation from basis codes and coefficients over the feature names `names`; zero
    /// coefficients are dropped. Panics when a kept code has a variable not below `names.len()`.
    pub fn from_codes(
        name: &str,
        order: usize,
        terms: &[(Code, f64)],
        names: &[String],
    ) -> OutputEquation {
        let terms = terms
            .iter()
            .filter(|(_, c)| *c != 0.0)
            .map(|&(code, c)| Term::from_code(code, names, c))
            .collect();
        OutputEquation::new(name, order, terms)
    }

    /// `y''' = 2*y + -0.5*u` style text.
    pub fn to_text(&self) -> String {
        let lhs = if self.order == 0 {
            self.name.clone()
        } else {
            derivative_name(&self.name, self.order)
        };
        let rhs: Vec<String> = self
            .terms
            .iter()
            .map(|t| {
                if t.expression.is_some() {
                    format!("{:+e}*({})", t.coefficient, t.monomial())
                } else {
                    format!("{:+e}*{}", t.coefficient, t.monomial())
                }
            })
            .collect();
        format!(
            "{lhs} = {}",
            if rhs.is_empty() {
                "0".into()
            } else {
                rhs.join(" ")
            }
        )
    }
}

/// A continuous-time model (the content of a `ctsid-model/2` file).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Model {
    pub format: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tau: Option<f64>,
    pub degree: usize,
    pub inputs: Vec<String>,
    /// Smoothing width of `sign(x)` (as `x / sqrt(x^2 + w^2)`) per variable its argument
    /// starts with; a variable not listed gets the exact sign.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub sign_smoothing: BTreeMap<String, f64>,
    /// How the sampled inputs are read between their samples when the model is simulated on a
    /// record; part of the model, since its input coefficients were fitted through it.
    #[serde(skip_serializing_if = "Interpolation::is_linear")]
    pub input_interpolation: Interpolation,
    pub outputs: Vec<OutputEquation>,
    /// The sections of [`SECTIONS`], kept verbatim.
    #[serde(flatten, skip_serializing_if = "Map::is_empty")]
    pub extra: Map<String, Value>,
}

/// How a sampled input is reconstructed between its samples.
///
/// `linear` (straight lines, the default) suits any record; `cubic` (the natural cubic spline
/// through the samples) suits band-limited inputs such as multisines and filtered noise, whose
/// peaks straight lines cut off when the sampling is only a few times the input's bandwidth;
/// `hold` (each sample held until the next, a zero-order hold) is what a digital controller or
/// a generator without a reconstruction filter applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    #[default]
    Linear,
    Cubic,
    Hold,
}

impl Interpolation {
    /// Every reconstruction, in the order the names are listed in messages.
    pub const ALL: [Interpolation; 3] = [
        Interpolation::Linear,
        Interpolation::Cubic,
        Interpolation::Hold,
    ];

    /// The name used in model files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Interpolation::Linear => "linear",
            Interpolation::Cubic => "cubic",
            Interpolation::Hold => "hold",
        }
    }

    fn is_linear(&self) -> bool {
        *self == Interpolation::Linear
    }
}

impl std::str::FromStr for Interpolation {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Interpolation::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or_else(|| {
                format!("unknown input interpolation '{s}' (known: linear, cubic, hold)")
            })
    }
}

/// `y_d0` is another name of output `y` itself: the one name of a variable, so that monomials
/// written either way compare equal.
fn canonical_var<'a>(name: &'a str, outputs: &[String]) -> &'a str {
    match name.strip_suffix("_d0") {
        Some(base) if outputs.iter().any(|o| o == base) => base,
        _ => name,
    }
}

/// Name of the k-th derivative of output `y`: `y` for k = 0, else `y_dk`.
pub fn derivative_name(output: &str, k: usize) -> String {
    if k == 0 {
        output.to_string()
    } else {
        format!("{output}_d{k}")
    }
}

/// The inverse of [`derivative_name`] for derivatives 1 and up: `("y", 2)` for `y_d2` (and
/// `y_d0`); `None` for a name without a `_d` and digits at its end.
pub fn derivative_of(name: &str) -> Option<(&str, usize)> {
    let (base, k) = name.rsplit_once("_d")?;
    if k.is_empty() || !k.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((base, k.parse().ok()?))
}

/// Where a variable lives: in the state vector or the input vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Var {
    /// Index into the state vector.
    State(usize),
    /// Index into the input vector.
    Input(usize),
}

// The raw shape of a file: exponents are read as JSON values so that a negative or fractional one
// gets a message naming the term rather than serde's generic "invalid type"; unknown keys are
// collected (`extra`) so that the error names the output and the term they sit in.
#[derive(Deserialize)]
struct RawModel {
    format: Option<Value>,
    tau: Option<f64>,
    degree: Option<usize>,
    inputs: Vec<String>,
    /// Read as pairs: a name given twice is an error, not the last width silently kept.
    #[serde(default)]
    sign_smoothing: Pairs,
    #[serde(default)]
    input_interpolation: Interpolation,
    outputs: Vec<RawOutput>,
    #[serde(flatten)]
    extra: Map<String, Value>,
}

#[derive(Deserialize)]
struct RawOutput {
    name: String,
    order: usize,
    // Required: a misspelt key would otherwise leave an equation without terms.
    terms: Option<Vec<RawTerm>>,
    #[serde(default)]
    limits: Limits,
    #[serde(flatten)]
    extra: Map<String, Value>,
}

#[derive(Deserialize)]
struct RawTerm {
    exponents: Option<Pairs>,
    expression: Option<String>,
    coefficient: f64,
    std_error: Option<f64>,
    // A list, checked for its two numbers by `read_term`: as `[f64; 2]` a third number was
    // reported as serde's "trailing characters".
    interval: Option<Vec<f64>>,
    origin: Option<Origin>,
    #[serde(flatten)]
    extra: Map<String, Value>,
}

const TERM_KEYS: &str = "exponents, expression, coefficient, std_error, interval, origin";

/// A JSON object read as its key-value pairs in file order, duplicates kept (a `Map` keeps only
/// the last of two equal keys, and `{"y": 1, "y": 2}` is a typo worth naming).
#[derive(Default)]
struct Pairs(Vec<(String, Value)>);

impl<'de> Deserialize<'de> for Pairs {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Pairs, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Pairs;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object of variable names and numbers ({\"y\": 2})")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut m: A,
            ) -> std::result::Result<Pairs, A::Error> {
                let mut v = Vec::new();
                while let Some(pair) = m.next_entry::<String, Value>()? {
                    v.push(pair);
                }
                Ok(Pairs(v))
            }
        }
        d.deserialize_map(V)
    }
}

/// Largest exponent of one variable in a term: powers are evaluated with `powi(i32)`, and degrees
/// are summed in `u32`; no identified model comes near it.
pub const MAX_EXPONENT: u32 = 64;

/// Largest model file read: a model of 100,000 terms takes about 10 MB; anything far larger is
/// not a model file (or a device that never ends).
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Highest derivative order a model file may give an output (that of the derivative estimates).
pub const MAX_ORDER: usize = crate::derivatives::MAX_ORDER;

/// Two terms with one monomial (or one expression) add up, but a file that says so is almost
/// surely a slip (and a million copies would only slow every evaluation). An expression that is
/// a monomial up to a constant factor (`y`, `2*y^2`, `1`) is that monomial's column: beside it
/// the coefficients are not determined (`show` printed `-2*y + 0.5*y`). `names` are the model's
/// variables ([`Model::variable_names`]).
fn check_distinct_terms(
    o: &OutputEquation,
    all: &[OutputEquation],
    names: &[String],
) -> std::result::Result<(), String> {
    let outputs: Vec<String> = all.iter().map(|o| o.name.clone()).collect();
    let mut seen: std::collections::HashMap<(BTreeMap<&str, u32>, String), usize> =
        Default::default();
    for (k, t) in o.terms.iter().enumerate() {
        // The key: the monomial's exponents, with the expression's text (without spaces) for
        // an expression that is no monomial.
        let of_expression = t.expression.as_deref().map(|e| {
            let powers = Expr::parse(e, names)
                .ok()
                .and_then(|x| x.monomial_up_to_scale());
            match powers {
                Some(p) => (
                    p.into_iter()
                        .map(|(v, p)| (canonical_var(&names[v], &outputs), p))
                        .collect(),
                    String::new(),
                ),
                None => (BTreeMap::new(), e.split_whitespace().collect()),
            }
        });
        let (mono, expr) = of_expression.unwrap_or_else(|| {
            let mono = t
                .exponents
                .iter()
                .map(|(v, &e)| (canonical_var(v, &outputs), e))
                .collect();
            (mono, String::new())
        });
        if let Some(first) = seen.insert((mono, expr), k) {
            // Named as written: "terms 1 and 2 are both 2*y" read wrong where term 1 is `y`.
            let (a, b) = (o.terms[first].monomial(), t.monomial());
            let same = if a == b {
                format!("are both {b}")
            } else {
                format!("({a} and {b}) are one column up to a constant factor")
            };
            return Err(format!(
                "output '{}': terms {} and {} {same}; combine them into one",
                o.name,
                first + 1,
                k + 1,
            ));
        }
    }
    Ok(())
}

/// Largest monomial degree of the terms.
fn largest_degree(outputs: &[OutputEquation]) -> usize {
    outputs
        .iter()
        .flat_map(|o| o.terms.iter().map(|t| t.degree() as usize))
        .max()
        .unwrap_or(0)
}

/// One output of a file; the error message names it (and the term at fault).
fn read_output(
    o: RawOutput,
    output_names: &[String],
    v1: bool,
    zeros: &mut Vec<(usize, usize, String)>,
) -> std::result::Result<OutputEquation, String> {
    if let Some(k) = o.extra.keys().next() {
        let hint = if o.terms.is_none() {
            " and no \"terms\" list"
        } else {
            ""
        };
        return Err(format!(
            "output '{}': unknown key \"{k}\"{hint} (known: name, order, terms, limits)",
            o.name
        ));
    }
    let Some(raw_terms) = o.terms else {
        return Err(format!("output '{}' has no \"terms\" list", o.name));
    };
    if v1 && !o.limits.is_none() {
        return Err(format!(
            "output '{}': limits need \"format\": \"{FORMAT}\"",
            o.name
        ));
    }
    let index = output_names.iter().position(|n| *n == o.name).unwrap_or(0);
    let terms = raw_terms
        .into_iter()
        .enumerate()
        .map(|(k, t)| {
            let (term, zero) = read_term(t, output_names, v1)
                .map_err(|m| format!("output '{}', term {}: {m}", o.name, k + 1))?;
            zeros.extend(zero.into_iter().map(|n| (index, k, n)));
            Ok(term)
        })
        .collect::<std::result::Result<Vec<_>, String>>()?;
    Ok(OutputEquation {
        name: o.name,
        order: o.order,
        terms,
        limits: o.limits,
    })
}

/// One term of a file and the names it gives exponent 0; the message says what is wrong with it
/// (the caller names it).
fn read_term(
    t: RawTerm,
    output_names: &[String],
    v1: bool,
) -> std::result::Result<(Term, Vec<String>), String> {
    if let Some(k) = t.extra.keys().next() {
        return Err(format!("unknown key \"{k}\" (known: {TERM_KEYS})"));
    }
    if v1
        && (t.expression.is_some()
            || t.std_error.is_some()
            || t.interval.is_some()
            || t.origin.is_some())
    {
        return Err(format!(
            "expressions, standard errors, intervals and origins need \"format\": \"{FORMAT}\""
        ));
    }
    let interval = match t.interval.as_deref() {
        None => None,
        Some(&[lo, hi]) => Some([lo, hi]),
        Some(v) => {
            return Err(format!(
                "interval has {} numbers; give [low, high]",
                v.len()
            ))
        }
    };
    let mut term = Term {
        std_error: t.std_error,
        interval,
        origin: t.origin,
        ..Term::monomial_term(BTreeMap::new(), t.coefficient)
    };
    match (t.exponents, t.expression) {
        (Some(_), Some(_)) => {
            Err("both \"exponents\" and \"expression\": a term is a monomial or an expression, not both".to_string())
        }
        (None, Some(e)) => {
            term.expression = Some(e.trim().to_string());
            Ok((term, Vec::new()))
        }
        // A term of a coefficient alone read as the constant (`show` printed `y_d1 = -2 + 3*u` for
        // a term that had lost its exponents): the constant says `"exponents": {}`.
        (None, None) => Err(
            "neither \"exponents\" nor \"expression\": give a monomial's exponents ({} for the constant) or an expression".to_string(),
        ),
        (Some(pairs), None) => {
            let (exponents, zeros) = read_exponents(pairs, output_names)?;
            term.exponents = exponents;
            Ok((term, zeros))
        }
    }
}

/// A monomial's exponents under their canonical names, and the names given exponent 0 (left
/// out of the term); duplicates and non-integers are errors.
fn read_exponents(
    pairs: Pairs,
    output_names: &[String],
) -> std::result::Result<(BTreeMap<String, u32>, Vec<String>), String> {
    let pairs: Vec<(String, Value)> = pairs
        .0
        .into_iter()
        .map(|(n, v)| (canonical_var(&n, output_names).to_string(), v))
        .collect();
    let mut exponents = BTreeMap::new();
    let mut zeros = Vec::new();
    // Names seen so far (zero exponents included), in a set: a term of tens of thousands of
    // pairs was checked pair against pair, seconds per megabyte of file.
    let mut seen = std::collections::HashSet::with_capacity(pairs.len());
    for (name, v) in &pairs {
        if !seen.insert(name.as_str()) {
            let note = if output_names.contains(name) {
                format!(" ({name}_d0 is {name})")
            } else {
                String::new()
            };
            return Err(format!("'{name}' appears twice in the exponents{note}"));
        }
        // The range is validate_at's; here only what a u32 can hold.
        let e = v
            .as_u64()
            .and_then(|e| u32::try_from(e).ok())
            .ok_or_else(|| {
                format!(
                    "exponent of '{name}' is {v}; exponents must be integers in 0..={MAX_EXPONENT}"
                )
            })?;
        if e > 0 {
            exponents.insert(name.clone(), e);
        } else {
            zeros.push(name.clone());
        }
    }
    Ok((exponents, zeros))
}

/// The `sign_smoothing` widths by variable; a name given twice or a width that is not a number
/// is an error (the widths' range is `validate_at`'s).
fn read_sign_smoothing(pairs: Pairs) -> std::result::Result<BTreeMap<String, f64>, String> {
    let mut out = BTreeMap::new();
    for (name, v) in pairs.0 {
        let w = v
            .as_f64()
            .ok_or_else(|| format!("sign_smoothing of '{name}' is {v}; give a number"))?;
        if out.insert(name.clone(), w).is_some() {
            return Err(format!(
                "sign_smoothing names '{name}' twice; give one width"
            ));
        }
    }
    Ok(out)
}

impl Model {
    /// A model with the given outputs; `degree` is the largest term degree.
    pub fn new(inputs: &[&str], outputs: Vec<OutputEquation>, tau: Option<f64>) -> Model {
        Model {
            format: FORMAT.into(),
            tau,
            degree: largest_degree(&outputs),
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            sign_smoothing: BTreeMap::new(),
            input_interpolation: Interpolation::Linear,
            outputs,
            extra: Map::new(),
        }
    }

    /// Parses and validates a model from JSON text; `path` only labels the error messages. Refuses
    /// text that is not JSON or not an object, a missing or unknown `format` (other than [`FORMAT`]
    /// and [`FORMAT_V1`]), an unknown key at any level, a missing or mistyped field, an output
    /// without a `terms` list, a term with both `exponents` and `expression` or neither, an exponent named
    /// twice or not a non-negative integer, expressions, standard errors, intervals or origins in
    /// a `/1` file, and all that [`Model::validate`] refuses.
    ///
    /// ```
    /// use ctsid::Model;
    /// let text = r#"{"format": "ctsid-model/2", "inputs": ["u"], "outputs": [{"name": "y",
    ///   "order": 1, "terms": [{"exponents": {"y": 1}, "coefficient": -2},
    ///                         {"exponents": {"u": 1}, "coefficient": 3}]}]}"#;
    /// let model = Model::from_json_str(text, "lag.json")?;
    /// assert_eq!(model.to_string().trim(), "y_d1 = -2*y + 3*u");
    /// // The compiled right-hand side: y' at y = 1, u = 1.
    /// let mut dx = [0.0];
    /// model.compile()?.rhs(&[1.0], &[1.0], &mut dx)?;
    /// assert_eq!(dx[0], 1.0);
    /// // Misspelt keys are refused, not read as defaults.
    /// assert!(Model::from_json_str(&text.replace("exponents", "exponent"), "bad.json").is_err());
    /// // Written whole (to a temporary file, then renamed) and read back the same.
    /// let path = std::env::temp_dir().join("ctsid-doc-lag.json");
    /// model.write(path.to_str().unwrap())?;
    /// assert_eq!(Model::read(path.to_str().unwrap())?.to_string(), model.to_string());
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn from_json_str(text: &str, path: &str) -> Result<Model> {
        let err = |message: String| Error::Model {
            path: path.into(),
            message,
        };
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // The format first: another JSON file (a regression result, say) is named as such
        // rather than by its first missing field.
        let value: Value =
            serde_json::from_str(text).map_err(|e| err(format!("not valid JSON: {e}")))?;
        if !value.is_object() {
            return Err(err(format!(
                "not a model file (a JSON object with \"format\": \"{FORMAT}\")"
            )));
        }
        if value.get("format").is_none() {
            return Err(err(format!(
                "no \"format\" field: not a {FORMAT} file (identify and discover write those)"
            )));
        }
        let raw: RawModel =
            serde_json::from_str(text).map_err(|e| err(format!("not a valid model file: {e}")))?;
        let format = match raw.format {
            Some(Value::String(s)) => s,
            Some(v) => return Err(err(format!("unknown format {v}; expected \"{FORMAT}\""))),
            None => {
                return Err(err(format!(
                    "no \"format\" field; expected \"format\": \"{FORMAT}\""
                )))
            }
        };
        if format != FORMAT && format != FORMAT_V1 {
            return Err(err(format!(
                "unknown format \"{format}\"; this version reads \"{FORMAT}\" and \"{FORMAT_V1}\""
            )));
        }
        if let Some(k) = raw.extra.keys().find(|k| !SECTIONS.contains(&k.as_str())) {
            return Err(err(format!(
                "unknown key \"{k}\" at the top level (known: format, tau, degree, inputs, sign_smoothing, input_interpolation, outputs, {})",
                SECTIONS.join(", ")
            )));
        }
        // Stored under the canonical name, so that expressions know it.
        let output_names: Vec<String> = raw.outputs.iter().map(|o| o.name.clone()).collect();
        let mut zeros = Vec::new();
        let outputs = raw
            .outputs
            .into_iter()
            .map(|o| read_output(o, &output_names, format == FORMAT_V1, &mut zeros).map_err(err))
            .collect::<Result<Vec<_>>>()?;
        let degree = raw.degree.unwrap_or_else(|| largest_degree(&outputs));
        // Whatever version was read, the model is now of the version this one writes.
        let model = Model {
            format: FORMAT.into(),
            tau: raw.tau,
            degree,
            inputs: raw.inputs,
            sign_smoothing: read_sign_smoothing(raw.sign_smoothing).map_err(err)?,
            input_interpolation: raw.input_interpolation,
            outputs,
            extra: raw.extra,
        };
        model.validate_at(path)?;
        model.check_zero_exponents(&zeros).map_err(err)?;
        Ok(model)
    }

    /// Names read with exponent 0 (`(output, term index, name)`) are dropped from their terms,
    /// but a name that is no variable of the model is a typo worth naming, as it would be with
    /// any other exponent.
    fn check_zero_exponents(
        &self,
        zeros: &[(usize, usize, String)],
    ) -> std::result::Result<(), String> {
        if zeros.is_empty() {
            return Ok(());
        }
        let table = self.variable_table()?;
        match zeros.iter().find(|(_, _, n)| !table.contains_key(n)) {
            Some((o, k, name)) => Err(format!(
                "output '{}', term {}: {} (with exponent 0)",
                self.outputs[*o].name,
                k + 1,
                self.explain_unknown(name)
            )),
            None => Ok(()),
        }
    }

    /// Reads and validates a model file. Refuses a path that is not a regular file of at most 256
    /// MiB or is not UTF-8 text, and all that [`Model::from_json_str`] refuses.
    pub fn read(path: impl AsRef<std::path::Path>) -> Result<Model> {
        use std::io::Read;
        // Opened through the path itself (a name that is not UTF-8 is still the user's file);
        // the messages show it as text.
        let path = path.as_ref();
        let shown = path.display().to_string();
        let io = |e: std::io::Error| Error::file(&shown, e);
        let mut text = String::new();
        crate::util::open_regular(path, Some(MAX_FILE_BYTES))?
            .read_to_string(&mut text)
            .map_err(io)?;
        Model::from_json_str(&text, &shown)
    }

    /// Pretty JSON text (validated first: a model that could not be read back is not written).
    /// Refuses a model that [`Model::validate`] refuses.
    pub fn to_json_string(&self) -> Result<String> {
        self.validate()?;
        serde_json::to_string_pretty(self).map_err(|e| Error::Model {
            path: "<memory>".into(),
            message: e.to_string(),
        })
    }

    /// Writes the model file. Refuses a model that [`Model::validate`] refuses, and errors as
    /// [`crate::util::write_atomic`] does.
    pub fn write(&self, path: impl AsRef<std::path::Path>) -> Result<()> {
        let text = self.to_json_string()?;
        crate::util::write_atomic(path.as_ref(), (text + "\n").as_bytes())
    }

    /// Checks names, orders, exponents and coefficients; the error names the term at fault. Refuses
    /// a format other than [`FORMAT`], a tau that [`crate::records::check_tau`] refuses, an unknown
    /// section, no outputs, an order of 0 or above [`MAX_ORDER`], an empty name or a variable name
    /// used twice, two equal terms in one output (an expression that is a monomial up to a factor
    /// counts as that monomial), a coefficient that is not finite, a `std_error`
    /// that is negative or not finite, an `interval` that is not a finite [low, high], a term with
    /// both exponents and an expression, an expression that does not parse or has a part that is
    /// not finite whatever the state is (`0/0`, `y/0`, `exp(800)`), an exponent above
    /// [`MAX_EXPONENT`], an unknown variable, a term above the model's degree, and a
    /// `sign_smoothing` width of an unknown variable or one that is not finite and positive or
    /// whose cube is not a normal number.
    pub fn validate(&self) -> Result<()> {
        self.validate_at("<memory>")
    }

    fn validate_at(&self, path: &str) -> Result<()> {
        let err = |message: String| Error::Model {
            path: path.into(),
            message,
        };
        self.validate_header().map_err(err)?;
        let table = self.variable_table().map_err(err)?;
        let names = self.variable_names();
        for o in &self.outputs {
            check_distinct_terms(o, &self.outputs, &names).map_err(err)?;
            o.limits
                .check()
                .map_err(|m| err(format!("output '{}': {m}", o.name)))?;
            for (k, t) in o.terms.iter().enumerate() {
                self.check_term(t, &table, &names)
                    .map_err(|m| err(format!("output '{}', term {}: {m}", o.name, k + 1)))?;
            }
        }
        let known: std::collections::HashSet<&str> = names.iter().map(String::as_str).collect();
        for (name, w) in &self.sign_smoothing {
            if !known.contains(name.as_str()) {
                return Err(err(format!(
                    "sign_smoothing: {}",
                    self.explain_unknown(name)
                )));
            }
            if !(w.is_finite() && *w > 0.0) {
                return Err(err(format!(
                    "sign_smoothing of '{name}' is {w}; give a positive width (or leave the variable out for the exact sign)"
                )));
            }
            // The smoothed sign is x / sqrt(x^2 + w^2) and its slope w^2 / (x^2 + w^2)^1.5: a
            // cube that underflows makes the slope infinite at x = 0 (a square that does, the
            // sign 0/0), one that overflows makes them 0 everywhere.
            if !(w * w * w).is_normal() {
                return Err(err(format!(
                    "sign_smoothing of '{name}' is {w}; give a width between 1e-100 and 1e100"
                )));
            }
        }
        Ok(())
    }

    /// Format, tau, sections, and the outputs' orders.
    fn validate_header(&self) -> std::result::Result<(), String> {
        if self.format != FORMAT {
            return Err(format!(
                "unknown format \"{}\"; this version writes \"{FORMAT}\"",
                self.format
            ));
        }
        if let Some(tau) = self.tau {
            crate::records::check_tau(tau).map_err(|e| e.to_string())?;
        }
        if let Some(k) = self.extra.keys().find(|k| !SECTIONS.contains(&k.as_str())) {
            return Err(format!(
                "unknown section \"{k}\" (known: {})",
                SECTIONS.join(", ")
            ));
        }
        if self.outputs.is_empty() {
            return Err("no outputs".into());
        }
        for o in &self.outputs {
            if o.order == 0 {
                return Err(format!(
                    "output '{}' has order 0; orders start at 1",
                    o.name
                ));
            }
            if o.order > MAX_ORDER {
                return Err(format!(
                    "output '{}' has order {}; orders go up to {MAX_ORDER}",
                    o.name, o.order
                ));
            }
        }
        Ok(())
    }

    /// One term's coefficient, uncertainty, and its monomial or expression.
    fn check_term(
        &self,
        t: &Term,
        table: &BTreeMap<String, Var>,
        names: &[String],
    ) -> std::result::Result<(), String> {
        if !t.coefficient.is_finite() {
            return Err(format!("coefficient {} is not finite", t.coefficient));
        }
        if let Some(s) = t.std_error {
            if !(s.is_finite() && s >= 0.0) {
                return Err(format!("std_error {s} is not a finite number >= 0"));
            }
        }
        if let Some([a, b]) = t.interval {
            if !(a.is_finite() && b.is_finite() && a <= b) {
                return Err(format!("interval [{a}, {b}] is not a finite [low, high]"));
            }
        }
        if let Some(e) = &t.expression {
            if !t.exponents.is_empty() {
                return Err("both exponents and an expression: a term is one or the other".into());
            }
            // The parser's message names the unknown variable or function.
            let parsed = Expr::parse(e, names).map_err(|e| e.to_string())?;
            return match parsed.constant_fault() {
                Some(why) => Err(format!(
                    "expression '{e}' has a part that is not finite whatever the state is ({why})"
                )),
                None => Ok(()),
            };
        }
        if let Some((name, e)) = t.exponents.iter().find(|(_, &e)| e > MAX_EXPONENT) {
            return Err(format!(
                "exponent of '{name}' is {e}; exponents go up to {MAX_EXPONENT}"
            ));
        }
        if let Some(name) = t.exponents.keys().find(|n| !table.contains_key(*n)) {
            return Err(self.explain_unknown(name));
        }
        if t.degree() as usize > self.degree {
            return Err(format!(
                "degree {} is above the model's degree {}",
                t.degree(),
                self.degree
            ));
        }
        Ok(())
    }

    // Every accepted variable name (with the `_d0` aliases) -> its place.
    pub(super) fn variable_table(&self) -> std::result::Result<BTreeMap<String, Var>, String> {
        let mut table = BTreeMap::new();
        let put = |name: String, var: Var, table: &mut BTreeMap<String, Var>| {
            if table.insert(name.clone(), var).is_some() {
                Err(format!("the variable name '{name}' is used twice (outputs, their derivatives and inputs must have distinct names)"))
            } else {
                Ok(())
            }
        };
        let mut off = 0;
        for o in &self.outputs {
            if o.name.is_empty() {
                return Err("an output has an empty name".into());
            }
            for k in 0..o.order {
                put(derivative_name(&o.name, k), Var::State(off + k), &mut table)?;
            }
            put(format!("{}_d0", o.name), Var::State(off), &mut table)?;
            off += o.order;
        }
        for (i, u) in self.inputs.iter().enumerate() {
            if u.is_empty() {
                return Err("an input has an empty name".into());
            }
            put(u.clone(), Var::Input(i), &mut table)?;
        }
        // Each output's left-hand side (its derivative of its order) is a name too: an input
        // `y_d1` beside `y` of order 1 read `y_d1 = -2*y + 3*y_d1`, one name for two things.
        for o in &self.outputs {
            let lhs = derivative_name(&o.name, o.order);
            if table.contains_key(&lhs) {
                return Err(format!("the variable name '{lhs}' is used twice: it is the left-hand side of output '{}' of order {} (outputs, their derivatives and inputs must have distinct names)", o.name, o.order));
            }
        }
        // A line break or another control character in a name splits the printed equations
        // and the written tables' lines.
        let names = self.outputs.iter().map(|o| &o.name).chain(&self.inputs);
        if let Some(n) = names.into_iter().find(|n| n.chars().any(char::is_control)) {
            return Err(format!(
                "the name {:?} holds a control character (a line break, a tab); rename it",
                crate::util::clip(n, 40)
            ));
        }
        // A name that reads as a number cannot be told from a constant (an input `2` showed as
        // `3*2` and a term `{"expression": "2"}` read the number, not the input), and `nan`
        // printed as `0.12*nan` reads as a broken coefficient. (Names the expression parser
        // cannot read as one name, refused by identify, still load: files written before.)
        let names = self.outputs.iter().map(|o| &o.name).chain(&self.inputs);
        for n in names {
            if let Some(why) = crate::util::name_fault(n) {
                return Err(format!(
                    "the name '{}' {why}; rename it",
                    crate::util::clip(n, 40)
                ));
            }
        }
        Ok(table)
    }

    fn explain_unknown(&self, name: &str) -> String {
        if let Some((base, k)) = derivative_of(name) {
            if let Some(o) = self.outputs.iter().find(|o| o.name == base) {
                return format!(
                    "'{name}' is derivative {k} of output '{base}' of order {}; right-hand sides may use {base}..{}",
                    o.order,
                    derivative_name(base, o.order - 1)
                );
            }
        }
        format!(
            "unknown variable '{name}' (known: {})",
            self.variable_names().join(", ")
        )
    }

    /// Names of the state variables in layout order, then the inputs: the feature names `z`.
    pub fn variable_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .outputs
            .iter()
            .flat_map(|o| (0..o.order).map(move |k| derivative_name(&o.name, k)))
            .collect();
        v.extend(self.inputs.iter().cloned());
        v
    }

    /// Number of states, sum of the orders.
    pub fn state_dim(&self) -> usize {
        self.outputs.iter().map(|o| o.order).sum()
    }

    /// Offset of output `i`'s derivative 0 in the state vector. Panics when `i` is greater than
    /// the number of outputs (`i` equal to it gives [`Model::state_dim`]).
    pub fn state_offset(&self, i: usize) -> usize {
        self.outputs[..i].iter().map(|o| o.order).sum()
    }

    /// Compiles the (validated) model into an evaluator. Refuses a model that [`Model::validate`]
    /// refuses.
    pub fn compile(&self) -> Result<CompiledModel> {
        self.validate()?;
        CompiledModel::new(self)
    }
}

impl std::fmt::Display for OutputEquation {
    /// `q_d2 = -2.13992*q_d1 + 0.0105145*force - 0.210733*sign(q_d1)`: coefficients to six
    /// significant digits, each term once.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} =", derivative_name(&self.name, self.order))?;
        if self.terms.is_empty() {
            return write!(f, " 0");
        }
        for (i, t) in self.terms.iter().enumerate() {
            let c = crate::regression::format_coefficient(t.coefficient.abs());
            let sign = match (t.coefficient < 0.0, i) {
                (true, 0) => "-",
                (true, _) => " - ",
                (false, 0) => "",
                (false, _) => " + ",
            };
            let body = match (t.is_monomial(), t.exponents.is_empty()) {
                (true, true) => c,
                (true, false) => format!("{c}*{}", t.monomial()),
                (false, _) => {
                    let e = t.monomial();
                    // Parenthesised where a sum or a leading sign would change its reading.
                    if e.contains(['+', '-']) {
                        format!("{c}*({e})")
                    } else {
                        format!("{c}*{e}")
                    }
                }
            };
            write!(f, "{}{sign}{body}", if i == 0 { " " } else { "" })?;
        }
        Ok(())
    }
}

impl std::fmt::Display for Model {
    /// One line per output equation (see [`OutputEquation`]'s `Display`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, o) in self.outputs.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{o}")?;
        }
        Ok(())
    }
}
