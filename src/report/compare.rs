//! Measured against simulated, the report every command that simulates writes
//! (`identify`, `simulate`, `discover` with `--report DIR`).
//!
//! Per run and output, two figures:
//! - `sim_<run>_<output>.svg`: the measured output and each free run, the fit
//!   (`100 (1 - NRMSE)`, MATLAB's `compare`) in the title; the simulation error below; and on a
//!   record longer than [`ZOOM_ABOVE`] samples a window around the largest error, where both
//!   traces can be told apart.
//! - `resid_<run>_<output>.svg`: the residual analysis of the last free run's error
//!   ([`super::resid`]): its autocorrelation and its cross-correlation with each input, with 99 %
//!   bands, at 25 lags each side spread over 5 % of the record ([`resid::lag_stride`]).
//!
//! At most `limit` runs are drawn per output (the summary says how many were left out); the
//! summary table, returned as Markdown, lists every run given.

use super::resid::{self, Resid};
use super::svg::{figure, Panel, Series};
use super::write_file;
use crate::error::Result;
use crate::metrics::{fit_percent, rms_nrmse};
use crate::records::RecordSet;
use crate::util::num4;
use std::path::Path;

/// A fit in percent to one decimal, or `-` where it has no meaning (a constant measured output:
/// the NRMSE's scale is zero and the fit would read `-inf %`).
fn fit_text(sim: &[f64], meas: &[f64]) -> String {
    let f = fit_percent(sim, meas);
    if f.is_finite() {
        format!("{f:.1} %")
    } else {
        "-".into()
    }
}

/// Records longer than this many samples get a zoomed window.
pub const ZOOM_ABOVE: usize = 2000;

/// Runs drawn per output by default.
pub const PLOTTED_RUNS: usize = 6;

/// One run and output: the measured output, its free runs and the inputs that drove them.
pub struct Comparison<'a> {
    pub run: &'a str,
    /// Sample times in seconds.
    pub t: &'a [f64],
    /// The output's column name (the y axis label).
    pub output: &'a str,
    pub measured: &'a [f64],
    /// Free runs as (label, simulated output); the last is the model the report analyses.
    pub simulated: Vec<(&'a str, &'a [f64])>,
    /// Inputs as (column name, samples), for the cross-correlations.
    pub inputs: Vec<(&'a str, &'a [f64])>,
}

const COLORS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];
const MEASURED: &str = "#222222";

impl Comparison<'_> {
    /// Colour of free run `k`: the analysed (last) model is always blue.
    fn color(&self, k: usize) -> &'static str {
        COLORS[(self.simulated.len() - 1 - k) % COLORS.len()]
    }

    fn errors(&self) -> Vec<Vec<f64>> {
        self.simulated
            .iter()
            .map(|(_, s)| s.iter().zip(self.measured).map(|(s, m)| s - m).collect())
            .collect()
    }

    fn title(&self) -> String {
        let fits: Vec<String> = self
            .simulated
            .iter()
            .map(|(label, s)| format!("{label} fit {}", fit_text(s, self.measured)))
            .collect();
        format!("{}, run {}: {}", self.output, self.run, fits.join(", "))
    }

    /// The window of [`ZOOM_ABOVE`]-sample records around the analysed run's largest error:
    /// a twentieth of the record, at least 400 samples.
    fn zoom(&self, error: &[f64]) -> Option<(f64, f64)> {
        let n = self.t.len().min(error.len());
        if n <= ZOOM_ABOVE {
            return None;
        }
        let peak = (0..n)
            .filter(|&i| error[i].is_finite())
            .max_by(|&a, &b| error[a].abs().total_cmp(&error[b].abs()))?;
        let width = (n / 20).max(400);
        let start = peak.saturating_sub(width / 2).min(n - width);
        Some((self.t[start], self.t[start + width - 1]))
    }
}

