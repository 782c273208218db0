//! The exponential-sum path of the derivatives (`derivatives::expsum`) against exact truth: it
//! takes over on sums of (damped) sinusoids and beats the smoother there, its sigma is calibrated
//! over noise draws, and it stays out of signals that are no short exponential sum.

use ctsid::derivatives::benchmark::{self, load_signal};
use ctsid::derivatives::score::{coverage, normalised_percentile, trimmed_range};
use ctsid::derivatives::{differentiate, differentiate_with, DerivativeOptions};
use ctsid::plants::noise::add_noise;
use ctsid::plants::rng::Rng;
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

fn signals_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals"))
}

fn smoother_only() -> DerivativeOptions {
    DerivativeOptions {
        exp_sum: false,
        ..Default::default()
    }
}

/// Damped sinusoids A e^{-a t} sin(w t + p) and their exact derivatives (not the shared signals).
fn damped_sines(n: usize, tau: f64) -> Vec<Vec<f64>> {
    let comps = [
        (1.0, 0.05, 1.3, 0.2),
        (0.5, 0.2, 2.9, 1.4),
        (0.3, 0.0, 5.1, 2.5),
    ];
    (0..=4)
        .map(|k| {
            (0..n)
                .map(|i| {
                    let t = i as f64 * tau;
                    comps
                        .iter()
                        .map(|&(amp, a, w, p)| {
                            let r = f64::hypot(a, w);
                            let arg = w.atan2(-a);
                            amp * r.powi(k) * (-a * t).exp() * (w * t + p + k as f64 * arg).sin()
                        })
                        .sum()
                })
                .collect()
        })
        .collect()
}

#[test]
fn takes_over_on_damped_sinusoids_and_beats_the_smoother() {
    let (n, tau) = (1000, 0.01);
    let truth = damped_sines(n, tau);
    let (a, b) = trimmed_range(n);
    let y = add_noise(&truth[0], 0.01, &mut Rng::new(11));
    let model = differentiate(&y, tau, 4).unwrap();
    let chain = differentiate_with(&y, tau, 4, &smoother_only()).unwrap();
    // Three sinusoids, two terms each; the offset of the centred run may take a real one more.
    assert!(
        matches!(model.exp_terms, Some(6..=7)),
        "terms {:?}",
        model.exp_terms
    );
    assert_eq!(chain.exp_terms, None);
    for (k, exact) in truth.iter().enumerate().skip(1) {
        let p95 = |d: &ctsid::derivatives::Derivatives| {
            normalised_percentile(&d.values[k], exact, 95.0, a, b)
        };
        let p100 = |d: &ctsid::derivatives::Derivatives| {
            normalised_percentile(&d.values[k], exact, 100.0, 0, n)
        };
        // Measured (this draw): trimmed p95 0.013/0.013/0.011/0.012 against the smoother's
        // 0.018/0.030/0.050/0.095; full p100 0.021/0.017/0.015/0.016 against 0.39/0.84/0.73/0.38.
        let gain = if k == 1 { 1.0 } else { 0.5 };
        assert!(
            p95(&model) < gain * p95(&chain),
            "order {k}: trimmed p95 {} vs smoother {}",
            p95(&model),
            p95(&chain)
        );
        assert!(
            p100(&model) < 0.2 * p100(&chain),
            "order {k}: full p100 {} vs smoother {}",
            p100(&model),
            p100(&chain)
        );
    }
}

#[test]
fn sigma_is_calibrated_over_noise_draws() {
    // A model's error is the error of a few parameters, coherent over the run: coverage is
    // judged over draws, pooled.
    let sig = load_signal(signals_dir(), "sines").unwrap();
    let draws = 20;
    for eta in [0.01, 0.05] {
        let mut used = 0;
        let mut cover = [0.0; 4];
        for s in 0..draws {
            let y = add_noise(&sig.truth[0], eta, &mut Rng::new(300 + s));
            let d = differentiate(&y, sig.tau, 4).unwrap();
            used += d.exp_terms.is_some() as usize;
            for k in 1..=4 {
                cover[k - 1] +=
                    coverage(&d.values[k], &sig.truth[k], &d.sigma[k], 2.0) / draws as f64;
            }
        }
        assert!(
            used >= draws as usize - 2,
            "{eta}: model in {used}/{draws} draws"
        );
        for (k, c) in cover.iter().enumerate() {
            assert!(
                (0.88..=0.995).contains(c),
                "{eta}: order {}: pooled 2-sigma coverage {c:.3}",
                k + 1
            );
        }
    }
}

#[test]
fn stays_out_of_signals_that_are_no_short_exponential_sum() {
    // The shared chirp, the throttle's transient response, and the plant response whose
    // harmonics fade into the noise (no clear order): the smoother keeps them.
    for name in ["chirp", "etc_s1", "sys3_multisine"] {
        let sig = load_signal(signals_dir(), name).unwrap();
        for (noise, y) in &sig.noisy {
            let d = differentiate(y, sig.tau, 4).unwrap();
            assert_eq!(d.exp_terms, None, "{name} {noise}%");
        }
    }
    // Frequency modulation and a smooth step, with noise.
    let (n, tau) = (1000, 0.01);
    let fm: Vec<f64> = (0..n)
        .map(|i| {
            let t = i as f64 * tau;
            (2.0 * t + 1.5 * (0.5 * t).sin()).sin()
        })
        .collect();
    let step: Vec<f64> = (0..n)
        .map(|i| ((i as f64 * tau - 5.0) / 0.5).tanh())
        .collect();
    for (what, x) in [("fm", fm), ("tanh step", step)] {
        for (s, eta) in [0.01, 0.03, 0.05].into_iter().enumerate() {
            let y = add_noise(&x, eta, &mut Rng::new(40 + s as u64));
            let d = differentiate(&y, tau, 4).unwrap();
            assert_eq!(d.exp_terms, None, "{what} at {eta}");
        }
    }
}

