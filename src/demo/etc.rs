//! `ctsid demo etc`: the source paper's electronic-throttle experiment, reproduced and judged
//! against the truth.
//!
//! Data as in the paper: 100 runs of 1000 samples at tau = 3 ms from rest, excitation
//! u = Sat(e^(-mu t) sum a_i sin(w_i t + psi_i)) with u_bar = 5, mu = 4, w_max = 10, n_B = 20,
//! noise eta * percentile(|y|, 99) * N(0, 1) with eta = 3 % (and a noise-free copy); 25 runs
//! train, 75 test. Patm defaults to 0 Pa: with the printed parameters the angle swings tens of
//! radians and, at Patm = 101 325 Pa, the aerodynamic term (pi - y) cos^2(y) dominates y'''.

use super::{coefficient_errors, nrmse_vs_truth, records, truth_profile};
use crate::derivatives::score::percentile;
use crate::identify::profile::{self, Profile};
use crate::identify::{identify, Identification, Orders, Settings, Split};
use crate::plants::{dataset, Plant, ThrottlePreset};
use crate::regression::EngineChoice;
use crate::report::{svg, write_file, Table};
use crate::{Error, Result};
use std::fmt::Write;
use std::path::PathBuf;

/// The paper's test percentiles for n = 3, d = 3 at 3 % noise (p50/80/90/95/98/99/100).
pub const PAPER_TEST: [f64; 7] = [0.01, 0.03, 0.04, 0.06, 0.12, 0.22, 1.46];

#[derive(Debug, Clone)]
pub struct EtcOptions {
    pub patm: f64,
    pub physical: bool,
    pub runs: usize,
    pub train: usize,
    pub samples: usize,
    pub tau: f64,
    pub noise: f64,
    pub seed: u64,
    pub degree: usize,
    pub engine: EngineChoice,
    pub out: Option<PathBuf>,
    /// Progress lines of the identification (see `identify::Settings::progress`).
    pub progress: Option<crate::identify::Progress>,
}

impl Default for EtcOptions {
    fn default() -> Self {
        EtcOptions {
            patm: 0.0,
            physical: false,
            runs: 100,
            train: 25,
            samples: 1000,
            tau: 0.003,
            noise: 0.03,
            seed: 1,
            degree: 3,
            engine: EngineChoice::Auto,
            out: None,
            progress: None,
        }
    }
}

fn prof_cells(p: &Profile) -> Vec<String> {
    p.0.iter().map(|v| format!("{v:.3}")).collect()
}

/// Largest `--patm` taken (Pa): a hundred atmospheres.
pub const PATM_MAX: f64 = 1e7;

