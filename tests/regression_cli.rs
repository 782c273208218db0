//! `ctsid regress` end to end: equation, JSON model, one-line errors.

mod common;

use common::cli::ctsid;

fn dir() -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("ctsid-regress-cli-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write_csv(path: &std::path::Path, bad_row: Option<usize>) {
    let mut s = String::from("A,B,C,L\n");
    let mut x = 0.123f64;
    for i in 0..400 {
        let mut v = [0.0; 3];
        for k in v.iter_mut() {
            x = (x * 7919.0 + 0.31).fract();
            *k = 2.0 * x - 1.0;
        }
        let l = 2.0 * v[0] * v[0] * v[1] - 0.5 * v[2] + 1.25;
        if bad_row == Some(i) {
            s.push_str(&format!("{},nan,{},{}\n", v[0], v[2], l));
        } else {
            s.push_str(&format!("{},{},{},{}\n", v[0], v[1], v[2], l));
        }
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn regress_writes_the_model_and_prints_the_equation() {
    let d = dir();
    let csv = d.join("data.csv");
    write_csv(&csv, None);
    let model = d.join("model.json");
    let (ok, out, err) = ctsid(&[
        "regress",
        csv.to_str().unwrap(),
        "--features",
        "A,B,C",
        "--label",
        "L",
        "--degree",
        "3",
        "--engine",
        "cpu",
        "-o",
        model.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.starts_with("L = -0.5*C + 2*A^2*B + 1.25\n"), "{out}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(v["label"], "L");
    let terms = v["terms"].as_array().unwrap();
    assert_eq!(terms.len(), 3);
    assert_eq!(terms[0]["exponents"].as_object().unwrap().len(), 0);
    assert!((terms[0]["coefficient"].as_f64().unwrap() - 1.25).abs() < 1e-9);
    assert_eq!(terms[2]["exponents"]["A"], 2);
    assert_eq!(terms[2]["exponents"]["B"], 1);
    let (ok, out, err) = ctsid(&[
        "regress",
        csv.to_str().unwrap(),
        "--features",
        "A,B,C",
        "--label",
        "L",
        "--degree",
        "3",
    ]);
    // The engine note goes to standard error; the result alone to standard output.
    assert!(ok && err.contains("note: cpu engine:"), "{err}");
    assert!(!out.contains("note:"), "{out}");
}

#[test]
fn regress_errors_are_one_line() {
    let d = dir();
    let csv = d.join("bad.csv");
    write_csv(&csv, Some(6));
    let c = csv.to_str().unwrap();
    let cases: [(&[&str], &str); 3] = [
        (
            &[
                "regress",
                c,
                "--features",
                "A,X",
                "--label",
                "L",
                "--degree",
                "2",
            ],
            "no column named 'X'",
        ),
        (
            &[
                "regress",
                c,
                "--features",
                "A,B",
                "--label",
                "L",
                "--degree",
                "2",
            ],
            "row 8, column 'B': 'nan' is not a finite number",
        ),
        (
            &[
                "regress",
                c,
                "--features",
                "A,C",
                "--label",
                "L",
                "--degree",
                "20",
            ],
            "invalid setting '--degree'",
        ),
    ];
    for (args, want) in cases {
        let (ok, _, err) = ctsid(args);
        assert!(!ok);
        assert!(err.contains(want), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
}

#[test]
fn regress_engine_gpu_runs_on_any_adapter_or_fails_clearly() {
    let d = dir();
    let csv = d.join("gpu.csv");
    write_csv(&csv, None);
    let (ok, out, err) = ctsid(&[
        "regress",
        csv.to_str().unwrap(),
        "--features",
        "A,B,C",
        "--label",
        "L",
        "--degree",
        "3",
        "--engine",
        "gpu",
    ]);
    if ctsid::engine::select::probe().is_empty() {
        assert!(
            std::env::var("CTSID_REQUIRE_GPU").as_deref() != Ok("1"),
            "CTSID_REQUIRE_GPU=1 but no GPU adapter"
        );
        println!("skipping the GPU half: no GPU adapter");
        assert!(!ok && err.contains("no Vulkan adapter"), "{err}");
    } else {
        assert!(ok, "{err}");
        assert!(err.contains("note: gpu engine on"), "{err}");
        assert!(out.contains("engine: gpu"), "{out}");
        // f32 sweeps pick the same terms; the coefficients come from the f64 refit.
        assert!(out.starts_with("L = -0.5*C + 2*A^2*B + 1.25\n"), "{out}");
    }
}

/// What a researcher's day with `regress` found (2026-11-30, session 24), each refused in one
/// line by the option it concerns.
#[test]
fn regress_refuses_what_read_wrong_before() {
    let d = dir();
    let csv = d.join("good.csv");
    write_csv(&csv, None);
    let c = csv.to_str().unwrap();
    // A feature named like a monomial printed `y = 3*x^2 + 0.5*x^2`.
    let text = std::fs::read_to_string(&csv)
        .unwrap()
        .replacen("A,B,C,L", "A,B^2,C,L", 1);
    let odd = d.join("odd.csv");
    std::fs::write(&odd, text).unwrap();
    let o = odd.to_str().unwrap();
    // Two rows were called a constant feature; -o - wrote a file named '-'.
    let short = d.join("short.csv");
    std::fs::write(&short, "A,B,C,L\n1,2,3,4\n2,1,3,5\n").unwrap();
    let s = short.to_str().unwrap();
    let base = |data: &str, features: &str| {
        let mut v = vec!["regress", "--label", "L", "--degree", "2", "--features"];
        v.push(if features.is_empty() {
            "A,B,C"
        } else {
            features
        });
        v.push(data);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    // Twelve rows, three of positive weight, C constant: too few samples, not a constant
    // feature (the constant check counted the rows of zero weight).
    let weighted = d.join("weighted.csv");
    let mut text = String::from("A,B,C,L,W\n");
    for i in 0..12 {
        let w = if i < 3 { 1 } else { 0 };
        text += &format!("{i},{},5,{},{w}\n", i * i % 7, 2 * i + 1);
    }
    std::fs::write(&weighted, text).unwrap();
    let w = weighted.to_str().unwrap();
    let cases: Vec<(Vec<String>, &[&str], &str)> = vec![
        (
            base(w, ""),
            &["--weights", "W"],
            "3 samples of positive weight are too few",
        ),
        (
            base(o, "A,B^2"),
            &[],
            "'B^2' is not one name to the expression parser",
        ),
        (
            base(c, ""),
            &["--weights", "L"],
            "'--weights': 'L' is also the label",
        ),
        (
            base(c, ""),
            &["--weights", "A"],
            "'--weights': 'A' is also a feature",
        ),
        (base(s, ""), &[], "2 samples are too few to select terms"),
        (
            base(c, ""),
            &["-o", "-"],
            "standard output is not an output file here",
        ),
        (
            base(c, ""),
            &["--max-terms", "0"],
            "invalid setting '--max-terms'",
        ),
        // Every option is named as a flag (a feature's was named as a field).
        (base(o, "A,B^2"), &[], "invalid setting '--features'"),
    ];
    for (mut args, extra, want) in cases {
        args.extend(extra.iter().map(|s| s.to_string()));
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, _, err) = ctsid(&refs);
        assert!(!ok && err.contains(want), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
    assert!(!std::path::Path::new("-").exists());
}

/// `--patience 0` runs the whole path up to --max-terms (to compare paths with other tools);
/// the default ends it once eBIC has not improved for 40 breakpoints.
#[test]
fn regress_patience_zero_runs_the_whole_path() {
    let d = dir();
    let csv = d.join("whole.csv");
    // Noisy: a noise-free label ends the path once its three terms fit exactly.
    let mut text = String::from("A,B,C,L\n");
    let mut x = 0.377f64;
    let mut next = || {
        x = (x * 7919.0 + 0.31).fract();
        2.0 * x - 1.0
    };
    for _ in 0..400 {
        let (a, b, c) = (next(), next(), next());
        let l = 2.0 * a * a * b - 0.5 * c + 1.25 + 0.3 * next();
        text += &format!("{a},{b},{c},{l}\n");
    }
    std::fs::write(&csv, text).unwrap();
    let steps = |patience: &str| {
        // `ctsid` splits an argument that starts with `-` at its spaces.
        let settings = "--label L --degree 4 --method lars --engine cpu --max-terms 30";
        let (ok, out, err) = ctsid(&[
            "regress",
            csv.to_str().unwrap(),
            "--features",
            "A,B,C",
            settings,
            "--patience",
            patience,
        ]);
        assert!(ok, "{err}");
        let after = out.split("path of ").nth(1).expect("no path line");
        after.split(' ').next().unwrap().parse::<usize>().unwrap()
    };
    let (short, whole) = (steps("1"), steps("0"));
    assert!(short < whole, "patience 1: {short} steps, 0: {whole}");
    assert!(whole >= 30, "{whole} steps for 30 terms");
}
