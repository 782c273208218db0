//! Reference tracking (`ctsid::control::track`, `ctsid control --law profile --reference`): the
//! source paper's exponential-profile law for orders 1 to 4 on known linear and nonlinear
//! plants (one not affine in its input), blocking, saturation, and bad settings.

mod common;

use common::cli::{ctsid, fails, temp_file};
use ctsid::control::{self, DesignOptions, Law, Plant, ProfileLaw, Reference, Scenario, Tracking};
use ctsid::model::{derivative_name, CompiledModel, Model, OutputEquation, Term};

/// `y^(n) = -sum_k C(n, k) y^(k) + u + extra`: every pole at -1, gain 1.
fn chain(n: usize, extra: Vec<Term>) -> Model {
    let mut terms = Vec::new();
    let mut binom = 1.0;
    for k in 0..n {
        let name = derivative_name("y", k);
        terms.push(Term::new(&[(name.as_str(), 1)], -binom));
        binom = binom * (n - k) as f64 / (k + 1) as f64;
    }
    terms.push(Term::new(&[("u", 1)], 1.0));
    terms.extend(extra);
    Model::new(&["u"], vec![OutputEquation::new("y", n, terms)], Some(0.01))
}

struct Run {
    trace: control::Trace,
    metrics: control::TrackingMetrics,
}

/// The design at 1.0 on `model` and the model at rest at 0: a loop around the model itself.
fn around_itself(model: &Model) -> (control::Design, CompiledModel, Vec<f64>, f64) {
    let d = control::design(model, &DesignOptions::new(1.0, 0.01)).unwrap();
    let (c, x0, u0) = control::model_at_rest(model, 0.0, 0.0).unwrap();
    (d, c, x0, u0)
}

fn scenario(duration: f64, limits: Option<(f64, f64)>) -> Scenario {
    Scenario {
        duration,
        noise_sd: 0.0,
        seed: 0,
        u_limits: limits,
    }
}

/// The model around itself following `tk`.
fn try_track(
    model: &Model,
    tk: &Tracking,
    limits: Option<(f64, f64)>,
    duration: f64,
) -> ctsid::Result<control::Trace> {
    let (d, c, x0, u0) = around_itself(model);
    let plant = Plant {
        system: &c,
        output: 0,
        x0,
        u0,
    };
    control::track(&d, &plant, &scenario(duration, limits), tk)
}

/// The model around itself, from rest at 0, following `reference` with `law`.
fn track(
    model: &Model,
    reference: Reference,
    law: Law,
    block: usize,
    limits: Option<(f64, f64)>,
    duration: f64,
) -> Run {
    let tk = Tracking {
        reference: reference.clone(),
        law,
        block,
    };
    let trace = try_track(model, &tk, limits, duration).unwrap();
    let metrics = control::tracking_metrics(&trace.t, &trace.y, &trace.u, &reference, limits);
    Run { trace, metrics }
}

fn profile(sigma: f64) -> Law {
    Law::Profile(ProfileLaw { sigma })
}

/// The last output sample.
fn last(r: &Run) -> f64 {
    *r.trace.y.last().unwrap()
}

#[test]
fn the_profile_law_follows_a_step_with_the_profile_dynamics_for_orders_1_to_4() {
    for n in 1..=4 {
        let r = track(
            &chain(n, vec![]),
            Reference::constant(1.0),
            profile(2.0),
            1,
            None,
            12.0,
        );
        // The closed loop is the profile itself: poles at -2, -4, ..., -2n, real: no overshoot,
        // and settled long before 12 s.
        assert!(
            (last(&r) - 1.0).abs() < 1e-3,
            "order {n}: ends at {}",
            last(&r)
        );
        assert!(
            r.metrics.overshoot < 0.5,
            "order {n}: overshoot {}",
            r.metrics.overshoot
        );
        // A first-order profile at rate 2 reaches 98 % in ln(50) / 2 = 1.96 s; higher orders
        // add faster modes only.
        assert!(
            r.metrics.settling_time < 3.5,
            "order {n}: settling {}",
            r.metrics.settling_time
        );
    }
}

#[test]
fn the_profile_law_follows_ramps_without_lag_on_a_nonlinear_plant() {
    // y'' = -y - 2 y' - 0.5 y^3 + u: affine in u, nonlinear in y.
    let m = chain(2, vec![Term::new(&[("y", 3)], -0.5)]);
    let r = track(
        &m,
        Reference::steps_and_ramps(0.0, 1.0, 10.0).unwrap(),
        profile(3.0),
        1,
        None,
        10.0,
    );
    // The profile carries the ramp's slope: the error on ramps is the transient of the steps'
    // corners only.
    assert!(r.metrics.rms_ramps < 0.02, "{:?}", r.metrics);
    assert!(r.metrics.overshoot < 1.0, "{:?}", r.metrics);
    // The same scenario under the pole placement (one linearisation at 1.0) is slower.
    let p = track(
        &m,
        Reference::steps_and_ramps(0.0, 1.0, 10.0).unwrap(),
        Law::PolePlacement,
        1,
        None,
        10.0,
    );
    assert!(p.metrics.rms.is_finite());
}