/// Runs the experiment; returns the report text (also printed by the CLI).
pub fn run(o: &EtcOptions) -> Result<String> {
    // Settings are checked before the minutes of simulation and fitting, not after.
    check(o)?;
    let t_all = std::time::Instant::now();
    let plant = if o.physical {
        Plant::throttle(ThrottlePreset::Physical)
    } else {
        Plant::throttle(ThrottlePreset::Paper { patm: o.patm })
    };
    let patm = if o.physical {
        crate::plants::throttle::PATM_STD
    } else {
        o.patm
    };
    let inputs = plant.input_names();
    let outputs = plant.output_names();
    let split_ids: Vec<usize> = (0..o.runs).collect();
    let ids: Vec<String> = split_ids.iter().map(|i| i.to_string()).collect();
    let split = Split::new(
        (0..o.train).collect(),
        None,
        (o.train..o.runs).collect(),
        &ids,
    )?;
    let truth = plant.true_model(Some(o.tau));
    let mut out = header(o, patm);
    let mut tables: Vec<(String, Table)> = Vec::new();
    let mut profile_table = profile_table();
    let mut noisy: Option<(Identification, Vec<crate::plants::Run>)> = None;
    // One identification of the demo: degree d, the order searched (None) or fixed.
    let run_identify = |runs: &[crate::plants::Run], d: usize, order: Option<usize>| {
        let rs = records(runs, &inputs, &outputs, o.tau)?;
        let mut s = Settings::new(outputs.clone(), inputs.clone(), d);
        s.engine = o.engine;
        match order {
            Some(n) => s.orders = Orders::Fixed(vec![n]),
            None => s.progress = o.progress.clone(),
        }
        identify(&rs, &split, &s)
    };
    let search = |eta: f64| -> Result<(Identification, Vec<crate::plants::Run>)> {
        // A failure here is the true plant's under these settings, not an identified model's.
        let runs = dataset(&plant, o.runs, o.samples, o.tau, eta, o.seed).map_err(|e| {
            Error::InvalidData(format!(
                "the true throttle (Patm = {patm} Pa) cannot be simulated to make the data: {e}"
            ))
        })?;
        Ok((run_identify(&runs, o.degree, None)?, runs))
    };
    // The noise-free and the noisy searches are independent: run them side by side (each one's
    // candidate scoring is uneven, one order often taking most of the time). The fixed n = 3,
    // d = 1 identification on the noisy runs is independent of both: it follows the noisy one,
    // which finishes well before the noise-free one.
    let fixed = |d: usize, runs: &[crate::plants::Run]| run_identify(runs, d, Some(3));
    let (clean, (noisy_search, d1)) = rayon::join(
        || search(0.0),
        || {
            let r = search(o.noise);
            let d1 = match &r {
                Ok((_, runs)) if o.degree != 1 => Some(fixed(1, runs)),
                _ => None,
            };
            (r, d1)
        },
    );
    for (k, (eta, result)) in [(0.0, clean), (o.noise, noisy_search)]
        .into_iter()
        .enumerate()
    {
        let (id, runs) = result?;
        profile_rows(&mut profile_table, eta, &id.outputs[0]);
        // The second search, also at noise 0 when asked for.
        if k == 1 {
            noisy = Some((id, runs));
        }
    }
    let _ = writeln!(out, "## Error profile per order on the training runs (p_q = percentile(|e|, q) / median(|label|)); the eta-rule chooses on the free-run profiles (held-out gate runs; '-' where a candidate could not be simulated), the 5-fold derivative-domain ones are the paper's, shown beside them\n\n{}", profile_table.markdown());
    tables.push(("profiles".into(), profile_table));
    let (id_noisy, runs) = noisy.expect("the loop above stores the second search");
    let _ = writeln!(
        out,
        "Selected order: {} (noise-free run above, noisy below; the truth is 3).\n",
        id_noisy.outputs[0].order
    );

    // Fixed n = 3 at d = 3 and d = 1: test percentiles against our labels and the true y'''.
    let (test_table, id, d1_model) = fixed_order_tests(o, &id_noisy, d1, &fixed, (&runs, &split))?;
    if let Some(r) = &id.refinement {
        let _ = writeln!(out, "{}", refinement_line(o.degree, r));
    }
    let _ = writeln!(
        out,
        "## Test runs ({}), n = 3\n\n{}",
        o.runs - o.train,
        test_table.markdown()
    );
    tables.push(("test_percentiles".into(), test_table));

    // The equation against the truth.
    if let Some(t) = equation_section(&mut out, o, &id, truth.as_ref()) {
        tables.push(("coefficients".into(), t));
    }

    // Derivatives against the truth on the test runs.
    let dt = derivatives_table(&id, &runs, &split);
    let _ = writeln!(out, "## Reconstructed derivatives against the true ones (test runs, normalised by median |truth|)\n\n{}", dt.markdown());
    tables.push(("derivatives".into(), dt));

    // Free-run simulation.
    let (st, div) = simulation_table(&id, &runs);
    let _ = writeln!(
        out,
        "## Free-run simulation ({} test runs, {} diverged)\n\n{}",
        id.simulations.len(),
        div,
        st.markdown()
    );
    tables.push(("simulation".into(), st));

    let (feedback_plot, tracking_plot) = control_sections(
        &mut out,
        &mut tables,
        o,
        (&plant, truth.as_ref()),
        (&id.model, d1_model.as_ref()),
    );
    let _ = writeln!(
        out,
        "Sample weighting: {}.\nTotal time {:.1} s.",
        id.weighting,
        t_all.elapsed().as_secs_f64()
    );

    if let Some(dir) = &o.out {
        let svgs = [
            ("feedback_step.svg", feedback_plot),
            ("tracking_profile_law.svg", tracking_plot),
        ];
        write_report(dir, &out, &tables, &svgs)?;
        plots(dir, &id, &runs, split.test[0], o.tau)?;
    }
    Ok(out)
}

