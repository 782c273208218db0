//! Record sets: one or more runs (experiments), each uniformly sampled at tau, with named
//! channels (inputs and outputs alike; the workflow decides which is which).
//!
//! Loading from CSV selects channels by column name, optionally groups rows into runs by a run
//! column (rows with the same id form one run, in file order; runs are ordered by first
//! appearance) and optionally checks a time column: strictly increasing within each run and
//! uniform to 1e-6 relative; tau comes from it when not given. Every problem is reported as one
//! line naming the file, the row (1-based, the header is row 1) and the column.

use crate::error::{Error, Result};
use crate::model::Interpolation;
use std::path::Path;

/// Relative tolerance on the sampling period.
pub const TAU_RTOL: f64 = 1e-6;

/// The first sample that is not a finite number below [`MAX_MAGNITUDE`] in magnitude (one test
/// for NaN, infinities and values too large to square). `None` when every sample is usable.
pub fn first_unusable(v: &[f64]) -> Option<usize> {
    v.iter()
        .position(|x| x.is_nan() || x.abs() >= MAX_MAGNITUDE)
}

/// The longest stretch of consecutive samples of `x` equal to `v` that does not start at the
/// first sample (0 where there is none).
fn longest_entered_stretch(x: &[f64], v: f64) -> usize {
    // `leading`: still in the samples the run starts with at `v`.
    let (mut best, mut cur, mut leading) = (0usize, 0usize, true);
    for &xk in x {
        if xk != v {
            (cur, leading) = (0, false);
        } else if !leading {
            cur += 1;
            best = best.max(cur);
        }
    }
    best
}

/// What is wrong with an unusable sample (see [`first_unusable`]), for messages.
pub fn unusable_reason(v: f64) -> String {
    if v.is_finite() {
        format!(
            "{v:e} is too large in magnitude to compute with (limit {MAX_MAGNITUDE:e}); rescale it"
        )
    } else {
        format!("{v} is not a finite number")
    }
}

/// The sample of channel `c` furthest from the channel's median, as (run, sample, ratio,
/// count): `ratio` is its distance from the median over that of the furthest sample but one in
/// `OUTLIER_SHARE` (at least the third furthest), and `count` the samples beyond `threshold`
/// times that reference. A glitch or a
/// missing-value code stands alone far outside; a settled step response (most samples at its
/// final value) or a step input has no such gap, though its median absolute deviation may be
/// near zero. None where the reference distance is 0 (an impulse on a constant channel).
fn furthest_sample(runs: &[Run], c: usize, threshold: f64) -> Option<(usize, usize, f64, usize)> {
    let mut v: Vec<f64> = runs
        .iter()
        .flat_map(|r| r.channels[c].iter().copied())
        .collect();
    if v.len() < 3 {
        return None;
    }
    let mid = v.len() / 2;
    let median = *v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
    for x in v.iter_mut() {
        *x = (*x - median).abs();
    }
    let rank = (v.len() / OUTLIER_SHARE).max(2);
    let reference = *v.select_nth_unstable_by(rank, |a, b| b.total_cmp(a)).1;
    if reference <= 0.0 {
        return None;
    }
    let (mut worst, mut at, mut beyond) = (0.0, (0, 0), 0);
    for (r, run) in runs.iter().enumerate() {
        for (i, x) in run.channels[c].iter().enumerate() {
            let d = (x - median).abs();
            beyond += (d > threshold * reference) as usize;
            if d > worst {
                (worst, at) = (d, (r, i));
            }
        }
    }
    Some((at.0, at.1, worst / reference, beyond))
}

/// Up to one sample in this many may stand out before the reference distance of
/// `furthest_sample` is one of them.
const OUTLIER_SHARE: usize = 500;

/// A sample far outside the rest of its channel (see [`RecordSet::suspect_samples`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Suspect {
    pub channel: String,
    pub run: String,
    /// Sample index within the run, and the CSV row where the record came from a file.
    pub sample: usize,
    pub row: Option<usize>,
    pub value: f64,
    /// Distance from the channel's median over that of nearly all its samples (see
    /// `furthest_sample`).
    pub ratio: f64,
    /// Samples of the channel that stand out as far (beyond [`SUSPECT_OUTLIER`]), this one
    /// included.
    pub count: usize,
}

impl Suspect {
    /// The one-line note the command line prints (and the Python package warns) for it.
    pub fn note(&self) -> String {
        let others = match self.count {
            0 | 1 => String::new(),
            n => format!(" ({} more as far out)", n - 1),
        };
        format!(
            "{}: {} is {:.1e} times further from the channel's median than nearly all its samples{others}: a missing-value code or a glitch? if so, remove or repair it",
            self.place(),
            crate::util::short(self.value),
            self.ratio
        )
    }

    /// Where it is: 'row 42, column 'y'' for a file, else run and sample.
    pub fn place(&self) -> String {
        match self.row {
            Some(row) => format!("row {row}, column '{}'", self.channel),
            None => format!(
                "run '{}': channel '{}' sample {}",
                self.run, self.channel, self.sample
            ),
        }
    }
}

/// A sample this many times further from its channel's median than nearly all others (see
/// `furthest_sample`) is reported by [`RecordSet::suspect_samples`]: a missing-value code such
/// as -9999 in a signal of size 1 stands out by 1e4. No shared record or test signal has one
/// (`tests/real_records.rs`), the exact fourth derivative of the throttle's 1 ms transient
/// included.
pub const SUSPECT_OUTLIER: f64 = 1e3;

/// Largest magnitude a sample may have: its square must stay finite in f64 (overflow at 1.8e308).
/// Higher powers, in polynomial features, are checked where a regression chooses the precision
/// of its sweeps (f64 on the CPU when f32 monomials would overflow).
pub const MAX_MAGNITUDE: f64 = 1e150;

/// Smallest largest-magnitude a channel may have (all zeros aside): below it squares fall under
/// 1e-200 and products of a few of them into subnormal numbers, where derivatives, regression
/// and simulation silently lose every digit (identification went wrong at 1e-150 and a
/// simulation scored RMS 0 at 1e-300).
pub const MIN_MAGNITUDE: f64 = 1e-100;