#[test]
fn a_plant_not_affine_in_its_input_is_solved_by_the_bounded_search() {
    // y' = -y + u + 0.5 u^3: the law's argmin is a root of a cubic in u.
    let m = chain(1, vec![Term::new(&[("u", 3)], 0.5)]);
    let r = track(
        &m,
        Reference::constant(1.0),
        profile(2.0),
        1,
        Some((-3.0, 3.0)),
        6.0,
    );
    assert!((last(&r) - 1.0).abs() < 1e-3, "ends at {}", last(&r));
    // y = 1 at rest needs u + 0.5 u^3 = 1: u = 0.7709.
    let u = *r.trace.u.last().unwrap();
    assert!((u - 0.770_916_997).abs() < 1e-4, "{u}");
    // Without limits the search has no range: a one-line error that says what to give.
    let tk = Tracking {
        reference: Reference::constant(1.0),
        law: profile(2.0),
        block: 1,
    };
    let e = try_track(&m, &tk, None, 1.0).unwrap_err().to_string();
    assert!(e.contains("--u-min") && !e.contains('\n'), "{e}");
}

#[test]
fn blocking_holds_the_input_and_saturation_clips_it() {
    let m = chain(3, vec![]);
    let block = 3;
    let r = track(
        &m,
        Reference::steps_and_ramps(0.0, 1.0, 10.0).unwrap(),
        profile(2.0),
        block,
        Some((-0.8, 1.6)),
        10.0,
    );
    for (k, w) in r.trace.u.windows(2).enumerate() {
        if (k + 1) % block != 0 {
            assert_eq!(
                w[0],
                w[1],
                "input changed inside a block at sample {}",
                k + 1
            );
        }
    }
    assert!(r.trace.u.iter().all(|u| (-0.8..=1.6).contains(u)));
    // The steps ask for more than 1.6 at once: the input sits on a limit for a while.
    assert!(r.metrics.saturated > 0, "{:?}", r.metrics);
    assert!((last(&r) - 0.0).abs() < 0.1, "ends at {}", last(&r));
}

#[test]
fn the_placement_law_with_a_constant_reference_is_the_step_run() {
    let (d, c, x0, u0) = around_itself(&chain(2, vec![]));
    let plant = Plant {
        system: &c,
        output: 0,
        x0,
        u0,
    };
    let s = scenario(3.0, None);
    let a = control::run(&d, &plant, &s).unwrap();
    let b = control::track(&d, &plant, &s, &Tracking::step(1.0)).unwrap();
    assert_eq!(a.y, b.y);
    assert_eq!(a.u, b.u);
}

#[test]
fn bad_tracking_settings_are_one_line_errors() {
    let model = std::env::temp_dir().join(format!("ctsid-tracking-{}.json", std::process::id()));
    chain(2, vec![]).write(&model).unwrap();
    let m = model.to_str().unwrap();
    let gap = temp_file("tracking", "gap.csv", "t,r\n0,0\n1,\n2,1\n");
    let nan = temp_file("tracking", "nan.csv", "t,r\n0,0\n1,nan\n");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--block", "0"], "block"),
        // Decided once at the start and held for the whole run (was a run of zeros, exit 0).
        (vec!["--block", "1000000"], "decided once"),
        (vec!["--law", "profile", "--sigma", "0"], "sigma"),
        (vec!["--law", "profile", "--sigma", "-1"], "sigma"),
        (
            vec!["--law", "profile", "--u-min", "1", "--u-max", "1"],
            "u-min",
        ),
        (vec!["--reference", gap.as_str()], "gap"),
        (vec!["--reference", nan.as_str()], "line 3"),
        (vec!["--sigma", "2"], "--law profile"),
    ];
    for (extra, says) in cases {
        let mut args = vec![
            "control",
            m,
            "--setpoint",
            "1",
            "--from",
            "0",
            "--tau",
            "0.01",
        ];
        args.extend(extra.iter().copied());
        fails(&args, &[says]);
    }
    // A working run of the built-in scenario prints the tracking figures.
    let (ok, out, err) = ctsid(&[
        "control",
        m,
        "--setpoint",
        "1",
        "--from",
        "0",
        "--law",
        "profile",
        "--sigma",
        "2",
        "--reference",
        "steps",
        "--block",
        "3",
        "--observer",
        "chain",
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("tracking RMS") && out.contains("per decision"),
        "{out}"
    );
    // The profile law's design: its rates and the observer it takes from the placement, not the
    // placement's controller poles and gains, which it does not use.
    assert!(
        out.contains("law: exponential profile, rates 2 .. 4 1/s"),
        "{out}"
    );
    assert!(
        out.contains("observer poles (the design's at bandwidth"),
        "{out}"
    );
    assert!(
        !out.contains("controller poles") && !out.contains("gains: u = u*"),
        "{out}"
    );
    std::fs::remove_file(&model).ok();
}
