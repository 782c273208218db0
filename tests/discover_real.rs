//! `discover` on measured benchmark records (../shared/data; skipped with a notice when absent).

use ctsid::discover::benchmarks::{emps, rms_after, silverbox};
use ctsid::discover::discover;

fn shared(rel: &str) -> Option<String> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if p.exists() {
        Some(p.to_string_lossy().into_owned())
    } else {
        eprintln!(
            "skipped: {} not found (the shared benchmark data is absent)",
            p.display()
        );
        None
    }
}

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
        before > 0.010 && after < 0.0015,
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
}