/// The n = 3 identifications at the demo's degree and at d = 1 (the search's own result when it
/// selected n = 3, `d1` when it was run beside the search, else `fixed(d, runs)`): their test
/// percentiles against our labels and the true y''' beside the paper's row, the identification
/// at the demo's degree and the d = 1 model.
#[allow(clippy::type_complexity)]
fn fixed_order_tests(
    o: &EtcOptions,
    id_noisy: &Identification,
    mut d1: Option<Result<Identification>>,
    fixed: &dyn Fn(usize, &[crate::plants::Run]) -> Result<Identification>,
    (runs, split): (&[crate::plants::Run], &Split),
) -> Result<(Table, Identification, Option<crate::model::Model>)> {
    let q = profile::headers("");
    let mut head = vec!["model", "against"];
    head.extend(q.iter().map(String::as_str));
    let mut test_table = Table::new(&head);
    test_table.row(
        std::iter::once("paper (n = 3, d = 3)".into())
            .chain(std::iter::once("its own labels".into()))
            .chain(PAPER_TEST.iter().map(|v| format!("{v:.2}")))
            .collect(),
    );
    let mut main_id = None;
    let mut d1_model = None;
    for d in [o.degree, 1] {
        // When the search selected n = 3, its result is the n = 3, d = degree identification
        // (same runs, same order-3 derivatives, same fit and refinement): no need to repeat it.
        let id = if d == o.degree && id_noisy.outputs[0].order == 3 {
            id_noisy.clone()
        } else if let Some(done) = d1.take_if(|_| d == 1) {
            done?
        } else {
            fixed(d, runs)?
        };
        let own = id.outputs[0]
            .test
            .expect("the demo has test runs (check_runs)");
        test_table.row(
            [format!("ours (n = 3, d = {d})"), "our labels".into()]
                .into_iter()
                .chain(prof_cells(&own))
                .collect(),
        );
        let vs_truth = profile_vs_true_label(&id, runs, split);
        test_table.row(
            [format!("ours (n = 3, d = {d})"), "true y'''".into()]
                .into_iter()
                .chain(prof_cells(&vs_truth))
                .collect(),
        );
        if d == 1 {
            d1_model = Some(id.model.clone());
        }
        if d == o.degree {
            main_id = Some(id);
        }
    }
    Ok((
        test_table,
        main_id.expect("the loop covers the demo's degree"),
        d1_model,
    ))
}

/// The columns of the error-profile table (one row per data set and candidate order).
fn profile_table() -> Table {
    let q = profile::headers("train");
    let mut head = vec!["data", "order n", "n terms"];
    head.extend(q.iter().map(String::as_str));
    head.extend([
        "5-fold p95",
        "5-fold p100",
        "free-run p95",
        "free-run p100",
        "selected",
    ]);
    Table::new(&head)
}

/// The refinement's verdict in one line of the report.
fn refinement_line(degree: usize, r: &crate::identify::RefinementReport) -> String {
    format!(
        "Refinement on free-run simulation error (n = 3, d = {}): {} ({}; gate: {}, NRMSE {:.4} -> {:.4}; {} iterations, {:.1} s).\n",
            degree,
            if r.kept { "kept" } else { "refused" },
            r.message,
            r.gate,
            r.validation_before.first().copied().unwrap_or(f64::NAN),
            r.validation_after.first().copied().unwrap_or(f64::NAN),
            r.iterations,
            r.seconds
    )
}

/// One row per candidate order of an identification's output (`eta` its noise level) in the
/// profile table.
fn profile_rows(table: &mut Table, eta: f64, rep: &crate::identify::OutputReport) {
    for c in &rep.candidates {
        let mut row = vec![
            if eta == 0.0 {
                "noise-free".to_string()
            } else {
                format!("{} % noise", eta * 100.0)
            },
            c.order.to_string(),
            c.n_terms.to_string(),
        ];
        row.extend(prof_cells(&c.train));
        row.push(format!("{:.3}", c.validation.p95()));
        row.push(format!("{:.3}", c.validation.p100()));
        for v in [
            c.simulation.as_ref().map(|s| s.p95()),
            c.simulation.as_ref().map(|s| s.p100()),
        ] {
            row.push(
                v.filter(|v| v.is_finite())
                    .map_or("-".into(), |v| format!("{v:.3}")),
            );
        }
        row.push(if c.order == rep.order {
            "<- selected".into()
        } else {
            String::new()
        });
        table.row(row);
    }
}

