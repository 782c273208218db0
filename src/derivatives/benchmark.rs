//! The comparison on `shared/signals`: our trimmed p95 and full p100 per signal, noise level and
//! order 1..4, beside the anchors quoted in the project's derivative issue (ml-derivatives 0.0.2,
//! better of its two modes, and an ML-tuned 6-state Kalman smoother). The anchor numbers are
//! reference measurements made outside this crate and are only printed, never used to decide.

use super::score::{coverage, normalised_percentile, spearman, trimmed_range};
use super::{differentiate_with, DerivativeOptions, Derivatives};
use crate::error::{Error, Result};
use std::path::Path;

pub const SIGNALS: [&str; 4] = ["sys3_multisine", "sines", "chirp", "etc_s1"];
pub const NOISES: [u32; 3] = [1, 3, 5];

/// The reference figures for one (signal, noise), orders 1..4: ml-derivatives' trimmed
/// p95, the Kalman smoother's trimmed p95, ml-derivatives' full p100 (where meaningful).
pub type Anchors = ([f64; 4], [f64; 4], Option<[f64; 4]>);

/// (signal, noise %) -> (ml-derivatives trimmed p95, Kalman trimmed p95, ml-derivatives full p100),
/// orders 1..4. `None` for a pair the issue gives no figures for.
pub fn anchors(signal: &str, noise: u32) -> Option<Anchors> {
    let t = match (signal, noise) {
        ("sys3_multisine", 1) => (
            [0.0464, 0.141, 1.59, 4.82],
            [0.0356, 0.0789, 0.216, 0.538],
            Some([0.068, 0.589, 2.77, 7.31]),
        ),
        ("sys3_multisine", 3) => (
            [0.128, 0.461, 2.25, 5.1],
            [0.0934, 0.22, 0.553, 1.34],
            Some([0.485, 1.03, 3.65, 7.77]),
        ),
        ("sys3_multisine", 5) => (
            [0.395, 0.885, 2.54, 5.73],
            [0.18, 0.426, 1.15, 2.67],
            Some([0.686, 1.36, 3.78, 13.5]),
        ),
        ("sines", 1) => (
            [0.0942, 0.158, 0.444, 0.817],
            [0.0555, 0.0815, 0.14, 0.211],
            Some([0.187, 0.74, 1.14, 0.902]),
        ),
        ("sines", 3) => (
            [0.205, 0.276, 0.643, 0.915],
            [0.104, 0.148, 0.213, 0.253],
            Some([1.07, 1.61, 1.3, 1.47]),
        ),
        ("sines", 5) => (
            [0.255, 0.407, 0.953, 1.05],
            [0.118, 0.155, 0.227, 0.281],
            Some([1.2, 2.31, 1.73, 1.19]),
        ),
        ("chirp", 1) => (
            [0.06, 0.627, 4.74, 10.3],
            [0.0222, 0.0543, 0.172, 0.604],
            Some([1.13, 5.42, 13.5, 20.2]),
        ),
        ("chirp", 3) => (
            [0.06, 0.637, 4.73, 10.3],
            [0.0338, 0.0933, 0.281, 0.849],
            Some([1.17, 5.56, 13.6, 20.3]),
        ),
        ("chirp", 5) => (
            [0.0705, 1.48, 5.48, 11.2],
            [0.048, 0.111, 0.306, 0.855],
            Some([1.22, 5.62, 13.7, 21.7]),
        ),
        ("etc_s1", 1) => ([0.165, 4.2, 41.5, 60.7], [0.179, 4.45, 16.1, 63.6], None),
        ("etc_s1", 3) => ([1.27, 48.1, 161.0, 956.0], [0.255, 4.72, 12.8, 44.0], None),
        ("etc_s1", 5) => (
            [10.1, 1320.0, 27500.0, 594000.0],
            [0.351, 5.84, 17.5, 39.4],
            None,
        ),
        _ => return None,
    };
    Some(t)
}

