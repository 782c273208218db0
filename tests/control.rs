//! Feedback design on a model (`ctsid::control`, `ctsid control`): gains against hand-derived
//! values, the loop against its designed response, a design on a wrong model run around the true
//! throttle, and bad input.

mod common;

use common::cli::{ctsid, fails, temp_file};
use ctsid::control::{self, DesignOptions, Plant, Scenario};
use ctsid::model::{Model, OutputEquation, Term};
use ctsid::plants::{Plant as BuiltIn, ThrottlePreset};

/// `y'' = -4 y - 0.4 y' + 2 u`: open-loop poles -0.2 +- 1.99i.
fn oscillator() -> Model {
    Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            2,
            vec![
                Term::new(&[("y", 1)], -4.0),
                Term::new(&[("y_d1", 1)], -0.4),
                Term::new(&[("u", 1)], 2.0),
            ],
        )],
        Some(0.01),
    )
}

#[test]
fn gains_match_the_hand_derived_placement() {
    let mut o = DesignOptions::new(1.0, 0.01);
    o.bandwidth = Some(3.0);
    let d = control::design(&oscillator(), &o).unwrap();
    assert!((d.u_star - 2.0).abs() < 1e-12, "{}", d.u_star);
    // Both open-loop poles (|l| = 2.01) and the integrator go to -3:
    // s^3 + (0.4 + 2 k2) s^2 + (4 + 2 k1) s + 2 ki = (s + 3)^3.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs();
    assert!(
        close(d.k[0], 11.5) && close(d.k[1], 4.3) && close(d.k_i, 13.5),
        "{d:?}"
    );
    // Observer at -9 twice: s^2 + (l1 + 0.4) s + (4 + 0.4 l1 + l2) = (s + 9)^2.
    assert!(close(d.l[0], 17.6) && close(d.l[1], 69.96), "{:?}", d.l);
    // A triple pole: the eigenvalue solver resolves it to about eps^(1/3).
    assert_eq!(d.closed_loop.len(), 3, "{:?}", d.closed_loop);
    for (r, i) in &d.closed_loop {
        assert!(
            (r + 3.0).abs() < 1e-3 && i.abs() < 1e-3,
            "{:?}",
            d.closed_loop
        );
    }
}

#[test]
fn the_chain_observer_reports_its_own_poles() {
    let mut o = DesignOptions::new(1.0, 0.01);
    o.bandwidth = Some(3.0);
    let d = control::design(&oscillator(), &o).unwrap();
    let c = control::with_chain_observer(d.clone()).unwrap();
    // Gains of a pure chain with both poles at -9: (18, 81); on the oscillator the error poles
    // are those of s^2 + (l1 + 0.4) s + (4 + 0.4 l1 + l2) = s^2 + 18.4 s + 92.2.
    assert_eq!(c.l, vec![18.0, 81.0]);
    let sum: f64 = c.observer.iter().map(|p| p.0).sum();
    let prod = (c.observer[0].0 * c.observer[1].0 - c.observer[0].1 * c.observer[1].1).abs();
    assert!(
        (sum + 18.4).abs() < 1e-9 && (prod - 92.2).abs() < 1e-9,
        "{:?}",
        c.observer
    );
    // The linearised observer's poles (-9 twice) were printed for the chain observer before.
    assert!(c.observer != d.observer);
    assert_eq!((c.k.clone(), c.k_i), (d.k.clone(), d.k_i));
}

/// The oscillator's design for a setpoint of 1.0 at bandwidth `w`, sampled at 0.01 s.
fn oscillator_design(w: f64) -> control::Design {
    let mut o = DesignOptions::new(1.0, 0.01);
    o.bandwidth = Some(w);
    control::design(&oscillator(), &o).unwrap()
}

/// Five noise-free seconds, the input unlimited.
fn five_quiet_seconds() -> Scenario {
    Scenario {
        duration: 5.0,
        noise_sd: 0.0,
        seed: 0,
        u_limits: None,
    }
}

