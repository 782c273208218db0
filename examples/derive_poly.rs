use ctsid::derivatives::{differentiate_with, DerivativeOptions};
fn main() {
    let tau = 0.01;
    let n = 400;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * tau).collect();
    let y: Vec<f64> = t
        .iter()
        .map(|t| 0.5 - 1.2 * t + 0.8 * t * t - 0.3 * t * t * t)
        .collect();
    for (ad, en) in [(false, false), (true, false), (false, true), (true, true)] {
        let d = differentiate_with(
            &y,
            tau,
            3,
            &DerivativeOptions {
                adaptive: ad,
                end_blend: en,
                ..Default::default()
            },
        )
        .unwrap();
        let e1: Vec<f64> = [0usize, 1, 5, 50, 200, 399]
            .iter()
            .map(|&i| d.values[1][i] - (-1.2 + 1.6 * t[i] - 0.9 * t[i] * t[i]))
            .collect();
        println!(
            "adaptive {ad} ends {en}: h {:.4} noise {:.3e} err1 {:?}",
            d.h, d.noise_sd, e1
        );
    }
}
