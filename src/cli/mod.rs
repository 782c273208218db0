//! Subcommand definitions and dispatch. Each subcommand lives in its own file.

mod csvout;
mod demo;
mod derive;
mod discover;
mod identify;
mod score;
mod simulate;

use clap::{Parser, Subcommand};

mod regress;
mod runs;
use ctsid::Result;

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
    /// Sparse polynomial regression of a label column on feature columns (LARS / LassoLars + eBIC).
    Regress(regress::RegressArgs),
    /// Find missing physics: compare a nominal model with runs, name, gate and add effects.
    Discover(discover::DiscoverArgs),
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Identify(a) => identify::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Derive(a) => derive::run(a),
        Command::Simulate(args) => simulate::run(args),
        Command::ScoreDerivatives(a) => score::run(a),
        Command::Regress(a) => regress::run(a),
        Command::Discover(a) => discover::run(a),
    }
}

/// Whether long stages print progress lines: on a terminal, unless `--quiet`. Piped or
/// redirected standard error gets none, so logs and scripts see only results and errors.
pub fn show_progress(quiet: bool) -> bool {
    use std::io::IsTerminal;
    !quiet && std::io::stderr().is_terminal()
}
