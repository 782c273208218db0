//! Identify on the GPU engine where the machine has one, on the CPU engine where it has not.
//!
//! `cargo run --release --example gpu_fallback -- DATA.csv OUTPUT INPUT TAU` (a record with a
//! `run` column as in `identify_csv`). `EngineChoice::Auto` makes the same choice by itself
//! (and also keeps the CPU engine for problems too small to pay for the GPU); asking for the
//! GPU and falling back shows the error a missing adapter gives. A GPU lost in the middle of a fit falls back by itself,
//! said in each output's `engine`.
use ctsid::engine::select::{probe, EngineChoice};
use ctsid::{Identifier, RecordSet, Split};
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
    let [data, y, u, tau] = args else {
        return Err(ctsid::Error::param(
            "arguments",
            "give DATA.csv OUTPUT INPUT TAU",
        ));
    };
    let tau: f64 = tau
        .parse()
        .map_err(|_| ctsid::Error::param("TAU", "not a number"))?;
    for a in probe() {
        println!(
            "adapter: {} ({:?}, driver {})",
            a.name, a.device_type, a.driver
        );
    }
    let records = RecordSet::read_csv(data, &[y, u], Some("run"), tau)?;
    let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
    let fit_on = |engine| {
        Identifier::new()
            .outputs([y])
            .inputs([u])
            .degree(4)
            .engine(engine)
            .fit(&records, &split)
    };
    let fit = match fit_on(EngineChoice::Gpu) {
        Err(ctsid::Error::NoGpu(why)) => {
            println!("{why}: on the CPU engine");
            fit_on(EngineChoice::Cpu)?
        }
        other => other?,
    };
    for o in &fit.outputs {
        println!("{}: {}", o.name, o.engine);
    }
    println!("{}", fit.model);
    Ok(())
}
