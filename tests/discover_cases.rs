//! `discover` on generated cases (one seed each, to keep CI time modest; the 10-seed matrix is
//! `cargo bench --bench discover_acceptance`).

use ctsid::discover::cases::{generate, generate_scaled, judge, options, split, Judgement};
use ctsid::discover::{discover, Discovery, Options};

/// Case `name` for `seed` at noise `eta`, excitation scaled by `scale`, run with the standard
/// options: the judgement and the discovery.
fn run_case(name: &str, seed: u64, eta: f64, scale: f64) -> (Judgement, Discovery) {
    let case = generate_scaled(name, seed, eta, scale).unwrap();
    let d = discover(&case.records, &case.nominal, &options(&case, seed)).unwrap();
    (judge(&case, &d), d)
}

fn run(name: &str, seed: u64) -> (bool, String, Discovery) {
    let (j, d) = run_case(name, seed, 0.03, 1.0);
    (j.pass, j.why, d)
}

/// Asserts that some effect was left out with `reason` in its report line.
fn assert_dropped(d: &Discovery, reason: &str) {
    assert!(
        d.dropped.iter().any(|s| s.contains(reason)),
        "no effect left out for '{reason}'\n{}",
        d.text()
    );
}

/// A tank driven harder than the standard case: its level swings near empty.
const DRIVEN_TANK: f64 = 1.0 / 0.6;

#[test]
fn coulomb_friction_is_named_with_its_coefficient_and_the_error_shrinks() {
    let (ok, why, d) = run("coulomb", 0);
    assert!(ok, "{why}\n{}", d.text());
    assert!(d.nrmse_before / d.nrmse_after > 3.0, "{}", d.text());
    let e = &d.effects[0];
    assert!(e.interval[1] < 0.0, "{}", d.text());
    // Its report says how constant it is over time: both halves of the runs agree.
    assert!(e.halves_z.is_finite() && e.halves_z < 3.5, "{}", d.text());
    assert!(
        e.halves
            .iter()
            .all(|c| (c / e.coefficient - 1.0).abs() < 0.2),
        "{}",
        d.text()
    );
}

#[test]
fn cubic_stiffness_and_quadratic_drag_are_named_with_their_coefficients() {
    for name in ["duffing", "quadratic_drag"] {
        let (ok, why, d) = run(name, 1);
        assert!(ok, "{name}: {why}\n{}", d.text());
    }
}

/// Asserts that `family` alone was added, its coefficient within 10 % of `coef`, and the
/// held-out error shrank at least 3x (the acceptance rule for one seed).
fn assert_added(d: &Discovery, family: &str, coef: f64) {
    assert_eq!(d.verdict, "added", "{}", d.text());
    let named: Vec<&str> = d.effects.iter().map(|e| e.family.as_str()).collect();
    assert_eq!(named, [family], "{}", d.text());
    let c = d.effects[0].coefficient;
    assert!(
        (c / coef - 1.0).abs() <= 0.1,
        "{family}: {c} vs {coef}\n{}",
        d.text()
    );
    assert!(d.nrmse_before / d.nrmse_after > 3.0, "{}", d.text());
}

#[test]
fn friction_is_not_confused_with_an_input_relay() {
    let (ok, why, d) = run("distractor_relay", 2);
    assert!(ok, "{why}\n{}", d.text());
    assert_added(&d, "coulomb_friction", -0.5);
}

#[test]
fn negative_control_adds_nothing() {
    let (ok, why, d) = run("negative_none", 0);
    assert!(ok, "{why}\n{}", d.text());
    assert_eq!(d.verdict, "none");
}

#[test]
fn mistuned_damping_is_retuned_not_disguised() {
    let (ok, why, d) = run("mistuned", 0);
    assert!(ok, "{why}\n{}", d.text());
    // A 23 % correction is within three times the default +-20 % confidence: not flagged.
    assert!(
        d.retuned.iter().all(|r| !r.outside_confidence),
        "{}",
        d.text()
    );
}

#[test]
fn quadratic_drag_is_never_named_as_cubic_damping_alone() {
    let (ok, why, d) = run("distractor_v3", 0);
    assert!(ok, "{why}\n{}", d.text());
    assert_added(&d, "quadratic_drag", -0.8);
}

