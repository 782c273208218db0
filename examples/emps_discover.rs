//! `discover` on the EMPS benchmark (a prismatic joint with friction, ../shared/data/emps): the
//! nominal is mass and viscous friction with the published M = 95.1 kg and Fv = 203.5 N s/m,
//! `q'' = -(Fv / M) q' + force / M`; the estimation record is cut into 6 runs (train 4,
//! validation 2) and the pulses record is the test run. Prints the verdict, the Coulomb force
//! read from the coefficient and the nominal mass (published: 20.4 N), and the free-run RMS error
//! on the test record in mm before and after (initial state from the first 20 samples).
//!
//! `cargo run --release --example emps_discover [-- DIR]`

use ctsid::discover::sim::{fit_x0_on, free_run, AugModel, SimRun};
use ctsid::discover::{discover, Options};
use ctsid::model::{Model, OutputEquation, Term};
use ctsid::records::{RecordSet, Run};

fn load(path: &str) -> Option<(Vec<f64>, Vec<f64>)> {
    let text = std::fs::read_to_string(path).ok()?;
    let mut q = Vec::new();
    let mut f = Vec::new();
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        q.push(c[2].parse::<f64>().ok()?);
        f.push(c[5].parse::<f64>().ok()?);
    }
    Some((q, f))
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "../shared/data/emps".into());
    let (Some((q, f)), Some((qt, ft))) = (
        load(&format!("{dir}/EMPS_train_DATA_EMPS.csv")),
        load(&format!("{dir}/EMPS_test_DATA_EMPS_PULSES.csv")),
    ) else {
        println!("skipped: EMPS records not found in {dir}");
        return;
    };
    let tau = 1e-3;
    let mut runs = Vec::new();
    let chunk = q.len() / 6;
    for k in 0..6 {
        let (s, e) = (k * chunk, (k + 1) * chunk);
        runs.push(Run {
            id: format!("est{k}"),
            channels: vec![q[s..e].to_vec(), f[s..e].to_vec()],
            t0: 0.0,
            rows: (s + 2..e + 2).collect(),
        });
    }
    runs.push(Run {
        id: "pulses".into(),
        channels: vec![qt.clone(), ft.clone()],
        t0: 0.0,
        rows: (2..qt.len() + 2).collect(),
    });
    let rs = RecordSet::new(tau, vec!["q".into(), "force".into()], runs).unwrap();
    let (m, fv) = (95.1089, 203.5034);
    let nominal = Model::new(
        &["force"],
        vec![OutputEquation::new(
            "q",
            2,
            vec![
                Term::new(&[("q_d1", 1)], -fv / m),
                Term::new(&[("force", 1)], 1.0 / m),
            ],
        )],
        Some(tau),
    );
    let t0 = std::time::Instant::now();
    let mut o = Options::new(vec![0, 1, 2, 3], vec![4, 5], vec![6]);
    o.refine_iterations = 15;
    let d = discover(&rs, &nominal, &o).unwrap();
    println!("{}", d.text());
    let rms_mm = |mm: &AugModel, r: &SimRun| -> f64 {
        let rr = SimRun {
            x0: fit_x0_on(mm, r, 20),
            ..r.clone()
        };
        let s = free_run(mm, &rr).unwrap_or_else(|| vec![f64::NAN; r.y.len()]);
        let e2: f64 = s[20..]
            .iter()
            .zip(&r.y[20..])
            .map(|(a, b)| (a - b).powi(2))
            .sum();
        1e3 * (e2 / (s.len() - 20) as f64).sqrt()
    };
    let test = &d.test_runs[0];
    println!(
        "EMPS pulses record, free-run RMS after 20 samples: {:.2} mm nominal -> {:.2} mm {} ({:.1} s)",
        rms_mm(d.nominal_model.as_ref().unwrap(), test),
        rms_mm(d.final_model.as_ref().unwrap(), test),
        d.verdict,
        t0.elapsed().as_secs_f64()
    );
}
