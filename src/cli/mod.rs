//! Subcommand definitions and dispatch. Each subcommand lives in its own file.
//!
//! Results go to standard output through [`out!`] / [`outln!`], never `print!`: a closed pipe
//! (`ctsid ... | head`) or a full disk is then an error line, not a panic.

/// `print!` that returns a [`ctsid::Result`] instead of panicking when standard output fails.
macro_rules! out {
    ($($t:tt)*) => { $crate::cli::write_stdout(&format!($($t)*)) };
}

/// `println!` that returns a [`ctsid::Result`] instead of panicking when standard output fails.
macro_rules! outln {
    ($($t:tt)*) => { $crate::cli::write_stdout(&format!("{}\n", format_args!($($t)*))) };
}

mod benchmark;
mod control;
mod csvout;
mod demo;
mod derive;
mod discover;
mod identify;
mod score;
mod show;
mod simulate;

use clap::{Parser, Subcommand};

mod regress;
mod runs;
use ctsid::{Error, Result};
use std::path::Path;

#[derive(Parser, Debug)]
#[command(
    name = "ctsid",
    version,
    about = "Continuous-time sparse identification of machines from noisy input/output records"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Identify y^(n) = P(y, ..., u) from measured runs: order search, fit, test, simulation.
    Identify(identify::IdentifyArgs),
    /// Built-in demonstrations on plants with known truth (the main job on built-in data).
    Demo(demo::DemoArgs),
    /// Derivatives of one column (per run), with a per-sample standard deviation.
    Derive(derive::DeriveArgs),
    /// Simulate a model file on every run of a record and report RMS / NRMSE.
    Simulate(simulate::SimulateArgs),
    /// Score the derivative method on the shared test signals against the reference anchors.
    ScoreDerivatives(score::ScoreArgs),
    /// Sparse polynomial regression of a label column on feature columns (LARS / LassoLars / forward OLS + eBIC).
    Regress(regress::RegressArgs),
    /// Find missing physics: compare a nominal model with runs, name, gate and add effects.
    Discover(discover::DiscoverArgs),
    /// Observer and state feedback with integral action designed on a model; a setpoint step simulated around a plant.
    Control(control::ControlArgs),
    /// Print a model file: its equations, then each term's coefficient, standard error, interval and origin.
    Show(show::ShowArgs),
    /// A public benchmark (silverbox, emps, tanks, unbalanced-disk) by one workflow: a linear nominal by identify, discover in rounds (with a second look on simulation error at what its gates refuse), the terms the data do not determine dropped, scored by the benchmark's protocol beside the published rows.
    Benchmark(benchmark::BenchmarkArgs),
}

/// Runs one command. Its files are written all or none ([`ctsid::util::Outputs`]): a command
/// that fails after writing its model file but before its report is done leaves neither (the
/// model file was written and the failing report's error followed), and the lines saying what was
/// written come after the files are in place.
///
/// A command whose only failure is standard output (`| head` closing the pipe, a full disk
/// behind `>`) keeps the files it wrote before: each is whole, and a long run's report should
/// not be lost to a closed pipe.
pub fn run(cli: Cli) -> Result<()> {
    let outputs = ctsid::util::Outputs::begin();
    let done = dispatch(cli);
    let keep = done.is_ok() || STDOUT_FAILED.with(|f| f.get());
    let committed = if keep { outputs.commit() } else { Ok(()) };
    let lines = WRITTEN.with(|w| w.take());
    if committed.is_ok() && keep {
        lines.iter().for_each(|line| eprintln!("{line}"));
    }
    done.and(committed)
}

thread_local! {
    /// Whether a write to standard output failed in this command ([`write_stdout`]).
    static STDOUT_FAILED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// What [`written`] says, printed once the command's files are in place.
    static WRITTEN: std::cell::RefCell<Vec<String>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Says on standard error, once the command's files are in place, that one was written.
pub fn written(line: String) {
    WRITTEN.with(|w| w.borrow_mut().push(line));
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Identify(a) => identify::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Derive(a) => derive::run(a),
        Command::Simulate(args) => simulate::run(args),
        Command::ScoreDerivatives(a) => score::run(a),
        Command::Regress(a) => regress::run(a),
        Command::Discover(a) => discover::run(a),
        Command::Control(a) => control::run(a),
        Command::Show(a) => show::run(a),
        Command::Benchmark(a) => benchmark::run(a),
    }
}

/// Whether long stages print progress lines: on a terminal, unless `--quiet`. Piped or
/// redirected standard error gets none, so logs and scripts see only results and errors.
pub fn show_progress(quiet: bool) -> Option<ctsid::identify::Progress> {
    use std::io::IsTerminal;
    (!quiet && std::io::stderr().is_terminal())
        .then(|| ctsid::identify::Progress::new(progress_line))
}

/// A progress line with the seconds since the first one, so a long run shows where its time goes.
fn progress_line(line: &str) {
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    let start = START.get_or_init(std::time::Instant::now);
    eprintln!("[{:7.2} s] {line}", start.elapsed().as_secs_f64());
}

/// Loads the channels of `spec` from `path` and notes on standard error the samples that look
/// like glitches or missing-value codes (legal values, kept: the user decides).
pub fn load_records(
    path: impl AsRef<Path>,
    spec: &ctsid::records::CsvSpec,
) -> Result<ctsid::records::RecordSet> {
    let rs = ctsid::records::RecordSet::from_csv(path, spec)?;
    for s in rs.suspect_samples() {
        eprintln!("note: {}", s.note());
    }
    Ok(rs)
}

