//! Bad or awkward input across the subcommands: every case is one line on standard error, a
//! non-zero exit, and no panic; and nothing is destroyed or silently mis-read.

mod common;

use common::cli::{bin, ctsid, fails, overall_nrmse, run, temp_file, words};
use std::path::{Path, PathBuf};

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("ctsid-badinput-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn file(name: &str, text: &str) -> String {
    temp_file("badinput", name, text)
}

/// A first-order model file `y' = -y + gain u` (no input term without a gain).
fn lag_model(name: &str, gain: Option<f64>) -> String {
    file(name, &common::cli::lag_model_text(-1.0, gain))
}

/// `simulate MODEL DATA --run-column run --tau 0.01 --report REP [-o OUT]`, the report cases'
/// command line.
fn simulate_report(model: &str, data: &str, rep: &Path, out: Option<&Path>) -> Vec<String> {
    let mut a: Vec<String> = [
        "simulate",
        model,
        data,
        "--run-column",
        "run",
        "--tau",
        "0.01",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    a.extend(["--report".to_string(), rep.display().to_string()]);
    if let Some(o) = out {
        a.extend(["-o".to_string(), o.display().to_string()]);
    }
    a
}

/// `args` as the `&str` slice the runners take.
fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// `ctsid simulate ARGS`, which must succeed: its pooled NRMSE in percent of output y.
fn simulated_nrmse(args: &[&str]) -> f64 {
    let out = run(&[&["simulate"], args].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    overall_nrmse(&String::from_utf8_lossy(&out.stdout), "y")
}

/// `run,t,u,y` with two runs of 300 samples, tau 0.01: y = sin(t + r) + 0.1 u, u = cos(3 t).
fn good_csv() -> String {
    let mut s = String::from("run,t,u,y\n");
    for r in 0..2 {
        for i in 0..300 {
            let t = i as f64 * 0.01;
            let u = (3.0 * t).cos();
            s += &format!("{r},{t},{u},{}\n", (t + r as f64).sin() + 0.1 * u);
        }
    }
    s
}

#[cfg(target_os = "linux")]
#[test]
fn a_failing_standard_output_is_an_error_line_not_a_panic() {
    let data = file("full.csv", &good_csv());
    for args in [
        ["regress", &data, "--features u,t --label y --degree 2"],
        [
            "derive",
            &data,
            "--column y --order 1 --run-column run --tau 0.01",
        ],
    ] {
        let out = bin()
            .args(words(&args))
            .stdout(std::fs::File::create("/dev/full").unwrap())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("standard output") && !err.contains("panicked"),
            "{err}"
        );
    }
    // Files whole before standard output failed are kept (all or none would have thrown away a
    // long run's report for a closed pipe).
    let model = lag_model("full-model.json", Some(1.0));
    let sim = dir().join("full-sim.csv");
    let rep = dir().join("full-rep");
    let _ = std::fs::remove_file(&sim);
    let _ = std::fs::remove_dir_all(&rep);
    let args = simulate_report(&model, &data, &rep, Some(&sim));
    let out = bin()
        .args(&args)
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    // simulate prints its rows before it writes: nothing was staged, nothing is written.
    assert!(!sim.exists() && !rep.exists());
    // demo writes its report, then prints: the report stays.
    let dd = dir().join("full-demo");
    let _ = std::fs::remove_dir_all(&dd);
    let out = bin()
        .args(words(&[
            "demo",
            "etc",
            "--degree 1 --engine cpu --quiet --out",
            &dd.display().to_string(),
        ]))
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("standard output"), "{err}");
    assert!(
        dd.join("report.md").is_file(),
        "the demo's report was thrown away"
    );
}

#[test]
fn writing_over_an_input_or_into_a_missing_folder_is_refused_before_any_work() {
    let text = good_csv();
    let data = file("inplace.csv", &text);
    let derive = "--column y --order 1 --run-column run --tau 0.01 -o";
    fails(&["derive", &data, derive, &data], &["also an input file"]);
    assert_eq!(
        std::fs::read_to_string(&data).unwrap(),
        text,
        "the input was changed"
    );
    let model = lag_model("m.json", None);
    fails(
        &[
            "simulate",
            &model,
            &data,
            "--run-column run --tau 0.01 -o",
            &data,
        ],
        &["also an input file"],
    );
    assert_eq!(std::fs::read_to_string(&data).unwrap(), text);
    let missing = dir().join("no-such-folder").join("m.json");
    let args = [
        "identify",
        &data,
        "--output y --input u --run-column run --time-column t --degree 2 -o",
        &missing.display().to_string(),
    ];
    let out = fails(&args, &["does not exist"]);
    // Refused before the fit: identify prints its report only after fitting.
    assert!(out.stdout.is_empty(), "the fit ran first");
    fails(
        &["demo", "etc", "--out", &data],
        &["is a file, not a folder"],
    );
}

