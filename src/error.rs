//! One error type for the library. Every variant renders as a single line that says what is
//! wrong and, where there is one, how to fix it; the CLI prints exactly that line.

use thiserror::Error;

/// Result alias used across the crate.
pub type Result<T> = std::result::Result<T, Error>;

/// Everything that can go wrong in ctsid, typed so library callers can react to it. New kinds
/// may be added: match with a wildcard arm.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// A file or stream that cannot be used, said in words (not a regular file, a missing
    /// folder, ...).
    #[error("{path}: {message}")]
    Io { path: String, message: String },

    /// An I/O operation on `path` failed; the `std::io::Error` is kept as the source.
    #[error("{path}: {source}")]
    File {
        path: String,
        #[source]
        source: std::io::Error,
    },

    #[error("{path}: CSV error at row {row}: {message}")]
    Csv {
        path: String,
        row: usize,
        message: String,
    },

    #[error("{path}: no column named '{column}' (columns are: {available})")]
    MissingColumn {
        path: String,
        column: String,
        available: String,
    },

    /// `run`: ` (run 'R')` where the file has a run column, else empty.
    #[error("{path}: row {row}{run}, column '{column}': '{value}' is not a finite number; remove or repair that sample")]
    NonFinite {
        path: String,
        row: usize,
        run: String,
        column: String,
        value: String,
    },

    /// `run` as in [`Error::NonFinite`].
    #[error("{path}: row {row}{run}, column '{column}': {value:e} is too large in magnitude to compute with (limit {:e}); rescale the column, e.g. to other units", crate::records::MAX_MAGNITUDE)]
    ValueTooLarge {
        path: String,
        row: usize,
        run: String,
        column: String,
        value: f64,
    },

    #[error("{path}: row {row}, column '{column}': time does not increase ({prev:?} then {value:?}); {hint}")]
    TimeNotIncreasing {
        path: String,
        row: usize,
        column: String,
        prev: f64,
        value: f64,
        /// What to do about it (depends on whether runs are grouped by a run column).
        hint: String,
    },

    #[error("{path}: row {row}, column '{column}': non-uniform sampling (step {step:?} s, expected {tau:?} s within 1e-6 relative); resample the record to a uniform grid, or, if the times are only rounded, give --tau and leave out the time column")]
    TimeNonUniform {
        path: String,
        row: usize,
        column: String,
        step: f64,
        tau: f64,
    },

    #[error("tau must be a number of seconds between {min:e} and {max:e}, got {0:?}", min = crate::records::TAU_MIN, max = crate::records::TAU_MAX)]
    InvalidTau(f64),

    #[error("--tau {given:?} disagrees with the time column '{column}' (step {from_time:?}); drop --tau or fix it")]
    TauMismatch {
        given: f64,
        from_time: f64,
        column: String,
    },

    #[error("no sampling period: give --tau or a --time-column")]
    MissingTau,

    #[error("{path}: no run has two samples, so the time column '{column}' gives no sampling period; give longer runs (or --tau)")]
    NoTimeStep { path: String, column: String },

    #[error("run '{run}' has {len} samples but {what} needs at least {min}; use longer runs or a lower order")]
    RunTooShort {
        run: String,
        len: usize,
        min: usize,
        what: String,
    },

    #[error("invalid setting '{name}': {reason}")]
    InvalidParameter { name: String, reason: String },

    #[error(
        "{what} needs about {needed_mib:.0} MiB, over the budget of {budget_mib:.0} MiB; {hint}"
    )]
    TooLarge {
        what: String,
        needed_mib: f64,
        budget_mib: f64,
        hint: String,
    },

    #[error("{0}")]
    InvalidData(String),

    #[error("numerical failure: {0}")]
    Numerical(String),

    #[error("GPU: {0}")]
    Gpu(String),

    #[error("no GPU adapter: {0}")]
    NoGpu(String),

    #[error("model file {path}: {message}")]
    Model { path: String, message: String },

    #[error("run '{run}': the model has an unstable mode growing at {rate:.3e} /s (e-fold every {:.3e} s) near t = {time:?} s, faster than the simulation's steps; the model is unstable there", 1.0 / rate)]
    UnstableMode { run: String, time: f64, rate: f64 },

    /// A term of the right-hand side went non-finite during a free run (not an instability).
    #[error("run '{run}': {what} at t = {time:?} s ({state}); the free run cannot go on from there (a root or power of a value that went negative, a division by zero)")]
    TermNotFinite {
        run: String,
        time: f64,
        what: String,
        state: String,
    },

    #[error("simulation diverged at t = {time:?} s into run '{run}' (state {state}); the model's free run is unstable there")]
    Diverged {
        run: String,
        time: f64,
        state: String,
    },
}

impl Error {
    /// Shorthand for an [`Error::File`]: `path` and the I/O error that happened on it.
    pub fn file(path: impl Into<String>, source: std::io::Error) -> Self {
        Error::File {
            path: path.into(),
            source,
        }
    }

    /// Shorthand for an [`Error::InvalidParameter`].
    pub fn param(name: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        }
    }
}
