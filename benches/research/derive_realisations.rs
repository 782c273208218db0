//! How much of the derivative scores is the one noise realisation each shared signal carries?
//! For every signal and noise level, this draws R fresh realisations of the same noise model
//! (the paper's: y + L * p99(|y|) * N(0,1), seeded) on the exact signal and prints, per order
//! 1..4, the median and the 10-90 % range of our trimmed p95 and full p100 across them, beside
//! our score on the shared realisation and the gate for that cell. A gate the shared
//! realisation fails while the median passes is a property of that draw, not of the method;
//! the anchors behind the gates are single draws too. Per cell it also prints in how many draws
//! the exponential-sum model took over from the smoother and the share of errors within two
//! sigma over all draws (a model's error is a few parameters' error, coherent over a run, so
//! its coverage is judged over draws rather than within one).
//!
//! `cargo bench --bench derive_realisations -- [R]` (default R = 50);
//! `... -- swap` instead scores each smooth signal at each level with each shared noise vector's
//! shape (rescaled to that level): order 1, trimmed p95. The signals are the repository's copy
//! (tests/data/signals, identical to ../shared/signals).
use ctsid::derivatives::benchmark::{gates, load_signal, score_one, NOISES, SIGNALS};
use ctsid::derivatives::differentiate;
use ctsid::derivatives::score::percentile;
use ctsid::plants::noise::add_noise;
use ctsid::plants::rng::Rng;
use std::path::Path;

fn main() {
    let arg = std::env::args().filter(|a| a != "--bench").nth(1);
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals"));
    if arg.as_deref() == Some("swap") {
        return swap(dir);
    }
    let r: usize = arg.and_then(|v| v.parse().ok()).unwrap_or(50);
    println!("{r} realisations per cell; median [10 %, 90 %] across them; shared: the shared draw; gate: the issue's target for the cell\n");
    for name in SIGNALS {
        let sig = load_signal(dir, name).unwrap();
        for (ni, &noise) in NOISES.iter().enumerate() {
            let eta = noise as f64 / 100.0;
            let shared_y = &sig.noisy.iter().find(|(n, _)| *n == noise).unwrap().1;
            let shared = score_one(&sig, &differentiate(shared_y, sig.tau, 4).unwrap(), noise);
            let mut p95 = vec![Vec::new(); 4];
            let mut p100 = vec![Vec::new(); 4];
            let mut cover = [0.0; 4];
            let mut models = 0;
            for k in 0..r {
                let mut rng = Rng::new(7919 * (k as u64 + 1) + 31 * ni as u64 + name.len() as u64);
                let y = add_noise(&sig.truth[0], eta, &mut rng);
                let d = differentiate(&y, sig.tau, 4).unwrap();
                models += d.exp_terms.is_some() as usize;
                let row = score_one(&sig, &d, noise);
                for o in 0..4 {
                    cover[o] += row.coverage2[o] / r as f64;
                    p95[o].push(row.trimmed_p95[o]);
                    p100[o].push(row.full_p100[o]);
                }
            }
            let (gate95, gate100) = gates(name, noise).unwrap();
            println!(
                "{name:15} {noise}% exponential-sum model in {models}/{r} draws; 2-sigma coverage over all draws {}",
                cover.map(|c| format!("{c:.3}")).join("/")
            );
            for o in 0..4 {
                let cell = |v: &[f64], shared: f64, gate: Option<f64>| -> String {
                    let med = percentile(v, 50.0);
                    let share = gate.map_or(String::new(), |g| {
                        let n = v.iter().filter(|x| **x <= g).count();
                        format!(" gate {g:.3}, met in {n}/{}", v.len())
                    });
                    format!(
                        "{med:.3} [{:.3}, {:.3}] shared {shared:.3}{share}",
                        percentile(v, 10.0),
                        percentile(v, 90.0)
                    )
                };
                println!(
                    "{name:15} {noise}% order {}  trimmed p95 {} | full p100 {}",
                    o + 1,
                    cell(&p95[o], shared.trimmed_p95[o], Some(gate95[o])),
                    cell(&p100[o], shared.full_p100[o], gate100.map(|m| m[o]))
                );
            }
        }
    }
}

/// Order-1 trimmed p95 at every level with every shared noise vector, rescaled to that level.
fn swap(dir: &Path) {
    for name in ["sys3_multisine", "sines", "chirp"] {
        let sig = load_signal(dir, name).unwrap();
        for &level in &NOISES {
            let cells: Vec<String> = NOISES
                .iter()
                .map(|&shape| {
                    let ym = &sig.noisy.iter().find(|(n, _)| *n == shape).unwrap().1;
                    let scale = level as f64 / shape as f64;
                    let y: Vec<f64> = ym
                        .iter()
                        .zip(&sig.truth[0])
                        .map(|(m, t)| t + (m - t) * scale)
                        .collect();
                    let row = score_one(&sig, &differentiate(&y, sig.tau, 4).unwrap(), level);
                    format!("{:.3}", row.trimmed_p95[0])
                })
                .collect();
            println!(
                "{name:15} at {level} % with the shape of the 1/3/5 % vectors: {}",
                cells.join(" ")
            );
        }
    }
}