#[test]
fn shared_sines_rows_meet_every_gate_through_the_model() {
    let sig = load_signal(signals_dir(), "sines").unwrap();
    for (noise, y) in &sig.noisy {
        let d = differentiate(y, sig.tau, 4).unwrap();
        if *noise == 0 {
            continue;
        }
        assert_eq!(d.exp_terms, Some(8), "sines {noise}%: four sinusoids");
        let row = benchmark::score_one(&sig, &d, *noise);
        assert!(
            benchmark::gates_pass(&row),
            "sines {noise}%: trimmed p95 {:?}, full p100 {:?}",
            row.trimmed_p95,
            row.full_p100
        );
    }
}

#[test]
fn exact_sinusoid_derivatives_hold_at_every_order() {
    // One undamped sinusoid at 1 % noise, orders up to 6: the model's k-th derivative is
    // w^k times a shifted sine; the relative error must not grow with k (a smoother's does).
    let (n, tau, w) = (800, 0.01, 3.0f64);
    let y0: Vec<f64> = (0..n).map(|i| (w * i as f64 * tau + 0.4).sin()).collect();
    let y = add_noise(&y0, 0.01, &mut Rng::new(5));
    let d = differentiate(&y, tau, 6).unwrap();
    assert_eq!(d.exp_terms, Some(2));
    for k in 1..=6 {
        let truth: Vec<f64> = (0..n)
            .map(|i| w.powi(k as i32) * (w * i as f64 * tau + 0.4 + k as f64 * FRAC_PI_2).sin())
            .collect();
        let p100 = normalised_percentile(&d.values[k], &truth, 100.0, 0, n);
        assert!(p100 < 0.01, "order {k}: full p100 {p100}");
    }
}

#[test]
fn sinusoids_with_a_small_transient_or_bump_keep_an_honest_sigma() {
    // Two sinusoids plus a small tanh transient, or a small Gaussian bump: white enough in
    // values for a model of the sinusoids alone, but the transient is in no model. Either the
    // smoother keeps the run or the sigma still covers the truth about as well as the smoother's
    // (which itself covers a bump's flanks less than 95 %). Without the agreement check the
    // model of the sinusoids alone is taken on the tanh case (seed 0: coverage 0.68 at order 1
    // against the smoother's 0.97).
    let (n, tau) = (1000, 0.01);
    let tanh_d = |x: f64, k: usize| -> f64 {
        // d^k/dx^k tanh(x) as a polynomial in u = tanh(x), by differentiating P(u) (1 - u^2).
        let u = x.tanh();
        let mut p = vec![0.0, 1.0];
        for _ in 0..k {
            let mut q = vec![0.0; p.len() + 2];
            for (i, c) in p.iter().enumerate().skip(1) {
                q[i - 1] += i as f64 * c;
                q[i + 1] -= i as f64 * c;
            }
            p = q;
        }
        p.iter()
            .enumerate()
            .map(|(i, c)| c * u.powi(i as i32))
            .sum()
    };
    let sines = |t: f64, k: usize| -> f64 {
        3f64.powi(k as i32) * (3.0 * t + 0.4 + k as f64 * FRAC_PI_2).sin()
            + 0.6 * 1.1f64.powi(k as i32) * (1.1 * t + 2.0 + k as f64 * FRAC_PI_2).sin()
    };
    let gauss_d = |x: f64, k: usize| -> f64 {
        // d^k/dx^k exp(-x^2) = (-1)^k H_k(x) exp(-x^2), physicists' Hermite polynomials.
        let (mut h0, mut h1) = (1.0, 2.0 * x);
        let hk = match k {
            0 => h0,
            _ => {
                for j in 1..k {
                    let h2 = 2.0 * x * h1 - 2.0 * j as f64 * h0;
                    h0 = h1;
                    h1 = h2;
                }
                h1
            }
        };
        (-1f64).powi(k as i32) * hk * (-x * x).exp()
    };
    type Exact = Box<dyn Fn(f64, usize) -> f64>;
    let cases: Vec<(&str, Exact, f64)> = vec![
        (
            "tanh",
            Box::new(move |t, k| sines(t, k) + 0.03 * tanh_d(t - 5.0, k)),
            0.01,
        ),
        (
            "bump",
            Box::new(move |t, k| {
                sines(t, k) + 0.05 * gauss_d((t - 4.0) / 0.3, k) / 0.3f64.powi(k as i32)
            }),
            0.05,
        ),
    ];
    for (name, f, eta) in &cases {
        let truth: Vec<Vec<f64>> = (0..=4)
            .map(|k| (0..n).map(|i| f(i as f64 * tau, k)).collect())
            .collect();
        for seed in 0..4 {
            let y = add_noise(&truth[0], *eta, &mut Rng::new(70 + seed));
            let d = differentiate(&y, tau, 4).unwrap();
            let s = differentiate_with(&y, tau, 4, &smoother_only()).unwrap();
            for (k, exact) in truth.iter().enumerate().skip(1) {
                let c = coverage(&d.values[k], exact, &d.sigma[k], 2.0);
                let cs = coverage(&s.values[k], exact, &s.sigma[k], 2.0);
                assert!(
                    c >= 0.85f64.min(cs - 0.05),
                    "{name}, seed {seed}, order {k}: coverage {c:.2}, smoother alone {cs:.2} ({:?})",
                    d.exp_terms
                );
            }
        }
    }
}
