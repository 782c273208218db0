//! The `ctsid` command line. Each subcommand lives in `src/cli/<name>.rs`; errors print as one
//! line on standard error and the process exits non-zero.

mod cli;

use clap::Parser;

fn main() {
    let args = cli::Cli::parse();
    if let Err(e) = cli::run(args) {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}
