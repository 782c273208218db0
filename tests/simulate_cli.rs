//! `ctsid simulate`: true models reproduce generated data; errors are one line and non-zero.

mod common;

use common::cli::{ctsid, fails, overall_nrmse};
use std::path::PathBuf;

use ctsid::plants::{dataset, write_csv, Plant, ThrottlePreset};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ctsid-simcli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `y'' = -y + u` identified at tau = 0.01 s, as a model file in `d`.
fn oscillator_file(d: &std::path::Path) -> PathBuf {
    let model = d.join("m.json");
    std::fs::write(
        &model,
        r#"{"format":"ctsid-model/1","tau":0.01,"inputs":["u"],"outputs":[{"name":"y","order":2,
        "terms":[{"exponents":{"y":1},"coefficient":-1},{"exponents":{"u":1},"coefficient":1}]}]}"#,
    )
    .unwrap();
    model
}

#[test]
fn true_throttle_model_reproduces_its_data() {
    let d = tmpdir("thr");
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let runs = dataset(&plant, 3, 400, 0.003, 0.0, 21).unwrap();
    let data = d.join("data.csv");
    write_csv(&plant, &runs, data.to_str().unwrap(), true).unwrap();
    let model = d.join("model.json");
    plant
        .true_model(Some(0.003))
        .unwrap()
        .write(model.to_str().unwrap())
        .unwrap();
    let sim = d.join("sim.csv");
    let (ok, out, err) = ctsid(&[
        "simulate",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "--run-column",
        "run",
        "--time-column",
        "t",
        "-o",
        sim.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // Noise-free data: measured 0.0017.
    assert!(overall_nrmse(&out, "y") < 0.005, "{out}");
    // y_sim beside the data, close to the truth on every row.
    let mut rdr = csv::Reader::from_path(&sim).unwrap();
    let h = rdr.headers().unwrap().clone();
    let iy = h.iter().position(|c| c == "y_true").unwrap();
    let is = h.iter().position(|c| c == "y_sim").unwrap();
    let mut n = 0;
    for r in rdr.records() {
        let r = r.unwrap();
        let (a, b): (f64, f64) = (r[iy].parse().unwrap(), r[is].parse().unwrap());
        // Measured at most 2.3e-3 rad (the input is interpolated between samples).
        assert!((a - b).abs() < 5e-3, "{a} vs {b}");
        n += 1;
    }
    assert_eq!(n, 1200);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn true_mimo_model_reproduces_noisy_data() {
    let d = tmpdir("mimo");
    let plant = Plant::mimo();
    let runs = dataset(&plant, 3, 1000, 0.003, 0.03, 3).unwrap();
    let data = d.join("data.csv");
    write_csv(&plant, &runs, data.to_str().unwrap(), true).unwrap();
    let model = d.join("model.json");
    plant
        .true_model(Some(0.003))
        .unwrap()
        .write(model.to_str().unwrap())
        .unwrap();
    let sim = d.join("sim.csv");
    // tau from the model file, no time column.
    let (ok, out, err) = ctsid(&[
        "simulate",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "--run-column",
        "run",
        "-o",
        sim.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // Against the truth (the measured output carries 3 % noise): NRMSE of y_sim vs y_true.
    let mut rdr = csv::Reader::from_path(&sim).unwrap();
    let h = rdr.headers().unwrap().clone();
    let rows: Vec<csv::StringRecord> = rdr.records().map(|r| r.unwrap()).collect();
    let col = |name: &str| -> Vec<f64> {
        let c = h.iter().position(|x| x == name).unwrap();
        rows.iter().map(|r| r[c].parse().unwrap()).collect()
    };
    for y in ["y1", "y2", "y3"] {
        let (rms, nrmse) =
            ctsid::metrics::rms_nrmse(&col(&format!("{y}_sim")), &col(&format!("{y}_true")));
        eprintln!("{y}: rms {rms:e} nrmse vs truth {:.3} %", 100.0 * nrmse);
        assert!(nrmse < 0.03, "{y}: NRMSE against the truth {nrmse}\n{out}");
        // The printed NRMSE is against the noisy measurement: near the noise's own share.
        assert!(overall_nrmse(&out, y) < 20.0, "{out}");
    }
    // A wrong model (inputs' signs flipped) is clearly worse: the metric can fail.
    let mut wrong = plant.true_model(Some(0.003)).unwrap();
    for o in &mut wrong.outputs {
        for t in &mut o.terms {
            if t.exponents.keys().any(|k| k.starts_with('u')) {
                t.coefficient = -t.coefficient;
            }
        }
    }
    let wm = d.join("wrong.json");
    wrong.write(wm.to_str().unwrap()).unwrap();
    let (_, out2, _) = ctsid(&[
        "simulate",
        wm.to_str().unwrap(),
        data.to_str().unwrap(),
        "--run-column",
        "run",
    ]);
    assert!(overall_nrmse(&out2, "y1") > 50.0, "{out2}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn errors_are_one_line() {
    let d = tmpdir("err");
    let model = oscillator_file(&d);
    let data = d.join("d.csv");
    let mut s = String::from("run,t,u,y\n");
    for r in 0..2 {
        for k in 0..40 {
            s += &format!("{r},{},{},{}\n", k as f64 * 0.01, 1.0, 0.0);
        }
    }
    std::fs::write(&data, &s).unwrap();
    let (m, dp) = (model.to_str().unwrap(), data.to_str().unwrap());
    // Works as a baseline. The measured y is constant (0), so NRMSE has nothing to normalise
    // by: '-' and a note, not 'inf'.
    let (ok, out, err) = ctsid(&["simulate", m, dp, "--run-column", "run"]);
    assert!(ok, "{err}");
    let all = out.lines().find(|l| l.starts_with("all")).unwrap();
    assert!(
        all.trim_end().ends_with(" -") && !out.contains("inf"),
        "{out}"
    );
    assert!(
        err.contains("NRMSE '-': the measured output is constant"),
        "{err}"
    );
    fails(
        &["simulate", m, dp, "--run-column", "batch"],
        &["no column named 'batch'"],
    );
    // Scoring from past a run's end: an error, not an RMS of nothing (it printed 0).
    fails(
        &[
            "simulate",
            m,
            dp,
            "--run-column",
            "run",
            "--score-from",
            "40",
        ],
        &["'score-from': 40 leaves nothing to score in run '0' (40 samples)"],
    );
    fails(
        &[
            "simulate",
            m,
            dp,
            "--run-column",
            "run",
            "--time-column",
            "time",
        ],
        &["no column named 'time'"],
    );
    // Missing output / input columns.
    let nod = d.join("noy.csv");
    std::fs::write(&nod, "run,u\n0,1\n").unwrap();
    fails(
        &["simulate", m, nod.to_str().unwrap(), "--run-column", "run"],
        &["no column named 'y'"],
    );
    // Model file that does not parse, or names unknown variables.
    let bad = d.join("bad.json");
    std::fs::write(&bad, "{\"format\": \"ctsid-model/1\", \"inputs\": [").unwrap();
    fails(
        &["simulate", bad.to_str().unwrap(), dp, "--run-column", "run"],
        &["model file"],
    );
    std::fs::write(
        &bad,
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"w":1},"coefficient":1}]}]}"#,
    )
    .unwrap();
    fails(
        &["simulate", bad.to_str().unwrap(), dp, "--run-column", "run"],
        &["unknown variable 'w'"],
    );
    // Too-short run.
    let short = d.join("short.csv");
    std::fs::write(&short, "run,u,y\n0,1,0\n0,1,0\n0,1,0\n").unwrap();
    fails(
        &[
            "simulate",
            m,
            short.to_str().unwrap(),
            "--run-column",
            "run",
        ],
        &["needs at least"],
    );
    // Non-numeric value, named by row and column.
    let nan = d.join("nan.csv");
    std::fs::write(&nan, s.replacen("0,0,1,0\n", "0,0,1,abc\n", 1)).unwrap();
    fails(
        &["simulate", m, nan.to_str().unwrap(), "--run-column", "run"],
        &["row 2 (run '0'), column 'y'"],
    );
    // No tau anywhere.
    let notau = d.join("notau.json");
    std::fs::write(
        &notau,
        std::fs::read_to_string(&model)
            .unwrap()
            .replace("\"tau\":0.01,", ""),
    )
    .unwrap();
    fails(
        &[
            "simulate",
            notau.to_str().unwrap(),
            dp,
            "--run-column",
            "run",
        ],
        &["--tau"],
    );
    fails(
        &["simulate", m, dp, "--run-column", "run", "--tau=-1"],
        &["tau"],
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_time_column_in_milliseconds_is_pointed_out() {
    let d = tmpdir("ms");
    let model = oscillator_file(&d);
    let m = model.to_str().unwrap();
    // The inverse too: a model identified at 1000 times the data's sampling (its data's times
    // in ms) is pointed out, by `simulate` and by `discover` (which said nothing).
    for (scale, note) in [
        (1.0, false),
        (1000.0, true),
        (1.0 / 60.0, true),
        (2.0, false),
        (0.001, true),
    ] {
        let data = d.join(format!("d{scale}.csv"));
        let mut s = String::from("t,u,y\n");
        for k in 0..200 {
            let t = k as f64 * 0.01;
            s += &format!("{},{},{}\n", t * scale, (3.0 * t).sin(), 0.0);
        }
        std::fs::write(&data, &s).unwrap();
        let (ok, _, err) = ctsid(&["simulate", m, data.to_str().unwrap(), "--time-column", "t"]);
        assert!(ok, "{err}");
        assert_eq!(
            err.contains("convert it to seconds") || err.contains("identify it again"),
            note,
            "x{scale}: {err}"
        );
        if scale == 0.001 {
            assert!(err.contains("if its data's times were in ms"), "{err}");
            let (_, _, err) = ctsid(&[
                "discover",
                data.to_str().unwrap(),
                "--nominal",
                m,
                "--time-column",
                "t",
            ]);
            assert!(err.contains("if its data's times were in ms"), "{err}");
        }
        if scale == 1000.0 {
            assert!(
                err.contains("(ms?)") && err.contains("about 1000 times"),
                "{err}"
            );
        }
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_time_column_that_disagrees_with_the_models_tau_is_refused() {
    let d = tmpdir("tlike");
    let model = oscillator_file(&d); // tau 0.01 s
    let m = model.to_str().unwrap();
    // Without --tau or --time-column the model's tau is the sampling period: a model of 0.25 ms
    // simulated on its record decimated to 2.5 ms scored 128 % without a word.
    for (column, step, refused) in [
        ("t", 0.02, true),
        ("time_s", 0.005, true),
        ("t", 0.01, false),
        ("t", 0.010_05, false),
        // The model's sampling in ms: the column is time in another unit, not another sampling.
        ("time_ms", 10.0, false),
    ] {
        let data = d.join(format!("{column}{step}.csv"));
        let mut s = format!("{column},u,y\n");
        for k in 0..200 {
            let t = k as f64 * step;
            s += &format!("{t},{},{}\n", (3.0 * t).sin(), 0.1 * (2.0 * t).cos());
        }
        std::fs::write(&data, &s).unwrap();
        let dp = data.to_str().unwrap();
        let (ok, out, err) = ctsid(&["simulate", m, dp]);
        assert_eq!(ok, !refused, "{column} {step}: {out}{err}");
        if refused {
            assert!(
                err.contains(&format!("column '{column}'"))
                    && err.contains(&format!("--time-column '{column}'"))
                    && err.lines().count() == 1,
                "{err}"
            );
            let (ok, _, err) = ctsid(&["simulate", m, dp, "--time-column", column]);
            assert!(ok, "{err}");
            let tau = step.to_string();
            let (ok, _, err) = ctsid(&["simulate", m, dp, "--tau", &tau]);
            assert!(ok, "{err}");
        }
    }
    // A column in ms at another sampling than the model's: `--time-column` refuses a column
    // named in ms, so the error suggests --tau in seconds (it suggested the refused column).
    let data = d.join("ms20.csv");
    let mut s = String::from("time_ms,u,y\n");
    for k in 0..200 {
        let t = k as f64 * 0.02;
        s += &format!(
            "{},{},{}\n",
            1e3 * t,
            (3.0 * t).sin(),
            0.1 * (2.0 * t).cos()
        );
    }
    std::fs::write(&data, &s).unwrap();
    let dp = data.to_str().unwrap();
    let (ok, _, err) = ctsid(&["simulate", m, dp]);
    assert!(
        !ok && err.contains("steps by 20 ms = 0.02 s: give --tau 0.02")
            && !err.contains("--time-column"),
        "{err}"
    );
    let (ok, _, err) = ctsid(&["simulate", m, dp, "--tau", "0.02"]);
    assert!(ok, "{err}");
    // A column named like time that is not uniform is not taken for time.
    let data = d.join("jitter.csv");
    let mut s = String::from("t,u,y\n");
    for k in 0..200 {
        let t = k as f64 * 0.02 + if k % 2 == 0 { 0.0 } else { 0.003 };
        s += &format!("{t},{},0.1\n", (3.0 * t).sin());
    }
    std::fs::write(&data, &s).unwrap();
    let (ok, _, err) = ctsid(&["simulate", m, data.to_str().unwrap()]);
    assert!(ok, "{err}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_run_whose_free_run_fails_is_marked_and_the_others_are_scored() {
    let d = tmpdir("diverge");
    // y' = y^2 + u: from y(0) = -1 (u = 0) it decays as -1 / (1 + t); from near 1 it blows up.
    let model = d.join("m.json");
    std::fs::write(
        &model,
        r#"{"format":"ctsid-model/1","tau":0.01,"inputs":["u"],"outputs":[{"name":"y","order":1,
        "terms":[{"exponents":{"y":2},"coefficient":1},{"exponents":{"u":1},"coefficient":1}]}]}"#,
    )
    .unwrap();
    let data = d.join("d.csv");
    let mut s = String::from("run,t,u,y\n");
    for r in 0..3 {
        for k in 0..300 {
            let t = k as f64 * 0.01;
            let y = if r == 1 { 1.0 } else { -1.0 / (1.0 + t) };
            s += &format!("{r},{t},0,{y}\n");
        }
    }
    std::fs::write(&data, &s).unwrap();
    let (m, dp) = (model.to_str().unwrap(), data.to_str().unwrap());
    let sim = d.join("sim.csv");
    let rep = d.join("rep");
    let (ok, out, err) = ctsid(&[
        "simulate",
        m,
        dp,
        "--run-column",
        "run",
        "--time-column",
        "t",
        "-o",
        sim.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // The failed run has its row, the others their scores and 'all' theirs alone.
    assert!(
        out.lines()
            .any(|l| l.split_whitespace().eq(["1", "y", "-", "failed"])),
        "{out}"
    );
    assert!(overall_nrmse(&out, "y") < 1e-3, "{out}");
    assert!(
        err.contains("left out of 'all'") && err.contains("run '1'") && err.contains("file row"),
        "{err}"
    );
    // -o: the failed run's simulated cells empty, the others filled; the report covers the others.
    let text = std::fs::read_to_string(&sim).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), 900);
    assert!(rows.iter().all(|r| r.ends_with(',') == r.starts_with("1,")));
    assert!(rep.join("sim_0_y.svg").exists() && !rep.join("sim_1_y.svg").exists());
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(
        md.contains("Not scored, and left out of every figure: simulation diverged"),
        "{md}"
    );
    // Every run failing is an error: nothing is scored.
    let only = d.join("only.csv");
    let one: String = s
        .lines()
        .filter(|l| !l.starts_with("0,") && !l.starts_with("2,"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&only, one).unwrap();
    fails(
        &["simulate", m, only.to_str().unwrap(), "--run-column", "run"],
        &["diverged", "run '1'"],
    );
    std::fs::remove_dir_all(&d).ok();
}

/// A record of `y' = -y + u` (exact between samples for an input held over each step), `runs`
/// runs of 300 samples at tau = 0.05 s, `t_ms` in ms beside `t`; the input held for `hold`
/// samples at a time (a step generator), or a smooth sum of sines where `hold` is 0.
fn first_order_csv(path: &std::path::Path, runs: usize, hold: usize) {
    let tau = 0.05;
    let mut text = String::from("run,t,t_ms,u,y\n");
    let mut level = 0.3f64;
    for r in 0..runs {
        let mut y = 0.0;
        for k in 0..300 {
            let t = k as f64 * tau;
            let u = if hold == 0 {
                (0.7 * t + r as f64).sin() + 0.5 * (1.9 * t).cos()
            } else {
                if k % hold == 0 {
                    level = (level * 7919.0 + 0.31).fract();
                }
                2.0 * level - 1.0
            };
            text += &format!("{r},{t},{},{u},{y}\n", 1e3 * t);
            // Exact for an input held over the step.
            let a = (-tau).exp();
            y = a * y + (1.0 - a) * u;
        }
    }
    std::fs::write(path, text).unwrap();
}

/// What a MIMO test engineer's day found (2026-11-30, session 24): held inputs read linearly,
/// a model's reading of its inputs on a record whose inputs move otherwise, a time column in
/// ms read as seconds, and messages that named no option.
#[test]
fn input_readings_and_time_units_are_pointed_out() {
    let d = tmpdir("held");
    let steps = d.join("steps.csv");
    first_order_csv(&steps, 4, 10);
    let s = steps.to_str().unwrap();
    let model = d.join("hold.json");
    let m = model.to_str().unwrap();
    // `ctsid` and `fails` split an argument that starts with `-` at its spaces.
    let common = "--output y --input u --run-column run --tau 0.05";
    let split = "--train 0-1 --validation 2 --test 3 --degree 1 --quiet";
    let id = |extra: &str| ctsid(&["identify", s, common, split, extra]);
    // Read by straight lines or by a spline, the held input is noted (the spline was not:
    // `simulate` of the same model then suggested hold).
    for reading in ["linear", "cubic"] {
        let (ok, _, err) = id(&format!("--order 1 --input-interpolation {reading}"));
        assert!(
            ok && err.contains("--input-interpolation hold reads it so")
                && err.contains(&format!("({reading} interpolation ramps")),
            "{reading}: {err}"
        );
    }
    let (ok, _, err) = ctsid(&[
        "identify",
        s,
        common,
        split,
        "--order 1 --input-interpolation hold -o",
        m,
    ]);
    assert!(ok && !err.contains("note: input"), "{err}");
    assert!(!err.contains("faster than the samples can show"), "{err}");
    // Order 2 for a first-order system: a pole thousands of times 1/tau, said.
    let (ok, _, err) = id("--order 2 --input-interpolation hold");
    assert!(
        ok && err.contains("faster than the samples can show"),
        "{err}"
    );
    // The hold model on a record of smooth inputs: a note, and the override reads them so.
    let smooth = d.join("smooth.csv");
    first_order_csv(&smooth, 1, 0);
    let sm = smooth.to_str().unwrap();
    let sim = |extra: &str| ctsid(&["simulate", m, sm, "--run-column run --tau 0.05", extra]);
    let (ok, _, err) = ctsid(&["simulate", m, sm, "--run-column run --tau 0.05"]);
    assert!(
        ok && err.contains("--input-interpolation linear reads them so"),
        "{err}"
    );
    let (ok, _, err) = sim("--input-interpolation linear");
    assert!(ok && !err.contains("reads them so"), "{err}");
    // A time column named in ms is not read as seconds.
    let other = "--output y --input u --run-column run --degree 1";
    fails(
        &["identify", s, other, "--time-column t_ms"],
        &["'--time-column': 't_ms' is named in ms"],
    );
    // An output listed as an input, and runs too short for the default search.
    fails(
        &[
            "identify",
            s,
            "--output y --input u,y --run-column run --tau 0.05 --degree 1",
        ],
        &["'y' is given as both an output and an input"],
    );
    // A run of 15 samples derives order 2 (14) but cannot start its free run (16); one of 20
    // derives order 4 (18) but starts free runs up to order 3 only (20; order 4 needs 24).
    let cut = |name: &str, t_end: f64| {
        let short: String = std::fs::read_to_string(&steps)
            .unwrap()
            .lines()
            .enumerate()
            .filter(|(i, l)| {
                *i == 0
                    || l.split(',')
                        .nth(1)
                        .and_then(|t| t.parse::<f64>().ok())
                        .is_some_and(|t| t < t_end)
            })
            .map(|(_, l)| format!("{l}\n"))
            .collect();
        let path = d.join(name);
        std::fs::write(&path, short).unwrap();
        path.to_str().unwrap().to_string()
    };
    for (name, t_end, n, fits) in [("short.csv", 0.74, "15", 1), ("twenty.csv", 0.99, "20", 3)] {
        let (ok, _, err) = ctsid(&["identify", &cut(name, t_end), common, "--degree 1"]);
        assert!(!ok && err.contains(&format!("{n} samples")), "{err}");
        let needle = format!("the highest order searched (orders up to {fits} fit this run)");
        assert!(err.contains(&needle), "{err}");
        // What the message says fits does fit.
        let (ok, _, err) = ctsid(&[
            "identify",
            &cut(name, t_end),
            common,
            &format!("--degree 1 --orders 1..{fits}"),
        ]);
        assert!(ok, "{name}: {err}");
    }
    // discover on a two-output model says what to do instead.
    let two = d.join("two.json");
    std::fs::write(
        &two,
        r#"{"format":"ctsid-model/2","tau":0.05,"inputs":["u"],"outputs":[
        {"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-1},{"exponents":{"u":1},"coefficient":1}]},
        {"name":"t","order":1,"terms":[{"exponents":{"t":1},"coefficient":-1}]}]}"#,
    )
    .unwrap();
    fails(
        &[
            "discover",
            s,
            "--nominal",
            two.to_str().unwrap(),
            "--run-column run --tau 0.05",
        ],
        &[
            "identify the output in question alone",
            "(for 'y': `identify --output y --input u,t`)",
        ],
    );
    std::fs::remove_dir_all(&d).ok();
}
