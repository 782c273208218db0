//! What the tolerances of `SimOptions::fitting` cost and buy: the Silverbox benchmark's final
//! model (built by `ctsid benchmark`'s workflow, about 45 s) simulated over the arrow from rest
//! at each relative tolerance, with steps per sample interval, rejected steps, time, and the
//! RMS difference to a run at rtol 1e-11 (the figures of docs/method/simulation.md).
//!
//! `cargo bench --bench fit_tolerance [-- DATA_DIR]` (default `../shared/data`)

use ctsid::benchmark::{load, run};
use ctsid::simulate::{run_data, simulate_model, SimOptions};

fn main() {
    let data = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .unwrap_or_else(|| "../shared/data".into());
    let b = match load("silverbox", &data) {
        Ok(b) => b,
        Err(e) => return println!("skipped: {e}"),
    };
    let model = run(&b).expect("the benchmark workflow").model;
    let compiled = model.compile().unwrap();
    let test = run_data(&model, &b.records, &b.records.runs[b.split.test[0]]).unwrap();
    let x0 = vec![test.y[0][0], 0.0];
    let sim = |rtol: f64, atol: f64| {
        let o = SimOptions {
            rtol,
            atol,
            ..SimOptions::default()
        };
        let clock = std::time::Instant::now();
        let tr = simulate_model(&compiled, &x0, &test.t, &test.u, &o).unwrap();
        let secs = clock.elapsed().as_secs_f64();
        (tr.series(0).unwrap(), tr.steps, tr.rejected, secs)
    };
    let reference = sim(1e-11, 1e-14).0;
    let n = test.t.len() as f64;
    println!("| rtol | atol | steps per sample | rejected | time | difference to rtol 1e-11 |");
    println!("|---|---|---|---|---|---|");
    for (rtol, atol) in [
        (1e-8, 1e-10),
        (1e-7, 1e-9),
        (1e-6, 1e-9),
        (1e-5, 1e-8),
        (1e-4, 1e-7),
    ] {
        let (s, steps, rejected, secs) = sim(rtol, atol);
        let diff = (s
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        println!(
            "| {rtol:e} | {atol:e} | {:.2} | {rejected} | {secs:.2} s | {diff:.1e} V |",
            steps as f64 / n
        );
    }
}
