//! Derivative reconstruction against exact truth: noise-free polynomials and sines, the shared
//! test signals (copied to tests/data/signals) with their exact derivatives, sigma calibration,
//! and bad inputs.

use ctsid::derivatives::score::{coverage, spearman, trimmed_range};
use ctsid::derivatives::{
    benchmark, differentiate, differentiate_runs, differentiate_with, DerivativeOptions,
};
use std::path::Path;

fn signals_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals"))
}

fn max_rel_err(est: &[f64], truth: &[f64], from: usize, to: usize) -> f64 {
    let scale = truth
        .iter()
        .map(|v| v.abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    (from..to)
        .map(|i| (est[i] - truth[i]).abs())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn noise_free_polynomial_is_reproduced() {
    // A cubic lies in the null space of the integrator-chain prior: derivatives must be exact
    // up to the small noise level the tuning assigns to rounding.
    let tau = 0.01;
    let n = 400;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * tau).collect();
    let y: Vec<f64> = t
        .iter()
        .map(|t| 0.5 - 1.2 * t + 0.8 * t * t - 0.3 * t * t * t)
        .collect();
    let truth = [
        y.clone(),
        t.iter()
            .map(|t| -1.2 + 1.6 * t - 0.9 * t * t)
            .collect::<Vec<_>>(),
        t.iter().map(|t| 1.6 - 1.8 * t).collect(),
        vec![-1.8; n],
    ];
    let d = differentiate(&y, tau, 3).unwrap();
    for (k, truth_k) in truth.iter().enumerate() {
        // Away from the first samples the estimate is exact to 3e-5; the first few carry
        // the finite (1e8 sigma^2) stand-in for a diffuse initial state.
        let e = max_rel_err(&d.values[k], truth_k, 10, n);
        assert!(
            e < 3e-5,
            "order {k}: max relative error {e:e} after sample 10"
        );
        if k < 3 {
            // The top requested order is the least determined by the first few samples.
            let e = max_rel_err(&d.values[k], truth_k, 0, n);
            assert!(e < 2e-3, "order {k}: max relative error {e:e}");
        }
    }
}

#[test]
fn noise_free_sines_are_accurate() {
    let tau = 0.01;
    let n = 1000;
    let w: [f64; 3] = [0.7, 1.9, 3.7];
    let f = |t: f64, k: i32| -> f64 {
        w.iter()
            .map(|&w| w.powi(k) * (w * t + 0.3 + k as f64 * std::f64::consts::FRAC_PI_2).sin())
            .sum()
    };
    let y: Vec<f64> = (0..n).map(|i| f(i as f64 * tau, 0)).collect();
    let d = differentiate(&y, tau, 4).unwrap();
    let (a, b) = trimmed_range(n);
    for k in 1..=4 {
        let truth: Vec<f64> = (0..n).map(|i| f(i as f64 * tau, k as i32)).collect();
        let e = max_rel_err(&d.values[k], &truth, a, b);
        assert!(
            e < 1e-3 * 10f64.powi(k as i32 - 1),
            "order {k}: trimmed max relative error {e:e}"
        );
    }
}

#[test]
fn shared_signals_meet_the_regression_gates() {
    // Gates every row meets today (see README's derivative table for the full gates):
    // trimmed p95 no worse than the ML-tuned 6-state Kalman smoother by more than 10 %, and
    // better than ml-derivatives at every order, noise and signal.
    let rows = benchmark::run(signals_dir()).unwrap();
    assert_eq!(rows.len(), 12);
    for r in &rows {
        let (ml, kal, _) = benchmark::anchors(&r.signal, r.noise).unwrap();
        for k in 0..4 {
            let ours = r.trimmed_p95[k];
            assert!(
                ours <= 1.1 * kal[k] || ours <= 0.5 * ml[k],
                "{} {}% order {}: {ours} vs Kalman {}",
                r.signal,
                r.noise,
                k + 1,
                kal[k]
            );
            assert!(
                ours < ml[k],
                "{} {}% order {}: {ours} vs ml-derivatives {}",
                r.signal,
                r.noise,
                k + 1,
                ml[k]
            );
        }
        // Rows that meet every gate of the issue today must keep meeting them.
        let full = matches!(
            (r.signal.as_str(), r.noise),
            ("etc_s1", _) | ("chirp", _) | ("sines", _) | ("sys3_multisine", 5)
        );
        if full {
            assert!(
                benchmark::gates_pass(r),
                "{} {}%: trimmed p95 {:?}, full p100 {:?}",
                r.signal,
                r.noise,
                r.trimmed_p95,
                r.full_p100
            );
        } else {
            // The two sys3 rows that miss some gate must not get worse than today (5 % slack).
            let today: [f64; 4] = match r.noise {
                1 => [0.033, 0.074, 0.210, 0.607],
                _ => [0.084, 0.189, 0.501, 1.403],
            };
            for (k, (ours, was)) in r.trimmed_p95.iter().zip(today).enumerate() {
                assert!(
                    *ours <= 1.05 * was,
                    "{} {}% order {}: {ours} (was {was})",
                    r.signal,
                    r.noise,
                    k + 1
                );
            }
        }
    }
}

#[test]
fn sigma_is_calibrated_and_informative_on_smooth_signals() {
    for name in ["sys3_multisine", "sines", "chirp"] {
        let sig = benchmark::load_signal(signals_dir(), name).unwrap();
        for (noise, y) in &sig.noisy {
            let d = differentiate(y, sig.tau, 4).unwrap();
            let mut corr = 0.0;
            for k in 1..=4 {
                let c = coverage(&d.values[k], &sig.truth[k], &d.sigma[k], 2.0);
                assert!(
                    c > 0.88,
                    "{name} {noise}% order {k}: only {c:.3} of errors within 2 sigma"
                );
                let err: Vec<f64> = (0..y.len())
                    .map(|i| (d.values[k][i] - sig.truth[k][i]).abs())
                    .collect();
                corr += spearman(&d.sigma[k], &err) / 4.0;
            }
            assert!(
                corr > 0.1,
                "{name} {noise}%: sigma not informative (mean rank correlation {corr:.3})"
            );
        }
    }
}

#[test]
fn sigma_grows_at_the_ends_and_through_transients() {
    let sig = benchmark::load_signal(signals_dir(), "etc_s1").unwrap();
    let y = &sig.noisy.iter().find(|(n, _)| *n == 3).unwrap().1;
    let d = differentiate(y, sig.tau, 3).unwrap();
    let n = y.len();
    let mid = d.sigma[3][n / 2];
    assert!(
        d.sigma[3][0] > 2.0 * mid && d.sigma[3][n - 1] > 2.0 * mid,
        "ends {} {} vs middle {}",
        d.sigma[3][0],
        d.sigma[3][n - 1],
        mid
    );
    // The saturation transient (largest true |y'''| after the first 5 %) gets a larger sigma than the median.
    let (a, b) = trimmed_range(n);
    let ipk = (a..b)
        .max_by(|&i, &j| sig.truth[3][i].abs().total_cmp(&sig.truth[3][j].abs()))
        .unwrap();
    let mut s: Vec<f64> = d.sigma[3][a..b].to_vec();
    s.sort_by(|x, y| x.total_cmp(y));
    let med = s[s.len() / 2];
    let near = (ipk.saturating_sub(3)..(ipk + 4).min(n))
        .map(|i| d.sigma[3][i])
        .fold(0.0, f64::max);
    assert!(
        near > 1.5 * med,
        "sigma near the transient {near} vs median {med}"
    );
}

#[test]
fn runs_are_smoothed_separately() {
    // Two runs with a jump between them: joint processing must not leak the jump into either.
    let tau = 0.01;
    let a: Vec<f64> = (0..300).map(|i| (i as f64 * tau).sin()).collect();
    let b: Vec<f64> = (0..300).map(|i| 50.0 + (i as f64 * tau).cos()).collect();
    let d = differentiate_runs(&[&a, &b], tau, 2, &DerivativeOptions::default()).unwrap();
    for i in 0..300 {
        let t = i as f64 * tau;
        assert!(
            (d[0].values[1][i] - t.cos()).abs() < 1e-2,
            "run 0 sample {i}"
        );
        assert!(
            (d[1].values[1][i] + t.sin()).abs() < 1e-2,
            "run 1 sample {i}"
        );
    }
}

#[test]
fn bad_inputs_give_errors_not_panics() {
    let y: Vec<f64> = (0..100).map(|i| (i as f64 * 0.1).sin()).collect();
    let mut bad = y.clone();
    bad[17] = f64::NAN;
    assert!(differentiate(&bad, 0.1, 2)
        .unwrap_err()
        .to_string()
        .contains("sample 17"));
    bad[17] = f64::INFINITY;
    assert!(differentiate(&bad, 0.1, 2).is_err());
    assert!(differentiate(&y[..5], 0.1, 2)
        .unwrap_err()
        .to_string()
        .contains("needs at least"));
    assert!(differentiate(&y, 0.0, 2)
        .unwrap_err()
        .to_string()
        .contains("tau"));
    assert!(differentiate(&y, -1.0, 2).is_err());
    assert!(differentiate(&y, f64::NAN, 2).is_err());
    assert!(differentiate(&y, 0.1, 99)
        .unwrap_err()
        .to_string()
        .contains("order"));
    let o = DerivativeOptions {
        states: Some(2),
        ..Default::default()
    };
    assert!(ctsid::derivatives::differentiate_with(&y, 0.1, 3, &o).is_err());
    let o = DerivativeOptions {
        h: Some(-1.0),
        ..Default::default()
    };
    assert!(ctsid::derivatives::differentiate_with(&y, 0.1, 2, &o).is_err());
    // A constant run is exact, with zero uncertainty.
    let c = differentiate(&vec![3.0; 50], 0.1, 2).unwrap();
    assert!(c.values[0].iter().all(|v| *v == 3.0) && c.values[1].iter().all(|v| *v == 0.0));
}

#[test]
fn smooth_window_must_be_finite_and_not_negative() {
    let y: Vec<f64> = (0..200).map(|i| (0.05 * i as f64).sin()).collect();
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let o = DerivativeOptions {
            smooth_window: bad,
            ..Default::default()
        };
        assert!(differentiate_runs(&[&y], 0.01, 2, &o).is_err(), "{bad}");
    }
    let off = DerivativeOptions {
        smooth_window: 0.0,
        ..Default::default()
    };
    assert!(differentiate_runs(&[&y], 0.01, 2, &off).is_ok());
}

