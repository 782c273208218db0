//! Name the effect a nominal model misses, through the library: `discover` on a CSV record.
//!
//! `cargo run --release --example discover_csv -- DATA.csv NOMINAL.json TAU`: DATA has a `run`
//! column and a column for each output and input of the nominal model, sampled every TAU
//! seconds; runs 0-3 train, 4 validates, 5 is the test run. Writes `augmented.json`, which
//! `ctsid simulate` and `Model::simulate` run like any model file.
use ctsid::discover::{discover, Options};
use ctsid::{Model, RecordSet, Split};

fn main() -> ctsid::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data, nominal, tau] = args.as_slice() else {
        return Err(ctsid::Error::param(
            "arguments",
            "give DATA.csv NOMINAL.json TAU",
        ));
    };
    let tau: f64 = tau
        .parse()
        .map_err(|_| ctsid::Error::param("TAU", "not a number"))?;
    let nominal = Model::read(nominal)?;
    let mut columns: Vec<&str> = nominal.outputs.iter().map(|o| o.name.as_str()).collect();
    columns.extend(nominal.inputs.iter().map(String::as_str));
    let records = RecordSet::read_csv(data, &columns, Some("run"), tau)?;
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
