//! The user examples run as their docs say: `identify_csv` on a record of a known oscillator
//! and `discover_csv` on a generated case with a hidden Coulomb friction. `cargo test` builds
//! the examples before it runs the tests; a run of this file alone (`--test examples_run`)
//! does not, and the tests then skip with a notice.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The example's binary beside this test's (`target/<profile>/examples/NAME`).
fn example(name: &str) -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let p = exe.parent()?.parent()?.join("examples").join(name);
    if p.is_file() {
        Some(p)
    } else {
        eprintln!("NOTICE: example {name} not built (run the whole `cargo test`); skipped");
        None
    }
}

/// Runs an example in `dir`; its standard output, after asserting that it succeeded.
fn run_in(bin: &Path, dir: &Path, args: &[&str]) -> String {
    let out = Command::new(bin)
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{}: {err}", bin.display());
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ctsid-examples-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn the_examples_identify_and_discover_on_a_csv_record() {
    let Some(bin) = example("discover_csv") else {
        return;
    };
    let case = ctsid::discover::cases::generate("coulomb", 106, 0.03).unwrap();
    let dir = temp_dir("discover");
    let rs = &case.records;
    let mut csv = format!("run,{}\n", rs.channel_names.join(","));
    for (r, run) in rs.runs.iter().enumerate() {
        for i in 0..run.len() {
            let v: Vec<String> = run.channels.iter().map(|c| format!("{:e}", c[i])).collect();
            csv += &format!("{r},{}\n", v.join(","));
        }
    }
    std::fs::write(dir.join("data.csv"), &csv).unwrap();
    case.nominal
        .write(dir.join("nominal.json").to_str().unwrap())
        .unwrap();
    let text = run_in(
        &bin,
        &dir,
        &["data.csv", "nominal.json", &rs.tau.to_string()],
    );
    assert!(text.starts_with("verdict: added"), "{text}");
    let augmented = ctsid::Model::read(dir.join("augmented.json").to_str().unwrap()).unwrap();
    let named: Vec<&String> = augmented.outputs[0]
        .terms
        .iter()
        .filter_map(|t| t.expression.as_ref())
        .collect();
    assert!(!named.is_empty(), "no named term added: {augmented}");
    std::fs::remove_dir_all(&dir).ok();

    // identify_csv on the same record: a model, its file, and a fit per run.
    let Some(bin) = example("identify_csv") else {
        return;
    };
    let dir = temp_dir("identify");
    std::fs::write(dir.join("data.csv"), &csv).unwrap();
    let text = run_in(&bin, &dir, &["data.csv", "y", "u", &rs.tau.to_string()]);
    assert!(text.starts_with("y_d2 = "), "{text}");
    assert_eq!(
        text.lines()
            .filter(|l| l.starts_with("run ") && l.contains("fit"))
            .count(),
        rs.runs.len(),
        "{text}"
    );
    assert!(ctsid::Model::read(dir.join("identified.json").to_str().unwrap()).is_ok());

    // The same runs end to end in one record without a run column, cut by SECONDS at the runs'
    // own length: the same runs, the same model. Without SECONDS the missing run column is one
    // line, not the `Debug` form a `main` returning `Result` prints.
    let n = rs.runs[0].len();
    assert!(rs.runs.iter().all(|r| r.len() == n));
    let joined: String = csv
        .lines()
        .map(|l| l.split_once(',').unwrap().1.to_string() + "\n")
        .collect();
    std::fs::write(dir.join("long.csv"), joined).unwrap();
    let seconds = (n as f64 * rs.tau).to_string();
    let cut = run_in(
        &bin,
        &dir,
        &["long.csv", "y", "u", &rs.tau.to_string(), &seconds],
    );
    assert_eq!(cut, text);
    let out = Command::new(&bin)
        .current_dir(&dir)
        .args(["long.csv", "y", "u", &rs.tau.to_string()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("'run'") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!err.contains('{'), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
