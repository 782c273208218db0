//! A materialised f64 design: the reference engine for tiny problems and for tests that bring
//! their own matrix (for example the scikit-learn fixtures). Exact f64 throughout.

use crate::engine::{ColumnStats, SweepEngine};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// Column-major n_samples x n_candidates matrix.
#[derive(Debug, Clone)]
pub struct DenseEngine {
    n_samples: usize,
    n_candidates: usize,
    data: Vec<f64>,
}

impl DenseEngine {
    /// A design of `n_samples` rows stored column after column; refuses `data` of another
    /// length than `n_samples * n_candidates`.
    pub fn from_column_major(
        n_samples: usize,
        n_candidates: usize,
        data: Vec<f64>,
    ) -> Result<DenseEngine> {
        if Some(data.len()) != n_samples.checked_mul(n_candidates) {
            return Err(Error::InvalidData(format!(
                "a dense design of {n_samples} x {n_candidates} needs that many values, got {}",
                data.len()
            )));
        }
        Ok(DenseEngine {
            n_samples,
            n_candidates,
            data,
        })
    }

    /// Builds from columns of equal length. Refuses columns of different lengths.
    pub fn from_columns(columns: &[Vec<f64>]) -> Result<DenseEngine> {
        let n = columns.first().map_or(0, Vec::len);
        if columns.iter().any(|c| c.len() != n) {
            return Err(Error::InvalidData(
                "design columns have different lengths".into(),
            ));
        }
        DenseEngine::from_column_major(n, columns.len(), columns.concat())
    }

    fn col(&self, j: usize) -> &[f64] {
        &self.data[j * self.n_samples..(j + 1) * self.n_samples]
    }
}

impl SweepEngine for DenseEngine {
    fn describe(&self) -> String {
        format!(
            "cpu (materialised f64, {} x {})",
            self.n_samples, self.n_candidates
        )
    }

    fn n_samples(&self) -> usize {
        self.n_samples
    }

    fn n_candidates(&self) -> usize {
        self.n_candidates
    }

    fn column_stats(&mut self, weights: Option<&[f64]>) -> Result<ColumnStats> {
        super::check_weights(weights, self.n_samples)?;
        let n = self.n_samples;
        let w = |i: usize| weights.map_or(1.0, |w| w[i]);
        let sw: f64 = (0..n).map(w).sum();
        let (mean, norm) = (0..self.n_candidates)
            .into_par_iter()
            .map(|j| {
                let c = self.col(j);
                let m = c.iter().enumerate().map(|(i, x)| w(i) * x).sum::<f64>() / sw;
                let s = c
                    .iter()
                    .enumerate()
                    .map(|(i, x)| w(i) * (x - m) * (x - m))
                    .sum::<f64>();
                (m, s.sqrt())
            })
            .unzip();
        Ok(ColumnStats { mean, norm })
    }

    fn sweep(&mut self, v: &[f64], out: &mut [f64]) -> Result<()> {
        if v.len() != self.n_samples || out.len() != self.n_candidates {
            return Err(Error::param(
                "sweep",
                "vector lengths do not match the design",
            ));
        }
        // X^T v by faer's matrix product: an implementation independent of the matrix-free
        // engines this one checks. Sequential, so that the reference is deterministic.
        let x =
            faer::MatRef::from_column_major_slice(&self.data, self.n_samples, self.n_candidates);
        let v = faer::ColRef::from_slice(v);
        let out = faer::ColMut::from_slice_mut(out);
        faer::linalg::matmul::matmul(
            out.as_mat_mut(),
            faer::Accum::Replace,
            x.transpose(),
            v.as_mat(),
            1.0,
            faer::Par::Seq,
        );
        Ok(())
    }

    fn columns(&mut self, idx: &[usize]) -> Result<Vec<Vec<f64>>> {
        idx.iter()
            .map(|&j| {
                if j < self.n_candidates {
                    Ok(self.col(j).to_vec())
                } else {
                    Err(Error::param(
                        "columns",
                        format!(
                            "candidate {j} is out of range ({} candidates)",
                            self.n_candidates
                        ),
                    ))
                }
            })
            .collect()
    }
}