/// The figure of measured and simulated outputs, the error below and, on long records, the zoom.
/// Panics when `c.measured` or a free run in `c.simulated` is shorter than `c.t`.
pub fn comparison_figure(c: &Comparison) -> String {
    let errors = c.errors();
    let mut traces = vec![Series {
        label: "measured",
        x: c.t,
        y: c.measured,
        color: MEASURED,
        band: None,
        dashed: false,
    }];
    let mut error_series = Vec::new();
    for (k, (label, sim)) in c.simulated.iter().enumerate() {
        let series = Series {
            label,
            x: c.t,
            y: sim,
            color: c.color(k),
            band: None,
            dashed: false,
        };
        traces.push(series);
        error_series.push(Series {
            y: &errors[k],
            ..series
        });
    }
    let mut panels = vec![
        Panel::lines("free run", "t (s)", c.output, traces.clone()),
        Panel::lines(
            "simulation error (simulated - measured)",
            "t (s)",
            &format!("{} error", c.output),
            error_series,
        )
        .height(200.0),
    ];
    if let Some((lo, hi)) = c.zoom(errors.last().map_or(&[][..], |e| &e[..])) {
        let title = format!(
            "zoom around the largest error, t in [{}, {}] s",
            num4(lo),
            num4(hi)
        );
        panels.push(Panel::lines(&title, "t (s)", c.output, traces).zoom(lo, hi));
    }
    figure(&c.title(), &panels)
}

/// The residual analysis of the analysed (last) free run, and its figure.
pub fn residual_figure(c: &Comparison) -> (Resid, String) {
    let error = c.errors().pop().unwrap_or_default();
    let stride = resid::lag_stride(error.len());
    let r = resid::analyse(&error, &c.inputs, resid::LAGS, stride);
    let dt = if c.t.len() > 1 { c.t[1] - c.t[0] } else { 1.0 };
    let mut data = vec![CorrelationData::new(
        format!(
            "autocorrelation of the error: {} of {} lags outside the 99 % band",
            r.auto.outside(),
            r.auto.tested()
        ),
        &r.auto,
        dt,
    )];
    for (name, cc) in &r.cross {
        data.push(CorrelationData::new(
            format!(
                "cross-correlation with {name} (positive lag: input leads): {} of {} outside",
                cc.outside(),
                cc.tested()
            ),
            cc,
            dt,
        ));
    }
    let panels: Vec<Panel> = data.iter().map(CorrelationData::panel).collect();
    let label = c.simulated.last().map_or("model", |s| s.0);
    let title = format!("{}, run {}: residual analysis of {label}", c.output, c.run);
    let svg = figure(&title, &panels);
    (r, svg)
}

/// A correlation as the slices a panel borrows.
struct CorrelationData {
    title: String,
    lags: Vec<f64>,
    r: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl CorrelationData {
    /// `dt`: the sampling period, so that lags read in seconds.
    fn new(title: String, c: &resid::Correlation, dt: f64) -> CorrelationData {
        CorrelationData {
            title,
            lags: c.lags.iter().map(|&k| k as f64 * dt).collect(),
            r: c.r.clone(),
            lo: vec![-c.bound; c.lags.len()],
            hi: vec![c.bound; c.lags.len()],
        }
    }

    fn panel(&self) -> Panel<'_> {
        let band = Series {
            label: "99 % band",
            x: &self.lags,
            y: &self.hi,
            color: "#888888",
            band: Some((&self.lo, &self.hi)),
            dashed: true,
        };
        let r = Series {
            label: "correlation",
            x: &self.lags,
            y: &self.r,
            color: COLORS[0],
            band: None,
            dashed: false,
        };
        Panel::stems(&self.title, "lag (s)", "r", vec![band, r])
    }
}