/// One test signal: time, exact derivatives y0..y4, and noisy measurements by noise percent.
pub struct Signal {
    pub name: String,
    pub tau: f64,
    pub truth: Vec<Vec<f64>>,
    pub noisy: Vec<(u32, Vec<f64>)>,
}

/// Loads `NAME.csv` from `dir`: columns `t`, `y0`..`y4` and `ym_1pct`, `ym_3pct`, `ym_5pct`.
/// Refuses a file that [`crate::records::RecordSet::from_csv`] refuses, a missing one or one that
/// lacks these columns among them.
pub fn load_signal(dir: &Path, name: &str) -> Result<Signal> {
    let mut columns: Vec<String> = (0..5).map(|k| format!("y{k}")).collect();
    columns.extend(NOISES.iter().map(|n| format!("ym_{n}pct")));
    let spec = crate::records::CsvSpec {
        columns,
        run_column: None,
        time_column: Some("t".into()),
        tau: None,
        rows_independent: false,
    };
    let rs = crate::records::RecordSet::from_csv(dir.join(format!("{name}.csv")), &spec)?;
    let mut ch = rs
        .runs
        .into_iter()
        .next()
        .map(|r| r.channels)
        .unwrap_or_default();
    let noisy = NOISES.iter().copied().zip(ch.split_off(5)).collect();
    Ok(Signal {
        name: name.into(),
        tau: rs.tau,
        truth: ch,
        noisy,
    })
}

/// Each published signal's sample count and period (`signals.json` beside them says the same),
/// which the gates and anchors are for.
fn published(name: &str) -> Option<(usize, f64)> {
    match name {
        "sys3_multisine" | "sines" | "chirp" => Some((1000, 0.01)),
        "etc_s1" => Some((1000, 0.003)),
        _ => None,
    }
}

/// The signal has the published length and period: a cut or resampled file was scored against
/// gates set for the published signal.
fn check_published(sig: &Signal) -> Result<()> {
    let Some((n, tau)) = published(&sig.name) else {
        return Ok(());
    };
    let have = sig.truth.first().map_or(0, Vec::len);
    if have != n || (sig.tau - tau).abs() > 1e-9 * tau {
        return Err(Error::InvalidData(format!(
            "{}.csv: {have} samples every {} s, the published signal has {n} every {} s; the gates are for the signals as published",
            sig.name,
            crate::util::short(sig.tau),
            crate::util::short(tau)
        )));
    }
    Ok(())
}

/// Our scores for one (signal, noise): per order 1..4.
#[derive(Debug, Clone)]
pub struct Row {
    pub signal: String,
    pub noise: u32,
    pub trimmed_p95: [f64; 4],
    pub full_p100: [f64; 4],
    /// Share of errors within 2 sigma (all samples), orders 1..4.
    pub coverage2: [f64; 4],
    /// Spearman correlation of sigma with |error|, orders 1..4.
    pub rank_corr: [f64; 4],
}

/// Scores one estimate `d` of `sig` at noise level `noise` (percent), orders 1 to 4. Panics
/// when `sig.truth`, `d.values` or `d.sigma` lacks an order 0..=4, or when one of their series
/// is shorter than `sig.truth[0]` (or, in `d.sigma`, longer).
pub fn score_one(sig: &Signal, d: &Derivatives, noise: u32) -> Row {
    let n = sig.truth[0].len();
    let (a, b) = trimmed_range(n);
    let mut row = Row {
        signal: sig.name.clone(),
        noise,
        trimmed_p95: [0.0; 4],
        full_p100: [0.0; 4],
        coverage2: [0.0; 4],
        rank_corr: [0.0; 4],
    };
    for k in 1..=4 {
        row.trimmed_p95[k - 1] = normalised_percentile(&d.values[k], &sig.truth[k], 95.0, a, b);
        row.full_p100[k - 1] = normalised_percentile(&d.values[k], &sig.truth[k], 100.0, 0, n);
        row.coverage2[k - 1] = coverage(&d.values[k], &sig.truth[k], &d.sigma[k], 2.0);
        let err: Vec<f64> = (0..n)
            .map(|i| (d.values[k][i] - sig.truth[k][i]).abs())
            .collect();
        row.rank_corr[k - 1] = spearman(&d.sigma[k], &err);
    }
    row
}

