//! The `--train / --validation / --test` arguments shared by the commands that split runs.

use clap::Args;
use ctsid::identify::split::{parse_runs, resolve};
use ctsid::Result;

/// Run lists like `0-24,30`, naming run ids of the record set. What an omitted list means is
/// up to the command (see its help).
#[derive(Args, Debug)]
pub struct SplitArgs {
    /// Training runs, like `0-24,30`.
    #[arg(long)]
    pub train: Option<String>,
    /// Validation runs.
    #[arg(long)]
    pub validation: Option<String>,
    /// Test runs (scored and simulated, never fitted).
    #[arg(long)]
    pub test: Option<String>,
}

/// The given lists resolved to run indices; `None` where a list was not given.
pub struct Given {
    pub train: Option<Vec<usize>>,
    pub validation: Option<Vec<usize>>,
    pub test: Option<Vec<usize>>,
}

impl SplitArgs {
    pub fn resolve(&self, ids: &[String]) -> Result<Given> {
        let pick = |t: &Option<String>, what: &str| -> Result<Option<Vec<usize>>> {
            t.as_deref()
                .map(|t| resolve(&parse_runs(t)?, ids, what))
                .transpose()
        };
        Ok(Given {
            train: pick(&self.train, "train")?,
            validation: pick(&self.validation, "validation")?,
            test: pick(&self.test, "test")?,
        })
    }
}
