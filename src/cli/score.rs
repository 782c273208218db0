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
    if !a.signals.is_dir() {
        return Err(ctsid::Error::Io {
            path: a.signals.display().to_string(),
            message:
                "no such folder; give --signals DIR (the repository's copy: tests/data/signals)"
                    .into(),
        });
    }
    let t = std::time::Instant::now();
    let rows = benchmark::run(&a.signals)?;
    let secs = t.elapsed().as_secs_f64();
    outln!("Derivative accuracy on {} (trimmed p95 / full p100 per order 1/2/3/4; anchors from the project's issue)\n", a.signals.display())?;
    out!("{}", benchmark::table(&rows))?;
    let passed = rows.iter().filter(|r| benchmark::gates_pass(r)).count();
    outln!(
        "\n{} of {} rows meet every gate; {} runs in {:.2} s",
        passed,
        rows.len(),
        rows.len(),
        secs
    )?;
    Ok(())
}