/// The feedback designed on the identified model and the paper's closed-loop experiment with
/// the d = 1 model, both run around the true plant: their report sections and tables, and the
/// plots (`None` where a design failed, which the report says).
fn control_sections(
    out: &mut String,
    tables: &mut Vec<(String, Table)>,
    o: &EtcOptions,
    (plant, truth): (&Plant, Option<&crate::model::Model>),
    (model, d1): (&crate::model::Model, Option<&crate::model::Model>),
) -> (Option<String>, Option<String>) {
    // Feedback designed on the identified model, run around the true plant. The sensor noise is
    // the data's relative level applied to the step (the data's own level, relative to swings of
    // tens of radians at Patm = 0, would bury a 0.5 rad step).
    // A model the design cannot use is a finding of the report, not a failure of the demo.
    let feedback_plot = report_section(
        (out, tables),
        "feedback",
        feedback(plant, model, truth, o.tau, o.noise * STEP, o.seed),
        "## Feedback designed on the identified model\n\nNot designed",
    );
    // The paper's closed-loop experiment: the d = 1 model in both laws, on the true plant.
    let tracking_plot = d1.and_then(|m1| {
        report_section(
            (out, tables),
            "tracking",
            paper_tracking(plant, m1, o.seed),
            "## The paper's closed-loop experiment\n\nNot run",
        )
    });
    (feedback_plot, tracking_plot)
}

/// A closed-loop section of the report: its text, its table under `name` and its plot, or where
/// it failed, `failed` and the reason (a finding of the report, not a failure of the demo).
fn report_section(
    (out, tables): (&mut String, &mut Vec<(String, Table)>),
    name: &str,
    result: Result<(String, Table, String)>,
    failed: &str,
) -> Option<String> {
    match result {
        Ok((text, table, plot)) => {
            let _ = writeln!(*out, "{text}");
            tables.push((name.into(), table));
            Some(plot)
        }
        Err(e) => {
            let _ = writeln!(*out, "{failed}: {e}.\n");
            None
        }
    }
}

/// Refuses a noise, degree, run split or atmospheric pressure the demo cannot use.
fn check(o: &EtcOptions) -> Result<()> {
    crate::util::finite_nonneg("noise", o.noise)?;
    crate::basis::check_degree(o.degree)?;
    super::check_runs(o.train, o.runs)?;
    crate::util::finite_nonneg("patm", o.patm)?;
    if o.patm > PATM_MAX {
        return Err(Error::param(
            "patm",
            format!("{:e} Pa is beyond any air pressure a throttle sees; give 0 to {PATM_MAX:e} Pa (the atmosphere is 101325 Pa)", o.patm),
        ));
    }
    Ok(())
}

/// The report's title and the experiment's settings.
fn header(o: &EtcOptions, patm: f64) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# Electronic throttle (the source paper's experiment)\n"
    );
    let _ = writeln!(
        out,
        "{} runs x {} samples, tau = {} s, {} train / {} test, noise {} % and 0 %, degree {}, seed {}, Patm = {} Pa{}.",
        o.runs,
        o.samples,
        o.tau,
        o.train,
        o.runs - o.train,
        o.noise * 100.0,
        o.degree,
        o.seed,
        patm,
        if o.physical { " (preset physical: excitation scaled so the angle stays within [0, pi/2])" } else { "" }
    );
    if !o.physical && patm == 0.0 {
        let _ = writeln!(out, "Patm defaults to 0 Pa: with the paper's printed parameters the angle swings tens of radians from rest, and with Patm = 101325 Pa the aerodynamic term (pi - y) cos^2(y) would dominate y'''. Give --patm to change it.");
    }
    let _ = writeln!(out);
    out
}

