//! `ctsid benchmark` on the public benchmarks (skipped with a notice without `../shared`): the
//! model files it writes simulate with `ctsid simulate` to the RMS it printed; Silverbox beats
//! the published linear and polynomial-NARX baselines, and so do the cascaded tanks, EMPS the
//! published linear one, the unbalanced disk its own linear nominal and (as a scale) the published linear figure.

mod common;

use common::cli::{ctsid, fails, temp_file};
use common::shared_data;

/// Runs `ctsid benchmark NAME --out DIR`; (its stdout, the model file).
fn bench(name: &str) -> (String, String) {
    let out = temp_file("bench", "x", "");
    let dir = std::path::Path::new(&out).parent().unwrap().join(name);
    let dir = dir.to_string_lossy().to_string();
    let (ok, stdout, err) = ctsid(&["benchmark", name, "--out", &dir]);
    assert!(ok, "{name}: {err}");
    (stdout, format!("{dir}/{name}.model.json"))
}

/// (ours, our linear nominal, the published linear baseline, the published polynomial NARX, NaN
/// where none is published) of each metric row.
fn rows(out: &str) -> Vec<(f64, f64, f64, f64)> {
    out.lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| metric"))
        .map(|l| {
            let c: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                c[2].parse().unwrap(),
                c[3].parse().unwrap(),
                c[4].parse().unwrap(),
                // "-" where the benchmark publishes no such row.
                c[5].parse().unwrap_or(f64::NAN),
            )
        })
        .collect()
}

/// The RMS `ctsid simulate` prints for the model file on the test record the benchmark wrote.
fn simulated_rms(out: &str) -> f64 {
    let cmd = out
        .split("the first row again: ctsid ")
        .nth(1)
        .unwrap_or_else(|| panic!("no check command in:\n{out}"))
        .trim();
    let args: Vec<&str> = cmd.split_whitespace().collect();
    let (ok, stdout, err) = ctsid(&args);
    assert!(ok, "{cmd}: {err}");
    let all = stdout.lines().last().unwrap();
    all.split_whitespace().nth(2).unwrap().parse().unwrap()
}

/// `ctsid simulate` on the written model file (its RMS times `scale`, the record's unit to the
/// benchmark's) agrees with the first row's printed RMS to 0.1 %.
fn assert_simulates_to_the_printed_rms(out: &str, scale: f64) {
    let printed = rows(out)[0].0;
    let simulated = scale * simulated_rms(out);
    assert!(
        (simulated - printed).abs() < 1e-3 * printed,
        "{simulated} vs {printed}"
    );
}

#[test]
fn silverbox_beats_the_linear_baseline_and_its_model_file_simulates_to_the_printed_rms() {
    if shared_data("silverbox/SNLS80mV.csv").is_none() {
        return;
    }
    let (out, _) = bench("silverbox");
    // Measured: 0.364 mV (arrow full) and 0.263 mV (without extrapolation) with the nonlinear
    // damping `y_V^2*y_V_d1` the second look adds (0.393 and 0.318 without it; 0.927 and 0.737
    // with the input read by straight lines); published linear 14.4 and 6.58, polynomial NARX
    // 2.25 and 0.571, best 0.26 and 0.32 (PNLSS); the goal 0.39 on the full arrow.
    for (ours, _, linear, pnarx) in rows(&out) {
        assert!(
            ours < linear / 5.0 && ours < pnarx,
            "ours {ours} against linear {linear}, polynomial NARX {pnarx}\n{out}"
        );
    }
    assert!(rows(&out)[0].0 <= 0.39, "{out}");
    assert!(
        out.lines().any(
            |l| l.contains("second look on simulation error: y_V^2*y_V_d1:")
                && l.ends_with("from zero: added")
        ),
        "{out}"
    );
    assert_simulates_to_the_printed_rms(&out, 1e3);
}

#[test]
fn emps_beats_the_linear_baseline_after_discover_and_simplify_and_its_model_file_simulates() {
    if shared_data("emps/EMPS_train_DATA_EMPS.csv").is_none() {
        return;
    }
    let (out, _) = bench("emps");
    // Measured: our linear nominal 15.06 mm, after the rounds (Coulomb friction and a
    // quadratic velocity term) 6.31 mm, after the simplification dropped the stiffness the
    // data do not determine (1.6 standard errors from zero) 5.15 mm; published linear 5.53,
    // polynomial NARX 5.17.
    let (ours, nominal, linear, _) = rows(&out)[0];
    assert!(
        ours < 0.6 * nominal && ours < linear,
        "ours {ours}, nominal {nominal}, published linear {linear}\n{out}"
    );
    assert!(out.contains("sign(q_m_d1)"), "{out}");
    assert!(
        out.contains("simplify: term q_m of q_m_d2") && out.contains("): dropped"),
        "{out}"
    );
    // The model file simulates the pulses record to the printed RMS (mm; the record is in m).
    assert_simulates_to_the_printed_rms(&out, 1e3);
}

