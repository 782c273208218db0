//! `ctsid simulate MODEL.json DATA.csv --run-column R [--tau T] [--time-column C] [-o SIM.csv]`
//!
//! Simulates every run of a record from an initial state estimated from its first samples, with
//! the inputs interpolated linearly between samples. The initial state is found in two steps:
//! a least-squares polynomial of degree n+1 on the first max(15, 4(n+2)) samples of each output,
//! differentiated at the first sample (`ctsid::simulate::estimate_initial_derivatives`), then
//! refined by Gauss-Newton on the model's own simulated outputs over the first `--init-window`
//! samples (default 200; `ctsid::simulate::fit_initial_state`), which corrects the fast modes
//! and the noise that a local fit cannot. Prints RMS and NRMSE (RMS error over the
//! standard deviation of the measured output) per run and output, and over all runs (pooled
//! samples); `-o` writes the data with one `<output>_sim` column per output beside it.
//!
//! The CSV reader here is private and small (the [`table`] module) so it can be replaced by the
//! shared record loader without touching the rest.

use clap::Args;
use ctsid::model::Model;
use ctsid::simulate::{
    estimate_initial_derivatives, fit_initial_state, initial_window, rms_nrmse, simulate_model,
    SimOptions,
};
use ctsid::{Error, Result};

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Model file (ctsid-model/1 JSON).
    pub model: String,
    /// Data file (CSV with a header row).
    pub data: String,
    /// Column holding the run id; rows with the same id form one run, in file order.
    #[arg(long)]
    pub run_column: String,
    /// Sampling period in seconds (default: from the time column, else the model's tau).
    #[arg(long)]
    pub tau: Option<f64>,
    /// Column holding time in seconds.
    #[arg(long)]
    pub time_column: Option<String>,
    /// Samples at the start of each run used to estimate its initial state (at least the
    /// local fit's window; the model-based refinement uses all of them).
    #[arg(long, default_value_t = 200)]
    pub init_window: usize,
    /// Where to write the data with the simulated outputs.
    #[arg(short = 'o', long)]
    pub output: Option<String>,
}

/// Minimal CSV access: named columns, run grouping, one-line errors naming row and column.
mod table {
    use ctsid::{Error, Result};

    pub struct Table {
        pub path: String,
        pub headers: Vec<String>,
        pub rows: Vec<csv::StringRecord>,
    }

    impl Table {
        pub fn read(path: &str) -> Result<Table> {
            let mut rdr = csv::ReaderBuilder::new()
                .trim(csv::Trim::All)
                .from_path(path)
                .map_err(|e| Error::Io {
                    path: path.into(),
                    message: e.to_string(),
                })?;
            let headers: Vec<String> = rdr
                .headers()
                .map_err(|e| Error::Csv {
                    path: path.into(),
                    row: 1,
                    message: e.to_string(),
                })?
                .iter()
                .map(|s| s.to_string())
                .collect();
            let mut rows = Vec::new();
            for (k, r) in rdr.records().enumerate() {
                // Row numbers are file lines: the header is row 1.
                rows.push(r.map_err(|e| Error::Csv {
                    path: path.into(),
                    row: k + 2,
                    message: e.to_string(),
                })?);
            }
            Ok(Table {
                path: path.into(),
                headers,
                rows,
            })
        }

        pub fn column(&self, name: &str) -> Result<usize> {
            self.headers
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| Error::MissingColumn {
                    path: self.path.clone(),
                    column: name.into(),
                    available: self.headers.join(", "),
                })
        }

        /// Values of column `c` at the given row indices, as finite numbers.
        pub fn numbers(&self, c: usize, rows: &[usize]) -> Result<Vec<f64>> {
            rows.iter()
                .map(|&r| {
                    let s = self.rows[r].get(c).unwrap_or("");
                    s.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| Error::NonFinite {
                            path: self.path.clone(),
                            row: r + 2,
                            column: self.headers[c].clone(),
                            value: s.into(),
                        })
                })
                .collect()
        }

        /// Row indices of each run, runs in order of first appearance.
        pub fn runs(&self, c: usize) -> Vec<(String, Vec<usize>)> {
            let mut order: Vec<(String, Vec<usize>)> = Vec::new();
            let mut index = std::collections::HashMap::new();
            for (r, rec) in self.rows.iter().enumerate() {
                let id = rec.get(c).unwrap_or("").to_string();
                let k = *index.entry(id.clone()).or_insert_with(|| {
                    order.push((id, Vec::new()));
                    order.len() - 1
                });
                order[k].1.push(r);
            }
            order
        }
    }
}

