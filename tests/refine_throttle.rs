//! Refinement on the paper's throttle at Patm = 0 (linear, stiff) with 3 % noise: the true
//! structure with the y' and y'' coefficients 30 % low, as the derivative fit's
//! errors-in-variables bias leaves them. Refinement must bring the free-run NRMSE on held-out
//! runs (against the noise-free output) under 2 % and the coefficients within a few percent.
//!
//! What the data determine: the throttle's fastest pole (-624.5 1/s, a 1.6 ms time constant) is
//! faster than the sampling (tau = 3 ms), so scaling every coefficient of `y''' = ...` by a
//! common factor k (which moves that pole to about -624.5 k and leaves the slow dynamics alone)
//! changes the sampled output by far less than the noise: started from k = 1, 0.73, 0.6 or 1.3
//! the refinement ends at the same cost (5.704e-3 to 5.706e-3) with k unchanged. The coefficients
//! are therefore checked relative to the y'' coefficient (the slow dynamics
//! `y''/c2 ... = ...`), which the data do determine, plus the free-run error against the truth.

use ctsid::identify::refine::{free_run_nrmse, refine_gated, RefineOptions, RunData};
use ctsid::model::Model;
use ctsid::plants::{dataset, Plant, ThrottlePreset};
use ctsid::simulate::estimate_initial_derivatives;

fn to_runs(runs: &[ctsid::plants::Run], truth: bool) -> Vec<RunData> {
    runs.iter()
        .map(|r| {
            let y = if truth { &r.y_true[0] } else { &r.y[0] };
            RunData {
                id: r.id.to_string(),
                t: r.t.clone(),
                y: vec![y.clone()],
                u: r.u.clone(),
                states: None,
                x0: estimate_initial_derivatives(&r.t, &r.y[0], 3, &r.id.to_string(), "test")
                    .unwrap(),
            }
        })
        .collect()
}

fn coefficients(m: &Model) -> Vec<f64> {
    m.outputs[0].terms.iter().map(|t| t.coefficient).collect()
}

#[test]
fn throttle_refinement_removes_the_bias() {
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let truth = plant.true_model(Some(0.003)).unwrap();
    let data = dataset(&plant, 16, 1000, 0.003, 0.03, 11).unwrap();
    let (train, held) = data.split_at(8);
    let train = to_runs(train, false);
    let held_meas = to_runs(held, false);
    let held_true = to_runs(held, true);
    // Terms: 1, y, y_d1, y_d2, u.
    let mut start = truth.clone();
    start.outputs[0].terms[2].coefficient *= 0.7;
    start.outputs[0].terms[3].coefficient *= 0.7;
    let t = std::time::Instant::now();
    let g = refine_gated(&start, &train, &held_meas, &RefineOptions::default()).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let r = g.refined.as_ref().unwrap();
    eprintln!(
        "{} in {secs:.2} s ({} iterations, {}/{} steps accepted/rejected); train NRMSE {:?} -> {:?}",
        g.message, r.lm.iterations, r.lm.accepted, r.lm.rejected, g.train_before, g.train_after
    );
    assert!(g.kept, "{}", g.message);
    let before = free_run_nrmse(&start, &held_true).unwrap()[0];
    let after = free_run_nrmse(&g.model, &held_true).unwrap()[0];
    eprintln!("held-out free-run NRMSE against the true output: {before:.4} -> {after:.4}");
    let c = coefficients(&g.model);
    let ct = coefficients(&truth);
    for (k, (a, b)) in c.iter().zip(&ct).enumerate() {
        eprintln!(
            "  term {k}: {a:.6e} vs {b:.6e} ({:+.2} %)",
            (a - b) / b * 100.0
        );
    }
    assert!(after < 0.02, "{before} -> {after}");
    // Relative to the y'' coefficient (term 3), before and after.
    let ratio = |c: &[f64], k: usize| c[k] / c[3];
    let cs = coefficients(&start);
    for k in [0, 1, 2, 4] {
        let (a, s, b) = (ratio(&c, k), ratio(&cs, k), ratio(&ct, k));
        eprintln!(
            "  term {k} / y'' term: start {:+.2} %, refined {:+.2} %",
            (s - b) / b * 100.0,
            (a - b) / b * 100.0
        );
        assert!((a - b).abs() < 0.03 * b.abs(), "term {k}: ratio {a} vs {b}");
    }
}
