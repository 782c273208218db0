//! `ctsid score-derivatives`: the comparison table on the shared test signals.

use clap::Args;
use ctsid::derivatives::benchmark;
use ctsid::Result;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ScoreArgs {
    /// Folder with the test signals (sys3_multisine.csv, sines.csv, chirp.csv, etc_s1.csv).
    #[arg(long, default_value = "../shared/signals")]
    pub signals: PathBuf,
}

pub fn run(a: ScoreArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let rows = benchmark::run(&a.signals)?;
    let secs = t.elapsed().as_secs_f64();
    println!("Derivative accuracy on {} (trimmed p95 / full p100 per order 1/2/3/4; anchors from the project's issue)\n", a.signals.display());
    print!("{}", benchmark::table(&rows));
    let passed = rows.iter().filter(|r| benchmark::gates_pass(r)).count();
    println!(
        "\n{} of {} rows meet every gate; {} runs in {:.2} s",
        passed,
        rows.len(),
        rows.len(),
        secs
    );
    Ok(())
}
