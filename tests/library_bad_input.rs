//! The library's entry points return typed errors for inputs a caller can pass by mistake:
//! no panic, no hang, no silently wrong result.

use ctsid::derivatives::{differentiate_runs, differentiate_with, DerivativeOptions};
use ctsid::discover::{cases, discover, Options};
use ctsid::engine::Features;
use ctsid::identify::{identify, Settings, Split};
use ctsid::model::Model;
use ctsid::records::{RecordSet, Run};
use ctsid::report::svg::{line_plot, Series};

fn sine(n: usize, phase: f64) -> Vec<f64> {
    (0..n).map(|i| (i as f64 * 0.01 + phase).sin()).collect()
}

fn run(id: &str, channels: Vec<Vec<f64>>) -> Run {
    Run {
        id: id.into(),
        channels,
        t0: 0.0,
        rows: Vec::new(),
    }
}

#[test]
fn features_of_unequal_length_are_an_error() {
    let e = Features::new(
        vec!["u".into(), "y".into()],
        vec![vec![0.0; 20], vec![0.0; 19]],
    );
    assert!(e.unwrap_err().to_string().contains("19 samples"));
    assert!(Features::new(vec!["u".into(), "y".into()], vec![vec![0.0; 20]]).is_err());
    // Built by hand past the constructor: checked where used.
    let bad = Features {
        n_samples: 20,
        names: vec!["u".into(), "y".into()],
        data: vec![0.0; 20],
    };
    let reg = ctsid::regression::Regression::builder()
        .degree(2)
        .build()
        .unwrap();
    assert!(reg.fit(&bad, &[0.0; 20], "l", None).is_err());
}

#[test]
fn split_indices_outside_the_record_set_are_an_error() {
    let ids: Vec<String> = (0..3).map(|i| i.to_string()).collect();
    let e = Split::new(vec![0, 1, 3], None, vec![2], &ids).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");
    assert!(Split::new(vec![5, 5], None, vec![], &ids[..2]).is_err());
    assert!(Split::new(vec![0], Some(vec![]), vec![1], &ids).is_err());
    // A split built by hand reaches identify: refused there, before any work.
    let rs = RecordSet::new(
        0.01,
        vec!["y".into(), "u".into()],
        (0..3)
            .map(|r| {
                run(
                    &r.to_string(),
                    vec![sine(300, r as f64), sine(300, 0.5 * r as f64)],
                )
            })
            .collect(),
    )
    .unwrap();
    let split = Split {
        train: vec![0, 7],
        validation: None,
        test: vec![],
    };
    let s = Settings::new(vec!["y".into()], vec!["u".into()], 2);
    assert!(identify(&rs, &split, &s).is_err());
}

#[test]
fn discover_checks_its_run_lists() {
    let case = cases::generate("coulomb", 0, 0.03).unwrap();
    let n = case.records.runs.len();
    for o in [
        Options::new(vec![0, n], vec![4], vec![6]),
        Options::new(vec![0, 1], vec![n + 3], vec![6]),
        Options::new(vec![0, 1], vec![4], vec![99]),
        Options::new(vec![0, 1], vec![1], vec![6]),
    ] {
        assert!(discover(&case.records, &case.nominal, &o).is_err());
    }
    let mut o = Options::new(vec![0, 1], vec![4], vec![6]);
    o.half_width = Some(1_000_000_000);
    let e = discover(&case.records, &case.nominal, &o).unwrap_err();
    assert!(e.to_string().contains("half width"), "{e}");
}

#[test]
fn derivative_overrides_are_checked() {
    let y = sine(200, 0.0);
    for opts in [
        DerivativeOptions {
            end_lambda: -0.5,
            ..Default::default()
        },
        DerivativeOptions {
            end_lambda: f64::NAN,
            ..Default::default()
        },
        DerivativeOptions {
            h: Some(1e20),
            ..Default::default()
        },
    ] {
        assert!(differentiate_with(&y, 0.01, 2, &opts).is_err(), "{opts:?}");
    }
    assert!(differentiate_with(&y, 1e-300, 2, &DerivativeOptions::default()).is_err());
    let mut big = y.clone();
    big[3] = 1e200;
    assert!(differentiate_with(&big, 0.01, 2, &DerivativeOptions::default()).is_err());
}

