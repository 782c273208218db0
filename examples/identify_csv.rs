//! Identify a model from a CSV record through the library's entry point, then simulate it:
//! `cargo run --release --example identify_csv -- DATA.csv OUTPUT INPUT TAU`; DATA has a `run`
//! column and the two named ones, sampled every TAU s; runs 0-3 train, 4 validates, 5 tests
//! (`tests/library_entry.rs` runs the same calls on a record it makes).
use ctsid::{Identifier, RecordSet, Split};

fn main() -> ctsid::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data, y, u, tau] = args.as_slice() else {
        return Err(ctsid::Error::param(
            "arguments",
            "give DATA.csv OUTPUT INPUT TAU",
        ));
    };
    let bad_tau = |_| ctsid::Error::param("TAU", "not a number");
    let tau: f64 = tau.parse().map_err(bad_tau)?;
    let records = RecordSet::read_csv(data, &[y, u], Some("run"), tau)?;
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