#[test]
fn augmented_model_file_is_valid_and_carries_the_discovery() {
    let case = generate("duffing", 0, 0.03).unwrap();
    let (tr, va, te) = split();
    let d = discover(
        &case.records,
        &case.nominal,
        &Options::new(tr.clone(), va.clone(), te.clone()),
    )
    .unwrap();
    let m = d.augmented_model(&case.nominal).unwrap();
    let text = m.to_json_string().unwrap();
    let back = ctsid::model::Model::from_json_str(&text, "augmented").unwrap();
    let disc = back.extra.get("discovery").unwrap();
    assert_eq!(disc["verdict"], "added");
    assert_eq!(disc["effects"][0]["family"], "cubic_stiffness");
    assert!(disc["nrmse_after"].as_f64().unwrap() < disc["nrmse_before"].as_f64().unwrap());
    // The cubic term is in the right-hand side itself, so the file simulates the discovery.
    let cubic = back.outputs[0]
        .terms
        .iter()
        .find(|t| t.monomial() == "y^3")
        .expect("no y^3 term in the file");
    assert!((cubic.coefficient - d.effects[0].coefficient).abs() < 1e-12);
    // Coulomb friction has no polynomial form: it is an expression term with its origin, and
    // the file simulates the final model exactly (same test-run NRMSE as the discovery's).
    let case = generate("coulomb", 0, 0.03).unwrap();
    let d = discover(&case.records, &case.nominal, &Options::new(tr, va, te)).unwrap();
    assert_eq!(d.verdict, "added");
    let m = d.augmented_model(&case.nominal).unwrap();
    let back = ctsid::model::Model::from_json_str(&m.to_json_string().unwrap(), "aug").unwrap();
    let t = back.outputs[0]
        .terms
        .iter()
        .find(|t| t.origin == Some(ctsid::model::Origin::Effect("coulomb_friction".into())))
        .expect("no coulomb_friction term in the file");
    assert!(t.expression.is_some() && t.std_error.is_some(), "{t:?}");
    // Refined on simulation error, the coefficient is no longer the weak-form estimate the
    // bootstrap interval belongs to (one once sat outside "its" interval): the term has none,
    // the discovery section keeps the estimate and its interval.
    let e = &d.effects[0];
    assert!(
        t.coefficient != e.weak_coefficient && t.interval.is_none(),
        "{t:?} {e:?}"
    );
    let section = &back.extra["discovery"]["effects"][0];
    assert_eq!(section["weak_coefficient"], e.weak_coefficient);
    assert_eq!(section["interval"][0], e.interval[0]);
    assert_eq!(
        &back,
        d.final_model
            .as_ref()
            .map(|f| {
                let mut f = f.clone();
                f.extra = back.extra.clone();
                f.outputs[0]
                    .terms
                    .iter_mut()
                    .zip(&back.outputs[0].terms)
                    .for_each(|(a, b)| a.interval = b.interval);
                f
            })
            .as_ref()
            .unwrap()
    );
}

#[test]
fn bad_inputs_are_typed_errors() {
    let case = generate("coulomb", 0, 0.03).unwrap();
    let mut o = Options::new(vec![0], vec![], vec![1]);
    assert!(discover(&case.records, &case.nominal, &o).is_err());
    o = Options::new(vec![0], vec![1], vec![2]);
    o.confidence.insert("y^7".into(), 0.1);
    assert!(discover(&case.records, &case.nominal, &o).is_err());
    o.confidence.clear();
    o.user_effects.push(("bad".into(), "sign(q)".into()));
    assert!(discover(&case.records, &case.nominal, &o).is_err());
    assert!(generate("nope", 0, 0.03).is_err());
}

/// The tank: the forward selection adds the outflow law and then a bump near the empty tank;
/// the bump fails its own gates (bootstrap inclusion) and is left out, the outflow is named
/// alone with its coefficient, the linearised terms fall away, and the free-run error against
/// the plant's noise-free output shrinks many times (against the measurement the 3 % noise
/// floor caps it).
#[test]
fn tank_outflow_is_named_alone_when_a_second_effect_fails_its_gates() {
    let (j, d) = run_case("tank", 1, 0.03, 1.0);
    assert!(j.pass, "{}\n{}", j.why, d.text());
    assert!(!d.dropped.is_empty(), "{}", d.text());
    assert_dropped(&d, "inclusion");
    assert!(j.truth_ratio > 5.0, "{}", d.text());
}

/// A tank driven harder (level swings near empty): the regression also takes a friction-like
/// bump in the level that passes the bootstrap gates; refitted without it the model simulates
/// the validation runs just as well, so it is left out and the outflow law is named alone.
#[test]
fn tank_bump_that_does_not_help_simulation_is_left_out() {
    let (j, d) = run_case("tank", 3, 0.03, DRIVEN_TANK);
    assert!(j.pass, "{}\n{}", j.why, d.text());
    assert_dropped(&d, "in simulation it");
}

/// At 10 % noise the forward selection takes a Stribeck hump beside the Coulomb law; it is
/// borderline on several gates (bootstrap inclusion, and refined on simulation error its
/// coefficient once took the sign its interval excludes) and must be left out: only Coulomb
/// friction is named.
#[test]
fn stribeck_hump_beside_coulomb_at_high_noise_is_left_out() {
    let (_, d) = run_case("coulomb", 5, 0.10, 1.0);
    let named: Vec<&str> = d.effects.iter().map(|e| e.family.as_str()).collect();
    assert_eq!(named, vec!["coulomb_friction"], "{}", d.text());
    assert!(
        d.dropped.iter().any(|s| s.starts_with("stribeck")),
        "{}",
        d.text()
    );
}