/// The identified equation, the true one and the coefficient table (returned; `None` without a
/// polynomial truth).
fn equation_section(
    out: &mut String,
    o: &EtcOptions,
    id: &Identification,
    truth: Option<&crate::model::Model>,
) -> Option<Table> {
    let _ = writeln!(
        *out,
        "## Identified equation ({} % noise, n = 3, d = {})\n\n    {}\n",
        crate::util::num4(100.0 * o.noise),
        o.degree,
        id.model.outputs[0].to_text()
    );
    if let Some(tm) = truth {
        let _ = writeln!(
            *out,
            "True equation (Patm = 0):\n\n    {}\n",
            tm.outputs[0].to_text()
        );
        let (rows, extra) = coefficient_errors(&id.model, tm, 0);
        let mut t = Table::new(&["term", "true", "identified", "relative error"]);
        for (m, tc, c, e) in rows {
            t.row(vec![
                m,
                format!("{tc:.5e}"),
                format!("{c:.5e}"),
                format!("{:+.2} %", 100.0 * e),
            ]);
        }
        let _ = writeln!(
            *out,
            "{}\nTerms not in the truth: {}\n",
            t.markdown(),
            if extra.is_empty() {
                "none".into()
            } else {
                extra.join(", ")
            }
        );
        Some(t)
    } else {
        let _ = writeln!(
            *out,
            "(No polynomial truth at Patm > 0: the aerodynamic term is not a polynomial.)\n"
        );
        None
    }
}

/// The reconstructed derivatives against the true ones on the test runs: profile and 2-sigma
/// coverage per derivative.
fn derivatives_table(id: &Identification, runs: &[crate::plants::Run], split: &Split) -> Table {
    let mut dt = Table::new(&["derivative", "p50", "p95", "p100", "2-sigma coverage"]);
    for k in 0..=3 {
        let est: Vec<&[f64]> = split
            .test
            .iter()
            .map(|&r| id.derivatives[0][r].values[k].as_slice())
            .collect();
        let tru: Vec<&[f64]> = split
            .test
            .iter()
            .map(|&r| runs[r].derivatives[0][k].as_slice())
            .collect();
        let p = truth_profile(&est, &tru);
        let (mut inside, mut all) = (0usize, 0usize);
        for &r in &split.test {
            let d = &id.derivatives[0][r];
            for i in 0..d.values[k].len() {
                all += 1;
                inside += ((d.values[k][i] - runs[r].derivatives[0][k][i]).abs()
                    <= 2.0 * d.sigma[k][i]) as usize;
            }
        }
        dt.row(vec![
            if k == 0 {
                "y".into()
            } else {
                format!("y_d{k}")
            },
            format!("{:.4}", p[0]),
            format!("{:.4}", p[1]),
            format!("{:.4}", p[2]),
            format!("{:.3}", inside as f64 / all as f64),
        ]);
    }
    dt
}

/// The free-run NRMSE on the test runs against the true output and the measurement, and how
/// many runs diverged.
fn simulation_table(id: &Identification, runs: &[crate::plants::Run]) -> (Table, usize) {
    let (med, max, pooled, div) = nrmse_vs_truth(id, runs, 0);
    let meas: Vec<f64> = id
        .simulations
        .iter()
        .filter(|s| s.error.is_none())
        .map(|s| s.nrmse[0])
        .collect();
    let mut st = Table::new(&[
        "free-run simulation on test runs",
        "median",
        "max",
        "pooled",
    ]);
    st.row(vec![
        "NRMSE against the true output".into(),
        format!("{:.3} %", 100.0 * med),
        format!("{:.3} %", 100.0 * max),
        format!("{:.3} %", 100.0 * pooled),
    ]);
    st.row(vec![
        "NRMSE against the measurement".into(),
        format!("{:.3} %", 100.0 * percentile(&meas, 50.0)),
        format!("{:.3} %", 100.0 * meas.iter().cloned().fold(0.0, f64::max)),
        "-".into(),
    ]);
    (st, div)
}

/// `report.md`, every table as markdown and CSV, and the SVGs that were made.
fn write_report(
    dir: &std::path::Path,
    out: &str,
    tables: &[(String, Table)],
    svgs: &[(&str, Option<String>)],
) -> Result<()> {
    write_file(dir, "report.md", out)?;
    for (name, t) in tables {
        write_file(dir, &format!("{name}.md"), &t.markdown())?;
        write_file(dir, &format!("{name}.csv"), &t.csv())?;
    }
    for (name, svg) in svgs {
        if let Some(p) = svg {
            write_file(dir, name, p)?;
        }
    }
    Ok(())
}

