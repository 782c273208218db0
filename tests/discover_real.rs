//! `discover` on measured benchmark records (../shared/data; skipped with a notice when absent).

mod common;

use common::cli::ctsid;
use common::shared_data as shared;
use ctsid::discover::benchmarks::{emps, rms_after, silverbox};
use ctsid::discover::discover;

#[test]
fn silverbox_names_cubic_stiffness_and_the_arrow_error_drops_toward_1_mv() {
    let Some(path) = shared("silverbox/SNLS80mV.csv") else {
        return;
    };
    let s = silverbox(&path).unwrap();
    let d = discover(&s.records, &s.nominal, &s.options).unwrap();
    assert_eq!(d.verdict, "added", "{}", d.text());
    assert_eq!(d.effects[0].family, "cubic_stiffness", "{}", d.text());
    let arrow = &d.test_runs[0];
    let before = rms_after(d.nominal_model.as_ref().unwrap(), arrow, s.init_samples);
    let after = rms_after(d.final_model.as_ref().unwrap(), arrow, s.init_samples);
    // Measured: 14.2 mV -> 0.93 mV.
    assert!(
        before > 0.012 && after < 0.00115,
        "{before} -> {after}\n{}",
        d.text()
    );
}

#[test]
fn emps_names_coulomb_friction_near_the_published_force() {
    let Some(dir) = shared("emps") else {
        return;
    };
    let s = emps(&dir).unwrap();
    let d = discover(&s.records, &s.nominal, &s.options).unwrap();
    let e = d
        .effects
        .iter()
        .find(|e| e.family == "coulomb_friction")
        .unwrap_or_else(|| panic!("{}", d.text()));
    // Force = coefficient / nominal input gain (1 / M); published 20.39 N.
    let force = -e.coefficient * 95.1089;
    assert!(
        (force - 20.39).abs() / 20.39 < 0.1,
        "{force} N\n{}",
        d.text()
    );
    let test = &d.test_runs[0];
    let before = rms_after(d.nominal_model.as_ref().unwrap(), test, s.init_samples);
    let after = rms_after(d.final_model.as_ref().unwrap(), test, s.init_samples);
    assert!(after < 0.2 * before, "{before} -> {after}");

    // The augmented model file, friction included, simulates on the pulses record with
    // `ctsid simulate` at the RMS the discovery reports for that run (one initial-state
    // convention for both).
    let model = common::cli::temp_file("emps", "augmented.json", "");
    d.augmented_model(&s.nominal)
        .unwrap()
        .write(&model)
        .unwrap();
    let pulses = format!("{dir}/EMPS_test_DATA_EMPS_PULSES.csv");
    let (ok, out, err) = ctsid(&["simulate", &model, &pulses, "--tau 0.001"]);
    assert!(ok, "{err}");
    let cli_rms: f64 = out
        .lines()
        .find(|l| l.starts_with("all"))
        .and_then(|l| l.split_whitespace().nth(2))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no 'all' row in:\n{out}"));
    let reported = d
        .runs
        .iter()
        .find(|r| r.run == "pulses")
        .and_then(|r| r.rms_final)
        .unwrap();
    eprintln!("EMPS pulses: discover reports RMS {reported:.6e} m, simulate {cli_rms:.6e} m");
    assert!(
        (cli_rms - reported).abs() <= 1e-6 * reported,
        "simulate {cli_rms} vs discover's report {reported}"
    );
}