/// A slow sensor drift (a ramp in the measured y) at 1 % noise: an offset force fits the residual
/// and would pass the other gates, but its coefficient on the first
/// half of the runs differs from the second by several standard deviations: nothing is added.
#[test]
fn sensor_drift_at_low_noise_is_not_named_an_offset() {
    let (j, d) = run_case("negative_drift", 0, 0.01, 1.0);
    assert!(j.pass, "{}\n{}", j.why, d.text());
    assert!(
        d.closest
            .as_deref()
            .is_some_and(|c| c.contains("not constant in time")),
        "{}",
        d.text()
    );
}

/// The same driven tank, seed 0: a friction-like bump beside the outflow law fails its own
/// gates and is left out; the outflow law is named alone. (With the smoother tuned on every run
/// the bump passed its bootstrap and was left out as not constant in time, 0.97 on the first
/// half of each training run and 0.31 on the second; tuned on the training runs alone it is
/// included in 77 % of the refits and goes at the first gate. The drift gate itself is judged
/// by `sensor_drift_at_low_noise_is_not_named_an_offset` above.)
#[test]
fn a_second_effect_that_fails_its_gates_is_left_out_beside_the_outflow_law() {
    let (j, d) = run_case("tank", 0, 0.03, DRIVEN_TANK);
    assert!(j.pass, "{}\n{}", j.why, d.text());
    assert_dropped(&d, "coulomb_friction");
}

#[test]
fn a_user_effect_the_data_cannot_carry_is_an_error_not_a_silent_omission() {
    let case = generate("duffing", 0, 0.03).unwrap();
    let base = options(&case, 0);
    for (name, expr, needle) in [
        ("", "y^2", "has no name"),
        ("cubic_stiffness", "y^3", "built-in"),
        ("cube", "y^3", "already in the dictionary"),
        // A multiple of a dictionary or nominal monomial (was kept, then vanished unnamed).
        ("cube2", "2*y^3", "already in the dictionary"),
        ("stiff", "-y", "a term of the nominal model"),
        ("root", "sqrt(y)", "not finite"),
        ("kink", "relu(y-100)", "constant on the training data"),
    ] {
        let mut o = base.clone();
        o.user_effects = vec![(name.into(), expr.into())];
        let e = discover(&case.records, &case.nominal, &o)
            .err()
            .unwrap_or_else(|| panic!("'{name}={expr}' was accepted"))
            .to_string();
        assert!(e.contains(needle), "'{name}={expr}': {e}");
    }
    // A user effect the data do carry is a candidate like any other, one that switches only
    // now and then (a step at y = 0.3) included.
    for (name, expr) in [
        ("dead_zone", "relu(abs(y)-0.1)*sign(y)"),
        ("step", "sign(y-0.3)"),
    ] {
        let mut o = base.clone();
        o.user_effects = vec![(name.into(), expr.into())];
        discover(&case.records, &case.nominal, &o).unwrap();
    }
}

#[test]
fn a_nominal_that_diverges_on_every_run_is_refused() {
    // It used to give verdict "retune" with NRMSE inf and 200-digit percentages.
    let mut case = generate("duffing", 0, 0.03).unwrap();
    for t in case.nominal.outputs[0].terms.iter_mut() {
        t.coefficient = t.coefficient.abs() * 1e3;
    }
    let e = discover(&case.records, &case.nominal, &options(&case, 0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("diverges in free run on every run"), "{e}");
}

#[test]
fn without_test_runs_nothing_is_scored_on_them_and_refused_candidates_are_offered() {
    // The negative control: nothing to add, so every candidate the gates refused comes back as
    // the nominal plus that one effect (what `ctsid benchmark`'s second look refits).
    let case = generate("negative_none", 0, 0.03).unwrap();
    let mut o = options(&case, 0);
    o.test.clear();
    let d = discover(&case.records, &case.nominal, &o).unwrap();
    assert!(d.nrmse_before.is_nan() && d.nrmse_after.is_nan());
    assert!(!d.text().contains("test runs:"), "{}", d.text());
    assert_eq!(d.verdict, "none", "{}", d.text());
    // Nothing added: the final scores are the nominal's, reused.
    assert!(d
        .runs
        .iter()
        .all(|r| r.nrmse_final == Some(r.nrmse_nominal)));
    assert!(!d.refused.is_empty(), "{}", d.text());
    let nominal = &case.nominal.outputs[0].terms;
    for r in &d.refused {
        let terms = &r.model.outputs[0].terms;
        assert_eq!(terms.len(), nominal.len() + 1);
        for (a, b) in terms.iter().zip(nominal) {
            assert_eq!(a.monomial(), b.monomial());
        }
        let last = terms.last().unwrap();
        assert!(
            matches!(last.origin, Some(ctsid::model::Origin::Effect(_))),
            "{:?}",
            last.origin
        );
        assert!(last.coefficient.is_finite() && last.coefficient != 0.0);
    }
}
