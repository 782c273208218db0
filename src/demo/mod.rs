//! Built-in demonstrations on simulated plants whose truth is known: the source paper's
//! electronic-throttle experiment ([`etc`]) and a MIMO plant of the paper's size ([`mimo`]).
//! Each prints its tables and, with an output folder, writes them as Markdown and CSV with SVG plots.

pub mod etc;
pub mod mimo;

use crate::derivatives::score::percentile;
use crate::identify::Identification;
use crate::model::Model as ModelFile;
use crate::plants::Run as PlantRun;
use crate::records::{RecordSet, Run};
use crate::{Error, Result};

/// A record set (channels: inputs then outputs, by name) from generated plant runs.
pub fn records(
    runs: &[PlantRun],
    inputs: &[String],
    outputs: &[String],
    tau: f64,
) -> Result<RecordSet> {
    let names: Vec<String> = inputs.iter().chain(outputs).cloned().collect();
    let recs = runs
        .iter()
        .map(|r| {
            let mut channels = r.u.clone();
            channels.extend(r.y.iter().cloned());
            Run {
                id: r.id.to_string(),
                channels,
                t0: r.t[0],
                rows: (0..r.t.len()).map(|i| i + 2).collect(),
            }
        })
        .collect();
    RecordSet::new(tau, names, recs)
}

/// Normalised error percentiles p50/p95/p100 of an estimate against the truth, pooled over runs.
pub fn truth_profile(est: &[&[f64]], truth: &[&[f64]]) -> [f64; 3] {
    let mut e = Vec::new();
    let mut t = Vec::new();
    for (a, b) in est.iter().zip(truth) {
        e.extend(a.iter().zip(b.iter()).map(|(x, y)| (x - y).abs()));
        t.extend(b.iter().map(|y| y.abs()));
    }
    let med = percentile(&t, 50.0).max(1e-300);
    [
        percentile(&e, 50.0) / med,
        percentile(&e, 95.0) / med,
        percentile(&e, 100.0) / med,
    ]
}

/// Free-run NRMSE of the simulated test runs against the noise-free output: RMS error over the
/// standard deviation of the true output, per run; returns (median, max, pooled).
pub fn nrmse_vs_truth(
    id: &Identification,
    runs: &[PlantRun],
    output: usize,
) -> (f64, f64, f64, usize) {
    let mut per = Vec::new();
    let (mut se, mut sv, mut n) = (0.0, 0.0, 0usize);
    let mut diverged = 0;
    for s in &id.simulations {
        let Some(r) = runs.iter().find(|r| r.id.to_string() == s.run) else {
            continue;
        };
        if s.error.is_some() || s.simulated.is_empty() {
            diverged += 1;
            continue;
        }
        let truth = &r.y_true[output];
        let mean = truth.iter().sum::<f64>() / truth.len() as f64;
        let var = truth.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        let err = s.simulated[output]
            .iter()
            .zip(truth)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>();
        per.push((err / var.max(1e-300)).sqrt());
        se += err;
        sv += var;
        n += truth.len();
    }
    let _ = n;
    if per.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN, diverged);
    }
    (
        percentile(&per, 50.0),
        per.iter().cloned().fold(0.0, f64::max),
        (se / sv.max(1e-300)).sqrt(),
        diverged,
    )
}

/// One true term: (monomial, true coefficient, identified coefficient, relative error).
pub type CoefficientRow = (String, f64, f64, f64);

/// Relative error of each true coefficient in an identified equation (missing terms count as
/// -100 %), and the terms identified but not in the truth.
pub fn coefficient_errors(
    found: &ModelFile,
    truth: &ModelFile,
    output: usize,
) -> (Vec<CoefficientRow>, Vec<String>) {
    let f = &found.outputs[output];
    let t = &truth.outputs[output];
    let mut rows = Vec::new();
    for tt in &t.terms {
        let c = f
            .terms
            .iter()
            .find(|x| x.exponents == tt.exponents)
            .map(|x| x.coefficient)
            .unwrap_or(0.0);
        rows.push((
            tt.monomial(),
            tt.coefficient,
            c,
            (c - tt.coefficient) / tt.coefficient,
        ));
    }
    let extra = f
        .terms
        .iter()
        .filter(|x| !t.terms.iter().any(|y| y.exponents == x.exponents))
        .map(|x| format!("{:+.4e}*{}", x.coefficient, x.monomial()))
        .collect();
    (rows, extra)
}

/// A demonstration's split: at least one training and one test run.
fn check_runs(train: usize, runs: usize) -> Result<()> {
    if train >= 1 && train < runs {
        Ok(())
    } else {
        Err(Error::param(
            "runs",
            format!("{train} training runs of {runs}; give 1 <= train < runs"),
        ))
    }
}
