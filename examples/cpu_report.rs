//! Prints measured CPU-engine times against references measured in the same run.
//! Run: `cargo run --release --example cpu_report` (see benches/cpu_report.sh).
use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::{CpuEngine, CpuOptions, Features, Precision, SweepEngine};
use std::time::Instant;

fn rng(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E3779B97F4A7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

fn main() {
    let n = 25_000;
    for (nz, d) in [(11usize, 6usize), (13, 9)] {
        let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
        let mut s = 1u64;
        let cols = (0..nz).map(|_| (0..n).map(|_| rng(&mut s)).collect()).collect();
        let f = Features::new(names.clone(), cols);
        let b = Basis::new(&names, d, BasisLimits::default()).unwrap();
        let mut e = CpuEngine::new(&b, &f, CpuOptions { precision: Precision::F32, materialize_limit_bytes: 0 }).unwrap();
        let v: Vec<f64> = (0..n).map(|_| rng(&mut s)).collect();
        let mut out = vec![0.0; b.len()];
        e.sweep(&v, &mut out).unwrap();
        let reps = 5;
        let t = Instant::now();
        for _ in 0..reps { e.sweep(&v, &mut out).unwrap(); }
        let dt = t.elapsed().as_secs_f64() / reps as f64;
        println!("{} x {}: sweep {:.4} s, {:.3e} pairs/s", n, b.len(), dt, (n * b.len()) as f64 / dt);
    }
}
