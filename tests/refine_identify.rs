//! The refinement inside `identify`: the throttle at Patm = 0 with 3 % noise, order 3 and degree
//! 1, whose five candidates are exactly the true terms, so the derivative fit gives the true
//! structure with the errors-in-variables bias in its coefficients. With refinement on (the
//! default) the refinement is kept and simulates far closer to the true output of the test runs
//! than the derivative fit; with it off, no report.

mod common;

use common::cli::{ctsid, temp_file};
use ctsid::demo::records;
use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::metrics::rms_nrmse;
use ctsid::plants::{dataset, Plant, ThrottlePreset};
use ctsid::regression::EngineChoice;

#[test]
fn identify_refines_the_throttle_and_reports_it() {
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let data = dataset(&plant, 14, 1000, 0.003, 0.03, 5).unwrap();
    let rs = records(&data, &plant.input_names(), &plant.output_names(), 0.003).unwrap();
    let ids: Vec<String> = (0..14).map(|i| i.to_string()).collect();
    let split = Split::new((0..8).collect(), Some(vec![8, 9]), (10..14).collect(), &ids).unwrap();
    let mut s = Settings::new(plant.output_names(), plant.input_names(), 1);
    s.orders = Orders::Fixed(vec![3]);
    s.engine = EngineChoice::Cpu;
    let vs_truth = |id: &ctsid::identify::Identification| -> f64 {
        let v: Vec<f64> = id
            .simulations
            .iter()
            .map(|sim| {
                let r: usize = sim.run.parse().unwrap();
                if sim.error.is_some() {
                    return f64::INFINITY;
                }
                rms_nrmse(&sim.simulated[0], &data[r].y_true[0]).1
            })
            .collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    };
    let t = std::time::Instant::now();
    let on = identify(&rs, &split, &s).unwrap();
    let secs = t.elapsed().as_secs_f64();
    s.refine = false;
    let off = identify(&rs, &split, &s).unwrap();
    assert!(off.refinement.is_none());
    let rep = on.refinement.as_ref().expect("refinement is on by default");
    let (a, b) = (vs_truth(&off), vs_truth(&on));
    eprintln!(
        "{} in {secs:.2} s\n derivative fit: {}\n refined:        {}\n validation NRMSE {:?} -> {:?}; test NRMSE vs truth {a:.4} -> {b:.4}",
        rep.message, rep.derivative_fit[0], on.model.outputs[0].to_text(), rep.validation_before, rep.validation_after
    );
    assert_eq!(rep.gate, "validation runs");
    assert_eq!(rep.gate_runs, vec!["8".to_string(), "9".to_string()]);
    assert_eq!(rep.derivative_fit[0], off.model.outputs[0].to_text());
    // Here the refinement must be kept: the derivative fit has the true structure with biased
    // coefficients (measured vs truth 0.30 -> 0.0072, validation 0.24 -> 0.11).
    assert!(rep.kept, "{}", rep.message);
    assert!(rep.validation_after[0] < rep.validation_before[0]);
    assert_eq!(rep.refined[0], on.model.outputs[0].to_text());
    assert!(b < a / 5.0, "refinement barely helped: {a} -> {b}");
    // The refinement's own targets: under 2 % against the truth on the test runs.
    assert!(b < 0.02, "test NRMSE against the true output {b}");
}

/// The completion's line says why each refused move was refused, and, where the refinement was
/// refused, that its trials start from the refined model (whose gate NRMSE is each trial's
/// "before") and that a completed model must also beat the written one (a reader saw "refinement
/// refused: 0.1589 -> 0.1865" and then trials "0.1865 -> 0.1749" refused at z 1757, with no word
/// of which rule failed). A lag `y' = -y + u - 0.3 y^3` fitted at order 1 and degree 2 (its cubic
/// out of reach), 1 % noise.
#[test]
fn the_completion_says_why_a_move_was_refused() {
    let mut seed = 3u64;
    let mut noise = || {
        // Sum of four uniforms: near-Gaussian, unit variance.
        (0..4)
            .map(|_| {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .sum::<f64>()
            * 3f64.sqrt()
    };
    let mut text = String::from("run,t,u,y\n");
    for r in 0..8 {
        let (mut y, dt) = (0.0f64, 0.01);
        for k in 0..600 {
            let t = k as f64 * dt;
            let rf = r as f64;
            let u = (0.7 * t * (rf + 1.0) + rf).sin() + 0.5 * (2.3 * t + rf * rf).sin();
            text += &format!("{r},{t:.2},{u},{}\n", y + 0.01 * noise());
            for _ in 0..10 {
                y += dt / 10.0 * (-y + u - 0.3 * y.powi(3));
            }
        }
    }
    let data = temp_file("completion_why", "d.csv", &text);
    let (ok, out, err) = ctsid(&[
        "identify",
        &data,
        "--output",
        "y",
        "--input",
        "u",
        "--run-column",
        "run",
        "--time-column",
        "t",
        "--train",
        "0-4",
        "--validation",
        "5-6",
        "--test",
        "7",
        "--order",
        "1",
        "--degree",
        "2",
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let line = out
        .lines()
        .find(|l| l.starts_with("Completion on simulation error"))
        .unwrap_or_else(|| panic!("no completion line\n{out}"));
    // Here the refinement is refused (measured: 0.0590 -> 0.0605), so the line says what the
    // trials start from; and a move is refused (u^2, z -2.4).
    assert!(out.contains("refinement refused"), "{out}");
    assert!(
        line.contains(
            "(the refinement was refused: the trials start from the model refined anyway"
        ),
        "{line}"
    );
    let refused = line.split("; refused ").nth(1).expect("a refused move");
    let items: Vec<&str> = refused
        .split("); ")
        .filter(|i| i.contains("gate NRMSE"))
        .collect();
    assert!(!items.is_empty(), "{line}");
    for item in items {
        // `... gate NRMSE a -> b: <the rule it failed>`
        let why = item
            .split(" -> ")
            .nth(1)
            .and_then(|r| r.split_once(": "))
            .map(|(_, w)| w);
        assert!(
            why.is_some_and(|w| w.len() > 5),
            "no reason in '{item}'\n{line}"
        );
    }
}
