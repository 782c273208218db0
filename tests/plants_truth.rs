//! Built-in plants: the throttle's printed linear equation, eigenvalues and DC gain, exact
//! derivatives against differencing on a fine grid, the excitation's corners, the noise level,
//! the MIMO plant's stability and size, the physical preset's angle range, determinism.

use ctsid::plants::excitation::ExcitationConfig;
use ctsid::plants::rng::Rng;
use ctsid::plants::throttle::{Throttle, ThrottleParams};
use ctsid::plants::{dataset, noise, Dynamics, Plant, ThrottlePreset};
use ctsid::simulate::{simulate, ConstantInput, Input, SimOptions, System};
use nalgebra::DMatrix;

fn throttle(patm: f64) -> Throttle {
    Throttle::new(ThrottleParams::paper(patm))
}

#[test]
fn throttle_at_zero_patm_is_the_printed_linear_equation() {
    let th = throttle(0.0);
    let c = th.linear_coefficients();
    let printed = [37664.0, -23978.0, -32032.0, -675.7, 1.222e6];
    for (a, b) in c.iter().zip(printed) {
        assert!((a / b - 1.0).abs() < 1e-12, "{a} vs {b}");
    }
    // y''' from the physical state equals the printed equation at arbitrary states and inputs.
    let mut rng = Rng::new(3);
    for _ in 0..100 {
        let x = [
            rng.uniform_in(-30.0, 30.0),
            rng.uniform_in(-100.0, 100.0),
            rng.uniform_in(-50.0, 50.0),
        ];
        let u = rng.uniform_in(-5.0, 5.0);
        let d = th.derivatives(&x, u, 0.0);
        let lin = 37664.0 - 23978.0 * d[0] - 32032.0 * d[1] - 675.7 * d[2] + 1.222e6 * u;
        assert!(
            (d[3] - lin).abs() <= 1e-9 * lin.abs().max(1e4),
            "{} vs {lin}",
            d[3]
        );
        // The true model file evaluates to the same.
        let m = th.true_model(Some(0.003)).unwrap().compile().unwrap();
        let z = [d[0], d[1], d[2], u];
        assert!((m.eval_output(0, &z).unwrap() - lin).abs() <= 1e-9 * lin.abs().max(1e4));
    }
    assert!(throttle(101_325.0).true_model(None).is_none());
}

#[test]
fn throttle_eigenvalues_and_dc_gain() {
    let th = throttle(0.0);
    let mut j = [0.0; 9];
    th.jacobian(&[1.0, 0.0, 0.0], &[0.0], &mut j);
    let jm = DMatrix::from_row_slice(3, 3, &j);
    let mut ev: Vec<f64> = jm
        .complex_eigenvalues()
        .iter()
        .map(|z| {
            assert!(z.im.abs() < 1e-9, "complex eigenvalue {z}");
            z.re
        })
        .collect();
    ev.sort_by(|a, b| b.partial_cmp(a).unwrap());
    for (got, want) in ev.iter().zip([-0.76, -50.5, -624.5]) {
        assert!((got - want).abs() < 0.01 * want.abs(), "{ev:?}");
    }
    // DC gain: y_ss - y0 = 1.222e6 / 23978 * u (about 51 rad per unit of u), reached by
    // simulating a constant input for 40 slow time constants.
    let u = 0.01;
    let x0 = th.rest_state();
    let tr = simulate(
        &th,
        &ConstantInput(vec![u]),
        &x0,
        &[0.0, 20.0, 50.0],
        &SimOptions::default(),
    )
    .unwrap();
    let want = th.p.y0 + 1.222e6 / 23978.0 * u;
    assert!(
        (tr.state(2).unwrap()[0] - want).abs() < 1e-8,
        "{} vs {want}",
        tr.state(2).unwrap()[0]
    );
}

/// Central differences of each exact derivative series against the next one, on a fine grid,
/// away from the excitation's corners.
fn check_derivatives(plant: &Plant, tau: f64, n: usize, tol: f64) {
    let runs = dataset(plant, 2, n, tau, 0.0, 11).unwrap();
    for r in &runs {
        let mut corners = Vec::new();
        r.excitation.breakpoints(0.0, r.t[n - 1], &mut corners);
        for (i, d) in r.derivatives.iter().enumerate() {
            for k in 0..d.len() - 1 {
                let scale = d[k + 1]
                    .iter()
                    .map(|v| v.abs())
                    .fold(0.0, f64::max)
                    .max(1e-12);
                let mut worst: f64 = 0.0;
                for s in 1..n - 1 {
                    if corners
                        .iter()
                        .any(|&c| c > r.t[s - 1] - 1e-12 && c < r.t[s + 1] + 1e-12)
                    {
                        continue;
                    }
                    let fd = (d[k][s + 1] - d[k][s - 1]) / (2.0 * tau);
                    worst = worst.max((fd - d[k + 1][s]).abs() / scale);
                }
                assert!(
                    worst < tol,
                    "{} output {i} derivative {}: relative error {worst:e}",
                    plant.name,
                    k + 1
                );
            }
        }
    }
}