/// The loop of design `d` around the plant `model`, started at rest at 0.
fn run_at_rest(model: &Model, d: &control::Design, s: &Scenario) -> control::Trace {
    let (c, x0, u0) = control::model_at_rest(model, 0.0, 0.0).unwrap();
    let plant = Plant {
        system: &c,
        output: 0,
        x0,
        u0,
    };
    control::run(d, &plant, s).unwrap()
}

#[test]
fn the_loop_around_its_own_model_follows_the_designed_response() {
    let model = oscillator();
    let d = oscillator_design(3.0);
    let s = five_quiet_seconds();
    let tr = run_at_rest(&model, &d, &s);
    let m = control::metrics(&tr, &d, 0.0).unwrap();
    // Measured: 0.48 % off the continuous-time design (the controller is sampled), no overshoot.
    assert!(m.design_deviation < 1.0, "{m:?}");
    assert!(m.overshoot < 0.5 && m.final_error.abs() < 0.1, "{m:?}");
    // Input limits that clip: the rest input 0 is below the lower limit, so the loop starts
    // clipped, and the upper limit cuts the peak of a faster design. The integrator integrates
    // only what pulls the input back inside: the output still settles, without the overshoot of
    // a wound-up integrator and without stalling at the limit.
    let clipped = |lo: f64, hi: f64, w: f64| {
        let d = oscillator_design(w);
        let sc = Scenario {
            u_limits: Some((lo, hi)),
            ..s.clone()
        };
        let tr = run_at_rest(&model, &d, &sc);
        (control::metrics(&tr, &d, 0.0).unwrap(), tr)
    };
    let (m, tr) = clipped(0.5, 2.5, 3.0);
    assert!(
        tr.u[0] == 0.5 && m.final_error.abs() < 0.1 && m.overshoot < 0.5,
        "{m:?}"
    );
    let (free, _) = clipped(-100.0, 100.0, 5.0);
    let (m, tr) = clipped(-100.0, 2.5, 5.0);
    assert!(free.u_max > 3.0, "the limit must clip: {free:?}");
    assert!(
        tr.u.contains(&2.5) && m.final_error.abs() < 0.1 && m.overshoot < 5.0,
        "{m:?}"
    );
}

/// The throttle's true linear model with every coefficient halved (the common-scale error the
/// identified throttle model shows: same slow response, fast pole at a different place) designs
/// the controller; the plant is the true throttle with its aerodynamic torque (Patm = 101325 Pa),
/// which no model here contains.
#[test]
fn a_design_on_a_wrong_model_holds_the_true_nonlinear_throttle() {
    let paper = BuiltIn::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let mut wrong = paper.true_model(Some(0.003)).unwrap();
    for t in wrong.outputs[0].terms.iter_mut() {
        t.coefficient *= 0.5;
    }
    let physical = BuiltIn::throttle(ThrottlePreset::Physical);
    let x_rest = physical.rest_state();
    let from = x_rest[0];
    let d = control::design(&wrong, &DesignOptions::new(from - 0.5, 0.003)).unwrap();
    let plant = Plant {
        system: physical.system(),
        output: 0,
        x0: x_rest,
        u0: 0.0,
    };
    let s = Scenario {
        duration: 15.0 / d.bandwidth,
        noise_sd: 0.005,
        seed: 3,
        u_limits: None,
    };
    let tr = control::run(&d, &plant, &s).unwrap();
    let m = control::metrics(&tr, &d, from).unwrap();
    // Measured: final error 0.24 % of the step (noise 1 % of it), 1.65 % off the design, overshoot
    // 0.11 %, rise 0.147 s.
    assert!(m.final_error.abs() < 0.75, "{m:?}");
    assert!(m.design_deviation < 5.0 && m.overshoot < 2.0, "{m:?}");
}

