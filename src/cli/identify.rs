//! `ctsid identify`: the main job on measured data.

use clap::Args;
use ctsid::identify::complete::Trial;
use ctsid::identify::split::{count_names, parse_list};
use ctsid::identify::{identify, Identification, Orders, OutputReport, Settings, Split};
use ctsid::model::Interpolation;
use ctsid::regression::EngineChoice;
use ctsid::report::compare::write_record_report;
use ctsid::report::{write_file, Table};
use ctsid::{Error, Result};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// CSV file with a header row.
    pub data: PathBuf,
    /// Output channel(s), comma separated.
    #[arg(long, value_delimiter = ',', required = true, value_parser = super::trimmed)]
    pub output: Vec<String>,
    /// Input channel(s), comma separated.
    #[arg(long, value_delimiter = ',', value_parser = super::trimmed)]
    pub input: Vec<String>,
    /// Run (experiment) id column.
    #[arg(long)]
    pub run_column: Option<String>,
    #[command(flatten)]
    pub sampling: super::runs::SamplingArgs,
    /// Omitted lists: training = every run not in validation or test; no validation runs =
    /// 5-fold over the training runs; no test runs.
    #[command(flatten)]
    pub split: super::runs::SplitArgs,
    #[command(flatten)]
    pub segment: super::runs::SegmentArgs,
    /// Candidate orders searched with the eta-rule, like `1..4` or `1,2,3`.
    #[arg(long, default_value = "1..4", conflicts_with = "order")]
    pub orders: String,
    /// Fixed order per output, comma separated.
    #[arg(long, value_delimiter = ',')]
    pub order: Option<Vec<usize>>,
    /// Largest monomial degree.
    #[arg(long)]
    pub degree: usize,
    /// eta of the eta-rule.
    #[arg(long, default_value_t = 1.2)]
    pub eta: f64,
    /// Sweep engine: auto, cpu or gpu.
    #[arg(long, default_value = "auto")]
    pub engine: EngineChoice,
    /// Structure search along which eBIC chooses the terms.
    #[arg(long, value_enum, default_value_t = super::regress::MethodArg::ForwardOls)]
    pub method: super::regress::MethodArg,
    /// Write the model file here.
    #[arg(short = 'o', long)]
    pub output_model: Option<PathBuf>,
    /// Write tables and plots into this folder.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// No progress lines (they are shown only when standard error is a terminal anyway).
    #[arg(long)]
    pub quiet: bool,
    /// A named candidate term beside the monomials, for every output (repeatable), e.g.
    /// `--term 'sign(y_d1)' --term 'abs(y_d1)*y_d1'`; functions: sign abs sqrt tanh sin cos exp
    /// sat relu.
    #[arg(long)]
    pub term: Vec<String>,
    /// How the inputs are read between samples when the model is simulated: linear, cubic
    /// (a natural spline, for band-limited inputs sampled a few times their bandwidth) or hold
    /// (zero-order hold); written into the model file.
    #[arg(long, default_value = "linear", value_parser = parse_interpolation)]
    pub input_interpolation: Interpolation,
    /// Leave out the hard limits read from an output the training runs hold at its extreme
    /// value (an overflowing level, an end stop) for five samples or more.
    #[arg(long)]
    pub no_limits: bool,
}

fn parse_interpolation(text: &str) -> std::result::Result<Interpolation, String> {
    text.parse()
}

fn parse_orders(text: &str) -> Result<Vec<usize>> {
    let t = text.replace("..", "-");
    // Counted before any range is spelled out (`1..9999999` expanded ten million strings); a
    // shorter list goes on to the settings' check, which names a repeated or too high order.
    if count_names(&t, "orders")? > 64 {
        return Err(Error::param(
            "orders",
            format!(
                "'{text}' names more orders than a search takes (1..={})",
                ctsid::identify::MAX_ORDER
            ),
        ));
    }
    parse_list(&t, "orders")?
        .iter()
        .map(|s| {
            s.parse::<usize>().map_err(|_| {
                Error::param(
                    "orders",
                    format!("'{text}' is not a list of orders like 1..4"),
                )
            })
        })
        .collect()
}

