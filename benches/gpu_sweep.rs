//! Criterion bench: one correlation sweep on the GPU engine, beside a plain rayon f64 loop
//! measured in the same run (NOT the crate's CPU engine, which is not on this branch yet).
//! Size from CTSID_BENCH_NZ / CTSID_BENCH_D / CTSID_BENCH_SAMPLES (default 10 variables,
//! degree 4, 5,000 samples: 1,001 candidates, small enough for lavapipe). Without a Vulkan
//! adapter the GPU case is skipped with a notice.

use criterion::{criterion_group, criterion_main, Criterion};
use rayon::prelude::*;

use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::gpu::{GpuEngine, GpuOptions};
use ctsid::engine::{Features, SweepEngine};

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn bench(c: &mut Criterion) {
    let (n_z, d, n_s) = (
        env("CTSID_BENCH_NZ", 10),
        env("CTSID_BENCH_D", 4),
        env("CTSID_BENCH_SAMPLES", 5000),
    );
    let names: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
    let basis = Basis::new(&names, d, BasisLimits::default()).unwrap();
    // Deterministic, cheap pseudo-random inputs (splitmix-style hash of the index).
    let h = |i: u64| {
        let mut z = i.wrapping_mul(0x9E3779B97F4A7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        2.0 * ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 - 1.0
    };
    let cols: Vec<Vec<f64>> = (0..n_z)
        .map(|k| (0..n_s).map(|i| h((k * n_s + i) as u64 + 1)).collect())
        .collect();
    let feats = Features::new(names, cols).unwrap();
    let v: Vec<f64> = (0..n_s).map(|i| h(i as u64 + 1_000_000_007)).collect();
    let label = format!("{n_s}x{}", basis.len());
    let mut g = c.benchmark_group("sweep");
    g.sample_size(10);

    match GpuEngine::new(&feats, &basis, GpuOptions::default()) {
        Ok(mut eng) => {
            eprintln!("gpu engine: {}", eng.describe());
            let mut out = vec![0.0; basis.len()];
            g.bench_function(format!("gpu/{label}"), |b| {
                b.iter(|| eng.sweep(&v, &mut out).unwrap())
            });
        }
        Err(e) => eprintln!("skipping the GPU case: {e}"),
    }

    let rows: Vec<f64> = (0..n_s)
        .flat_map(|i| (0..n_z).map(move |k| (i, k)))
        .map(|(i, k)| feats.column(k)[i])
        .collect();
    let codes = basis.codes().to_vec();
    let mut out = vec![0.0; basis.len()];
    g.bench_function(format!("naive_rayon_f64_reference/{label}"), |b| {
        b.iter(|| {
            out.par_iter_mut().zip(codes.par_iter()).for_each(|(o, c)| {
                let vars: Vec<usize> = c.vars().collect();
                *o = (0..n_s)
                    .map(|i| vars.iter().fold(v[i], |a, &k| a * rows[i * n_z + k]))
                    .sum();
            })
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