#[test]
fn tanks_with_the_lower_tanks_overflow_beats_the_linear_baseline_and_its_model_file_simulates() {
    if shared_data("cascaded_tanks/cascaded_tanks_estimation.csv").is_none() {
        return;
    }
    let (out, model_file) = bench("tanks");
    // Measured: 0.360 V with the lower tank's level held at 10 V read from the training run as
    // a hard limit and the second look's u^2*y (0.524 V with the limit alone, 0.728 V with
    // neither; docs/benchmarks.md); published linear 0.588, polynomial NARX 0.413.
    let (ours, nominal, linear, pnarx) = rows(&out)[0];
    assert!(
        ours < pnarx && ours < linear && ours < 0.8 * nominal,
        "ours {ours}, our linear nominal {nominal}, published linear {linear}, polynomial NARX {pnarx}\n{out}"
    );
    assert!(
        out.contains("u_V^2*y_V: validation NRMSE") && out.contains(": added"),
        "{out}"
    );
    assert!(out.contains("u_V^2*y_V, y_V held at most 10\n"), "{out}");
    let model = std::fs::read_to_string(model_file).unwrap();
    let limits: serde_json::Value = serde_json::from_str(&model).unwrap();
    assert_eq!(
        limits["outputs"][0]["limits"],
        serde_json::json!({"max": 10.0}),
        "{model}"
    );
    assert_simulates_to_the_printed_rms(&out, 1.0);
}

/// `--out` into a folder whose name is not UTF-8: the model file lands in that folder (it was
/// written through a lossy string, to a folder named with U+FFFD).
#[cfg(unix)]
#[test]
fn tanks_writes_its_model_into_a_folder_whose_name_is_not_utf8() {
    use std::os::unix::ffi::OsStrExt;
    if shared_data("cascaded_tanks/cascaded_tanks_estimation.csv").is_none() {
        return;
    }
    let base = std::path::PathBuf::from(temp_file("bench", "y", ""))
        .parent()
        .unwrap()
        .to_path_buf();
    let dir = base.join(std::ffi::OsStr::from_bytes(b"out-\xff"));
    let _ = std::fs::remove_dir_all(&dir);
    let out = common::cli::bin()
        .args(["benchmark", "tanks", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("tanks.model.json").is_file());
    assert!(dir.join("tanks.csv").is_file());
}

#[test]
fn unbalanced_disk_with_gravity_and_friction_beats_its_linear_nominal_and_its_model_file_simulates()
{
    if shared_data("unbalanced_disk/unbalanced_disk_training_val_test.csv").is_none() {
        return;
    }
    let (out, _) = bench("unbalanced-disk");
    // Measured: our linear nominal (order 3: the motor adds a pole) 0.2075 rad on the record's
    // last seventh (207.5 mrad); the rounds add the softening of gravity's sin (theta^3, +426 against the
    // linear -3345: 0.13, sin's 1/6 at order 3), a nonlinear damping, Coulomb friction on the
    // velocity and theta^2 (the disk's offset angle), 0.0397 rad (0.103 before the dictionary
    // had friction on the velocity of an order-3 model), printed in mrad. The published linear
    // 0.255 rad is on a hidden test record of the same setup (a scale only).
    let (ours, nominal, linear, pnarx) = rows(&out)[0];
    assert!(pnarx.is_nan(), "{out}");
    assert!(
        ours < 0.3 * nominal && ours < linear / 4.0,
        "ours {ours}, nominal {nominal}, published linear {linear}\n{out}"
    );
    let last = out.lines().find(|l| l.starts_with("final model:")).unwrap();
    assert!(
        last.contains("theta_rad^3") && last.contains("tanh(theta_rad_d1/"),
        "{out}"
    );
    // The model file simulates the test run to the printed RMS (mrad; the record is in rad).
    assert_simulates_to_the_printed_rms(&out, 1e3);
}

#[test]
fn unknown_benchmarks_and_missing_data_are_one_line_errors() {
    fails(
        &["benchmark", "nope"],
        &["silverbox, emps, tanks, unbalanced-disk"],
    );
    fails(
        &["benchmark", "emps", "--data", "/nonexistent"],
        &["EMPS_train"],
    );
}

/// A record whose rows are out of order (two swapped), or whose time column says another
/// sampling period, is refused by row: the protocols split and score samples by position, and
/// a shuffled file was scored as if it were the benchmark's.
#[test]
fn a_record_out_of_order_or_at_another_rate_is_refused() {
    let Some(est) = shared_data("cascaded_tanks/cascaded_tanks_estimation.csv") else {
        return;
    };
    let text = std::fs::read_to_string(&est).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    let write = |name: &str, lines: &[&str]| tanks_copy("bench-order", name, lines);
    // Rows 101 and 102 of the file (samples 99 and 100) swapped.
    lines.swap(100, 101);
    let swapped = write("swapped", &lines);
    fails(
        &["benchmark", "tanks", "--data", &swapped],
        &["row 101", "column 'k' is 100 where sample 99 was expected"],
    );
    lines.swap(100, 101);
    // The time column at twice the benchmark's 4 s.
    let twice: Vec<String> = lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return l.to_string();
            }
            let mut c: Vec<String> = l.split(',').map(String::from).collect();
            c[1] = format!("{}", 8.0 * (i - 1) as f64);
            c.join(",")
        })
        .collect();
    let twice: Vec<&str> = twice.iter().map(String::as_str).collect();
    let slow = write("slow", &twice);
    fails(
        &["benchmark", "tanks", "--data", &slow],
        &["row 3", "column 't_s' is 8 where k * 4 = 4 was expected"],
    );
}