/// `identify` with Coulomb friction as a named term, on the estimation record cut into six
/// runs (four train, two validation) and the pulses record as the test run, in one file as a
/// user would make it: a model of at most six terms, test RMS below 8 mm (issue 17).
#[test]
fn emps_identify_with_a_sign_term_is_small_and_simulates_the_pulses_record() {
    let Some(dir) = shared("emps") else {
        return;
    };
    let read = |f: &str| -> Vec<(String, String)> {
        let text = std::fs::read_to_string(format!("{dir}/{f}")).unwrap();
        let mut lines = text.lines();
        let head: Vec<&str> = lines.next().unwrap().split(',').collect();
        let (q, f) = (
            head.iter().position(|h| *h == "q_m").unwrap(),
            head.iter().position(|h| *h == "force_N").unwrap(),
        );
        lines
            .map(|l| {
                let v: Vec<&str> = l.split(',').collect();
                (v[q].to_string(), v[f].to_string())
            })
            .collect()
    };
    let est = read("EMPS_train_DATA_EMPS.csv");
    let chunk = est.len() / 6;
    let mut text = String::from("run,q_m,force_N\n");
    for (k, part) in est.chunks(chunk).take(6).enumerate() {
        for (q, f) in part {
            text += &format!("est{k},{q},{f}\n");
        }
    }
    for (q, f) in read("EMPS_test_DATA_EMPS_PULSES.csv") {
        text += &format!("pulses,{q},{f}\n");
    }
    let data = common::cli::temp_file("emps-id", "emps.csv", &text);
    let model = common::cli::temp_file("emps-id", "model.json", "");
    let (ok, out, err) = ctsid(&[
        "identify",
        &data,
        "--output q_m --input force_N --run-column run --tau 0.001 --order 2 --degree 1 --quiet",
        "--term",
        "sign(q_m_d1)",
        "--train est0,est1,est2,est3 --validation est4,est5 --test pulses -o",
        &model,
    ]);
    assert!(ok, "{err}");
    let m = ctsid::model::Model::read(&model).unwrap();
    let terms = &m.outputs[0].terms;
    assert!(terms.len() <= 6, "{} terms:\n{out}", terms.len());
    assert!(
        terms
            .iter()
            .any(|t| t.expression.as_deref() == Some("sign(q_m_d1)")),
        "{out}"
    );
    let rms: f64 = out
        .lines()
        .find(|l| l.starts_with("| pulses | q_m |"))
        .and_then(|l| l.split('|').nth(3))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no pulses row in:\n{out}"));
    // Measured 7.94 mm.
    eprintln!(
        "EMPS identify --term sign(q_m_d1): {} terms, test RMS {rms:.4e} m\n{m}",
        terms.len()
    );
    assert!(rms < 8e-3, "test RMS {rms} m\n{out}");
}

/// The unbalanced disk is one 875 s record: `--segment 125` cuts it into seven runs (identify
/// trains on all with 5 folds; discover's default split trains on 0-2, validates on 3-4 and tests
/// on 5-6). Its simulator (said to match the setup) has gravity -w0^2 sin(theta + delta), whose
/// cubic term is +w0^2/6 = 21 at w0 = 11.34 rad/s, and Coulomb friction -6.06 tanh(theta'/0.001).
#[test]
fn unbalanced_disk_cut_into_pieces_names_coulomb_friction_and_the_gravity_cubic() {
    let Some(path) = shared("unbalanced_disk/unbalanced_disk_training_val_test.csv") else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("ctsid-disk-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = dir.join("nominal.json").display().to_string();
    let report = dir.join("report").display().to_string();
    let pieces = "--time-column t_s --segment 125";
    let (ok, _, err) = ctsid(&[
        "identify",
        &path,
        "--output theta_rad --input u_V --order 2 --degree 1 --quiet",
        pieces,
        "-o",
        &nominal,
    ]);
    assert!(ok, "{err}");
    let (ok, out, err) = ctsid(&[
        "discover",
        &path,
        "--nominal",
        &nominal,
        pieces,
        "--report",
        &report,
    ]);
    assert!(ok, "{err}");
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report/discovery.json")).unwrap())
            .unwrap();
    assert_eq!(d["verdict"], "added", "{out}");
    let effect = |family: &str| {
        d["effects"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["family"] == family)
            .unwrap_or_else(|| panic!("no {family}:\n{out}"))
            .clone()
    };
    // Measured: -5.16 (weak form -5.99) against the simulator's -6.06; cubic +16.7 (weak 15.2)
    // against +21 from sin (the in-house check in the data's README found +13).
    let coulomb = effect("coulomb_friction")["coefficient"].as_f64().unwrap();
    assert!((-7.5..=-4.5).contains(&coulomb), "{coulomb}\n{out}");
    let cubic = effect("cubic_stiffness")["coefficient"].as_f64().unwrap();
    assert!((10.0..=30.0).contains(&cubic), "{cubic}\n{out}");
    // Measured: mean test free-run NRMSE 0.422 -> 0.318.
    let (before, after) = (
        d["nrmse_before"].as_f64().unwrap(),
        d["nrmse_after"].as_f64().unwrap(),
    );
    assert!(after < 0.85 * before, "{before} -> {after}\n{out}");
    std::fs::remove_dir_all(&dir).ok();
}
