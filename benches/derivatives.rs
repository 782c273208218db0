//! Derivative reconstruction speed: 100 runs x 1000 samples (orders 0..6, joint tuning) and one
//! run of 100,000 samples, each with the default options and with the smoother only (no
//! exponential-sum model; the signal is a sum of five sines, so the model is fitted on every
//! run: the pair shows what it costs). Single-threaded by construction (no threads are used).
use criterion::{criterion_group, criterion_main, Criterion};
use ctsid::derivatives::{differentiate_runs, DerivativeOptions};

fn signal(n: usize, seed: u64, tau: f64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E3779B97F4A7C15) | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let w: Vec<(f64, f64)> = (0..5)
        .map(|i| (0.5 + i as f64 * 1.3, rnd() * 6.0))
        .collect();
    (0..n)
        .map(|i| {
            w.iter()
                .map(|(f, p)| (f * i as f64 * tau + p).sin())
                .sum::<f64>()
                + 0.1 * (rnd() - 0.5)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let runs: Vec<Vec<f64>> = (0..100).map(|r| signal(1000, r + 1, 0.01)).collect();
    let refs: Vec<&[f64]> = runs.iter().map(|r| r.as_slice()).collect();
    let mut g = c.benchmark_group("derivatives");
    g.sample_size(10);
    let long = signal(100_000, 99, 0.001);
    let smoother_only = DerivativeOptions {
        exp_sum: false,
        ..Default::default()
    };
    for (what, opts) in [
        ("", DerivativeOptions::default()),
        (", smoother only", smoother_only),
    ] {
        g.bench_function(format!("100 runs x 1000 samples, orders 0..6{what}"), |b| {
            b.iter(|| differentiate_runs(&refs, 0.01, 6, &opts).unwrap())
        });
        g.bench_function(format!("1 run x 100000 samples, orders 0..6{what}"), |b| {
            b.iter(|| differentiate_runs(&[&long], 0.001, 6, &opts).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
