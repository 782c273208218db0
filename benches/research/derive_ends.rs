//! The held-out check of the end prior (`DerivativeOptions::end_check`): for signals whose ends
//! do and do not look like their middle, 10 noise seeds each, the smoother alone (no
//! exponential-sum model) with the check and without it. Prints in how many runs the check left
//! the prior out at the start and at the finish, and over those ends the range of the largest
//! error in the first (last) 5 % of samples, in units of the derivative's RMS over the run,
//! orders 1-4, without -> with the check.
//!
//! `cargo bench --bench derive_ends`
use ctsid::derivatives::{differentiate_with, DerivativeOptions, Derivatives};
use ctsid::plants::noise::add_noise;
use ctsid::plants::rng::Rng;
use nalgebra::Complex;

type Exact = Box<dyn Fn(f64, usize) -> f64>;

fn main() {
    let tau = 0.01;
    let mut cases: Vec<(&str, usize, Exact)> = vec![
        (
            "first-order step from the step",
            1000,
            Box::new(|t, k| {
                let e = (-2.0 * t).exp();
                if k == 0 {
                    1.0 - e
                } else {
                    -(-2.0f64).powi(k as i32) * e
                }
            }),
        ),
        (
            "damped oscillation from its peak",
            1000,
            Box::new(|t, k| {
                let l = Complex::new(-0.4, 2.0 * std::f64::consts::PI * 0.7);
                (l.powi(k as i32) * (l * t).exp()).re
            }),
        ),
    ];
    for n in [1000, 200] {
        cases.push((
            "multisine",
            n,
            Box::new(|t, k| {
                [(0.23, 0.4), (0.61, 2.1), (1.13, 4.0), (1.97, 5.5)]
                    .iter()
                    .map(|&(f, p)| {
                        let w = 2.0 * std::f64::consts::PI * f;
                        w.powi(k as i32)
                            * (w * t + p + k as f64 * std::f64::consts::FRAC_PI_2).sin()
                    })
                    .sum()
            }),
        ));
        cases.push((
            "ramp plus sine",
            n,
            Box::new(|t, k| {
                let ramp = [0.5 * t, 0.5, 0.0, 0.0, 0.0][k];
                ramp + 2f64.powi(k as i32)
                    * (2.0 * t + k as f64 * std::f64::consts::FRAC_PI_2).sin()
            }),
        ));
    }
    let opts = |check| DerivativeOptions {
        exp_sum: false,
        end_check: check,
        ..Default::default()
    };
    for (name, n, f) in &cases {
        let truth: Vec<Vec<f64>> = (0..=4)
            .map(|k| (0..*n).map(|i| f(i as f64 * tau, k)).collect())
            .collect();
        let rms: Vec<f64> = truth
            .iter()
            .map(|d| (d.iter().map(|v| v * v).sum::<f64>() / *n as f64).sqrt())
            .collect();
        let edge = (n / 20).max(1);
        // Largest error over the first (end 0) or last (end 1) 5 %, per order 1..4.
        let worst = |d: &Derivatives, end: usize| -> Vec<f64> {
            let range = if end == 0 { 0..edge } else { n - edge..*n };
            (1..=4)
                .map(|k| {
                    range
                        .clone()
                        .map(|i| (d.values[k][i] - truth[k][i]).abs())
                        .fold(0.0, f64::max)
                        / rms[k]
                })
                .collect()
        };
        for eta in [0.01, 0.03] {
            let mut dropped = [0usize; 2];
            let mut spans = [[(f64::INFINITY, 0.0f64); 4], [(f64::INFINITY, 0.0f64); 4]];
            for seed in 1..=10u64 {
                let y = add_noise(&truth[0], eta, &mut Rng::new(100 + seed));
                let off = differentiate_with(&y, tau, 4, &opts(false)).unwrap();
                let on = differentiate_with(&y, tau, 4, &opts(true)).unwrap();
                for (end, count) in dropped.iter_mut().enumerate() {
                    let (a, b) = (worst(&off, end), worst(&on, end));
                    if a == b {
                        continue;
                    }
                    *count += 1;
                    for k in 0..4 {
                        spans[0][k] = (spans[0][k].0.min(a[k]), spans[0][k].1.max(a[k]));
                        spans[1][k] = (spans[1][k].0.min(b[k]), spans[1][k].1.max(b[k]));
                    }
                }
            }
            let fmt = |s: &[(f64, f64); 4]| -> String {
                s.iter()
                    .map(|(lo, hi)| format!("{lo:.2}-{hi:.2}"))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            let changed = if dropped.iter().sum::<usize>() > 0 {
                format!(
                    "; where left out, without -> with the check: {} -> {}",
                    fmt(&spans[0]),
                    fmt(&spans[1])
                )
            } else {
                String::new()
            };
            println!(
                "{name} (N = {n}) at {:.0} %: prior left out at the start in {}/10 runs, at the finish in {}/10{changed}",
                eta * 100.0,
                dropped[0],
                dropped[1]
            );
        }
    }
}
