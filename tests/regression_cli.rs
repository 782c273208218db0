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
            "invalid setting 'degree'",
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
