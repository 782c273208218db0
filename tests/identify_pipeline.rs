//! The identification workflow end to end on a small built-in case with a known equation:
//! a forced Duffing oscillator y'' = -4 y - 0.6 y' - 2 y^3 + 3 u, several runs of a seeded
//! multisine. Noise-free and at 1 % noise (the paper's definition): the order search must pick 2
//! and the true terms; the free-run simulation of unseen runs must be close. Plus the CLI's
//! one-line errors for bad splits and channels.

use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::model::{Model, OutputEquation, Term};
use ctsid::plants::{noise::add_noise, rng::Rng};
use ctsid::records::{RecordSet, Run};
use ctsid::simulate::{simulate_model, SimOptions};
use std::collections::BTreeMap;

const TAU: f64 = 0.01;
const N: usize = 800;

fn truth() -> Model {
    let eq = OutputEquation::new(
        "y",
        2,
        vec![
            Term::new(&[("y", 1)], -4.0),
            Term::new(&[("y_d1", 1)], -0.6),
            Term::new(&[("y", 3)], -2.0),
            Term::new(&[("u", 1)], 3.0),
        ],
    );
    Model::new(&["u"], vec![eq], Some(TAU))
}

/// The record set and each run's noise-free output.
fn data(runs: usize, eta: f64, seed: u64) -> (RecordSet, Vec<Vec<f64>>) {
    let c = truth().compile().unwrap();
    let mut rng = Rng::new(seed);
    let t: Vec<f64> = (0..N).map(|k| k as f64 * TAU).collect();
    let mut out = Vec::new();
    let mut clean = Vec::new();
    for r in 0..runs {
        let comps: Vec<(f64, f64, f64)> = (0..6)
            .map(|_| {
                (
                    rng.uniform_in(-1.0, 1.0),
                    rng.uniform_in(0.3, 4.0),
                    // Phases in [0, 6.28) as the test was written (not TAU: that redraws the data).
                    #[allow(clippy::approx_constant)]
                    rng.uniform_in(0.0, 6.28),
                )
            })
            .collect();
        let u: Vec<f64> = t
            .iter()
            .map(|&t| comps.iter().map(|(a, w, p)| a * (w * t + p).sin()).sum())
            .collect();
        let x0 = [rng.uniform_in(-0.5, 0.5), rng.uniform_in(-0.5, 0.5)];
        let traj = simulate_model(
            &c,
            &x0,
            &t,
            std::slice::from_ref(&u),
            &SimOptions {
                rtol: 1e-10,
                atol: 1e-12,
                ..Default::default()
            },
        )
        .unwrap();
        let y = traj.series(0).unwrap();
        clean.push(y.clone());
        let y = if eta > 0.0 {
            add_noise(&y, eta, &mut rng)
        } else {
            y
        };
        out.push(Run {
            id: r.to_string(),
            channels: vec![y, u],
            t0: 0.0,
            rows: (0..N).map(|i| i + 2).collect(),
        });
    }
    (
        RecordSet::new(TAU, vec!["y".into(), "u".into()], out).unwrap(),
        clean,
    )
}

fn terms(m: &Model) -> BTreeMap<String, f64> {
    m.outputs[0]
        .terms
        .iter()
        .map(|t| (t.monomial(), t.coefficient))
        .collect()
}