pub fn run(a: IdentifyArgs) -> Result<()> {
    if let Some(o) = &a.output_model {
        super::check_output_file(o, &[a.data.as_ref()])?;
    }
    if let Some(d) = &a.report {
        super::check_output_dir(d)?;
        if let Some(o) = &a.output_model {
            super::check_output_outside_report(o.as_ref(), d)?;
        }
    }
    // Every setting is checked before the data are read.
    let s = settings(&a)?;
    a.segment.check()?;
    let mut columns = a.output.clone();
    columns.extend(a.input.iter().cloned());
    let spec = a.sampling.spec(columns, a.run_column.clone(), None)?;
    let rs = a.segment.apply(super::load_records(&a.data, &spec)?)?;
    let ids: Vec<String> = rs.runs.iter().map(|r| r.id.clone()).collect();
    let given = a.split.resolve(&ids)?;
    let train = given
        .train
        .clone()
        .unwrap_or_else(|| given.unnamed(ids.len()));
    let split = Split::new(
        train,
        given.validation,
        given.test.unwrap_or_default(),
        &ids,
    )?;
    let id = identify(&rs, &split, &s).map_err(|e| a.segment.explain(e))?;
    for n in &id.notes {
        eprintln!("note: {n}");
    }

    let mut text: String = id
        .outputs
        .iter()
        .map(|rep| output_section(&id, rep))
        .collect();
    text += &test_section(&id, &a.output);
    text += &format!("Weighting: {}.\n", id.weighting);
    if let Some(r) = &id.refinement {
        text += &format!("Refinement by free-run simulation error: {}.\n", r.message);
        text += &completion_text(r);
    }
    out!("{text}")?;

    if let Some(path) = &a.output_model {
        id.model_file().write(path)?;
        super::written(format!("model written to {}", path.display()));
    }
    if let Some(dir) = &a.report {
        write_report(dir, &a, &id, (&rs, &ids), &text)?;
        super::written(format!("report written to {}", dir.display()));
    }
    Ok(())
}

/// The completion's trials in words ([`ctsid::identify::complete`]): the moves kept, those the
/// gate runs refused (with their significance and the rule they failed), and how many the
/// linearised screen set aside before any refinement. Empty where nothing was tried (noise-free
/// data, or no held-out run).
fn completion_text(r: &ctsid::identify::RefinementReport) -> String {
    let trials: Vec<&Trial> = r.completion.iter().filter(|t| !t.term.is_empty()).collect();
    if trials.is_empty() {
        return String::new();
    }
    let figures = |t: &Trial| {
        let why = if t.why.is_empty() {
            String::new()
        } else {
            format!(": {}", t.why)
        };
        format!(
            "z {:.1}, gate NRMSE {} -> {}{why}",
            t.z,
            ctsid::util::num4(t.gate_before),
            ctsid::util::num4(t.gate_after)
        )
    };
    let (screened, tried): (Vec<&Trial>, Vec<&Trial>) =
        trials.iter().partition(|t| t.screened_out());
    let list = |kept: bool| -> Vec<String> {
        tried
            .iter()
            .filter(|t| t.kept == kept)
            .map(|t| format!("{} ({})", t.describe(), figures(t)))
            .collect()
    };
    let (kept, refused) = (list(true), list(false));
    let mut text = format!(
        "Completion on simulation error (a term is kept when the gate runs' free runs improve at z >= {} and by {} % of the error above the noise, a removal when they get no significantly worse): ",
        ctsid::identify::complete::Z_KEEP,
        100.0 * ctsid::identify::complete::MIN_GAIN
    );
    // Where the refinement was refused, the trials still start from a refined model (a term
    // the refinement lacked can be what it needed), so a trial's "before" is that model's gate
    // NRMSE, not the written one's; the completed model must also beat the written one.
    let start = tried.first().map(|t| t.gate_before);
    if let (false, Some(start)) = (r.kept, start) {
        text += &format!(
            "(the refinement was refused: the trials start from the model refined anyway, gate NRMSE {}; a completed model is kept only where it also beats the model as fitted, {}) ",
            ctsid::util::num4(start),
            ctsid::util::num4(ctsid::identify::refine::overall(&r.validation_before))
        );
    }
    text += &if kept.is_empty() {
        "none kept".to_string()
    } else {
        format!("kept {}", kept.join("; "))
    };
    if !refused.is_empty() {
        text += &format!("; refused {}", refused.join("; "));
    }
    if !screened.is_empty() {
        text += &format!(
            "; {} more set aside by the linearised screen (too small a predicted gain on the fit runs)",
            screened.len()
        );
    }
    text + ".\n"
}

