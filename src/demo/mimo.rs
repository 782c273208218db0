//! `ctsid demo mimo`: a MIMO plant of the paper's size (2 inputs, 3 outputs of relative degree 3,
//! so dim z = 11) with known polynomial coupling, identified at d = 2, 4, 6 (78, 1365 and 12 376
//! candidates per output), with the recovered equations, errors against truth and time per engine.

use super::{coefficient_errors, nrmse_vs_truth, records};
use crate::identify::{identify, Orders, Settings, Split};
use crate::plants::{dataset, Plant};
use crate::regression::EngineChoice;
use crate::report::{write_file, Table};
use crate::{Error, Result};
use std::fmt::Write;
use std::path::PathBuf;

#[derive(Debug, Clone)]
pub struct MimoOptions {
    pub runs: usize,
    pub train: usize,
    pub samples: usize,
    pub tau: f64,
    pub noise: f64,
    pub seed: u64,
    pub degrees: Vec<usize>,
    /// Candidate orders of every output, chosen by identify's order search (one value fixes
    /// them).
    pub orders: Vec<usize>,
    pub engines: Vec<EngineChoice>,
    /// Structure search (identify's default unless given).
    pub method: Option<crate::regression::Method>,
    pub out: Option<PathBuf>,
    /// Progress lines of the identification (see `identify::Settings::progress`).
    pub progress: Option<crate::identify::Progress>,
}

impl Default for MimoOptions {
    fn default() -> Self {
        MimoOptions {
            runs: 40,
            train: 25,
            samples: 1000,
            tau: 0.01,
            noise: 0.0,
            seed: 1,
            degrees: vec![2, 4, 6],
            orders: vec![1, 2, 3, 4],
            engines: vec![EngineChoice::Cpu],
            method: None,
            out: None,
            progress: None,
        }
    }
}

pub fn run(o: &MimoOptions) -> Result<String> {
    crate::util::finite_nonneg("noise", o.noise)?;
    super::check_runs(o.train, o.runs)?;
    for &d in &o.degrees {
        crate::basis::check_degree(d)?;
    }
    // A degree or engine listed twice ran the same case twice, minutes each.
    if let Some((_, j)) = crate::util::first_repeat(&o.degrees) {
        return Err(Error::param(
            "degrees",
            format!("degree {} is listed twice", o.degrees[j]),
        ));
    }
    if let Some((_, j)) = crate::util::first_repeat(&o.engines) {
        return Err(Error::param(
            "engines",
            format!("{:?} is listed twice", o.engines[j]),
        ));
    }
    // Before the data are simulated (an order of 0 failed inside the first fit).
    crate::identify::check_orders(&o.orders, "orders")?;
    let plant = Plant::mimo();
    let inputs = plant.input_names();
    let outputs = plant.output_names();
    let truth = plant
        .true_model(Some(o.tau))
        .expect("the MIMO plant has a polynomial truth");
    let runs = dataset(&plant, o.runs, o.samples, o.tau, o.noise, o.seed)?;
    let rs = records(&runs, &inputs, &outputs, o.tau)?;
    let ids: Vec<String> = (0..o.runs).map(|i| i.to_string()).collect();
    let split = Split::new(
        (0..o.train).collect(),
        None,
        (o.train..o.runs).collect(),
        &ids,
    )?;
    let mut out = String::new();
    let _ = writeln!(out, "# MIMO plant: 2 inputs, 3 outputs of order 3 (dim z = 11)\n\n{} runs x {} samples, tau = {} s, noise {} %, {} train / {} test.\n", o.runs, o.samples, o.tau, o.noise * 100.0, o.train, o.runs - o.train);
    let _ = writeln!(out, "True equations:\n");
    for eq in &truth.outputs {
        let _ = writeln!(out, "    {}", eq.to_text());
    }
    let mut per_output = Table::new(&[
        "degree",
        "output",
        "order (truth 3)",
        "true terms found",
        "extra terms",
        "test NRMSE vs truth",
    ]);
    let mut summary = Table::new(&[
        "degree",
        "candidates / output",
        "engine",
        "orders",
        "time (s)",
        "true terms found",
        "extra terms",
        "max coef. error",
        "test NRMSE vs truth (pooled)",
    ]);
    for &d in &o.degrees {
        // True terms of higher degree than d cannot be found at d: count them apart.
        let beyond: usize = truth
            .outputs
            .iter()
            .flat_map(|o| &o.terms)
            .filter(|t| t.degree() as usize > d)
            .count();
        for &engine in &o.engines {
            let mut s = Settings::new(outputs.clone(), inputs.clone(), d);
            if let Some(m) = o.method {
                s.method = m;
            }
            s.orders = match o.orders.as_slice() {
                [n] => Orders::Fixed(vec![*n; outputs.len()]),
                list => Orders::Search(list.to_vec()),
            };
            s.engine = engine;
            s.progress = o.progress.clone();
            let t = std::time::Instant::now();
            // An engine the user named that cannot run is the demo's failure, not a table cell.
            let id = identify(&rs, &split, &s).map_err(|e| {
                Error::Numerical(format!(
                    "demo mimo: degree {d} with engine {engine} failed: {e}"
                ))
            })?;
            let secs = t.elapsed().as_secs_f64();
            let (mut found, mut total, mut extra, mut worst) = (0, 0, 0, 0.0f64);
            let _ = writeln!(out, "\n## d = {d}, engine {}\n", id.outputs[0].engine);
            let mut nr = Vec::new();
            for i in 0..outputs.len() {
                let (rows, ex) = coefficient_errors(&id.model, &truth, i);
                let hit = rows.iter().filter(|r| r.2 != 0.0).count();
                total += rows.len();
                found += hit;
                extra += ex.len();
                worst = rows.iter().map(|r| r.3.abs()).fold(worst, f64::max);
                let _ = writeln!(out, "    {}", id.model.outputs[i].to_text());
                nr.push(format!("{:.2} %", 100.0 * nrmse_vs_truth(&id, &runs, i).2));
                per_output.row(vec![
                    d.to_string(),
                    outputs[i].clone(),
                    id.model.outputs[i].order.to_string(),
                    format!("{hit} / {}", rows.len()),
                    ex.len().to_string(),
                    nr[i].clone(),
                ]);
            }
            // What identify notes (an order search that did not settle, say) is part of the
            // demo's answer, as `identify` prints it.
            for n in &id.notes {
                let _ = writeln!(out, "\nnote: {n}");
            }
            let orders: Vec<String> = id
                .model
                .outputs
                .iter()
                .map(|e| e.order.to_string())
                .collect();
            summary.row(vec![
                d.to_string(),
                crate::basis::count(11, d).unwrap_or(0).to_string(),
                id.outputs[0].engine.clone(),
                orders.join(", "),
                format!("{secs:.2}"),
                if beyond > 0 {
                    format!("{found} / {total} ({beyond} of degree > {d})")
                } else {
                    format!("{found} / {total}")
                },
                extra.to_string(),
                format!("{:.2} %", 100.0 * worst),
                nr.join(", "),
            ]);
        }
    }
    let _ = writeln!(
        out,
        "\n## Summary\n\n{}\n## Per output\n\n{}",
        summary.markdown(),
        per_output.markdown()
    );
    if let Some(dir) = &o.out {
        write_file(dir, "mimo_report.md", &out)?;
        write_file(dir, "mimo_summary.csv", &summary.csv())?;
        write_file(dir, "mimo_outputs.csv", &per_output.csv())?;
    }
    Ok(out)
}