/// A sample this many times further from its channel's median than nearly all others is
/// refused as corrupt: a spike of 1e149 in a signal of size 1 passed every other check and made
/// junk of the model.
pub const MAX_OUTLIER: f64 = 1e12;

/// One run: samples of every channel, all of the same length.
#[derive(Debug, Clone)]
pub struct Run {
    pub id: String,
    /// `channels[c][i]`: sample i of channel c (channel order of the record set).
    pub channels: Vec<Vec<f64>>,
    /// Time of the first sample (0 when no time column was given).
    pub t0: f64,
    /// 1-based CSV row of each sample, for error messages downstream; empty for a run built in
    /// memory (messages then name the sample).
    pub rows: Vec<usize>,
}

impl Run {
    /// A run built in memory: `channels[c][i]`, sample i of channel c in the record set's channel
    /// order, starting at time 0, with no CSV rows (messages then name the run and the sample).
    ///
    /// ```
    /// use ctsid::records::{RecordSet, Run};
    /// let y: Vec<f64> = (0..100).map(|k| (0.1 * k as f64).sin()).collect();
    /// let u = vec![1.0; 100];
    /// let rs = RecordSet::new(0.01, vec!["y".into(), "u".into()], vec![Run::new("0", vec![y, u])])?;
    /// assert_eq!(rs.runs[0].len(), 100);
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn new(id: impl Into<String>, channels: Vec<Vec<f64>>) -> Run {
        Run {
            id: id.into(),
            channels,
            t0: 0.0,
            rows: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, |c| c.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// How a channel moves between samples ([`RecordSet::step_shape`]).
#[derive(Debug, Clone, Copy)]
pub struct StepShape {
    /// Share of the sample-to-sample steps with no change (a signal held for several samples).
    pub held: f64,
    /// Sum of |second differences| over the sum of |first differences|: near 0 for a signal
    /// that varies smoothly between samples, near 1 or above for one that jumps.
    pub roughness: f64,
}

/// A channel held at its extreme value ([`RecordSet::held_extremes`]): the value and the longest
/// stretch of consecutive samples at it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldExtreme {
    pub value: f64,
    pub samples: usize,
}

/// Consecutive samples at a channel's extreme value from which [`RecordSet::held_extremes`] reads
/// a hard limit: a noisy sensor that moves never repeats its value five times, a level that
/// overflows or a carriage against its stop does.
pub const HELD_EXTREME_SAMPLES: usize = 5;

/// Share of the steps away from the extremes that may repeat a value for
/// [`RecordSet::held_extremes`]: a coarsely quantised sensor repeats values everywhere, and its
/// value held at a turning point says nothing of a limit.
const REPEATS_ELSEWHERE: f64 = 0.01;

/// Share of a channel's sample-to-sample steps with no change above which it looks held between
/// samples (steps a generator or a controller holds for several samples).
pub const HELD_SHARE: f64 = 0.5;

impl StepShape {
    /// Whether the channel keeps its value over more than [`HELD_SHARE`] of its steps.
    pub fn is_held(&self) -> bool {
        self.held > HELD_SHARE
    }

    /// The reading between samples these steps suggest where `reading` does not suit them:
    /// `hold` for a held signal read by straight lines or a spline (which ramp each change over
    /// a sample), `linear` for a signal that varies smoothly read as held; `None` otherwise.
    /// `identify`'s note and `simulate`'s use this one rule.
    pub fn suggests(&self, reading: Interpolation) -> Option<Interpolation> {
        let smooth = self.held < 0.05 && self.roughness < 0.5;
        match reading {
            Interpolation::Hold if smooth => Some(Interpolation::Linear),
            Interpolation::Linear | Interpolation::Cubic if self.is_held() => {
                Some(Interpolation::Hold)
            }
            _ => None,
        }
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
    /// The rows are samples of a static relation (`regress`), not runs in time: a column named
    /// like a run id is not checked to hold one run (see [`RecordSet::from_reader`]).
    pub rows_independent: bool,
}

/// Fewest training samples an output must leave its resting value at ([`RecordSet::require_varies`]):
/// fewer cannot carry a derivative, let alone a dynamics.
pub const MIN_MOVING: usize = 10;

/// A run too short for the method, where runs were cut into pieces of `seconds`
/// ([`RecordSet::segmented_seconds`]), is a piece too short: mostly the fix is a longer piece,
/// given by `option` (`--segment`, `segment=`). A run shorter than a piece was not cut, and
/// needs more samples or a lower order. Other errors pass unchanged.
pub fn piece_too_short(e: Error, seconds: f64, option: &str) -> Error {
    match e {
        Error::RunTooShort {
            run,
            len,
            min,
            what,
        } => Error::param(
            "segment",
            format!(
                "piece '{run}' of {} s has {len} samples but {what} needs at least {min}; give a longer {option} (a run shorter than one piece needs more samples or a lower order)",
                crate::util::short(seconds)
            ),
        ),
        e => e,
    }
}

/// A piece's length in seconds for [`RecordSet::segmented_seconds`], checked before any data
/// are read: finite and > 0.
pub fn check_piece_seconds(seconds: f64) -> Result<()> {
    if seconds.is_finite() && seconds > 0.0 {
        return Ok(());
    }
    Err(Error::param(
        "segment",
        format!(
            "{} s; give the length of a piece in seconds, > 0",
            crate::util::short(seconds)
        ),
    ))
}

impl RecordSet {
    /// Builds a record set from in-memory runs (validated like a file). Refuses a tau that
    /// [`check_tau`] refuses, a channel name given twice, a run id used twice, a run with another number of channels
    /// than names, with no samples, with channels of different lengths or with row numbers
    /// that are not one per sample, a NaN, infinite or too large sample
    /// ([`first_unusable`]), a channel whose largest magnitude is below [`MIN_MAGNITUDE`] (all
    /// zeros aside) and a sample [`MAX_OUTLIER`] times further from its channel's median than
    /// nearly all others.
    pub fn new(tau: f64, channel_names: Vec<String>, runs: Vec<Run>) -> Result<RecordSet> {
        check_tau(tau)?;
        if let Some((_, j)) = crate::util::first_repeat(&channel_names) {
            return Err(Error::InvalidData(format!(
                "channel '{}' is named twice (channel {})",
                channel_names[j],
                j + 1
            )));
        }
        // Runs are named in split lists and reports: a repeated id would be silently left out
        // of a list (its name binds the first) or trained on beside its twin in the test list.
        let ids: Vec<&str> = runs.iter().map(|r| r.id.as_str()).collect();
        if let Some((i, j)) = crate::util::first_repeat(&ids) {
            return Err(Error::InvalidData(format!(
                "run id '{}' is used twice (runs {} and {})",
                ids[j],
                i + 1,
                j + 1
            )));
        }
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
            // Every channel empty (the lengths are compared below): its output was reported as
            // constant within every training run.
            if r.channels.iter().all(Vec::is_empty) {
                return Err(Error::InvalidData(format!("run '{}' has no samples", r.id)));
            }
            if !(r.rows.is_empty() || r.rows.len() == n) {
                return Err(Error::InvalidData(format!(
                    "run '{}' has {n} samples but {} CSV row numbers; give one per sample or none",
                    r.id,
                    r.rows.len()
                )));
            }
            for (c, ch) in r.channels.iter().enumerate() {
                if ch.len() != n {
                    return Err(Error::InvalidData(format!(
                        "run '{}': channel '{}' has {} samples, expected {n}",
                        r.id,
                        channel_names[c],
                        ch.len()
                    )));
                }
                if let Some(i) = first_unusable(ch) {
                    return Err(Error::InvalidData(format!(
                        "run '{}': channel '{}' sample {i}: {}",
                        r.id,
                        channel_names[c],
                        unusable_reason(ch[i])
                    )));
                }
            }
        }
        for (c, name) in channel_names.iter().enumerate() {
            let largest = runs
                .iter()
                .flat_map(|r| r.channels[c].iter())
                .fold(0.0f64, |m, x| m.max(x.abs()));
            if largest > 0.0 && largest < MIN_MAGNITUDE {
                return Err(Error::InvalidData(format!(
                    "channel '{name}': its largest magnitude is {largest:e}, too small to compute with (limit {MIN_MAGNITUDE:e}: its squares and products underflow); rescale it"
                )));
            }
            if let Some((r, i, ratio, _)) =
                furthest_sample(&runs, c, MAX_OUTLIER).filter(|f| f.2 > MAX_OUTLIER)
            {
                let at = match runs[r].rows.get(i) {
                    Some(row) => format!("row {row}, column '{name}'"),
                    None => format!("run '{}': channel '{name}' sample {i}", runs[r].id),
                };
                return Err(Error::InvalidData(format!(
                    "{at}: {} is {ratio:.1e} times further from the channel's median than nearly all its samples; a corrupted sample or a missing-value code? remove or repair it",
                    crate::util::short(runs[r].channels[c][i])
                )));
            }
        }
        Ok(RecordSet {
            tau,
            channel_names,
            runs,
        })
    }

    /// The sample furthest from the rest of each channel where it lies [`SUSPECT_OUTLIER`] times
    /// further from the channel's median than nearly all others: legal values that look like a glitch or
    /// a missing-value code. Callers decide what to say; the record set keeps them.
    pub fn suspect_samples(&self) -> Vec<Suspect> {
        (0..self.channel_names.len())
            .filter_map(|c| {
                let (r, i, ratio, count) = furthest_sample(&self.runs, c, SUSPECT_OUTLIER)?;
                (ratio > SUSPECT_OUTLIER).then(|| Suspect {
                    channel: self.channel_names[c].clone(),
                    run: self.runs[r].id.clone(),
                    sample: i,
                    row: self.runs[r].rows.get(i).copied(),
                    value: self.runs[r].channels[c][i],
                    ratio,
                    count,
                })
            })
            .collect()
    }

    /// Index of a channel by name, with an error that lists the available ones. Refuses a name that
    /// is no channel.
    pub fn channel_index(&self, name: &str) -> Result<usize> {
        self.channel_names
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| Error::MissingColumn {
                path: "record set".into(),
                column: name.into(),
                available: crate::util::clip(&self.channel_names.join(", "), 400),
            })
    }

    /// Samples of one channel in run `run` (an index into `runs`). Refuses a name that is no
    /// channel and a run index out of range.
    pub fn channel(&self, run: usize, name: &str) -> Result<&[f64]> {
        let c = self.channel_index(name)?;
        let r = self.runs.get(run).ok_or_else(|| {
            Error::param(
                "run",
                format!(
                    "index {run} with {} runs in the record set",
                    self.runs.len()
                ),
            )
        })?;
        Ok(&r.channels[c])
    }

    /// Refuses a channel that is constant over `runs`: as an output there is nothing to explain,
    /// as an input it is indistinguishable from the constant term. `role` names it ("input"). An
    /// empty `runs` passes. Panics when an entry of `runs` is not below the number of runs, or
    /// (with `runs` not empty) `channel` is not below the number of channels.
    pub fn require_varies(&self, channel: usize, runs: &[usize], role: &str) -> Result<()> {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &r in runs {
            for &v in &self.runs[r].channels[channel] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        if lo.is_finite() && hi - lo <= 1e-12 * lo.abs().max(hi.abs()) {
            let name = &self.channel_names[channel];
            let fix = if role == "output" {
                "there is nothing to identify; check the column"
            } else {
                "it cannot be told from the constant term; vary it in the experiments or leave it out"
            };
            return Err(Error::InvalidData(format!(
                "{role} '{name}' is constant ({lo:?}) over the training runs: {fix}"
            )));
        }
        if role == "output" {
            self.require_moves(channel, runs)?;
        }
        Ok(())
    }

    /// Refuses an output that stays at one value on all but a handful ([`MIN_MOVING`]) of the
    /// samples of `runs` (at least ten times as many): a glitch in a constant column passed the
    /// check above and the fit failed later with "the chosen terms are linearly dependent".
    fn require_moves(&self, channel: usize, runs: &[usize]) -> Result<()> {
        let mut v: Vec<f64> = runs
            .iter()
            .flat_map(|&r| self.runs[r].channels[channel].iter().copied())
            .collect();
        let n = v.len();
        if n == 0 {
            return Ok(());
        }
        let mid = n / 2;
        let median = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        let tol = 1e-12 * median.abs().max(f64::MIN_POSITIVE);
        let moving = v.iter().filter(|x| (*x - median).abs() > tol).count();
        // On a record of a few samples the length is what is wrong, and is said later
        // (`require_derivable`).
        if moving < MIN_MOVING && n >= 10 * MIN_MOVING {
            return Err(Error::InvalidData(format!(
                "output '{}' is constant ({median:?}) except at {moving} of {n} training samples: there is nothing to identify; check the column (a glitch?)",
                self.channel_names[channel]
            )));
        }
        Ok(())
    }

    /// Refuses an input that is an output up to scale and offset over `runs` (correlation 1 to
    /// nine digits): the input column repeats the output (the same column named twice, a
    /// copy), so no equation can tell them apart (`identify` returned `y_d1 = 0` with no term).
    pub fn require_distinct(&self, input: usize, output: usize, runs: &[usize]) -> Result<()> {
        let pairs = || {
            runs.iter().flat_map(move |&r| {
                let run = &self.runs[r];
                run.channels[input]
                    .iter()
                    .zip(&run.channels[output])
                    .map(|(&a, &b)| (a, b))
            })
        };
        let n = pairs().count().max(1) as f64;
        let (ma, mb) = pairs().fold((0.0, 0.0), |(x, y), (a, b)| (x + a / n, y + b / n));
        let (mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0);
        for (a, b) in pairs() {
            saa += (a - ma) * (a - ma);
            sbb += (b - mb) * (b - mb);
            sab += (a - ma) * (b - mb);
        }
        let r = sab / (saa * sbb).sqrt();
        if r.abs() >= 1.0 - 1e-9 {
            return Err(Error::InvalidData(format!(
                "input '{}' is output '{}' up to scale and offset (correlation {r:.12}) over the training runs: an input must be what drives the machine; check the columns",
                self.channel_names[input], self.channel_names[output]
            )));
        }
        Ok(())
    }

    /// Refuses a channel that varies over `runs` only from run to run, constant within each of
    /// them (an output held at a different level in every training run): its derivatives are
    /// zero in every one of them, so there is no dynamics to identify and no run to tune the
    /// derivatives on. `role` names the channel's part in the message.
    pub fn require_varies_within(&self, channel: usize, runs: &[usize], role: &str) -> Result<()> {
        let varies = |r: usize| {
            let c = &self.runs[r].channels[channel];
            let (lo, hi) = c
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            lo.is_finite() && hi - lo > 1e-12 * lo.abs().max(hi.abs())
        };
        if runs.is_empty() || runs.iter().any(|&r| varies(r)) {
            return Ok(());
        }
        Err(Error::InvalidData(format!(
            "{role} '{}' is constant within every training run (its level changes only from run to run): there are no dynamics to identify; give training runs in which it moves",
            self.channel_names[channel]
        )))
    }

    /// How channel `c` moves from sample to sample over `runs`: what tells an input held between
    /// samples from one that varies smoothly (the model's `input_interpolation`). `None` where it
    /// never changes.
    pub fn step_shape(&self, c: usize, runs: &[usize]) -> Option<StepShape> {
        let (mut steps, mut held, mut d1, mut d2) = (0usize, 0usize, 0.0, 0.0);
        for x in runs
            .iter()
            .filter_map(|&r| self.runs.get(r))
            .map(|r| &r.channels[c])
        {
            steps += x.len().saturating_sub(1);
            held += x.windows(2).filter(|w| w[0] == w[1]).count();
            d1 += x.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>();
            d2 += x
                .windows(3)
                .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
                .sum::<f64>();
        }
        (d1 > 0.0).then(|| StepShape {
            held: held as f64 / steps.max(1) as f64,
            roughness: d2 / d1,
        })
    }

    /// Where channel `c` sits at its smallest and at its largest value over `runs` for at
    /// least [`HELD_EXTREME_SAMPLES`] consecutive samples, having moved there within a run (a
    /// run that starts at rest on its extreme is no limit): the signature of a hard limit, an
    /// overflowing tank's level or an end stop (the cascaded tanks' lower level held at 10 V for
    /// 27 samples). Nothing where the channel repeats a value in more than 1 % of its other
    /// steps (a coarse quantisation, a held signal; the samples a run starts with at rest aside),
    /// since a dwell at a turning point looks the same there.
    pub fn held_extremes(&self, c: usize, runs: &[usize]) -> [Option<HeldExtreme>; 2] {
        let xs: Vec<&[f64]> = runs
            .iter()
            .filter_map(|&r| self.runs.get(r))
            .map(|r| r.channels[c].as_slice())
            .collect();
        let (lo, hi) = xs
            .iter()
            .flat_map(|x| x.iter())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if lo >= hi {
            return [None, None];
        }
        let (mut steps, mut repeats) = (0usize, 0usize);
        for x in &xs {
            // A run that starts settled at rest repeats its first value without any limit.
            let settled = x.iter().take_while(|&&v| v == x[0]).count();
            for w in x[settled.saturating_sub(1)..].windows(2) {
                if w[0] != lo && w[0] != hi {
                    steps += 1;
                    repeats += usize::from(w[0] == w[1]);
                }
            }
        }
        if repeats as f64 > REPEATS_ELSEWHERE * steps as f64 {
            return [None, None];
        }
        [lo, hi].map(|v| {
            let samples = xs.iter().map(|x| longest_entered_stretch(x, v)).max()?;
            (samples >= HELD_EXTREME_SAMPLES).then_some(HeldExtreme { value: v, samples })
        })
    }

    /// Refuses any run too short for derivatives up to `order` (named by its id).
    pub fn require_derivable(&self, order: usize) -> Result<()> {
        self.require_min_len(
            crate::derivatives::min_samples(order),
            &format!("derivatives up to order {order}"),
        )
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

    /// The runs cut into consecutive pieces of `len` samples, each piece a run of its own.
    ///
    /// Most measured records are one long run; identification needs several (folds, a
    /// validation run, a test run), so a long run is cut where the experiment itself has no
    /// boundary. A remainder shorter than half a piece joins the last piece (no stub runs); a
    /// run shorter than `len` stays whole. Pieces are named `RUN#0`, `RUN#1`, ..., or `0`, `1`,
    /// ... when the set is the single run `0` a file without a run column gives;
    /// [`crate::identify::split::resolve`] lets a list name `RUN` for all its pieces, so run ids
    /// may not contain `#` themselves. Each piece keeps its own start time and CSV rows. Refuses
    /// `len` below 2 and a run id that contains `#`.
    pub fn segmented(&self, len: usize) -> Result<RecordSet> {
        if len < 2 {
            return Err(Error::param(
                "segment",
                format!("{len} samples per piece; give at least 2"),
            ));
        }
        let single = self.runs.len() == 1 && self.runs[0].id == "0";
        if let Some(r) = self.runs.iter().find(|r| r.id.contains('#')) {
            return Err(Error::param(
                "segment",
                format!(
                    "run '{}' has a '#' in its id, which names the pieces of cut runs; rename the run",
                    r.id
                ),
            ));
        }
        let mut runs = Vec::new();
        for r in &self.runs {
            let n = r.len();
            let mut k = (n / len).max(1);
            if n > k * len && n - k * len >= len.div_ceil(2) {
                k += 1;
            }
            for p in 0..k {
                let a = p * len;
                let b = if p + 1 == k { n } else { a + len };
                runs.push(Run {
                    id: if single {
                        p.to_string()
                    } else {
                        format!("{}#{p}", r.id)
                    },
                    channels: r.channels.iter().map(|c| c[a..b].to_vec()).collect(),
                    t0: r.t0 + a as f64 * self.tau,
                    rows: r.rows.get(a..b).map(<[usize]>::to_vec).unwrap_or_default(),
                });
            }
        }
        RecordSet::new(self.tau, self.channel_names.clone(), runs)
    }

    /// [`RecordSet::segmented`] with the piece given in seconds (the command line's
    /// `--segment`, Python's `segment=`): refuses a length that is not finite and > 0, or that
    /// is under 2 samples at this record's `tau`.
    pub fn segmented_seconds(&self, seconds: f64) -> Result<RecordSet> {
        check_piece_seconds(seconds)?;
        let len = (seconds / self.tau).round();
        if len < 2.0 {
            return Err(Error::param(
                "segment",
                format!(
                    "{} s is less than 2 samples at tau = {} s; give a longer piece",
                    crate::util::short(seconds),
                    crate::util::short(self.tau)
                ),
            ));
        }
        self.segmented(len.min(usize::MAX as f64) as usize)
    }

    /// Loads channels from a CSV file with a header row. Refuses a path that is not a readable
    /// regular file, and all that [`RecordSet::from_reader`] refuses.
    pub fn from_csv(path: impl AsRef<Path>, spec: &CsvSpec) -> Result<RecordSet> {
        let path = path.as_ref();
        let p = path.display().to_string();
        let file = crate::util::open_regular(path, None)?;
        Self::from_reader(file, &p, spec)
    }

    /// Loads `columns` of a CSV file whose runs are told apart by `run_column` (the whole file
    /// is one run without it), sampled every `tau` seconds. [`RecordSet::from_csv`] takes a
    /// time column instead. Refuses what [`RecordSet::from_csv`] refuses, a `tau` that
    /// [`check_tau`] refuses among it.
    ///
    /// ```
    /// use ctsid::RecordSet;
    /// let path = std::env::temp_dir().join("ctsid-doc-read-csv.csv");
    /// let rows: String = (0..40).map(|k| format!("{},{},{}\n", k / 20, k % 20, (k % 7) as f64)).collect();
    /// std::fs::write(&path, format!("run,y,u\n{rows}"))?;
    /// let records = RecordSet::read_csv(&path, &["y", "u"], Some("run"), 0.01)?;
    /// assert_eq!((records.runs.len(), records.runs[1].id.as_str()), (2, "1"));
    /// assert_eq!(records.channel(1, "u")?.len(), 20);
    /// // A column the file lacks is a one-line error naming it.
    /// let err = RecordSet::read_csv(&path, &["y", "w"], Some("run"), 0.01).unwrap_err();
    /// assert!(err.to_string().contains("'w'"), "{err}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn read_csv(
        path: impl AsRef<Path>,
        columns: &[&str],
        run_column: Option<&str>,
        tau: f64,
    ) -> Result<RecordSet> {
        let spec = CsvSpec {
            columns: columns.iter().map(|c| c.to_string()).collect(),
            run_column: run_column.map(str::to_string),
            time_column: None,
            tau: Some(tau),
            rows_independent: false,
        };
        Self::from_csv(path, &spec)
    }

    /// Loads from any reader; `label` names the source in messages. Refuses a tau that
    /// [`check_tau`] refuses, neither a tau nor a time column, a run or time column that is also a
    /// channel, no columns, an empty file, a column missing from the header or named twice in it, a
    /// malformed row (a wrong number of fields), a cell that is not a finite number below
    /// [`MAX_MAGNITUDE`], an empty run id, no data rows, times that do not increase within a run or
    /// are not uniform, a time column with no run of two samples and no tau, a tau that disagrees
    /// with the time column by more than [`TAU_RTOL`], a column named `run` or `run_id` that holds
    /// several runs where no run column is given (their runs would be joined; not checked where
    /// the spec's rows are independent), and all that [`RecordSet::new`] refuses.
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
        // One column cannot both name the runs and time them: every sample became a run of
        // its own, refused as "within run '0.00' times must increase".
        if let (Some(r), Some(t)) = (&spec.run_column, &spec.time_column) {
            if r == t {
                return Err(Error::InvalidData(format!(
                    "{label}: column '{r}' is given as both the run column and the time column; give each its own"
                )));
            }
        }
        // A run id or a time stamp is no signal: as a channel it would be fitted as one.
        for (role, col) in [("run", &spec.run_column), ("time", &spec.time_column)] {
            if let Some(c) = col.as_ref().filter(|c| spec.columns.contains(c)) {
                return Err(Error::InvalidData(format!(
                    "{label}: column '{c}' is the {role} column; it cannot also be an input or output channel"
                )));
            }
        }
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(false)
            .from_reader(reader);
        let at = locate_columns(&mut rdr, label, spec)?;
        let runs = read_rows(&mut rdr, label, spec, &at)?;
        let tau = match spec.time_column.as_deref() {
            Some(tname) => tau_from_times(&runs, spec.tau, tname, label, at.run.is_some())?,
            None => spec.tau,
        };
        finish(tau, runs, spec, label)
    }
}

/// Where the channels, the run id and the time stamps are in a file's rows.
struct Columns {
    channels: Vec<usize>,
    run: Option<usize>,
    time: Option<usize>,
    /// Without a run column: a column named `run` or `run_id` (any case), whose values are
    /// checked to be one run's ([`read_rows`]).
    unnamed_run: Option<(usize, String)>,
}

/// Reads the header and finds the columns `spec` names (each exactly once).
fn locate_columns<R: std::io::Read>(
    rdr: &mut csv::Reader<R>,
    label: &str,
    spec: &CsvSpec,
) -> Result<Columns> {
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
    if header.iter().all(|h| h.is_empty()) {
        return Err(Error::InvalidData(format!(
            "{label}: empty file (no header row naming the columns)"
        )));
    }
    let find = |name: &str| -> Result<usize> {
        let mut at = header.iter().enumerate().filter(|(_, h)| *h == name);
        match (at.next(), at.next()) {
            (Some((i, _)), None) => Ok(i),
            (Some((i, _)), Some((j, _))) => Err(Error::InvalidData(format!(
                "{label}: column '{name}' appears twice in the header (columns {} and {}); rename one",
                i + 1,
                j + 1
            ))),
            _ => Err(Error::MissingColumn {
                path: label.into(),
                column: name.into(),
                available: crate::util::clip(&header.join(", "), 400),
            }),
        }
    };
    if spec.columns.is_empty() {
        return Err(Error::param("columns", "name at least one column to load"));
    }
    Ok(Columns {
        channels: spec
            .columns
            .iter()
            .map(|c| find(c))
            .collect::<Result<_>>()?,
        run: spec.run_column.as_deref().map(find).transpose()?,
        time: spec.time_column.as_deref().map(find).transpose()?,
        unnamed_run: header
            .iter()
            .position(|h| ["run", "run_id"].contains(&h.to_ascii_lowercase().as_str()))
            .filter(|_| spec.run_column.is_none() && !spec.rows_independent)
            .map(|i| (i, header[i].clone())),
    })
}

/// A cell as a finite number that its squares cannot overflow, or the error naming it (by its
/// run too where the file has a run column: a row number alone left the run to be looked up).
fn parse_cell(s: &str, label: &str, (row, run): (usize, Option<&str>), col: &str) -> Result<f64> {
    // Formatted only for an error: this runs once per cell.
    let run = || {
        run.map_or(String::new(), |r| {
            format!(" (run '{}')", crate::util::clip(r, 40))
        })
    };
    match s.parse::<f64>() {
        Ok(v) if first_unusable(&[v]).is_none() => Ok(v),
        // Squares and low powers of larger values overflow f64.
        Ok(v) if v.is_finite() => Err(Error::ValueTooLarge {
            path: label.into(),
            row,
            run: run(),
            column: col.into(),
            value: v,
        }),
        _ => Err(Error::NonFinite {
            path: label.into(),
            row,
            run: run(),
            column: col.into(),
            value: crate::util::clip(s, 60),
        }),
    }
}

/// The data rows, gathered into runs by their run id in the order the ids first appear.
fn read_rows<R: std::io::Read>(
    rdr: &mut csv::Reader<R>,
    label: &str,
    spec: &CsvSpec,
    at: &Columns,
) -> Result<Vec<Acc>> {
    let mut runs: Vec<Acc> = Vec::new();
    let mut index: std::collections::HashMap<String, usize> = Default::default();
    let mut unnamed_first: Option<String> = None;
    for (i, rec) in rdr.records().enumerate() {
        let row = i + 2;
        let rec = rec.map_err(|e| Error::Csv {
            path: label.into(),
            row,
            message: e.to_string(),
        })?;
        // A file of several runs read without its run column is one run, its runs joined end to
        // end, and every figure of it still looks plausible.
        if let Some((c, name)) = &at.unnamed_run {
            let v = &rec[*c];
            match &unnamed_first {
                None => unnamed_first = Some(v.to_string()),
                Some(f) if f != v => {
                    return Err(Error::InvalidData(format!(
                        "{label}: column '{name}' holds more than one run ('{}' and '{}' at row {row}) but no run column was given: the runs would be joined end to end; give it as the run column (--run-column {name}), or drop it if the file is one run",
                        crate::util::clip(f, 40),
                        crate::util::clip(v, 40)
                    )))
                }
                Some(_) => {}
            }
        }
        let id = at
            .run
            .map(|c| rec[c].to_string())
            .unwrap_or_else(|| "0".into());
        // An empty id is a lost cell, not a run: as one it would pull the row out of its
        // run and blame the time column for the gap.
        if let (Some(c), true) = (&spec.run_column, id.is_empty()) {
            return Err(Error::InvalidData(format!(
                "{label}: row {row}, column '{c}': empty run id; give every row its run"
            )));
        }
        let k = *index.entry(id.clone()).or_insert_with(|| {
            runs.push(Acc {
                id: id.clone(),
                channels: vec![Vec::new(); at.channels.len()],
                times: Vec::new(),
                rows: Vec::new(),
            });
            runs.len() - 1
        });
        let acc = &mut runs[k];
        let at_row = (row, at.run.map(|_| id.as_str()));
        for (c, &col) in at.channels.iter().enumerate() {
            acc.channels[c].push(parse_cell(&rec[col], label, at_row, &spec.columns[c])?);
        }
        if let (Some(tc), Some(tname)) = (at.time, spec.time_column.as_deref()) {
            acc.times.push(parse_cell(&rec[tc], label, at_row, tname)?);
        }
        acc.rows.push(row);
    }
    if runs.is_empty() {
        return Err(Error::InvalidData(format!("{label}: no data rows")));
    }
    Ok(runs)
}

/// The sampling step from the time stamps of column `tname`: they must increase within each
/// run and be uniform (to [`TAU_RTOL`] or the stamps' own digits), and agree with a `given`
/// step. `given` when no run has two samples; an error when neither says the step.
fn tau_from_times(
    runs: &[Acc],
    given: Option<f64>,
    tname: &str,
    label: &str,
    has_run_column: bool,
) -> Result<Option<f64>> {
    for r in runs {
        for w in 1..r.times.len() {
            let (a, b) = (r.times[w - 1], r.times[w]);
            if b <= a {
                return Err(Error::TimeNotIncreasing {
                    path: label.into(),
                    row: r.rows[w],
                    column: tname.into(),
                    prev: a,
                    value: b,
                    hint: if has_run_column {
                        format!(
                            "within run '{}' times must increase: is the run id used twice, or the rows out of order?",
                            r.id
                        )
                    } else {
                        "sort the rows or give a run column".into()
                    },
                });
            }
        }
    }
    // The first run with two samples gives the step: its (lower) median step to judge
    // uniformity by, so that one odd step is blamed on its own row, then its mean step,
    // which carries every digit of the stamps, as tau.
    let Some(first) = runs.iter().find(|r| r.times.len() >= 2) else {
        if given.is_none() {
            return Err(Error::NoTimeStep {
                path: label.into(),
                column: tname.into(),
            });
        }
        return Ok(given);
    };
    let mut steps: Vec<f64> = first.times.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let median = steps[(steps.len() - 1) / 2];
    for r in runs {
        // Time stamps far from zero (Unix time) carry only so many digits: a step
        // is uniform when it agrees to 1e-6 relative or to a few units in the last
        // place of the stamps themselves.
        let big = r.times.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let tol = (TAU_RTOL * median).max(4.0 * big * f64::EPSILON);
        for w in 1..r.times.len() {
            let step = r.times[w] - r.times[w - 1];
            // Compare absolute times with the grid, so that stamps rounded in print pass. A
            // step half a step off is a lost or an extra sample whatever the grid says (the
            // grid's allowance grows with the sample's index, and from sample 1e6 on it let a
            // lost sample through).
            let expect = r.times[0] + w as f64 * median;
            // (Not where the stamps' own precision is a good part of a step.)
            let gross = (step - median).abs() > 0.5 * median && tol < 0.25 * median;
            if gross || (step - median).abs() > tol && (r.times[w] - expect).abs() > tol * w as f64
            {
                return Err(Error::TimeNonUniform {
                    path: label.into(),
                    row: r.rows[w],
                    column: tname.into(),
                    step,
                    tau: median,
                });
            }
        }
    }
    let n = first.times.len();
    let mean = (first.times[n - 1] - first.times[0]) / (n - 1) as f64;
    match given {
        Some(t) if ((t - mean) / t).abs() > TAU_RTOL => Err(Error::TauMismatch {
            given: t,
            from_time: mean,
            column: tname.into(),
        }),
        Some(t) => Ok(Some(t)),
        None => Ok(Some(mean)),
    }
}

/// One run while the file is read.
struct Acc {
    id: String,
    channels: Vec<Vec<f64>>,
    times: Vec<f64>,
    rows: Vec<usize>,
}

/// The record set from the grouped runs, once tau is settled.
fn finish(tau: Option<f64>, runs: Vec<Acc>, spec: &CsvSpec, label: &str) -> Result<RecordSet> {
    let tau = tau.ok_or(Error::MissingTau)?;
    let runs = runs
        .into_iter()
        .map(|a| Run {
            id: a.id,
            t0: a.times.first().copied().unwrap_or(0.0),
            channels: a.channels,
            rows: a.rows,
        })
        .collect();
    // Errors that name a row name the file too, as those found while reading do.
    RecordSet::new(tau, spec.columns.clone(), runs).map_err(|e| match e {
        Error::InvalidData(m) if m.starts_with("row ") => {
            Error::InvalidData(format!("{label}: {m}"))
        }
        e => e,
    })
}

/// Sampling periods outside [TAU_MIN, TAU_MAX] seconds are refused: beyond them the powers of
/// 1/tau that scale high derivatives leave the range of f64 (and no instrument samples there).
pub const TAU_MIN: f64 = 1e-12;
pub const TAU_MAX: f64 = 1e9;

/// Checks a sampling period (seconds) against [TAU_MIN, TAU_MAX]. NaN and infinities are refused
/// too.
pub fn check_tau(tau: f64) -> Result<()> {
    if (TAU_MIN..=TAU_MAX).contains(&tau) {
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
            rows_independent: false,
        }
    }