#[test]
fn bad_designs_are_errors_that_say_why() {
    let e = |m: &Model, o: &DesignOptions| control::design(m, o).unwrap_err().to_string();
    let mut no_u = oscillator();
    no_u.outputs[0].terms.pop();
    assert!(e(&no_u, &DesignOptions::new(1.0, 0.01)).contains("input has no effect"));
    let mut o = DesignOptions::new(1.0, 0.01);
    o.bandwidth = Some(100.0);
    let msg = e(&oscillator(), &o);
    assert!(
        msg.contains("too fast") && msg.contains("below 16.6667"),
        "{msg}"
    );
    assert!(e(&oscillator(), &DesignOptions::new(f64::NAN, 0.01)).contains("setpoint"));
    // A fast unstable mode feedback must move needs faster sampling, whatever the bandwidth.
    let unstable = Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            2,
            vec![Term::new(&[("y", 1)], 1e4), Term::new(&[("u", 1)], 1.0)],
        )],
        Some(0.01),
    );
    let mut o = DesignOptions::new(1.0, 0.01);
    o.bandwidth = Some(1.0);
    let msg = e(&unstable, &o);
    assert!(
        msg.contains("'tau'") && msg.contains("below 5.000e-3"),
        "{msg}"
    );
    o.tau = 1e-4;
    assert!(control::design(&unstable, &o).is_ok());
    // At y = 1, P = -(u - 1)^2: a double root in u would need unbounded gains: no effect there.
    let double = input_poly(2.0, -1.0, 0.0);
    let msg = e(&double, &DesignOptions::new(1.0, 0.01));
    assert!(msg.contains("no effect"), "{msg}");
    let mut two = oscillator();
    two.inputs.push("v".into());
    assert!(e(&two, &DesignOptions::new(1.0, 0.01)).contains("one output and one input"));
}

/// `y^(n) = -3.965 y - 0.9185 y' + 3.941 u` (an identified second-order model given order n).
fn high_order(n: usize) -> Model {
    Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            n,
            vec![
                Term::new(&[("y", 1)], -3.965),
                Term::new(&[("y_d1", 1)], -0.9185),
                Term::new(&[("u", 1)], 3.941),
            ],
        )],
        Some(0.02),
    )
}

#[test]
fn a_sampled_loop_that_is_unstable_is_refused_with_a_tau_that_works() {
    // Order 7 at tau = 0.02 s: every placed pole is slow against tau (below 4 rad/s), yet the
    // held input and measurement make the loop unstable (it used to be reported with an
    // overshoot of 2936 % and exit 0).
    let e = control::design(&high_order(7), &DesignOptions::new(1.0, 0.02)).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("'tau'") && msg.contains("unstable"), "{msg}");
    let tau: f64 = msg
        .split("give a tau of ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no tau suggested: {msg}"));
    assert!(tau < 0.02, "{msg}");
    // At the suggested tau the loop around the model follows its design.
    let model = high_order(7);
    let d = control::design(&model, &DesignOptions::new(1.0, tau)).unwrap();
    let (c, x0, u0) = control::model_at_rest(&model, 0.0, 0.0).unwrap();
    let plant = Plant {
        system: &c,
        output: 0,
        x0,
        u0,
    };
    let s = Scenario {
        duration: control::default_duration(&d),
        noise_sd: 0.0,
        seed: 1,
        u_limits: None,
    };
    let m = control::metrics(&control::run(&d, &plant, &s).unwrap(), &d, 0.0).unwrap();
    assert!(
        m.settling_time.is_finite() && m.design_deviation < 2.0,
        "{m:?}"
    );
    // Orders 2 and 3 of the same model are fine at 0.02 s.
    for n in [2, 3] {
        assert!(control::design(&high_order(n), &DesignOptions::new(1.0, 0.02)).is_ok());
    }
}

#[test]
fn eigenvalues_of_huge_matrices_end() {
    // nalgebra's balancing never ended on entries beyond 1e154 (`ctsid control` hung on a model
    // coefficient of 1e160).
    let m = nalgebra::DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 1e200, -0.9]);
    let e = control::design::eigenvalues(&m).unwrap();
    assert!(
        (e[1].0 - 1e100).abs() < 1e88 && (e[0].0 + 1e100).abs() < 1e88,
        "{e:?}"
    );
    // Badly scaled companion matrix of (s + 1)(s + 1e3)(s + 1e6): balancing keeps the slow root.
    let m = nalgebra::DMatrix::from_row_slice(
        3,
        3,
        &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0, -1e9, -1.001001e9, -1.001001e6],
    );
    let e = control::design::eigenvalues(&m).unwrap();
    for (got, want) in e.iter().zip([-1e6, -1e3, -1.0]) {
        assert!((got.0 / want - 1.0).abs() < 1e-8 && got.1 == 0.0, "{e:?}");
    }
}

