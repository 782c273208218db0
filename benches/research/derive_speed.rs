//! Timing of the speed targets (single thread): 100 runs x 1000 samples, orders 0..6,
//! and one run of 1,000,000 samples, with the default options, without the smoother level of
//! the local blend, and without the exponential-sum model (same run; the signal is a sum of five
//! sines, so the model is fitted and used on every short run, the most it costs). Prints wall
//! time; the criterion bench is benches/derivatives.rs.
use ctsid::derivatives::{differentiate_runs, DerivativeOptions};
fn signal(n: usize, seed: u64, tau: f64) -> Vec<f64> {
    let mut s = seed;
    let mut rnd = || {
        s = s.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let w: Vec<(f64, f64)> = (0..5)
        .map(|i| (0.5 + i as f64 * 1.3, rnd() * 6.0))
        .collect();
    (0..n)
        .map(|i| {
            let t = i as f64 * tau;
            w.iter().map(|(f, p)| (f * t + p).sin()).sum::<f64>() + 0.03 * (rnd() - 0.5) * 3.46
        })
        .collect()
}
fn main() {
    let runs: Vec<Vec<f64>> = (0..100).map(|r| signal(1000, r, 0.01)).collect();
    let refs: Vec<&[f64]> = runs.iter().map(|r| r.as_slice()).collect();
    let long = signal(1_000_000, 7, 0.001);
    // The default, and without the smoother level of the local blend, in the same run.
    let plain = DerivativeOptions {
        smooth_window: 0.0,
        ..Default::default()
    };
    let chain = DerivativeOptions {
        exp_sum: false,
        ..Default::default()
    };
    for (what, o) in [
        ("default", DerivativeOptions::default()),
        ("no smoother level", plain),
        ("smoother only (no exponential-sum model)", chain),
    ] {
        let t = std::time::Instant::now();
        let d = differentiate_runs(&refs, 0.01, 6, &o).unwrap();
        println!(
            "{what}: 100 runs x 1000 samples, orders 0..6: {:.3} s (h = {:.4}; exponential-sum model on {} runs)",
            t.elapsed().as_secs_f64(),
            d[0].h,
            d.iter().filter(|r| r.exp_terms.is_some()).count()
        );
        let t = std::time::Instant::now();
        let d = differentiate_runs(&[&long], 0.001, 6, &o).unwrap();
        println!(
            "{what}: 1 run x 1,000,000 samples, orders 0..6: {:.3} s (h = {:.4})",
            t.elapsed().as_secs_f64(),
            d[0].h
        );
    }
}
