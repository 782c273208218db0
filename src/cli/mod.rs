//! Subcommand definitions and dispatch.

mod simulate;

use clap::{Parser, Subcommand};
use ctsid::Result;

#[derive(Parser, Debug)]
#[command(name = "ctsid", version, about = "Continuous-time sparse identification of machines from noisy input/output records")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Print the library version and the available engines.
    Info,
    /// Simulate a model file on every run of a record and report RMS / NRMSE.
    Simulate(simulate::SimulateArgs),
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Info => {
            println!("ctsid {}", env!("CARGO_PKG_VERSION"));
            Ok(())
        }
        Command::Simulate(args) => simulate::run(args),
    }
}