pub fn run(args: SimulateArgs) -> Result<()> {
    let model = Model::read(&args.model)?;
    let compiled = model.compile()?;
    if let Some(tau) = args.tau {
        if !(tau.is_finite() && tau > 0.0) {
            return Err(Error::InvalidTau(tau));
        }
    }
    let tab = table::Table::read(&args.data)?;
    let run_col = tab.column(&args.run_column)?;
    let out_cols: Vec<usize> = model
        .outputs
        .iter()
        .map(|o| tab.column(&o.name))
        .collect::<Result<_>>()?;
    let in_cols: Vec<usize> = model
        .inputs
        .iter()
        .map(|u| tab.column(u))
        .collect::<Result<_>>()?;
    let time_col = args
        .time_column
        .as_deref()
        .map(|c| tab.column(c))
        .transpose()?;
    let tau = match (time_col, args.tau.or(model.tau)) {
        (Some(_), t) => t,
        (None, Some(t)) => Some(t),
        (None, None) => return Err(Error::MissingTau),
    };
    let sim_names: Vec<String> = model
        .outputs
        .iter()
        .map(|o| format!("{}_sim", o.name))
        .collect();
    if args.output.is_some() {
        if let Some(n) = sim_names.iter().find(|n| tab.headers.contains(n)) {
            return Err(Error::InvalidData(format!(
                "{}: already has a column '{n}'; rename it or simulate another file",
                tab.path
            )));
        }
    }
    let runs = tab.runs(run_col);
    if runs.is_empty() {
        return Err(Error::InvalidData(format!("{}: no data rows", tab.path)));
    }
    let n_out = model.outputs.len();
    let mut sim_values = vec![vec![f64::NAN; n_out]; tab.rows.len()];
    let mut pooled_sim: Vec<Vec<f64>> = vec![Vec::new(); n_out];
    let mut pooled_meas: Vec<Vec<f64>> = vec![Vec::new(); n_out];
    println!(
        "{:<12} {:<12} {:>14} {:>10}",
        "run", "output", "RMS", "NRMSE %"
    );
    for (id, rows) in &runs {
        let t: Vec<f64> = match time_col {
            Some(c) => {
                let t = tab.numbers(c, rows)?;
                for k in 1..t.len() {
                    if t[k].partial_cmp(&t[k - 1]) != Some(std::cmp::Ordering::Greater) {
                        return Err(Error::TimeNotIncreasing {
                            path: tab.path.clone(),
                            row: rows[k] + 2,
                            column: tab.headers[c].clone(),
                            prev: t[k - 1],
                            value: t[k],
                        });
                    }
                }
                if let (Some(given), true) = (args.tau, t.len() > 1) {
                    let step = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
                    if (step - given).abs() > 1e-6 * given {
                        return Err(Error::TauMismatch {
                            given,
                            from_time: step,
                            column: tab.headers[c].clone(),
                        });
                    }
                }
                t
            }
            None => {
                let tau = tau.expect("checked above");
                (0..rows.len()).map(|k| k as f64 * tau).collect()
            }
        };
        let ys: Vec<Vec<f64>> = out_cols
            .iter()
            .map(|&c| tab.numbers(c, rows))
            .collect::<Result<_>>()?;
        let us: Vec<Vec<f64>> = in_cols
            .iter()
            .map(|&c| tab.numbers(c, rows))
            .collect::<Result<_>>()?;
        let mut x0 = Vec::with_capacity(compiled.n_state());
        for (i, o) in model.outputs.iter().enumerate() {
            let what = format!(
                "estimating the initial state of output '{}' (order {})",
                o.name, o.order
            );
            x0.extend(estimate_initial_derivatives(
                &t, &ys[i], o.order, id, &what,
            )?);
        }
        let opts = SimOptions {
            run: id.clone(),
            ..Default::default()
        };
        let window = args.init_window.max(initial_window(
            compiled.orders().iter().copied().max().unwrap_or(1),
        ));
        let x0 = fit_initial_state(&compiled, &t, &ys, &us, &x0, window, &opts);
        let traj = simulate_model(&compiled, &x0, &t, &us, &opts)?;
        for (i, o) in model.outputs.iter().enumerate() {
            let sim = traj.series(compiled.offset(i));
            let (rms, nrmse) = rms_nrmse(&sim, &ys[i]);
            println!(
                "{:<12} {:<12} {:>14.6e} {:>10.4}",
                id,
                o.name,
                rms,
                100.0 * nrmse
            );
            for (k, &r) in rows.iter().enumerate() {
                sim_values[r][i] = sim[k];
            }
            pooled_sim[i].extend_from_slice(&sim);
            pooled_meas[i].extend_from_slice(&ys[i]);
        }
    }
    for (i, o) in model.outputs.iter().enumerate() {
        let (rms, nrmse) = rms_nrmse(&pooled_sim[i], &pooled_meas[i]);
        println!(
            "{:<12} {:<12} {:>14.6e} {:>10.4}",
            "all",
            o.name,
            rms,
            100.0 * nrmse
        );
    }
    if let Some(path) = &args.output {
        let io = |e: &dyn std::fmt::Display| Error::Io {
            path: path.clone(),
            message: e.to_string(),
        };
        let mut w = csv::Writer::from_path(path).map_err(|e| io(&e))?;
        let mut header = tab.headers.clone();
        header.extend(sim_names.iter().cloned());
        w.write_record(&header).map_err(|e| io(&e))?;
        for (r, rec) in tab.rows.iter().enumerate() {
            let mut row: Vec<String> = rec.iter().map(|s| s.to_string()).collect();
            row.extend(sim_values[r].iter().map(|v| format!("{v}")));
            w.write_record(&row).map_err(|e| io(&e))?;
        }
        w.flush().map_err(|e| io(&e))?;
        eprintln!("wrote {path}");
    }
    Ok(())
}
