//! `ctsid derive`: derivatives of one column, per run, written beside the input's columns.

use clap::Args;
use ctsid::derivatives::{differentiate_runs, DerivativeOptions};
use ctsid::{Error, Result};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct DeriveArgs {
    /// Input CSV file with a header row.
    pub input: PathBuf,
    /// Column to differentiate.
    #[arg(long)]
    pub column: String,
    /// Highest derivative order (1..=8).
    #[arg(long)]
    pub order: usize,
    #[command(flatten)]
    pub sampling: super::runs::SamplingArgs,
    /// Run (experiment) id column; rows with the same id form one run.
    #[arg(long)]
    pub run_column: Option<String>,
    /// Output CSV (standard output when omitted).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Tune each run on its own instead of jointly over the record set.
    #[arg(long)]
    pub per_run_tuning: bool,
    /// Always use the smoother: never replace a run's estimate by an exponential-sum model
    /// (by default one is used where it explains the run to the noise level; see the README).
    #[arg(long)]
    pub smoother_only: bool,
}

pub fn run(a: DeriveArgs) -> Result<()> {
    if a.order == 0 || a.order > ctsid::derivatives::MAX_ORDER {
        return Err(Error::param(
            "order",
            format!(
                "{}; give an order of 1..={}",
                a.order,
                ctsid::derivatives::MAX_ORDER
            ),
        ));
    }
    let mut names: Vec<String> = (0..=a.order)
        .map(|k| format!("{}_d{k}", a.column))
        .collect();
    names.extend((0..=a.order).map(|k| format!("{}_sigma{k}", a.column)));
    // `-o -` is refused by every command; derive writes to standard output without `-o`.
    if a.output.as_deref() == Some(std::path::Path::new("-")) {
        return Err(Error::Io {
            path: "-".into(),
            message: "derive writes to standard output when -o is left out; give -o a file name (./- for a file named '-')".into(),
        });
    }
    super::csvout::check(&a.input, a.output.as_deref(), &[], &names, "derive")?;
    let spec = a
        .sampling
        .spec(vec![a.column.clone()], a.run_column.clone(), None)?;
    let rs = super::load_records(&a.input, &spec)?;
    rs.require_derivable(a.order)?;
    let runs: Vec<&[f64]> = rs.runs.iter().map(|r| r.channels[0].as_slice()).collect();
    let opts = DerivativeOptions {
        exp_sum: !a.smoother_only,
        ..Default::default()
    };
    let ders = if a.per_run_tuning {
        runs.iter()
            .map(|y| differentiate_runs(&[y], rs.tau, a.order, &opts).map(|mut v| v.remove(0)))
            .collect::<Result<Vec<_>>>()?
    } else {
        differentiate_runs(&runs, rs.tau, a.order, &opts)?
    };
    let n_orders = a.order + 1;
    super::csvout::write_with_columns(&a.input, a.output.as_deref(), &rs, &names, |r, i, k| {
        if k < n_orders {
            format!("{:.12e}", ders[r].values[k][i])
        } else {
            format!("{:.6e}", ders[r].sigma[k - n_orders][i])
        }
    })?;
    if a.per_run_tuning {
        eprintln!(
            "derived '{}' up to order {} on {} run(s) tuned one by one, tau = {:?} s:",
            a.column,
            a.order,
            ders.len(),
            rs.tau
        );
        print_per_run(&rs, &ders);
        return Ok(());
    }
    let d0 = &ders[0];
    let models: Vec<String> = ders
        .iter()
        .zip(&rs.runs)
        .filter_map(|(d, r)| d.exp_terms.map(|t| format!("{} ({t} terms)", r.id)))
        .collect();
    let model_note = if models.is_empty() {
        String::new()
    } else {
        format!(
            "; exponential-sum model on {} of {} run(s): {}",
            models.len(),
            ders.len(),
            models.join(", ")
        )
    };
    eprintln!(
        "derived '{}' up to order {} on {} run(s), tau = {:?} s: noise sd {:.4e}, smoothing bandwidth {:.3} rad/s{model_note}",
        a.column,
        a.order,
        ders.len(),
        rs.tau,
        d0.noise_sd,
        d0.h / rs.tau
    );
    Ok(())
}

/// With `--per-run-tuning` each run has its own noise level and bandwidth: one line per run
/// (the first run's figures alone read as the record's, and a constant run keeps the untuned
/// default).
fn print_per_run(rs: &ctsid::RecordSet, ders: &[ctsid::derivatives::Derivatives]) {
    for (d, r) in ders.iter().zip(&rs.runs) {
        let figures = if d.values[0].iter().all(|v| *v == d.values[0][0]) {
            "constant, not tuned".to_string()
        } else {
            format!(
                "noise sd {:.4e}, smoothing bandwidth {:.3} rad/s{}",
                d.noise_sd,
                d.h / rs.tau,
                d.exp_terms.map_or(String::new(), |t| format!(
                    ", exponential-sum model ({t} terms)"
                ))
            )
        };
        eprintln!("  run {}: {figures}", r.id);
    }
}