#[test]
fn polynomial_and_exponential_drifts_keep_their_derivatives() {
    // A slow drift over the whole run tunes a tiny h; the stationary end prior, whose "ends"
    // then cover the run, once pulled every derivative towards zero (y'' of t + 0.3 t^2 came
    // out as 0.003 with 2-sigma coverage 0): a run shorter than four end widths has no middle
    // and gets no end prior.
    use ctsid::plants::noise::add_noise;
    use ctsid::plants::rng::Rng;
    let (n, tau) = (1000, 0.01);
    type Drift = Box<dyn Fn(f64, usize) -> f64>;
    let drifts: Vec<(&str, Drift)> = vec![
        (
            "t + 0.3 t^2",
            Box::new(|t, k| match k {
                0 => t + 0.3 * t * t,
                1 => 1.0 + 0.6 * t,
                2 => 0.6,
                _ => 0.0,
            }),
        ),
        (
            "exp(0.3 t)",
            Box::new(|t, k| 0.3f64.powi(k as i32) * (0.3 * t).exp()),
        ),
    ];
    for (name, f) in &drifts {
        let truth: Vec<Vec<f64>> = (0..=3)
            .map(|k| (0..n).map(|i| f(i as f64 * tau, k)).collect())
            .collect();
        for eta in [0.01, 0.05] {
            let y = add_noise(&truth[0], eta, &mut Rng::new(17));
            let d = differentiate(&y, tau, 3).unwrap();
            let (a, b) = trimmed_range(n);
            for k in 1..=2 {
                let e = max_rel_err(&d.values[k], &truth[k], a, b);
                let c = coverage(&d.values[k], &truth[k], &d.sigma[k], 2.0);
                // With the end prior: 0.49 / 0.97 relative error on the exponential, y'' of the
                // quadratic 0.003 against 0.6. The exponential's sigma stays too small (coverage
                // 0.4-0.8: the heavily smoothed chain's bias), so only its error is held here.
                let poly = name.starts_with('t');
                let limit = if poly { 0.1 } else { [0.05, 0.2][k - 1] };
                assert!(
                e < limit && (!poly || c > 0.9),
                "{name} at {eta}, order {k}: trimmed max relative error {e:.3}, coverage {c:.2}"
            );
            }
        }
    }
}

