//! Running the `ctsid` binary from the tests: arguments, one-line errors, temporary files.

use std::process::{Command, Output};

/// The binary, ready for arguments.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ctsid"))
}

/// The arguments, with every one that starts with `-` split at spaces: `"--column y --order 1"`
/// is four arguments, while paths and values like `"u, t"` stay whole.
pub fn words(args: &[&str]) -> Vec<String> {
    args.iter()
        .flat_map(|a| {
            if a.starts_with('-') {
                a.split_whitespace().map(String::from).collect()
            } else {
                vec![a.to_string()]
            }
        })
        .collect()
}

pub fn run(args: &[&str]) -> Output {
    bin().args(words(args)).output().unwrap()
}

/// (success, standard output, standard error).
pub fn ctsid(args: &[&str]) -> (bool, String, String) {
    let out = run(args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// Runs and asserts a one-line error containing every needle, exit code 2.
pub fn fails(args: &[&str], needles: &[&str]) -> Output {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: not one line:\n{err}"
    );
    assert!(err.starts_with("error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: '{n}' not in: {err}");
    }
    out
}

/// Writes `text` to `name` in this test binary's own temporary folder (`tag` tells the test
/// files apart); the path.
pub fn temp_file(tag: &str, name: &str, text: &str) -> String {
    let dir = std::env::temp_dir().join(format!("ctsid-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// `simulate`'s pooled NRMSE (%) of `output`: its `all` row.
pub fn overall_nrmse(stdout: &str, output: &str) -> f64 {
    let line = stdout
        .lines()
        .find(|l| l.split_whitespace().take(2).eq(["all", output]))
        .unwrap_or_else(|| panic!("no 'all {output}' row in:\n{stdout}"));
    // run, output, RMS, NRMSE %, fit %
    line.split_whitespace().nth(3).unwrap().parse().unwrap()
}

/// Model-file text of the first-order lag `y' = pole y [+ gain u]`.
pub fn lag_model_text(pole: f64, gain: Option<f64>) -> String {
    let u = gain.map_or(String::new(), |g| {
        format!(r#",{{"exponents":{{"u":1}},"coefficient":{g}}}"#)
    });
    format!(
        r#"{{"format":"ctsid-model/1","inputs":["u"],"outputs":[{{"name":"y","order":1,"terms":[{{"exponents":{{"y":1}},"coefficient":{pole}}}{u}]}}]}}"#
    )
}
