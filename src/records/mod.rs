//! Record sets: one or more runs (experiments), each uniformly sampled at tau, with named
//! channels (inputs and outputs alike; the workflow decides which is which).
//!
//! Loading from CSV selects channels by column name, optionally groups rows into runs by a run
//! column (rows with the same id form one run, in file order; runs are ordered by first
//! appearance) and optionally checks a time column: strictly increasing within each run and
//! uniform to 1e-6 relative; tau comes from it when not given. Every problem is reported as one
//! line naming the file, the row (1-based, the header is row 1) and the column.

use crate::error::{Error, Result};
use std::path::Path;

/// Relative tolerance on the sampling period.
pub const TAU_RTOL: f64 = 1e-6;

/// One run: samples of every channel, all of the same length.
#[derive(Debug, Clone)]
pub struct Run {
    pub id: String,
    /// `channels[c][i]`: sample i of channel c (channel order of the record set).
    pub channels: Vec<Vec<f64>>,
    /// Time of the first sample (0 when no time column was given).
    pub t0: f64,
    /// 1-based CSV row of each sample, for error messages downstream.
    pub rows: Vec<usize>,
}

impl Run {
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, |c| c.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A set of runs sharing tau and channel names.
#[derive(Debug, Clone)]
pub struct RecordSet {
    pub tau: f64,
    pub channel_names: Vec<String>,
    pub runs: Vec<Run>,
}

/// What to read from a CSV file.
#[derive(Debug, Clone, Default)]
pub struct CsvSpec {
    /// Channels to load, by column name.
    pub columns: Vec<String>,
    pub run_column: Option<String>,
    pub time_column: Option<String>,
    /// Sampling period in seconds; required unless a time column is given.
    pub tau: Option<f64>,
}

impl RecordSet {
    /// Builds a record set from in-memory runs (validated like a file).
    pub fn new(tau: f64, channel_names: Vec<String>, runs: Vec<Run>) -> Result<RecordSet> {
        check_tau(tau)?;
        for r in &runs {
            if r.channels.len() != channel_names.len() {
                return Err(Error::InvalidData(format!(
                    "run '{}' has {} channels, expected {}",
                    r.id,
                    r.channels.len(),
                    channel_names.len()
                )));
            }
            let n = r.len();
            for (c, ch) in r.channels.iter().enumerate() {
                if ch.len() != n {
                    return Err(Error::InvalidData(format!(
                        "run '{}': channel '{}' has {} samples, expected {n}",
                        r.id,
                        channel_names[c],
                        ch.len()
                    )));
                }
                if let Some(i) = ch.iter().position(|v| !v.is_finite()) {
                    return Err(Error::InvalidData(format!(
                        "run '{}': channel '{}' sample {i} is not a finite number ({})",
                        r.id, channel_names[c], ch[i]
                    )));
                }
            }
        }
        Ok(RecordSet {
            tau,
            channel_names,
            runs,
        })
    }

    /// Index of a channel by name, with an error that lists the available ones.
    pub fn channel_index(&self, name: &str) -> Result<usize> {
        self.channel_names
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| Error::MissingColumn {
                path: "record set".into(),
                column: name.into(),
                available: self.channel_names.join(", "),
            })
    }

    /// Samples of one channel in one run.
    pub fn channel(&self, run: usize, name: &str) -> Result<&[f64]> {
        let c = self.channel_index(name)?;
        Ok(&self.runs[run].channels[c])
    }

    /// Refuses any run shorter than `min` samples, naming `what` needs them.
    pub fn require_min_len(&self, min: usize, what: &str) -> Result<()> {
        for r in &self.runs {
            if r.len() < min {
                return Err(Error::RunTooShort {
                    run: r.id.clone(),
                    len: r.len(),
                    min,
                    what: what.into(),
                });
            }
        }
        Ok(())
    }

    /// Loads channels from a CSV file with a header row.
    pub fn from_csv(path: impl AsRef<Path>, spec: &CsvSpec) -> Result<RecordSet> {
        let path = path.as_ref();
        let p = path.display().to_string();
        let file = std::fs::File::open(path).map_err(|e| Error::Io {
            path: p.clone(),
            message: e.to_string(),
        })?;
        Self::from_reader(file, &p, spec)
    }

