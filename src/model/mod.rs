//! The model file `ctsid-model/1`: a continuous-time polynomial model a person can read and write.
//!
//! ```json
//! {"format": "ctsid-model/1", "tau": 0.003, "degree": 3, "inputs": ["u"],
//!  "outputs": [{"name": "y", "order": 3,
//!               "terms": [{"exponents": {"y": 1, "y_d1": 2, "u": 1}, "coefficient": 1.5},
//!                         {"exponents": {}, "coefficient": 37664.0}]}]}
//! ```
//!
//! Each output `y` of order `n` obeys `y^(n) = sum_k c_k * prod_v v^e_kv`, where the variables are
//! the derivatives `y_dk` (`y` itself, or `y_d0`, is order 0) of every output, below that output's
//! own order, and the inputs by name. The constant term has empty exponents. Coefficients are in
//! the original units of the signals.
//!
//! What this module assumes and guarantees:
//! - `tau` and `degree` may be omitted in a hand-written file (`degree` is then the largest term
//!   degree); fields this version does not know (training metrics, settings) are kept verbatim in
//!   `extra` and written back, at the top level, per output and per term.
//! - [`Model::from_json_str`] / [`Model::read`] validate everything and fail with one line naming the
//!   term and the variable at fault; [`Model::validate`] does the same for models built in code.
//! - [`CompiledModel`] turns a validated model into a fast evaluator of the right-hand sides with a
//!   fixed state layout: for each output in file order its derivatives `0..n_i-1`, concatenated;
//!   the inputs are a separate vector.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::basis::Code;
use crate::error::{Error, Result};

/// The format tag this version reads and writes.
pub const FORMAT: &str = "ctsid-model/1";

/// One monomial of a right-hand side: `coefficient * prod(var^exponent)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Term {
    /// Variable name -> positive integer exponent; empty for the constant.
    pub exponents: BTreeMap<String, u32>,
    pub coefficient: f64,
    /// Fields this version does not interpret (kept for the round trip).
    #[serde(flatten, default, skip_serializing_if = "Map::is_empty")]
    pub extra: Map<String, Value>,
}

impl Term {
    pub fn new(exponents: &[(&str, u32)], coefficient: f64) -> Term {
        Term {
            exponents: exponents
                .iter()
                .filter(|(_, e)| *e > 0)
                .map(|(n, e)| (n.to_string(), *e))
                .collect(),
            coefficient,
            extra: Map::new(),
        }
    }

    /// The term of a basis monomial `code` over the variables `names` (the regression's features).
    pub fn from_code(code: Code, names: &[String], coefficient: f64) -> Term {
        let exps = code.exponents(names.len());
        Term {
            exponents: exps
                .iter()
                .enumerate()
                .filter(|(_, &e)| e > 0)
                .map(|(v, &e)| (names[v].clone(), e))
                .collect(),
            coefficient,
            extra: Map::new(),
        }
    }

    /// Total degree.
    pub fn degree(&self) -> u32 {
        self.exponents
            .values()
            .fold(0u32, |a, &e| a.saturating_add(e))
    }

