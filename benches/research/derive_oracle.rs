//! How low can any method go on `sys3_multisine`? An oracle that knows all 19 true poles (the
//! plant's -2, -0.5 +- 3j and the input's -0.3 +- j i, i = 1..8, from signals.json) and fits
//! only the amplitudes by least squares is efficient for white noise among estimators that use
//! the pole set alone. Its derivatives' trimmed p95 on the shared realisation and the median over
//! fresh draws are printed beside the gates: a gate below the oracle is out of reach of
//! any method that does not also know the plant's initial state and input.
//!
//! `cargo bench --bench derive_oracle`
use ctsid::derivatives::benchmark::{gates, load_signal};
use ctsid::derivatives::score::{normalised_percentile, percentile, trimmed_range};
use ctsid::plants::noise::add_noise;
use ctsid::plants::rng::Rng;
use nalgebra::{Complex, DMatrix, DVector};
use std::path::Path;

fn main() {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals"));
    let sig = load_signal(dir, "sys3_multisine").unwrap();
    let n = sig.truth[0].len();
    let mut poles = vec![Complex::new(-2.0, 0.0), Complex::new(-0.5, 3.0)];
    poles.extend((1..=8).map(|i| Complex::new(-0.3, i as f64)));
    // Real basis: e^{at} for the real pole, e^{at} cos(bt) and e^{at} sin(bt) for each pair.
    let basis = |k: usize, t: f64| -> Vec<f64> {
        let mut row = Vec::new();
        for p in &poles {
            let v = p.powi(k as i32) * (p * t).exp();
            row.push(v.re);
            if p.im != 0.0 {
                row.push(-v.im);
            }
        }
        row
    };
    let cols = basis(0, 0.0).len();
    let design = |k: usize| -> DMatrix<f64> {
        DMatrix::from_fn(n, cols, |i, j| basis(k, i as f64 * sig.tau)[j])
    };
    let a0 = design(0);
    let deriv: Vec<DMatrix<f64>> = (1..=4).map(design).collect();
    let svd = a0.clone().svd(true, true);
    let (lo, hi) = trimmed_range(n);
    let score = |y: &[f64]| -> [f64; 4] {
        let x = svd.solve(&DVector::from_column_slice(y), 1e-14).unwrap();
        let mut out = [0.0; 4];
        for k in 1..=4 {
            let est = &deriv[k - 1] * &x;
            out[k - 1] = normalised_percentile(est.as_slice(), &sig.truth[k], 95.0, lo, hi);
        }
        out
    };
    println!("sys3_multisine, least squares on the 19 true poles: trimmed p95, orders 1..4\n");
    for (ni, (noise, y)) in sig.noisy.iter().enumerate() {
        if *noise == 0 {
            continue;
        }
        let shared = score(y);
        let draws: Vec<[f64; 4]> = (0..50)
            .map(|r| {
                let mut rng = Rng::new(104_729 * (r + 1) + ni as u64);
                score(&add_noise(&sig.truth[0], *noise as f64 / 100.0, &mut rng))
            })
            .collect();
        let median: Vec<f64> = (0..4)
            .map(|k| percentile(&draws.iter().map(|d| d[k]).collect::<Vec<_>>(), 50.0))
            .collect();
        let (gate, _) = gates("sys3_multisine", *noise).unwrap();
        let fmt = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.3}"))
                .collect::<Vec<_>>()
                .join("/")
        };
        println!(
            "{noise}%: shared draw {} | median of 50 draws {} | gate {}",
            fmt(&shared),
            fmt(&median),
            fmt(&gate)
        );
    }
}