/// Writes both figures for the first `limit` runs of each output and returns the summary as
/// Markdown: per run and output the RMS, NRMSE, fit, error mean and the residual tests. Errs when a
/// figure cannot be written ([`write_file`]); a comparison without a free run is left out. Panics
/// as [`comparison_figure`] does, on the comparisons it draws.
pub fn write_comparisons(dir: &Path, comparisons: &[Comparison], limit: usize) -> Result<String> {
    let mut table = super::Table::new(&[
        "run",
        "output",
        "RMS",
        "fit %",
        "error mean",
        "autocorrelation outside 99 %",
        "cross-correlation outside 99 %",
        "plots",
    ]);
    let mut drawn = std::collections::HashMap::<&str, usize>::new();
    // File stems in use ([`super::unique_stem`]).
    let mut stems = std::collections::HashSet::<String>::new();
    let mut left_out = 0;
    for c in comparisons {
        let Some((_, sim)) = c.simulated.last() else {
            continue;
        };
        let count = drawn.entry(c.output).or_default();
        let (r, resid_svg) = residual_figure(c);
        let plots = if *count < limit {
            *count += 1;
            let base = super::safe_name(&format!("{}_{}", c.run, c.output));
            let stem = super::unique_stem(base, &mut stems);
            write_file(dir, &format!("sim_{stem}.svg"), &comparison_figure(c))?;
            write_file(dir, &format!("resid_{stem}.svg"), &resid_svg)?;
            format!("sim_{stem}.svg, resid_{stem}.svg")
        } else {
            left_out += 1;
            "-".into()
        };
        table.row(summary_row(c, sim, &r, plots));
    }
    let mut md = table.markdown();
    if left_out > 0 {
        md += &format!(
            "\n{left_out} run(s) not plotted (at most {limit} per output); their scores are above.\n"
        );
    }
    Ok(md)
}

fn summary_row(c: &Comparison, sim: &[f64], r: &Resid, plots: String) -> Vec<String> {
    let (rms, _) = rms_nrmse(sim, c.measured);
    let cross: Vec<String> = r
        .cross
        .iter()
        .map(|(n, cc)| format!("{n}: {}/{}", cc.outside(), cc.tested()))
        .collect();
    vec![
        c.run.to_string(),
        c.output.to_string(),
        num4(rms),
        fit_text(sim, c.measured).trim_end_matches(" %").to_string(),
        num4(r.mean),
        format!("{}/{}", r.auto.outside(), r.auto.tested()),
        if cross.is_empty() {
            "-".into()
        } else {
            cross.join(", ")
        },
        plots,
    ]
}