/// `y'' = -y - y' + c2 u^2 + c3 u^3 + c1 u`: steady inputs where Newton from u = 0 alone fails.
fn input_poly(c1: f64, c2: f64, c3: f64) -> Model {
    let mut terms = vec![
        Term::new(&[("y", 1)], -1.0),
        Term::new(&[("y_d1", 1)], -1.0),
    ];
    for (p, c) in [(1, c1), (2, c2), (3, c3)] {
        if c != 0.0 {
            terms.push(Term::new(&[("u", p)], c));
        }
    }
    Model::new(&["u"], vec![OutputEquation::new("y", 2, terms)], Some(0.01))
}

#[test]
fn steady_inputs_are_found_where_newton_from_zero_fails() {
    // u^2 = 1: the slope is 0 at u = 0, the root is +-1 (the smallest |u| wins; +1 first).
    let u = control::steady_input(&input_poly(0.0, 1.0, 0.0), 1.0).unwrap();
    assert!((u.abs() - 1.0).abs() < 1e-9, "{u}");
    // u^3 - 2 u = 1: plain Newton from 0 cycles; damped Newton finds a root.
    let u = control::steady_input(&input_poly(-2.0, 0.0, 1.0), 1.0).unwrap();
    assert!((u * u * u - 2.0 * u - 1.0).abs() < 1e-9, "{u}");
    // At y = -1 the input would need u^2 = -1: no root.
    let e = control::steady_input(&input_poly(0.0, 1.0, 0.0), -1.0).unwrap_err();
    assert!(e.to_string().contains("no steady input"), "{e}");
    // A starting output where the model overflows is an error, not an endless eigenvalue loop.
    let cubic = Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            2,
            vec![
                Term::new(&[("y", 1)], -1.0),
                Term::new(&[("y", 3)], 0.001),
                Term::new(&[("u", 1)], 1.0),
            ],
        )],
        Some(0.01),
    );
    let c = cubic.compile().unwrap();
    let e = control::rest_state(&c, 0, 1e160, 0.0).unwrap_err();
    assert!(e.to_string().contains("--from"), "{e}");
}

