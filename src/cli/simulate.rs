//! `ctsid simulate MODEL.json DATA.csv [--run-column R] [--tau T] [--time-column C] [--segment S] [-o SIM.csv] [--report DIR]`
//!
//! Simulates every run of a record from an initial state estimated from its first samples, with
//! the inputs interpolated linearly between samples, by the library's one convention
//! (`ctsid::simulate::initial_state`, as identify and discover score models): a least-squares
//! polynomial of degree n+1 on the first max(15, 4(n+2)) samples of each output, differentiated
//! at the first sample, then refined by Levenberg-Marquardt on the model's own simulated outputs
//! over windows that double up to the first `--init-window` samples (default 200), which
//! corrects the fast modes and the noise that a local fit cannot. Prints RMS and NRMSE (RMS error over the
//! standard deviation of the measured output) per run and output, and over all runs (pooled
//! samples); `-o` writes the data with one `<output>_sim` column per output beside it;
//! `--report` writes the figures of [`ctsid::report::compare`] and their summary.
//! The data are read by the shared record loader ([`RecordSet`]): runs, uniform time, one-line
//! errors naming row and column.

use clap::Args;
use ctsid::metrics::rms_nrmse;
use ctsid::model::Model;
use ctsid::report::compare::write_record_report;
use ctsid::report::write_file;
use ctsid::simulate::{free_run, run_data, SimOptions, INIT_WINDOW};
use ctsid::util::num4;
use ctsid::{Error, Result};
use rayon::prelude::*;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Model file (ctsid-model/2 JSON, or /1).
    pub model: String,
    /// Data file (CSV with a header row).
    pub data: String,
    /// Column holding the run id; rows with the same id form one run, in file order (without
    /// it the file is one run).
    #[arg(long)]
    pub run_column: Option<String>,
    #[command(flatten)]
    pub sampling: super::runs::SamplingArgs,
    #[command(flatten)]
    pub segment: super::runs::SegmentArgs,
    /// Samples at the start of each run used to estimate its initial state (at least order + 2;
    /// a local polynomial fit on up to 4 (order + 2) of them, then the model's own free run
    /// fitted on all of them).
    #[arg(long, default_value_t = INIT_WINDOW)]
    pub init_window: usize,
    /// Score each run from this sample on (the public benchmarks leave the samples that set
    /// the initial state out of their RMS); the simulation still covers the whole run.
    #[arg(long, default_value_t = 0)]
    pub score_from: usize,
    /// Where to write the data with the simulated outputs.
    #[arg(short = 'o', long)]
    pub output: Option<String>,
    /// Folder for the report: per run and output, measured against simulated with the fit and
    /// the error (`sim_*.svg`), the residual analysis (`resid_*.svg`), and `report.md`.
    #[arg(long)]
    pub report: Option<std::path::PathBuf>,
    /// How this record's inputs are read between samples: linear, cubic or hold (default: the
    /// model file's, the reading it was identified with; a note says when the record's inputs
    /// look otherwise).
    #[arg(long, value_parser = |t: &str| t.parse::<ctsid::model::Interpolation>())]
    pub input_interpolation: Option<ctsid::model::Interpolation>,
}

