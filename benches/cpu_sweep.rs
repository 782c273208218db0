//! Criterion benches of the CPU engine: one correlation sweep, and a LARS path.
//! Sizes: 25,000 samples x 12,376 candidates (n_z = 11, d = 6), the reference problem.
//! `sweep ... F32 near zero` sweeps variables `u^5` (u uniform in [-1, 1]: 2.5 % of the values
//! below 1e-8) with a v of the same kind, whose degree-6 f32 products would be subnormal without
//! the engine's powers of two (docs/method/regression.md, "Subnormal f32 products"); it should
//! take about as long as the uniform case beside it.
use criterion::{criterion_group, criterion_main, Criterion};
use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::{CpuEngine, CpuOptions, Features, Precision, SweepEngine};
use ctsid::regression::{lars_path, Method, PathOptions};
use std::hint::black_box;

fn uniform(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E3779B97F4A7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

fn setup(precision: Precision) -> (CpuEngine, Vec<f64>) {
    setup_with(precision, 1)
}

/// The reference problem with every variable (and the label) raised to the odd power `power`.
fn setup_with(precision: Precision, power: i32) -> (CpuEngine, Vec<f64>) {
    let n = 25_000;
    let mut s = 1u64;
    let names: Vec<String> = (0..11).map(|k| format!("z{k}")).collect();
    let cols = (0..11)
        .map(|_| (0..n).map(|_| uniform(&mut s).powi(power)).collect())
        .collect();
    let f = Features::new(names.clone(), cols).unwrap();
    let b = Basis::new(&names, 6, BasisLimits::default()).unwrap();
    let e = CpuEngine::new(
        &b,
        &f,
        CpuOptions {
            precision,
            materialize_limit_bytes: 0,
        },
    )
    .unwrap();
    let y = (0..n)
        .map(|i| {
            let y = f.column(0)[i].powi(3) * f.column(4)[i] - 2.0 * f.column(7)[i] * f.column(2)[i]
                + 0.01 * uniform(&mut s);
            y.powi(power)
        })
        .collect();
    (e, y)
}

fn sweep(c: &mut Criterion) {
    for p in [Precision::F32, Precision::F64] {
        let (mut e, v) = setup(p);
        let mut out = vec![0.0; e.n_candidates()];
        c.bench_function(&format!("sweep 25000x12376 {p:?}"), |b| {
            b.iter(|| e.sweep(black_box(&v), &mut out).unwrap())
        });
    }
    let (mut e, v) = setup_with(Precision::F32, 5);
    let mut out = vec![0.0; e.n_candidates()];
    c.bench_function("sweep 25000x12376 F32 near zero", |b| {
        b.iter(|| e.sweep(black_box(&v), &mut out).unwrap())
    });
}

fn path(c: &mut Criterion) {
    let (mut e, y) = setup(Precision::F32);
    let opts = PathOptions {
        method: Method::LassoLars,
        max_terms: 20,
        max_steps: 20,
        ..PathOptions::default()
    };
    c.bench_function("lassolars path 20 steps 25000x12376 F32", |b| {
        b.iter(|| lars_path(&mut e, black_box(&y), None, &opts).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = sweep, path
}
criterion_main!(benches);