/// Test profile of the fixed-order model against the true y''' (same sample mask as our labels).
fn profile_vs_true_label(
    id: &Identification,
    runs: &[crate::plants::Run],
    split: &Split,
) -> Profile {
    let Ok(c) = id.model.compile() else {
        return Profile([f64::NAN; 7]);
    };
    let n = id.model.outputs[0].order;
    let all_sig: Vec<f64> = split
        .train
        .iter()
        .flat_map(|&r| id.derivatives[0][r].sigma[n].iter().copied())
        .collect();
    let sref = percentile(&all_sig, 50.0);
    let (mut e, mut l) = (Vec::new(), Vec::new());
    let mut z = vec![0.0; n + 1];
    for &r in &split.test {
        let d = &id.derivatives[0][r];
        for i in 0..d.values[0].len() {
            if d.sigma[n][i] > 5.0 * sref {
                continue;
            }
            for k in 0..n {
                z[k] = d.values[k][i];
            }
            z[n] = runs[r].u[0][i];
            let truth = runs[r].derivatives[0][n][i];
            e.push(truth - c.eval_output_unchecked(0, &z));
            l.push(truth);
        }
    }
    Profile::new(&e, &l)
}

fn plots(
    dir: &std::path::Path,
    id: &Identification,
    runs: &[crate::plants::Run],
    r: usize,
    _tau: f64,
) -> Result<()> {
    let run = &runs[r];
    let t = &run.t;
    let s = |label, y, color| svg::Series {
        label,
        x: t,
        y,
        color,
        band: None,
        dashed: false,
    };
    write_file(
        dir,
        "excitation.svg",
        &svg::line_plot(
            &format!("Excitation, test run {r}"),
            "t (s)",
            "u",
            &[s("u", &run.u[0], "black")],
        ),
    )?;
    write_file(
        dir,
        "measurement.svg",
        &svg::line_plot(
            &format!("Measurement, test run {r}"),
            "t (s)",
            "y (rad)",
            &[
                s("measured", &run.y[0], "gray"),
                s("true", &run.y_true[0], "black"),
            ],
        ),
    )?;
    let d = &id.derivatives[0][r];
    for k in 1..=3 {
        let lo: Vec<f64> = (0..t.len())
            .map(|i| d.values[k][i] - 2.0 * d.sigma[k][i])
            .collect();
        let hi: Vec<f64> = (0..t.len())
            .map(|i| d.values[k][i] + 2.0 * d.sigma[k][i])
            .collect();
        let est = svg::Series {
            label: "estimate +- 2 sigma",
            x: t,
            y: &d.values[k],
            color: "steelblue",
            band: Some((&lo, &hi)),
            dashed: false,
        };
        let tru = svg::Series {
            label: "truth",
            x: t,
            y: &run.derivatives[0][k],
            color: "black",
            band: None,
            dashed: true,
        };
        // The true derivatives spike at the run's start (the plant leaves rest under a step):
        // the y window follows the bulk, or the estimate is a flat line under the spike.
        let panel = svg::Panel::lines("", "t (s)", &format!("y_d{k}"), vec![est, tru]).bulk_y();
        write_file(
            dir,
            &format!("derivative_{k}.svg"),
            &svg::figure(&format!("y_d{k}, test run {r}"), &[panel.height(384.0)]),
        )?;
    }
    if let Some(sim) = id
        .simulations
        .iter()
        .find(|x| x.run == r.to_string() && x.error.is_none())
    {
        let model = &sim.simulated[0];
        let error: Vec<f64> = model
            .iter()
            .zip(&run.y_true[0])
            .map(|(a, b)| a - b)
            .collect();
        let title = format!(
            "Free-run simulation, test run {r}: fit {:.1} % against the measurement, {:.2} % against the truth",
            crate::metrics::fit_percent(model, &run.y[0]),
            crate::metrics::fit_percent(model, &run.y_true[0])
        );
        let traces = vec![
            s("measured", &run.y[0], "#aaaaaa"),
            s("true", &run.y_true[0], "black"),
            svg::Series {
                label: "simulated model",
                x: t,
                y: model,
                color: "#d62728",
                band: None,
                dashed: true,
            },
        ];
        let panels = [
            svg::Panel::lines("free run", "t (s)", "y (rad)", traces),
            svg::Panel::lines(
                "simulated minus true output",
                "t (s)",
                "y error (rad)",
                vec![s("error", &error, "#d62728")],
            )
            .height(200.0),
        ];
        let plot = svg::figure(&title, &panels);
        write_file(dir, "simulation.svg", &plot)?;
    }
    Ok(())
}

/// The setpoint step of the feedback section, in rad (closing the plate).
const STEP: f64 = 0.5;

