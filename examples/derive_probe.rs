//! Experiment: trimmed p95 per order over a grid of fixed smoothing levels, for one signal.
use ctsid::derivatives::{benchmark, differentiate_with, DerivativeOptions};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let sig = benchmark::load_signal(std::path::Path::new("../shared/signals"), &a[1]).unwrap();
    let noise: u32 = a[2].parse().unwrap();
    let m: usize = a[3].parse().unwrap();
    let lambda: f64 = a.get(4).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let y = &sig.noisy.iter().find(|(n, _)| *n == noise).unwrap().1;
    let ml = differentiate_with(
        y,
        sig.tau,
        4,
        &DerivativeOptions {
            states: Some(m),
            adaptive: false,
            end_blend: false,
            ..Default::default()
        },
    )
    .unwrap();
    let r = benchmark::score_one(&sig, &ml, noise);
    println!("ML h = {:.4}: {:?}", ml.h, r.trimmed_p95);
    for e in -12..=4 {
        let h = ml.h * 2f64.powf(e as f64 * 0.5);
        let d = differentiate_with(
            y,
            sig.tau,
            4,
            &DerivativeOptions {
                states: Some(m),
                h: Some(h),
                adaptive: false,
                end_blend: false,
                ..Default::default()
            },
        )
        .unwrap();
        let r = benchmark::score_one(&sig, &d, noise);
        println!(
            "h = {:.4} ({:+.1} oct): {:.4} {:.4} {:.4} {:.4}",
            h,
            e as f64 * 0.5,
            r.trimmed_p95[0],
            r.trimmed_p95[1],
            r.trimmed_p95[2],
            r.trimmed_p95[3]
        );
    }
}