fn run_case(eta: f64, coef_tol: f64, nrmse_tol: f64) {
    let (rs, clean) = data(12, eta, 7);
    let ids: Vec<String> = (0..12).map(|i| i.to_string()).collect();
    let split = Split::new((0..8).collect(), Some(vec![8, 9]), vec![10, 11], &ids).unwrap();
    let mut s = Settings::new(vec!["y".into()], vec!["u".into()], 3);
    s.orders = Orders::Search(vec![1, 2, 3]);
    s.engine = ctsid::regression::EngineChoice::Cpu;
    let id = identify(&rs, &split, &s).unwrap();
    assert_eq!(
        id.outputs[0].order,
        2,
        "eta {eta}: selected order; candidates {:?}",
        id.outputs[0]
            .candidates
            .iter()
            .map(|c| (c.order, c.validation.p95(), c.validation.p100()))
            .collect::<Vec<_>>()
    );
    let got = terms(&id.model);
    let want = terms(&truth());
    for (m, c) in &want {
        let g = got.get(m).copied().unwrap_or(0.0);
        println!(
            "eta {eta}: term {m}: {g} vs {c} (rel {:.1e})",
            ((g - c) / c).abs()
        );
        assert!(
            ((g - c) / c).abs() < coef_tol,
            "eta {eta}: term {m}: {g} vs {c} (model {:?})",
            got
        );
    }
    let spurious: Vec<(&String, &f64)> =
        got.iter().filter(|(m, _)| !want.contains_key(*m)).collect();
    assert!(
        spurious.is_empty(),
        "eta {eta}: terms outside the truth {spurious:?}"
    );
    // Free run on both test runs, scored against the noise-free output (the truth).
    assert_eq!(id.simulations.len(), 2, "eta {eta}: test runs simulated");
    for sim in &id.simulations {
        assert!(
            sim.error.is_none(),
            "eta {eta}: run {}: {:?}",
            sim.run,
            sim.error
        );
        let truth = &clean[sim.run.parse::<usize>().unwrap()];
        let sim_y = &sim.simulated[0];
        assert_eq!(sim_y.len(), truth.len());
        let mean = truth.iter().sum::<f64>() / truth.len() as f64;
        let sd =
            (truth.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / truth.len() as f64).sqrt();
        let rms = (sim_y
            .iter()
            .zip(truth)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / truth.len() as f64)
            .sqrt();
        let nrmse = rms / sd;
        println!(
            "eta {eta}: run {}: free-run NRMSE vs truth {nrmse:.2e}",
            sim.run
        );
        assert!(
            nrmse < nrmse_tol,
            "eta {eta}: run {}: free-run NRMSE vs truth {nrmse}",
            sim.run
        );
    }
}

// Bounds about 5x what was measured: noise-free coefficients within 4.6e-5, free-run NRMSE
// against the truth 3.5e-5 / 1.6e-4; at 1 % noise 3.1e-3 and 1.8e-3 / 8.6e-4.
#[test]
fn noise_free_duffing_is_identified_exactly() {
    run_case(0.0, 3e-4, 1e-3);
}

#[test]
fn duffing_at_one_percent_noise_keeps_order_and_terms() {
    run_case(0.01, 0.015, 0.01);
}

fn ctsid(args: &[&str]) -> (bool, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ctsid"))
        .args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn identify_cli_errors_are_one_line() {
    let (rs, _) = data(4, 0.0, 3);
    let dir = std::env::temp_dir().join(format!("ctsid-identify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("d.csv");
    let mut text = String::from("run,t,y,u\n");
    for r in &rs.runs {
        for i in 0..r.len() {
            text += &format!(
                "{},{},{},{}\n",
                r.id,
                i as f64 * TAU,
                r.channels[0][i],
                r.channels[1][i]
            );
        }
    }
    std::fs::write(&path, text).unwrap();
    let short = dir.join("short.csv");
    std::fs::write(&short, "run,t,y,u\n0,0,1,0\n0,0.01,2,0\n0,0.02,3,1\n").unwrap();
    let p = path.to_str().unwrap();
    let base = [
        "identify",
        p,
        "--run-column",
        "run",
        "--time-column",
        "t",
        "--degree",
        "2",
    ];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["--output", "nope", "--input", "u"],
            "no column named 'nope'",
        ),
        (vec!["--output", "y", "--input", "v"], "no column named 'v'"),
        (
            vec!["--output", "y", "--input", "u", "--test", "9"],
            "run '9' does not exist",
        ),
        // Counted before expanding (eight such ranges used to take 4.4 GB and 21 s).
        (
            vec![
                "--output",
                "y",
                "--input",
                "u",
                "--test",
                "0-9999999,0-9999999,0-9999999,0-9999999,0-9999999,0-9999999,0-9999999,0-9999999",
            ],
            "the list names more than",
        ),
        (
            vec![
                "--output", "y", "--input", "u", "--train", "0-2", "--test", "2,3",
            ],
            "in both train and test",
        ),
        (
            vec!["--output", "y", "--input", "u", "--orders", "0..2"],
            "outside 1..=6",
        ),
    ];
    for (extra, want) in cases {
        let mut args: Vec<&str> = base.to_vec();
        args.extend(extra);
        let (ok, err) = ctsid(&args);
        assert!(!ok, "{args:?} should fail");
        assert!(err.contains(want), "{args:?}: '{want}' not in {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    let (ok, err) = ctsid(&[
        "identify",
        short.to_str().unwrap(),
        "--run-column",
        "run",
        "--time-column",
        "t",
        "--degree",
        "2",
        "--output",
        "y",
        "--input",
        "u",
    ]);
    assert!(!ok && err.contains("needs at least"), "{err}");
}
