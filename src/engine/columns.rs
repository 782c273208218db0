//! Candidates beyond the monomial basis: dense columns computed on the CPU (the named terms of
//! `identify --term`), appended after any engine's own candidates.
//!
//! The matrix-free monomial sweep stays as it is, on the CPU or the GPU; a handful of extra
//! columns costs one dot product each per sweep, in f64, beside it.

use super::{ColumnStats, SweepEngine};
use crate::error::{Error, Result};

/// An engine's candidates followed by `columns` (each of the engine's sample count).
pub struct WithColumns<'a> {
    inner: &'a mut dyn SweepEngine,
    columns: &'a [Vec<f64>],
}

impl<'a> WithColumns<'a> {
    /// Fails when a column's length is not the engine's sample count.
    pub fn new(inner: &'a mut dyn SweepEngine, columns: &'a [Vec<f64>]) -> Result<WithColumns<'a>> {
        let n = inner.n_samples();
        if let Some(k) = columns.iter().position(|c| c.len() != n) {
            return Err(Error::InvalidData(format!(
                "extra column {} has {} samples, the engine {n}",
                k + 1,
                columns[k].len()
            )));
        }
        Ok(WithColumns { inner, columns })
    }

    /// The wrapped engine.
    pub fn into_inner(self) -> &'a mut dyn SweepEngine {
        self.inner
    }
}

impl SweepEngine for WithColumns<'_> {
    fn describe(&self) -> String {
        format!(
            "{} + {} named column(s) (cpu, f64)",
            self.inner.describe(),
            self.columns.len()
        )
    }
    fn n_samples(&self) -> usize {
        self.inner.n_samples()
    }
    fn n_candidates(&self) -> usize {
        self.inner.n_candidates() + self.columns.len()
    }
    fn column_stats(&mut self, weights: Option<&[f64]>) -> Result<ColumnStats> {
        let mut s = self.inner.column_stats(weights)?;
        let w = |i: usize| weights.map_or(1.0, |w| w[i]);
        let sw: f64 = (0..self.n_samples()).map(w).sum();
        for c in self.columns {
            let m = c.iter().enumerate().map(|(i, x)| w(i) * x).sum::<f64>() / sw;
            let ss: f64 = c
                .iter()
                .enumerate()
                .map(|(i, x)| w(i) * (x - m) * (x - m))
                .sum();
            s.mean.push(m);
            s.norm.push(ss.sqrt());
        }
        Ok(s)
    }
    fn sweep(&mut self, v: &[f64], out: &mut [f64]) -> Result<()> {
        let nb = self.inner.n_candidates();
        self.inner.sweep(v, &mut out[..nb])?;
        for (o, c) in out[nb..].iter_mut().zip(self.columns) {
            *o = c.iter().zip(v).map(|(a, b)| a * b).sum();
        }
        Ok(())
    }
    fn columns(&mut self, idx: &[usize]) -> Result<Vec<Vec<f64>>> {
        let nb = self.inner.n_candidates();
        let base: Vec<usize> = idx.iter().copied().filter(|&j| j < nb).collect();
        let mut from_inner = self.inner.columns(&base)?.into_iter();
        idx.iter()
            .map(|&j| {
                if j < nb {
                    from_inner
                        .next()
                        .ok_or_else(|| Error::Numerical("engine returned too few columns".into()))
                } else {
                    self.columns.get(j - nb).cloned().ok_or_else(|| {
                        Error::param("columns", format!("candidate {j} out of range"))
                    })
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extra_columns_follow_the_engine_candidates() {
        use crate::engine::DenseEngine;
        let base = vec![vec![1.0, 2.0, 3.0, -1.0], vec![0.5, -0.5, 2.0, 1.0]];
        let mut dense = DenseEngine::from_columns(&base).unwrap();
        let extra = vec![vec![1.0, -1.0, 1.0, -1.0]];
        let mut e = WithColumns::new(&mut dense, &extra).unwrap();
        assert_eq!(e.n_candidates(), 3);
        let v = [1.0, 2.0, 3.0, 4.0];
        let mut out = vec![0.0; 3];
        e.sweep(&v, &mut out).unwrap();
        assert_eq!(out, vec![10.0, 9.5, -2.0]);
        let st = e.column_stats(None).unwrap();
        assert_eq!((st.mean[2], st.norm[2]), (0.0, 2.0));
        let cols = e.columns(&[2, 1]).unwrap();
        assert_eq!(cols, vec![extra[0].clone(), base[1].clone()]);
        let short = vec![vec![1.0]];
        assert!(WithColumns::new(&mut dense, &short).is_err());
    }
}
