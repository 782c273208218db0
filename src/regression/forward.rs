//! Forward selection by orthogonal least squares (OLS-FROLS, the classic structure selection of
//! NARX identification), written against the same [`SweepEngine`](crate::engine::SweepEngine) as the LARS path.
//!
//! # Why a second path
//! LARS and the lasso move every active coefficient at once and shrink them; when candidates are
//! strongly correlated (monomials of the derivatives of smooth signals are), the lasso path
//! fills up with small correlated terms before the true ones get their full weight: on the
//! noise-free MIMO plant at d = 4 (1365 candidates per output) the LassoLars path reached its 40
//! terms without containing the true model (`ctsid demo mimo --degrees 4 --method lassolars`:
//! 7 of 18 true terms). Forward OLS instead adds, at each step, the
//! candidate that lowers the least-squares residual of the current support the most, so every
//! breakpoint is the exact least-squares fit of its support and a true term, once in, keeps its
//! full coefficient.
//!
//! # Method
//! With the standardised candidates `x~_j` (unit norm, centred, weighted, as in [`super::path`])
//! and an orthonormal basis `q_1..q_k` of the active columns, the residual `r` is orthogonal to
//! every `q_i`, so candidate j would lower the residual sum of squares by
//! `(x~_j^T r)^2 / (1 - sum_i (x~_j^T q_i)^2)`: the squared correlation over the squared distance
//! of `x~_j` from the active span. Both come from one sweep per step: the sweep of the new
//! direction `q` updates every correlation (`c -= gamma g`) and every projection (`+= g^2`),
//! and a sweep of `r` refreshes the correlations exactly every 8 steps. Sweeps decide, exact columns measure: the chosen candidate's correlation and distance
//! are recomputed from its f64 column (Gram-Schmidt, twice for orthogonality); when the exact
//! gain is less than half the swept one (an f32 engine's rounding on a nearly collinear
//! candidate), the exact values replace the swept ones and the choice is made again. A candidate
//! within `collinearity_tol` of the active span is skipped for the rest of the path.
//!
//! Breakpoints carry the least-squares coefficients of their support (standardised units), so
//! the eBIC selection, the refit and the pruning that follow are the ones of the LARS path.
//! `alpha` is the largest |correlation| / n among the inactive candidates, as for LARS;
//! `alpha_min` and the relevance threshold `epsilon` (a new term lowering ||r|| / ||y~|| by
//! less) stop the path as they do there. The swept projections are not refreshed: with an f32
//! engine a candidate within about 1e-3 of the active span may be judged differently than in
//! f64 (the exact check only corrects gains that sweeps overstate).

// `!(x > t)` is deliberate throughout: NaN must fail these checks.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use super::path::{dot, Begun, Breakpoint, Event, Path, PathOptions, StopReason};
use crate::error::Result;

