//! Identify a model from a CSV record through the library's entry point, then simulate it:
//! `cargo run --release --example identify_csv -- DATA.csv OUTPUT INPUT TAU [SECONDS]`. DATA
//! has the two named columns, sampled every TAU s, and a `run` column; or, with SECONDS, it is
//! one long record cut into runs of SECONDS (`RecordSet::segmented_seconds`, the command line's
//! `--segment`). Runs 0-3 train, 4 validates, 5 tests (`tests/library_entry.rs` runs the same
//! calls on a record it makes). Errors print as the command line's one-line messages.
use ctsid::{Identifier, RecordSet, Split};
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // `Display`, not the `Debug` form `main() -> Result` would print.
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> ctsid::Result<()> {
    let (data, y, u, tau, seconds) = match args {
        [d, y, u, t] => (d, y, u, t, None),
        [d, y, u, t, s] => (d, y, u, t, Some(s)),
        _ => {
            return Err(ctsid::Error::param(
                "arguments",
                "give DATA.csv OUTPUT INPUT TAU [SECONDS]",
            ))
        }
    };
    let number = |what: &'static str, text: &str| {
        text.parse::<f64>()
            .map_err(|_| ctsid::Error::param(what, format!("'{text}' is not a number")))
    };
    let tau = number("TAU", tau)?;
    // Every setting before the data are read, as the command line checks them.
    let seconds = seconds.map(|s| number("SECONDS", s)).transpose()?;
    let records = match seconds {
        // A file without a run column is run "0", cut into runs "0", "1", ...
        Some(s) => RecordSet::read_csv(data, &[y, u], None, tau)?.segmented_seconds(s)?,
        None => RecordSet::read_csv(data, &[y, u], Some("run"), tau)?,
    };
    let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
    let fit = Identifier::new()
        .outputs([y])
        .inputs([u])
        .degree(2)
        .fit(&records, &split)?;
    println!("{}", fit.model);
    for run in fit.model.simulate(&records)?.runs {
        println!("run {}: fit {:.1} %", run.id, run.fit_percent()[0]);
    }
    fit.model.write("identified.json")
}
