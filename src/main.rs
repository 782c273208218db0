//! The `ctsid` command line. Each subcommand lives in `src/cli/<name>.rs`; errors print as one
//! line on standard error and the process exits non-zero.

mod cli;

use clap::Parser;

fn main() {
    // Mesa's Vulkan loader complains on every adapter probe when XDG_RUNTIME_DIR is unset (as in
    // containers and CI); give it a private folder before any thread starts.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let dir = std::env::temp_dir().join(format!("ctsid-xdg-{}", std::process::id()));
        if std::fs::create_dir_all(&dir).is_ok() {
            std::env::set_var("XDG_RUNTIME_DIR", &dir);
        }
    }
    let args = cli::Cli::parse();
    if let Err(e) = cli::run(args) {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}
