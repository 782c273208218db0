//! `ctsid regress`: sparse polynomial regression of one CSV column on others.
//!
//! Reads the named columns with a small private CSV reader (the records loader of the library
//! handles runs and time; regression needs only plain columns), fits with
//! [`ctsid::regression::Regression`], prints the equation and the selection diagnostics, and
//! writes the model as JSON with `-o`.

use clap::{Args, ValueEnum};
use ctsid::engine::Features;
use ctsid::records::CsvSpec;
use ctsid::regression::{EngineChoice, Method, Regression};
use ctsid::{Error, Result};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RegressArgs {
    /// CSV file with a header row.
    pub data: PathBuf,
    /// Feature columns, comma separated.
    #[arg(long, value_delimiter = ',', required = true, value_parser = super::trimmed)]
    pub features: Vec<String>,
    /// Label column.
    #[arg(long)]
    pub label: String,
    /// Largest monomial degree (1 to 12; at most 32 features and 5,000,000 candidates).
    #[arg(long)]
    pub degree: usize,
    /// Most active terms along the path (and at most half the samples).
    #[arg(long, default_value_t = 40)]
    pub max_terms: usize,
    /// End the path after this many breakpoints in a row without a better eBIC (default 40, 10
    /// for forward-ols); 0 runs the whole path up to --max-terms (to compare paths).
    #[arg(long)]
    pub patience: Option<usize>,
    /// Structure search: the LARS / lasso path (scikit-learn's) or forward orthogonal least squares.
    #[arg(long, value_enum, default_value_t = MethodArg::Lassolars)]
    pub method: MethodArg,
    /// Which engine runs the sweeps X^T v: the CPU one, the GPU one (wgpu; an error without an
    /// adapter), or auto (the GPU where one pays, else the CPU; a note says which and why).
    #[arg(long, value_enum, default_value_t = EngineArg::Auto)]
    pub engine: EngineArg,
    /// Optional column of per-sample weights (weighted least squares; not a feature or the
    /// label).
    #[arg(long)]
    pub weights: Option<String>,
    /// Relevance threshold: end the path when a new term lowers the relative residual
    /// ||r|| / ||y - mean|| by less than this (0: off). Meant for forward-ols, which adds one term
    /// per step; on a lars / lasso path it ends at the first small step, before later terms are
    /// tried.
    #[arg(long, default_value_t = 0.0)]
    pub epsilon: f64,
    /// Write the model as JSON here.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum MethodArg {
    Lars,
    Lassolars,
    ForwardOls,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Method {
        match m {
            MethodArg::Lars => Method::Lars,
            MethodArg::Lassolars => Method::LassoLars,
            MethodArg::ForwardOls => Method::ForwardOls,
        }
    }
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum EngineArg {
    Cpu,
    Gpu,
    Auto,
}

/// Reads the named columns through the shared record loader (same one-line errors as every
/// command). Regression treats rows as independent samples: no run grouping, and the sampling
/// period the loader asks for plays no part.
fn read_columns(path: &std::path::Path, wanted: &[String]) -> Result<Vec<Vec<f64>>> {
    let spec = CsvSpec {
        columns: wanted.to_vec(),
        run_column: None,
        time_column: None,
        tau: Some(1.0),
        // Samples of a static relation: a run column means nothing here.
        rows_independent: true,
    };
    let mut rs = super::load_records(path, &spec)?;
    Ok(rs.runs.remove(0).channels)
}

/// The library's setting named as the option that sets it (`'max_terms'` read as a field).
fn as_flag(e: Error) -> Error {
    match e {
        Error::InvalidParameter { name, reason } => {
            let flag = match name.as_str() {
                "max_terms" => "--max-terms",
                "epsilon" => "--epsilon",
                "degree" => "--degree",
                "weights" => "--weights",
                _ => return Error::InvalidParameter { name, reason },
            };
            Error::param(flag, reason)
        }
        e => e,
    }
}

/// The columns before any are read: no feature is the label, the weights are neither, and each
/// feature is one name in printed monomials (`x^2` beside `x` printed `3*x^2 + 0.5*x^2`).
fn check_columns(a: &RegressArgs) -> Result<()> {
    if let Some(dup) = a.features.iter().find(|f| **f == a.label) {
        return Err(Error::param(
            "--features",
            format!("'{dup}' is also the label"),
        ));
    }
    if let Some(w) = &a.weights {
        if *w == a.label || a.features.contains(w) {
            let role = if *w == a.label {
                "the label"
            } else {
                "a feature"
            };
            return Err(Error::param(
                "--weights",
                format!("'{w}' is also {role}; give a column of weights of its own"),
            ));
        }
    }
    for f in &a.features {
        ctsid::util::check_channel_name(f, "--features", "column")?;
    }
    Ok(())
}

pub fn run(a: RegressArgs) -> Result<()> {
    if let Some(o) = &a.output {
        super::check_output_file(o, &[&a.data])?;
    }
    let engine = match a.engine {
        EngineArg::Cpu => EngineChoice::Cpu,
        EngineArg::Gpu => EngineChoice::Gpu,
        EngineArg::Auto => EngineChoice::Auto,
    };
    let method = Method::from(a.method);
    let mut builder = Regression::builder()
        .degree(a.degree)
        .max_terms(a.max_terms)
        .method(method)
        .engine(engine)
        .epsilon(a.epsilon);
    if let Some(p) = a.patience {
        builder = builder.ebic_patience(p);
    }
    let reg = builder.build().map_err(as_flag)?;
    check_columns(&a)?;
    if a.epsilon > 0.0 && !matches!(a.method, MethodArg::ForwardOls) {
        eprintln!("note: --epsilon ends the lars / lasso path at its first step that lowers the relative residual by less than {}; terms that would enter later are not tried (forward-ols adds one term per step)", a.epsilon);
    }
    let mut wanted = a.features.clone();
    wanted.push(a.label.clone());
    if let Some(w) = &a.weights {
        wanted.push(w.clone());
    }
    let mut cols = read_columns(&a.data, &wanted)?;
    let weights = a.weights.as_ref().map(|_| cols.pop().unwrap());
    if let Some(w) = &weights {
        ctsid::regression::check_weight_span(w).map_err(as_flag)?;
    }
    let label = cols.pop().unwrap();
    // A constant feature makes every monomial with it a multiple of one without it: the model
    // read `l = 0.4*a*k` for `l = 2*a` with `k` = 5 throughout (identify refuses a constant
    // channel the same way). Too few rows are the fit's error, not a constant (one row was
    // called a constant feature).
    // Rows of zero weight take no part in the fit: the library's count of samples.
    let used = ctsid::regression::rows_that_count(weights.as_deref(), label.len());
    let enough = used.len() >= ctsid::regression::MIN_SAMPLES;
    for (name, c) in a.features.iter().zip(&cols).filter(|_| enough) {
        let first = c[used[0]];
        if used.iter().all(|&i| c[i] == first) {
            return Err(Error::param(
                "--features",
                format!(
                    "'{name}' is constant ({}) over the data; a constant feature only rescales other terms, so leave it out",
                    ctsid::util::short(first)
                ),
            ));
        }
    }
    let features = Features::new(a.features.clone(), cols)?;
    let started = std::time::Instant::now();
    let model = reg.fit(&features, &label, &a.label, weights.as_deref())?;
    let d = &model.diagnostics;
    outln!("{}", model.equation())?;
    // Engine notes are about the run, not the result: standard error, like identify's.
    for note in &d.notes {
        eprintln!("note: {note}");
    }
    outln!(
        "engine: {}; {} samples, {} candidates ({} constant), {:?} path of {} steps ({:?}), {} sweeps, {} refreshes, fitted in {:.2} s",
        d.engine, d.n_samples, d.n_candidates, d.constant_candidates, d.method, d.path_steps, d.stop, d.sweeps, d.refreshes,
        started.elapsed().as_secs_f64()
    )?;
    // `pruned [1]` read like an index; the constant term is named `1`.
    let pruned = match d.pruned.as_slice() {
        [] => "none".to_string(),
        p => p
            .iter()
            .map(|t| {
                if t == "1" {
                    "1 (the constant)"
                } else {
                    t.as_str()
                }
            })
            .collect::<Vec<_>>()
            .join(", "),
    };
    outln!(
        "selection: eBIC chose breakpoint {} ({} terms, eBIC {:.2}); pruned: {pruned}; final eBIC {:.2}, R^2 {:.6}",
        d.chosen_breakpoint,
        model.path[d.chosen_breakpoint].active.len(),
        d.ebic_path_choice,
        d.ebic_final,
        d.r2
    )?;
    if !d.skipped_collinear.is_empty() {
        outln!(
            "skipped as collinear with the active set: {}",
            d.skipped_collinear.join(", ")
        )?;
    }
    if let Some(out) = &a.output {
        let text =
            serde_json::to_string_pretty(&model).map_err(|e| Error::InvalidData(e.to_string()))?;
        ctsid::util::write_atomic(out, text.as_bytes())?;
        super::written(format!("model written to {}", out.display()));
    }
    Ok(())
}
