//! The model: one type for every term, polynomial or named, and its file `ctsid-model/2`.
//!
//! ```json
//! {"format": "ctsid-model/2", "tau": 0.001, "degree": 1, "inputs": ["force"],
//!  "sign_smoothing": {"q_d1": 2.4e-05},
//!  "outputs": [{"name": "q", "order": 2,
//!               "terms": [{"exponents": {"q_d1": 1}, "coefficient": -2.14, "origin": "nominal"},
//!                         {"exponents": {"force": 1}, "coefficient": 0.0105},
//!                         {"expression": "sign(q_d1)", "coefficient": -0.21,
//!                          "std_error": 0.004, "origin": {"effect": "coulomb_friction"}}]}]}
//! ```
//!
//! Each output `y` of order `n` obeys `y^(n) = sum_k c_k * phi_k(z)`, where `z` holds the
//! derivatives `y_dk` (`y` itself, or `y_d0`, is order 0) of every output below that output's own
//! order, and the inputs by name. A term's `phi` is either a monomial (`exponents`, a map of
//! variable to positive integer power; empty for the constant) or a named expression
//! (`expression`, in the language of [`expr`]: `sign abs sqrt tanh sin cos exp sat relu`,
//! `+ - * / ^`, numbers), never both. Coefficients are in the original units of the signals.
//! A term may say where it came from (`origin`: `identified`, `nominal`, or `{"effect": family}`)
//! and how well its coefficient is known (`std_error`, `interval`).
//!
//! `sign_smoothing` gives, per variable, the width `w` over which `sign(x)` of an argument
//! starting with that variable is smoothed to `x / sqrt(x^2 + w^2)` for the integrator: a
//! model simulates the same wherever it is read. A variable not listed gets the exact sign.
//! `input_interpolation` (`linear` when absent, `cubic` or `hold`; [`Interpolation`]) says how
//! the sampled inputs of a record are read between their samples when the model is simulated:
//! the input coefficients were fitted through that reconstruction.
//! An output may carry `"limits": {"max": 10.0}` (and/or `min`): hard limits of its level
//! ([`Limits`]: an overflowing tank, an end stop), which every simulation keeps.
//!
//! What this module assumes and guarantees:
//! - `tau` and `degree` may be omitted in a hand-written file (`degree` is then the largest
//!   monomial degree). Two sections the tools write for people, `training` and `discovery`, are
//!   kept verbatim; any other unknown key, at any level, is an error naming it and where it is.
//! - [`Model::from_json_str`] / [`Model::read`] validate everything (also the expressions, whose
//!   unknown variables and functions are named) and fail with one line naming the term at fault;
//!   [`Model::validate`] does the same for models built in code. `ctsid-model/1` files
//!   (polynomials only) are read too and written back as `/2`.
//! - Writing then reading then writing gives the same bytes.
//! - [`CompiledModel`] turns a validated model into a fast evaluator of the right-hand sides and
//!   their exact derivatives, with a fixed state layout: for each output in file order its
//!   derivatives `0..n_i-1`, concatenated; the inputs are a separate vector.

mod compiled;
pub mod expr;
mod file;
mod tape;

pub use compiled::CompiledModel;
pub use expr::Expr;
pub use file::{
    derivative_name, derivative_of, Interpolation, Limits, Model, Origin, OutputEquation, Term,
    Var, FORMAT, FORMAT_V1, MAX_EXPONENT, MAX_ORDER, SECTIONS,
};