#[test]
fn the_command_prints_the_design_and_writes_the_trace() {
    let model = temp_file(
        "control",
        "osc.json",
        &oscillator().to_json_string().unwrap(),
    );
    let trace = temp_file("control", "trace.csv", "");
    let report = std::env::temp_dir().join(format!("ctsid-control-report-{}", std::process::id()));
    let (ok, out, err) = ctsid(&[
        "control",
        &model,
        "--setpoint 1 --from 0 --bandwidth 3 -o",
        &trace,
        "--report",
        &report.display().to_string(),
    ]);
    assert!(ok, "{err}");
    for f in ["step.svg", "input.svg"] {
        let svg = std::fs::read_to_string(report.join(f)).unwrap();
        assert!(svg.starts_with("<svg") && !svg.contains("NaN"), "{f}");
    }
    std::fs::remove_dir_all(&report).ok();
    assert!(
        out.contains("K: y 1.150000e1, y_d1 4.300000e0; k_i 1.350000e1"),
        "{out}"
    );
    assert!(
        out.contains("largest difference from the designed response"),
        "{out}"
    );
    // A linear model takes any setpoint; 1e300 is echoed as 1e300, not in 301 digits.
    let (ok, out, err) = ctsid(&["control", &model, "--setpoint 1e300 --from 0 --bandwidth 3"]);
    assert!(ok, "{err}");
    assert!(
        out.contains("operating point: y = 1e300,") && out.contains("step 0 -> 1e300 around"),
        "{out}"
    );
    let text = std::fs::read_to_string(&trace).unwrap();
    assert!(
        text.starts_with("t,reference,designed,y,y_measured,y_hat,y_d1_hat,u\n"),
        "{text}"
    );
    assert_eq!(
        text.lines().count(),
        1 + 501,
        "15 / 3 s at 0.01 s, both ends"
    );
    fails(
        &["control", &model, "--setpoint 1 --from 0 --bandwidth 100"],
        &["'bandwidth'", "too fast"],
    );
    fails(
        &["control", &model, "--setpoint 1 --from 0 --u-min 0"],
        &["--u-max"],
    );
    fails(
        &["control", &model, "--setpoint 1 --from 0 --plant", &trace],
        &["trace.csv"],
    );
    fails(
        &["control", &model, "--setpoint 1 --from 1"],
        &["'from'", "no step"],
    );
    fails(
        &[
            "control",
            &model,
            "--setpoint 1 --from 0 --u-min -1 --u-max 1.5",
        ],
        &["steady input of 2e0", "out of reach"],
    );
    fails(
        &["control", &model, "--setpoint 1 --from 0 --duration 1e5"],
        &["'duration'", "at most 1000000"],
    );
    let mut huge = oscillator();
    huge.outputs[0].terms[0] = Term::new(&[("y", 1)], 1e160);
    let huge = temp_file("control", "huge.json", &huge.to_json_string().unwrap());
    fails(
        &["control", &huge, "--setpoint 1 --from 0"],
        &[
            "the default bandwidth 1.0000e80 rad/s",
            "give a bandwidth below",
        ],
    );
    let h7 = temp_file(
        "control",
        "h7.json",
        &high_order(7).to_json_string().unwrap(),
    );
    fails(
        &["control", &h7, "--setpoint 1 --from 0"],
        &["'tau'", "unstable", "give a tau of"],
    );
    let h6 = temp_file(
        "control",
        "h6.json",
        &high_order(6).to_json_string().unwrap(),
    );
    let out = fails(
        &["control", &h6, "--setpoint 1 --from 0 -o", &trace],
        &["'tau'", "does not settle", "--tau", "works)"],
    );
    // The suggested tau is one that was checked: taking it, the loop settles.
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let at = err.find("--tau ").unwrap() + 6;
    let tau = err[at..].split_whitespace().next().unwrap();
    let (ok, _, err2) = ctsid(&["control", &h6, "--setpoint 1 --from 0 --tau", tau]);
    assert!(ok, "--tau {tau}: {err2}");
    // A failed loop writes no files (the trace from before is left as it was).
    assert_eq!(std::fs::read_to_string(&trace).unwrap(), text);
    // A model whose mode no sampling can follow says so, not 'tau below 5e-81 s'.
    fails(
        &["control", &huge, "--setpoint 1 --from 0 --bandwidth 10"],
        &["faster than any sampling", "check the model's coefficients"],
    );
    // A run shorter than the designed settling is a note, not an error.
    let (ok, _, err) = ctsid(&[
        "control",
        &model,
        "--setpoint 1 --from 0 --bandwidth 3 --duration 0.5",
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("has not settled within the 0.5000 s run; give a longer --duration"),
        "{err}"
    );
    // A nonlinear model that strays from its linear design yet settles, later than the run:
    // y' = -2 y + 3 u - 0.5 y^3 from 10 to 1 settles in about 9 s, the run is 3.4 s. That is a
    // --duration to give, not a bandwidth (as it was called before).
    let cubic = temp_file(
        "control",
        "cubic.json",
        r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"y":1},"coefficient":-2},{"exponents":{"u":1},"coefficient":3},{"exponents":{"y":3},"coefficient":-0.5}]}]}"#,
    );
    let out = fails(
        &["control", &cubic, "--setpoint 1 --from 10"],
        &["'duration'", "it settles in", "give --duration"],
    );
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let at = err.find("--duration ").unwrap() + 11;
    let dur = err[at..].split_whitespace().next().unwrap();
    let (ok, out, err2) = ctsid(&["control", &cubic, "--setpoint 1 --from 10 --duration", dur]);
    assert!(
        ok && out.contains("settling (2 %) 9."),
        "--duration {dur}: {err2}\n{out}"
    );
    let mut other = oscillator();
    other.outputs[0].name = "z".into();
    other.outputs[0].terms[0] = Term::new(&[("z", 1)], -4.0);
    other.outputs[0].terms[1] = Term::new(&[("z_d1", 1)], -0.4);
    let other = temp_file("control", "z.json", &other.to_json_string().unwrap());
    fails(
        &["control", &model, "--setpoint 1 --from 0 --plant", &other],
        &["'plant'", "output 'z'", "same machine"],
    );
}

