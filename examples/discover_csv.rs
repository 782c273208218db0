//! Name the effect a nominal model misses, through the library: `discover` on a CSV record.
//!
//! `cargo run --release --example discover_csv -- DATA.csv NOMINAL.json TAU [SECONDS]`: DATA
//! has a column for each output and input of the nominal model, sampled every TAU seconds, and
//! a `run` column; or, with SECONDS, it is one long record cut into runs of SECONDS. Runs 0-3
//! train, 4 validates, 5 is the test run. Writes `augmented.json`, which `ctsid simulate` and
//! `Model::simulate` run like any model file. Errors print as one-line messages.
use ctsid::discover::{discover, Options};
use ctsid::{Model, RecordSet, Split};
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> ctsid::Result<()> {
    let (data, nominal, tau, seconds) = match args {
        [d, n, t] => (d, n, t, None),
        [d, n, t, s] => (d, n, t, Some(s)),
        _ => {
            return Err(ctsid::Error::param(
                "arguments",
                "give DATA.csv NOMINAL.json TAU [SECONDS]",
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
    let nominal = Model::read(nominal)?;
    let mut columns: Vec<&str> = nominal.outputs.iter().map(|o| o.name.as_str()).collect();
    columns.extend(nominal.inputs.iter().map(String::as_str));
    let records = match seconds {
        Some(s) => RecordSet::read_csv(data, &columns, None, tau)?.segmented_seconds(s)?,
        None => RecordSet::read_csv(data, &columns, Some("run"), tau)?,
    };
    let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
    let options = Options::new(
        split.train,
        split.validation.unwrap_or_default(),
        split.test,
    );
    let found = discover(&records, &nominal, &options)?;
    println!("{}", found.text());
    found.augmented_model(&nominal)?.write("augmented.json")
}