#[test]
fn a_constant_first_run_reports_the_record_sets_smoothing_level() {
    let flat = vec![1.0; 300];
    let live = sine(300, 0.0);
    let d = differentiate_runs(&[&flat, &live], 0.01, 2, &DerivativeOptions::default()).unwrap();
    assert_eq!(d[0].h, d[1].h);
    assert_eq!(d[0].noise_sd, d[1].noise_sd);
}

#[test]
fn record_sets_refuse_names_twice_and_huge_values() {
    let e = RecordSet::new(
        0.01,
        vec!["y".into(), "y".into()],
        vec![run("0", vec![sine(50, 0.0), sine(50, 1.0)])],
    );
    assert!(e.unwrap_err().to_string().contains("named twice"));
    let e = RecordSet::new(
        0.01,
        vec!["y".into()],
        vec![run("a", vec![sine(50, 0.0)]), run("a", vec![sine(50, 1.0)])],
    );
    assert!(e
        .unwrap_err()
        .to_string()
        .contains("run id 'a' is used twice"));
    let mut v = sine(50, 0.0);
    v[7] = 1e160;
    assert!(RecordSet::new(0.01, vec!["y".into()], vec![run("0", vec![v])]).is_err());
    // Tiny channels: squares and products underflow (identification went wrong at 1e-150).
    let tiny = |scale: f64| {
        let v: Vec<f64> = sine(50, 0.0).iter().map(|x| x * scale).collect();
        RecordSet::new(0.01, vec!["y".into()], vec![run("0", vec![v])])
    };
    let e = tiny(1e-150).unwrap_err().to_string();
    assert!(
        e.contains("channel 'y'") && e.contains("too small") && e.contains("rescale"),
        "{e}"
    );
    assert!(tiny(1e-90).is_ok());
    // All zeros is a constant channel, not a tiny one.
    assert!(RecordSet::new(0.01, vec!["y".into()], vec![run("0", vec![vec![0.0; 50]])]).is_ok());
    // A spike far beyond any physical range (below the magnitude limit) is named, in its run;
    // a large but physical excursion, and an impulse on a zero channel, pass.
    let spiked = |value: f64| {
        let mut v = sine(50, 0.0);
        v[7] = value;
        RecordSet::new(
            0.01,
            vec!["y".into()],
            vec![run("a", vec![sine(50, 1.0)]), run("b", vec![v])],
        )
    };
    let e = spiked(1e149).unwrap_err().to_string();
    assert!(
        e.contains("run 'b': channel 'y' sample 7: 1e149") && e.contains("remove or repair it"),
        "{e}"
    );
    let e = spiked(-1e13).unwrap_err().to_string();
    assert!(e.contains("sample 7: -1e13 is "), "{e}");
    // A spike on a step channel (median absolute deviation 0) is refused too; a noise-free
    // step response settled over most of a long record (a gap-free tail) passes.
    let mut step: Vec<f64> = (0..1000).map(|i| if i < 400 { 0.0 } else { 1.0 }).collect();
    step[700] = 1e149;
    let e = RecordSet::new(0.01, vec!["u".into()], vec![run("0", vec![step])]).unwrap_err();
    assert!(e.to_string().contains("sample 700: 1e149 is"), "{e}");
    let settled: Vec<f64> = (0..30_000)
        .map(|i| 1.0 - (-(i as f64) * 0.01).exp())
        .collect();
    let rs = RecordSet::new(0.01, vec!["y".into()], vec![run("0", vec![settled])]).unwrap();
    assert!(rs.suspect_samples().is_empty());
    // Below the refusal, far samples are listed for the caller to report.
    let rs = spiked(1e6).unwrap();
    let s = rs.suspect_samples();
    assert_eq!(s.len(), 1, "{s:?}");
    assert_eq!((s[0].run.as_str(), s[0].sample, s[0].count), ("b", 7, 1));
    assert_eq!(s[0].place(), "run 'b': channel 'y' sample 7");
    assert!(spiked(0.3).unwrap().suspect_samples().is_empty());
    let mut impulse = vec![0.0; 50];
    impulse[3] = 1e100;
    assert!(RecordSet::new(0.01, vec!["u".into()], vec![run("0", vec![impulse])]).is_ok());
}

