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
    /// Largest monomial degree.
    #[arg(long)]
    pub degree: usize,
    /// Most active terms along the path.
    #[arg(long, default_value_t = 40)]
    pub max_terms: usize,
    /// Structure search: the LARS / lasso path (scikit-learn's) or forward orthogonal least squares.
    #[arg(long, value_enum, default_value_t = MethodArg::Lassolars)]
    pub method: MethodArg,
    #[arg(long, value_enum, default_value_t = EngineArg::Auto)]
    pub engine: EngineArg,
    /// Optional column of per-sample weights (weighted least squares).
    #[arg(long)]
    pub weights: Option<String>,
    /// Relevance threshold epsilon (0: off).
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
    let reg = Regression::builder()
        .degree(a.degree)
        .max_terms(a.max_terms)
        .method(method)
        .engine(engine)
        .epsilon(a.epsilon)
        .build()?;
    if let Some(dup) = a.features.iter().find(|f| **f == a.label) {
        return Err(Error::param(
            "features",
            format!("'{dup}' is also the label"),
        ));
    }
    let mut wanted = a.features.clone();
    wanted.push(a.label.clone());
    if let Some(w) = &a.weights {
        wanted.push(w.clone());
    }
    let mut cols = read_columns(&a.data, &wanted)?;
    let weights = a.weights.as_ref().map(|_| cols.pop().unwrap());
    if let Some(w) = &weights {
        ctsid::regression::check_weight_span(w)?;
    }
    let label = cols.pop().unwrap();
    // A constant feature makes every monomial with it a multiple of one without it: the model
    // read `l = 0.4*a*k` for `l = 2*a` with `k` = 5 throughout (identify refuses a constant
    // channel the same way).
    for (name, c) in a.features.iter().zip(&cols) {
        if c.iter().all(|v| *v == c[0]) {
            return Err(Error::param(
                "features",
                format!(
                    "'{name}' is constant ({}) over the data; a constant feature only rescales other terms, so leave it out",
                    ctsid::util::short(c[0])
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
        "engine: {}; {} samples, {} candidates ({} constant), {:?} path of {} steps ({:?}), {} sweeps, {} refreshes, {:.2} s",
        d.engine, d.n_samples, d.n_candidates, d.constant_candidates, d.method, d.path_steps, d.stop, d.sweeps, d.refreshes,
        started.elapsed().as_secs_f64()
    )?;
    outln!(
        "selection: eBIC chose breakpoint {} ({} terms, eBIC {:.2}); pruned [{}]; final eBIC {:.2}, R^2 {:.6}",
        d.chosen_breakpoint,
        model.path[d.chosen_breakpoint].active.len(),
        d.ebic_path_choice,
        d.pruned.join(", "),
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