/// Closing the plate by [`STEP`] from rest (u = 0) under feedback designed on `model` at the
/// controller sampling `tau`: the loop around the model itself (the design check) and around
/// the true plant, with measurement noise `noise_sd`; and, when the truth is polynomial, the
/// same design made on the true model, around the true plant. Report text and table.
fn feedback(
    plant: &Plant,
    model: &crate::model::Model,
    truth: Option<&crate::model::Model>,
    tau: f64,
    noise_sd: f64,
    seed: u64,
) -> Result<(String, Table, String)> {
    use crate::control::{self, format_poles, DesignOptions, Scenario};
    let x_rest = plant.rest_state();
    let from = x_rest[0];
    let setpoint = from - STEP;
    let o = DesignOptions::new(setpoint, tau);
    let ours = control::design(model, &o)?;
    let mut t = Table::new(&[
        "designed on",
        "plant",
        "noise sd (rad)",
        "rise 10-90 % (s)",
        "overshoot %",
        "settling 2 % (s)",
        "final error % of step",
        "largest difference from the designed response, % of step",
        "input range",
    ]);
    let row = |t: &mut Table,
               d: &control::Design,
               on: &str,
               name: &str,
               p: &control::Plant,
               noise: f64|
     -> Result<control::Trace> {
        let scenario = Scenario {
            duration: control::default_duration(&ours),
            noise_sd: noise,
            seed,
            u_limits: None,
        };
        let tr = control::run(d, p, &scenario)?;
        let m = control::metrics(&tr, d, from)?;
        t.row(vec![
            on.into(),
            name.into(),
            format!("{noise:.3}"),
            format!("{:.4}", m.rise_time),
            format!("{:.2}", m.overshoot),
            format!("{:.4}", m.settling_time),
            format!("{:+.3}", m.final_error),
            format!("{:.2}", m.design_deviation),
            format!("{:.4e} .. {:.4e}", m.u_min, m.u_max),
        ]);
        Ok(tr)
    };
    let (own, x_own, u_own) = control::model_at_rest(model, from, ours.u_star)?;
    let own_plant = control::Plant {
        system: &own,
        output: 0,
        x0: x_own,
        u0: u_own,
    };
    let true_plant = control::Plant {
        system: plant.system(),
        output: 0,
        x0: x_rest.clone(),
        u0: 0.0,
    };
    let reference = match truth {
        Some(tm) => {
            let mut ot = o.clone();
            ot.bandwidth = Some(ours.bandwidth);
            Some(control::design(tm, &ot)?)
        }
        None => None,
    };
    let noises = if noise_sd > 0.0 {
        vec![0.0, noise_sd]
    } else {
        vec![0.0]
    };
    // The plot shows the loop that matters: designed on the identified model, around the true
    // plant, with the sensor noise when there is any.
    let mut shown = None;
    for noise in noises {
        row(
            &mut t,
            &ours,
            "identified model",
            "identified model",
            &own_plant,
            noise,
        )?;
        shown = Some(row(
            &mut t,
            &ours,
            "identified model",
            "true plant",
            &true_plant,
            noise,
        )?);
        if let Some(r) = &reference {
            row(&mut t, r, "true model", "true plant", &true_plant, noise)?;
        }
    }
    let tr = shown.expect("at least the noise-free rows run");
    let plot = control::step_plot(
        &ours,
        &tr,
        from,
        "throttle under feedback designed on the identified model: true plant",
        "y (rad)",
        "true plant",
    )?;
    let mut text = format!(
        "## Feedback designed on the identified model\n\nSetpoint {setpoint:.4} rad from rest at {from:.4} rad (u = 0); controller sampled every {tau} s; state feedback with integral action; bandwidth {w:.3} rad/s (the default: the geometric mean of the identified model's open-loop pole magnitudes {ol}), controller poles {cl}, observer poles {ob}; the observer runs the identified (nonlinear) model. The designed response is the linearised model's under the continuous-time law (real poles, setpoint through the integrator: no overshoot). Without noise and with sensor noise of {noise_sd:.3} rad ({pct} % of the step, the data's relative level).\n",
        w = ours.bandwidth,
        ol = format_poles(&ours.open_loop),
        cl = format_poles(&ours.closed_loop),
        ob = format_poles(&ours.observer),
        pct = 100.0 * noise_sd / STEP,
    );
    if let Some(r) = &reference {
        let _ = writeln!(
            text,
            "The true model's poles are {}; the same bandwidth on it gives the reference rows.\n",
            format_poles(&r.open_loop)
        );
    }
    let _ = writeln!(text, "{}", t.markdown());
    Ok((text, t, plot))
}