pub fn run(args: SimulateArgs) -> Result<()> {
    args.segment.check()?;
    if let Some(d) = &args.report {
        super::check_output_dir(d)?;
        if let Some(o) = &args.output {
            super::check_output_outside_report(o.as_ref(), d)?;
        }
    }
    let mut model = Model::read(&args.model)?;
    if let Some(i) = args.input_interpolation {
        model.input_interpolation = i;
    }
    // The initial state's local fit needs order + 2 samples: a smaller window was raised to the
    // local fit's 16 or more without a word (`--init-window 0` scored as 15).
    let top = model.outputs.iter().map(|o| o.order).max().unwrap_or(1);
    let least = ctsid::simulate::min_init_window(top);
    if args.init_window < least {
        return Err(Error::param(
            "init-window",
            format!(
                "{}: an initial state of order {top} needs at least {least} samples",
                args.init_window
            ),
        ));
    }
    let sim_names: Vec<String> = model
        .outputs
        .iter()
        .map(|o| format!("{}_sim", o.name))
        .collect();
    // The data are read twice only to write them out again with -o; everything that would
    // stop the writing is checked before the simulation.
    if let Some(o) = &args.output {
        super::csvout::check(
            args.data.as_ref(),
            Some(o.as_ref()),
            &[args.model.as_ref()],
            &sim_names,
            "simulate -o",
        )?;
    }
    let compiled = model.compile()?;
    let mut columns: Vec<String> = model.outputs.iter().map(|o| o.name.clone()).collect();
    columns.extend(model.inputs.iter().cloned());
    // Without a time column the model's own tau is the sampling period.
    let spec = args
        .sampling
        .spec(columns, args.run_column.clone(), model.tau)?;
    if spec.time_column.is_none() && args.sampling.tau.is_none() {
        check_time_like_columns(&args.data, &spec, model.tau)?;
    }
    let rs = args
        .segment
        .apply(super::load_records(&args.data, &spec)?)?;
    check_score_from(&rs, args.score_from)?;
    if args.input_interpolation.is_none() {
        note_input_shape(&model, &rs);
    }
    super::note_tau_units(rs.tau, model.tau, spec.time_column.is_some());
    let time_known = spec.time_column.is_some();
    let mut sc = simulate_and_print(&args, (&model, &compiled), &rs, time_known)?;
    // Every run failed: nothing to score, and the first failure is the error.
    if sc.failed.len() == rs.runs.len() {
        return Err(Error::InvalidData(sc.failed.swap_remove(0)));
    }
    for (i, o) in model.outputs.iter().enumerate() {
        let (rms, nrmse) = rms_nrmse(&sc.pooled_sim[i], &sc.pooled_meas[i]);
        sc.constant |= nrmse.is_infinite();
        score_row("all", &o.name, rms, nrmse)?;
    }
    for f in &sc.failed {
        eprintln!("note: not scored, and left out of 'all': {f}");
    }
    if sc.constant {
        eprintln!(
            "note: NRMSE '-': the measured output is constant there, so there is no spread to normalise by; judge by RMS (in the output's units)"
        );
    }
    if let Some(path) = &args.output {
        let out = std::path::Path::new(path);
        super::csvout::write_with_columns(
            std::path::Path::new(&args.data),
            Some(out),
            &rs,
            &sim_names,
            // A failed run's simulated cells are left empty.
            |r, i, k| {
                sc.simulated[r]
                    .as_ref()
                    .map_or(String::new(), |s| format!("{}", s[k][i]))
            },
        )?;
        super::written(format!("wrote {path}"));
    }
    if let Some(dir) = &args.report {
        write_report(dir, &args, &model, &rs, &sc)?;
        super::written(format!("report written to {}", dir.display()));
    }
    Ok(())
}

/// What [`simulate_and_print`] leaves for the pooled row and the files: each run's simulated
/// outputs (`None` where its free run failed, see [`failure_time`]), the failures in words, the
/// scored samples of every output pooled, and whether some measured output was constant.
struct Scored {
    simulated: Vec<Option<Vec<Vec<f64>>>>,
    failed: Vec<String>,
    pooled_sim: Vec<Vec<f64>>,
    pooled_meas: Vec<Vec<f64>>,
    constant: bool,
}

/// Simulates every run (in chunks, in parallel within a chunk) and prints its rows as the chunk
/// ends: rows appear while a long record is still being simulated. A run whose free run fails
/// is the model's property on that run, so the others are still scored (one diverging run of
/// six stopped the command, with nothing written); any other error stops the command.
fn simulate_and_print(
    args: &SimulateArgs,
    (model, compiled): (&Model, &ctsid::model::CompiledModel),
    rs: &ctsid::RecordSet,
    time_known: bool,
) -> Result<Scored> {
    let n_out = model.outputs.len();
    let mut sc = Scored {
        simulated: Vec::with_capacity(rs.runs.len()),
        failed: Vec::new(),
        pooled_sim: vec![Vec::new(); n_out],
        pooled_meas: vec![Vec::new(); n_out],
        constant: false,
    };
    // Run by run rather than `Model::simulate` (all runs at once), from the library's one
    // initial-state convention: the same run data and free run.
    let simulate_run = |run: &ctsid::records::Run| -> Result<Vec<Vec<f64>>> {
        let data = run_data(model, rs, run)?;
        free_run(compiled, &data, args.init_window, &SimOptions::default())
    };
    let chunk = 2 * rayon::current_num_threads().max(1);
    for runs in rs.runs.chunks(chunk) {
        let results: Vec<std::result::Result<Vec<Vec<f64>>, String>> = runs
            .par_iter()
            .map(|run| match simulate_run(run) {
                Ok(sim) => Ok(Ok(sim)),
                Err(e) => match failure_time(&e) {
                    Some(t) => Ok(Err(format!(
                        "{e}{}",
                        file_place(run, t, rs.tau, time_known)
                    ))),
                    None => Err(e),
                },
            })
            .collect::<Result<_>>()
            .map_err(|e| args.segment.explain(e))?;
        // The header once the first runs are simulated.
        if sc.simulated.is_empty() {
            outln!(
                "{:<12} {:<12} {:>14} {:>10} {:>8}",
                "run",
                "output",
                "RMS",
                "NRMSE %",
                "fit %"
            )?;
        }
        for (run, result) in runs.iter().zip(results) {
            let per_run = result.map_err(|f| sc.failed.push(f)).ok();
            // Below every run's length: checked after reading the records.
            let from = args.score_from;
            for (i, o) in model.outputs.iter().enumerate() {
                let Some(per_run) = &per_run else {
                    outln!("{:<12} {:<12} {:>14} {:>10}", run.id, o.name, "-", "failed")?;
                    continue;
                };
                let (sim, meas) = (&per_run[i][from..], &run.channels[i][from..]);
                let (rms, nrmse) = rms_nrmse(sim, meas);
                sc.constant |= nrmse.is_infinite();
                score_row(&run.id, &o.name, rms, nrmse)?;
                sc.pooled_sim[i].extend_from_slice(sim);
                sc.pooled_meas[i].extend_from_slice(meas);
            }
            sc.simulated.push(per_run);
        }
    }
    Ok(sc)
}

