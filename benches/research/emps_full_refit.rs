//! What the EMPS pulses record tests that the estimation record does not (docs/benchmarks.md,
//! "EMPS: why the pulses record stays near 5 mm"). A benchmark model file (one output, `q_m`
//! from `force_N`) is refitted on the free-run error of the whole estimation record as one run
//! of 24.8 s (the benchmark's workflow trains on runs of 4 s), as it is and with a constant force
//! appended, with multiple-shooting segments of 2 s and without segments; each refit is scored
//! by a free run of the whole estimation record and of the pulses record (RMS in mm after the 20
//! samples that set the initial state), beside the error's least-squares fit in time and
//! position.
//!
//! `cargo bench --bench emps_full_refit -- MODEL.json` (MODEL.json from `ctsid benchmark emps
//! --out DIR`; about 20 s).
use ctsid::benchmark::{fit_runs, load, test_scores};
use ctsid::identify::refine::{refine, RefineOptions, RunData};
use ctsid::model::Term;
use ctsid::simulate::{free_run, SimOptions};
use ctsid::Model;
use nalgebra::{DMatrix, DVector};

/// Samples that set the initial state (the benchmark's protocol).
const INIT: usize = 20;

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let Some(path) = args.get(1) else {
        return println!("usage: emps_full_refit MODEL.json");
    };
    let model = Model::read(path).unwrap();
    let b = match load("emps", "../shared/data") {
        Ok(b) => b,
        Err(e) => return println!("skipped: {e}"),
    };
    let run = estimation_run();
    let mut with_constant = model.clone();
    with_constant.outputs[0].terms.push(Term::new(&[], 1e-3));
    report("the model file", &model, &run, &b);
    for (label, m) in [("as it is", &model), ("with a constant", &with_constant)] {
        for segment_len in [2000usize, run.t.len()] {
            let ro = RefineOptions {
                max_iterations: 15,
                polish_iterations: 20,
                skip_below: 0.0,
                segment_len,
                ..RefineOptions::default()
            };
            let r = refine(m, std::slice::from_ref(&run), &ro).unwrap();
            report(
                &format!("refitted {label}, segments of {segment_len} samples"),
                &r.model,
                &run,
                &b,
            );
        }
    }
}

/// The estimation record as one run (`q_m` from `force_N`).
fn estimation_run() -> RunData {
    let text = std::fs::read_to_string("../shared/data/emps/EMPS_train_DATA_EMPS.csv").unwrap();
    let (mut t, mut q, mut f) = (vec![], vec![], vec![]);
    for line in text.lines().skip(1) {
        let c: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        t.push(c[1]);
        q.push(c[2]);
        f.push(c[5]);
    }
    // Position and a difference quotient as the first guess: the refinement fits the
    // initial state.
    let x0 = vec![q[0], (q[1] - q[0]) / (t[1] - t[0])];
    RunData {
        id: "estimation".into(),
        t,
        y: vec![q],
        u: vec![f],
        states: None,
        x0,
    }
}

/// The coefficients, and for the estimation and the pulses record the free-run RMS and the
/// error's least-squares fit `e = a + b t + c q` (in time and position) with the RMS left.
fn report(label: &str, m: &Model, run: &RunData, b: &ctsid::benchmark::Benchmark) {
    let c = m.compile().unwrap();
    let sim = free_run(&c, run, INIT, &SimOptions::default())
        .unwrap()
        .remove(0);
    let test = fit_runs(b, m, &b.split.test[..1]).unwrap().remove(0);
    let test_sim = test_scores(b, m).unwrap().1;
    let coefs: Vec<String> = m.outputs[0]
        .terms
        .iter()
        .map(|t| format!("{:.4e}", t.coefficient))
        .collect();
    println!("{label}: coefficients {}", coefs.join(" "));
    for (name, r, s) in [("estimation", run, &sim), ("pulses", &test, &test_sim)] {
        let (t, y) = (&r.t[INIT..], &r.y[0][INIT..]);
        let e: Vec<f64> = y.iter().zip(&s[INIT..]).map(|(a, s)| a - s).collect();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let x = DMatrix::from_fn(e.len(), 3, |k, j| [1.0, t[k], y[k]][j]);
        let ev = DVector::from_column_slice(&e);
        let fit = x.clone().svd(true, true).solve(&ev, 1e-12).unwrap();
        let left = &ev - &x * &fit;
        println!(
            "  {name} record {:.2} mm; e = {:.2} mm + {:.3} mm/s t + {:.4} q, {:.2} mm left",
            rms(&e) * 1e3,
            fit[0] * 1e3,
            fit[1] * 1e3,
            fit[2],
            rms(left.as_slice()) * 1e3
        );
    }
}