#[test]
fn eigenvalues_of_pure_chains_of_even_order_converge() {
    // y^(n) = -a y + u for even n: the roots of s^n = -a sit symmetric about the origin, and the
    // plain Schur iteration stalled on n = 4, 6 ('did not converge'; control refused the model).
    for n in [2usize, 4, 6] {
        let a = 2.0f64;
        let mut m = nalgebra::DMatrix::zeros(n, n);
        for k in 0..n - 1 {
            m[(k, k + 1)] = 1.0;
        }
        m[(n - 1, 0)] = -a;
        let e = control::design::eigenvalues(&m).unwrap_or_else(|e| panic!("n = {n}: {e}"));
        assert_eq!(e.len(), n);
        let r = a.powf(1.0 / n as f64);
        for (re, im) in &e {
            let z = num_complex_pow(*re, *im, n);
            assert!(
                ((re * re + im * im).sqrt() - r).abs() < 1e-9
                    && (z.0 + a).abs() < 1e-7
                    && z.1.abs() < 1e-7,
                "n = {n}: {e:?}"
            );
        }
    }
}

/// (re + i im)^n as (re, im).
fn num_complex_pow(re: f64, im: f64, n: usize) -> (f64, f64) {
    (0..n).fold((1.0, 0.0), |(a, b), _| (a * re - b * im, a * im + b * re))
}

/// The EMPS model of the README's quick start: `q'' = c - k q - d q' + b u - fc sign(q')`, the
/// sign smoothed over 8.6e-5 m/s as identify writes it.
const EMPS_LIKE: &str = r#"{"format":"ctsid-model/2","tau":0.001,"inputs":["force_N"],
  "sign_smoothing":{"q_m_d1":8.596398560777084e-05},
  "outputs":[{"name":"q_m","order":2,"terms":[
    {"exponents":{},"coefficient":0.04190766187410891},
    {"exponents":{"q_m":1},"coefficient":-0.05532853856282718},
    {"exponents":{"q_m_d1":1},"coefficient":-1.8527244252390804},
    {"exponents":{"force_N":1},"coefficient":0.010476679342917355},
    {"expression":"sign(q_m_d1)","coefficient":-0.23950480722818857}]}]}"#;

/// A sign's slope at rest is its smoothing's (1 / width), not the machine's: the design leaves
/// it out and says so (it gave EMPS an open-loop pole at -2788 /s, a default bandwidth of
/// 0.235 rad/s and a 33 s step); a smooth friction law's slope (`tanh(50*y_d1)`) is the model's
/// and stays.
#[test]
fn a_sign_smoothings_slope_is_left_out_of_the_design() {
    let emps = Model::from_json_str(EMPS_LIKE, "emps").unwrap();
    let d = control::design(&emps, &DesignOptions::new(0.1, 0.001)).unwrap();
    let mut fast: Vec<f64> = d.open_loop.iter().map(|(re, _)| *re).collect();
    fast.sort_by(f64::total_cmp);
    // s^2 + 1.8527 s + 0.0553 = 0: -1.8224 and -0.0304.
    assert!(
        (fast[0] + 1.8224).abs() < 1e-3 && (fast[1] + 0.0304).abs() < 1e-3,
        "{fast:?}"
    );
    assert!((d.a[(1, 1)] + 1.8527).abs() < 1e-3, "{}", d.a);
    assert!(
        d.notes.len() == 1 && d.notes[0].contains("sign smoothing"),
        "{:?}",
        d.notes
    );
    // A smooth law keeps its slope, with the smoothing entry still in the file (the branch that
    // compares with the exact sign runs and finds nothing to change).
    let smooth = EMPS_LIKE.replace("sign(q_m_d1)", "tanh(50*q_m_d1)");
    let m = Model::from_json_str(&smooth, "tanh").unwrap();
    let d = control::design(&m, &DesignOptions::new(0.1, 0.001)).unwrap();
    // -1.8527 - 50 * 0.2395 = -13.828
    assert!((d.a[(1, 1)] + 13.828).abs() < 1e-2, "{}", d.a);
    assert!(d.notes.is_empty(), "{:?}", d.notes);
    // A sign 116 widths off its switch: its smoothed slope is small, the exact one 0, and the
    // design is within 0.1 % of the exact one (an extrapolation in 1/w made it 0.81).
    let off = EMPS_LIKE.replace("sign(q_m_d1)", "sign(q_m_d1 + 0.01)");
    let m = Model::from_json_str(&off, "off").unwrap();
    let d = control::design(&m, &DesignOptions::new(0.1, 0.001)).unwrap();
    assert!((d.a[(1, 1)] + 1.8527).abs() < 2e-3, "{}", d.a);
}