#[test]
fn model_exponents_are_bounded() {
    let text = r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":4294967295,"u":1},"coefficient":1}]}]}"#;
    let e = Model::from_json_str(text, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("up to 64") || e.contains("0..=64"), "{e}");
}

#[test]
fn simulation_settings_are_checked() {
    let model = Model::from_json_str(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-1}]}]}"#,
        "m",
    )
    .unwrap()
    .compile()
    .unwrap();
    let t: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();
    let opts = ctsid::simulate::SimOptions {
        h_max: Some(0.0),
        ..Default::default()
    };
    let u = vec![vec![0.0; 10]];
    assert!(ctsid::simulate::simulate_model(&model, &[1.0], &t, &u, &opts).is_err());
}

#[test]
fn plots_of_nanosecond_time_stamps_end() {
    let x: Vec<f64> = (0..100).map(|i| 1.7e18 + i as f64).collect();
    let y = sine(100, 0.0);
    let svg = line_plot(
        "t",
        "x",
        "y",
        &[Series {
            label: "y",
            x: &x,
            y: &y,
            color: "black",
            band: None,
            dashed: false,
        }],
    );
    // It returns (the tick loop used to spin forever here), with finite coordinates.
    assert!(svg.starts_with("<svg") && !svg.contains("NaN"), "{svg}");
}

#[test]
fn demo_settings_are_checked_first() {
    let o = ctsid::demo::etc::EtcOptions {
        train: 100,
        ..Default::default()
    };
    let e = ctsid::demo::etc::run(&o).unwrap_err().to_string();
    assert!(e.contains("train"), "{e}");
}

#[test]
fn refinement_runs_of_the_wrong_shape_are_an_error() {
    use ctsid::identify::refine::{free_run_nrmse, refine_gated, RefineOptions, RunData};
    let model = Model::from_json_str(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-1},{"exponents":{"u":1},"coefficient":1}]}]}"#,
        "m",
    )
    .unwrap();
    let t: Vec<f64> = (0..300).map(|i| i as f64 * 0.01).collect();
    let good = RunData {
        id: "0".into(),
        t: t.clone(),
        y: vec![sine(300, 0.0)],
        u: vec![sine(300, 1.0)],
        x0: vec![0.0],
        states: None,
    };
    // Output shorter than the time grid, and an input channel missing.
    let short = RunData {
        y: vec![sine(100, 0.0)],
        ..good.clone()
    };
    let no_input = RunData {
        u: vec![],
        ..good.clone()
    };
    for bad in [short, no_input] {
        assert!(free_run_nrmse(&model, std::slice::from_ref(&bad)).is_err());
        assert!(refine_gated(
            &model,
            std::slice::from_ref(&good),
            &[bad],
            &RefineOptions::default()
        )
        .is_err());
    }
    let reg = ctsid::regression::Regression::builder()
        .degree(2)
        .effective_samples(f64::NAN)
        .build();
    assert!(reg.is_err());
}

#[test]
fn plant_excitation_and_dataset_sizes_are_checked() {
    let mut p = ctsid::plants::Plant::mimo();
    p.excitation.u_bar = -1.0;
    assert!(ctsid::plants::dataset(&p, 1, 100, 1e-3, 0.0, 0).is_err());
    let p = ctsid::plants::Plant::mimo();
    let e = ctsid::plants::dataset(&p, 1 << 20, 1 << 20, 1e-3, 0.0, 0).unwrap_err();
    assert!(e.to_string().contains("MiB"), "{e}");
}