    /// Loads from any reader; `label` names the source in messages.
    pub fn from_reader<R: std::io::Read>(
        reader: R,
        label: &str,
        spec: &CsvSpec,
    ) -> Result<RecordSet> {
        if let Some(t) = spec.tau {
            check_tau(t)?;
        }
        if spec.tau.is_none() && spec.time_column.is_none() {
            return Err(Error::MissingTau);
        }
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(false)
            .from_reader(reader);
        let header: Vec<String> = rdr
            .headers()
            .map_err(|e| Error::Csv {
                path: label.into(),
                row: 1,
                message: e.to_string(),
            })?
            .iter()
            .map(|s| s.to_string())
            .collect();
        let find = |name: &str| -> Result<usize> {
            header
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| Error::MissingColumn {
                    path: label.into(),
                    column: name.into(),
                    available: header.join(", "),
                })
        };
        if spec.columns.is_empty() {
            return Err(Error::param("columns", "name at least one column to load"));
        }
        let cols: Vec<usize> = spec
            .columns
            .iter()
            .map(|c| find(c))
            .collect::<Result<_>>()?;
        let run_col = spec.run_column.as_deref().map(find).transpose()?;
        let time_col = spec.time_column.as_deref().map(find).transpose()?;

        struct Acc {
            id: String,
            channels: Vec<Vec<f64>>,
            times: Vec<f64>,
            rows: Vec<usize>,
        }
        let mut runs: Vec<Acc> = Vec::new();
        let mut index: std::collections::HashMap<String, usize> = Default::default();
        let parse = |s: &str, row: usize, col: &str| -> Result<f64> {
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(Error::NonFinite {
                    path: label.into(),
                    row,
                    column: col.into(),
                    value: s.into(),
                }),
            }
        };
        for (i, rec) in rdr.records().enumerate() {
            let row = i + 2;
            let rec = rec.map_err(|e| Error::Csv {
                path: label.into(),
                row,
                message: e.to_string(),
            })?;
            let id = run_col
                .map(|c| rec[c].to_string())
                .unwrap_or_else(|| "0".into());
            let k = *index.entry(id.clone()).or_insert_with(|| {
                runs.push(Acc {
                    id: id.clone(),
                    channels: vec![Vec::new(); cols.len()],
                    times: Vec::new(),
                    rows: Vec::new(),
                });
                runs.len() - 1
            });
            let acc = &mut runs[k];
            for (c, &col) in cols.iter().enumerate() {
                acc.channels[c].push(parse(&rec[col], row, &spec.columns[c])?);
            }
            if let Some(tc) = time_col {
                acc.times
                    .push(parse(&rec[tc], row, spec.time_column.as_deref().unwrap())?);
            }
            acc.rows.push(row);
        }
        if runs.is_empty() {
            return Err(Error::InvalidData(format!("{label}: no data rows")));
        }

        let mut tau = spec.tau;
        if let Some(tname) = spec.time_column.as_deref() {
            // tau from the first run with two samples; every step of every run must agree.
            let from_time = runs
                .iter()
                .find(|r| r.times.len() >= 2)
                .map(|r| r.times[1] - r.times[0]);
            for r in &runs {
                for w in 1..r.times.len() {
                    let (a, b) = (r.times[w - 1], r.times[w]);
                    if b <= a {
                        return Err(Error::TimeNotIncreasing {
                            path: label.into(),
                            row: r.rows[w],
                            column: tname.into(),
                            prev: a,
                            value: b,
                        });
                    }
                }
            }
            if let Some(ft) = from_time {
                match tau {
                    Some(t) if ((t - ft) / t).abs() > TAU_RTOL => {
                        return Err(Error::TauMismatch {
                            given: t,
                            from_time: ft,
                            column: tname.into(),
                        })
                    }
                    None => tau = Some(ft),
                    _ => {}
                }
                let t = tau.unwrap();
                for r in &runs {
                    for w in 1..r.times.len() {
                        let step = r.times[w] - r.times[w - 1];
                        // Compare absolute times with the grid, so slow drift is caught too.
                        let expect = r.times[0] + w as f64 * t;
                        if ((step - t) / t).abs() > TAU_RTOL
                            && ((r.times[w] - expect) / t).abs() > TAU_RTOL * (w as f64).max(1.0)
                        {
                            return Err(Error::TimeNonUniform {
                                path: label.into(),
                                row: r.rows[w],
                                column: tname.into(),
                                step,
                                tau: t,
                            });
                        }
                    }
                }
            }
        }
        let tau = tau.ok_or(Error::MissingTau)?;
        check_tau(tau)?;
        let runs = runs
            .into_iter()
            .map(|a| Run {
                id: a.id,
                t0: a.times.first().copied().unwrap_or(0.0),
                channels: a.channels,
                rows: a.rows,
            })
            .collect();
        Ok(RecordSet {
            tau,
            channel_names: spec.columns.clone(),
            runs,
        })
    }
}

