//! Subcommand definitions and dispatch.

use clap::{Parser, Subcommand};

mod regress;
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
    /// Sparse polynomial regression of a label column on feature columns (LARS / LassoLars + eBIC).
    Regress(regress::RegressArgs),
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Info => {
            println!("ctsid {}", env!("CARGO_PKG_VERSION"));
            Ok(())
        }
        Command::Regress(a) => regress::run(a),
    }
}
