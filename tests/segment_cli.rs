//! `--segment`: one long record cut into pieces that identify, discover and simulate treat as
//! runs, so a single measured record can be split into training, validation and test runs.

mod common;

use common::cli::{ctsid, fails, overall_nrmse, temp_file};

/// One run of `y' = -2 y + 3 u` (no run column), tau = 0.01 s, 3000 samples, u a sum of three
/// sines; RK4 on the exact input, with a deterministic measurement ripple of 0.2 % of |y|'s range.
fn long_record() -> String {
    let tau = 0.01;
    let u = |t: f64| (1.3 * t).sin() + 0.5 * (3.7 * t + 1.0).sin() + 0.3 * (7.1 * t).cos();
    let f = |t: f64, y: f64| -2.0 * y + 3.0 * u(t);
    let mut s = String::from("t,u,y\n");
    let mut y = 0.5;
    for i in 0..3000 {
        let t = i as f64 * tau;
        let ripple = 0.005 * ((i * 7919 % 101) as f64 / 50.0 - 1.0);
        s += &format!("{t},{},{}\n", u(t), y + ripple);
        let h = tau / 4.0;
        for j in 0..4 {
            let ts = t + j as f64 * h;
            let k1 = f(ts, y);
            let k2 = f(ts + h / 2.0, y + h / 2.0 * k1);
            let k3 = f(ts + h / 2.0, y + h / 2.0 * k2);
            let k4 = f(ts + h, y + h * k3);
            y += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
    }
    s
}

/// Coefficient of the monomial `name` ("y", "u", "y*u", ...) in the model file's first output.
fn coefficient(model: &str, name: &str) -> f64 {
    let m = ctsid::model::Model::read(model).unwrap();
    m.outputs[0]
        .terms
        .iter()
        .find(|t| t.monomial() == name)
        .map_or(0.0, |t| t.coefficient)
}

#[test]
fn one_record_cut_into_pieces_is_identified_tested_and_simulated() {
    let data = temp_file("segment", "long.csv", &long_record());
    let model = temp_file("segment", "m.json", "");
    // Without pieces the file is one run: there is no run 4 to test on.
    fails(
        &[
            "identify",
            &data,
            "--output y --input u --tau 0.01 --degree 2 --test 4",
        ],
        &["run '4' does not exist"],
    );
    let (ok, out, err) = ctsid(&[
        "identify",
        &data,
        "--output y --input u --tau 0.01 --degree 2 --order 1 --segment 6",
        "--train 0-2 --validation 3 --test 4",
        "-o",
        &model,
    ]);
    assert!(ok, "{err}");
    // Five pieces of 600 samples; the test table names piece 4.
    assert!(out.contains("| 4 | y |"), "{out}");
    let (a, b) = (coefficient(&model, "y"), coefficient(&model, "u"));
    assert!(
        (a + 2.0).abs() < 0.05 && (b - 3.0).abs() < 0.075,
        "y' = {a} y + {b} u\n{out}"
    );
    // simulate cuts the same pieces without a run column: one row per piece, then all.
    let (ok, out, err) = ctsid(&["simulate", &model, &data, "--tau 0.01 --segment 6"]);
    assert!(ok, "{err}");
    for p in 0..5 {
        assert!(
            out.lines().any(|l| l.starts_with(&format!("{p} "))),
            "{out}"
        );
    }
    assert!(overall_nrmse(&out, "y") < 2.0, "{out}");
}

#[test]
fn pieces_of_several_runs_are_named_by_their_run() {
    let one = long_record();
    let mut text = String::from("run,t,u,y\n");
    for r in ["a", "b"] {
        for line in one.lines().skip(1).take(1800) {
            text += &format!("{r},{line}\n");
        }
    }
    let data = temp_file("segment", "two.csv", &text);
    // a: pieces a#0..a#2 train; b#0 validates, b#1-2 test.
    let (ok, out, err) = ctsid(&[
        "identify",
        &data,
        "--output y --input u --run-column run --tau 0.01 --degree 1 --order 1 --segment 6",
        "--train a --validation b#0 --test b#1-2",
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("| b#1 | y |") && out.contains("| b#2 | y |"),
        "{out}"
    );
}

#[test]
fn bad_pieces_are_one_line_errors() {
    let data = temp_file("segment", "bad.csv", &long_record());
    let base = "--output y --input u --tau 0.01 --degree 1";
    fails(
        &["identify", &data, base, "--segment 0"],
        &["'segment'", "> 0"],
    );
    fails(
        &["identify", &data, base, "--segment 0.001"],
        &["less than 2 samples"],
    );
    // 10 samples per piece: too short for the derivatives, and the fix is a longer piece.
    fails(
        &["identify", &data, base, "--segment 0.1"],
        &["piece '0'", "give a longer --segment"],
    );
    let model = temp_file(
        "segment",
        "lag.json",
        &common::cli::lag_model_text(-2.0, Some(3.0)),
    );
    // Without a run column the file is one run: too few for discover, which says how to cut it;
    // simulate runs it whole.
    fails(
        &["discover", &data, "--nominal", &model, "--tau 0.01"],
        &["1 run(s)", "--segment"],
    );
    let (ok, out, err) = ctsid(&["simulate", &model, &data, "--tau 0.01"]);
    assert!(ok && out.lines().any(|l| l.starts_with("0 ")), "{err}");
}