/// The forward-OLS steps of a started path (see the module docs); the monitor is called as in
/// [`super::lars_path_monitored`], which starts the path and dispatches here.
pub(super) fn forward_path(
    begun: Begun,
    opts: &PathOptions,
    monitor: &mut dyn FnMut(&Path, usize) -> bool,
) -> Result<Path> {
    let Begun {
        mut sd,
        mut path,
        y_tilde,
    } = begun;
    let (n, nc) = (y_tilde.len(), sd.usable.len());
    let y_norm = path.y_norm;

    let mut r = y_tilde.clone();
    let mut c = vec![0.0; nc];
    sd.corr(&r, &mut c)?;
    // Squared norm of each candidate's projection on the active span.
    let mut proj = vec![0.0; nc];
    let mut g = vec![0.0; nc];
    let mut q: Vec<Vec<f64>> = Vec::new();
    // x~_active[k] = sum_{i <= k} rmat[k][i] q_i, and z_i = q_i^T y~.
    let mut rmat: Vec<Vec<f64>> = Vec::new();
    let mut z: Vec<f64> = Vec::new();
    let mut active: Vec<usize> = Vec::new();
    let mut in_active = vec![false; nc];
    let mut skipped = vec![false; nc];
    let tol2 = opts.collinearity_tol * opts.collinearity_tol;
    let mut step = 0usize;
    let mut prev_rel = 1.0;
    loop {
        // Breakpoint `step`: the least-squares fit of the current support.
        let coefs = back_substitute(&rmat, &z);
        let rel = dot(&r, &r).sqrt() / y_norm;
        let alpha = (0..nc)
            .filter(|&j| sd.usable[j] && !in_active[j])
            .map(|j| c[j].abs())
            .fold(0.0, f64::max)
            / n as f64;
        path.breakpoints.push(Breakpoint {
            alpha,
            active: active.clone(),
            coefs,
            rel_residual: rel,
        });
        // The relevance stop first: the last term lowered the relative residual by less than
        // epsilon (each breakpoint is the exact least-squares fit of its support, so that is
        // the term's own gain), and the path ends before it, whatever else would stop it here.
        if opts.epsilon > 0.0 && step > 0 && prev_rel - rel < opts.epsilon {
            path.breakpoints.pop();
            path.stop = StopReason::Relevance;
            break;
        }
        if monitor(&path, step) {
            path.stop = StopReason::NoImprovement;
            break;
        }
        if let Some(reason) = stop_reason(opts, (step, active.len(), n), (rel, alpha)) {
            path.stop = reason;
            break;
        }
        prev_rel = rel;
        // The candidate with the largest gain; exact values replace inflated swept ones.
        let mut chosen = None;
        while chosen.is_none() {
            let mut best = (usize::MAX, 0.0f64);
            for j in 0..nc {
                if !sd.usable[j] || in_active[j] || skipped[j] {
                    continue;
                }
                let d2 = 1.0 - proj[j];
                if !(d2 > tol2) {
                    continue;
                }
                let gain = c[j] * c[j] / d2;
                if gain > best.1 {
                    best = (j, gain);
                }
            }
            let (j, gain) = best;
            if j == usize::MAX {
                break;
            }
            let (xt, m, s) = sd.exact_column(j)?;
            let (v, coef_on_q) = orthogonalise(&q, &xt);
            let d2 = dot(&v, &v);
            let cj = dot(&xt, &r);
            if !(d2 > tol2) {
                skipped[j] = true;
                path.events.push(Event::SkippedCollinear {
                    step,
                    candidate: j,
                    pivot: d2.max(0.0).sqrt(),
                });
                continue;
            }
            let exact = cj * cj / d2;
            if exact < 0.5 * gain {
                c[j] = cj;
                proj[j] = 1.0 - d2;
                continue;
            }
            chosen = Some((j, xt, v, coef_on_q, d2.sqrt(), m, s));
        }
        let Some((j, xt, mut v, coef_on_q, dist, m, s)) = chosen else {
            // Every usable candidate is active or collinear with the active ones.
            path.stop = StopReason::AlphaMin;
            break;
        };
        v.iter_mut().for_each(|x| *x /= dist);
        let gamma = dot(&v, &r);
        r.iter_mut().zip(&v).for_each(|(ri, qi)| *ri -= gamma * qi);
        let mut row = coef_on_q;
        row.push(dist);
        rmat.push(row);
        z.push(dot(&v, &y_tilde));
        path.store.add(j, m, s, &xt, &y_tilde);
        // One sweep of the new direction updates every correlation and projection.
        sd.corr(&v, &mut g)?;
        for k in 0..nc {
            c[k] -= gamma * g[k];
            proj[k] += g[k] * g[k];
        }
        q.push(v);
        active.push(j);
        in_active[j] = true;
        path.events.push(Event::Added { step, candidate: j });
        step += 1;
        // The incremental correlations carry the engine's rounding: refresh them exactly
        // (one sweep of the residual) every few steps.
        if step.is_multiple_of(8) {
            sd.corr(&r, &mut c)?;
            path.refreshes += 1;
        }
    }
    path.sweeps = sd.sweeps;
    Ok(path)
}

/// Why a forward path ends at breakpoint `step` with `active` terms of `n` samples, residual
/// `rel` (`prev_rel` at the last breakpoint) and largest inactive correlation `alpha`, if it does.
fn stop_reason(
    opts: &PathOptions,
    (step, active, n): (usize, usize, usize),
    (rel, alpha): (f64, f64),
) -> Option<StopReason> {
    if step >= opts.max_steps {
        Some(StopReason::MaxSteps)
    } else if active >= opts.max_terms {
        Some(StopReason::MaxTerms)
    } else if active + 2 > n {
        Some(StopReason::SampleLimit)
    } else if rel < 1e-12 {
        Some(StopReason::ExactFit)
    } else if alpha <= opts.alpha_min {
        Some(StopReason::AlphaMin)
    } else {
        None
    }
}

/// Column `xt` less its projection on the orthonormal `q`, and its coefficients on them.
/// Gram-Schmidt, repeated once when the first pass cancelled most of the column (Kahan's
/// "twice is enough"; otherwise one pass is already orthogonal to rounding).
fn orthogonalise(q: &[Vec<f64>], xt: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut v = xt.to_vec();
    let mut coef_on_q = vec![0.0; q.len()];
    let mut before = 1.0;
    for _ in 0..2 {
        for (i, qi) in q.iter().enumerate() {
            let a = dot(qi, &v);
            coef_on_q[i] += a;
            v.iter_mut().zip(qi).for_each(|(x, b)| *x -= a * b);
        }
        let after = dot(&v, &v);
        if after > 0.5 * before {
            break;
        }
        before = after;
    }
    (v, coef_on_q)
}

/// Solves `R b = z` where row k of `rmat` holds the coefficients of active column k on
/// `q_0..q_k` (so `X~_A = Q R` with `R[i][k] = rmat[k][i]`): the least-squares coefficients.
fn back_substitute(rmat: &[Vec<f64>], z: &[f64]) -> Vec<f64> {
    let k = z.len();
    let mut b = vec![0.0; k];
    for i in (0..k).rev() {
        let s: f64 = (i + 1..k).map(|m| rmat[m][i] * b[m]).sum();
        b[i] = (z[i] - s) / rmat[i][i];
    }
    b
}
