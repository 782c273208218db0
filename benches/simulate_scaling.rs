//! How simulation cost grows with the number of terms and of states (issue "Reliability, round
//! two"): one free run of 500 samples (tau 0.01 s, a two-input multisine) from a known initial
//! state, and the initial-state fit that `ctsid simulate` adds (LM on the first 200 samples,
//! forward sensitivities of every state) on the free run plus 1 % white noise. Times are medians of a few runs in this process; the
//! printed slopes are log-log growth exponents between the smallest and largest size, measured
//! in the same run (1 = linear).
//!
//! Measured (2026-11-26, this 2-core machine, shared): see docs/method/simulation.md.
//! Run: `cargo bench --bench simulate_scaling` (`-- terms` or `-- states` for one table;
//! `SCALING_ONLY=40` for one size of the states table).
use std::time::Instant;

use ctsid::model::Model;
use ctsid::simulate::{initial_state, simulate_model, SimOptions};

/// One output of order `order` per `outputs`, each a critically damped chain driven by u1 and
/// the previous output, plus `extra` small degree-3 monomials (graded-lex, as identify's basis
/// lists them) in all states and both inputs, on the first output: every extra term costs the
/// same, so the terms table measures cost per term, not per degree.
fn model(outputs: usize, order: usize, extra: usize) -> Model {
    let mut outs = Vec::new();
    // (s + 1)^order
    let binom: Vec<f64> = (0..=order)
        .map(|k| (0..k).fold(1.0, |a, i| a * (order - i) as f64 / (i + 1) as f64))
        .collect();
    let mut vars: Vec<String> = Vec::new();
    for i in 0..outputs {
        vars.push(format!("y{i}"));
        vars.extend((1..order).map(|k| format!("y{i}_d{k}")));
    }
    vars.extend(["u1".to_string(), "u2".to_string()]);
    let monos: Vec<Vec<u32>> = if extra == 0 {
        Vec::new()
    } else {
        let basis = ctsid::basis::Basis::new(&vars, 3, Default::default()).unwrap();
        (0..basis.len())
            .map(|j| basis.code(j).exponents(vars.len()))
            .filter(|e| e.iter().sum::<u32>() == 3)
            .take(extra)
            .collect()
    };
    for i in 0..outputs {
        let y = format!("y{i}");
        let mut terms = Vec::new();
        for (k, b) in binom.iter().enumerate().take(order) {
            let v = if k == 0 {
                y.clone()
            } else {
                format!("{y}_d{k}")
            };
            terms.push(format!(
                r#"{{"exponents": {{"{v}": 1}}, "coefficient": {}}}"#,
                -b
            ));
        }
        terms.push(r#"{"exponents": {"u1": 1}, "coefficient": 1.0}"#.to_string());
        if i > 0 {
            terms.push(format!(
                r#"{{"exponents": {{"y{}": 1}}, "coefficient": 0.1}}"#,
                i - 1
            ));
        }
        if i == 0 {
            for (j, m) in monos.iter().enumerate() {
                let e: Vec<String> = m
                    .iter()
                    .zip(&vars)
                    .filter(|(p, _)| **p > 0)
                    .map(|(p, v)| format!(r#""{v}": {p}"#))
                    .collect();
                let c = 1e-4 * if j % 2 == 0 { 1.0 } else { -1.0 };
                terms.push(format!(
                    r#"{{"exponents": {{{}}}, "coefficient": {c}}}"#,
                    e.join(", ")
                ));
            }
        }
        outs.push(format!(
            r#"{{"name": "{y}", "order": {order}, "terms": [{}]}}"#,
            terms.join(", ")
        ));
    }
    let text = format!(
        r#"{{"format": "ctsid-model/2", "inputs": ["u1", "u2"], "outputs": [{}]}}"#,
        outs.join(", ")
    );
    Model::from_json_str(&text, "bench").unwrap()
}

/// Median of up to `reps` timings; one timing when it takes over 2 s.
fn median(mut f: impl FnMut(), reps: usize) -> f64 {
    let mut t = Vec::new();
    for _ in 0..reps.max(1) {
        let s = Instant::now();
        f();
        t.push(s.elapsed().as_secs_f64());
        if t[0] > 2.0 {
            break;
        }
    }
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// (free run, initial-state fit) seconds.
fn time(m: &Model, reps: usize) -> (f64, f64) {
    let c = m.compile().unwrap();
    let times: Vec<f64> = (0..500).map(|k| k as f64 * 0.01).collect();
    let u: Vec<Vec<f64>> = vec![
        times
            .iter()
            .map(|t| (1.3 * t).sin() + 0.3 * (7.0 * t).sin())
            .collect(),
        times.iter().map(|t| 0.5 * (2.1 * t).cos()).collect(),
    ];
    let opts = SimOptions::default();
    let x0 = vec![0.0; c.n_state()];
    let run = || simulate_model(&c, &x0, &times, &u, &opts).unwrap();
    let tr = run();
    // The measured outputs: the free run plus 1 % (of each output's spread) white noise,
    // seeded, as a record would have; the initial-state fit stops at the noise.
    let mut seed = 12345u64;
    let mut noise = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let ys: Vec<Vec<f64>> = (0..c.n_outputs())
        .map(|i| {
            let y = tr.series(c.offset(i)).unwrap();
            let sd = ctsid::metrics::std_dev(&y);
            y.iter().map(|v| v + 0.017 * sd * noise()).collect()
        })
        .collect();
    let free = median(|| drop(run()), reps);
    let fit = median(
        || drop(initial_state(&c, &times, &ys, &u, 200, &opts).unwrap()),
        reps.min(3),
    );
    (free, fit)
}

fn slope(a: (f64, f64), b: (f64, f64)) -> f64 {
    (b.1 / a.1).ln() / (b.0 / a.0).ln()
}

fn main() {
    // `cargo bench --bench simulate_scaling -- states` (or `terms`) runs one part.
    let only: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let part = |name: &str| only.is_empty() || only.iter().any(|a| a == name);
    if part("terms") {
        terms();
    }
    if part("states") {
        states();
    }
}

fn terms() {
    println!("## Terms (12 outputs of order 2 plus N degree-3 monomials on the first)\n");
    println!("| terms | free run (500 samples) | initial-state fit |");
    println!("|---|---|---|");
    let mut rows = Vec::new();
    for extra in [250, 500, 1000, 2000, 3000] {
        let m = model(12, 2, extra);
        let n: usize = m.outputs.iter().map(|o| o.terms.len()).sum();
        let (free, fit) = time(&m, 3);
        println!("| {n} | {:.3} s | {:.3} s |", free, fit);
        rows.push((n as f64, free, fit));
    }
    let (a, b) = (rows[0], rows[rows.len() - 1]);
    println!(
        "\ngrowth exponent in terms: free run {:.2}, initial-state fit {:.2}\n",
        slope((a.0, a.1), (b.0, b.1)),
        slope((a.0, a.2), (b.0, b.2))
    );
}

fn states() {
    println!("## States (N outputs of order 8, chained)\n");
    println!("| outputs | states | free run (500 samples) | initial-state fit |");
    println!("|---|---|---|---|");
    let mut rows = Vec::new();
    for outputs in [5, 10, 20, 40] {
        if std::env::var("SCALING_ONLY").is_ok_and(|v| v != outputs.to_string()) {
            continue;
        }
        let m = model(outputs, 8, 0);
        let (free, fit) = time(&m, 3);
        println!(
            "| {outputs} | {} | {:.3} s | {:.3} s |",
            8 * outputs,
            free,
            fit
        );
        rows.push(((8 * outputs) as f64, free, fit));
    }
    let (a, b) = (rows[0], rows[rows.len() - 1]);
    println!(
        "\ngrowth exponent in states: free run {:.2}, initial-state fit {:.2}",
        slope((a.0, a.1), (b.0, b.1)),
        slope((a.0, a.2), (b.0, b.2))
    );
}