    #[test]
    fn an_extreme_held_after_moving_there_reads_as_a_limit_and_a_dwell_of_a_quantised_one_not() {
        let names = || vec!["y".to_string()];
        // Noise-like samples rising to 10, held there for 6 samples, falling again.
        let wave = |k: usize| 5.0 + 4.0 * (0.05 * k as f64).sin() + 0.01 * ((k * 7919) % 13) as f64;
        let mut y: Vec<f64> = (0..200).map(wave).collect();
        y[40..46].fill(10.0);
        let rs = RecordSet::new(0.1, names(), vec![Run::new("a", vec![y.clone()])]).unwrap();
        let [lo, hi] = rs.held_extremes(0, &[0]);
        assert_eq!(
            (lo, hi),
            (
                None,
                Some(HeldExtreme {
                    value: 10.0,
                    samples: 6
                })
            )
        );
        // Four samples are not enough; a run that starts on its extreme is at rest, not held.
        let mut short = y.clone();
        short[44..46].copy_from_slice(&[9.9, 9.8]);
        let mut rest = y.clone();
        rest[40..46].copy_from_slice(&[9.0, 8.9, 9.1, 8.8, 9.05, 8.95]);
        rest[..8].fill(-1.0);
        // A quantised signal repeats values everywhere: its held top says nothing of a limit.
        let quantised: Vec<f64> = y.iter().map(|v| (v * 2.0).round() / 2.0).collect();
        for (what, x) in [
            ("four samples", short),
            ("at rest", rest),
            ("quantised", quantised),
        ] {
            let rs = RecordSet::new(0.1, names(), vec![Run::new("a", vec![x])]).unwrap();
            assert_eq!(rs.held_extremes(0, &[0]), [None, None], "{what}");
        }
    }