#[test]
fn throttle_exact_derivatives_agree_with_differencing() {
    check_derivatives(
        &Plant::throttle(ThrottlePreset::Paper { patm: 0.0 }),
        2e-6,
        3000,
        1e-4,
    );
    // The nonlinear aerodynamic term's derivatives too.
    check_derivatives(
        &Plant::throttle(ThrottlePreset::Paper { patm: 101_325.0 }),
        2e-6,
        3000,
        1e-4,
    );
}

#[test]
fn mimo_exact_derivatives_agree_with_differencing() {
    check_derivatives(&Plant::mimo(), 1e-4, 3000, 1e-5);
}

#[test]
fn excitation_corners_are_exact_and_complete() {
    let cfg = ExcitationConfig::paper();
    let mut total = 0;
    for seed in 0..20 {
        let e = cfg.draw(&mut Rng::new(seed));
        let mut c = Vec::new();
        e.corners(0.0, 3.0, &mut c);
        for &tc in &c {
            assert!(
                (e.raw(tc).0.abs() - cfg.u_bar).abs() < 1e-9,
                "corner at {tc}"
            );
        }
        // Brute-force count of band crossings on a grid 100 times finer than the scan.
        let n = 300_000;
        let inside = |t: f64| e.raw(t).0.abs() < cfg.u_bar;
        let mut count = 0;
        for k in 0..n {
            if inside(k as f64 * 3.0 / n as f64) != inside((k + 1) as f64 * 3.0 / n as f64) {
                count += 1;
            }
        }
        assert_eq!(c.len(), count, "seed {seed}");
        assert!(c.windows(2).all(|w| w[0] < w[1]));
        total += count;
        // Saturated values never exceed u_bar.
        for k in 0..3000 {
            assert!(e.value(k as f64 * 1e-3).abs() <= cfg.u_bar);
        }
    }
    // The saturation is active in the paper's setting.
    assert!(total > 10, "only {total} corners over 20 signals");
}

#[test]
fn dataset_is_deterministic_for_a_seed_and_prefix_stable() {
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let a = dataset(&plant, 4, 300, 0.003, 0.03, 5).unwrap();
    let b = dataset(&plant, 4, 300, 0.003, 0.03, 5).unwrap();
    let c = dataset(&plant, 2, 300, 0.003, 0.03, 5).unwrap();
    let d = dataset(&plant, 4, 300, 0.003, 0.03, 6).unwrap();
    for k in 0..4 {
        assert_eq!(a[k].y, b[k].y);
        assert_eq!(a[k].u, b[k].u);
        assert_eq!(a[k].derivatives, b[k].derivatives);
        assert_ne!(a[k].y, d[k].y);
    }
    assert_eq!(a[0].y, c[0].y);
    assert_eq!(a[1].u, c[1].u);
    assert_ne!(a[0].u, a[1].u);
    // Starts at rest.
    assert!((a[0].y_true[0][0] - std::f64::consts::FRAC_PI_2).abs() < 1e-4);
}

#[test]
fn noise_has_the_paper_level() {
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let runs = dataset(&plant, 3, 1000, 0.003, 0.03, 1).unwrap();
    for r in &runs {
        let abs: Vec<f64> = r.y_true[0].iter().map(|v| v.abs()).collect();
        let level = 0.03 * noise::percentile(&abs, 99.0);
        let sd = (r.y[0]
            .iter()
            .zip(&r.y_true[0])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / 1000.0)
            .sqrt();
        assert!((sd / level - 1.0).abs() < 0.1, "{sd} vs {level}");
    }
    let clean = dataset(&plant, 1, 100, 0.003, 0.0, 1).unwrap();
    assert_eq!(clean[0].y, clean[0].y_true);
}