#[test]
fn a_stiff_stable_model_is_simulated_not_called_divergent() {
    // y'' = -9e10 y - 6e5 y' + 9e10 u: a double pole at -3e5 rad/s, sampled at 10 ms, so y
    // follows u. Newton's corrections on y' stall at round-off where y' crosses zero; they are
    // accepted there (the step's error estimate still judges the step).
    let model = Model::from_json_str(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[{"exponents":{"y":1},"coefficient":-9e10},{"exponents":{"y_d1":1},"coefficient":-6e5},{"exponents":{"u":1},"coefficient":9e10}]}]}"#,
        "stiff",
    )
    .unwrap()
    .compile()
    .unwrap();
    let t: Vec<f64> = (0..800).map(|i| i as f64 * 0.01).collect();
    let u: Vec<f64> = t
        .iter()
        .map(|t| (1.3 * t).sin() + 0.5 * (3.1 * t + 0.4).sin())
        .collect();
    let x0 = [u[0], 1.3 + 0.5 * 3.1 * 0.4f64.cos()];
    let traj = ctsid::simulate::simulate_model(
        &model,
        &x0,
        &t,
        std::slice::from_ref(&u),
        &ctsid::simulate::SimOptions::default(),
    )
    .unwrap();
    let y = traj.series(0).unwrap();
    let worst = y
        .iter()
        .zip(&u)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-3, "max |y - u| = {worst}");
}

#[test]
fn public_functions_refuse_wrong_lengths_and_indices() {
    use ctsid::engine::DenseEngine;
    use ctsid::metrics::percentile;

    assert!(DenseEngine::from_column_major(3, 2, vec![0.0; 5]).is_err());
    assert!(DenseEngine::from_column_major(usize::MAX, 2, vec![]).is_err());
    assert!(DenseEngine::from_column_major(3, 2, vec![0.0; 6]).is_ok());
    assert!(percentile(&[1.0, 2.0], 101.0).is_nan());
    assert!(percentile(&[1.0, 2.0], -1.0).is_nan());
    assert!(percentile(&[], 50.0).is_nan());
    assert_eq!(percentile(&[1.0, 3.0], 50.0), 2.0);

    let text = r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[{"exponents":{"y":1},"coefficient":-1},{"exponents":{"u":1},"coefficient":1}]}]}"#;
    let model = Model::from_json_str(text, "test").unwrap();
    let c = model.compile().unwrap();
    assert!(c.eval_output(1, &[0.0; 3]).is_err());
    assert!(c.eval_output(0, &[0.0; 2]).is_err());
    assert!(c.term_values(0, &[0.0; 4]).is_err());
    assert!(c.grad_output(3, &[0.0; 3]).is_err());
    let mut dx = vec![0.0; 2];
    assert!(c.rhs(&[0.0; 1], &[0.0], &mut dx).is_err());
    assert!(c.rhs(&[0.0; 2], &[], &mut dx).is_err());
    assert!(c.rhs(&[0.0; 2], &[0.0], &mut dx[..1]).is_err());
    c.rhs(&[1.0, 0.0], &[0.5], &mut dx).unwrap();
    assert_eq!(dx, vec![0.0, -0.5]);
    let (mut jx, mut ju) = (vec![0.0; 4], vec![0.0; 2]);
    assert!(c
        .jacobians(&[0.0; 2], &[0.0], &mut jx[..3], &mut ju)
        .is_err());
    c.jacobians(&[0.0; 2], &[0.0], &mut jx, &mut ju).unwrap();
    assert_eq!(jx, vec![0.0, 1.0, -1.0, 0.0]);

    let times: Vec<f64> = (0..5).map(|k| k as f64 * 0.1).collect();
    let tr = ctsid::simulate::simulate(
        &c,
        &ctsid::simulate::ConstantInput(vec![1.0]),
        &[0.0, 0.0],
        &times,
        &Default::default(),
    )
    .unwrap();
    assert!(tr.state(5).is_err() && tr.state(4).is_ok());
    assert!(tr.series(2).is_err() && tr.series(1).unwrap().len() == 5);
}