#[test]
fn columns_named_twice_and_values_too_large_are_refused() {
    let derive = "--column y --order 1 --time-column t";
    let dup = file("dup.csv", "t,y,y\n0,1,2\n0.1,2,3\n");
    fails(
        &["derive", &dup, derive],
        &["'y' appears twice", "columns 2 and 3"],
    );
    let big = file(
        "big.csv",
        &(String::from("t,y\n")
            + &(0..40)
                .map(|i| format!("{},{}\n", i as f64 * 0.1, if i == 7 { 1e300 } else { 1.0 }))
                .collect::<String>()),
    );
    fails(&["derive", &big, derive], &["row 9", "too large"]);
    let empty = file("empty.csv", "");
    fails(
        &["derive", &empty, "--column y --order 1 --tau 0.1"],
        &["empty file"],
    );
    let single = file("single.csv", "run,t,y\n0,0,1\n1,0,2\n");
    fails(
        &["derive", &single, derive, "--run-column run"],
        &["no run has two samples"],
    );
    // The run and time columns are not channels (identify once fitted `y'' = -9 y` with the
    // run id as its unused input).
    let good = file("runs_time.csv", &good_csv());
    let id = "--run-column run --time-column t --degree 1";
    fails(
        &["identify", &good, id, "--output y --input run"],
        &["column 'run' is the run column"],
    );
    fails(
        &["identify", &good, id, "--output t --input u"],
        &["column 't' is the time column"],
    );
    // A corrupted sample (a spike far beyond any physical range) is named where it is.
    let mut text = good_csv();
    let line = text.lines().nth(41).unwrap().to_string();
    let mut cells: Vec<String> = line.split(',').map(String::from).collect();
    let y = cells.len() - 1;
    cells[y] = "-9.9e37".into();
    text = text.replacen(&line, &cells.join(","), 1);
    let spike = file("spike.csv", &text);
    fails(
        &["identify", &spike, id, "--output y --input u"],
        &[
            "spike.csv: row 42, column 'y': -9.9e37 is",
            "remove or repair it",
        ],
    );
    // A missing-value code within the magnitude limits is legal but named in a note; the
    // command still runs.
    let mut text = good_csv();
    for k in [51, 52] {
        let line = text.lines().nth(k).unwrap().to_string();
        let mut cells: Vec<String> = line.split(',').map(String::from).collect();
        *cells.last_mut().unwrap() = "-9999".into();
        text = text.replacen(&line, &cells.join(","), 1);
    }
    let code = file("code.csv", &text);
    let out = run(&[
        "derive",
        &code,
        "--column y --order 1 --time-column t --run-column run",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("note: row 52, column 'y': -9999 is ")
            && err.contains("(1 more as far out): a missing-value code or a glitch?"),
        "{err}"
    );
    let clean = run(&[
        "derive",
        &good,
        "--column y --order 1 --time-column t --run-column run",
    ]);
    assert!(!String::from_utf8_lossy(&clean.stderr).contains("note:"));
    // A lost run id is named where it is (it used to surface as non-uniform time a row later).
    let mut text = good_csv();
    let at = text.match_indices('\n').nth(100).unwrap().0 + 1;
    text.replace_range(at..at + 1, "");
    let lost = file("lost_run.csv", &text);
    fails(
        &["identify", &lost, id, "--output y --input u"],
        &["row 102, column 'run': empty run id"],
    );
}

#[test]
fn time_stamps_far_from_zero_and_an_odd_first_step() {
    let derive = "--column y --order 1 --time-column t";
    // Unix time at 1 ms: the stamps carry about 0.2 us; the grid is uniform to that.
    let mut s = String::from("t,y\n");
    for i in 0..400 {
        s += &format!("{},{}\n", 1.7e9 + i as f64 * 1e-3, (i as f64 * 1e-2).sin());
    }
    let unix = file("unix.csv", &s);
    let out = run(&["derive", &unix, derive]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // ... and the derivative is taken at tau = 1 ms: y' = 10 cos(10 (t - t0)).
    let text = String::from_utf8(out.stdout).unwrap();
    let mut rows = 0;
    for (i, line) in text.lines().skip(1).enumerate() {
        let d1: f64 = line.split(',').nth(3).unwrap().parse().unwrap();
        let want = 10.0 * (i as f64 * 1e-2).cos();
        // Measured at most 1.8e-6: a tau off by 1e-6 relative would show.
        assert!((d1 - want).abs() < 1e-5, "row {i}: {d1} vs {want}");
        rows += 1;
    }
    assert_eq!(rows, 400);
    assert!(text.starts_with("t,y,y_d0,y_d1,"), "{text:.40}");
    // The first step is twice the rest: blamed on its own row (3), not on the second.
    let mut s = String::from("t,y\n0,0\n");
    for i in 2..40 {
        s += &format!("{},{}\n", i as f64 * 0.01, i);
    }
    let odd = file("odd.csv", &s);
    fails(
        &["derive", &odd, derive],
        &["row 3", "non-uniform", "leave out the time column"],
    );
}

#[test]
fn usage_errors_are_one_line() {
    let data = file("usage.csv", &good_csv());
    fails(
        &["derive", &data, "--column y --order 1 --tau -1"],
        &["'-1'", "--tau=-1", "--help"],
    );
    fails(&["derive", &data], &["--column", "--order"]);
    let identify = "--output y --degree 2";
    fails(
        &["identify", &data, identify, "--engine foo"],
        &["invalid value", "foo"],
    );
    fails(
        &["derive", &data, "--column y --order 100 --tau 0.01"],
        &["1..=8"],
    );
    fails(
        &["identify", &data, identify, "--orders 4..1"],
        &["'orders'", "backwards"],
    );
    fails(
        &["identify", &data, identify, "--orders 2,2 --tau 0.01"],
        &["listed twice"],
    );
    // Refused before ten million orders are spelled out.
    fails(
        &[
            "identify",
            &data,
            identify,
            "--orders 1..9999999 --tau 0.01",
        ],
        &["'orders'", "names more orders", "1..=6"],
    );
    // A header with a space before a name is that name (the loader trims it): no second column.
    let spaced = file(
        "spaced.csv",
        &good_csv().replacen("run,t,u,y", "run, t, u, u_d1", 1),
    );
    fails(
        &[
            "derive",
            &spaced,
            "--column u --order 1 --run-column run --time-column t",
        ],
        &["already has a column 'u_d1'"],
    );
    // A trailing comma is an empty name, not a second output ('1 orders for 2 outputs').
    fails(
        &["identify", &data, "--output y, --degree 2 --order 1"],
        &["empty name", "--output"],
    );
}

#[test]
fn demo_settings_are_checked_before_the_work() {
    fails(&["demo", "mimo", "--degrees", "0"], &["degree", "1..=12"]);
    // Was found inside the first fit, after the plant's data were simulated.
    fails(&["demo", "mimo", "--orders", "0"], &["orders", "1..=6"]);
    fails(
        &["demo", "mimo", "--degrees", "2,2"],
        &["degree 2 is listed twice"],
    );
    fails(&["demo", "mimo", "--engines", "cpu,cpu"], &["listed twice"]);
    // A huge setting is written short (it was printed with 301 digits).
    let data = file("eps.csv", &good_csv());
    let out = fails(
        &[
            "regress",
            &data,
            "--features u --label y --degree 1 --epsilon 1e300",
        ],
        &["epsilon", "1e300"],
    );
    assert!(
        out.stderr.len() < 200,
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    fails(&["demo", "etc", "--noise=-1"], &["noise"]);
    fails(&["demo", "etc", "--patm", "nan"], &["patm"]);
    // A setting far outside physics is blamed, not the model identified under it.
    fails(&["demo", "etc", "--patm", "1e300"], &["patm", "101325"]);
}

#[test]
fn a_huge_bad_field_is_cut_in_the_error_and_a_folder_name_is_no_output_file() {
    let mut text = String::from("t,u,y\n0,");
    text += &"x".repeat(2_000_000);
    text += ",1\n0.01,1,2\n";
    let data = file("hugefield.csv", &text);
    let model = lag_model("mh.json", Some(1.0));
    let out = fails(
        &["simulate", &model, &data, "--time-column t"],
        &["2000000 characters"],
    );
    assert!(
        out.stderr.len() < 1000,
        "{} bytes of error",
        out.stderr.len()
    );
    let good = file("good-for-dir.csv", &good_csv());
    let newdir = dir().join("newdir").display().to_string() + "/";
    fails(
        &[
            "simulate",
            &model,
            &good,
            "--run-column run --tau 0.01 -o",
            &newdir,
        ],
        &["ends in a separator"],
    );
    // Found before the simulation (the table was printed, then the writing failed): a data file
    // that already has the simulated column, and an -o file that is the report folder (one
    // output was left without the other).
    let clash = file(
        "has-sim.csv",
        &good_csv()
            .replacen("run,t,u,y", "run,t,u,y,y_sim", 1)
            .replace('\n', ",0\n")
            .replacen("y_sim,0", "y_sim", 1),
    );
    let out = fails(
        &[
            "simulate",
            &model,
            &clash,
            "--run-column run --tau 0.01 -o",
            &dir().join("o1.csv").display().to_string(),
        ],
        &["already has a column 'y_sim'"],
    );
    assert!(
        out.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let same = dir().join("same-out").display().to_string();
    let out = fails(
        &[
            "simulate",
            &model,
            &good,
            "--run-column run --tau 0.01 -o",
            &same,
            "--report",
            &same,
        ],
        &["also the report folder"],
    );
    assert!(out.stdout.is_empty() && !std::path::Path::new(&same).exists());
}

#[test]
fn constant_channels_are_refused() {
    let mut s = String::from("run,t,u,y\n");
    for r in 0..3 {
        for i in 0..300 {
            let t = i as f64 * 0.01;
            s += &format!("{r},{t},1.0,{}\n", (t + r as f64).sin());
        }
    }
    let constu = file("constu.csv", &s);
    let rest = "--run-column run --time-column t --degree 2 --order 2";
    fails(
        &["identify", &constu, "--output y --input u", rest],
        &["input 'u' is constant"],
    );
    fails(
        &["identify", &constu, "--output u --input y", rest],
        &["output 'u' is constant"],
    );
}

#[test]
fn regression_refuses_too_few_samples_degree_zero_and_a_feature_twice() {
    let short = file("short.csv", "u,y\n1,2\n2,3\n3,5\n4,4\n5,9\n");
    fails(
        &["regress", &short, "--features u --label y --degree 3"],
        &["5 samples", "at least 10"],
    );
    let data = file("reg.csv", &good_csv());
    fails(
        &["regress", &data, "--features u,t --label y --degree 0"],
        &["degree"],
    );
    fails(
        &["regress", &data, "--features u,u --label y --degree 2"],
        &["'u' is named twice"],
    );
    // Spaces after the commas are not part of the names.
    let out = run(&[
        "regress",
        &data,
        "--features",
        "u, t",
        "--label y --degree 1",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn large_signals_are_not_called_divergent() {
    // y' = -y + u with u = 1e13: y rises to 1e13, beyond the old absolute bound of 1e12.
    let model = lag_model("lag.json", Some(1.0));
    let mut s = String::from("run,u,y\n");
    for i in 0..500 {
        let t = i as f64 * 0.01;
        s += &format!("0,1e13,{}\n", 1e13 * (1.0 - (-t).exp()));
    }
    let data = file("lag.csv", &s);
    let nrmse = simulated_nrmse(&[&model, &data, "--run-column run --tau 0.01"]);
    assert!(nrmse < 0.1, "NRMSE {nrmse} %");
}

#[test]
fn no_private_runtime_folder_is_left_behind() {
    let tmp = dir().join("tmpdir");
    std::fs::create_dir_all(&tmp).unwrap();
    let out = bin()
        .arg("--version")
        .env_remove("XDG_RUNTIME_DIR")
        .env("TMPDIR", &tmp)
        .output()
        .unwrap();
    assert!(out.status.success());
    let left: Vec<_> = std::fs::read_dir(&tmp).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn pipes_hard_links_and_far_time_stamps() {
    let data = file("piped.csv", &good_csv());
    let derive = "--column y --order 1 --run-column run --tau 0.01";
    // derive copies the input's rows, so it must read the file twice: a pipe is refused.
    let mut child = bin()
        .args(words(&["derive", "/dev/stdin", derive]))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        let mut pipe = child.stdin.take().unwrap();
        // The refusal may come before the data are read: a broken pipe here is fine.
        let _ = pipe.write_all(std::fs::read(&data).unwrap().as_slice());
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("regular file"), "{err}");
    // A hard link to the input is the input.
    #[cfg(unix)]
    {
        let link = dir().join("hardlink.csv");
        let _ = std::fs::remove_file(&link);
        std::fs::hard_link(&data, &link).unwrap();
        fails(
            &["derive", &data, derive, "-o", &link.display().to_string()],
            &["also an input file"],
        );
    }
    // Unix-time stamps: the model is simulated on time since the run's start, so it is as
    // accurate as on stamps from zero (y' = -y + 2 sin t from y = 0: exact solution below).
    let mut s = String::from("run,t,u,y\n");
    for i in 0..3000 {
        let t = i as f64 * 1e-3;
        s += &format!(
            "0,{:.3},{},{}\n",
            1.7e9 + t,
            t.sin(),
            t.sin() - t.cos() + (-t).exp()
        );
    }
    let unix = file("unix_lag.csv", &s);
    let model = lag_model("lag2.json", Some(2.0));
    let nrmse = simulated_nrmse(&[&model, &unix, "--run-column run --time-column t"]);
    assert!(nrmse < 1e-3, "NRMSE {nrmse} %");
}

#[test]
fn odd_settings_and_line_breaks_in_names() {
    let data = file("odd_settings.csv", &good_csv());
    fails(
        &[
            "derive",
            &data,
            "--column y --order 1 --run-column run --tau 1e-300",
        ],
        &["between 1e-12 and 1e9"],
    );
    fails(
        &[
            "identify",
            &data,
            "--output y --input u --run-column run --tau 0.01 --degree 2 --eta inf",
        ],
        &["eta", "finite"],
    );
    // A header name with a line break (quoted CSV) still gives one line.
    let nl = file("nl.csv", "run,t,\"u\nx\",y\n0,0,1,2\n");
    fails(
        &[
            "identify",
            &nl,
            "--output y --input u --run-column run --time-column t --degree 2",
        ],
        &["no column named 'u'"],
    );
    let model = lag_model("nom.json", None);
    let discover = "--run-column run --tau 0.01";
    fails(
        &[
            "discover",
            &data,
            "--nominal",
            &model,
            discover,
            "--confidence y=10 --confidence y=20",
        ],
        &["'y' is given twice"],
    );
    fails(
        &[
            "discover",
            &data,
            "--nominal",
            &model,
            discover,
            "--effect a=y^2 --effect a=y^3",
        ],
        &["'a' is given twice"],
    );
}

#[test]
fn regress_edge_cases_found_by_the_sixth_reading() {
    let rows = |f: &dyn Fn(usize) -> String, head: &str| {
        let mut s = format!("{head}\n");
        for i in 0..60 {
            s += &f(i);
            s += "\n";
        }
        s
    };
    let sin = |a: f64, i: usize| (a * i as f64).sin();
    // Features near 1e60 at degree 6: a breakpoint the selection does not choose holds x^6,
    // whose coefficient leaves f64 in the data's units; that refused the whole fit.
    let big = file(
        "big60.csv",
        &rows(
            &|i| {
                let (x, z) = (1e60 * sin(0.7, i), (1.3 * i as f64).cos());
                format!("{x:e},{z},{}", 1e-60 * x + z + 0.05 * sin(5.1, i))
            },
            "x,z,y",
        ),
    );
    let (ok, out, err) = ctsid(&[
        "regress",
        &big,
        "--features x,z --label y --degree 6 --engine cpu",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("*x") && out.contains("*z"), "{out}");
    // Rows of zero weight are not samples: three weighted rows fitted three terms exactly.
    let w3 = file(
        "w3.csv",
        &rows(
            &|i| {
                let (x, z) = (sin(0.7, i), (1.3 * i as f64).cos());
                format!("{x},{z},{},{}", 2.0 * x + z, (i < 3) as u8)
            },
            "x,z,y,w",
        ),
    );
    fails(
        &[
            "regress",
            &w3,
            "--features x,z --label y --degree 3 --weights w --engine cpu",
        ],
        &["3 samples of positive weight are too few"],
    );
    // Weights spanning more than f64's sums keep (one 1e20 times the others made every centred
    // column numerically constant: a wrong model, exit 0; the reader refuses such a weight as a
    // glitch from about 1e13, `regress`, for half the rows at 1e13, beyond MAX_WEIGHT_RATIO =
    // 1e12). A weight 1e9 times the others pins its row and still fits.
    let spread = |big: f64, every: usize| {
        rows(
            &|i| {
                let (x, z) = (sin(0.7, i), (1.3 * i as f64).cos());
                let w = if i % every == 7 % every {
                    big
                } else {
                    1.0 + (i % 3) as f64
                };
                format!("{x},{z},{},{w}", 2.0 * x + z + 0.01 * sin(5.1, i))
            },
            "x,z,y,w",
        )
    };
    fails(
        &[
            "regress",
            &file("w13.csv", &spread(1e13, 2)),
            "--features x,z --label y --degree 3 --weights w --engine cpu",
        ],
        &["'--weights'", "they span 1e13", "rescale them or drop rows"],
    );
    let (ok, out, err) = ctsid(&[
        "regress",
        &file("w9.csv", &spread(1e9, 1000)),
        "--features x,z --label y --degree 3 --weights w --engine cpu",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("*x") && out.contains("*z"), "{out}");
    // --epsilon: the term that failed the relevance test was kept (the path's last breakpoint).
    let eps = file(
        "eps.csv",
        &rows(
            &|i| {
                let (x, z) = (sin(0.7, i), (1.3 * i as f64).cos());
                format!("{x},{z},{}", 2.0 * x + 0.5 * x * z + 0.01 * sin(5.1, i))
            },
            "x,z,y",
        ),
    );
    // (Forward OLS: each breakpoint is the exact fit of its support, so the drop is the term's
    // own gain. A LARS step's drop is not, and its path keeps its last breakpoint.)
    let args = "--features x,z --label y --degree 2 --method forward-ols --epsilon 0.3";
    let (ok, out, err) = ctsid(&["regress", &eps, args]);
    assert!(ok, "{err}");
    let model = out.lines().find(|l| l.starts_with("y =")).unwrap_or("");
    // x*z lowers the relative residual by about 0.17 < 0.3: only x is left.
    assert!(model.contains("*x") && !model.contains("x*z"), "{out}");
    // A constant label: eBIC was -inf, and the model file held a null that did not read back.
    let cl = file("cl.csv", &rows(&|i| format!("{},5", sin(0.7, i)), "x,y"));
    let json = dir().join("cl.json").display().to_string();
    let (ok, out, err) = ctsid(&[
        "regress",
        &cl,
        "--features x --label y --degree 2 -o",
        &json,
    ]);
    assert!(ok, "{err}");
    assert!(!out.contains("inf") && !err.contains("inf"), "{out}{err}");
    let text = std::fs::read_to_string(&json).unwrap();
    assert!(!text.contains("null"), "{text}");
}

/// `-o` to a device or a pipe is refused before the work (the output was renamed over it: as
/// root, `-o /dev/full` replaced the device by a regular file), a link's file is written with
/// the link kept, and a name as long as file systems allow is written (its temporary name was
/// longer, so it failed after the whole table was printed).
#[cfg(unix)]
#[test]
fn outputs_to_devices_links_and_long_names() {
    let model = lag_model("mo.json", Some(1.0));
    let good = file("good-for-outputs.csv", &good_csv());
    let sim = |out: &str| {
        vec![
            "simulate".to_string(),
            model.clone(),
            good.clone(),
            "--run-column".into(),
            "run".into(),
            "--tau".into(),
            "0.01".into(),
            "-o".into(),
            out.to_string(),
        ]
    };
    let args = sim("/dev/null");
    let refs: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let out = fails(&refs, &["not a regular file"]);
    assert!(out.stdout.is_empty(), "the work ran before the refusal");

    let target = dir().join("linked-target.csv");
    std::fs::write(&target, "old").unwrap();
    let link = dir().join("link-to-target.csv");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let args = sim(&link.display().to_string());
    let refs: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let (ok, _, err) = ctsid(&refs);
    assert!(ok, "{err}");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read_to_string(&target).unwrap().contains("y_sim"));

    let long = dir().join("l".repeat(251) + ".csv");
    let args = sim(&long.display().to_string());
    let refs: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let (ok, _, err) = ctsid(&refs);
    assert!(ok, "{err}");
    assert!(long.is_file());
    std::fs::remove_file(&long).ok();
}

/// Terms that are never finite, or not finite on the data, are refused by name: `identify
/// --term '0/0'` ran with the term set aside quietly, and a model file with `y/0` was read,
/// then blamed on the step size by `simulate`.
#[test]
fn terms_that_are_not_finite_are_refused_by_name() {
    let good = file("terms-finite.csv", &good_csv());
    let id = "--run-column run --time-column t --degree 1 --output y --input u --order 1";
    fails(
        &["identify", &good, id, "--term", "0/0"],
        &["'0/0' has a part that is not finite whatever the data are"],
    );
    fails(
        &["identify", &good, id, "--term", "exp(1000)"],
        &["'exp(1000)'", "not finite"],
    );
    fails(
        &["identify", &good, id, "--term", "1/(y-y)"],
        &["'1/(y-y)' is not finite on", "reformulate"],
    );
    // A channel named like a number shared the constant candidate's name `1` (another model
    // than the same data named `u`).
    let numeric = file(
        "numeric-name.csv",
        &good_csv().replacen("run,t,u,y", "run,t,1,y", 1),
    );
    fails(
        &[
            "identify",
            &numeric,
            "--run-column run --time-column t --degree 1 --output y --input 1 --order 1",
        ],
        &["'1' reads as a number", "rename"],
    );
    // A monomial already among the candidates (was accepted as a second column of y).
    for copy in ["y", "2*y", "-u/3"] {
        fails(
            &["identify", &good, id, &format!("--term={copy}")],
            &[
                &format!("'{copy}' is a monomial of degree 1"),
                "already a candidate",
            ],
        );
    }
    let text = common::cli::lag_model_text(-1.0, Some(1.0));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (expr, says) in [("y/0", "divides by zero"), ("sqrt(-1)", "NaN")] {
        let mut m = v.clone();
        m["format"] = "ctsid-model/2".into();
        m["outputs"][0]["terms"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({"expression": expr, "coefficient": 1.0}));
        let path = file(&format!("bad-expr-{}.json", expr.len()), &m.to_string());
        fails(&["show", &path], &[expr, says]);
    }
}

/// `-o` inside the `--report` folder was replaced by a report file (`-o rep/report.md` lost the
/// simulated CSV; discover's model became its summary): refused before the work.
#[test]
fn an_output_inside_the_report_folder_is_refused() {
    let model = lag_model("inside.json", Some(1.0));
    let good = file("good-inside.csv", &good_csv());
    let rep = dir().join("inside-rep");
    std::fs::create_dir_all(&rep).unwrap();
    let inside = rep.join("report.md");
    let out = fails(
        &strs(&simulate_report(&model, &good, &rep, Some(&inside))),
        &["inside the report folder"],
    );
    assert!(out.stdout.is_empty(), "the work ran before the refusal");
    assert!(!inside.exists());
    // `control` wrote its plot over its trace, `identify` its report over its model, both
    // with exit 0 (session 22's fuzzing).
    let svg = rep.join("step.svg");
    let svg_s = svg.display().to_string();
    let rep_s = rep.display().to_string();
    fails(
        &[
            "control",
            &model,
            "--setpoint 1 --from 0 --tau 0.01",
            "-o",
            &svg_s,
            "--report",
            &rep_s,
        ],
        &["inside the report folder"],
    );
    let csv = file("good-inside-id.csv", &good_csv());
    fails(
        &[
            "identify",
            &csv,
            "--output y --input u --time-column t --run-column run",
            "--degree 1 --order 1 --quiet -o",
            &inside.display().to_string(),
            "--report",
            &rep_s,
        ],
        &["inside the report folder"],
    );
    assert!(!svg.exists() && !inside.exists());
}

/// Found by session 22's fuzzing, each exit 0 before: a term of a coefficient alone read as
/// the constant; an expression that is a monomial beside that monomial; `--init-window 0`
/// raised to 15 without a word; an input that repeats the output fitted as `y_d1 = 0`; and
/// `control --noise NaN` refused only after the whole design was printed.
#[test]
fn slips_that_passed_before_are_refused() {
    let text = common::cli::lag_model_text(-1.0, Some(1.0));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let with_term = |name: &str, term: serde_json::Value| {
        let mut m = v.clone();
        m["format"] = "ctsid-model/2".into();
        m["outputs"][0]["terms"].as_array_mut().unwrap().push(term);
        file(name, &m.to_string())
    };
    let bare = with_term("bare-term.json", serde_json::json!({"coefficient": 2.0}));
    fails(
        &["show", &bare],
        &["neither \"exponents\" nor \"expression\""],
    );
    let twice = with_term(
        "expr-twice.json",
        serde_json::json!({"expression": "2*y", "coefficient": 0.5}),
    );
    fails(
        &["show", &twice],
        &["terms 1 and 3 (y and 2*y) are one column up to a constant factor"],
    );
    let three = with_term(
        "interval-three.json",
        serde_json::json!({"exponents": {"u": 2}, "coefficient": 0.5, "interval": [0.1, 0.5, 0.9]}),
    );
    fails(&["show", &three], &["interval has 3 numbers"]);
    // A named term that is no monomial stays a term of its own.
    let own = with_term(
        "expr-own.json",
        serde_json::json!({"expression": "sqrt(abs(y))", "coefficient": 0.5}),
    );
    assert!(run(&["show", &own]).status.success());

    let model = lag_model("init-window.json", Some(1.0));
    let data = file("init-window.csv", &good_csv());
    let sim = "--run-column run --time-column t --init-window";
    fails(
        &["simulate", &model, &data, sim, "0"],
        &["init-window", "at least 3"],
    );
    assert!(run(&["simulate", &model, &data, sim, "3"]).status.success());

    let mut same = String::from("t,u,y\n");
    for i in 0..400 {
        let t = i as f64 * 0.01;
        let y = (t).sin() + 0.3 * (2.7 * t).cos();
        same += &format!("{t},{},{y}\n", 2.0 * y + 1.0);
    }
    let same = file("u-is-y.csv", &same);
    fails(
        &[
            "identify",
            &same,
            "--output y --input u --time-column t --degree 1 --order 1",
        ],
        &["input 'u' is output 'y' up to scale and offset"],
    );
    // A constant output with one glitch failed inside the fit ("the chosen terms are linearly
    // dependent").
    let mut glitch = String::from("t,u,y\n");
    for i in 0..400 {
        let t = i as f64 * 0.01;
        let y = if i == 200 { 0.7 } else { 0.5 };
        glitch += &format!("{t},{},{y}\n", (3.0 * t).sin());
    }
    let glitch = file("glitch.csv", &glitch);
    fails(
        &[
            "identify",
            &glitch,
            "--output y --input u --time-column t --degree 1 --order 1",
        ],
        &["output 'y' is constant (0.5) except at 1 of"],
    );

    let out = fails(
        &[
            "control",
            &model,
            "--setpoint 1 --from 0 --tau 0.01 --noise NaN",
        ],
        &["noise"],
    );
    assert!(
        out.stdout.is_empty(),
        "the design was printed before the refusal"
    );
    // The profile law on a model not affine in its input, without limits to search in.
    let square = with_term(
        "u-squared.json",
        serde_json::json!({"exponents": {"u": 2}, "coefficient": 0.3}),
    );
    let out = fails(
        &[
            "control",
            &square,
            "--setpoint 1 --from 0 --tau 0.01 --law profile",
        ],
        &["--u-min and --u-max"],
    );
    assert!(
        out.stdout.is_empty(),
        "the design was printed before the refusal"
    );
}

/// A control byte from the data (NUL, ESC) is shown escaped in the error line: raw, a NUL cut
/// the line in a terminal and an ESC sequence recoloured it.
#[test]
fn control_bytes_from_the_data_are_escaped_in_errors() {
    let mut s = good_csv();
    s = s.replacen("0,0.01,", "0,\u{1b}[31m0.01,", 1);
    let data = file("esc.csv", &s);
    let model = lag_model("esc.json", Some(1.0));
    let out = fails(
        &[
            "simulate",
            &model,
            &data,
            "--run-column run --time-column t",
        ],
        &["\\u{1b}[31m0.01"],
    );
    assert!(!out.stderr.contains(&0x1b));
}

/// Terms near 1e308: the steady-input search summed the terms' magnitudes, which overflowed, and
/// called the input ineffective ("dP/du = 0"); the error now names what is wrong (the default
/// bandwidth the model's poles give).
#[test]
fn a_model_near_the_end_of_f64_is_not_called_uncontrollable() {
    let model = file(
        "huge-coefs.json",
        &common::cli::lag_model_text(-1e308, Some(1e308)),
    );
    let out = fails(
        &["control", &model, "--setpoint 1 --from 0 --tau 0.01"],
        &["bandwidth"],
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("dP/du = 0"));
    // Sensor noise of 1e300 overflowed the observer and was blamed on the bandwidth alone.
    let lag = lag_model("lag-noise.json", Some(2.0));
    fails(
        &[
            "control",
            &lag,
            "--setpoint 1 --from 0 --tau 0.01 --noise 1e300",
        ],
        &["diverged", "the sensor noise (sd 1e300)"],
    );
}

/// `score-derivatives` on a folder whose signal is cut short: the gates are for the signals as
/// published, and a cut file was scored against them.
#[test]
fn a_cut_test_signal_is_not_scored_against_the_published_gates() {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/signals");
    let cut = dir().join("signals-cut");
    std::fs::create_dir_all(&cut).unwrap();
    for f in [
        "sys3_multisine.csv",
        "chirp.csv",
        "etc_s1.csv",
        "signals.json",
    ] {
        std::fs::copy(src.join(f), cut.join(f)).unwrap();
    }
    let sines = std::fs::read_to_string(src.join("sines.csv")).unwrap();
    let kept: Vec<&str> = sines.lines().take(901).collect();
    std::fs::write(cut.join("sines.csv"), kept.join("\n")).unwrap();
    let folder = cut.display().to_string();
    fails(
        &["score-derivatives", "--signals", &folder],
        &["sines.csv: 900 samples every 0.01 s, the published signal has 1000 every 0.01 s"],
    );
}

/// An eighth reading (control's references, model-file names, discover on short pieces), each
/// once a silent wrong answer or a lost input.
#[test]
fn references_names_and_short_pieces_found_by_the_eighth_reading() {
    let lag = lag_model("lag8.json", Some(2.0));
    let step = "--setpoint 1 --from 0 --tau 0.01";
    // `-o` onto the reference file replaced the user's reference with the trace.
    let r = file("ref8.csv", "t,r\n0,0\n1,0\n1,1\n5,1\n");
    fails(
        &["control", &lag, step, "--reference", &r, "-o", &r],
        &["is also an input file"],
    );
    assert!(std::fs::read_to_string(&r).unwrap().starts_with("t,r\n"));
    // A reference that ends before t = 0 or within ten samples (a constant of one knot) ran ten
    // samples without a word: it now runs as long as a step would, and says so.
    let early = file("ref8-early.csv", "t,r\n-5,0\n-1,1\n");
    let (ok, out, err) = ctsid(&["control", &lag, step, "--reference", &early]);
    assert!(ok, "{err}");
    assert!(
        err.contains("note: the reference ends at t = -1 s, within the first 10 samples"),
        "{err}"
    );
    assert!(!out.contains(" 0.1000 s"), "{out}");
    let constant = file("ref8-const.csv", "t,r\n0,1\n");
    let (ok, _, err) = ctsid(&["control", &lag, step, "--reference", &constant]);
    assert!(ok && err.contains("as a step's would"), "{err}");
    // Knots 1e-320 s apart: the slope overflowed and the error blamed a NaN setpoint.
    let steep = file("ref8-steep.csv", "t,r\n0,0\n1e-320,1\n2,1\n");
    fails(
        &["control", &lag, step, "--reference", &steep],
        &["the slope between knots 1 and 2 (0 to 1 over 1e-320 s) overflows"],
    );
    // A state named with a comma: the trace's header had one field more than its rows.
    let comma = file(
        "comma8.json",
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"a,b","order":1,"terms":[{"exponents":{"a,b":1},"coefficient":-2},{"exponents":{"u":1},"coefficient":3}]}]}"#,
    );
    let trace = dir().join("trace8.csv").display().to_string();
    let (ok, _, err) = ctsid(&["control", &comma, step, "-o", &trace]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&trace).unwrap();
    let mut rdr = csv::Reader::from_reader(text.as_bytes());
    let width = rdr.headers().unwrap().len();
    assert!(rdr.headers().unwrap().iter().any(|h| h == "a,b_hat"));
    assert!(rdr.records().all(|r| r.unwrap().len() == width));
    // An input named like the output's left-hand side (`y_d1` beside `y` of order 1) read
    // `y_d1 = -2*y + 3*y_d1`; a line break in a name split the printed equations.
    let lhs = file(
        "lhs8.json",
        r#"{"format":"ctsid-model/1","inputs":["y_d1"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-2},{"exponents":{"y_d1":1},"coefficient":3}]}]}"#,
    );
    fails(&["show", &lhs], &["'y_d1' is used twice", "left-hand side"]);
    let nl = file(
        "nl8.json",
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y\n#x","order":1,"terms":[{"exponents":{"u":1},"coefficient":3}]}]}"#,
    );
    fails(&["show", &nl], &["holds a control character"]);
    // discover on pieces of 13 samples: every free run "diverged", the gates compared inf with
    // inf, and a re-tuned model came back with exit 0.
    let mut text = String::from("t,u,y\n");
    let (mut y, h) = (0.0f64, 0.001);
    for k in 0..600 {
        let t = k as f64 * 0.01;
        let u = |t: f64| 1.5 * (1.1 * t).sin() + 0.8 * (3.7 * t).sin();
        text += &format!("{t},{},{y}\n", u(t));
        for j in 0..10 {
            let s = t + j as f64 * h;
            y += h * (-2.0 * y - y * y * y + 3.0 * u(s));
        }
    }
    let data = file("short8.csv", &text);
    let nominal = file(
        "nominal8.json",
        &common::cli::lag_model_text(-2.0, Some(3.0)),
    );
    let out = dir().join("short8-out.json");
    fails(
        &[
            "discover",
            &data,
            "--nominal",
            &nominal,
            "--time-column t --segment 0.13 -o",
            out.to_str().unwrap(),
        ],
        &["'segment'", "13 samples", "needs at least 15"],
    );
    assert!(!out.exists());
}

/// A command's files are written all or none: `simulate -o SIM --report REP` whose report cannot
/// be finished (REP/report.md is a folder) wrote the simulated CSV and the figures before the
/// error; now neither, no temporary file is left, and nothing says "wrote".
#[test]
fn a_report_that_fails_half_way_leaves_no_output() {
    let model = lag_model("half.json", Some(1.0));
    let good = file("good-half.csv", &good_csv());
    let rep = dir().join("half-rep");
    std::fs::create_dir_all(rep.join("report.md")).unwrap();
    let sim = dir().join("half-sim.csv");
    let _ = std::fs::remove_file(&sim);
    let args = simulate_report(&model, &good, &rep, Some(&sim));
    let out = fails(&strs(&args), &["report.md"]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("wrote"));
    assert!(!sim.exists(), "the simulated CSV was written");
    let left: Vec<String> = std::fs::read_dir(&rep)
        .unwrap()
        .chain(std::fs::read_dir(dir()).unwrap())
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".ctsid-") || n.ends_with(".svg"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    // The same command with a report it can write leaves both, and says so.
    std::fs::remove_dir(rep.join("report.md")).unwrap();
    let (ok, _, err) = ctsid(&strs(&args));
    assert!(ok, "{err}");
    assert!(sim.exists() && rep.join("report.md").is_file());
    assert!(
        err.contains("wrote") && err.contains("report written"),
        "{err}"
    );
}

/// A report's own file names were never checked against the inputs: `simulate
/// rep/sim_0_y.svg rep/report.md --report rep` replaced the model and the data with the report
/// (exit 0). Refused now, and neither input is touched.
#[test]
fn a_report_file_that_is_an_input_is_refused() {
    let rep = dir().join("input-rep");
    std::fs::create_dir_all(&rep).unwrap();
    let model = rep.join("sim_0_y.svg");
    let data = rep.join("report.md");
    let model_text = common::cli::lag_model_text(-1.0, Some(1.0));
    std::fs::write(&model, &model_text).unwrap();
    std::fs::write(&data, good_csv()).unwrap();
    let (m, d) = (model.display().to_string(), data.display().to_string());
    fails(
        &strs(&simulate_report(&m, &d, &rep, None)),
        &["this command read", "destroy an input"],
    );
    assert_eq!(std::fs::read_to_string(&model).unwrap(), model_text);
    assert_eq!(std::fs::read_to_string(&data).unwrap(), good_csv());
}

/// The ninth reading: a constant regression feature was credited in the model (`l = 0.4*a*k` for
/// `l = 2*a`, `k` = 5); a model file's input named `2` showed as `3*2`; identify refused an input
/// named `2` as a 'features' setting it does not have; `control --duration 1e12` printed the
/// whole design before its error.
#[test]
fn findings_of_the_ninth_reading() {
    let mut rk = String::from("a,k,l\n");
    for i in 0..200 {
        let a = (0.37 * i as f64).sin();
        rk += &format!("{a},5,{}\n", 10.0 + 2.0 * a + 0.01 * (1.7 * i as f64).cos());
    }
    let rk = file("constant-feature.csv", &rk);
    fails(
        &["regress", &rk, "--features a,k --label l --degree 2"],
        &["'k' is constant (5)", "leave it out"],
    );
    let numbered = file(
        "numbered-input.json",
        r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["2"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-2.0},{"exponents":{"2":1},"coefficient":3.0}]}]}"#,
    );
    fails(&["show", &numbered], &["'2' reads as a number"]);
    let renamed = good_csv().replacen("run,t,u,y", "run,t,2,y", 1);
    let data = file("numbered-channel.csv", &renamed);
    fails(
        &[
            "identify",
            &data,
            "--output y --input 2 --run-column run --time-column t --degree 1 --order 1",
        ],
        &["setting 'input'", "'2' reads as a number"],
    );
    let model = lag_model("long-duration.json", Some(1.0));
    let out = fails(
        &[
            "control",
            &model,
            "--setpoint 1 --from 0 --tau 0.01 --duration 1e12",
        ],
        &["'duration'", "samples"],
    );
    fails(
        &[
            "control",
            &model,
            "--setpoint 1 --from 0 --tau 0.01 --duration=-1",
        ],
        &["'duration'", "give a value > 0"],
    );
    assert!(
        out.stdout.is_empty(),
        "the design was printed before the error"
    );
    // A term that is not finite where the free run starts was blamed on the model's stability
    // (the step size collapsed at t = 0); the error names the term.
    let inf = file(
        "nonfinite-term.json",
        r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-2.0},{"expression":"1/(y-y)","coefficient":0.1}]}]}"#,
    );
    let good = file("good-nonfinite.csv", &good_csv());
    fails(
        &["simulate", &inf, &good, "--run-column run --tau 0.01"],
        &["the term '1/(y-y)' of output 'y' is inf", "initial state"],
    );
}

