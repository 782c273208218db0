//! `discover` on the Silverbox benchmark (an electronic Duffing oscillator, ../shared/data/silverbox):
//! a linear nominal `y'' = a0 y + a1 y' + b u + c` fitted by least squares on smoothed derivatives
//! of the training multisine, then `discover` on 8 multisine chunks (train 4, validation 2) with the
//! arrow (samples 100..40575) as the test run. Prints the verdict and the arrow's free-run RMS
//! error in mV before and after, each model started from an initial state fitted on the first
//! 50 samples and scored on the rest (the benchmark's convention).
//!
//! `cargo run --release --example silverbox_discover [-- PATH/SNLS80mV.csv]`

use ctsid::derivatives::{differentiate_runs, DerivativeOptions};
use ctsid::discover::sim::{fit_x0_on, free_run, AugModel, SimRun};
use ctsid::discover::{discover, Options};
use ctsid::model::{Model, OutputEquation, Term};
use ctsid::records::{RecordSet, Run};
use nalgebra::{DMatrix, DVector};

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "../shared/data/silverbox/SNLS80mV.csv".into());
    let Ok(text) = std::fs::read_to_string(&path) else {
        println!("skipped: {path} not found");
        return;
    };
    let mut u = Vec::new();
    let mut y = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        u.push(f[2].parse::<f64>().unwrap());
        y.push(f[3].parse::<f64>().unwrap());
    }
    let tau = 1.0 / 610.3515625;
    let mut runs = Vec::new();
    let (a, b) = (40650usize, 105712usize);
    let chunk = (b - a) / 6;
    for k in 0..6 {
        let (s, e) = (a + k * chunk, a + (k + 1) * chunk);
        runs.push(Run {
            id: format!("ms{k}"),
            channels: vec![y[s..e].to_vec(), u[s..e].to_vec()],
            t0: 0.0,
            rows: (s + 2..e + 2).collect(),
        });
    }
    runs.push(Run {
        id: "arrow".into(),
        channels: vec![y[100..40575].to_vec(), u[100..40575].to_vec()],
        t0: 0.0,
        rows: (102..40577).collect(),
    });
    let rs = RecordSet::new(tau, vec!["y".into(), "u".into()], runs).unwrap();
    let train = vec![0, 1, 2, 3];
    let validation = vec![4, 5];
    let test = vec![6];

    // Linear nominal from smoothed derivatives (least squares on the training chunks).
    let ys: Vec<&[f64]> = train
        .iter()
        .map(|&r| rs.runs[r].channels[0].as_slice())
        .collect();
    let der = differentiate_runs(&ys, tau, 2, &DerivativeOptions::default()).unwrap();
    let mut rows = Vec::new();
    let mut lab = Vec::new();
    for (k, &r) in train.iter().enumerate() {
        let d = &der[k];
        let uu = &rs.runs[r].channels[1];
        for i in 50..uu.len() - 50 {
            rows.push([d.values[0][i], d.values[1][i], uu[i], 1.0]);
            lab.push(d.values[2][i]);
        }
    }
    let x = DMatrix::from_fn(rows.len(), 4, |i, j| rows[i][j]);
    let th = x
        .clone()
        .svd(true, true)
        .solve(&DVector::from_column_slice(&lab), 1e-12)
        .unwrap();
    let nominal = Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            2,
            vec![
                Term::new(&[("y", 1)], th[0]),
                Term::new(&[("y_d1", 1)], th[1]),
                Term::new(&[("u", 1)], th[2]),
                Term::new(&[], th[3]),
            ],
        )],
        Some(tau),
    );
    println!(
        "nominal: y'' = {:.5e} y + {:.5e} y_d1 + {:.5e} u + {:.5e}",
        th[0], th[1], th[2], th[3]
    );
    let t0 = std::time::Instant::now();
    let mut o = Options::new(train, validation, test);
    o.refine_iterations = 15;
    let d = discover(&rs, &nominal, &o).unwrap();
    println!("{}", d.text());
    let rms_mv = |m: &AugModel, r: &SimRun| -> f64 {
        let rr = SimRun {
            x0: fit_x0_on(m, r, 50),
            ..r.clone()
        };
        let s = free_run(m, &rr).unwrap_or_else(|| vec![f64::NAN; r.y.len()]);
        let e2: f64 = s[50..]
            .iter()
            .zip(&r.y[50..])
            .map(|(a, b)| (a - b).powi(2))
            .sum();
        1e3 * (e2 / (s.len() - 50) as f64).sqrt()
    };
    let arrow = &d.test_runs[0];
    let before = rms_mv(d.nominal_model.as_ref().unwrap(), arrow);
    let after = rms_mv(d.final_model.as_ref().unwrap(), arrow);
    println!(
        "Silverbox arrow (full, 40,475 samples), free-run RMS after 50 samples: {before:.2} mV nominal -> {after:.2} mV {} ({:.1} s)",
        d.verdict,
        t0.elapsed().as_secs_f64()
    );
}