#[test]
fn io_errors_keep_their_source() {
    use std::error::Error as _;
    let e = Model::read("/nonexistent/ctsid/model.json").unwrap_err();
    let io = e
        .source()
        .and_then(|s| s.downcast_ref::<std::io::Error>())
        .expect("the io::Error is the source");
    assert_eq!(io.kind(), std::io::ErrorKind::NotFound);
    assert!(
        e.to_string().starts_with("/nonexistent/ctsid/model.json: "),
        "{e}"
    );
}

#[test]
fn discover_on_data_near_the_magnitude_limit_is_an_answer_or_a_clear_error() {
    // Records near `MAX_MAGNITUDE` (1e150), on a fast clock so that the derivatives go beyond
    // it: the dictionary's scales (standard deviations, whose squares overflow) wrote
    // `tanh(y_d1/inf)` into a formula that did not parse; cubes of the level overflow too.
    // What comes back is a verdict whose formulas are all finite, or one clear line.
    let case = cases::generate("duffing", 0, 0.03).unwrap();
    for (scale, clock) in [(1e120, 1.0), (1e149, 1.0), (1e149, 1e-4)] {
        let mut rs = case.records.clone();
        rs.tau *= clock;
        for r in &mut rs.runs {
            for c in &mut r.channels {
                c.iter_mut().for_each(|x| *x *= scale);
            }
        }
        let (train, val, test) = cases::split();
        let o = Options::new(train, val, test);
        match discover(&rs, &case.nominal, &o) {
            Ok(d) => {
                let formulas: Vec<String> = d
                    .effects
                    .iter()
                    .map(|e| e.formula.clone())
                    .chain(d.closest.clone())
                    .chain(d.dropped.clone())
                    .collect();
                for f in &formulas {
                    assert!(!f.contains("inf") && !f.contains("NaN"), "{scale:e}: {f}");
                }
                println!("{scale:e} x{clock}: {} {formulas:?}", d.verdict);
            }
            Err(e) => {
                let m = e.to_string();
                println!("{scale:e} x{clock}: error: {m}");
                // The dictionary's own formulas must parse: an error may only be about the data.
                assert!(
                    !m.contains('\n') && !m.contains("unknown variable"),
                    "{scale:e}: {m}"
                );
            }
        }
    }
}

#[test]
fn long_products_compile_in_linear_size_and_only_a_flood_of_them_is_refused() {
    // 995 factors (999 when this was found): each derivative tree had about 500,000 nodes, and twenty such terms took
    // 945 MB, so they were refused; as one program with shared entries each term takes about
    // 3,000 (`model::tape`), and the model compiles and evaluates. (Each term has its own factor
    // `u + k`: a multiple of another term's monomial is refused as the same column.)
    let long = vec!["y"; 995].join("*");
    let model = |n: usize| {
        let terms: Vec<String> = (0..n)
            .map(|k| {
                format!(
                    r#"{{"expression": "{long}*(u+{})", "coefficient": 1e-9}}"#,
                    k + 1
                )
            })
            .collect();
        format!(
            r#"{{"format": "ctsid-model/2", "inputs": ["u"], "outputs": [{{"name": "y", "order": 1, "terms": [{{"exponents": {{"u": 1}}, "coefficient": 1.0}}, {}]}}]}}"#,
            terms.join(", ")
        )
    };
    let m = ctsid::model::Model::from_json_str(&model(20), "long.json").unwrap();
    let c = m.compile().unwrap();
    let mut dx = [0.0];
    c.rhs(&[1.0], &[1.0], &mut dx).unwrap();
    // 1 + 1e-9 * (2 + 3 + ... + 21) at y = 1, u = 1.
    assert!((dx[0] - (1.0 + 1e-9 * 230.0)).abs() < 1e-15, "{dx:?}");
    // Thousands of such terms still exceed the model-wide budget: one line, not the memory.
    let m = ctsid::model::Model::from_json_str(&model(1400), "flood.json").unwrap();
    let e = m.compile().unwrap_err().to_string();
    assert!(
        e.contains("too large") && !e.contains('\n') && e.len() < 400,
        "{e}"
    );
}

