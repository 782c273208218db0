//! Sweep engines: everything that touches *all* candidate columns.
//!
//! The LARS path algorithm (in [`crate::regression`]) only ever needs three things from the
//! full design matrix X (n_samples x n_candidates, column j = monomial j of the basis evaluated
//! on the feature rows):
//! 1. column statistics (weighted mean and centred norm) of every candidate, once;
//! 2. the correlation sweep `X^T v` for a vector v, once or a few times per step;
//! 3. exact f64 values of the few columns that enter the active set.
//!
//! [`SweepEngine`] is that interface, in the spirit of faer's matrix-free `LinOp`: the
//! algorithm is written once against it, and an engine decides how the monomial values are
//! produced (on the fly, never materialised above a size limit) and where the arithmetic runs
//! (CPU threads or GPU compute shaders). Engines compute *raw* sums; centring, scaling and
//! weights are the algorithm's business (it passes `w * v` when it wants a weighted sweep), which
//! keeps engines small and lets CPU and GPU results be compared element by element.

use crate::error::{Error, Result};

pub mod columns;
pub mod cpu;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod select;

pub use columns::WithColumns;
pub use cpu::{CpuEngine, CpuOptions, DenseEngine};

/// Feature rows Z, stored column-major (variable k is `data[k*n_samples..(k+1)*n_samples]`).
#[derive(Debug, Clone)]
pub struct Features {
    pub n_samples: usize,
    pub names: Vec<String>,
    pub data: Vec<f64>,
}

impl Features {
    /// One column per name, all of one length. Refuses a number of names other than of columns, and
    /// columns of different lengths.
    pub fn new(names: Vec<String>, columns: Vec<Vec<f64>>) -> Result<Features> {
        if names.len() != columns.len() {
            return Err(Error::InvalidData(format!(
                "{} feature names for {} columns",
                names.len(),
                columns.len()
            )));
        }
        let n_samples = columns.first().map_or(0, |c| c.len());
        if let Some(k) = columns.iter().position(|c| c.len() != n_samples) {
            return Err(Error::InvalidData(format!(
                "feature '{}' has {} samples, '{}' has {n_samples}",
                names[k],
                columns[k].len(),
                names[0]
            )));
        }
        Ok(Features {
            n_samples,
            names,
            data: columns.concat(),
        })
    }

    /// The shape the engines rely on (the fields are public: a value built by hand is checked
    /// where it is used). Refuses `data` whose length is not `names.len() * n_samples`.
    pub fn check(&self) -> Result<()> {
        if self.data.len() != self.names.len() * self.n_samples {
            return Err(Error::InvalidData(format!(
                "features: {} values for {} variables x {} samples",
                self.data.len(),
                self.names.len(),
                self.n_samples
            )));
        }
        Ok(())
    }

    pub fn n_vars(&self) -> usize {
        self.names.len()
    }

    /// Samples of variable `k`. Panics when `data` holds fewer than `(k + 1) * n_samples` values
    /// (on a value that passes [`Features::check`]: `k` not below [`Features::n_vars`]).
    pub fn column(&self, k: usize) -> &[f64] {
        &self.data[k * self.n_samples..(k + 1) * self.n_samples]
    }
}

/// Weighted statistics of every candidate column.
#[derive(Debug, Clone, Default)]
pub struct ColumnStats {
    /// mean_j = sum_i w_i x_ij / sum_i w_i
    pub mean: Vec<f64>,
    /// norm_j = sqrt(sum_i w_i (x_ij - mean_j)^2)
    pub norm: Vec<f64>,
}

/// The arithmetic an engine uses to build monomial values; sums are always accumulated in f64.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    F32,
    #[default]
    F64,
}

/// What the path algorithm needs from the full candidate matrix (see the module docs).
pub trait SweepEngine {
    /// Short description for logs and reports, e.g. `cpu (f64, 2 threads)`.
    fn describe(&self) -> String;
    fn n_samples(&self) -> usize;
    fn n_candidates(&self) -> usize;
    /// Weighted mean and centred norm of every candidate; `None` means unit weights.
    fn column_stats(&mut self, weights: Option<&[f64]>) -> Result<ColumnStats>;
    /// `out[j] = sum_i x_ij * v[i]` for every candidate j (`v.len() == n_samples`).
    fn sweep(&mut self, v: &[f64], out: &mut [f64]) -> Result<()>;
    /// Exact f64 values of the chosen columns, each of length n_samples, in the order of `idx`.
    fn columns(&mut self, idx: &[usize]) -> Result<Vec<Vec<f64>>>;
}