    #[test]
    fn runs_built_in_memory_are_checked_and_named_by_sample() {
        let names = || vec!["y".to_string()];
        let e = RecordSet::new(0.1, names(), vec![Run::new("a", vec![vec![]])]).unwrap_err();
        assert_eq!(e.to_string(), "run 'a' has no samples");
        let mut r = Run::new("b", vec![vec![1.0, 2.0, 3.0]]);
        r.rows = vec![2, 3];
        let e = RecordSet::new(0.1, names(), vec![r])
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 samples but 2 CSV row numbers"), "{e}");
        // A glitch in a run without CSV rows is named by run and sample, not by a made-up row.
        let mut y: Vec<f64> = (0..300).map(|k| (0.1 * k as f64).sin()).collect();
        y[52] = 1e13;
        let e = RecordSet::new(0.1, names(), vec![Run::new("c", vec![y])]).unwrap_err();
        assert!(
            e.to_string().contains("run 'c': channel 'y' sample 52"),
            "{e}"
        );
    }

    #[test]
    fn pieces_in_seconds_round_to_samples_and_refuse_what_is_no_length() {
        let y: Vec<f64> = (0..100).map(|k| (0.1 * k as f64).sin()).collect();
        let rs = RecordSet::new(0.1, vec!["y".into()], vec![Run::new("0", vec![y])]).unwrap();
        // 2.54 s at tau 0.1 is 25 samples (rounded): pieces of 25.
        let s = rs.segmented_seconds(2.54).unwrap();
        assert_eq!(s.runs.iter().map(Run::len).collect::<Vec<_>>(), [25; 4]);
        // 0.16 s rounds to 2 samples (allowed), 0.14 s to 1 (refused).
        assert_eq!(rs.segmented_seconds(0.16).unwrap().runs.len(), 50);
        let e = rs.segmented_seconds(0.14).unwrap_err().to_string();
        assert!(e.contains("less than 2 samples at tau = 0.1 s"), "{e}");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = rs.segmented_seconds(bad).unwrap_err().to_string();
            assert!(
                e.contains("give the length of a piece in seconds, > 0"),
                "{e}"
            );
        }
        // A method's "run too short" on pieces says to give a longer piece.
        let short = Error::RunTooShort {
            run: "3".into(),
            len: 10,
            min: 16,
            what: "the derivatives".into(),
        };
        let e = piece_too_short(short, 1.0, "segment=").to_string();
        assert!(
            e.contains("piece '3' of 1 s has 10 samples") && e.contains("a longer segment="),
            "{e}"
        );
    }

    #[test]
    fn segmented_cuts_runs_into_pieces_that_keep_time_and_rows() {
        let run = |id: &str, n: usize| Run {
            id: id.into(),
            channels: vec![(0..n).map(|i| i as f64).collect()],
            t0: 10.0,
            rows: (2..n + 2).collect(),
        };
        // The one run of a file without a run column (id 0) gives plain numbers.
        let one = RecordSet::new(0.5, vec!["y".into()], vec![run("0", 23)]).unwrap();
        let s = one.segmented(10).unwrap();
        // 23 = 10 + 13: a remainder of 3 (< half a piece) joins the last piece.
        let ids: Vec<&str> = s.runs.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["0", "1"]);
        let named = RecordSet::new(0.5, vec!["y".into()], vec![run("est", 23)]).unwrap();
        let ids: Vec<String> = named
            .segmented(10)
            .unwrap()
            .runs
            .into_iter()
            .map(|r| r.id)
            .collect();
        assert_eq!(ids, ["est#0", "est#1"]);
        let hash = RecordSet::new(0.5, vec!["y".into()], vec![run("a#1", 23)]).unwrap();
        assert!(hash.segmented(10).unwrap_err().to_string().contains("'#'"));
        assert_eq!(s.runs[1].len(), 13);
        assert_eq!(s.runs[1].channels[0][0], 10.0);
        assert_eq!(s.runs[1].t0, 15.0);
        assert_eq!(s.runs[1].rows[0], 12);
        // A remainder of at least half a piece is a piece; a short run stays whole.
        let two = RecordSet::new(0.5, vec!["y".into()], vec![run("a", 25), run("b", 4)]).unwrap();
        let s = two.segmented(10).unwrap();
        let ids: Vec<&str> = s.runs.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["a#0", "a#1", "a#2", "b#0"]);
        let lens: Vec<usize> = s.runs.iter().map(Run::len).collect();
        assert_eq!(lens, [10, 10, 5, 4]);
        assert!(two.segmented(1).is_err());
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
        // One sample lost after a million: the grid's allowance had grown past a step.
        let mut text = String::from("t,y\n");
        for k in (0..=1_000_001u64).chain(1_000_003..1_000_010) {
            text.push_str(&format!("{k},1\n"));
        }
        let e = load(&text, spec(&["y"], None, Some("t"), None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("row 1000004") && e.contains("non-uniform"),
            "{e}"
        );
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
