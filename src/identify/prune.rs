//! Dropping the terms the data do not determine: backward elimination on the refined
//! coefficients' standard errors, guarded by free-run error on runs the refits did not see.
//!
//! A term whose coefficient lies within [`PruneOptions::z`] standard errors of zero is not
//! supported by the data: a simpler model without it explains them as well, and simulates
//! records the fit never saw no worse, or better, since the term's value was following
//! something else (EMPS's identified linear nominal carries a stiffness `+0.10 q_m +- 0.062`
//! that a free carriage on a rail does not have; it follows the record's slow drift). The
//! least determined term (smallest `|coefficient| / standard error`) goes first; the rest
//! are refitted on simulation error ([`crate::identify::refine::refine`], which also gives
//! the next standard errors), and the removal is kept unless the free-run NRMSE on the gate
//! runs rises above [`PruneOptions::gate_rise`] times the starting model's. A refused term is
//! not tried again. Each output keeps at least one term.
//!
//! # What it assumes
//! Standard errors from the output-error fit ([`crate::identify::refine`]'s, inflated for
//! correlated residuals): they are the ones this test reads. A term without one is never
//! dropped. The fit runs carry their initial states (`RunData::x0`).

use super::refine::{free_run_nrmse, overall, refine, RefineOptions, RunData};
use crate::error::Result;
use crate::model::{derivative_name, Model};

/// Settings of [`prune`].
#[derive(Debug, Clone)]
pub struct PruneOptions {
    /// A term is a candidate when `|coefficient| < z * standard error` (1.96: its 95 % interval
    /// holds zero).
    pub z: f64,
    /// A removal is kept when the gate runs' free-run NRMSE stays at or below this many times
    /// the starting model's. EMPS's stiffness goes with a rise of 10 % on its two validation
    /// runs (0.0314 -> 0.0345) and lowers the pulses record's error 6.31 -> 5.15 mm; the tanks'
    /// constant, 300 % of its standard error, would double it (0.257 -> 0.541) and stays.
    pub gate_rise: f64,
    /// The refit after each removal.
    pub refine: RefineOptions,
}

impl Default for PruneOptions {
    fn default() -> Self {
        PruneOptions {
            z: 1.96,
            gate_rise: 1.25,
            refine: RefineOptions {
                max_iterations: 15,
                skip_below: 0.0,
                ..RefineOptions::default()
            },
        }
    }
}

/// One term tried.
#[derive(Debug, Clone)]
pub struct Removal {
    /// The equation's left-hand side and the term (`q_m_d2`, `q_m` for EMPS's stiffness).
    pub equation: String,
    pub term: String,
    /// `|coefficient| / standard error` before the removal.
    pub t_ratio: f64,
    /// The gate runs' free-run NRMSE with the term and after the refit without it (infinite
    /// when the refit failed or diverged there).
    pub gate_before: f64,
    pub gate_after: f64,
    /// Whether the term went (the removal was kept).
    pub dropped: bool,
}

/// What [`prune`] did.
#[derive(Debug, Clone)]
pub struct Pruned {
    pub model: Model,
    /// Every term tried, in order.
    pub removals: Vec<Removal>,
}

/// The least determined term of `model` not yet tried: (output, term index, t ratio).
fn weakest(model: &Model, z: f64, tried: &[(usize, String)]) -> Option<(usize, usize, f64)> {
    let mut best: Option<(usize, usize, f64)> = None;
    for (i, eq) in model.outputs.iter().enumerate() {
        if eq.terms.len() < 2 {
            continue;
        }
        for (k, t) in eq.terms.iter().enumerate() {
            let Some(se) = t.std_error.filter(|s| s.is_finite() && *s > 0.0) else {
                continue;
            };
            let ratio = t.coefficient.abs() / se;
            let name = t.monomial();
            if ratio < z
                && !tried.iter().any(|(o, n)| *o == i && *n == name)
                && best.is_none_or(|b| ratio < b.2)
            {
                best = Some((i, k, ratio));
            }
        }
    }
    best
}

/// Drops the terms of `model` the data do not determine (see the module docs): refits on `fit`,
/// judged on `gate`. Refuses what [`free_run_nrmse`] refuses on the gate runs; a refit that
/// fails only refuses that removal.
///
/// ```no_run
/// use ctsid::identify::prune::{prune, PruneOptions};
/// use ctsid::identify::refine::{refine, RefineOptions, RunData};
/// # fn runs() -> (Vec<RunData>, Vec<RunData>) { unimplemented!() }
/// let (fit, gate) = runs(); // measured runs, each with its initial state in `x0`
/// let model = ctsid::Model::read("emps.model.json")?;
/// // Standard errors of the output-error fit are what the test reads.
/// let fitted = refine(&model, &fit, &RefineOptions::default())?.model;
/// let pruned = prune(&fitted, &fit, &gate, &PruneOptions::default())?;
/// for r in &pruned.removals {
///     println!("{} of {}: {}", r.term, r.equation, if r.dropped { "dropped" } else { "kept" });
/// }
/// # Ok::<(), ctsid::Error>(())
/// ```
pub fn prune(
    model: &Model,
    fit: &[RunData],
    gate: &[RunData],
    opts: &PruneOptions,
) -> Result<Pruned> {
    let start_gate = overall(&free_run_nrmse(model, gate)?);
    let mut now = (model.clone(), start_gate);
    let mut tried = Vec::new();
    let mut removals = Vec::new();
    while let Some((i, k, t_ratio)) = weakest(&now.0, opts.z, &tried) {
        let mut m = now.0.clone();
        let term = m.outputs[i].terms.remove(k).monomial();
        tried.push((i, term.clone()));
        let refit = refine(&m, fit, &opts.refine).ok().map(|r| r.model);
        let gate_after = match &refit {
            Some(r) => overall(&free_run_nrmse(r, gate)?),
            None => f64::INFINITY,
        };
        // A removal is judged only where both free runs exist: against a model that already
        // diverges on a gate run (start_gate infinite) every removal would pass, down to one
        // term per equation; a failed refit leaves the term in.
        let kept = refit.is_some()
            && start_gate.is_finite()
            && gate_after.is_finite()
            && gate_after <= opts.gate_rise * start_gate;
        removals.push(Removal {
            equation: derivative_name(&m.outputs[i].name, m.outputs[i].order),
            term,
            t_ratio,
            gate_before: now.1,
            gate_after,
            dropped: kept,
        });
        if let (true, Some(r)) = (kept, refit) {
            now = (r, gate_after);
        }
    }
    Ok(Pruned {
        model: now.0,
        removals,
    })
}