/// Runs the method on every signal and noise level in `dir`. Refuses a signal file that
/// [`load_signal`] refuses or whose length or period is not the published one, and a measurement
/// that [`differentiate_with`] refuses.
pub fn run(dir: &Path) -> Result<Vec<Row>> {
    run_with(dir, &DerivativeOptions::default())
}

/// As [`run`], with overrides (for experiments). Refuses what [`run`] refuses, and options that
/// [`differentiate_with`] refuses.
pub fn run_with(dir: &Path, opts: &DerivativeOptions) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    for name in SIGNALS {
        let sig = load_signal(dir, name)?;
        check_published(&sig)?;
        for (noise, y) in &sig.noisy {
            let d = differentiate_with(y, sig.tau, 4, opts)
                .map_err(|e| Error::InvalidData(format!("{name}.csv, ym_{noise}pct: {e}")))?;
            rows.push(score_one(&sig, &d, *noise));
        }
    }
    Ok(rows)
}

fn fmt4(v: &[f64; 4]) -> String {
    v.iter()
        .map(|x| format!("{:.3}", x))
        .collect::<Vec<_>>()
        .join("/")
}

/// The comparison table as Markdown, with a verdict per row against the gates.
pub fn table(rows: &[Row]) -> String {
    let mut s = String::from("| signal | noise | ours trimmed p95 | ml-derivatives | Kalman 6-state | ours full p100 | ml-der. full p100 | 2-sigma coverage | rank corr | gates |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let Some((ml, kal, mlfull)) = anchors(&r.signal, r.noise) else {
            continue;
        };
        let ok = gates_pass(r);
        s += &format!(
            "| {} | {}% | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.signal,
            r.noise,
            fmt4(&r.trimmed_p95),
            fmt4(&ml),
            fmt4(&kal),
            fmt4(&r.full_p100),
            mlfull.map(|v| fmt4(&v)).unwrap_or_else(|| "-".into()),
            r.coverage2
                .iter()
                .map(|x| format!("{:.2}", x))
                .collect::<Vec<_>>()
                .join("/"),
            r.rank_corr
                .iter()
                .map(|x| format!("{:.2}", x))
                .collect::<Vec<_>>()
                .join("/"),
            if ok { "pass" } else { "FAIL" }
        );
    }
    s
}

/// The gates for one (signal, noise %): per order 1..4, the largest trimmed p95 and, where
/// it applies, the largest full p100. Smooth signals: half of ml-derivatives' and the Kalman
/// smoother's trimmed p95, ml-derivatives' p100; etc_s1: either anchor at 1 %, half of
/// ml-derivatives' above. `None` where [`anchors`] has no figures.
pub fn gates(signal: &str, noise: u32) -> Option<([f64; 4], Option<[f64; 4]>)> {
    let (ml, kal, mlfull) = anchors(signal, noise)?;
    let p95 = std::array::from_fn(|k| match (signal, noise) {
        ("etc_s1", 1) => ml[k].min(kal[k]),
        ("etc_s1", _) => 0.5 * ml[k],
        _ => (0.5 * ml[k]).min(kal[k]),
    });
    Some((p95, mlfull.filter(|_| signal != "etc_s1")))
}

/// The accuracy gates for one row. A row with no gates ([`gates`] gives `None`) passes.
pub fn gates_pass(r: &Row) -> bool {
    let Some((p95, p100)) = gates(&r.signal, r.noise) else {
        return true;
    };
    (0..4).all(|k| r.trimmed_p95[k] <= p95[k] && p100.is_none_or(|f| r.full_p100[k] <= f[k]))
}