/// A copy with another number of rows than the published file, or with a missing-value code in
/// it, is refused: a tanks record with `-9999` in one row was fitted (`y_V_d2 = 0`) and scored
/// against the published rows with exit status 0, a cut copy of the EMPS pulses scored 7.86 mm
/// against 5.15 under the same protocol line, and rows appended to a tanks record were left out
/// without a word (the tenth reading, session 18).
#[test]
fn a_cut_extended_or_coded_record_is_refused() {
    let Some(est) = shared_data("cascaded_tanks/cascaded_tanks_estimation.csv") else {
        return;
    };
    let text = std::fs::read_to_string(&est).unwrap();
    let lines: Vec<String> = text.lines().map(String::from).collect();
    let write = |name: &str, lines: &[String]| tanks_copy("bench-whole", name, lines);
    // Row 301 (sample 299): its level replaced by a missing-value code.
    let mut coded = lines.clone();
    let mut cells: Vec<String> = coded[300].split(',').map(String::from).collect();
    let y = lines[0].split(',').position(|c| c == "y_V").unwrap();
    cells[y] = "-9999".into();
    coded[300] = cells.join(",");
    let dir = write("coded", &coded);
    fails(
        &["benchmark", "tanks", "--data", &dir],
        &[
            "row 301, column 'y_V'",
            "-9999",
            "the benchmark's file has none",
        ],
    );
    let dir = write("cut", &lines[..1000]);
    fails(
        &["benchmark", "tanks", "--data", &dir],
        &["999 rows, the benchmark's file has 1024"],
    );
    // Two rows more, continuing the record's time and index.
    let mut longer = lines.clone();
    for k in 1024..1026 {
        longer.push(format!("{k},{},3.0,5.0", 4 * k));
    }
    assert!(lines[0].starts_with("k,t_s,"), "{}", lines[0]);
    let dir = write("longer", &longer);
    fails(
        &["benchmark", "tanks", "--data", &dir],
        &["1026 rows, the benchmark's file has 1024"],
    );
}

/// `--out`'s files are checked before the work: a pipe in the place of `NAME.csv`, or
/// `NAME_test.csv` linked to the record the benchmark reads, failed only after the whole run.
#[test]
fn out_files_are_checked_before_the_work() {
    let Some(est) = shared_data("cascaded_tanks/cascaded_tanks_estimation.csv") else {
        return;
    };
    let root = std::path::Path::new(&temp_file("bench-outfiles", "x", ""))
        .parent()
        .unwrap()
        .to_path_buf();
    let piped = root.join("piped");
    std::fs::create_dir_all(&piped).unwrap();
    let fifo = piped.join("tanks.csv");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        refused_before_the_work(&piped, &["tanks.csv", "not a regular file"]);
    }
    let before = std::fs::read(&est).unwrap();
    let linked = root.join("linked");
    std::fs::create_dir_all(&linked).unwrap();
    let link = linked.join("tanks_test.csv");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&est, &link).unwrap();
    refused_before_the_work(
        &linked,
        &["tanks_test.csv", "a record this benchmark reads"],
    );
    assert_eq!(std::fs::read(&est).unwrap(), before);
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
}

/// `ctsid benchmark tanks --out DIR` fails with `needles` before printing anything.
fn refused_before_the_work(dir: &std::path::Path, needles: &[&str]) {
    let out = fails(
        &["benchmark", "tanks", "--out", &dir.display().to_string()],
        needles,
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.is_empty(), "{stdout}");
}

/// A data folder `TAG/NAME` holding the tanks' test record and `lines` as the estimation record
/// (a damaged copy); its path for `--data`.
fn tanks_copy<S: AsRef<str>>(tag: &str, name: &str, lines: &[S]) -> String {
    let root = std::path::Path::new(&temp_file(tag, "x", ""))
        .parent()
        .unwrap()
        .join(name);
    let dir = root.join("cascaded_tanks");
    std::fs::create_dir_all(&dir).unwrap();
    let text: Vec<&str> = lines.iter().map(AsRef::as_ref).collect();
    std::fs::write(dir.join("cascaded_tanks_estimation.csv"), text.join("\n")).unwrap();
    let test = shared_data("cascaded_tanks/cascaded_tanks_test.csv").unwrap();
    std::fs::copy(test, dir.join("cascaded_tanks_test.csv")).unwrap();
    root.display().to_string()
}