#[test]
fn a_step_response_keeps_its_steep_start() {
    // y = 1 - exp(-t / 0.5) sampled from the step, 1 % noise: steepest at the first sample. The
    // stationary end prior shrank that start (largest y' error over the first 50 samples 1.55
    // times y''s RMS, y'' 4.2 times); the held-out check leaves it out there.
    use ctsid::plants::noise::add_noise;
    use ctsid::plants::rng::Rng;
    let (n, tau, tc) = (1000, 0.01, 0.5);
    let truth: Vec<Vec<f64>> = (0..=2)
        .map(|k| {
            (0..n)
                .map(|i| {
                    let e = (-(i as f64) * tau / tc).exp();
                    if k == 0 {
                        1.0 - e
                    } else {
                        -(-1.0 / tc).powi(k) * e
                    }
                })
                .collect()
        })
        .collect();
    for seed in [9, 10] {
        let y = add_noise(&truth[0], 0.01, &mut Rng::new(seed));
        // The smoother itself (an exponential-sum model could take this run over).
        let smoother = DerivativeOptions {
            exp_sum: false,
            ..Default::default()
        };
        let d = differentiate_with(&y, tau, 4, &smoother).unwrap();
        for (k, limit) in [(1, 0.6), (2, 1.5)] {
            let rms = (truth[k].iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
            let worst = (0..50)
                .map(|i| (d.values[k][i] - truth[k][i]).abs())
                .fold(0.0, f64::max)
                / rms;
            assert!(
                worst < limit,
                "seed {seed}, order {k}: largest start error {worst:.2} x RMS"
            );
        }
    }
}