/// The identification's settings from the arguments, checked.
fn settings(a: &IdentifyArgs) -> Result<Settings> {
    let mut s = Settings::new(a.output.clone(), a.input.clone(), a.degree);
    s.orders = match &a.order {
        Some(o) => Orders::Fixed(o.clone()),
        None => Orders::Search(parse_orders(&a.orders)?),
    };
    s.eta = a.eta;
    s.engine = a.engine;
    s.method = a.method.into();
    s.progress = super::show_progress(a.quiet);
    s.terms = a.term.clone();
    s.input_interpolation = a.input_interpolation;
    s.limits = !a.no_limits;
    s.validate()?;
    Ok(s)
}

/// One output's section of the printed report: the order search's table, the written
/// equation and the notes that explain it.
fn output_section(id: &Identification, rep: &OutputReport) -> String {
    let q = ctsid::identify::profile::headers("validation");
    let mut head = vec!["order", "terms"];
    head.extend(q.iter().map(String::as_str));
    head.extend(["free-run p95", "free-run p100", "selected"]);
    let mut t = Table::new(&head);
    let cell = |v: f64| {
        if v.is_finite() {
            ctsid::util::num4(v)
        } else {
            "-".into()
        }
    };
    for c in &rep.candidates {
        let mut row = vec![c.order.to_string(), c.n_terms.to_string()];
        row.extend(c.validation.0.iter().map(|&v| cell(v)));
        let sim = c.simulation.as_ref();
        row.push(sim.map_or("-".into(), |s| cell(s.p95())));
        row.push(sim.map_or("-".into(), |s| cell(s.p100())));
        row.push(if c.order == rep.order {
            "<-".into()
        } else {
            String::new()
        });
        t.row(row);
    }
    // The equation printed is the model written with -o (after refinement); the derivative
    // fit it started from is shown beside it when they differ.
    let written = id
        .model
        .outputs
        .iter()
        .find(|o| o.name == rep.name)
        .map(|o| o.to_string())
        .unwrap_or_default();
    let mut text = format!("## Output '{}': order {} ({} samples, {} left out for uncertain labels; engine {})\n\n{}\n    {}\n\n", rep.name, rep.order, rep.samples_used, rep.samples_excluded, rep.engine, t.markdown(), written);
    // What the profiles are: the columns carried no unit, and a reader took them for residuals
    // of y in its own units.
    let label = format!("{}_d{}", rep.name, rep.order);
    text += &format!(
        "Profiles (the paper's error profile): validation pQ is the Q-th percentile of |{label} - fit| over the validation samples, divided by the median |{label}| ({label} from the smoother); free-run pQ the same of the free run's error against the measured '{}' over its median magnitude, where the order was searched on simulation.\n\n",
        rep.name
    );
    if let Some(r) = id.refinement.as_ref().filter(|r| r.kept) {
        // The refinement's figures are of all outputs together: under each output they read
        // as that output's.
        let how = if id.model.outputs.len() > 1 {
            "refined with the other outputs: the joint figures are at the end".to_string()
        } else {
            r.message.clone()
        };
        text += &format!(
            "Refinement on free-run error changed the derivative fit\n    {}\ninto the model above ({how}).\n\n",
            rep.equation
        );
    }
    if rep.candidates.iter().any(|c| c.simulation.is_some()) {
        // Held-out runs where there were any; with one training run and no validation runs the
        // free runs were of the training run itself, and the text says so.
        let proxy = id
            .refinement
            .as_ref()
            .is_some_and(|r| r.gate == ctsid::identify::PROXY_GATE);
        let on = if proxy {
            "simulation of the training run itself, as no run was held out"
        } else {
            "simulation on held-out runs"
        };
        // The rule in full: "the lowest order wins" alone did not say why order 1 beat an order 2
        // of lower p95 (within eta of it, the MIMO search takes the lowest order).
        let eta = id.provenance["eta"].as_f64().unwrap_or(f64::NAN);
        let rule = if id.model.outputs.len() > 1 {
            format!("of the orders whose free-run p100 is within eta = {eta} times the best, the lowest whose p95 is within eta times the smallest")
        } else {
            format!("of the orders whose free-run p100 is within eta = {eta} times the best, the one of smallest p95, the lowest of equals")
        };
        text += &format!("The eta-rule chose on the free-run profiles ({on}): {rule} (errors below {} count as equal); the derivative-domain validation profiles are shown beside them.\n\n", ctsid::identify::FREE_RUN_RESOLUTION);
    }
    if rep
        .candidates
        .iter()
        .any(|c| !c.validation.p50().is_finite())
    {
        text += "No derivative validation profile: without --validation runs it is 5-fold over the training runs, and one training run gives no folds (the free-run refinement gate then uses the training runs themselves); a long record cut into runs with --segment SECONDS gives folds and held-out runs.\n\n";
    }
    if let Some(p) = &rep.test {
        text += &format!(
            "Test runs, against our labels: p50/80/90/95/98/99/100 = {} (the same profile: |{label} - fit| over the median |{label}|)\n\n",
            p.compact()
        );
    }
    text
}

