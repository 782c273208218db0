//! # ctsid: continuous-time sparse identification
//!
//! ctsid finds continuous-time models `y^(n) = P(y, y', ..., y^(n-1), u)` of real machines from
//! short, noisy, uniformly sampled input/output runs, with P a sparse multivariate polynomial plus,
//! where the physics needs them, named terms (`sign(y_d1)` for Coulomb friction, `abs(y_d1)*y_d1`
//! for drag) in one model type ([`Model`]).
//!
//! # Quick start
//!
//! Read a record, say which runs train, validate and test, identify, simulate:
//!
//! ```no_run
//! use ctsid::{Identifier, RecordSet, Split};
//!
//! let records = RecordSet::read_csv("machine.csv", &["y", "u"], Some("run"), 0.01)?;
//! let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
//! let fit = Identifier::new().outputs(["y"]).inputs(["u"]).degree(3).fit(&records, &split)?;
//! println!("{}", fit.model); // y_d2 = ... : the equations
//! let sim = fit.model.simulate(&records)?; // free runs from the measured inputs
//! println!("fit on run 5: {:.1} %", sim.runs[5].fit_percent()[0]);
//! fit.model.write("machine.model.json")?; // ctsid simulate / control / discover read it
//! # Ok::<(), ctsid::Error>(())
//! ```
//!
//! A record without a run column is one run, `0`; `RecordSet::read_csv(path, &cols, None,
//! tau)?.segmented_seconds(4.0)?` cuts it into runs `0`, `1`, ... of 4 s (the command line's
//! `--segment 4`), and a test record in a file of its own is a second [`RecordSet`] to simulate
//! (the README's library quick start does both on the EMPS record). Runs built in memory are
//! [`records::Run::new`]`(id, channels)` in [`RecordSet::new`].
//!
//! [`Identifier`] names the other settings (fixed order, named terms such as `sign(y_d1)`,
//! engine, progress callback); [`Model::read`] loads a model file;
//! [`simulate::simulate_model`] runs a model from an initial state of your own. The library
//! prints nothing: progress goes to a callback, notes into the results. `examples/identify_csv.rs`
//! is the same as a program.
//!
//! # Modules
//!
//! The modules follow the pipeline:
//!
//! | stage | module | what it assumes |
//! |---|---|---|
//! | records | [`records`] | runs uniformly sampled at tau, named channels |
//! | derivatives | [`derivatives`] | a smooth signal plus white measurement noise, per run |
//! | candidate basis | [`basis`] | monomials of degree <= 12 in <= 32 variables |
//! | sweep engines | [`engine`] | CPU (rayon) or GPU (wgpu compute shaders) |
//! | sparse regression | [`regression`] | LARS / LassoLars and forward OLS, written once against [`engine::SweepEngine`] |
//! | model file | [`model`] | `ctsid-model/2` JSON, chains of integrators closed by sums of monomials and named terms |
//! | simulation | [`simulate`] | Radau IIA with error control, inputs with known breakpoints; one initial-state convention |
//! | scores | [`metrics`] | RMS, NRMSE and fit % of a simulated output |
//! | built-in plants | [`plants`] | throttle and MIMO plants with known truth, seeded excitation and noise |
//! | identification | [`identify`] | order search (eta-rule), sigma-weighted fits, test profiles, free-run simulation |
//! | demonstrations | [`demo`] | the paper's throttle experiment and a MIMO plant, judged against truth |
//! | missing physics | [`discover`] | a nominal model file; one output; named effect dictionary |
//! | feedback | [`control`] | one output, one input: observer and state feedback with integral action, pole placement |
//! | reports | [`report`] | Markdown / CSV tables and SVG plots |
//! | (shared) Levenberg-Marquardt | [`lm`] | residuals and normal equations from the caller |
//!
//! Errors are typed ([`Error`]); nothing in the library panics on bad input.

// Numerical kernels index several arrays with one loop variable, as the formulas they implement
// do; iterator zips over three or four slices read worse there.
#![allow(clippy::needless_range_loop)]

pub mod basis;
pub mod benchmark;
pub mod control;
pub mod demo;
pub mod derivatives;
pub mod discover;
pub mod engine;
pub mod error;
pub mod identify;
pub mod linalg;
pub mod lm;
pub mod metrics;
pub mod model;
pub mod plants;
pub mod records;
pub mod regression;
pub mod report;
pub mod simulate;
pub mod util;

pub use error::{Error, Result};
pub use identify::{Identification, Identifier, Split};
pub use model::Model;
pub use records::RecordSet;
pub use simulate::Simulation;

// The README's library quick start is compiled with the doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