    /// Human-readable monomial, `y*y_d1^2*u`, or `1`.
    pub fn monomial(&self) -> String {
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputEquation {
    pub name: String,
    pub order: usize,
    pub terms: Vec<Term>,
    #[serde(flatten, default, skip_serializing_if = "Map::is_empty")]
    pub extra: Map<String, Value>,
}

impl OutputEquation {
    pub fn new(name: &str, order: usize, terms: Vec<Term>) -> OutputEquation {
        OutputEquation {
            name: name.into(),
            order,
            terms,
            extra: Map::new(),
        }
    }

    /// The equation from basis codes and coefficients over the feature names `names`; zero
    /// coefficients are dropped.
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
            .map(|t| format!("{:+e}*{}", t.coefficient, t.monomial()))
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

/// A continuous-time polynomial model (the content of a `ctsid-model/1` file).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Model {
    pub format: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tau: Option<f64>,
    pub degree: usize,
    pub inputs: Vec<String>,
    pub outputs: Vec<OutputEquation>,
    #[serde(flatten, skip_serializing_if = "Map::is_empty")]
    pub extra: Map<String, Value>,
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

/// Where a variable lives: in the state vector or the input vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Var {
    /// Index into the state vector.
    State(usize),
    /// Index into the input vector.
    Input(usize),
}

// The raw shape of a file: exponents are read as JSON values so that a negative or fractional one
// gets a message naming the term rather than serde's generic "invalid type".
#[derive(Deserialize)]
struct RawModel {
    format: Option<Value>,
    tau: Option<f64>,
    degree: Option<usize>,
    inputs: Vec<String>,
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
    #[serde(flatten)]
    extra: Map<String, Value>,
}

#[derive(Deserialize)]
struct RawTerm {
    #[serde(default)]
    exponents: Pairs,
    coefficient: f64,
    #[serde(flatten)]
    extra: Map<String, Value>,
}

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
                f.write_str("an object of variable names and exponents")
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

/// Highest derivative order a model file may give an output (that of the derivative estimates).
pub const MAX_ORDER: usize = crate::derivatives::MAX_ORDER;

impl Model {
    /// A model with the given outputs; `degree` is the largest term degree.
    pub fn new(inputs: &[&str], outputs: Vec<OutputEquation>, tau: Option<f64>) -> Model {
        let degree = outputs
            .iter()
            .flat_map(|o| o.terms.iter().map(|t| t.degree() as usize))
            .max()
            .unwrap_or(0);
        Model {
            format: FORMAT.into(),
            tau,
            degree,
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            outputs,
            extra: Map::new(),
        }
    }

    /// Parses and validates a model from JSON text; `path` only labels the error messages.
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
        if format != FORMAT {
            return Err(err(format!(
                "unknown format \"{format}\"; this version reads \"{FORMAT}\""
            )));
        }
        // Stored under the canonical name, so that discover's expressions know it.
        let output_names: Vec<String> = raw.outputs.iter().map(|o| o.name.clone()).collect();
        let canonical = |name: String| canonical_var(&name, &output_names).to_string();
        let mut outputs = Vec::with_capacity(raw.outputs.len());
        for o in raw.outputs {
            let Some(raw_terms) = o.terms else {
                let keys: Vec<&str> = o.extra.keys().map(String::as_str).collect();
                return Err(err(format!(
                    "output '{}' has no \"terms\" list{}",
                    o.name,
                    if keys.is_empty() {
                        String::new()
                    } else {
                        format!(" (fields not understood: {})", keys.join(", "))
                    }
                )));
            };
            let mut terms = Vec::with_capacity(raw_terms.len());
            for (k, t) in raw_terms.into_iter().enumerate() {
                let mut exponents = BTreeMap::new();
                let pairs: Vec<(String, Value)> = t
                    .exponents
                    .0
                    .into_iter()
                    .map(|(n, v)| (canonical(n), v))
                    .collect();
                for (i, (name, _)) in pairs.iter().enumerate() {
                    if pairs[..i].iter().any(|(n, _)| n == name) {
                        let note = if output_names.contains(name) {
                            format!(" ({name}_d0 is {name})")
                        } else {
                            String::new()
                        };
                        return Err(err(format!(
                            "output '{}', term {}: '{name}' appears twice in the exponents{note}",
                            o.name,
                            k + 1
                        )));
                    }
                }
                for (name, v) in pairs {
                    // The range is validate_at's; here only what a u32 can hold.
                    let e = v.as_u64().and_then(|e| u32::try_from(e).ok()).ok_or_else(|| {
                        err(format!(
                            "output '{}', term {}: exponent of '{name}' is {v}; exponents must be integers in 0..={MAX_EXPONENT}",
                            o.name,
                            k + 1
                        ))
                    })?;
                    if e > 0 {
                        exponents.insert(name, e);
                    }
                }
                terms.push(Term {
                    exponents,
                    coefficient: t.coefficient,
                    extra: t.extra,
                });
            }
            outputs.push(OutputEquation {
                name: o.name,
                order: o.order,
                terms,
                extra: o.extra,
            });
        }
        let degree = raw.degree.unwrap_or_else(|| {
            outputs
                .iter()
                .flat_map(|o| o.terms.iter().map(|t| t.degree() as usize))
                .max()
                .unwrap_or(0)
        });
        let model = Model {
            format,
            tau: raw.tau,
            degree,
            inputs: raw.inputs,
            outputs,
            extra: raw.extra,
        };
        model.validate_at(path)?;
        Ok(model)
    }

    /// Reads and validates a model file.
    pub fn read(path: &str) -> Result<Model> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
            path: path.into(),
            message: e.to_string(),
        })?;
        Model::from_json_str(&text, path)
    }

    /// Pretty JSON text (validated first: a model that could not be read back is not written).
    pub fn to_json_string(&self) -> Result<String> {
        self.validate()?;
        serde_json::to_string_pretty(self).map_err(|e| Error::Model {
            path: "<memory>".into(),
            message: e.to_string(),
        })
    }

    /// Writes the model file.
    pub fn write(&self, path: &str) -> Result<()> {
        let text = self.to_json_string()?;
        std::fs::write(path, text + "\n").map_err(|e| Error::Io {
            path: path.into(),
            message: e.to_string(),
        })
    }

    /// Checks names, orders, exponents and coefficients; the error names the term at fault.
    pub fn validate(&self) -> Result<()> {
        self.validate_at("<memory>")
    }

    fn validate_at(&self, path: &str) -> Result<()> {
        let err = |message: String| Error::Model {
            path: path.into(),
            message,
        };
        if self.format != FORMAT {
            return Err(err(format!(
                "unknown format \"{}\"; this version reads \"{FORMAT}\"",
                self.format
            )));
        }
        if let Some(tau) = self.tau {
            crate::records::check_tau(tau).map_err(|e| err(e.to_string()))?;
        }
        if self.outputs.is_empty() {
            return Err(err("no outputs".into()));
        }
        for o in &self.outputs {
            if o.order == 0 {
                return Err(err(format!(
                    "output '{}' has order 0; orders start at 1",
                    o.name
                )));
            }
            if o.order > MAX_ORDER {
                return Err(err(format!(
                    "output '{}' has order {}; orders go up to {MAX_ORDER}",
                    o.name, o.order
                )));
            }
            // Two terms with one monomial add up, but a file that says so is almost surely a
            // slip (and a million copies would only slow every evaluation).
            let outputs: Vec<String> = self.outputs.iter().map(|o| o.name.clone()).collect();
            let mut seen: std::collections::HashMap<BTreeMap<&str, u32>, usize> =
                Default::default();
            for (k, t) in o.terms.iter().enumerate() {
                let mono = t
                    .exponents
                    .iter()
                    .map(|(v, &e)| (canonical_var(v, &outputs), e))
                    .collect();
                if let Some(first) = seen.insert(mono, k) {
                    return Err(err(format!(
                        "output '{}': terms {} and {} have the same monomial {}; combine them into one",
                        o.name,
                        first + 1,
                        k + 1,
                        t.monomial()
                    )));
                }
            }
        }
        let table = self.variable_table().map_err(err)?;
        for o in &self.outputs {
            for (k, t) in o.terms.iter().enumerate() {
                let at = format!("output '{}', term {}", o.name, k + 1);
                if !t.coefficient.is_finite() {
                    return Err(err(format!(
                        "{at}: coefficient {} is not finite",
                        t.coefficient
                    )));
                }
                if let Some((name, e)) = t.exponents.iter().find(|(_, &e)| e > MAX_EXPONENT) {
                    return Err(err(format!(
                        "{at}: exponent of '{name}' is {e}; exponents go up to {MAX_EXPONENT}"
                    )));
                }
                for name in t.exponents.keys() {
                    if !table.contains_key(name) {
                        return Err(err(format!("{at}: {}", self.explain_unknown(name))));
                    }
                }
                if t.degree() as usize > self.degree {
                    return Err(err(format!(
                        "{at}: degree {} is above the model's degree {}",
                        t.degree(),
                        self.degree
                    )));
                }
            }
        }
        Ok(())
    }

    // Every accepted variable name (with the `_d0` aliases) -> its place.
    fn variable_table(&self) -> std::result::Result<BTreeMap<String, Var>, String> {
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
        Ok(table)
    }

    fn explain_unknown(&self, name: &str) -> String {
        if let Some((base, k)) = name.rsplit_once("_d") {
            if let (Some(o), Ok(k)) = (
                self.outputs.iter().find(|o| o.name == base),
                k.parse::<usize>(),
            ) {
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

    /// Offset of output `i`'s derivative 0 in the state vector.
    pub fn state_offset(&self, i: usize) -> usize {
        self.outputs[..i].iter().map(|o| o.order).sum()
    }

    /// Compiles the (validated) model into an evaluator.
    pub fn compile(&self) -> Result<CompiledModel> {
        self.validate()?;
        CompiledModel::new(self)
    }
}

/// A compiled right-hand side term: coefficient and its factors (variable slot in z, exponent).
#[derive(Debug, Clone)]
struct CTerm {
    coef: f64,
    factors: Vec<(usize, u32)>,
}

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
}

impl CompiledModel {
    fn new(m: &Model) -> Result<CompiledModel> {
        let table = m.variable_table().map_err(|message| Error::Model {
            path: "<memory>".into(),
            message,
        })?;
        let n_state = m.state_dim();
        let slot = |v: Var| match v {
            Var::State(i) => i,
            Var::Input(i) => n_state + i,
        };
        let terms = m
            .outputs
            .iter()
            .map(|o| {
                o.terms
                    .iter()
                    .map(|t| CTerm {
                        coef: t.coefficient,
                        factors: t
                            .exponents
                            .iter()
                            .map(|(n, &e)| (slot(table[n]), e))
                            .collect(),
                    })
                    .collect()
            })
            .collect();
        Ok(CompiledModel {
            orders: m.outputs.iter().map(|o| o.order).collect(),
            offsets: (0..m.outputs.len()).map(|i| m.state_offset(i)).collect(),
            n_state,
            n_inputs: m.inputs.len(),
            terms,
            names: m.variable_names(),
        })
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
    /// Offset of output `i` in the state vector.
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
    /// recompiling: for refinement loops that simulate many coefficient vectors.
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

    /// `P_i(z)`: the highest derivative of output `i` at `z = [state, inputs]`.
    pub fn eval_output(&self, i: usize, z: &[f64]) -> f64 {
        self.terms[i]
            .iter()
            .map(|t| {
                t.coef
                    * t.factors.iter().fold(1.0, |a, &(v, e)| match e {
                        1 => a * z[v],
                        2 => a * z[v] * z[v],
                        _ => a * z[v].powi(e as i32),
                    })
            })
            .sum()
    }

    /// `d rhs / d c` for the coefficients `coefs` (indices into [`CompiledModel::coefficients`]):
    /// written row-major `n_state x coefs.len()` into `out`. Each coefficient only moves the
    /// top derivative of its own output, by the value of its monomial.
    pub fn coefficient_jacobian(&self, x: &[f64], u: &[f64], coefs: &[usize], out: &mut [f64]) {
        let q = coefs.len();
        out.iter_mut().for_each(|v| *v = 0.0);
        let z = |v: usize| {
            if v < x.len() {
                x[v]
            } else {
                u[v - x.len()]
            }
        };
        for (col, &k) in coefs.iter().enumerate() {
            let mut rest = k;
            let mut i = 0;
            while rest >= self.terms[i].len() {
                rest -= self.terms[i].len();
                i += 1;
            }
            let t = &self.terms[i][rest];
            let m = t
                .factors
                .iter()
                .fold(1.0, |a, &(v, e)| a * z(v).powi(e as i32));
            let row = self.offsets[i] + self.orders[i] - 1;
            out[row * q + col] = m;
        }
    }

    /// `dP_i/dz` at `z`, written into `grad` (length n_state + n_inputs).
    pub fn grad_output(&self, i: usize, z: &[f64], grad: &mut [f64]) {
        grad.iter_mut().for_each(|g| *g = 0.0);
        for t in &self.terms[i] {
            for (a, &(v, e)) in t.factors.iter().enumerate() {
                let mut p = t.coef * e as f64 * z[v].powi(e as i32 - 1);
                for (b, &(w, f)) in t.factors.iter().enumerate() {
                    if a != b {
                        p *= z[w].powi(f as i32);
                    }
                }
                grad[v] += p;
            }
        }
    }

    /// The state derivative: the chains of integrators closed by the polynomials.
    pub fn rhs(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        // The solver calls this several times per step: no allocation for the usual sizes.
        let nz = self.n_state + self.n_inputs;
        let mut stack = [0.0f64; 32];
        let mut heap = Vec::new();
        let z: &mut [f64] = if nz <= stack.len() {
            &mut stack[..nz]
        } else {
            heap.resize(nz, 0.0);
            &mut heap
        };
        z[..x.len()].copy_from_slice(x);
        z[x.len()..x.len() + u.len()].copy_from_slice(u);
        let z = &*z;
        for (i, (&n, &o)) in self.orders.iter().zip(&self.offsets).enumerate() {
            for k in 0..n - 1 {
                dx[o + k] = x[o + k + 1];
            }
            dx[o + n - 1] = self.eval_output(i, z);
        }
    }

    /// Jacobian of [`CompiledModel::rhs`] with respect to the state (row-major n x n) and to the
    /// inputs (row-major n x n_u).
    pub fn jacobians(&self, x: &[f64], u: &[f64], jx: &mut [f64], ju: &mut [f64]) {
        let n = self.n_state;
        let nu = self.n_inputs;
        let mut z = Vec::with_capacity(n + nu);
        z.extend_from_slice(x);
        z.extend_from_slice(u);
        jx.iter_mut().for_each(|v| *v = 0.0);
        ju.iter_mut().for_each(|v| *v = 0.0);
        let mut g = vec![0.0; n + nu];
        for (i, (&ord, &o)) in self.orders.iter().zip(&self.offsets).enumerate() {
            for k in 0..ord - 1 {
                jx[(o + k) * n + o + k + 1] = 1.0;
            }
            self.grad_output(i, &z, &mut g);
            let row = o + ord - 1;
            jx[row * n..row * n + n].copy_from_slice(&g[..n]);
            ju[row * nu..row * nu + nu].copy_from_slice(&g[n..]);
        }
    }
}