/// The free runs on the test runs, per run and output (empty without test runs).
fn test_section(id: &Identification, outputs: &[String]) -> String {
    if id.simulations.is_empty() {
        return String::new();
    }
    let mut t = Table::new(&["test run", "output", "RMS", "NRMSE"]);
    for sim in &id.simulations {
        match &sim.error {
            Some(e) => t.row(vec![
                sim.run.clone(),
                "-".into(),
                "-".into(),
                format!("diverged: {e}"),
            ]),
            None => {
                for (o, name) in outputs.iter().enumerate() {
                    t.row(vec![
                        sim.run.clone(),
                        name.clone(),
                        format!("{:.4e}", sim.rms[o]),
                        format!("{:.2} %", 100.0 * sim.nrmse[o]),
                    ]);
                }
            }
        }
    }
    // Diverged runs have no error to pool: the heading says over how many runs it is, and a
    // test part where every run diverged has no overall figure (it printed `NaN %`).
    let failed = id.simulations.iter().filter(|s| s.error.is_some()).count();
    let total = id.simulations.len();
    // Each figure named by its output, and how runs are combined: `simulate`'s `all` row pools
    // the runs' samples instead (2.03 % against 2.12 % on the same runs), and three bare
    // figures did not say which output each was.
    let overall: Vec<String> = id
        .test_nrmse()
        .iter()
        .zip(outputs)
        .map(|(v, name)| format!("{:.2} % ({name})", 100.0 * v))
        .collect();
    let overall = format!("{}, root mean square over the runs", overall.join(", "));
    let heading = match failed {
        0 => format!("overall NRMSE {overall}"),
        1 if total == 1 => "the test run diverged".to_string(),
        f if f == total => format!("all {total} test runs diverged"),
        f => format!(
            "overall NRMSE {overall} over the {} of {total} test runs that did not diverge",
            total - f
        ),
    };
    format!(
        "## Free-run simulation on test runs ({heading})\n\n{}\n",
        t.markdown()
    )
}

/// `--report DIR`: the printed text, then figures and residual tests of the test runs' free runs.
fn write_report(
    dir: &std::path::Path,
    a: &IdentifyArgs,
    id: &Identification,
    (rs, ids): (&ctsid::records::RecordSet, &[String]),
    text: &str,
) -> Result<()> {
    let runs: Vec<(usize, &[Vec<f64>])> = id
        .simulations
        .iter()
        .filter(|s| s.error.is_none())
        .filter_map(|s| Some((ids.iter().position(|i| *i == s.run)?, &s.simulated[..])))
        .collect();
    let outputs: Vec<&str> = a.output.iter().map(String::as_str).collect();
    let inputs: Vec<&str> = a.input.iter().map(String::as_str).collect();
    let table = if runs.is_empty() {
        "No test run was simulated (none given with --test, or each diverged); for test data in a separate file, `ctsid simulate MODEL DATA --report DIR` writes these figures.\n".to_string()
    } else {
        write_record_report(dir, rs, &outputs, &inputs, "model", &runs, 0)?
    };
    let text = format!(
        "{text}\n## Free runs on the test runs\n\nFit = 100 (1 - NRMSE); residual tests at 99 % (see `ctsid simulate --report`).\n\n{table}"
    );
    write_file(dir, "report.md", &text)
}
