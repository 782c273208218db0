//! Arguments shared by the commands that read records: `--tau / --time-column`, and
//! `--train / --validation / --test` for those that split runs.

use clap::Args;
use ctsid::identify::split::resolve_list;
use ctsid::records::{CsvSpec, RecordSet};
use ctsid::{Error, Result};

/// How samples are timed: a sampling period, or a time column it is read from.
#[derive(Args, Debug)]
pub struct SamplingArgs {
    /// Sampling period in seconds (default: from --time-column; for `simulate`, the model's tau
    /// when neither is given).
    #[arg(long)]
    pub tau: Option<f64>,
    /// Time column in seconds: strictly increasing and uniform within each run.
    #[arg(long)]
    pub time_column: Option<String>,
}

impl SamplingArgs {
    /// The CSV spec for `columns` grouped by `run_column`, with `fallback_tau` as the period
    /// when neither --tau nor --time-column is given. Refuses a time column named in another
    /// unit than seconds (`time_ms`): read as seconds it gave a model at 1000 times the step
    /// with coefficients 1000 times too small, and `identify` said nothing.
    pub fn spec(
        &self,
        columns: Vec<String>,
        run_column: Option<String>,
        fallback_tau: Option<f64>,
    ) -> Result<CsvSpec> {
        if let Some((c, unit)) = self
            .time_column
            .as_deref()
            .and_then(|c| time_unit(c).map(|u| (c, u)))
        {
            return Err(Error::param(
                "--time-column",
                format!(
                    "'{c}' is named in {unit}, but a time column is read in seconds; give --tau with the sampling period in seconds instead (the column is then not read), or a column in seconds"
                ),
            ));
        }
        Ok(CsvSpec {
            columns,
            run_column,
            time_column: self.time_column.clone(),
            tau: self
                .tau
                .or(fallback_tau.filter(|_| self.time_column.is_none())),
            rows_independent: false,
        })
    }
}

/// What follows `t` or `time` in a column named like time (`t`, `time`, `t_s`, `time [ms]`, not
/// `temp` or `throttle`), lowercase; `None` for any other name.
pub fn time_like(name: &str) -> Option<String> {
    let n = name.trim().to_ascii_lowercase();
    ["time", "t"].iter().find_map(|p| {
        n.strip_prefix(p)
            .filter(|r| r.is_empty() || r.starts_with(['_', ' ', '[', '(']))
            .map(str::to_string)
    })
}

/// The unit a column named like time says it is in, where that is not seconds: `time_ms`,
/// `t [ms]`, `t_us`, `time (min)`, `t_h`.
fn time_unit(name: &str) -> Option<&'static str> {
    time_unit_seconds(name).map(|(u, _)| u)
}

/// [`time_unit`] and how many seconds one of that unit is.
pub(super) fn time_unit_seconds(name: &str) -> Option<(&'static str, f64)> {
    let rest = time_like(name)?;
    let unit = rest.trim_matches(|c: char| "_ [()]".contains(c));
    [
        ("ms", "ms", 1e-3),
        ("msec", "ms", 1e-3),
        ("us", "us", 1e-6),
        ("usec", "us", 1e-6),
        ("min", "minutes", 60.0),
        ("minutes", "minutes", 60.0),
        ("h", "hours", 3600.0),
        ("hr", "hours", 3600.0),
        ("hours", "hours", 3600.0),
    ]
    .iter()
    .find(|(k, _, _)| *k == unit)
    .map(|&(_, u, s)| (u, s))
}

#[cfg(test)]
mod tests {
    use super::time_unit;

    #[test]
    fn time_columns_named_in_other_units_are_told_apart() {
        for (name, unit) in [
            ("time_ms", "ms"),
            ("t [ms]", "ms"),
            ("T_us", "us"),
            ("time (min)", "minutes"),
            ("t_h", "hours"),
        ] {
            assert_eq!(time_unit(name), Some(unit), "{name}");
        }
        for name in ["t", "time", "t_s", "time [s]", "temp_ms", "tms", "throttle"] {
            assert_eq!(time_unit(name), None, "{name}");
        }
    }
}

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

impl Given {
    /// The runs of `0..n` that no given list names (where omitted lists take their runs from).
    pub fn unnamed(&self, n: usize) -> Vec<usize> {
        let mut named = vec![false; n];
        for &r in [&self.train, &self.validation, &self.test]
            .into_iter()
            .flatten()
            .flatten()
        {
            if r < n {
                named[r] = true;
            }
        }
        (0..n).filter(|&r| !named[r]).collect()
    }
}

impl SplitArgs {
    pub fn resolve(&self, ids: &[String]) -> Result<Given> {
        let pick = |t: &Option<String>, what: &str| -> Result<Option<Vec<usize>>> {
            t.as_deref().map(|t| resolve_list(t, ids, what)).transpose()
        };
        Ok(Given {
            train: pick(&self.train, "train")?,
            validation: pick(&self.validation, "validation")?,
            test: pick(&self.test, "test")?,
        })
    }
}

/// Long runs cut into pieces that count as runs (`RecordSet::segmented`).
#[derive(Args, Debug)]
pub struct SegmentArgs {
    /// Cut every run into consecutive pieces of this many seconds, each then a run of its own (a
    /// remainder shorter than half a piece joins the last): a file without a run column gives
    /// runs 0, 1, ..., runs of a run column RUN#0, RUN#1, ..., and a list naming RUN takes all
    /// its pieces.
    #[arg(long, value_name = "SECONDS")]
    pub segment: Option<f64>,
}

impl SegmentArgs {
    /// Checks the length before any data are read.
    pub fn check(&self) -> Result<()> {
        self.segment
            .map_or(Ok(()), ctsid::records::check_piece_seconds)
    }

    /// The record set cut into pieces (unchanged without --segment).
    pub fn apply(&self, rs: RecordSet) -> Result<RecordSet> {
        match self.segment {
            Some(s) => rs.segmented_seconds(s),
            None => Ok(rs),
        }
    }

    /// A run too short for the method is, when pieces were cut, a piece too short: mostly the
    /// fix is a longer --segment (a run shorter than a piece was not cut, and needs more
    /// samples or a lower order).
    pub fn explain(&self, e: Error) -> Error {
        match self.segment {
            Some(s) => ctsid::records::piece_too_short(e, s, "--segment"),
            None => e,
        }
    }
}