/// Writes `text` to standard output and flushes it.
pub fn write_stdout(text: &str) -> Result<()> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    o.write_all(text.as_bytes())
        .and_then(|_| o.flush())
        .map_err(|e| {
            STDOUT_FAILED.with(|f| f.set(true));
            Error::file("standard output", e)
        })
}

/// Checks an output file before any work is done: its folder exists, it is not a folder, it
/// is none of `inputs` (writing would truncate a file that is still to be read), and it is a
/// target [`ctsid::util::output_target`] accepts.
pub fn check_output_file(out: &Path, inputs: &[&Path]) -> Result<()> {
    // `-o -` wrote a file named `-` ("model written to -") where the Unix habit reads
    // standard output.
    if out == Path::new("-") {
        return Err(Error::Io {
            path: "-".into(),
            message: "standard output is not an output file here; give a file name (./- for a file named '-')".into(),
        });
    }
    // A folder, a device, a pipe, a name ending in a separator, a missing folder, a link into
    // one or an over-long name: refused now, not after the work (`util::output_target`).
    ctsid::util::output_target(out)?;
    if inputs.iter().any(|i| ctsid::util::same_file(out, i)) {
        return Err(Error::Io {
            path: out.display().to_string(),
            message: "is also an input file; writing it would destroy the input, so give another output file".into(),
        });
    }
    Ok(())
}

/// A time unit's factor to seconds, as printed, and the unit: a sampling ratio of one of these
/// is mostly a time in another unit.
const UNIT_FACTORS: [(f64, &str, &str); 4] = [
    (1e3, "1000", "ms"),
    (1e6, "1e6", "us"),
    (1.0 / 60.0, "1/60", "min"),
    (1.0 / 3600.0, "1/3600", "h"),
];

/// Whether `ratio` is within 1 % of `k`.
fn near_factor(ratio: f64, k: f64) -> bool {
    (ratio / k - 1.0).abs() < 0.01
}

/// Whether a sampling ratio is a time unit's factor ([`UNIT_FACTORS`]).
pub fn is_unit_factor(ratio: f64) -> bool {
    UNIT_FACTORS.iter().any(|&(k, _, _)| near_factor(ratio, k))
}

/// A note where the data's sampling is a unit's factor from the model's (a continuous-time
/// model simulates at any sampling, but a ratio of 1e3, 1e6, 1/60 or 1/3600 to the
/// identification's is mostly a time column in ms, us, min or h; and the inverse, a model
/// identified on such a column). `simulate` had it; `discover` with a nominal of another unit
/// said nothing.
pub fn note_tau_units(data_tau: f64, model_tau: Option<f64>, from_time_column: bool) {
    let Some(mt) = model_tau else { return };
    let (data, model) = (ctsid::util::num4(data_tau), ctsid::util::num4(mt));
    let source = if from_time_column {
        "the time column"
    } else {
        "--tau"
    };
    for (k, label, unit) in UNIT_FACTORS {
        if near_factor(data_tau / mt, k) {
            eprintln!(
                "note: the data are sampled every {data} s, the model was identified at {model} s (about {label} times): if {source} is in another unit ({unit}?), convert it to seconds"
            );
        }
        if near_factor(mt / data_tau, k) {
            eprintln!(
                "note: the model was identified at {model} s, about {label} times the data's {data} s: if its data's times were in {unit}, identify it again with times in seconds"
            );
        }
    }
}

/// Refuses an output file inside the report folder, or named as the folder: the report's
/// files would replace it (`-o rep/report.md --report rep` lost the simulated CSV) or the
/// folder could not be made. Checked before the work, like the other outputs.
pub fn check_output_outside_report(out: &Path, report: &Path) -> Result<()> {
    // Absolute, through links, where the folders exist; the report folder may not exist yet.
    let resolve = |p: &Path| -> std::path::PathBuf {
        let parent = p
            .parent()
            .filter(|q| !q.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let base = std::fs::canonicalize(parent).unwrap_or_else(|_| parent.to_path_buf());
        p.file_name().map_or(base.clone(), |n| base.join(n))
    };
    let (o, r) = (resolve(out), resolve(report));
    if o == r || o.parent() == Some(r.as_path()) {
        return Err(Error::Io {
            path: out.display().to_string(),
            message: if o == r {
                "is also the report folder; write it elsewhere".into()
            } else {
                format!(
                    "is inside the report folder {}, whose files would replace it; write it elsewhere",
                    report.display()
                )
            },
        });
    }
    Ok(())
}

/// Checks a report folder before any work: it is not an existing file and its parent exists.
pub fn check_output_dir(dir: &Path) -> Result<()> {
    let name = dir.display().to_string();
    if dir.exists() && !dir.is_dir() {
        return Err(Error::Io {
            path: name,
            message: "is a file, not a folder; give a folder for the report".into(),
        });
    }
    if let Some(p) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !p.is_dir() {
            return Err(Error::Io {
                path: name,
                message: format!("folder {} does not exist; create it first", p.display()),
            });
        }
    }
    Ok(())
}

/// Value parser for names in comma lists: `--input "u, t"` means `u` and `t` (CSV headers are
/// trimmed too).
/// A channel name from a comma-separated list, trimmed; an empty one (`--output y,`) is named
/// as such rather than counted as a channel.
pub fn trimmed(s: &str) -> std::result::Result<String, String> {
    let t = s.trim();
    if t.is_empty() {
        return Err("an empty name in the list (a doubled or trailing comma?)".into());
    }
    Ok(t.to_string())
}