/// The paper's closed-loop settings: controller sampling (s), blocking, input saturation.
const PAPER_TAU: f64 = 0.8e-3;
const PAPER_BLOCK: usize = 3;
const PAPER_U_MAX: f64 = 0.15;

/// The source paper's closed-loop experiment: the degree-1 model in the controller, sampled
/// every 0.8 ms, the input decided every 3 samples and saturated at +-0.15, the 5 s scenario of
/// steps and ramps (between rest and rest - [`STEP`]), around the true plant; the pole
/// placement (linearised observer) beside the paper's exponential-profile law (chain observer,
/// sigma = the placement's bandwidth). Report text, table and the profile law's plot.
fn paper_tracking(
    plant: &Plant,
    model: &crate::model::Model,
    seed: u64,
) -> Result<(String, Table, String)> {
    use crate::control::{self, DesignOptions, Law, ProfileLaw, Reference, Scenario, Tracking};
    let x_rest = plant.rest_state();
    let from = x_rest[0];
    let reference = Reference::steps_and_ramps(from, from - STEP, 5.0)?;
    let mid = from - 0.5 * STEP;
    let d = control::design(model, &DesignOptions::new(mid, PAPER_TAU))?;
    let mut d_chain = d.clone();
    d_chain.l = control::chain_observer_gains(d.order, d.observer_speed * d.bandwidth);
    let true_plant = control::Plant {
        system: plant.system(),
        output: 0,
        x0: x_rest.clone(),
        u0: 0.0,
    };
    let limits = Some((-PAPER_U_MAX, PAPER_U_MAX));
    let scenario = Scenario {
        duration: 5.0,
        noise_sd: 0.0,
        seed,
        u_limits: limits,
    };
    let mut t = Table::new(&[
        "law",
        "observer",
        "tracking RMS (rad)",
        "on ramps (rad)",
        "overshoot % (worst step)",
        "settling 2 % (s, longest)",
        "saturated samples",
        "input reversals per s",
        "computation per decision (us)",
    ]);
    let laws = [
        ("pole placement", "linearised", &d, Law::PolePlacement),
        (
            "exponential profile",
            "chain",
            &d_chain,
            Law::Profile(ProfileLaw { sigma: d.bandwidth }),
        ),
    ];
    let mut plot = String::new();
    for (name, observer, design, law) in laws {
        let tk = Tracking {
            reference: reference.clone(),
            law,
            block: PAPER_BLOCK,
        };
        let tr = control::track(design, &true_plant, &scenario, &tk)?;
        let m = control::tracking_metrics(&tr.t, &tr.y, &tr.u, &reference, limits);
        let f = |v: f64| {
            if v.is_nan() {
                "-".into()
            } else {
                format!("{v:.4}")
            }
        };
        t.row(vec![
            name.into(),
            observer.into(),
            format!("{:.3e}", m.rms),
            format!("{:.3e}", m.rms_ramps),
            f(m.overshoot),
            f(m.settling_time),
            m.saturated.to_string(),
            format!("{:.1}", m.reversals_per_s),
            format!("{:.1}", 1e6 * tr.decision_seconds),
        ]);
        if matches!(law, Law::Profile(_)) {
            plot = control::tracking::tracking_plot(
                &tr,
                "throttle: the paper's scenario under the exponential-profile law (d = 1 model, true plant)",
                "y (rad)",
                "u",
            );
        }
    }
    let text = format!(
        "## The paper's closed-loop experiment\n\nThe degree-1 model (n = 3) in the controller, sampled every {PAPER_TAU} s, the input decided every {PAPER_BLOCK} samples and saturated at +-{PAPER_U_MAX}; the reference: steps and ramps between {from:.4} and {:.4} rad over 5 s; the true plant, no noise. Pole placement with its linearised observer (bandwidth {:.3} rad/s) beside the paper's exponential-profile law (sigma = {:.3} 1/s) with the chain-of-integrators observer (poles at {:.3}). Computation per decision is this machine's wall-clock time (the paper: 1.3 s for its 5 s run).\n\n{}",
        from - STEP,
        d.bandwidth,
        d.bandwidth,
        -d.observer_speed * d.bandwidth,
        t.markdown()
    );
    Ok((text, t, plot))
}