/// `report.md` (the scores and residual tests of every run) and the figures of the first runs.
fn write_report(
    dir: &std::path::Path,
    args: &SimulateArgs,
    model: &Model,
    rs: &ctsid::RecordSet,
    sc: &Scored,
) -> Result<()> {
    let outputs: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    let inputs: Vec<&str> = model.inputs.iter().map(String::as_str).collect();
    let runs: Vec<(usize, &[Vec<f64>])> = sc
        .simulated
        .iter()
        .enumerate()
        .filter_map(|(r, s)| s.as_deref().map(|s| (r, s)))
        .collect();
    let table = write_record_report(dir, rs, &outputs, &inputs, "model", &runs, args.score_from)?;
    // The runs whose free run failed are named, as on the console.
    let failures: String = sc
        .failed
        .iter()
        .map(|f| format!("\n\nNot scored, and left out of every figure: {f}"))
        .collect();
    let scored = if args.score_from > 0 {
        format!(" Scores, tests and figures cover each run from its sample {} on (`--score-from`), as the printed table.", args.score_from)
    } else {
        String::new()
    };
    let text = format!(
        "# Free-run simulation of {} on {}\n\nEach run starts from the initial state fitted on its first {} samples.{scored} Fit = 100 (1 - NRMSE). Residual tests at 99 %: lags of the simulation error's autocorrelation (whiteness) and of its cross-correlation with each input (independence from past inputs, the test that matters for a simulation model) outside the band.\n\n{table}",
        args.model, args.data, args.init_window
    ) + &failures;
    write_file(dir, "report.md", &text)
}

/// One row of the table: RMS, NRMSE and fit (100 (1 - NRMSE), the benchmarks' FIT index).
fn score_row(run: &str, output: &str, rms: f64, nrmse: f64) -> Result<()> {
    let fit = if nrmse.is_finite() {
        num4(100.0 * (1.0 - nrmse))
    } else {
        "-".into()
    };
    outln!(
        "{:<12} {:<12} {:>14.6e} {:>10} {:>8}",
        run,
        output,
        rms,
        percent(nrmse),
        fit
    )
}

/// The time (seconds into its run) at which a run's free run failed, where the error is such a
/// failure (diverged, a term left its domain, an unstable mode, a numerical failure from the
/// run's initial state on: its start), not bad input.
fn failure_time(e: &Error) -> Option<f64> {
    match e {
        Error::Diverged { time, .. }
        | Error::TermNotFinite { time, .. }
        | Error::UnstableMode { time, .. } => Some(*time),
        Error::Numerical(_) => Some(0.0),
        _ => None,
    }
}

/// Where `t` seconds into `run` is in the file: its CSV row, and its time there when the
/// times came from a time column (errors give times from the run's start).
fn file_place(run: &ctsid::records::Run, t: f64, tau: f64, time_known: bool) -> String {
    let k = ((t / tau).floor().max(0.0) as usize).min(run.len().saturating_sub(1));
    match (run.rows.get(k), time_known) {
        (Some(row), true) => format!(" (file row {row}, time {} s)", num4(run.t0 + t)),
        (Some(row), false) => format!(" (file row {row})"),
        (None, _) => String::new(),
    }
}

