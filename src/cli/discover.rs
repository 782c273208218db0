//! `ctsid discover`: the missing-physics workflow on measured runs (see `ctsid::discover`).

use clap::Args;
use ctsid::discover::{discover, Options};
use ctsid::identify::Split;
use ctsid::model::Model;
use ctsid::report::write_file;
use ctsid::{Error, Result};
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct DiscoverArgs {
    /// CSV file with a header row.
    pub data: PathBuf,
    /// The nominal model file (ctsid-model/2 or /1, one output).
    #[arg(long)]
    pub nominal: PathBuf,
    /// Run (experiment) id column (without it the file is one run: cut it with --segment).
    #[arg(long)]
    pub run_column: Option<String>,
    #[command(flatten)]
    pub sampling: super::runs::SamplingArgs,
    #[command(flatten)]
    pub segment: super::runs::SegmentArgs,
    /// Omitted lists: training = the first half of the runs, validation = the next quarter,
    /// test = the rest (of the runs no given list names).
    #[command(flatten)]
    pub split: super::runs::SplitArgs,
    /// Prior half-width of a nominal term, `TERM=PCT` (`y_d1=10`, `u=fixed`, `1=approximate`):
    /// the prior of the effect search's weak-form fit and the yardstick of the re-tuned report.
    /// The final refit on simulation error holds only `fixed` (0) terms and frees the others,
    /// however small their confidence.
    #[arg(long)]
    pub confidence: Vec<String>,
    /// Extra dictionary entries, `NAME=EXPRESSION` (`backlash=relu(abs(y)-0.1)*sign(y)`).
    #[arg(long)]
    pub effect: Vec<String>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the augmented model file here.
    #[arg(short = 'o', long)]
    pub output_model: Option<PathBuf>,
    /// Write the evidence (discovery.json, summary.md, and SVG plots: each test run before and
    /// after, the residual along each coordinate) into this folder.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

pub fn run(a: DiscoverArgs) -> Result<()> {
    if let Some(o) = &a.output_model {
        super::check_output_file(o, &[&a.data, &a.nominal])?;
    }
    if let Some(d) = &a.report {
        super::check_output_dir(d)?;
        if let Some(o) = &a.output_model {
            super::check_output_outside_report(o, d)?;
        }
    }
    let mut conf = BTreeMap::new();
    for (c, (t, p)) in a
        .confidence
        .iter()
        .zip(pairs(&a.confidence, "confidence", "TERM=PCT")?)
    {
        let v = match p.as_str() {
            "fixed" => 0.0,
            "approximate" => 1.0,
            s => {
                let v: f64 = s.trim_end_matches('%').parse().map_err(|_| {
                    Error::param(
                        "confidence",
                        format!("'{c}': '{s}' is not a percentage, 'fixed' or 'approximate'"),
                    )
                })?;
                if !(v >= 0.0 && v.is_finite()) {
                    return Err(Error::param(
                        "confidence",
                        format!("'{c}': give a finite percentage >= 0"),
                    ));
                }
                v / 100.0
            }
        };
        if conf.insert(t.clone(), v).is_some() {
            return Err(Error::param("confidence", format!("'{t}' is given twice")));
        }
    }
    let user_effects = pairs(&a.effect, "effect", "NAME=EXPRESSION")?;
    ctsid::discover::dictionary::check_user_names(&user_effects)?;
    a.segment.check()?;
    let nominal = Model::read(&a.nominal)?;
    let mut columns: Vec<String> = nominal.outputs.iter().map(|o| o.name.clone()).collect();
    columns.extend(nominal.inputs.iter().cloned());
    let spec = a.sampling.spec(columns, a.run_column.clone(), None)?;
    let rs = a.segment.apply(super::load_records(&a.data, &spec)?)?;
    super::note_tau_units(rs.tau, nominal.tau, spec.time_column.is_some());
    let names: Vec<String> = rs.runs.iter().map(|r| r.id.clone()).collect();
    let n = names.len();
    let given = a.split.resolve(&names)?;
    let sp = &a.split;
    if n < 3 && (sp.train.is_none() || sp.validation.is_none() || sp.test.is_none()) {
        return Err(Error::param(
            "split",
            format!("{n} run(s); give --train, --validation and --test explicitly (one run each at least), or cut long runs into pieces with --segment SECONDS"),
        ));
    }
    // Omitted lists share, in order, the runs no given list names: training half of them,
    // validation a quarter, test the rest (by these weights among the omitted lists only).
    let mut rest = given.unnamed(n);
    let mut lists = [given.train, given.validation, given.test];
    let list_names = ["train", "validation", "test"];
    // Overlaps first: otherwise they show as an omitted list left empty, which misleads.
    for a_i in 0..3 {
        for b_i in a_i + 1..3 {
            if let (Some(la), Some(lb)) = (&lists[a_i], &lists[b_i]) {
                if let Some(r) = la.iter().find(|r| lb.contains(r)) {
                    return Err(Error::param(
                        "split",
                        format!(
                            "run '{}' is in both {} and {}; splits must not overlap",
                            names[*r], list_names[a_i], list_names[b_i]
                        ),
                    ));
                }
            }
        }
    }
    let weights = [2usize, 1, 1];
    let omitted: Vec<usize> = (0..3).filter(|&i| lists[i].is_none()).collect();
    let mut weight_left: usize = omitted.iter().map(|&i| weights[i]).sum();
    let unnamed = rest.len();
    for (k, &i) in omitted.iter().enumerate() {
        let take = if k + 1 == omitted.len() {
            rest.len()
        } else {
            (rest.len() * weights[i] / weight_left)
                .max(1)
                .min(rest.len())
        };
        if take == 0 {
            let why = if unnamed == 0 {
                format!("the given lists name all {n} runs")
            } else {
                let to: Vec<&str> = omitted[..k].iter().map(|&j| list_names[j]).collect();
                format!(
                    "the {unnamed} run(s) the lists do not name went to {}",
                    to.join(" and ")
                )
            };
            return Err(Error::param(
                list_names[i],
                format!(
                    "no run is left for it ({why}); give --{} explicitly or name fewer runs in the others",
                    list_names[i]
                ),
            ));
        }
        lists[i] = Some(rest.drain(..take).collect());
        weight_left -= weights[i];
    }
    let [train, validation, test] = lists.map(Option::unwrap_or_default);
    // The same checks as identify: non-empty training, no run in two lists.
    let checked = Split::new(train, Some(validation), test, &names)?;
    let (train, validation, test) = (
        checked.train,
        checked.validation.unwrap_or_default(),
        checked.test,
    );
    let mut o = Options::new(train, validation, test);
    o.seed = a.seed;
    o.confidence = conf;
    o.user_effects = user_effects;
    let d = discover(&rs, &nominal, &o).map_err(|e| a.segment.explain(e))?;
    out!("{}", d.text())?;
    if let Some(p) = &a.output_model {
        d.augmented_model(&nominal)?.write(p)?;
        // With no effect added the file is the nominal's equations as written: said, so that a
        // file named 'augmented' is not taken for a found effect.
        let what = match (d.effects.is_empty(), d.retuned.is_empty()) {
            (true, true) => "the nominal's equations: no effect passed the gates",
            (true, false) => "the nominal re-tuned: no effect passed the gates",
            (false, _) => "the nominal with the effects above",
        };
        super::written(format!("model written to {} ({what})", p.display()));
    }
    if let Some(dir) = &a.report {
        let json = serde_json::to_string_pretty(&d)
            .map_err(|e| Error::Numerical(format!("discovery JSON: {e}")))?;
        write_file(dir, "discovery.json", &json)?;
        write_file(dir, "summary.md", &d.text())?;
        for (name, svg) in d.plots() {
            write_file(dir, &name, &svg)?;
        }
    }
    Ok(())
}

/// `KEY=VALUE` arguments as trimmed pairs; `usage` shows the form in the error.
fn pairs(args: &[String], what: &str, usage: &str) -> Result<Vec<(String, String)>> {
    args.iter()
        .map(|a| {
            a.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| Error::param(what, format!("'{a}': use {usage}")))
        })
        .collect()
}
