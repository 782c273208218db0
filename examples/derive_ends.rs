//! Experiment: where the worst errors sit (index of the max error per order) and the error profile at the ends.
use ctsid::derivatives::{benchmark, differentiate_with, DerivativeOptions};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let sig = benchmark::load_signal(std::path::Path::new("../shared/signals"), &a[1]).unwrap();
    let noise: u32 = a[2].parse().unwrap();
    let lam: f64 = a.get(3).map(|s| s.parse().unwrap()).unwrap_or(0.5);
    let y = &sig.noisy.iter().find(|(n, _)| *n == noise).unwrap().1;
    let d = differentiate_with(
        y,
        sig.tau,
        4,
        &DerivativeOptions {
            end_lambda: lam,
            ..Default::default()
        },
    )
    .unwrap();
    let n = y.len();
    println!("h = {:.4}, 1/h = {:.1} samples", d.h, 1.0 / d.h);
    for k in 1..=4 {
        let med = ctsid::derivatives::score::percentile(
            &sig.truth[k].iter().map(|v| v.abs()).collect::<Vec<_>>(),
            50.0,
        );
        let err: Vec<f64> = (0..n)
            .map(|i| (d.values[k][i] - sig.truth[k][i]).abs() / med)
            .collect();
        let (imax, emax) = err
            .iter()
            .enumerate()
            .fold((0, 0.0), |b, (i, &e)| if e > b.1 { (i, e) } else { b });
        let head: Vec<String> = [0, 1, 2, 5, 10, 20, 40]
            .iter()
            .map(|&i| format!("{:.3}", err[i]))
            .collect();
        let tail: Vec<String> = [0, 1, 2, 5, 10, 20, 40]
            .iter()
            .map(|&i| format!("{:.3}", err[n - 1 - i]))
            .collect();
        println!(
            "order {k}: max {emax:.3} at {imax}; head {}; tail {}",
            head.join(" "),
            tail.join(" ")
        );
    }
}