#[test]
fn paper_throttle_swings_tens_of_radians() {
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let runs = dataset(&plant, 10, 1000, 0.003, 0.0, 2).unwrap();
    let swing = runs
        .iter()
        .map(|r| {
            r.y_true[0]
                .iter()
                .map(|y| (y - std::f64::consts::FRAC_PI_2).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max);
    assert!(swing > 10.0 && swing < 500.0, "largest swing {swing} rad");
}

#[test]
fn physical_preset_keeps_the_angle_in_range() {
    let plant = Plant::throttle(ThrottlePreset::Physical);
    match &plant.dynamics {
        Dynamics::Throttle(t) => assert_eq!(t.p.patm, 101_325.0),
        _ => panic!(),
    }
    let runs = dataset(&plant, 50, 1000, 0.003, 0.0, 9).unwrap();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in &runs {
        for &y in &r.y_true[0] {
            lo = lo.min(y);
            hi = hi.max(y);
        }
    }
    assert!(
        lo >= 0.0 && hi <= std::f64::consts::FRAC_PI_2,
        "angle in [{lo}, {hi}]"
    );
    // And the excitation does move it substantially.
    assert!(hi - lo > 0.3, "angle range [{lo}, {hi}]");
}

#[test]
fn mimo_plant_is_stable_and_of_the_paper_size() {
    let plant = Plant::mimo();
    assert_eq!(plant.orders(), vec![3, 3, 3]);
    assert_eq!(plant.input_names().len(), 2);
    let m = plant.true_model(Some(0.003)).unwrap();
    assert_eq!(m.variable_names().len(), 11);
    assert_eq!(ctsid::basis::count(11, 6), Some(12_376));
    let runs = dataset(&plant, 30, 1000, 0.003, 0.0, 4).unwrap();
    let names = m.variable_names();
    let mut peak: f64 = 0.0;
    for (i, o) in m.outputs.iter().enumerate() {
        // RMS of each term's contribution to the label y_i^(3) over all samples.
        let mut contrib = vec![0.0; o.terms.len()];
        let mut total = 0.0;
        let mut count = 0.0;
        for r in &runs {
            for k in 0..1000 {
                peak = peak.max(r.y_true[i][k].abs());
                let mut z: Vec<f64> = (0..3)
                    .flat_map(|j| (0..3).map(move |d| (j, d)))
                    .map(|(j, d)| r.derivatives[j][d][k])
                    .collect();
                z.extend([r.u[0][k], r.u[1][k]]);
                for (ti, t) in o.terms.iter().enumerate() {
                    let v = t.exponents.iter().fold(t.coefficient, |acc, (n, &e)| {
                        acc * z[names.iter().position(|x| x == n).unwrap()].powi(e as i32)
                    });
                    contrib[ti] += v * v;
                }
                total += r.derivatives[i][3][k].powi(2);
                count += 1.0;
            }
        }
        let rms_total = (total / count).sqrt();
        for (t, c) in o.terms.iter().zip(&contrib) {
            let share = (c / count).sqrt() / rms_total;
            // Every true term, coupling included, carries a visible share of the label.
            assert!(
                share > 0.02,
                "{}: term {} carries only {share:.4} of the RMS of the label",
                o.name,
                t.monomial()
            );
        }
    }
    assert!(peak < 6.0, "outputs reach {peak}");
}

#[test]
fn step_control_keeps_accuracy_on_the_stiff_throttle() {
    // Same run at a loose and at a very tight tolerance, and in two realisations (physical
    // state and the companion form of the true model): all agree.
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let th = match &plant.dynamics {
        Dynamics::Throttle(t) => t.clone(),
        _ => unreachable!(),
    };
    let ex = plant.excitation_for(3, 0);
    let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.003).collect();
    let x0 = th.rest_state();
    let tight = simulate(
        &th,
        &ex,
        &x0,
        &t,
        &SimOptions {
            rtol: 1e-12,
            atol: 1e-12,
            ..Default::default()
        },
    )
    .unwrap();
    let loose = simulate(
        &th,
        &ex,
        &x0,
        &t,
        &SimOptions {
            rtol: 1e-6,
            atol: 1e-6,
            ..Default::default()
        },
    )
    .unwrap();
    let model = th.true_model(None).unwrap().compile().unwrap();
    let xc = [x0[0], 0.0, 0.0];
    let comp = simulate(&model, &ex, &xc, &t, &SimOptions::default()).unwrap();
    let y_tight = tight.series(0).unwrap();
    let range = y_tight
        .iter()
        .map(|y| (y - x0[0]).abs())
        .fold(0.0, f64::max);
    let err = |a: &[f64]| {
        a.iter()
            .zip(&y_tight)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
            / range
    };
    assert!(
        err(&loose.series(0).unwrap()) < 1e-5,
        "loose: {:e}",
        err(&loose.series(0).unwrap())
    );
    assert!(
        err(&comp.series(0).unwrap()) < 1e-7,
        "companion: {:e}",
        err(&comp.series(0).unwrap())
    );
    // The stiffness does not force tiny steps: far fewer than an explicit method's 2/624.5 s.
    assert!(loose.steps < 3000, "{} steps", loose.steps);
}