/// Around the EMPS model the default bandwidth (0.235 rad/s, the geometric mean of its
/// open-loop poles) sticks and slips on the friction: the error names a bandwidth checked to
/// follow its design, not the sampling. That bandwidth works; with input limits the step line
/// counts the samples at a limit, the trace has the designed response and the model's names;
/// a tracking loop that rings gets a note.
#[test]
fn a_loop_that_strays_names_a_bandwidth_that_works() {
    let model = temp_file("control_emps", "emps.json", EMPS_LIKE);
    // The design's note on the sign, then the error.
    let (ok, _, err) = ctsid(&["control", &model, "--setpoint", "0.1", "--from", "0"]);
    let last = err.trim_end().lines().last().unwrap_or("");
    assert!(
        !ok && last.starts_with("error: invalid setting 'bandwidth'")
            && last.contains("follows its design and settles in"),
        "{err}"
    );
    let w = last
        .split("--bandwidth ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap()
        .to_string();
    let trace = temp_file("control_emps", "trace.csv", "");
    // The arguments after the model as words (the helper splits those that start with '-').
    let at_w =
        format!("--setpoint 0.1 --from 0 --bandwidth {w} --u-min -300 --u-max 300 -o {trace}");
    let (ok, out, err) = ctsid(&["control", &model, &at_w]);
    assert!(ok, "{err}");
    assert!(
        err.contains("note: d q_m_d2 / d q_m_d1 at the setpoint"),
        "{err}"
    );
    assert!(out.contains("input at a limit in "), "{out}");
    let text = std::fs::read_to_string(&trace).unwrap();
    assert!(
        text.starts_with("t,reference,designed,q_m,q_m_measured,q_m_hat,q_m_d1_hat,force_N\n"),
        "{text}"
    );
    let (ok, _, err) = ctsid(&[
        "control",
        &model,
        "--setpoint 0.1 --from 0 --reference steps",
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("note: the loop does not settle on the reference's steps"),
        "{err}"
    );
}

/// A plant whose level cannot rise above 0.6 (an overflow, `limits` in its model), driven toward
/// a setpoint of 1.0: the closed loop keeps the plant on its limit (the loop's simulation keeps a
/// plant's limits as every simulation does), where without the limit it reaches the setpoint.
#[test]
fn a_plant_with_a_limit_stays_on_it_in_closed_loop() {
    let model = oscillator();
    let d = oscillator_design(3.0);
    let mut capped = oscillator();
    capped.outputs[0].limits.max = Some(0.6);
    let s = five_quiet_seconds();
    let run = |m: &Model| run_at_rest(m, &d, &s);
    let (free, held) = (run(&model), run(&capped));
    let last = |y: &[f64]| y[y.len() - 1];
    assert!((last(&free.y) - 1.0).abs() < 0.1, "free {}", last(&free.y));
    let top = held.y.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
    assert!(
        top <= 0.6 && last(&held.y) == 0.6,
        "held: top {top}, last {}",
        last(&held.y)
    );
}
