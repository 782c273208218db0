//! The `derive` subcommand end to end: output columns, row order across interleaved runs, and
//! one-line errors with a non-zero exit for bad input.

mod common;

use common::cli::ctsid;

fn temp(name: &str, text: &str) -> String {
    common::cli::temp_file("cli", name, text)
}

#[test]
fn derive_writes_columns_in_file_order() {
    // Two interleaved runs; y = t^2 in run a, y = 3 t in run b.
    let mut text = String::from("run,t,y\n");
    for i in 0..200 {
        let t = i as f64 * 0.01;
        text += &format!("a,{t},{}\n", t * t);
        text += &format!("b,{t},{}\n", 3.0 * t);
    }
    let input = temp("two_runs.csv", &text);
    let (ok, out, err) = ctsid(&[
        "derive",
        &input,
        "--column",
        "y",
        "--order",
        "2",
        "--time-column",
        "t",
        "--run-column",
        "run",
    ]);
    assert!(ok, "{err}");
    let mut lines = out.lines();
    assert_eq!(
        lines.next().unwrap(),
        "run,t,y,y_d0,y_d1,y_d2,y_sigma0,y_sigma1,y_sigma2"
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(rows.len(), 400);
    // Polynomials of degree <= 2 are in the smoother's null space: exact to rounding at every
    // sample, the ends included (measured 2e-14 / 7e-11 off for y' / y'').
    for (j, r) in rows.iter().enumerate() {
        let t: f64 = r[1].parse().unwrap();
        let d1: f64 = r[4].parse().unwrap();
        let expect = if r[0] == "a" { 2.0 * t } else { 3.0 };
        assert!((d1 - expect).abs() < 1e-12, "row {j}: {d1} vs {expect}");
        let (y, d0, d2): (f64, f64, f64) = (
            r[2].parse().unwrap(),
            r[3].parse().unwrap(),
            r[5].parse().unwrap(),
        );
        let expect = if r[0] == "a" { 2.0 } else { 0.0 };
        assert!((d0 - y).abs() < 1e-9, "row {j}: {d0} vs {y}");
        assert!((d2 - expect).abs() < 1e-9, "row {j}: {d2} vs {expect}");
        // No noise: sigma is tiny (the noise estimate is 1e-11; measured at most 1.5e-5, at
        // y'' at the ends).
        assert!(
            r[6..9]
                .iter()
                .all(|s| (0.0..1e-4).contains(&s.parse::<f64>().unwrap())),
            "row {j}: {r:?}"
        );
    }
}

#[test]
fn derive_bad_input_is_one_line_and_non_zero() {
    let cases = [
        (
            "t,y\n0,1\n0.1,2\n",
            vec!["--column", "z", "--order", "1", "--time-column", "t"],
            "no column named 'z'",
        ),
        (
            "t,y\n0,1\n0.1,x\n",
            vec!["--column", "y", "--order", "1", "--time-column", "t"],
            "row 3",
        ),
        (
            "t,y\n0,1\n0.2,2\n0.1,3\n",
            vec!["--column", "y", "--order", "1", "--time-column", "t"],
            "does not increase",
        ),
        (
            "y\n1\n2\n3\n",
            vec!["--column", "y", "--order", "1", "--tau", "0.1"],
            "needs at least",
        ),
        (
            "y\n1\n2\n3\n",
            vec!["--column", "y", "--order", "1", "--tau", "0"],
            "tau must be",
        ),
        (
            "y\n1\n2\n3\n",
            vec!["--column", "y", "--order", "1"],
            "--tau",
        ),
        // `-o -` is refused, and derive says where its output goes without -o.
        (
            "y\n1\n2\n3\n",
            vec!["--column", "y", "--order", "1", "--tau", "0.1", "-o", "-"],
            "derive writes to standard output when -o is left out",
        ),
    ];
    for (i, (text, args, want)) in cases.iter().enumerate() {
        let input = temp(&format!("bad{i}.csv"), text);
        let mut all = vec!["derive", input.as_str()];
        all.extend(args.iter().copied());
        let (ok, _, err) = ctsid(&all);
        assert!(!ok, "case {i} should fail");
        assert_eq!(
            err.trim().lines().count(),
            1,
            "case {i}: one line expected, got {err}"
        );
        assert!(err.contains(want), "case {i}: '{want}' not in {err}");
    }
}

#[test]
fn derive_names_the_runs_an_exponential_sum_took_and_can_refuse_it() {
    // The shared sines at 1 %: four sinusoids, taken by the model; --smoother-only keeps the
    // smoother and says nothing about a model.
    let sines = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals/sines.csv");
    let args = [
        "derive",
        sines,
        "--column",
        "ym_1pct",
        "--order",
        "2",
        "--time-column",
        "t",
    ];
    let (ok, out, err) = ctsid(&args);
    assert!(ok, "{err}");
    assert!(
        err.contains("exponential-sum model on 1 of 1 run(s): 0 (8 terms)"),
        "{err}"
    );
    let (ok2, out2, err2) = ctsid(&[&args[..], &["--smoother-only"]].concat());
    assert!(ok2, "{err2}");
    assert!(!err2.contains("exponential-sum"), "{err2}");
    // Same columns, different estimates.
    assert_eq!(out.lines().next(), out2.lines().next());
    assert_ne!(out, out2);
}

#[test]
fn per_run_tuning_reports_each_runs_own_figures() {
    // Run a constant, run b a noisy sine: the first run's figures (untuned) were printed as
    // the record's.
    let mut text = String::from("run,y\n");
    for i in 0..100 {
        text += &format!("a,{}\n", 1.0 + 0.0 * i as f64);
    }
    for i in 0..300 {
        let noise = 0.01 * (((i * 7919) % 17) as f64 / 8.0 - 1.0);
        text += &format!("b,{}\n", (0.3 * i as f64).sin() + noise);
    }
    let input = temp("per_run.csv", &text);
    let args = [
        "derive",
        &input,
        "--column y --order 2 --tau 0.1 --run-column run",
    ];
    let (ok, _, err) = ctsid(&[&args[..], &["--per-run-tuning"]].concat());
    assert!(ok, "{err}");
    assert!(err.contains("run a: constant, not tuned"), "{err}");
    let b = err
        .lines()
        .find(|l| l.contains("run b:"))
        .unwrap_or_else(|| panic!("{err}"));
    // Run b alone is the record's only varying run: the same figures as a joint tuning.
    let (ok, _, joint) = ctsid(&args);
    assert!(ok, "{joint}");
    let bandwidth = |s: &str| {
        s.split("bandwidth ")
            .nth(1)
            .map(|x| x.split(' ').next().unwrap().to_string())
    };
    assert_eq!(bandwidth(b), bandwidth(&joint), "{b} / {joint}");
}