/// A note for each input whose samples look read otherwise than the model file says: held over
/// most steps where the model reads linearly, or varying smoothly where it holds (a model
/// identified on held steps scored a multisine record at 3 % against truth, 0.1 % read
/// linearly, and nothing said why).
fn note_input_shape(model: &Model, rs: &ctsid::records::RecordSet) {
    let all: Vec<usize> = (0..rs.runs.len()).collect();
    for name in &model.inputs {
        let Some(shape) = rs
            .channel_index(name)
            .ok()
            .and_then(|c| rs.step_shape(c, &all))
        else {
            continue;
        };
        if let Some(s) = shape.suggests(model.input_interpolation) {
            eprintln!(
                "note: the model reads input '{name}' by {} between samples, but in these data it {}: --input-interpolation {} reads them so",
                model.input_interpolation.name(),
                if shape.is_held() {
                    format!("keeps its value over {:.0} % of the steps", 100.0 * shape.held)
                } else {
                    "varies smoothly from sample to sample".to_string()
                },
                s.name()
            );
        }
    }
}

/// Without `--tau` or `--time-column` the model's tau is the sampling period. A column named
/// like time (`t`, `time`, `t_s`, `time_ms`, ...) that is uniform with another step means the
/// file is sampled otherwise, and the free run would use the wrong step without a word (a model
/// of 0.25 ms on its record decimated to 2.5 ms scored 128 %). Such a column is read as a time
/// column only to compare; one that is not uniform is not taken for time.
fn check_time_like_columns(
    data: &str,
    spec: &ctsid::records::CsvSpec,
    model_tau: Option<f64>,
) -> Result<()> {
    let Some(mt) = model_tau else { return Ok(()) };
    // Through the loader's own opening (a pipe is refused, not read); any failure here is the
    // loader's to report.
    let Ok(file) = ctsid::util::open_regular(data.as_ref(), None) else {
        return Ok(());
    };
    let mut rdr = csv::Reader::from_reader(file);
    let Ok(header) = rdr.headers() else {
        return Ok(());
    };
    for name in header
        .iter()
        .filter(|n| super::runs::time_like(n).is_some())
    {
        if spec.columns.iter().any(|c| c == name) || spec.run_column.as_deref() == Some(name) {
            continue;
        }
        let as_time = ctsid::records::CsvSpec {
            time_column: Some(name.to_string()),
            tau: None,
            ..spec.clone()
        };
        let Ok(rs) = ctsid::records::RecordSet::from_csv(data, &as_time) else {
            continue;
        };
        // A column named in ms (or us, min, h) cannot be the time column (`--time-column`
        // refuses it): its step in seconds is what to compare, and `--tau` what to suggest.
        if let Some((unit, seconds)) = super::runs::time_unit_seconds(name) {
            let step = rs.tau * seconds;
            if (step / mt - 1.0).abs() > 0.01 {
                return Err(Error::param(
                    "tau",
                    format!(
                        "the model was identified at tau = {} s, but column '{name}' of {data} steps by {} {unit} = {} s: give --tau {} to simulate at the data's sampling",
                        num4(mt),
                        seven(rs.tau),
                        seven(step),
                        seven(step)
                    ),
                ));
            }
            continue;
        }
        // A column in ms (or us, min, h) beside a model in seconds is the model's sampling in
        // another unit (`time_ms` stepping by 1 at tau = 1 ms simulated right before).
        let ratio = rs.tau / mt;
        if super::is_unit_factor(ratio) {
            continue;
        }
        if (ratio - 1.0).abs() > 0.01 {
            return Err(Error::param(
                "tau",
                format!(
                    "the model was identified at tau = {} s, but column '{name}' of {data} steps by {} s: give --time-column '{name}' to simulate at the data's sampling (or --tau)",
                    num4(mt),
                    num4(rs.tau)
                ),
            ));
        }
    }
    Ok(())
}

/// `x` to seven significant digits, as short as they allow (a mean step of 20.000000000000004 ms
/// reads 20).
fn seven(x: f64) -> String {
    ctsid::util::short(format!("{x:.6e}").parse().unwrap_or(x))
}

/// NRMSE in percent for the table: '-' where it is undefined (a constant measurement that the
/// simulation misses), scientific notation where four decimals would be a wall of digits.
fn percent(nrmse: f64) -> String {
    if nrmse.is_infinite() {
        "-".into()
    } else {
        num4(100.0 * nrmse)
    }
}

/// Refuses a `--score-from` at or past the end of a run: scoring from there would print an RMS
/// of nothing (0), not an error.
fn check_score_from(rs: &ctsid::records::RecordSet, from: usize) -> Result<()> {
    match rs.runs.iter().find(|r| from >= r.len()) {
        Some(run) => Err(Error::param(
            "score-from",
            format!(
                "{from} leaves nothing to score in run '{}' ({} samples); give a sample before its end",
                run.id,
                run.len()
            ),
        )),
        None => Ok(()),
    }
}