/// [`write_comparisons`] for free runs of one model on runs of a record set: `runs` holds
/// (index of the run in `records`, simulated outputs in the order of `outputs`); channels are
/// found by name. Times are the record's own (`t0 + k tau`). Every run is shown and scored from its
/// sample `from` on (`simulate --score-from`: the samples before it set the initial state and are
/// left out of the printed scores, so of these too; a run no longer than `from` shows nothing).
/// Refuses an output or input that is not
/// a channel of `records`, and errs as [`write_comparisons`] does. Panics when an index in `runs`
/// is not below the number of runs of `records`, a run's simulation has fewer outputs than
/// `outputs`, or (on a drawn run) a simulated output is shorter than its run.
pub fn write_record_report<'a>(
    dir: &Path,
    records: &'a RecordSet,
    outputs: &[&str],
    inputs: &[&str],
    label: &'a str,
    runs: &[(usize, &'a [Vec<f64>])],
    from: usize,
) -> Result<String> {
    let times: Vec<Vec<f64>> = runs
        .iter()
        .map(|&(r, _)| {
            let run = &records.runs[r];
            (from.min(run.len())..run.len())
                .map(|k| run.t0 + k as f64 * records.tau)
                .collect()
        })
        .collect();
    let tail = |x: &'a [f64]| &x[from.min(x.len())..];
    let channel = |r: usize, name: &str| -> Result<&[f64]> {
        Ok(tail(
            &records.runs[r].channels[records.channel_index(name)?],
        ))
    };
    let mut comparisons = Vec::new();
    // Output by output, so that each output's first runs are the ones drawn.
    for (o, &output) in outputs.iter().enumerate() {
        for (k, &(r, sim)) in runs.iter().enumerate() {
            comparisons.push(Comparison {
                run: &records.runs[r].id,
                t: &times[k],
                output,
                measured: channel(r, output)?,
                simulated: vec![(label, tail(&sim[o][..]))],
                inputs: inputs
                    .iter()
                    .map(|&i| Ok((i, channel(r, i)?)))
                    .collect::<Result<_>>()?,
            });
        }
    }
    write_comparisons(dir, &comparisons, PLOTTED_RUNS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_measured_output_has_no_fit_figure() {
        assert_eq!(fit_text(&[0.5, 0.6, 0.4], &[1.0; 3]), "-");
        assert_eq!(fit_text(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]), "100.0 %");
    }

    fn signals(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        let u: Vec<f64> = t.iter().map(|t| (3.0 * t).sin().signum()).collect();
        let y: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        let s: Vec<f64> = t.iter().map(|t| 0.9 * t.sin()).collect();
        (t, u, y, s)
    }

    fn comparison<'a>(t: &'a [f64], u: &'a [f64], y: &'a [f64], s: &'a [f64]) -> Comparison<'a> {
        Comparison {
            run: "r1",
            t,
            output: "angle (rad)",
            measured: y,
            simulated: vec![("model", s)],
            inputs: vec![("u (V)", u)],
        }
    }

    #[test]
    fn the_figure_names_the_fit_and_zooms_only_on_long_records() {
        let (t, u, y, s) = signals(500);
        let short = comparison_figure(&comparison(&t, &u, &y, &s));
        // 10 % too small everywhere: NRMSE 0.1 * rms(y) / sd(y).
        let fit = fit_percent(&s, &y);
        assert!(
            short.contains(&format!("model fit {fit:.1} %")),
            "{short:.300}"
        );
        assert!(short.contains("simulation error") && !short.contains("zoom"));
        assert!(
            short.contains("angle (rad)"),
            "the axis carries the column name"
        );
        let (t, u, y, s) = signals(10_000);
        let long = comparison_figure(&comparison(&t, &u, &y, &s));
        assert!(long.contains("zoom around the largest error"));
    }

    /// The report of [`comparison`] for each of `runs` (plots for at most `limit`) in a fresh
    /// folder named by `tag`: the folder and the summary.
    fn report_of(runs: &[&str], limit: usize, tag: &str) -> (std::path::PathBuf, String) {
        let (t, u, y, s) = signals(400);
        let cs: Vec<Comparison> = runs
            .iter()
            .map(|r| Comparison {
                run: r,
                ..comparison(&t, &u, &y, &s)
            })
            .collect();
        let dir = std::env::temp_dir().join(format!("ctsid-{tag}-{}", std::process::id()));
        let md = write_comparisons(&dir, &cs, limit).unwrap();
        (dir, md)
    }

    #[test]
    fn runs_beyond_the_limit_are_scored_but_not_drawn() {
        let (dir, md) = report_of(&["a", "b", "c"], 2, "compare");
        assert!(dir.join("sim_a_angle__rad_.svg").is_file());
        assert!(dir.join("resid_b_angle__rad_.svg").is_file());
        assert!(!dir.join("sim_c_angle__rad_.svg").exists());
        assert!(
            md.contains("| c |") && md.contains("1 run(s) not plotted"),
            "{md}"
        );
        let resid = std::fs::read_to_string(dir.join("resid_a_angle__rad_.svg")).unwrap();
        assert!(resid.contains("cross-correlation with u (V)") && resid.contains("99 % band"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn runs_of_one_safe_name_get_plots_of_their_own() {
        let (dir, md) = report_of(&["a b", "a_b"], 5, "compare-safe");
        assert!(dir.join("sim_a_b_angle__rad_.svg").is_file());
        assert!(dir.join("sim_a_b_angle__rad__2.svg").is_file());
        // The table names the files as they are on disk.
        assert!(md.contains("sim_a_b_angle__rad__2.svg"), "{md}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