fn check_tau(tau: f64) -> Result<()> {
    if tau.is_finite() && tau > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidTau(tau))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str, spec: CsvSpec) -> Result<RecordSet> {
        RecordSet::from_reader(text.as_bytes(), "t.csv", &spec)
    }

    fn spec(cols: &[&str], run: Option<&str>, time: Option<&str>, tau: Option<f64>) -> CsvSpec {
        CsvSpec {
            columns: cols.iter().map(|s| s.to_string()).collect(),
            run_column: run.map(Into::into),
            time_column: time.map(Into::into),
            tau,
        }
    }

    #[test]
    fn groups_runs_in_file_order_and_takes_tau_from_time() {
        let text = "run,t,y,u\n1,0,1,0\n1,0.1,2,0\n2,5,3,1\n1,0.2,4,0\n2,5.1,5,1\n";
        let rs = load(text, spec(&["y", "u"], Some("run"), Some("t"), None)).unwrap();
        assert_eq!(rs.runs.len(), 2);
        assert_eq!(rs.runs[0].id, "1");
        assert_eq!(rs.runs[0].channels[0], vec![1.0, 2.0, 4.0]);
        assert_eq!(rs.runs[1].channels[1], vec![1.0, 1.0]);
        assert!((rs.tau - 0.1).abs() < 1e-12);
        assert_eq!(rs.runs[1].t0, 5.0);
    }

    #[test]
    fn each_bad_input_names_row_and_column() {
        let e = load("t,y\n0,1\n", spec(&["z"], None, Some("t"), None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no column named 'z'") && e.contains("t, y"),
            "{e}"
        );
        let e = load("t,y\n0,1\n0.1,nan\n", spec(&["y"], None, Some("t"), None))
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 3") && e.contains("'y'"), "{e}");
        let e = load("t,y\n0,1\n0.1,abc\n", spec(&["y"], None, Some("t"), None))
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 3") && e.contains("abc"), "{e}");
        let e = load(
            "t,y\n0,1\n0.1,2\n0.05,3\n",
            spec(&["y"], None, Some("t"), None),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("row 4") && e.contains("does not increase"),
            "{e}"
        );
        let e = load(
            "t,y\n0,1\n0.1,2\n0.25,3\n",
            spec(&["y"], None, Some("t"), None),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("row 4") && e.contains("non-uniform"), "{e}");
        let e = load(
            "t,y\n0,1\n0.1,2\n",
            spec(&["y"], None, Some("t"), Some(0.2)),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("disagrees"), "{e}");
        let e = load("y\n1\n", spec(&["y"], None, None, Some(-1.0)))
            .unwrap_err()
            .to_string();
        assert!(e.contains("tau must be"), "{e}");
        let e = load("y\n1\n", spec(&["y"], None, None, None))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--tau"), "{e}");
        let rs = load("y\n1\n2\n", spec(&["y"], None, None, Some(0.1))).unwrap();
        let e = rs
            .require_min_len(10, "order 2 derivatives")
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 samples") && e.contains("at least 10"), "{e}");
    }
}