#[test]
fn an_output_constant_within_every_training_run_is_refused() {
    // Four steady-state training runs at different levels and one moving test run: the
    // training runs passed the pooled constancy check, and the model came out `y_d1 = 0`.
    let mut runs: Vec<Run> = (0..4)
        .map(|r| {
            run(
                &r.to_string(),
                vec![vec![r as f64; 200], vec![0.5 * r as f64; 200]],
            )
        })
        .collect();
    runs.push(run("4", vec![sine(200, 0.0), sine(200, 1.0)]));
    let rs = RecordSet::new(0.05, vec!["y".into(), "u".into()], runs).unwrap();
    let split = Split {
        train: vec![0, 1, 2, 3],
        validation: None,
        test: vec![4],
    };
    let s = Settings::new(vec!["y".into()], vec!["u".into()], 1);
    let e = identify(&rs, &split, &s).unwrap_err().to_string();
    assert!(e.contains("constant within every training run"), "{e}");
    // An input held at one level per training run (step experiments) is a design, not an
    // error: its training derivatives are exact zeros whatever the tuning.
    let ys: Vec<&[f64]> = rs.runs.iter().map(|r| r.channels[1].as_slice()).collect();
    let opts = ctsid::derivatives::DerivativeOptions {
        tune_runs: Some(vec![0, 1, 2, 3]),
        ..Default::default()
    };
    assert!(ctsid::derivatives::differentiate_runs(&ys, 0.05, 1, &opts).is_ok());
}

#[test]
fn a_test_run_too_short_to_simulate_is_refused_not_scored_nan() {
    // Twenty samples: enough for derivatives up to order 4 (the search's highest, 18), not for
    // a free run's initial state at that order (24).
    let rs = RecordSet::new(
        0.05,
        vec!["y".into(), "u".into()],
        vec![
            run("0", vec![sine(300, 0.0), sine(300, 1.0)]),
            run("1", vec![sine(300, 0.5), sine(300, 2.0)]),
            run("2", vec![sine(20, 0.0), sine(20, 1.0)]),
        ],
    )
    .unwrap();
    let split = Split {
        train: vec![0],
        validation: Some(vec![1]),
        test: vec![2],
    };
    let s = Settings::new(vec!["y".into()], vec!["u".into()], 1);
    let e = identify(&rs, &split, &s).unwrap_err().to_string();
    assert!(e.contains("'2'") && e.contains("initial state"), "{e}");
}

#[test]
fn derivatives_beyond_the_magnitude_limit_are_an_error_not_a_zero_sigma() {
    // A signal of 1e120 on a picosecond clock: its eighth derivative is near 1e210, whose
    // square overflows; the sigmas of orders 4 to 8 came out exactly 0.
    let y: Vec<f64> = (0..400)
        .map(|k| {
            1e120
                * (2.0 * std::f64::consts::PI * k as f64 / 40.0).sin()
                * (1.0 + 1e-3 * ((k * 7919) % 13) as f64)
        })
        .collect();
    let opts = ctsid::derivatives::DerivativeOptions {
        exp_sum: false,
        ..Default::default()
    };
    let e = ctsid::derivatives::differentiate_runs(&[&y], 1e-12, 8, &opts).unwrap_err();
    assert!(e.to_string().contains("beyond 1e150"), "{e}");
    // The same shape at ordinary magnitudes is fine.
    let small: Vec<f64> = y.iter().map(|v| v * 1e-120).collect();
    assert!(ctsid::derivatives::differentiate_runs(&[&small], 1e-2, 8, &opts).is_ok());
}