/// A test run on which the identified model diverges: the heading printed `overall NRMSE NaN %`
/// (the pooled error of no run); it now says that the test run diverged, and over how many runs
/// a pooled figure is when only some diverge.
#[test]
fn a_diverging_test_run_gives_no_nan_heading() {
    // y' = -2 y + 3 u - 0.5 y^3 (Euler, 200 substeps per sample), six runs of 300 samples; the
    // last has 40 times the input, far outside what the quadratic fit of the others saw.
    let mut s = String::from("run,t,u,y\n");
    let mut seed = 5u64;
    for r in 0..6 {
        let amp = if r < 5 { 1.0 } else { 40.0 };
        let mut y = 0.0f64;
        for k in 0..300 {
            let t = k as f64 * 0.01;
            let rf = (r + 1) as f64;
            let u = amp * ((0.7 * t * rf).sin() + 0.5 * (3.1 * t + r as f64).sin());
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = 0.005 * (((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5) * 3.4;
            s += &format!("{r},{t:.2},{u:.6},{:.6}\n", y + noise);
            for _ in 0..200 {
                y += 0.00005 * (-2.0 * y + 3.0 * u - 0.5 * y * y * y);
            }
        }
    }
    let data = file("diverging-test.csv", &s);
    let (ok, out, err) = ctsid(&[
        "identify",
        &data,
        "--output y --input u --run-column run --time-column t --degree 2 --order 1 --train 0-3 --validation 4 --test 5 --quiet",
    ]);
    assert!(ok, "{err}");
    assert!(!out.contains("NaN"), "{out}");
    assert!(
        out.contains("(the test run diverged)") || out.contains("(overall NRMSE"),
        "{out}"
    );
    // The run does diverge with this model (else the test checks nothing).
    assert!(out.contains("diverged:"), "{out}");
}

/// A run id holding a comma cannot be named in a run list (`--test 'a,b'` tested runs `a` and
/// `b` and trained on `a,b`): refused where a run list is resolved (the tenth reading).
#[test]
fn a_run_id_with_a_comma_is_refused() {
    let mut text = String::from("run,t,u,y\n");
    for id in ["\"a,b\"", "a", "b", "c"] {
        for k in 0..40 {
            let t = k as f64 * 0.1;
            text.push_str(&format!("{id},{t},{},{}\n", t.sin(), t.cos()));
        }
    }
    let csv = temp_file("comma-runs", "runs.csv", &text);
    let args = words(&[
        "identify",
        &csv,
        "--run-column run --time-column t --output y --input u --degree 1 --test a,b --quiet",
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails(&args, &["run id 'a,b' holds a comma"]);
}

/// One column as both the run column and the time column made every sample a run of its own,
/// refused as "within run '0.00' times must increase" (the tenth reading).
#[test]
fn one_column_cannot_be_both_run_and_time() {
    let csv = temp_file("run-time", "rt.csv", "t,u,y\n0,1,2\n0.1,1,2\n0.2,1,2\n");
    let args = words(&[
        "identify",
        &csv,
        "--run-column t --time-column t --output y --input u --degree 1",
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails(
        &args,
        &["'t' is given as both the run column and the time column"],
    );
}

/// Left by the tenth reading: channels named `nan` or `y^2` were taken as inputs and printed as
/// `0.12*nan` (a broken coefficient to the eye) and `0.3*y^2` (a power); a name the expression
/// parser cannot read as one name cannot be named in a term either. Refused by the option (or
/// the model file) that names them; plain names still work.
#[test]
fn channels_whose_names_print_ambiguously_are_refused() {
    for (k, (header, name, why)) in [
        ("run,t,nan,y", "nan", "reads as a non-finite number"),
        ("run,t,Inf,y", "Inf", "reads as a non-finite number"),
        (
            "run,t,y^2,y",
            "y^2",
            "is not one name to the expression parser",
        ),
        ("run,t,force [N],y", "force [N]", "is not one name"),
    ]
    .into_iter()
    .enumerate()
    {
        let data = file(
            &format!("odd-channel-{k}.csv"),
            &good_csv().replacen("run,t,u,y", header, 1),
        );
        let opts = "--output y --run-column run --time-column t --degree 1 --order 1 --input";
        fails(
            &["identify", &data, opts, name],
            &[
                "setting 'input'",
                &format!("'{name}' {why}"),
                "rename the channel",
            ],
        );
    }
    // A model file may still name `y^2` (files written before keep loading), not `NaN`.
    let odd = file(
        "odd-input.json",
        r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["NaN"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-2.0},{"exponents":{"NaN":1},"coefficient":3.0}]}]}"#,
    );
    fails(&["show", &odd], &["'NaN' reads as a non-finite number"]);
    let power = odd.replace("odd-input", "power-input");
    std::fs::write(
        &power,
        std::fs::read_to_string(&odd).unwrap().replace("NaN", "y^2"),
    )
    .unwrap();
    let (ok, shown, err) = ctsid(&["show", &power]);
    assert!(ok && shown.contains("y^2"), "{err}");
    let plain = file(
        "plain-channel.csv",
        &good_csv().replacen("run,t,u,y", "run,t,θ_1,y", 1),
    );
    let (ok, _, err) = ctsid(&[
        "identify",
        &plain,
        "--output y --input θ_1 --run-column run --time-column t --degree 1 --order 1",
    ]);
    assert!(ok, "{err}");
}

/// A file of several runs read without its run column was one run, its runs joined end to end:
/// every command scored or fitted it without a word (the Python package did the same with a
/// frame). Refused by name where a column named `run` or `run_id` holds more than one value;
/// one value (a single run that carries its id) passes.
#[test]
fn a_run_column_left_out_is_refused_where_it_holds_several_runs() {
    let data = file("runs_unnamed.csv", &good_csv());
    for cmd in [
        "identify --output y --input u --time-column t --degree 1 --order 1",
        "derive --column y --order 1 --time-column t",
    ] {
        let args: Vec<&str> = std::iter::once(cmd.split(' ').next().unwrap())
            .chain(std::iter::once(data.as_str()))
            .chain(cmd.split(' ').skip(1))
            .collect();
        fails(
            &args,
            &["column 'run' holds more than one run", "--run-column run"],
        );
    }
    let one: String = good_csv()
        .lines()
        .filter(|l| !l.starts_with("1,"))
        .map(|l| format!("{l}\n"))
        .collect();
    let one = file("runs_one.csv", &one);
    let (ok, _, err) = ctsid(&[
        "derive",
        &one,
        "--column",
        "y",
        "--order",
        "1",
        "--time-column",
        "t",
    ]);
    assert!(ok, "{err}");
}

/// `ctsid ... 2>&1 | head -1` closes standard error after one line: the next note or the
/// error line panicked in the standard `eprintln!` (exit 101, a panic message nobody sees).
#[test]
fn a_closed_standard_error_is_no_panic() {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let status = bin()
        .args(["show", "/nonexistent/model.json"])
        .stdout(std::process::Stdio::null())
        .stderr(writer)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(2), "{status:?}");
}

/// A cell that is no number in a file of several runs names its run beside the file row (the
/// row alone left the run to be looked up); a file without a run column is as before.
#[test]
fn a_bad_cell_names_its_run() {
    let runs = temp_file("runcell", "runs.csv", "run,y,u\n1,1,2\n1,2,3\n2,nan,1\n");
    fails(
        &[
            "identify",
            &runs,
            "--output y --input u --run-column run --tau 1 --degree 1",
        ],
        &["row 4 (run '2'), column 'y': 'nan' is not a finite number"],
    );
    let one = temp_file("runcell", "one.csv", "y,u\n1,2\n2,3\nnan,1\n");
    fails(
        &["identify", &one, "--output y --input u --tau 1 --degree 1"],
        &["row 4, column 'y': 'nan' is not a finite number"],
    );
}
